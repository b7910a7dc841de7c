//! The `motionlab` command line.

use anyhow::{anyhow, bail, Context, Result};
use clap::{Args, Parser, Subcommand};
use motionlab::experiment::diff::{diff, Options as DiffOptions};
use motionlab::experiment::folder::check_complete;
use motionlab::experiment::output::remove_stale_temps;
use motionlab::experiment::report::write_report;
use motionlab::experiment::resolve::{resolve, ResolveOptions, Resolved};
use motionlab::experiment::runner::{merge, run, Clock, RunOptions, MAX_JOBS};
use motionlab::experiment::shard::Shard;
use motionlab::experiment::spec::SpecFile;
use motionlab::families;
use motionlab::families::na::table1_structure::{
    build_spec, table1_emulator, Params as Table1Params, EMULATOR_NAMES,
};
use motionlab::physics::{self, IntegratorKind, Model, Ode};
use motionlab::verbs::{self, Controls};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;

/// Reproduces NeuroAnimator, mass-spring motion synthesis and linear Bellman combination.
///
/// Experiments are TOML files in `experiments/` (one per experiment id). `run` runs one,
/// `reproduce` runs them all and writes `results/REPORT.md` with the papers' numbers beside
/// ours. Tables go to `results/<id>/` as CSV and Parquet, figures to `paper_figures/`.
///
/// Only a full-scale `reproduce` writes to `results/` and `paper_figures/` by default (the
/// committed outputs); `--quick` runs default to `quick/results/` and `quick/paper_figures/`,
/// and `run` to `runs/results/` and `runs/paper_figures/`.
///
/// Environment: `MOTIONLAB_CACHE=DIR` holds the trained emulators (default
/// `target/motionlab-cache`); `MOTIONLAB_SIMD=scalar|avx2|avx512` caps the vector instructions
/// the dispatched kernels use (every level gives the same bits; for comparing them).
#[derive(Parser)]
#[command(name = "motionlab", version, about, long_about)]
struct Cli {
    /// Folder of experiment files (default: ./experiments, else the one shipped with the crate).
    #[arg(long, global = true, value_name = "DIR")]
    experiments: Option<PathBuf>,
    #[command(subcommand)]
    command: Command,
}

#[derive(Args, Clone)]
struct Outputs {
    /// Results root: tables go to <OUT>/<id>/. Default: `results` for a full `reproduce`,
    /// `quick/results` with --quick, `runs/results` for `run`.
    #[arg(long, value_name = "DIR")]
    out: Option<PathBuf>,
    /// Figures folder. Default: `paper_figures` for a full `reproduce`, `quick/paper_figures`
    /// with --quick, `runs/paper_figures` for `run`.
    #[arg(long, value_name = "DIR")]
    figures: Option<PathBuf>,
    /// Worker threads (results are identical for any value), 1 to 1024. Default: all cores.
    #[arg(long, value_name = "N")]
    jobs: Option<usize>,
    /// Scale budgets down so each experiment finishes in seconds (applies each file's [quick]).
    #[arg(long)]
    quick: bool,
}

#[derive(Subcommand)]
enum Command {
    /// One line per experiment: id, paper item, title.
    List,
    /// Run one experiment by id or path to its TOML file.
    ///
    /// Holds <OUT>/<id>/.motionlab.lock while it writes (a shard: its shard folder's), and
    /// refuses while another run holds it; marks <OUT>/<id>/INCOMPLETE until run.json is
    /// written, and `reproduce`, `merge` and the report refuse a folder so marked until it is
    /// rerun.
    Run {
        /// Experiment id (e.g. physics_validation) or path to a .toml file.
        target: String,
        #[command(flatten)]
        outputs: Outputs,
        /// Replace the file's seed.
        #[arg(long)]
        seed: Option<u64>,
        /// Override a [params] key (dotted for nested keys; VALUE is TOML, e.g. 0.5, [1,2], "rk4").
        /// Repeatable. `seed=N` sets the seed. Overriding a swept key removes that sweep axis.
        #[arg(long = "set", value_name = "KEY=VALUE")]
        sets: Vec<String>,
        /// Run every sweep point with K seeds (the spec's seed, +1, …, +K-1): tables get a
        /// leading `seed` column, each seed's tables go to <OUT>/<id>/seeds/<seed>/ as well, and
        /// seed_summary.csv and the report give mean and spread over seeds. K is at most 1000;
        /// a sweep has at most 10000 points, and points times seeds at most 100000.
        #[arg(long, value_name = "K")]
        seeds: Option<usize>,
        /// Run only the units (sweep points times seeds) whose index is I-1 modulo N, into
        /// <OUT>/<id>/shards/I-of-N/; `motionlab merge` joins the N shards.
        #[arg(long, value_name = "I/N", value_parser = parse_shard)]
        shard: Option<Shard>,
        /// Skip the units whose stored results are complete (a sweep keeps each unit's results
        /// in <OUT>/<id>/units/, a shard in its folder), keyed by a hash of the unit's resolved
        /// spec and the code revision; run the rest.
        #[arg(long)]
        resume: bool,
    },
    /// Merge the shards of `run <ID> --shard I/N` (all N of them, from <OUT>/<id>/shards/) into
    /// the tables, figures and run.json the unsharded run writes. Refuses, writing nothing, when
    /// a shard is missing, unfinished or duplicated, or the shards came from different specs or
    /// revisions.
    Merge {
        /// Experiment id or path to its .toml file (as given to `run`).
        target: String,
        #[command(flatten)]
        outputs: Outputs,
    },
    /// Run every experiment (or --only some), then write <OUT>/REPORT.md.
    Reproduce {
        #[command(flatten)]
        outputs: Outputs,
        /// Comma-separated experiment ids to run (the report still covers every experiment).
        #[arg(long, value_delimiter = ',', value_name = "ID,...")]
        only: Vec<String>,
        /// Run every experiment with K seeds, as `run --seeds K`; each section then reports the
        /// first seed, the verdict of every seed and the mean and spread over seeds (K at most
        /// 1000). An experiment whose file sweeps its own `seeds` keeps those.
        #[arg(long, value_name = "K")]
        seeds: Option<usize>,
    },
    /// Print a model as JSON: state and control names, parameters with units, dt.
    Describe {
        /// Model name (see `motionlab describe --help` for the list).
        #[arg(value_parser = clap::builder::PossibleValuesParser::new(physics::MODEL_NAMES))]
        model: String,
    },
    /// Simulate a model from a start state and write the trajectory as CSV (t, state...).
    ///
    /// Every input is checked before any work: the start state (finite, one value per state
    /// variable), the controls file, --duration and --dt (positive, finite) and the number of
    /// steps, duration / dt, at most 10000000 (MAX_STEPS). Rows are written as they are
    /// computed; with --out, to a temporary file renamed into place when the run succeeds.
    Simulate {
        /// Model name.
        #[arg(value_parser = clap::builder::PossibleValuesParser::new(physics::MODEL_NAMES))]
        model: String,
        /// Start state, comma-separated, in `describe`'s order and units.
        #[arg(
            long,
            value_delimiter = ',',
            allow_hyphen_values = true,
            required = true
        )]
        state: Vec<f64>,
        /// Controls: CSV with column `t` and one column per control (every control of the
        /// model, each once; a UTF-8 byte-order mark is fine), held piecewise-constant (each row
        /// from its t until the next row's t; the first row also before its t). Values must be
        /// finite and at most 1e6 in magnitude (MAX_CONTROL).
        #[arg(long, value_name = "FILE.csv")]
        controls: Option<PathBuf>,
        /// Simulated time in seconds: at most 10000000 (MAX_STEPS) steps of --dt.
        #[arg(long)]
        duration: f64,
        /// Time step in seconds (default: the model's dt).
        #[arg(long)]
        dt: Option<f64>,
        /// Integrator: euler, semi_implicit_euler, rk4, dopri5, rk45.
        #[arg(long, default_value = "rk4")]
        integrator: String,
        /// Output CSV (default: standard output).
        #[arg(long, value_name = "FILE.csv")]
        out: Option<PathBuf>,
    },
    /// Step a trained Table 1 emulator from a start state and write its trajectory as CSV with
    /// `simulate`'s columns (t, state...), one row per super-step, so the two files compare row
    /// by row. The net is built as `na_table1_structure` builds it (its experiment file gives
    /// size, data, training and seed): loaded from the emulator cache (target/motionlab-cache or
    /// $MOTIONLAB_CACHE), or trained now when no experiment has trained it yet.
    ///
    /// Its inputs are checked as `simulate` checks them, before the net is loaded or trained:
    /// the start state, the controls file and --duration, at most 10000000 (MAX_STEPS)
    /// super-steps. Rows are written as they are computed.
    Emulate {
        /// Table 1 net: pendulum_passive, pendulum_active, pendulum_ext, truck, lander, dolphin.
        #[arg(value_parser = clap::builder::PossibleValuesParser::new(EMULATOR_NAMES))]
        net: String,
        /// Physical steps per emulator step N (25, 50 or 100; 50 is Table 1's).
        #[arg(long, default_value_t = 50)]
        steps: usize,
        /// Start state, comma-separated, in `describe`'s order and units for the emulated model
        /// (pendulum_active: pendulum3, pendulum_passive: pendulum3_passive, pendulum_ext:
        /// pendulum3_ext).
        #[arg(
            long,
            value_delimiter = ',',
            allow_hyphen_values = true,
            required = true
        )]
        state: Vec<f64>,
        /// Controls: the same CSV as `simulate`'s, read at each super-step's start and held
        /// (every control of the model, each once; finite, at most 1e6 in magnitude).
        #[arg(long, value_name = "FILE.csv")]
        controls: Option<PathBuf>,
        /// Emulated time in seconds (rounded to whole super-steps; at most 10000000 of them,
        /// MAX_STEPS).
        #[arg(long)]
        duration: f64,
        /// Output CSV (default: standard output).
        #[arg(long, value_name = "FILE.csv")]
        out: Option<PathBuf>,
        /// Use the nets of `reproduce --quick` (the spec's [quick] table): fewer examples,
        /// trained in seconds, less accurate.
        #[arg(long)]
        quick: bool,
    },
    /// Compare two results folders (two revisions' `results/`, a shard merge against a plain
    /// run, a rerun on another machine): experiment folders and CSV tables on one side only, each
    /// shared table's columns, row count and cells beyond the tolerances, and the verdicts of the
    /// two REPORT.md claims tables. Timing columns, run.json and the Parquet twins are not
    /// compared.
    ///
    /// Exits 0 when nothing differs, 1 when something does, 2 on an error (a folder that does
    /// not exist, a file that cannot be read), as `diff` and `cmp` do.
    Diff(DiffArgs),
    /// Throughput of the hot loops.
    Bench {
        /// Print one JSON object of named numbers.
        #[arg(long)]
        json: bool,
        /// Seconds to spend on each metric.
        #[arg(long, default_value_t = 0.5)]
        seconds: f64,
    },
}

#[derive(Args)]
struct DiffArgs {
    /// Folder A (e.g. `results`).
    a: PathBuf,
    /// Folder B, compared against A.
    b: PathBuf,
    /// Relative tolerance of numeric cells: equal within atol + rtol * max(|a|, |b|).
    #[arg(long, default_value = "1e-9", value_name = "R")]
    rtol: f64,
    /// Absolute tolerance of numeric cells.
    #[arg(long, default_value = "1e-12", value_name = "A")]
    atol: f64,
    /// Compare the timing columns too: names ending in `seconds`, `_s` or `seconds_per_pass`, or
    /// starting with `seconds` or `wall` (wall-clock times, which differ on every run).
    #[arg(long)]
    all_columns: bool,
    /// Differing cells shown per table (all are counted).
    #[arg(long, default_value_t = 10, value_name = "N")]
    max_cells: usize,
    /// Print one JSON object with the same content instead of text.
    #[arg(long)]
    json: bool,
}

fn experiments_dir(cli: &Option<PathBuf>) -> PathBuf {
    if let Some(d) = cli {
        return d.clone();
    }
    let local = PathBuf::from("experiments");
    if local.is_dir() {
        local
    } else {
        Path::new(env!("CARGO_MANIFEST_DIR")).join("experiments")
    }
}

/// Experiment files in the order of `TARGETS.md`: NeuroAnimator, mass-spring synthesis, linear
/// Bellman combination, then the rest; alphabetical within each.
fn spec_files(dir: &Path) -> Result<Vec<PathBuf>> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
        .with_context(|| format!("reading experiments folder {}", dir.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|e| e == "toml"))
        .collect();
    let rank = |p: &PathBuf| {
        let stem = p.file_stem().and_then(|s| s.to_str()).unwrap_or("");
        let group = ["na_", "ms_", "lbc_"]
            .iter()
            .position(|g| stem.starts_with(g))
            .unwrap_or(3);
        (group, stem.to_string())
    };
    files.sort_by_key(rank);
    Ok(files)
}

/// Every experiment file of `dir`, resolved (quick or not, with `--seeds`), in report order. An
/// experiment whose file sweeps its own `seeds` axis keeps it under `--seeds` (its seeds are
/// part of its design, as `ms_search_settings`'s are); `run` on such a file with `--seeds` is
/// refused instead, naming both.
fn resolve_all(dir: &Path, quick: bool, seeds: Option<usize>) -> Result<Vec<Resolved>> {
    let mut all = Vec::new();
    for f in spec_files(dir)? {
        let file = SpecFile::load(&f)?;
        let own_seeds = file.raw.sweep.contains_key("seeds");
        all.push(resolve(
            &file,
            &ResolveOptions {
                quick,
                seeds: seeds.filter(|_| !own_seeds),
                ..Default::default()
            },
            &families::registry(),
        )?);
    }
    Ok(all)
}

fn default_jobs() -> usize {
    std::thread::available_parallelism().map_or(1, |n| n.get())
}

impl Outputs {
    /// The results and figures folders: as given, else by what runs. Only a full-scale
    /// `reproduce` (`committed`) defaults to the committed `results/` and `paper_figures/`, so
    /// quick and ad-hoc runs never overwrite them.
    fn folders(&self, committed: bool) -> (PathBuf, PathBuf) {
        let root = if self.quick {
            Some("quick")
        } else if committed {
            None
        } else {
            Some("runs")
        };
        let under =
            |name: &str| root.map_or_else(|| PathBuf::from(name), |r| Path::new(r).join(name));
        (
            self.out.clone().unwrap_or_else(|| under("results")),
            self.figures
                .clone()
                .unwrap_or_else(|| under("paper_figures")),
        )
    }
}

fn run_options(o: &Outputs, committed: bool) -> RunOptions {
    let (out, figures) = o.folders(committed);
    RunOptions {
        out,
        figures,
        jobs: o.jobs.unwrap_or_else(default_jobs),
        progress: true,
        resume: false,
        shard: None,
    }
}

fn parse_shard(text: &str) -> Result<Shard, String> {
    Shard::parse(text)
}

/// The experiment file of `target`: a path to a .toml file, or an id in `exp_dir`.
fn spec_path(exp_dir: &Path, target: &str) -> Result<PathBuf> {
    if target.ends_with(".toml") || Path::new(target).is_file() {
        return Ok(PathBuf::from(target));
    }
    let p = exp_dir.join(format!("{target}.toml"));
    if !p.is_file() {
        bail!(
            "no experiment `{target}` (no file {}); `motionlab list` shows them",
            p.display()
        );
    }
    Ok(p)
}

/// Removes what interrupted runs left half-written in the output folders of the experiments
/// `ids` (temporary files of atomic writes; see `remove_stale_temps`), saying which.
fn remove_leftovers(opts: &RunOptions, ids: &[String]) -> Result<()> {
    for f in remove_stale_temps(&opts.out, &opts.figures, ids)? {
        eprintln!(
            "removed {} (a temporary file left by an interrupted run)",
            f.display()
        );
    }
    Ok(())
}

/// Refuses, before any work, when the folder of one of `ids` in `out` holds a run that did not
/// finish (its `INCOMPLETE` marker): the report would read it.
fn refuse_incomplete<'a>(out: &Path, ids: impl IntoIterator<Item = &'a String>) -> Result<()> {
    for id in ids {
        check_complete(&out.join(id))?;
    }
    Ok(())
}

/// Says on stderr what a run did besides its results (a lock taken over, old seeds removed).
fn say_notes(notes: &[String]) {
    for n in notes {
        eprintln!("{n}");
    }
}

fn check_jobs(o: &Outputs) -> Result<()> {
    if o.jobs == Some(0) {
        bail!("--jobs must be at least 1");
    }
    if let Some(n) = o.jobs.filter(|&n| n > MAX_JOBS) {
        bail!("--jobs must be at most {MAX_JOBS}, got {n}");
    }
    Ok(())
}

/// The error and its causes, joined by ": ", leaving out a cause that the text before it
/// already states (an io error's "(os error N)" would otherwise come twice).
fn error_text(e: &anyhow::Error) -> String {
    let mut text = String::new();
    for cause in e.chain().map(|c| c.to_string()) {
        if text.is_empty() {
            text = cause;
        } else if !text.contains(&cause) {
            text.push_str(": ");
            text.push_str(&cause);
        }
    }
    text
}

/// Writes a line to standard output. A closed pipe (`motionlab list | head -1`) comes back as
/// an io error of kind `BrokenPipe`, which [`main`] treats as a normal end.
fn say(line: impl std::fmt::Display) -> Result<()> {
    writeln!(std::io::stdout().lock(), "{line}")?;
    Ok(())
}

/// Whether `e` is standard output's reader having gone away.
fn broken_pipe(e: &anyhow::Error) -> bool {
    e.chain().any(|c| {
        c.downcast_ref::<std::io::Error>()
            .is_some_and(|io| io.kind() == std::io::ErrorKind::BrokenPipe)
    })
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    // `diff` tells a difference (exit 1) from an error (exit 2), which no other verb does.
    if let Command::Diff(args) = &cli.command {
        return diff_verb(args);
    }
    // The vector-instruction cap, read once at start-up: an unknown value is an error here
    // rather than a warning in the middle of a run.
    if let Err(e) = motionlab::simd::requested() {
        eprintln!("error: {e}");
        return ExitCode::FAILURE;
    }
    let _ = motionlab::simd::level();
    match dispatch(cli) {
        Ok(()) => ExitCode::SUCCESS,
        // The reader of our output stopped reading: not an error of ours.
        Err(e) if broken_pipe(&e) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {}", error_text(&e));
            ExitCode::FAILURE
        }
    }
}

/// Runs `diff`: exit 0 when the folders agree, 1 when they differ, 2 on an error.
fn diff_verb(args: &DiffArgs) -> ExitCode {
    match print_diff(args) {
        Ok(false) => ExitCode::SUCCESS,
        Ok(true) => ExitCode::from(1),
        Err(e) => {
            eprintln!("error: {}", error_text(&e));
            ExitCode::from(2)
        }
    }
}

/// Compares the two folders and prints the result (text, or JSON with `--json`); returns
/// whether they differ. A reader that stops reading early does not change the answer.
fn print_diff(args: &DiffArgs) -> Result<bool> {
    let opts = DiffOptions {
        rtol: args.rtol,
        atol: args.atol,
        all_columns: args.all_columns,
        max_cells: args.max_cells,
    };
    let d = diff(&args.a, &args.b, &opts)?;
    let text = if args.json {
        serde_json::to_string_pretty(&d)?
    } else {
        d.to_string()
    };
    match say(text) {
        Err(e) if !broken_pipe(&e) => Err(e),
        _ => Ok(d.changed),
    }
}

fn dispatch(cli: Cli) -> Result<()> {
    let exp_dir = experiments_dir(&cli.experiments);
    match cli.command {
        Command::List => {
            for f in spec_files(&exp_dir)? {
                let s = SpecFile::load(&f)?;
                say(format!(
                    "{:<26} {:<28} {}",
                    s.raw.id, s.raw.paper_item, s.raw.title
                ))?;
            }
            Ok(())
        }
        Command::Run {
            target,
            outputs,
            seed,
            sets,
            seeds,
            shard,
            resume,
        } => {
            let ropts = ResolveOptions {
                quick: outputs.quick,
                seed,
                sets,
                seeds,
            };
            run_command(&exp_dir, &target, &outputs, ropts, shard, resume)
        }
        Command::Merge { target, outputs } => merge_command(&exp_dir, &target, &outputs),
        Command::Reproduce {
            outputs,
            only,
            seeds,
        } => reproduce_command(&exp_dir, &outputs, &only, seeds),
        Command::Describe { model } => {
            let m =
                physics::model_by_name(&model).ok_or_else(|| anyhow!("unknown model {model}"))?;
            say(serde_json::to_string_pretty(&physics::describe(&*m))?)?;
            Ok(())
        }
        Command::Simulate {
            model,
            state,
            controls,
            duration,
            dt,
            integrator,
            out,
        } => simulate(
            &model,
            &state,
            controls.as_deref(),
            duration,
            dt,
            &integrator,
            out.as_deref(),
        ),
        Command::Emulate {
            net,
            steps,
            state,
            controls,
            duration,
            out,
            quick,
        } => emulate(
            &experiments_dir(&cli.experiments),
            (&net, steps, quick),
            &state,
            controls.as_deref(),
            duration,
            out.as_deref(),
        ),
        Command::Diff(_) => unreachable!("`main` runs `diff` itself, for its own exit codes"),
        Command::Bench { json, seconds } => {
            if !(seconds > 0.0) {
                bail!("--seconds must be > 0");
            }
            let m = motionlab::bench::metrics(seconds);
            if json {
                say(motionlab::bench::to_json(&m))?;
            } else {
                for x in &m {
                    say(format!("{:<45} {:>14.1}", x.name, x.value))?;
                }
            }
            Ok(())
        }
    }
}

/// `run`: one experiment, resolved with `ropts`, optionally one shard of it or resuming.
fn run_command(
    exp_dir: &Path,
    target: &str,
    outputs: &Outputs,
    ropts: ResolveOptions,
    shard: Option<Shard>,
    resume: bool,
) -> Result<()> {
    check_jobs(outputs)?;
    let file = SpecFile::load(&spec_path(exp_dir, target)?)?;
    let res = resolve(&file, &ropts, &families::registry())?;
    let opts = RunOptions {
        resume,
        shard,
        ..run_options(outputs, false)
    };
    remove_leftovers(&opts, std::slice::from_ref(&res.id))?;
    let s = run(&res, &opts)?;
    say_notes(&s.notes);
    let units = if resume || shard.is_some() {
        format!(" ({} units run, {} resumed)", s.computed, s.reused)
    } else {
        String::new()
    };
    eprintln!(
        "{}: {} files in {:.2} s{units} -> {}",
        s.id,
        s.files.len(),
        s.seconds,
        s.dir.display()
    );
    Ok(())
}

/// `merge`: one experiment's shards into its results, then the report over every file.
fn merge_command(exp_dir: &Path, target: &str, outputs: &Outputs) -> Result<()> {
    check_jobs(outputs)?;
    let file = SpecFile::load(&spec_path(exp_dir, target)?)?;
    let opts = run_options(outputs, false);
    // The report covers every experiment file, as `reproduce` writes it; a bad file
    // stops everything before any work.
    let mut all = resolve_all(exp_dir, outputs.quick, None)?;
    let others = all.iter().map(|r| &r.id).filter(|id| **id != file.raw.id);
    refuse_incomplete(&opts.out, others)?;
    let mut ids: Vec<String> = all.iter().map(|r| r.id.clone()).collect();
    ids.push(file.raw.id.clone());
    remove_leftovers(&opts, &ids)?;
    let (s, merged) = merge(&file, &opts, &families::registry())?;
    say_notes(&s.notes);
    eprintln!(
        "{}: merged {} units, {} files in {:.2} s -> {}",
        s.id,
        s.reused,
        s.files.len(),
        s.seconds,
        s.dir.display()
    );
    match all.iter().position(|r| r.id == merged.id) {
        Some(i) => all[i] = merged,
        None => all.push(merged),
    }
    let report = write_report(&opts.out, &opts.figures, &all)?;
    eprintln!("report: {}", report.display());
    Ok(())
}

/// `reproduce`: every experiment (or those in `only`) run, then the report.
fn reproduce_command(
    exp_dir: &Path,
    outputs: &Outputs,
    only: &[String],
    seeds: Option<usize>,
) -> Result<()> {
    check_jobs(outputs)?;
    let t0 = Instant::now();
    // Resolve every file first: a bad file stops everything before any work.
    let all = resolve_all(exp_dir, outputs.quick, seeds)?;
    for id in only {
        if !all.iter().any(|r| r.id == *id) {
            bail!("--only: no experiment `{id}`");
        }
    }
    let opts = run_options(outputs, true);
    // The report reads the experiments not rerun as they are.
    let kept = all
        .iter()
        .map(|r| &r.id)
        .filter(|id| !only.is_empty() && !only.contains(id));
    refuse_incomplete(&opts.out, kept)?;
    let ids: Vec<String> = all.iter().map(|r| r.id.clone()).collect();
    remove_leftovers(&opts, &ids)?;
    let chosen: Vec<&Resolved> = all
        .iter()
        .filter(|r| only.is_empty() || only.contains(&r.id))
        .collect();
    // What each took in the last run here (its run.json, before this run replaces it): the
    // estimate of what is left.
    let last: Vec<Option<LastRun>> = chosen
        .iter()
        .map(|r| last_run(&opts.out.join(&r.id)))
        .collect();
    for (k, r) in chosen.iter().enumerate() {
        eprintln!(
            "[{}/{}] {}{}",
            k + 1,
            chosen.len(),
            r.id,
            time_left(&last[k..], t0.elapsed().as_secs_f64())
        );
        let clock = Clock::start();
        let s = run(r, &opts).with_context(|| format!("experiment {}", r.id))?;
        say_notes(&s.notes);
        let cpu = clock
            .cpu_seconds()
            .map(|c| format!(" ({:.0}% of a core)", 100.0 * c / s.seconds.max(1e-9)))
            .unwrap_or_default();
        eprintln!(
            "{:<26} {:>8.2} s{cpu}  {} files",
            s.id,
            s.seconds,
            s.files.len()
        );
    }
    let report = write_report(&opts.out, &opts.figures, &all)?;
    eprintln!(
        "report: {} (total {:.1} s)",
        report.display(),
        t0.elapsed().as_secs_f64()
    );
    Ok(())
}

/// What an experiment's last run here took, from its run.json: the wall seconds, and how many
/// emulator nets it trained itself because the cache lacked them (its time includes theirs).
#[derive(Debug, Clone, Copy, PartialEq)]
struct LastRun {
    seconds: f64,
    trained: u64,
}

/// The [`LastRun`] of the run.json in `dir`, if there is a readable one.
fn last_run(dir: &Path) -> Option<LastRun> {
    let text = std::fs::read_to_string(dir.join("run.json")).ok()?;
    let v: serde_json::Value = serde_json::from_str(&text).ok()?;
    Some(LastRun {
        seconds: v.get("seconds_total")?.as_f64()?,
        trained: v
            .pointer("/emulator_nets/trained")
            .and_then(serde_json::Value::as_u64)
            .unwrap_or(0),
    })
}

/// The progress line's estimate: the last run's times of the experiments still to run (`left`,
/// this one first), or which have none; `elapsed` seconds so far. Where those runs trained
/// nets, the line says so: a run that finds them cached takes less.
fn time_left(left: &[Option<LastRun>], elapsed: f64) -> String {
    let minutes = |s: f64| format!("{:.1} min", s / 60.0);
    let known: f64 = left.iter().flatten().map(|r| r.seconds).sum();
    let unknown = left.iter().filter(|s| s.is_none()).count();
    let trained: u64 = left.iter().flatten().map(|r| r.trained).sum();
    let this = match left.first() {
        Some(Some(r)) if r.trained > 0 => format!(
            "took {:.0} s last time, training {} emulator nets; ",
            r.seconds, r.trained
        ),
        Some(Some(r)) => format!("took {:.0} s last time; ", r.seconds),
        _ => String::new(),
    };
    let trained = if trained > 0 {
        format!(" (the last runs trained {trained} nets: less where they are cached now)")
    } else {
        String::new()
    };
    let rest = if unknown == 0 {
        format!("about {} left in all{trained}", minutes(known))
    } else if unknown == left.len() {
        "no past run here to estimate from".to_string()
    } else {
        format!(
            "about {} left for the {} with a past run here{trained}, and {unknown} more",
            minutes(known),
            left.len() - unknown
        )
    };
    format!(" ({this}{rest}; {} so far)", minutes(elapsed))
}

fn emulate(
    experiments: &Path,
    (net, steps, quick): (&str, usize, bool),
    state: &[f64],
    controls: Option<&Path>,
    duration: f64,
    out: Option<&Path>,
) -> Result<()> {
    if steps == 0 {
        bail!("--steps must be >= 1");
    }
    // Every input is checked as `simulate` checks it, before the net is loaded or trained.
    let physics_name = match net {
        "dolphin" => "dolphin",
        other => motionlab::emulator::catalog::NetModel::ALL
            .iter()
            .find(|m| m.name() == other)
            .map(|m| m.physics_name())
            .ok_or_else(|| anyhow!("unknown net {other}"))?,
    };
    let m = physics::model_by_name(physics_name)
        .ok_or_else(|| anyhow!("unknown model {physics_name}"))?;
    let names = m.state_names();
    let path = experiments.join("na_table1_structure.toml");
    let file = SpecFile::load(&path)?;
    let mut table = file.raw.params.clone();
    if quick {
        motionlab::experiment::resolve::merge(&mut table, &file.raw.quick);
    }
    let params: Table1Params = toml::Value::Table(table)
        .try_into()
        .map_err(|e| anyhow!("{}: [params]: {e}", path.display()))?;
    motionlab::experiment::resolve::Validate::validate(&params)
        .map_err(|e| anyhow!("{}: {e}", path.display()))?;
    let label = format!("{net} emulates {physics_name}, which");
    let super_dt = table1_super_dt(&params, file.raw.seed, net, steps)?;
    let check = |dt: f64| {
        verbs::check_run(&label, &names, state, duration, "the emulator's step", dt)
            .map(|n| n.max(1))
    };
    check(super_dt)?;
    let schedule = match controls {
        Some(p) => Some(Controls::load(p, &m.control_names())?),
        None => None,
    };
    eprintln!("{net} N{steps}: loading from the emulator cache, or training (may take minutes)…");
    let e = table1_emulator(&params, file.raw.seed, net, steps)?;
    let n = check(e.dt())?;
    verbs::write_csv(out, |rows| {
        rows.header(&names)?;
        verbs::emulate_rows(&e, state, n, schedule.as_ref(), rows)
    })?;
    Ok(())
}

/// The super-step Δt = N δt of Table 1's net `net` at N = `steps`, as [`table1_emulator`] will
/// build it, known before the net is loaded or trained.
fn table1_super_dt(params: &Table1Params, seed: u64, net: &str, steps: usize) -> Result<f64> {
    if net == "dolphin" {
        let d = params
            .dolphin
            .as_ref()
            .ok_or_else(|| anyhow!("the Table 1 spec has no [params.dolphin]"))?;
        return Ok(d.spec(seed, steps, params.example_scale).super_dt());
    }
    let spec = params
        .nets
        .iter()
        .find(|n| n.model.name() == net)
        .ok_or_else(|| {
            anyhow!(
                "no net `{net}` in the Table 1 spec (nets: {})",
                EMULATOR_NAMES.join(", ")
            )
        })?;
    Ok(build_spec(seed, spec, steps, params.example_scale, &params.training).super_dt())
}

fn simulate(
    model: &str,
    state: &[f64],
    controls: Option<&Path>,
    duration: f64,
    dt: Option<f64>,
    integrator: &str,
    out: Option<&Path>,
) -> Result<()> {
    let m: Box<dyn Ode> =
        physics::model_by_name(model).ok_or_else(|| anyhow!("unknown model {model}"))?;
    let names = m.state_names();
    let dt = dt.unwrap_or_else(|| m.default_dt());
    let steps = verbs::check_run(model, &names, state, duration, "--dt", dt)?;
    let kind = IntegratorKind::from_name(integrator).ok_or_else(|| {
        anyhow!(
            "--integrator: unknown `{integrator}` (euler, semi_implicit_euler, rk4, dopri5, rk45)"
        )
    })?;
    let schedule = match controls {
        Some(p) => Some(Controls::load(p, &m.control_names())?),
        None => None,
    };
    let mut sim = physics::Simulator::new(m, kind);
    verbs::write_csv(out, |rows| {
        rows.header(&names)?;
        verbs::simulate_rows(&mut sim, state, dt, steps, schedule.as_ref(), rows)
    })?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_estimate_sums_the_last_runs_and_says_which_trained_nets() {
        let warm = |seconds| {
            Some(LastRun {
                seconds,
                trained: 0,
            })
        };
        assert_eq!(
            time_left(&[warm(60.0), warm(120.0)], 30.0),
            " (took 60 s last time; about 3.0 min left in all; 0.5 min so far)"
        );
        let cold = Some(LastRun {
            seconds: 600.0,
            trained: 12,
        });
        assert_eq!(
            time_left(&[cold, warm(60.0), None], 0.0),
            " (took 600 s last time, training 12 emulator nets; about 11.0 min left for the 2 \
             with a past run here (the last runs trained 12 nets: less where they are cached \
             now), and 1 more; 0.0 min so far)"
        );
        assert_eq!(
            time_left(&[None], 6.0),
            " (no past run here to estimate from; 0.1 min so far)"
        );
    }

    #[test]
    fn a_run_json_without_nets_trained_none() {
        let dir = std::env::temp_dir().join(format!("motionlab-last-run-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(dir.join("run.json"), r#"{"seconds_total": 4.5}"#).unwrap();
        assert_eq!(
            last_run(&dir),
            Some(LastRun {
                seconds: 4.5,
                trained: 0
            })
        );
        std::fs::write(
            dir.join("run.json"),
            r#"{"seconds_total": 9.0, "emulator_nets": {"trained": 3}}"#,
        )
        .unwrap();
        assert_eq!(last_run(&dir).map(|r| r.trained), Some(3));
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
