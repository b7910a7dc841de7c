//! Runs a resolved experiment: every sweep point on a rayon pool of `jobs` threads, tables
//! prefixed with the point's sweep values and concatenated, written as CSV + Parquet, figures,
//! and `run.json` (id, seed, resolved spec, crate version, git revision and whether the code
//! had uncommitted changes, threads, seconds per stage).

use super::output::{atomic_write, write_table, Cell, Table, Tables};
use super::plot::FigureSink;
use super::resolve::Resolved;
use super::{Error, RunContext};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Where and how to run.
#[derive(Debug, Clone)]
pub struct RunOptions {
    /// Results root: tables go to `<out>/<id>/`.
    pub out: PathBuf,
    /// Figures folder.
    pub figures: PathBuf,
    /// Worker threads (results do not depend on it).
    pub jobs: usize,
    /// Draw progress bars (only on a terminal).
    pub progress: bool,
}

/// What a run wrote.
#[derive(Debug, Clone)]
pub struct RunSummary {
    /// Experiment id.
    pub id: String,
    /// Its results folder.
    pub dir: PathBuf,
    /// Every file written.
    pub files: Vec<PathBuf>,
    /// Wall time in seconds.
    pub seconds: f64,
}

/// The git revision of the working directory, when it is a git checkout.
pub fn git_revision() -> Option<String> {
    let out = std::process::Command::new("git")
        .args(["rev-parse", "HEAD"])
        .stderr(std::process::Stdio::null())
        .output()
        .ok()?;
    out.status
        .success()
        .then(|| String::from_utf8_lossy(&out.stdout).trim().to_string())
}

/// The paths whose changes change results: the code, the experiment files and the build.
pub const CODE_PATHS: [&str; 4] = ["src", "experiments", "Cargo.toml", "Cargo.lock"];

/// Whether the checkout has uncommitted changes to [`CODE_PATHS`] (`None` outside a git
/// checkout).
pub fn git_dirty() -> Option<bool> {
    let out = std::process::Command::new("git")
        .args(["status", "--porcelain", "--"])
        .args(CODE_PATHS)
        .stderr(std::process::Stdio::null())
        .output()
        .ok()?;
    out.status.success().then(|| !out.stdout.is_empty())
}

/// Runs every sweep point, then writes tables, figures and `run.json`.
pub fn run(res: &Resolved, opts: &RunOptions) -> Result<RunSummary, Error> {
    let t0 = Instant::now();
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(opts.jobs.max(1))
        .build()
        .map_err(|e| Error::Other(format!("thread pool: {e}")))?;
    let ctx = RunContext::new(res.seed, res.quick, opts.progress);
    let mut merged: Vec<(String, Table)> = Vec::new();
    pool.install(|| -> Result<(), Error> {
        for (i, point) in res.points.iter().enumerate() {
            let label = if point.values.is_empty() {
                "run".to_string()
            } else {
                format!("run point {i}")
            };
            let tables = ctx.stage(&label, || point.job.run(&ctx))?;
            let prefix: Vec<(String, Cell)> = point
                .values
                .iter()
                .map(|(k, v)| (k.clone(), Cell::from(v)))
                .collect();
            for (name, t) in tables.0 {
                let t = t.with_prefix(&prefix);
                match merged.iter_mut().find(|(n, _)| *n == name) {
                    Some((_, acc)) => acc
                        .append(&t)
                        .map_err(|e| Error::Other(format!("table {name}: {e}")))?,
                    None => merged.push((name, t)),
                }
            }
        }
        Ok(())
    })?;
    let dir = opts.out.join(&res.id);
    let mut files = Vec::new();
    ctx.stage("write tables", || -> Result<(), Error> {
        for (name, t) in &merged {
            files.extend(write_table(&dir, name, t)?);
        }
        Ok(())
    })?;
    let tables = Tables(merged);
    let sink = FigureSink {
        dir: opts.figures.clone(),
        id: res.id.clone(),
    };
    let figs = ctx.stage("figures", || {
        pool.install(|| res.family.figures(&sink, &tables))
    })?;
    files.extend(figs);
    let seconds = t0.elapsed().as_secs_f64();
    let stages: serde_json::Map<String, serde_json::Value> = ctx
        .stages()
        .into_iter()
        .map(|(k, v)| (k, serde_json::json!(v)))
        .collect();
    let meta = serde_json::json!({
        "id": res.id,
        "seed": res.seed,
        "spec": res.to_json(),
        "crate_version": env!("CARGO_PKG_VERSION"),
        "git_revision": git_revision(),
        "git_dirty": git_dirty(),
        "threads": opts.jobs.max(1),
        "seconds_per_stage": stages,
        "seconds_total": seconds,
        "files": files.iter().map(|f| rel_name(&opts.out, &opts.figures, f)).collect::<Vec<_>>(),
    });
    let run_json = dir.join("run.json");
    let text = serde_json::to_string_pretty(&meta).map_err(|e| Error::Other(e.to_string()))?;
    atomic_write(&run_json, text.as_bytes())?;
    files.push(run_json);
    Ok(RunSummary {
        id: res.id.clone(),
        dir,
        files,
        seconds,
    })
}

fn rel_name(out: &Path, figures: &Path, f: &Path) -> String {
    f.strip_prefix(out)
        .or_else(|_| f.strip_prefix(figures))
        .unwrap_or(f)
        .display()
        .to_string()
}
