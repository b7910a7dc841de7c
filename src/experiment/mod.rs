//! # Experiments as data
//!
//! An experiment file (`experiments/<id>.toml`, see [`spec`]) names a *family* — the code that
//! knows how to run that kind of experiment — and gives its parameters. The pipeline is
//!
//! 1. [`spec::SpecFile::load`]: TOML → raw serde types, with source positions;
//! 2. [`resolve::resolve`]: `[quick]` and `--set` overrides, sweep expansion, and each family's
//!    typed, validated parameters (errors name file, line and key; nothing has run yet);
//! 3. [`runner::run`]: each unit's (sweep point, times seed when seeds are swept) [`Job`]
//!    produces [`output::Tables`]; the runner prefixes seed and sweep values, writes CSV +
//!    Parquet atomically, asks the family for figures and writes `run.json`; [`shard`] keeps
//!    units for `--resume`, runs `--shard I/N` and merges shards, [`seeds`] aggregates seeds;
//! 4. [`report`]: `REPORT.md`, each family's section read back from its CSVs.
//!
//! [`diff`] compares two results folders (`motionlab diff`): tables, cells and verdicts.
//!
//! This module is the harness only: it runs whatever [`Registry`] it is handed and names no
//! family. The families live in [`crate::families`], one folder per paper, and
//! [`crate::families::registry`] lists them; `main.rs` hands that registry to [`resolve::resolve`]
//! and [`runner::merge`]. Families never write files themselves: jobs return tables, figure
//! functions receive them. To add an experiment family, implement [`Experiment`] (and [`Job`]
//! for its parameters) in a new file there and list it in [`crate::families`].

pub mod diff;
pub mod folder;
pub mod output;
pub mod plot;
pub mod report;
pub mod resolve;
pub mod rows;
pub mod rule;
pub mod runner;
pub mod seeds;
pub mod shard;
pub mod spec;
pub mod stats;

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use output::Tables;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use resolve::ParamError;
use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::time::Instant;

/// Errors of running experiments.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// A bad experiment file or override.
    #[error(transparent)]
    Spec(#[from] spec::SpecError),
    /// Reading or writing a file failed.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// A result table that is not whole (a row cut short, a cell that is not a number).
    #[error("{}:{line}: {message}", path.display())]
    Table {
        /// The file.
        path: PathBuf,
        /// 1-based line.
        line: usize,
        /// What is wrong.
        message: String,
    },
    /// polars failed to build, write or read a table.
    #[error("table: {0}")]
    Polars(String),
    /// plotters failed to draw.
    #[error("figure {path}: {message}")]
    Plot {
        /// The figure.
        path: String,
        /// The cause.
        message: String,
    },
    /// A simulation blew up.
    #[error(transparent)]
    BlowUp(#[from] crate::physics::BlowUp),
    /// Anything else a family reports.
    #[error("{0}")]
    Other(String),
}

/// An experiment family: parses its parameters into a [`Job`], draws its figures and writes its
/// report section.
pub trait Experiment: Sync {
    /// Family name, the `experiment = "…"` of a spec.
    fn kind(&self) -> &'static str;
    /// Checks raw `[params]` (after overrides) and returns the typed job.
    fn resolve(&self, params: &toml::Value) -> Result<Box<dyn Job>, ParamError>;
    /// Draws figures from the tables of a run; returns the files written.
    fn figures(&self, fig: &plot::FigureSink, tables: &Tables) -> Result<Vec<PathBuf>, Error>;
    /// The report section, computed from the CSVs in `dir` (the experiment's result folder).
    fn report(&self, dir: &Path) -> Result<report::Findings, Error>;
    /// An implementation check (lattice counts, integrator orders, projection accuracy), not a
    /// reproduction of a paper's claim: the report's summary lists these apart.
    fn is_check(&self) -> bool {
        false
    }
    /// An experiment beyond the papers (its claim is ours, not a paper's): the report's summary
    /// lists these apart and does not count them among the reproduced claims.
    fn is_beyond(&self) -> bool {
        false
    }
    /// Results plotted over seeds (mean and spread) in `<id>_seeds` when seeds are swept.
    fn seed_metrics(&self) -> &'static [seeds::SeedMetric] {
        &[]
    }
    /// Whether its verdict is a judgement over seeds (see [`Family::SEEDS_POOLED`]).
    fn seeds_pooled(&self) -> bool {
        false
    }
    /// One-line captions of the figures and animations it draws, by name (the file name
    /// `<id>_<name>.png|gif` without the id and extension); the report prints each under its
    /// figure.
    fn captions(&self) -> &'static [(&'static str, &'static str)] {
        &[]
    }
}

/// What a family file implements: its name, its typed parameters (which run as the [`Job`])
/// and its figures and report section; every `Family` is an [`Experiment`].
pub trait Family: Sync {
    /// Family name, the `experiment = "…"` of a spec.
    const KIND: &'static str;
    /// The `[params]` table, deserialized with unknown keys rejected and then validated.
    type Params: serde::de::DeserializeOwned + resolve::Validate + Job + 'static;
    /// Draws figures from the tables of a run; returns the files written.
    fn figures(&self, fig: &plot::FigureSink, tables: &Tables) -> Result<Vec<PathBuf>, Error>;
    /// The report section, computed from the CSVs in `dir` (the experiment's result folder).
    fn report(&self, dir: &Path) -> Result<report::Findings, Error>;
    /// Whether this family checks our implementation rather than reproducing a paper's claim.
    const CHECK: bool = false;
    /// Whether its claim is ours, beyond the papers (listed apart in the report's summary).
    const BEYOND: bool = false;
    /// Results plotted over seeds (mean and spread) in the `<id>_seeds` figure when seeds are
    /// swept (`--seeds K` or a `seeds` sweep axis); none by default.
    const SEED_METRICS: &'static [seeds::SeedMetric] = &[];
    /// Its verdict is a judgement over seeds (e.g. a setting's mean against the seed spread):
    /// with swept seeds its report reads the experiment's folder, every seed's rows at once,
    /// instead of the first seed's, and the report gives no verdict per seed.
    const SEEDS_POOLED: bool = false;
    /// One-line captions of its figures and animations, by name (`<id>_<name>.png|gif`
    /// without the id and extension), printed under each in the report.
    const CAPTIONS: &'static [(&'static str, &'static str)] = &[];
}

impl<F: Family> Experiment for F {
    fn is_check(&self) -> bool {
        F::CHECK
    }

    fn seed_metrics(&self) -> &'static [seeds::SeedMetric] {
        F::SEED_METRICS
    }

    fn seeds_pooled(&self) -> bool {
        F::SEEDS_POOLED
    }

    fn captions(&self) -> &'static [(&'static str, &'static str)] {
        F::CAPTIONS
    }

    fn is_beyond(&self) -> bool {
        F::BEYOND
    }

    fn kind(&self) -> &'static str {
        F::KIND
    }

    fn resolve(&self, params: &toml::Value) -> Result<Box<dyn Job>, ParamError> {
        resolve::typed_job::<F::Params>(params)
    }

    fn figures(&self, fig: &plot::FigureSink, tables: &Tables) -> Result<Vec<PathBuf>, Error> {
        Family::figures(self, fig, tables)
    }

    fn report(&self, dir: &Path) -> Result<report::Findings, Error> {
        Family::report(self, dir)
    }
}

/// The experiment families the harness can run, handed to it from the top (`main.rs`, or a
/// library user with families of their own): the harness never names a family.
#[derive(Clone, Copy)]
pub struct Registry {
    families: &'static [&'static dyn Experiment],
}

impl Registry {
    /// A registry of `families`, listed in that order in unknown-family errors.
    pub const fn new(families: &'static [&'static dyn Experiment]) -> Self {
        Self { families }
    }

    /// Every family.
    pub fn families(&self) -> &'static [&'static dyn Experiment] {
        self.families
    }

    /// The family called `kind`.
    pub fn find(&self, kind: &str) -> Option<&'static dyn Experiment> {
        self.families.iter().copied().find(|f| f.kind() == kind)
    }
}

/// A typed, validated experiment point that can run.
pub trait Job: Send + Sync {
    /// The parameters as JSON (for `run.json`).
    fn params_json(&self) -> serde_json::Value;
    /// Runs and returns the named tables. Uses `ctx` for randomness, progress and timing.
    fn run(&self, ctx: &RunContext) -> Result<Tables, Error>;
}

/// What a running job may use: its seed, quick flag, progress bars and stage timer.
pub struct RunContext {
    /// Root seed.
    pub seed: u64,
    /// Whether budgets are scaled down.
    pub quick: bool,
    show_progress: bool,
    stages: Mutex<Vec<(String, f64)>>,
}

pub use crate::seed::mix_seed;

impl RunContext {
    /// A context; progress bars are drawn only when `show_progress` and stderr is a terminal.
    pub fn new(seed: u64, quick: bool, show_progress: bool) -> Self {
        Self {
            seed,
            quick,
            show_progress,
            stages: Mutex::new(Vec::new()),
        }
    }

    /// An independent random stream: same `(seed, stream)`, same numbers, on any thread.
    pub fn rng(&self, stream: u64) -> ChaCha8Rng {
        ChaCha8Rng::seed_from_u64(mix_seed(self.seed, stream))
    }

    /// A progress bar of `len` steps, drawn on stderr; hidden when stdout or stderr is not a
    /// terminal.
    pub fn progress(&self, len: u64, message: &str) -> ProgressBar {
        use std::io::IsTerminal;
        let pb = ProgressBar::new(len);
        let tty = std::io::stdout().is_terminal() && std::io::stderr().is_terminal();
        if !(self.show_progress && tty) {
            pb.set_draw_target(ProgressDrawTarget::hidden());
        }
        pb.set_style(
            ProgressStyle::with_template(
                "{msg:>28} [{bar:30}] {pos}/{len} {elapsed_precise} eta {eta}",
            )
            .unwrap_or_else(|_| ProgressStyle::default_bar())
            .progress_chars("=> "),
        );
        pb.set_message(message.to_string());
        pb
    }

    /// Runs `f` as a named stage and records its wall time.
    pub fn stage<T>(&self, name: &str, f: impl FnOnce() -> T) -> T {
        let t0 = Instant::now();
        let out = f();
        let dt = t0.elapsed().as_secs_f64();
        self.stages
            .lock()
            .expect("stage timer poisoned")
            .push((name.to_string(), dt));
        out
    }

    /// Records a stage timed elsewhere (e.g. a unit run in its own context).
    pub fn record(&self, name: &str, seconds: f64) {
        self.stages
            .lock()
            .expect("stage timer poisoned")
            .push((name.to_string(), seconds));
    }

    /// Seconds per stage so far.
    pub fn stages(&self) -> Vec<(String, f64)> {
        self.stages.lock().expect("stage timer poisoned").clone()
    }
}

/// Maps a parameter error into the job's error type (for family code).
pub fn other(e: impl std::fmt::Display) -> Error {
    Error::Other(e.to_string())
}
