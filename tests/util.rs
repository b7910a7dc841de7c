//! Helpers: run the binary, read files.

use std::fs::File;
use std::path::{Path, PathBuf};
use std::process::Output;
use std::sync::OnceLock;

pub fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// Runs `motionlab` with `args` in `cwd`.
pub fn motionlab(cwd: &Path, args: &[&str]) -> Output {
    std::process::Command::new(env!("CARGO_BIN_EXE_motionlab"))
        .args(args)
        .current_dir(cwd)
        .env("MOTIONLAB_TEST", "1")
        .output()
        .expect("run motionlab")
}

pub fn ok(out: &Output) -> String {
    assert!(
        out.status.success(),
        "motionlab failed:\nstdout: {}\nstderr: {}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

pub fn header(path: &Path) -> String {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    text.lines().next().unwrap_or("").to_string()
}

/// The shipped experiment file `id`.
pub fn spec(id: &str) -> String {
    std::fs::read_to_string(root().join("experiments").join(format!("{id}.toml"))).unwrap()
}

/// Every file below `dir` with its bytes, sorted by relative path.
pub fn files_with_ext(dir: &Path, ext: &str) -> Vec<(String, Vec<u8>)> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                stack.push(p);
            } else if p.extension().is_some_and(|x| x == ext) {
                let rel = p.strip_prefix(dir).unwrap().display().to_string();
                out.push((rel, std::fs::read(&p).unwrap()));
            }
        }
    }
    out.sort();
    out
}

/// Runs the shipped experiment `id` in quick mode in a fresh temp dir (outputs in `out/` and
/// `figs/` there) with `--jobs jobs`.
pub fn run_quick(id: &str, jobs: &str) -> tempfile::TempDir {
    run_quick_with(id, &["--jobs", jobs])
}

/// `motionlab run <id> --quick` with `extra` arguments (e.g. `--seeds 2`, `--set k=v`) into
/// `out/` and `figs/` of a fresh temporary folder.
pub fn run_quick_with(id: &str, extra: &[&str]) -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    let exp = root().join("experiments");
    let mut args = vec![
        "--experiments",
        exp.to_str().unwrap(),
        "run",
        id,
        "--quick",
        "--out",
        "out",
        "--figures",
        "figs",
    ];
    args.extend_from_slice(extra);
    ok(&motionlab(dir.path(), &args));
    dir
}

/// The folder of [`quick_reproduction`]: `out/` and `figs/` of one `reproduce --quick`.
pub struct Shared {
    dir: PathBuf,
    /// Held while the test binary runs, so a second `cargo test` waits rather than sharing it.
    _lock: File,
}

impl Shared {
    pub fn path(&self) -> &Path {
        &self.dir
    }
}

impl AsRef<Path> for Shared {
    fn as_ref(&self) -> &Path {
        &self.dir
    }
}

/// One `reproduce --quick --jobs 2` of every shipped experiment, the main job as users run it,
/// made once per test binary and read by every test that checks one experiment's quick outputs
/// (`out/<id>/`, `figs/<id>_*`). Each of those used to run its experiment again on its own,
/// which doubled the suite's time. The folder, `target/tmp/quick-reproduction`, is replaced by
/// the next test run and kept until then for a look at the quick outputs. A failed run fails
/// every test that reads it, with its output, without running it again.
pub fn quick_reproduction() -> &'static Shared {
    static RUN: OnceLock<Result<Shared, String>> = OnceLock::new();
    let run = RUN.get_or_init(|| {
        let tmp = PathBuf::from(env!("CARGO_TARGET_TMPDIR"));
        let lock = File::create(tmp.join("quick-reproduction.lock")).map_err(|e| e.to_string())?;
        lock.lock().map_err(|e| e.to_string())?;
        let dir = tmp.join("quick-reproduction");
        if dir.exists() {
            std::fs::remove_dir_all(&dir).map_err(|e| e.to_string())?;
        }
        std::fs::create_dir_all(&dir).map_err(|e| e.to_string())?;
        let exp = root().join("experiments");
        let out = motionlab(
            &dir,
            &[
                "--experiments",
                exp.to_str().unwrap(),
                "reproduce",
                "--quick",
                "--jobs",
                "2",
                "--out",
                "out",
                "--figures",
                "figs",
            ],
        );
        if !out.status.success() {
            return Err(format!(
                "reproduce --quick failed:\nstdout: {}\nstderr: {}",
                String::from_utf8_lossy(&out.stdout),
                String::from_utf8_lossy(&out.stderr)
            ));
        }
        Ok(Shared { dir, _lock: lock })
    });
    run.as_ref().unwrap_or_else(|e| panic!("{e}"))
}

/// The stderr of a run that must have failed (panics with it when the run succeeded).
pub fn fails(out: &Output) -> String {
    assert!(
        !out.status.success(),
        "motionlab should have failed:\nstderr: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stderr).into_owned()
}

/// The stderr of a run that must have succeeded.
pub fn stderr(out: &Output) -> String {
    ok(out);
    String::from_utf8_lossy(&out.stderr).into_owned()
}
