//! `na_table2_speedup` (NeuroAnimator §5.1, Table 2): wall time of 20,000 physical simulation
//! steps against the emulators that cover the same simulated time, N25, N50, N100 for the
//! passive and active pendulum, N50 for the truck and the lander, and N50 with and without 5
//! regularization steps per emulation step for the hierarchical dolphin (§5.3).
//!
//! Both competitors run here, in one process, on one thread, one after the other: the physical
//! simulator is the same RK4 at δt that generated the training data (the lander's quaternion
//! renormalized after each step), stepping in place without allocation; an emulator takes
//! 20,000 / n steps of [`crate::emulator::Emulator::predict`] (transforms + network, no
//! allocation). Controls (typical random controls of the model,
//! [`ControlSignal`](crate::emulator::dataset::ControlSignal)) are precomputed for both, the
//! physical one per step and the emulator one per super step. Each loop is timed `repeats`
//! times and the fastest is kept. Emulators come from the cache when `na_table1_structure`
//! (same seed and settings) trained them already.
//!
//! Speedup = n × (physical step cost / emulator step cost), with n the physical steps one
//! emulator step covers, so a cheap simulator makes a small speedup whatever the net costs
//! so every row carries that breakdown. Two comparisons the paper made
//! besides: the dolphin against an implicit mass-spring integrator like its \[18\]
//! ([`crate::physics::dolphin::ImplicitDolphin`], linearized backward Euler) at the paper's
//! δt = 0.01 s (§6: 20 s are 2,000 physical steps), covering the emulator's simulated time; and
//! every rigid model at equal accuracy ([`super::equal_accuracy`]): the largest physical step
//! Δt / j whose 40-super-step rollout error (Table 1's `rollout40_error_mean` measure) is at
//! most the emulator's, timed over the emulator's simulated time.
//!
//! Tables: `speedup` (model, emulator, physical_s, emulator_s, speedup, physical_steps,
//! emulator_steps, physical_step_s, emulator_step_s, n, step_cost_ratio, physical_integrator,
//! physical_dt) and `equal_accuracy` (model, emulator, emulator_error, substeps, matched_dt,
//! matched_error, coarser_error, physical_steps, emulator_steps, physical_s, emulator_s,
//! speedup). Timings (`physical_s`, `emulator_s`, `speedup`, `*_step_s`, `step_cost_ratio`)
//! vary run to run; every other column is bit-reproducible.
//!
//! Here: the parameters and their validation, and the family; `timing` holds the timed loops,
//! `job` runs them and tabulates the speedups, `figures` and `report` present them (the report
//! holds the verdict rule).

mod figures;
mod job;
mod report;
mod timing;

pub use job::{breakdown, Breakdown};

use super::table1_structure::{validate_nets, validate_training, DolphinNets};
use crate::emulator::catalog::{NetSpec, TrainSettings};
use crate::emulator::hierarchy::Regularizer;
use crate::experiment::output::Tables;
use crate::experiment::plot::FigureSink;
use crate::experiment::report::Findings;
use crate::experiment::resolve::{each_bar, ensure, positive, ParamError, Validate};
use crate::experiment::{Error, Family};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// The family.
pub struct NaSpeedup;

/// One model to time and the emulators (n values) to time it against.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TimedNet {
    /// The network (model, size, data, training method).
    pub net: NetSpec,
    /// Physical steps per emulator step, one emulator each (e.g. [25, 50, 100]).
    pub emulators: Vec<usize>,
}

/// Parameters of `na_table2_speedup`.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Params {
    /// Physical steps per timing run (the paper: 20,000).
    pub physical_steps: usize,
    /// Timing repetitions; the fastest is kept.
    pub repeats: usize,
    /// Multiplies every net's example count.
    pub example_scale: f64,
    /// Models and their emulators.
    pub models: Vec<TimedNet>,
    /// Training settings.
    pub training: TrainSettings,
    /// The dolphin rows: N50 and N50 with regularization steps after each emulation step.
    #[serde(default)]
    pub dolphin: Option<TimedDolphin>,
    /// The verdict's thresholds (ours, from the paper's words).
    pub rule: Table2Rule,
}

/// The verdict's thresholds ([`report::table2_rule`]; ours, from the paper's words: N100
/// "50-100 times faster ... and more", every emulator "one to two orders of magnitude").
#[derive(Debug, Clone, Copy, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Table2Rule {
    /// The slowest N100 speedup must be at least this.
    pub n100_min: f64,
    /// The slowest rigid-body N50 speedup must be at least this.
    pub n50_min: f64,
}

impl Table2Rule {
    /// Both above 1, what the physical simulator itself scores.
    fn validate(&self) -> Result<(), ParamError> {
        each_bar(
            self,
            |v| v > 1.0,
            "must be above 1: the physical simulator itself scores 1",
        )
    }
}

/// The dolphin rows of Table 2.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TimedDolphin {
    /// The hierarchy (as in `na_table1_structure`).
    pub nets: DolphinNets,
    /// Physical steps per emulator step n.
    pub steps: usize,
    /// The regularization step (§5.3).
    pub regularization: Regularizer,
    /// Regularization steps after each emulation step (the paper: 5).
    pub regularization_steps: usize,
    /// Step of the implicit (backward Euler) physical dolphin timed against N`steps` over the
    /// same simulated time (the paper's δt: 0.01 s); absent: no such row.
    #[serde(default)]
    pub implicit_dt: Option<f64>,
}

impl Validate for Params {
    fn validate(&self) -> Result<(), ParamError> {
        ensure(self.physical_steps >= 1, "physical_steps", "must be >= 1")?;
        ensure(self.repeats >= 1, "repeats", "must be >= 1")?;
        self.rule.validate()?;
        let nets: Vec<NetSpec> = self.models.iter().map(|m| m.net.clone()).collect();
        validate_nets(&nets, self.example_scale)?;
        for (i, m) in self.models.iter().enumerate() {
            ensure(
                !m.emulators.is_empty() && m.emulators.iter().all(|&n| n >= 1),
                &format!("models[{i}].emulators"),
                "need at least one n >= 1",
            )?;
            for &n in &m.emulators {
                ensure(
                    self.physical_steps.is_multiple_of(n),
                    &format!("models[{i}].emulators"),
                    format!("n = {n} must divide physical_steps"),
                )?;
            }
        }
        if let Some(d) = &self.dolphin {
            d.nets.validate("dolphin.nets", self.example_scale)?;
            ensure(
                d.steps >= 1 && self.physical_steps.is_multiple_of(d.steps),
                "dolphin.steps",
                "must be >= 1 and divide physical_steps",
            )?;
            validate_regularizer("dolphin.regularization", &d.regularization)?;
            if let Some(h) = d.implicit_dt {
                positive("dolphin.implicit_dt", h)?;
                let per_super = d.steps as f64 * d.nets.physical_dt / h;
                ensure(
                    (per_super - per_super.round()).abs() < 1e-9 && per_super.round() >= 1.0,
                    "dolphin.implicit_dt",
                    format!(
                        "must divide the emulator's super-step {} s",
                        d.steps as f64 * d.nets.physical_dt
                    ),
                )?;
            }
        }
        validate_training(&self.training)
    }
}

/// The explicit integrator of the dolphin's training data.
const DOLPHIN_EXPLICIT: &str = "semi-implicit Euler";
/// The implicit integrator of the dolphin's extra row.
const DOLPHIN_IMPLICIT: &str = "backward Euler";

/// Checks a regularizer: positive step and scales, and a step the explicit scheme survives
/// (the softened body's fastest spring mode ω = 330 √scale rad/s must keep ω δt < 1, and its
/// damping D × scale, D the dolphin's, δt D scale ≤ 0.5).
pub fn validate_regularizer(key: &str, r: &Regularizer) -> Result<(), ParamError> {
    positive(&format!("{key}.dt"), r.dt)?;
    positive(&format!("{key}.stiffness_scale"), r.stiffness_scale)?;
    positive(&format!("{key}.damping_scale"), r.damping_scale)?;
    ensure(
        330.0 * r.stiffness_scale.sqrt() * r.dt < 1.0,
        &format!("{key}.dt"),
        format!(
            "explicit regularization steps are unstable: 330 rad/s x sqrt(stiffness_scale) x dt = {:.2} must be < 1",
            330.0 * r.stiffness_scale.sqrt() * r.dt
        ),
    )?;
    let damping = crate::physics::dolphin::DolphinParams::default().damping;
    ensure(
        r.dt * r.damping_scale * damping <= 0.5,
        &format!("{key}.damping_scale"),
        format!(
            "explicit regularization steps are unstable: dt x {damping} N s/m x damping_scale = {:.2} must be <= 0.5",
            r.dt * r.damping_scale * damping
        ),
    )
}

impl Family for NaSpeedup {
    const CAPTIONS: &'static [(&'static str, &'static str)] = &[
        (
            "speedup",
            "speedup of each emulator over the physical simulator (log scale): seconds for the same simulated time, per model and super-step size.",
        ),
    ];
    const KIND: &'static str = "na_table2_speedup";
    type Params = Params;
    fn figures(&self, fig: &FigureSink, tables: &Tables) -> Result<Vec<PathBuf>, Error> {
        figures::draw(fig, tables)
    }

    fn report(&self, dir: &Path) -> Result<Findings, Error> {
        report::findings(dir)
    }
}
