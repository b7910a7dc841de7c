//! # `lbc_stepping` (LBC §6.1 "Stepping"): a short and a long DDP step interpolated by LBC
//!
//! "Linear Bellman combination can create a stepping controller which can take steps of various
//! lengths. For this application, two example steps, a short step and a long step, are combined
//! to interpolate the step lengths. A complete walk can be constructed by sequencing step
//! controllers together." Here, on SIMBICON's 2-D biped with penalty contact
//! ([`crate::physics::biped`]):
//!
//! - **Start**: the SIMBICON applet's walk ([`crate::control::simbicon::Gait::walk`]) at its
//!   first left heel strike after `warmup_s` (both feet down, the right about to swing).
//! - **Steps** ([`job`]): DDP through the contact (RK4 knots of `knot_dt` on finite-difference
//!   Jacobians of the contact dynamics), from that start to a terminal state whose right heel is
//!   `length` ahead of the left heel, over the duration of SIMBICON's own step from the start
//!   (fixed). The terminal state is SIMBICON's at its right heel strike with the pelvis and both
//!   hips moved (ankles compensating, feet keeping their angles) so that both heels are on the
//!   ground `length` apart ([`job::step_target`]); its velocities are SIMBICON's. The objective
//!   is §6.1's: (x(T) − x̄_i(T))ᵀ Q_T (x(T) − x̄_i(T)) + ∫ (x − x̄)ᵀ Q (x − x̄) + ½ uᵀ R u dt, the
//!   average trajectory x̄ being SIMBICON's own step from the start (whose length lies between
//!   the two), initialized with SIMBICON's torques along it. Each DDP step gets its TV-LQR
//!   tracker and value function (LBC §5.2).
//! - **LBC** of the short and long trackers with projected weights (§4.1): the desired terminal
//!   cost of a length is the same quadratic centred on that length's target, projected in reward
//!   space onto the two components' exp(−g_i/λ); λ by the rule in the spec. The naive blend
//!   averages the two trackers' torques with the same (normalized) weights; each tracker alone
//!   and a direct DDP solve for every desired length (the ground truth, with its seconds)
//!   complete the comparison. Every controller is run on the simulator (RK4 at `knot_dt /
//!   substeps`, the control held over each knot), then SIMBICON walks on for `continue_s` to
//!   see that the step left the body walkable.
//! - **Walk**: footholds `walk_m` apart with a gap between consecutive footholds (from the
//!   stance toe plus `rule.tolerance_m` to the next foothold minus it); each step is LBC's with
//!   the desired length from the actual stance heel to the next foothold, the body mirrored
//!   (left and right legs swapped) so that every step starts on the left foot like the examples.
//!
//! Tables: `components` (component, target_length_m, reached_length_m, iterations, cost,
//! termination, seconds, average_scale), `targets` (desired_length_m, method, reached_length_m, fell, effort,
//! seconds + landed, length_error_m, weight_short, weight_long; `seconds`, the wall time to build
//! and run the controller, is the only non-deterministic column), `weights` (desired_length_m, t,
//! alpha_short), `average_effect` (average_scale, desired_length_m, method, reached_length_m,
//! fell, effort, landed: LBC and the naive blend with the examples optimized at each scale of
//! the average-trajectory term), `walk` (step, stance_heel_m, foothold_m, desired_length_m, reached_length_m,
//! landing_heel_m, landing_toe_m, gap_start_m, gap_end_m, in_gap, fell, weight_short), `motion`
//! (step, t, alpha_short, q0..q8 of the walk, world frame), `rule`.

mod figures;
mod job;
mod report;
mod rows;

pub use job::{step_length, step_target};
pub use report::{verdict_of, SteppingFacts, Walk, WalkStep};

use crate::control::simbicon::Gait;
use crate::experiment::output::Tables;
use crate::experiment::plot::FigureSink;
use crate::experiment::report::Findings;
use crate::experiment::resolve::{ensure, positive, ParamError, Validate};
use crate::experiment::{Error, Family};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// The family.
pub struct LbcStepping;

/// The verdict's threshold (ours; the spec states the rule).
#[derive(Debug, Clone, Copy, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Rule {
    /// A step reaches its length when its heel lands within this of it (m); also the margin
    /// of the walk's gaps.
    pub tolerance_m: f64,
    /// LBC's mean length error must beat the naive blend's by at least this (m).
    pub error_margin_m: f64,
}

/// Parameters of `lbc_stepping`.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Params {
    /// SIMBICON's walk: the start, the step's duration, the average trajectory, DDP's initial
    /// torques and the walking after each step.
    pub gait: Gait,
    /// Seconds walked before the start's heel strike.
    pub warmup_s: f64,
    /// DDP's knot (one RK4 step, s).
    pub knot_dt: f64,
    /// Simulator steps per knot.
    pub substeps: usize,
    /// The short example's step length (m, heel to heel).
    pub short_m: f64,
    /// The long example's step length (m).
    pub long_m: f64,
    /// Desired lengths between them (m).
    pub desired_m: Vec<f64>,
    /// The objective's scales: Q_T on the pelvis' position and velocity and the angles and
    /// rates; the running Q on the pelvis' height and the angles (none along the ground).
    pub cost: super::CostScales,
    /// Other scales of the average-trajectory term at which the two examples are optimized
    /// again and LBC and the naive blend run (the `average_effect` table; empty: none).
    #[serde(default)]
    pub compare_average_scales: Vec<f64>,
    /// Torque limit of every joint (N m), for DDP and every controller.
    pub torque_limit: f64,
    /// DDP's iterations at most.
    pub max_iterations: usize,
    /// DDP stops when an iteration improves the cost by less than this fraction.
    pub tol_cost: f64,
    /// Seconds SIMBICON walks on after a step (a fall there counts as the step's).
    pub continue_s: f64,
    /// The walk: lengths between consecutive footholds (m; at least 6).
    pub walk_m: Vec<f64>,
    /// Seconds between the walk's animation frames.
    pub gif_frame_s: f64,
    /// The verdict's threshold.
    pub rule: Rule,
}

/// The most desired lengths or walk steps.
pub const MAX_LENGTHS: usize = 50;
/// The most DDP iterations.
pub const MAX_ITERATIONS: usize = 500;

impl Validate for Params {
    fn validate(&self) -> Result<(), ParamError> {
        let g = &self.gait;
        ensure(
            g.kp > 0.0 && g.kd >= 0.0 && g.torque_limit > 0.0,
            "gait",
            "kp and torque_limit must be positive, kd non-negative",
        )?;
        ensure(
            g.states[0].duration.is_some_and(|d| d > 0.0) && g.states[1].duration.is_none(),
            "gait.states",
            "state 0 needs a positive duration, state 1 none (it ends at heel strike)",
        )?;
        positive("warmup_s", self.warmup_s)?;
        ensure(self.warmup_s <= 60.0, "warmup_s", "at most 60 s")?;
        crate::families::lbc::knot_dt_on_ground(self.knot_dt)?;
        ensure(
            (1..=100).contains(&self.substeps),
            "substeps",
            "must be 1 to 100",
        )?;
        ensure(
            self.short_m > 0.1 && self.short_m < self.long_m && self.long_m < 0.8,
            "short_m",
            "need 0.1 < short_m < long_m < 0.8 (m)",
        )?;
        positive("rule.tolerance_m", self.rule.tolerance_m)?;
        positive("rule.error_margin_m", self.rule.error_margin_m)?;
        let tol = self.rule.tolerance_m;
        ensure(
            !self.desired_m.is_empty() && self.desired_m.len() <= MAX_LENGTHS,
            "desired_m",
            format!("1 to {MAX_LENGTHS} lengths"),
        )?;
        ensure(
            self.desired_m
                .iter()
                .all(|&d| d > self.short_m + tol && d < self.long_m - tol),
            "desired_m",
            "every desired length must lie more than rule.tolerance_m inside (short_m, long_m)",
        )?;
        self.cost.validate()?;
        ensure(
            self.compare_average_scales.len() <= 4
                && self
                    .compare_average_scales
                    .iter()
                    .all(|v| v.is_finite() && *v >= 0.0),
            "compare_average_scales",
            "at most 4 finite, non-negative scales",
        )?;
        positive("torque_limit", self.torque_limit)?;
        ensure(
            (1..=MAX_ITERATIONS).contains(&self.max_iterations),
            "max_iterations",
            format!("must be 1 to {MAX_ITERATIONS}"),
        )?;
        positive("tol_cost", self.tol_cost)?;
        ensure(
            self.continue_s >= 0.0 && self.continue_s <= 10.0,
            "continue_s",
            "must be in [0, 10] s",
        )?;
        ensure(
            self.walk_m.len() >= 6 && self.walk_m.len() <= MAX_LENGTHS,
            "walk_m",
            format!("6 to {MAX_LENGTHS} steps (the issue asks for at least 6)"),
        )?;
        ensure(
            self.walk_m
                .iter()
                .all(|&d| d >= self.short_m && d <= self.long_m),
            "walk_m",
            "every length must lie in [short_m, long_m] (LBC interpolates, it does not extrapolate)",
        )?;
        positive("gif_frame_s", self.gif_frame_s)?;
        Ok(())
    }
}

impl Family for LbcStepping {
    const KIND: &'static str = "lbc_stepping";
    type Params = Params;
    const CAPTIONS: &'static [(&'static str, &'static str)] = &[
        (
            "lengths",
            "step length reached on the simulator (the landing heel from the stance heel at the step's start) against the desired length for LBC, the naive blend with the same weights, each example's tracker alone and a direct DDP solve per length; the band is the rule's tolerance, a cross marks a fall.",
        ),
        (
            "effort",
            "each controller's effort ½∫uᵀRu dt over the step against the desired length.",
        ),
        (
            "weights",
            "LBC's weight of the short step's tracker α_short over the step, for each desired length (the projected weight w_short/(w_short+w_long) is where each line starts).",
        ),
        (
            "walk",
            "the walk over gaps: the body at the start and at the end of each step (LBC's) and the gaps between the footholds (red; a sole must not touch one), to scale.",
        ),
        (
            "walk_anim",
            "the walk over gaps, LBC stepping from foothold to foothold, played at real time; the title gives the step and α_short.",
        ),
    ];

    fn figures(&self, fig: &FigureSink, tables: &Tables) -> Result<Vec<PathBuf>, Error> {
        figures::figures(fig, tables)
    }

    fn report(&self, dir: &Path) -> Result<Findings, Error> {
        report::report(dir)
    }
}
