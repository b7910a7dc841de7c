//! Runs a resolved experiment: every unit (sweep point, times seed when seeds are swept) on a
//! rayon pool of `jobs` threads, tables prefixed with the unit's seed and sweep values and
//! concatenated in unit order, written as CSV + Parquet, figures, and `run.json` (id, seed,
//! resolved spec, crate version, the git revision the binary was built from and whether its
//! code had uncommitted changes then,
//! threads, seconds per stage). A sweep's units are also kept one file each for `--resume`;
//! `--shard I/N` runs a share of the units and [`merge`] joins the shares (see
//! [`super::shard`]).

use super::folder::{mark_complete, mark_incomplete, FolderLock};
use super::output::{atomic_write, write_table, Cell, Table, Tables};
use super::plot::FigureSink;
use super::resolve::{Resolved, Unit};
use super::seeds;
use super::shard::{
    load_unit, read_shards, save_unit, unit_key, unit_path, Shard, ShardRecord, SHARD_RECORD,
};
use super::spec::SpecFile;
use super::{Error, Registry, RunContext};
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
    /// Reuse the stored units whose key matches instead of running them again.
    pub resume: bool,
    /// Run only this shard's units into `<out>/<id>/shards/I-of-N/`.
    pub shard: Option<Shard>,
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
    /// Units run now.
    pub computed: usize,
    /// Units loaded from their stored results (`--resume`, `merge`).
    pub reused: usize,
    /// What the run did besides its results that its user should hear of (a lock taken over,
    /// an earlier run's seeds removed), one line each.
    pub notes: Vec<String>,
}

/// When a run started: on the wall clock, and in the CPU time the process had used.
#[derive(Debug, Clone, Copy)]
pub struct Clock {
    wall: Instant,
    cpu: Option<f64>,
}

impl Clock {
    /// Now.
    pub fn start() -> Self {
        Clock {
            wall: Instant::now(),
            cpu: process_cpu_seconds(),
        }
    }

    /// Wall-clock seconds since the start.
    pub fn wall_seconds(&self) -> f64 {
        self.wall.elapsed().as_secs_f64()
    }

    /// CPU seconds the whole process (every thread) has used since the start, where the
    /// platform tells ([`process_cpu_seconds`]). Over the wall seconds it says how many cores
    /// the run kept busy; a run alone in its process is the only user.
    pub fn cpu_seconds(&self) -> Option<f64> {
        Some(process_cpu_seconds()? - self.cpu?)
    }
}

/// User plus system CPU time of this process, all its threads, in seconds: fields 14 and 15 of
/// Linux's `/proc/self/stat`, in clock ticks of USER_HZ, which the kernel fixes at 100 a second
/// for user space. `None` where there is no such file (other systems).
pub fn process_cpu_seconds() -> Option<f64> {
    let stat = std::fs::read_to_string("/proc/self/stat").ok()?;
    // The command name (field 2) is in parentheses and may hold spaces: count after it.
    let rest = &stat[stat.rfind(')')? + 1..];
    let fields: Vec<&str> = rest.split_whitespace().collect();
    let ticks = |i: usize| fields.get(i)?.parse::<u64>().ok();
    // `rest` starts at field 3.
    Some((ticks(14 - 3)? + ticks(15 - 3)?) as f64 / 100.0)
}

/// `f` of every item, in order, run as many at a time as the current rayon pool has threads
/// (the run's `--jobs`), each on one thread of its own: for work that reports its own seconds,
/// which are then those of one core, whatever the thread count. (A rayon job that enters a
/// one-thread pool keeps stealing its own pool's jobs while it waits, so a `par_iter` over
/// such runs would start all of them at once, each with a share of a core.)
pub fn one_core_each<T: Sync, R: Send>(
    items: &[T],
    f: impl Fn(&T) -> R + Sync,
) -> Result<Vec<R>, Error> {
    let lanes = rayon::current_num_threads().clamp(1, items.len().max(1));
    let next = std::sync::atomic::AtomicUsize::new(0);
    let done: std::sync::Mutex<Vec<Option<R>>> =
        std::sync::Mutex::new(items.iter().map(|_| None).collect());
    std::thread::scope(|scope| -> Result<(), Error> {
        let workers: Vec<_> = (0..lanes)
            .map(|_| {
                scope.spawn(|| -> Result<(), Error> {
                    let one = rayon::ThreadPoolBuilder::new()
                        .num_threads(1)
                        .build()
                        .map_err(|e| Error::Other(format!("thread pool: {e}")))?;
                    loop {
                        let i = next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                        let Some(item) = items.get(i) else {
                            return Ok(());
                        };
                        let r = one.install(|| f(item));
                        done.lock().unwrap_or_else(|e| e.into_inner())[i] = Some(r);
                    }
                })
            })
            .collect();
        for w in workers {
            w.join()
                .unwrap_or_else(|panic| std::panic::resume_unwind(panic))?;
        }
        Ok(())
    })?;
    Ok(done
        .into_inner()
        .unwrap_or_else(|e| e.into_inner())
        .into_iter()
        .map(|r| r.expect("every item ran"))
        .collect())
}

/// The most worker threads a run may use (`--jobs`): more than any machine's cores, and few
/// enough that creating them takes no time.
pub const MAX_JOBS: usize = 1024;

/// A value `build.rs` embedded, `None` where it could not tell (`unknown`).
fn embedded(value: Option<&'static str>) -> Option<&'static str> {
    value.filter(|v| !v.is_empty() && *v != "unknown")
}

/// The git revision the binary was built from (embedded at build time by `build.rs`, so the
/// same binary names the same revision in any working directory); `None` when it was built
/// outside a git checkout.
pub fn git_revision() -> Option<String> {
    embedded(option_env!("MOTIONLAB_GIT_REVISION")).map(str::to_string)
}

/// The paths whose changes change results: the code, the experiment files and the build.
pub const CODE_PATHS: [&str; 4] = ["src", "experiments", "Cargo.toml", "Cargo.lock"];

/// Whether the source the binary was built from had uncommitted changes at build time (to
/// what is compiled in: `src`, `build.rs`, `Cargo.toml`, `Cargo.lock`; embedded by
/// `build.rs`); `None` when it was built outside a git checkout.
pub fn git_dirty() -> Option<bool> {
    match embedded(option_env!("MOTIONLAB_GIT_DIRTY")) {
        Some("true") => Some(true),
        Some("false") => Some(false),
        _ => None,
    }
}

/// Runs the experiment's units (or, with [`RunOptions::shard`], only the shard's), then writes
/// tables, figures and `run.json` (a shard writes its units and `shard.json` instead; see
/// [`super::shard`]). Holds the lock of the folder it writes (`<out>/<id>/`, a shard's own
/// folder) throughout, and refuses when another run holds it ([`super::folder`]).
pub fn run(res: &Resolved, opts: &RunOptions) -> Result<RunSummary, Error> {
    let t0 = Clock::start();
    check_jobs(opts.jobs)?;
    let dir = opts.out.join(&res.id);
    let (_lock, lock_note) = FolderLock::acquire(&match opts.shard {
        Some(sh) => dir.join("shards").join(sh.dir_name()),
        None => dir.clone(),
    })?;
    // Nets used before this run (another experiment's) are not this run's.
    let _ = crate::emulator::cache::take_usage();
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(opts.jobs.max(1))
        .build()
        .map_err(|e| Error::Other(format!("thread pool: {e}")))?;
    let units = res.units();
    let revision = git_revision();
    let dirty = git_dirty();
    let (selected, store): (Vec<Unit>, Option<PathBuf>) = match opts.shard {
        Some(sh) => {
            let shard_dir = dir.join("shards").join(sh.dir_name());
            // An unfinished shard has no record: remove an old one before any work.
            let record = shard_dir.join(SHARD_RECORD);
            if record.exists() {
                std::fs::remove_file(&record).map_err(|e| Error::Io {
                    path: record.clone(),
                    source: e,
                })?;
            }
            (
                units.iter().copied().filter(|u| sh.owns(u.index)).collect(),
                Some(shard_dir.join("units")),
            )
        }
        None => {
            let keep = units.len() > 1 || opts.resume;
            (units, keep.then(|| dir.join("units")))
        }
    };
    let ctx = RunContext::new(res.seed, res.quick, opts.progress);
    let (mut results, mut reused) = (Vec::with_capacity(selected.len()), 0);
    pool.install(|| -> Result<(), Error> {
        for unit in &selected {
            let key = unit_key(res, unit, revision.as_deref());
            let path = store.as_ref().map(|s| unit_path(s, &key));
            if let Some(p) = path.as_ref().filter(|_| opts.resume) {
                if let Ok(r) = load_unit(p, &key) {
                    reused += 1;
                    results.push((unit.index, key, r));
                    continue;
                }
            }
            let r = run_unit(res, unit, opts.progress)?;
            if let Some(p) = &path {
                save_unit(p, &key, &r)?;
            }
            results.push((unit.index, key, r));
        }
        Ok(())
    })?;
    let computed = results.len() - reused;
    for (_, _, (_, stages)) in &results {
        for (name, secs) in stages {
            ctx.record(name, *secs);
        }
    }
    if let Some(sh) = opts.shard {
        let shard_dir = dir.join("shards").join(sh.dir_name());
        let record = ShardRecord {
            id: res.id.clone(),
            shard: sh.index,
            of: sh.count,
            spec_hash: res.spec_hash(),
            git_revision: revision,
            git_dirty: dirty,
            quick: res.options.quick,
            seed: res.options.seed,
            sets: res.options.sets.clone(),
            seeds: res.options.seeds,
            units: results
                .iter()
                .map(|(i, key, _)| {
                    let name = unit_path(Path::new(""), key).display().to_string();
                    (*i, name)
                })
                .collect(),
            threads: opts.jobs.max(1),
            seconds_total: t0.wall_seconds(),
        };
        let path = shard_dir.join(SHARD_RECORD);
        let text =
            serde_json::to_string_pretty(&record).map_err(|e| Error::Other(e.to_string()))?;
        atomic_write(&path, text.as_bytes())?;
        let mut files: Vec<PathBuf> = results
            .iter()
            .filter_map(|(_, key, _)| store.as_ref().map(|s| unit_path(s, key)))
            .collect();
        files.push(path);
        return Ok(RunSummary {
            id: res.id.clone(),
            dir: shard_dir,
            files,
            seconds: t0.wall_seconds(),
            computed,
            reused,
            notes: lock_note.into_iter().collect(),
        });
    }
    let tables = results.into_iter().map(|(_, _, (t, _))| t).collect();
    let provenance = Provenance {
        git_revision: revision,
        git_dirty: dirty,
        extra: serde_json::json!({ "units": { "total": selected.len(), "computed": computed, "reused": reused } }),
    };
    let mut s = finish(res, opts, tables, &ctx, provenance, &pool, t0)?;
    s.computed = computed;
    s.reused = reused;
    if let Some(note) = lock_note {
        s.notes.insert(0, note);
    }
    Ok(s)
}

/// Merges the shards in `<out>/<id>/shards/` (see [`super::shard::read_shards`]) into the tables,
/// figures and `run.json` of the unsharded run; returns them and the experiment as the shards
/// resolved it. Holds the lock of `<out>/<id>/` while it writes ([`super::folder`]).
pub fn merge(
    file: &SpecFile,
    opts: &RunOptions,
    registry: &Registry,
) -> Result<(RunSummary, Resolved), Error> {
    let t0 = Clock::start();
    check_jobs(opts.jobs)?;
    let m = read_shards(file, &opts.out, registry)?;
    let (_lock, lock_note) = FolderLock::acquire(&opts.out.join(&m.resolved.id))?;
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(opts.jobs.max(1))
        .build()
        .map_err(|e| Error::Other(format!("thread pool: {e}")))?;
    let ctx = RunContext::new(m.resolved.seed, m.resolved.quick, opts.progress);
    let mut tables = Vec::with_capacity(m.results.len());
    for (t, stages) in m.results {
        for (name, secs) in &stages {
            ctx.record(name, *secs);
        }
        tables.push(t);
    }
    let provenance = Provenance {
        git_revision: m.git_revision,
        git_dirty: m.git_dirty,
        extra: serde_json::json!({ "merged_shards": m.count }),
    };
    let n = tables.len();
    let mut s = finish(&m.resolved, opts, tables, &ctx, provenance, &pool, t0)?;
    s.reused = n;
    if let Some(note) = lock_note {
        s.notes.insert(0, note);
    }
    Ok((s, m.resolved))
}

/// At most [`MAX_JOBS`] worker threads.
fn check_jobs(jobs: usize) -> Result<(), Error> {
    if jobs > MAX_JOBS {
        return Err(Error::Other(format!(
            "jobs: must be at most {MAX_JOBS}, got {jobs}"
        )));
    }
    Ok(())
}

/// Runs one unit: its point's job with its seed; tables prefixed with its seed (when seeds are
/// swept) and sweep values.
fn run_unit(
    res: &Resolved,
    unit: &Unit,
    progress: bool,
) -> Result<(Tables, Vec<(String, f64)>), Error> {
    let point = &res.points[unit.point];
    let ctx = RunContext::new(unit.seed, res.quick, progress);
    let mut label = match res.seeds {
        Some(_) => format!("run seed {}", unit.seed),
        None => "run".to_string(),
    };
    if !point.values.is_empty() {
        label = format!("{label} point {}", unit.point);
    }
    let tables = ctx.stage(&label, || point.job.run(&ctx))?;
    let mut prefix: Vec<(String, Cell)> = Vec::new();
    if res.seeds.is_some() {
        prefix.push(("seed".into(), Cell::I(unit.seed as i64)));
    }
    prefix.extend(point.values.iter().map(|(k, v)| (k.clone(), Cell::from(v))));
    let tables = Tables(
        tables
            .0
            .into_iter()
            .map(|(name, t)| (name, t.with_prefix(&prefix)))
            .collect(),
    );
    Ok((tables, ctx.stages()))
}

/// `run.json`'s record of the emulator nets a run loaded from the cache or trained.
fn net_usage_json(u: crate::emulator::cache::NetUsage) -> serde_json::Value {
    serde_json::json!({
        "loaded_from_cache": u.loaded,
        "cached_training_seconds": u.loaded_train_s,
        "trained": u.trained,
        "training_seconds": u.trained_s,
    })
}

/// Where the results came from, for `run.json`.
struct Provenance {
    git_revision: Option<String>,
    git_dirty: Option<bool>,
    extra: serde_json::Value,
}

/// Concatenates the units' tables (in unit order), writes them, the per-seed tables and seed
/// summary when seeds are swept, figures and `run.json`: between the folder's `INCOMPLETE`
/// marker, written first, and its removal, last ([`super::folder`]). The tables, summary and
/// figure of seeds an earlier run had and this one has not are removed
/// ([`seeds::remove_stale_outputs`]).
fn finish(
    res: &Resolved,
    opts: &RunOptions,
    units: Vec<Tables>,
    ctx: &RunContext,
    provenance: Provenance,
    pool: &rayon::ThreadPool,
    t0: Clock,
) -> Result<RunSummary, Error> {
    let mut merged: Vec<(String, Table)> = Vec::new();
    for tables in units {
        for (name, t) in tables.0 {
            match merged.iter_mut().find(|(n, _)| *n == name) {
                Some((_, acc)) => acc
                    .append(&t)
                    .map_err(|e| Error::Other(format!("table {name}: {e}")))?,
                None => merged.push((name, t)),
            }
        }
    }
    let dir = opts.out.join(&res.id);
    mark_incomplete(&dir)?;
    let mut notes = Vec::new();
    let keep = res.seeds.clone().unwrap_or_default();
    let stale = seeds::remove_stale_outputs(&dir, &opts.figures, &res.id, &keep)?;
    if !stale.is_empty() {
        let named: Vec<String> = stale
            .iter()
            .filter(|p| !p.parent().is_some_and(|d| stale.iter().any(|s| s == d)))
            .map(|p| rel_name(&opts.out, &opts.figures, p))
            .collect();
        notes.push(format!(
            "removed {} (an earlier run's results of seeds this run does not have)",
            named.join(", ")
        ));
    }
    let mut files = Vec::new();
    let tables = Tables(merged);
    // With swept seeds, figures (like the report) show the first seed.
    let mut figure_tables = None;
    let axes: Vec<String> = res.points[0]
        .values
        .iter()
        .map(|(k, _)| k.clone())
        .collect();
    ctx.stage("write tables", || -> Result<(), Error> {
        for (name, t) in &tables.0 {
            files.extend(write_table(&dir, name, t)?);
        }
        if let Some(seeds) = &res.seeds {
            for &seed in seeds {
                let one = seeds::one_seed(&tables, seed);
                let seed_dir = dir.join("seeds").join(seed.to_string());
                for (name, t) in &one.0 {
                    files.extend(write_table(&seed_dir, name, t)?);
                }
                figure_tables.get_or_insert(one);
            }
            let summary = seeds::seed_summary(&tables, seeds, &axes);
            files.extend(write_table(&dir, seeds::SUMMARY, &summary)?);
        }
        Ok(())
    })?;
    let sink = FigureSink {
        dir: opts.figures.clone(),
        id: res.id.clone(),
    };
    let figs = ctx.stage("figures", || {
        pool.install(|| {
            res.family
                .figures(&sink, figure_tables.as_ref().unwrap_or(&tables))
        })
    })?;
    files.extend(figs);
    if res.seeds.is_some() {
        let metrics = res.family.seed_metrics();
        if let Some(fig) = seeds::seed_figure(&tables, &axes, metrics) {
            files.extend(ctx.stage("seed figure", || sink.draw("seeds", &fig))?);
        }
    }
    // The verdict's checks with intervals, as the report will judge them from these tables
    // (the first seed's where seeds are swept and judged one by one). A table the report
    // cannot read yet draws nothing here; the report says why.
    let judged = match (&res.seeds, res.family.seeds_pooled()) {
        (Some(seeds), false) => seeds
            .first()
            .map_or(dir.clone(), |s| dir.join("seeds").join(s.to_string())),
        _ => dir.clone(),
    };
    if let Ok(Some(rule)) = res.family.report(&judged).map(|f| f.rule) {
        files.extend(ctx.stage("checks figure", || {
            super::report::checks_figure(&sink, &rule)
        })?);
    }
    let seconds = t0.wall_seconds();
    let stages: serde_json::Map<String, serde_json::Value> = ctx
        .stages()
        .into_iter()
        .map(|(k, v)| (k, serde_json::json!(v)))
        .collect();
    let mut meta = serde_json::json!({
        "id": res.id,
        "seed": res.seed,
        "spec": res.to_json(),
        "crate_version": env!("CARGO_PKG_VERSION"),
        "git_revision": provenance.git_revision,
        "git_dirty": provenance.git_dirty,
        "threads": opts.jobs.max(1),
        "seconds_per_stage": stages,
        "seconds_total": seconds,
        "cpu_seconds": t0.cpu_seconds(),
        "emulator_nets": net_usage_json(crate::emulator::cache::take_usage()),
        "files": files.iter().map(|f| rel_name(&opts.out, &opts.figures, f)).collect::<Vec<_>>(),
    });
    if let (Some(m), Some(extra)) = (meta.as_object_mut(), provenance.extra.as_object()) {
        for (k, v) in extra {
            m.insert(k.clone(), v.clone());
        }
    }
    let run_json = dir.join("run.json");
    let text = serde_json::to_string_pretty(&meta).map_err(|e| Error::Other(e.to_string()))?;
    atomic_write(&run_json, text.as_bytes())?;
    files.push(run_json);
    mark_complete(&dir)?;
    Ok(RunSummary {
        id: res.id.clone(),
        dir,
        files,
        seconds,
        computed: 0,
        reused: 0,
        notes,
    })
}

fn rel_name(out: &Path, figures: &Path, f: &Path) -> String {
    f.strip_prefix(out)
        .or_else(|_| f.strip_prefix(figures))
        .unwrap_or(f)
        .display()
        .to_string()
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::atomic::{AtomicUsize, Ordering};

    #[test]
    fn one_core_each_runs_every_item_once_in_order_on_one_thread_and_no_more_at_once() {
        for lanes in [1, 2, 3] {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(lanes)
                .build()
                .unwrap();
            let (running, most) = (AtomicUsize::new(0), AtomicUsize::new(0));
            let items: Vec<u64> = (0..12).collect();
            let out = pool
                .install(|| {
                    one_core_each(&items, |&i| {
                        let now = running.fetch_add(1, Ordering::SeqCst) + 1;
                        most.fetch_max(now, Ordering::SeqCst);
                        // Inside, rayon sees one thread: a par_iter stays on this core.
                        let threads = rayon::current_num_threads();
                        std::thread::sleep(std::time::Duration::from_millis(5));
                        running.fetch_sub(1, Ordering::SeqCst);
                        (i * i, threads)
                    })
                })
                .unwrap();
            let squares: Vec<u64> = out.iter().map(|o| o.0).collect();
            assert_eq!(squares, items.iter().map(|i| i * i).collect::<Vec<_>>());
            assert!(out.iter().all(|o| o.1 == 1), "one thread each");
            assert!(most.into_inner() <= lanes, "at most {lanes} at once");
        }
    }

    #[test]
    fn the_process_cpu_clock_advances_while_busy() {
        if process_cpu_seconds().is_none() {
            return; // no /proc here: nothing to read (the run.json field is null)
        }
        let clock = Clock::start();
        let mut x = 1.0f64;
        // Busy until the clock (10 ms ticks) has moved by 50 ms; a clock that never moves
        // fails after a minute of wall time.
        while clock.cpu_seconds().unwrap() < 0.05 {
            assert!(clock.wall_seconds() < 60.0, "CPU clock stuck");
            for _ in 0..10_000 {
                x = std::hint::black_box(x.sqrt() + 1.0);
            }
        }
        assert!(clock.cpu_seconds().unwrap() >= 0.05);
    }
}
