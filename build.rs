//! Embeds the git revision of the source the binary is built from, so that `run.json`, shards
//! and `--resume` name the code that runs, whatever folder the binary runs in (issue 55).
//!
//! Sets, for `env!` in the crate:
//! - `MOTIONLAB_GIT_REVISION`: `git rev-parse HEAD`;
//! - `MOTIONLAB_GIT_DIRTY`: `true` when the compiled sources ([`COMPILED`]) had uncommitted
//!   changes at build time, else `false`;
//! - `MOTIONLAB_CODE_REVISION`: the last commit that changed the code or the experiment files
//!   (`git log -1 -- src experiments Cargo.toml Cargo.lock`), for the report's staleness marks.
//!
//! Each is `unknown` when git or the repository is absent (a source tarball, a vendored copy):
//! the build never fails for lack of git.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

/// What is compiled into the binary: a change here makes the build dirty.
const COMPILED: [&str; 4] = ["src", "build.rs", "Cargo.toml", "Cargo.lock"];

/// The paths whose last change the report compares results against (`runner::CODE_PATHS`).
const CODE_PATHS: [&str; 4] = ["src", "experiments", "Cargo.toml", "Cargo.lock"];

/// Standard output of `git args` in `dir`, trimmed, when git ran and succeeded.
fn git(dir: &Path, args: &[&str]) -> Option<String> {
    let out = Command::new("git")
        .arg("--no-optional-locks")
        .args(args)
        .current_dir(dir)
        .stdin(Stdio::null())
        .stderr(Stdio::null())
        .output()
        .ok()?;
    out.status
        .success()
        .then(|| String::from_utf8_lossy(&out.stdout).trim().to_string())
}

fn main() {
    let dir = PathBuf::from(std::env::var_os("CARGO_MANIFEST_DIR").unwrap_or_default());
    for p in COMPILED {
        if dir.join(p).exists() {
            println!("cargo:rerun-if-changed={p}");
        }
    }
    let revision = git(&dir, &["rev-parse", "--verify", "HEAD"]).filter(|r| !r.is_empty());
    let (mut dirty, mut code) = (None, None);
    if revision.is_some() {
        dirty = git(
            &dir,
            &[&["status", "--porcelain", "--"][..], &COMPILED[..]].concat(),
        )
        .map(|s| !s.is_empty());
        code = git(
            &dir,
            &[&["log", "-1", "--format=%H", "--"][..], &CODE_PATHS[..]].concat(),
        )
        .filter(|r| !r.is_empty());
        // A commit, a checkout or staging changes these: run again then.
        let path = |args: &[&str]| git(&dir, args).map(|p| dir.join(p));
        let mut watched = vec![];
        if let Some(git_dir) = path(&["rev-parse", "--git-dir"]) {
            // Not the index: staging changes neither the revision nor whether the compiled
            // sources differ from it (a change to them reruns this script through `src`), and
            // any `git status` rewrites the index, which would rebuild the crate each time.
            watched.push(git_dir.join("HEAD"));
        }
        if let Some(common) = path(&["rev-parse", "--git-common-dir"]) {
            if let Some(head_ref) = git(&dir, &["symbolic-ref", "-q", "HEAD"]) {
                watched.push(common.join(head_ref));
            }
            watched.push(common.join("packed-refs"));
        }
        // A path that does not exist would make cargo run this script on every build.
        for w in watched.iter().filter(|w| w.exists()) {
            println!("cargo:rerun-if-changed={}", w.display());
        }
    }
    let text = |v: Option<String>| v.unwrap_or_else(|| "unknown".into());
    println!("cargo:rustc-env=MOTIONLAB_GIT_REVISION={}", text(revision));
    println!(
        "cargo:rustc-env=MOTIONLAB_GIT_DIRTY={}",
        text(dirty.map(|d| d.to_string()))
    );
    println!("cargo:rustc-env=MOTIONLAB_CODE_REVISION={}", text(code));
}
