//! `na_baselines_swim` (NeuroAnimator §6): learning the dolphin's swim controller by
//! backpropagation through time against gradient-free searches.
//!
//! The paper: simulated annealing and the simplex method need 500–3,500 iterations (over an
//! hour) to learn a controller; backpropagation through time through the emulator needs about
//! 20 (under 10 s). Here every method searches the same 120 normalized knots (20 per muscle,
//! 6 muscles, [−1, 1]) of the swim task of [`super::swim`] from the same random start
//! (half-width `init_spread`, the full range in the spec; the first start of
//! `na_fig13_control`'s dolphin) and minimizes the same objective J = effort − distance swum;
//! every run is scored at its best-so-far iterate (lowest J on its substrate), as
//! `na_fig13_control` scores its runs:
//!
//! - `bptt_momentum`, `bptt_plain`: descent through the hierarchy's global net
//!   ([`crate::control::search::bptt_search`]), η in units of 1/λ (λ: the largest Hessian
//!   eigenvalue magnitude of J at the start, whose power-iteration cost is charged to both);
//! - `annealing`, `simplex`, `hill_climbing` ([`crate::control::search`]): on the emulator
//!   (the same global net rollout) **and** on the physical simulator (the knots replayed on
//!   the mass-spring dolphin, 50 physical steps per emulator step, mass states mapped to the
//!   six segment frames at the emulator step times).
//!
//! Every method's objective is J on its own substrate. Counting follows
//! [`crate::control::search`]: an iteration is one annealing proposal, one simplex step, one
//! hill-climbing batch or one BPTT gradient step; a gradient counts one evaluation.
//!
//! Tables:
//! - `baselines` (method, substrate, iteration, evaluations, seconds, objective, gradients,
//!   current): one row per iteration; `objective` is the best J so far, `current` J at the
//!   method's current point. `seconds` (wall clock from the start of the method, the BPTT
//!   step-scale estimate included for BPTT) is the only non-deterministic column.
//! - `final` (method, substrate, iterations, evaluations, seconds, objective_substrate,
//!   objective_emulator, objective_simulator, distance_emulator_m, distance_simulator_m,
//!   target, iterations_to_bptt, evaluations_to_bptt, seconds_to_bptt, best_iteration): the
//!   best knots of each run evaluated on both substrates and the forward distance (m) they
//!   swim; `target` is BPTT-momentum's best J on the row's substrate (on the simulator: its
//!   learned knots replayed there) and the `*_to_bptt` columns are where the run's best J
//!   first reached it (NaN: never); `best_iteration` is where it reached its own best.
//! - `search_seeds` ([`job::SearchSeedRow`]): the emulator runs from each of
//!   [`Params::search_seeds`] random starts (the run's own first), each with the common target
//!   of its start; the verdict reads their medians ([`report::swim_rule_over`]).
//!
//! Here: the parameters and their validation, and the family; `settings` holds each method's
//! settings, `job` runs the searches, `figures` and `report` present them (the report holds
//! the verdict rule).

mod figures;
mod job;
mod report;
mod settings;

pub use settings::{
    AnnealingSettings, BpttSettings, Budgets, ClimbSettings, SearchBudget, SimplexSettings,
};

use super::swim::SwimTask;
use super::table1_structure::DolphinNets;
use crate::experiment::output::Tables;
use crate::experiment::plot::FigureSink;
use crate::experiment::report::Findings;
use crate::experiment::resolve::{ensure, positive, ParamError, Validate};
use crate::experiment::{Error, Family};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// The family.
pub struct NaBaselines;

/// Parameters of `na_baselines_swim`.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Params {
    /// Physical steps per emulator step n (N50).
    pub steps: usize,
    /// Multiplies the nets' example counts.
    pub example_scale: f64,
    /// Power iterations for the BPTT step scale λ.
    pub curvature_iterations: usize,
    /// Half-width of the uniform random initial knots (normalized units).
    pub init_spread: f64,
    /// Search seeds the verdict's medians run over: the run's own and the next
    /// `search_seeds - 1` (each its own random start and gradient-free randomness; the
    /// emulator runs only). 1 (the default) judges the run's own seed alone.
    #[serde(default = "one_seed")]
    pub search_seeds: usize,
    /// The swim task.
    pub swim: SwimTask,
    /// The dolphin hierarchy (only its global net is used).
    pub nets: DolphinNets,
    /// The BPTT runs.
    pub bptt: BpttSettings,
    /// Gradient-free budgets per substrate.
    pub budget: Budgets,
    /// Simulated annealing.
    pub annealing: AnnealingSettings,
    /// Nelder–Mead simplex.
    pub simplex: SimplexSettings,
    /// Parallel hill climbing.
    pub hill_climbing: ClimbSettings,
    /// The same runs again on the dolphin's last-round DAgger global net of
    /// `na_fig13_control` (ours), if run.
    #[serde(default)]
    pub dagger: Option<SwimDagger>,
    /// The verdict's thresholds (ours; [`report::swim_rule`]).
    pub rule: SwimRule,
}

fn one_seed() -> usize {
    1
}

/// The most search seeds a run may ask for.
pub const MAX_SEARCH_SEEDS: usize = 32;

/// The verdict's thresholds (ours: the paper compares "about 20 iterations" with "500-3,500").
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SwimRule {
    /// Where the common target J* lies between the initial J and the best J any method
    /// reaches on the substrate.
    pub target_fraction: f64,
    /// BPTT is fast when it reaches J* within this many iterations.
    pub fast_iterations: f64,
    /// A gradient-free method is slow when it needs at least this many times BPTT's
    /// iterations (or never gets there).
    pub slow_factor: f64,
    /// Partly needs more than this share of the methods slow.
    pub partly_slow_share: f64,
}

/// `[params.dagger]`: what, besides this file's task, nets and BPTT settings, determines
/// `na_fig13_control`'s dolphin DAgger chain (its `[params.dolphin]` restarts and
/// `[params.dolphin.dagger]`), so its cached nets are the ones searched on.
#[derive(Debug, Clone, Copy, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SwimDagger {
    /// Seeded restarts of the chain's learner.
    pub restarts: usize,
    /// Rounds, perturbations, fine-tuning budget.
    pub settings: crate::emulator::dagger::DaggerSettings,
    /// Super-steps of the fine-tuning's rollout windows.
    pub rollout_k: usize,
    /// Weight of the rollout loss.
    pub rollout_weight: f64,
}

/// The substrate name of runs on the DAgger net.
pub const DAGGER_SUBSTRATE: &str = "dagger_emulator";

impl Params {
    /// `na_fig13_control`'s parameters with the dolphin task alone and its DAgger chain, as
    /// this file states them: what keys and builds the DAgger nets.
    pub fn fig13(&self, d: &SwimDagger) -> super::fig13_control::Params {
        use super::fig13_control::dolphin_dagger::DolphinDagger;
        use super::fig13_control::DolphinControl;
        super::fig13_control::Params {
            steps: self.steps,
            curvature_iterations: self.curvature_iterations,
            example_scale: self.example_scale,
            tasks: vec![],
            training: self.nets.training,
            dolphin: Some(DolphinControl {
                nets: self.nets.clone(),
                swim: self.swim.clone(),
                iterations: self.bptt.iterations,
                eta: self.bptt.eta,
                alpha: self.bptt.alpha,
                init_spread: self.init_spread,
                restarts: d.restarts,
                step_rule: crate::control::bptt::StepRule::Fixed,
                dagger: Some(DolphinDagger {
                    settings: d.settings,
                    rollout_k: d.rollout_k,
                    rollout_weight: d.rollout_weight,
                }),
                ours_swim: None,
            }),
            sweep: None,
            physics_sweep: None,
            dagger: None,
            net_seeds: vec![],
            net_seeds_ours: vec![],
            net_lines: vec![],
            rule: None,
        }
    }
}

impl Validate for Params {
    fn validate(&self) -> Result<(), ParamError> {
        ensure(self.steps >= 1, "steps", "must be >= 1")?;
        let r = &self.rule;
        ensure(
            r.target_fraction > 0.0 && r.target_fraction <= 1.0,
            "rule.target_fraction",
            "must be in (0, 1]",
        )?;
        ensure(
            r.fast_iterations >= 1.0,
            "rule.fast_iterations",
            "must be >= 1",
        )?;
        ensure(r.slow_factor > 1.0, "rule.slow_factor", "must be above 1")?;
        ensure(
            r.partly_slow_share >= 0.0 && r.partly_slow_share < 1.0,
            "rule.partly_slow_share",
            "must be in [0, 1)",
        )?;
        positive("example_scale", self.example_scale)?;
        ensure(
            self.curvature_iterations >= 1,
            "curvature_iterations",
            "must be >= 1",
        )?;
        ensure(
            self.init_spread >= 0.0 && self.init_spread <= 1.0,
            "init_spread",
            "must be in [0, 1]",
        )?;
        ensure(
            (1..=MAX_SEARCH_SEEDS).contains(&self.search_seeds),
            "search_seeds",
            format!("must be in 1..={MAX_SEARCH_SEEDS}"),
        )?;
        self.swim.validate("swim")?;
        self.nets.validate("nets", self.example_scale)?;
        if let Some(d) = &self.dagger {
            ensure(d.restarts >= 1, "dagger.restarts", "must be >= 1")?;
            super::fig13_control::dolphin_dagger::DolphinDagger {
                settings: d.settings,
                rollout_k: d.rollout_k,
                rollout_weight: d.rollout_weight,
            }
            .validate("dagger")?;
        }
        let b = &self.bptt;
        ensure(b.iterations >= 1, "bptt.iterations", "must be >= 1")?;
        positive("bptt.eta", b.eta)?;
        positive("bptt.plain_eta", b.plain_eta)?;
        ensure(
            (0.0..1.0).contains(&b.alpha),
            "bptt.alpha",
            "must be in [0, 1)",
        )?;
        self.budget.emulator.validate("budget.emulator")?;
        self.budget.simulator.validate("budget.simulator")?;
        let a = &self.annealing;
        positive("annealing.start_temperature", a.start_temperature)?;
        positive("annealing.end_temperature", a.end_temperature)?;
        ensure(
            a.end_temperature <= a.start_temperature,
            "annealing.end_temperature",
            "must be <= start_temperature",
        )?;
        positive("annealing.step", a.step)?;
        positive("annealing.end_step", a.end_step)?;
        ensure(
            a.end_step <= a.step,
            "annealing.end_step",
            "must be <= step",
        )?;
        let s = &self.simplex;
        positive("simplex.step", s.step)?;
        ensure(
            s.sd_tolerance >= 0.0 && s.sd_tolerance.is_finite(),
            "simplex.sd_tolerance",
            "must be >= 0",
        )?;
        ensure(
            s.penalty >= 0.0 && s.penalty.is_finite(),
            "simplex.penalty",
            "must be >= 0",
        )?;
        let h = &self.hill_climbing;
        ensure(h.batch >= 1, "hill_climbing.batch", "must be >= 1")?;
        positive("hill_climbing.step", h.step)?;
        ensure(
            h.shrink > 0.0 && h.shrink <= 1.0,
            "hill_climbing.shrink",
            "must be in (0, 1]",
        )?;
        ensure(
            h.grow >= 1.0 && h.grow.is_finite(),
            "hill_climbing.grow",
            "must be >= 1",
        )
    }
}

/// A gradient-free search method.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Search {
    /// Simulated annealing.
    Annealing,
    /// Nelder–Mead simplex.
    Simplex,
    /// Hill climbing (ours, the mass-spring paper's search).
    HillClimbing,
}

impl Search {
    /// Every search, in table order.
    pub const ALL: [Search; 3] = [Search::Annealing, Search::Simplex, Search::HillClimbing];

    /// Its name in the tables.
    pub const fn name(self) -> &'static str {
        match self {
            Search::Annealing => "annealing",
            Search::Simplex => "simplex",
            Search::HillClimbing => "hill_climbing",
        }
    }
}

/// The gradient-free methods' names, in table order.
pub const SEARCHES: [&str; 3] = [
    Search::ALL[0].name(),
    Search::ALL[1].name(),
    Search::ALL[2].name(),
];
/// Every method, in table order.
pub const METHODS: [&str; 5] = [
    "bptt_momentum",
    "bptt_plain",
    "annealing",
    "simplex",
    "hill_climbing",
];

impl Family for NaBaselines {
    const CAPTIONS: &'static [(&'static str, &'static str)] = &[
        (
            "objective",
            "the dolphin swim's objective J (best so far) vs iteration and vs wall-clock seconds (each run on one core): BPTT beside simulated annealing, the simplex method and hill climbing, solid on the emulator and dashed on the simulator, and (right) on the DAgger net; one key, in the middle panel, serves all.",
        ),
    ];
    const KIND: &'static str = "na_baselines_swim";
    type Params = Params;
    fn figures(&self, fig: &FigureSink, tables: &Tables) -> Result<Vec<PathBuf>, Error> {
        figures::draw(fig, tables)
    }

    fn report(&self, dir: &Path) -> Result<Findings, Error> {
        report::findings(dir)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The DAgger net searched on is built as `na_fig13_control`'s: this file's task, nets,
    /// BPTT settings and `[params.dagger]` rebuild exactly its dolphin task and chain (and its
    /// steps, step-scale iterations and example scale), on Fig. 13's 4 s swim (its
    /// `dolphin_4s` line; Fig. 13's own dolphin swims 20 s).
    #[test]
    fn the_dagger_net_is_fig13s_dolphin_chain() {
        use crate::experiment::spec::SpecFile;
        let params = |file: &str| -> toml::Table {
            let f = SpecFile::load(std::path::Path::new(file)).unwrap();
            f.raw.params
        };
        let ours: Params = toml::Value::Table(params("experiments/na_baselines_swim.toml"))
            .try_into()
            .unwrap();
        let theirs: crate::families::na::fig13_control::Params =
            toml::Value::Table(params("experiments/na_fig13_control.toml"))
                .try_into()
                .unwrap();
        let built = ours.fig13(&ours.dagger.expect("the spec runs the DAgger net"));
        let mut theirs = theirs;
        if let Some(d) = theirs.dolphin.as_mut() {
            d.swim = d.ours_swim.take().expect("Fig. 13's 4 s swim");
        }
        assert_eq!(
            serde_json::to_value(&built.dolphin).unwrap(),
            serde_json::to_value(&theirs.dolphin).unwrap(),
            "dolphin task and chain"
        );
        assert_eq!(
            (built.steps, built.curvature_iterations, built.example_scale),
            (
                theirs.steps,
                theirs.curvature_iterations,
                theirs.example_scale
            )
        );
    }
}
