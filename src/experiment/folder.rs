//! # An experiment's output folder: its lock and its `INCOMPLETE` marker
//!
//! - **Lock.** A run (or `merge`) into `<out>/<id>/`, and a shard's run into its
//!   `<out>/<id>/shards/<I-of-N>/`, first creates the folder's lock file [`LOCK`] (exclusively:
//!   it fails when the file exists) holding its process id and host, and removes it when it ends,
//!   whether it succeeded or failed ([`FolderLock`]'s `Drop`). A second run into the same folder
//!   refuses before any work, naming the folder and the process that holds it. A lock left by a
//!   run that was killed (its process no longer runs on this host) is taken over, saying so; one
//!   held from another host, or whose process this machine cannot see, is not: the message says
//!   to delete the lock file if that run is gone.
//! - **Marker.** Before a run rewrites an experiment's folder (its tables, seeds, figures and
//!   `run.json`, in that order) it writes [`INCOMPLETE`] there, and removes it only after
//!   `run.json`, written last, is in place. A run that is killed or fails part way (a full disk,
//!   a figures folder it cannot write) leaves the marker, and [`check_complete`] (used by the
//!   report, `reproduce` and `merge`) refuses such a folder, saying to rerun the experiment;
//!   rerunning it (with `--resume`, it reuses the units already computed) removes the marker.

use super::output::{atomic_write, process_alive};
use super::Error;
use std::io::Write;
use std::path::{Path, PathBuf};

/// The lock file of an experiment's (or a shard's) folder while a run writes it.
pub const LOCK: &str = ".motionlab.lock";

/// The marker file of an experiment folder that a run has begun to rewrite and not finished.
pub const INCOMPLETE: &str = "INCOMPLETE";

/// This machine's host name (Linux's `/proc/sys/kernel/hostname`, else `$HOSTNAME`, else
/// `unknown`).
pub fn host_name() -> String {
    std::fs::read_to_string("/proc/sys/kernel/hostname")
        .ok()
        .or_else(|| std::env::var("HOSTNAME").ok())
        .map(|h| h.trim().to_string())
        .filter(|h| !h.is_empty())
        .unwrap_or_else(|| "unknown".into())
}

/// The holder a lock file names: `pid <PID> host <HOST>`.
fn parse_holder(text: &str) -> Option<(u32, String)> {
    let mut words = text.split_whitespace();
    let (Some("pid"), Some(pid), Some("host"), Some(host)) =
        (words.next(), words.next(), words.next(), words.next())
    else {
        return None;
    };
    Some((pid.parse().ok()?, host.to_string()))
}

/// The exclusive lock of a folder a run writes (see the [module docs](crate::experiment::folder)); removed when
/// dropped.
#[derive(Debug)]
pub struct FolderLock {
    path: PathBuf,
    text: String,
}

impl FolderLock {
    /// Takes the lock of `dir` (created when missing), or refuses with an error that names the
    /// folder and the process holding it. Returns the lock and, when it took over the lock of a
    /// run that no longer runs, a line saying so.
    pub fn acquire(dir: &Path) -> Result<(FolderLock, Option<String>), Error> {
        let io = |path: &Path| {
            let path = path.to_path_buf();
            move |source| Error::Io { path, source }
        };
        std::fs::create_dir_all(dir).map_err(io(dir))?;
        let path = dir.join(LOCK);
        let host = host_name();
        let text = format!("pid {} host {host}\n", std::process::id());
        let mut note = None;
        // A few tries: between our look and our create another run may take or free it.
        for _ in 0..4 {
            match std::fs::OpenOptions::new()
                .write(true)
                .create_new(true)
                .open(&path)
            {
                Ok(mut f) => {
                    if let Err(e) = f.write_all(text.as_bytes()) {
                        let _ = std::fs::remove_file(&path);
                        return Err(io(&path)(e));
                    }
                    return Ok((FolderLock { path, text }, note));
                }
                Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {}
                Err(e) => return Err(io(&path)(e)),
            }
            let held = match std::fs::read_to_string(&path) {
                Ok(t) => t,
                Err(e) if e.kind() == std::io::ErrorKind::NotFound => continue,
                Err(e) => return Err(io(&path)(e)),
            };
            let holder = parse_holder(&held);
            let stale = holder
                .as_ref()
                .is_some_and(|(pid, h)| *h == host && process_alive(*pid) == Some(false));
            if !stale {
                let who = match &holder {
                    Some((pid, h)) => format!("process {pid} on host {h}"),
                    None => "an unknown process".into(),
                };
                return Err(Error::Other(format!(
                    "{}: another motionlab run ({who}) is writing this folder (lock file {}); \
                     wait for it to end, or delete the lock file if that run is gone",
                    dir.display(),
                    path.display()
                )));
            }
            // Moved aside first, so that of two runs taking over only one removes it.
            let aside = dir.join(format!("{LOCK}.stale-{}", std::process::id()));
            match std::fs::rename(&path, &aside) {
                Ok(()) => {}
                Err(e) if e.kind() == std::io::ErrorKind::NotFound => continue,
                Err(e) => return Err(io(&path)(e)),
            }
            if std::fs::read_to_string(&aside).is_ok_and(|t| t == held) {
                std::fs::remove_file(&aside).map_err(io(&aside))?;
                let (pid, _) = holder.unwrap_or_default();
                note = Some(format!(
                    "{}: took over the lock of motionlab process {pid}, which no longer runs \
                     (a run that was stopped)",
                    dir.display()
                ));
            } else {
                // Another run took it over just before: its lock goes back.
                let _ = std::fs::rename(&aside, &path);
            }
        }
        Err(Error::Other(format!(
            "{}: could not take the lock file {} (other runs keep taking it)",
            dir.display(),
            path.display()
        )))
    }

    /// The lock file.
    pub fn path(&self) -> &Path {
        &self.path
    }
}

impl Drop for FolderLock {
    fn drop(&mut self) {
        // Only our own lock: one taken over by mistake stays its new holder's.
        if std::fs::read_to_string(&self.path).is_ok_and(|t| t == self.text) {
            let _ = std::fs::remove_file(&self.path);
        }
    }
}

/// Writes the [`INCOMPLETE`] marker into the experiment folder `dir` (atomically), before a run
/// rewrites it.
pub fn mark_incomplete(dir: &Path) -> Result<(), Error> {
    let text = format!(
        "A motionlab run (process {} on host {}) began to rewrite this folder and has not \
         finished: it runs still, or it was stopped or failed part way, and the files here may mix \
         two runs. Rerun the experiment; the marker goes when a run has written run.json.\n",
        std::process::id(),
        host_name()
    );
    atomic_write(&dir.join(INCOMPLETE), text.as_bytes())
}

/// Removes the [`INCOMPLETE`] marker of `dir` (after `run.json` is written).
pub fn mark_complete(dir: &Path) -> Result<(), Error> {
    let path = dir.join(INCOMPLETE);
    match std::fs::remove_file(&path) {
        Err(e) if e.kind() != std::io::ErrorKind::NotFound => Err(Error::Io { path, source: e }),
        _ => Ok(()),
    }
}

/// An error naming the experiment folder `dir` when it holds the [`INCOMPLETE`] marker of a run
/// that did not finish (see the [module docs](crate::experiment::folder)).
pub fn check_complete(dir: &Path) -> Result<(), Error> {
    if !dir.join(INCOMPLETE).exists() {
        return Ok(());
    }
    let id = dir
        .file_name()
        .map_or_else(String::new, |n| n.to_string_lossy().into_owned());
    Err(Error::Other(format!(
        "{}: the last run into this folder did not finish (it was stopped or failed part way, or \
         runs still; see {}), so its files may mix two runs: rerun it (`motionlab run {id}`, \
         `--resume` reuses its finished units) before a report or merge uses it",
        dir.display(),
        dir.join(INCOMPLETE).display()
    )))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_second_lock_of_a_folder_is_refused_until_the_first_is_dropped() {
        let d = tempfile::tempdir().unwrap();
        let dir = d.path().join("exp");
        let (first, note) = FolderLock::acquire(&dir).unwrap();
        assert!(note.is_none());
        assert!(first.path().is_file());
        let e = FolderLock::acquire(&dir).unwrap_err().to_string();
        assert!(e.contains(&dir.display().to_string()), "{e}");
        assert!(
            e.contains(&format!("process {}", std::process::id())),
            "{e}"
        );
        drop(first);
        assert!(!dir.join(LOCK).exists(), "the lock is removed when dropped");
        let (again, _) = FolderLock::acquire(&dir).unwrap();
        drop(again);
    }

    #[test]
    fn a_lock_of_a_process_that_is_gone_is_taken_over_one_of_another_host_is_not() {
        let d = tempfile::tempdir().unwrap();
        let path = d.path().join(LOCK);
        // No process has an id above Linux's largest (2²²).
        std::fs::write(&path, format!("pid {} host {}\n", u32::MAX, host_name())).unwrap();
        let (lock, note) = FolderLock::acquire(d.path()).unwrap();
        let note = note.expect("a takeover is reported");
        assert!(note.contains(&u32::MAX.to_string()), "{note}");
        drop(lock);
        let names: Vec<_> = std::fs::read_dir(d.path()).unwrap().collect();
        assert!(names.is_empty(), "nothing left: {names:?}");
        let other = format!("pid {} host not-{}\n", u32::MAX, host_name());
        std::fs::write(&path, &other).unwrap();
        let e = FolderLock::acquire(d.path()).unwrap_err().to_string();
        assert!(
            e.contains("host not-") && e.contains("delete the lock"),
            "{e}"
        );
        assert_eq!(std::fs::read_to_string(&path).unwrap(), other);
        std::fs::write(&path, "garbage").unwrap();
        let e = FolderLock::acquire(d.path()).unwrap_err().to_string();
        assert!(e.contains("unknown process"), "{e}");
    }

    #[test]
    fn a_marked_folder_is_refused_until_the_mark_is_removed() {
        let d = tempfile::tempdir().unwrap();
        let dir = d.path().join("exp");
        check_complete(&dir).unwrap();
        mark_incomplete(&dir).unwrap();
        let e = check_complete(&dir).unwrap_err().to_string();
        assert!(
            e.contains(&dir.display().to_string()) && e.contains("rerun"),
            "{e}"
        );
        mark_complete(&dir).unwrap();
        check_complete(&dir).unwrap();
        mark_complete(&dir).unwrap();
    }
}
