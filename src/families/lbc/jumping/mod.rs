//! # `lbc_jumping` (LBC §6.1 "Jumping"): take-off controllers interpolated by LBC to the take-off
//! state a landing tracker needs
//!
//! "The height of a jump is determined by the speed of the character at the moment of takeoff
//! [...] we use linear Bellman combination to interpolate takeoff controllers [...] we created a
//! tracking controller that lands a jump for a given initial condition. We then used this
//! initial condition as the target for the linear Bellman combination. The resulting jump lands
//! successfully. A weighted average controller using the same weights fails to land as it falls
//! outside of the region of competence for the tracking controller." Here, on the diver with
//! ground contact at its foot ([`crate::physics::jumper`], LBC §6.3's jumping body):
//!
//! - **Take-offs** ([`job`]): vertical leaps from a crouch. A Wooten-style PD push ([`Push`]:
//!   the joints driven toward an extended pose at stiffness `strength`, the torso held upright
//!   in the world by the hip) defines the take-off state at a fixed time `takeoff_s` (after the
//!   feet have left the ground). Two examples, a low and a high jump (strengths `low` and
//!   `high`), are optimized by DDP from the crouch to their take-off states with §6.1's
//!   objective (the average trajectory being the push of the mean strength), initialized with
//!   their own pushes' torques; each gets its TV-LQR tracker and value function.
//! - **Landing tracker** for each desired jump: the desired take-off state is the push's at a
//!   strength in between (`desired`); a PD landing ([`Landing`]: the feet flattened in the air,
//!   then the torso held in the world by the hip and the centre of mass balanced over the sole
//!   by the ankle) from that state gives the landing motion, and its TV-LQR tracker (§6.1's
//!   objective: the landing's last state at rest as the terminal target, the landing motion as
//!   the average trajectory) lands the jump from that take-off state.
//! - **LBC** of the two take-off trackers with projected weights (§4.1: the desired take-off
//!   state's quadratic projected onto the examples' exp(−g_i/λ), λ by §4.1's scale rule), the
//!   naive blend with the same weights, and each tracker alone, each followed at `takeoff_s` by
//!   the desired jump's landing tracker and then the PD landing holding the body for `hold_s`.
//!   Everything is run on the simulator (RK4 at `knot_dt / substeps`, the control held over a
//!   knot).
//!
//! Tables: `jumps` (desired, method, takeoff_error, landed + desired_strength, height_m, fell,
//! effort, weight_low, weight_high, speed_error_m_s, seconds), `components`, `landing`,
//! `weights`, `entropy` (α's normalized entropy and distance from the fixed weights at every
//! knot of the take-off, LBC's and the naive blend's), `motion`, `rule`.

mod figures;
mod job;
mod report;
mod rows;

pub use job::{jump_height, standing, Landing, Push};
pub use report::{verdict_of, JumpFacts};

use crate::experiment::output::Tables;
use crate::experiment::plot::FigureSink;
use crate::experiment::report::Findings;
use crate::experiment::resolve::{ensure, positive, ParamError, Validate};
use crate::experiment::{Error, Family};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// The family.
pub struct LbcJumping;

/// The crouch the jumps start from ([`crate::physics::jumper::Jumper::crouch`]).
#[derive(Debug, Clone, Copy, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Crouch {
    /// Torso tipped forward from upright (rad).
    pub lean: f64,
    /// Shank tipped forward from vertical (rad).
    pub shin: f64,
    /// Arms swung back from hanging (rad).
    pub arm: f64,
}

/// The verdict's threshold (ours; the spec states the rule).
#[derive(Debug, Clone, Copy, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Rule {
    /// A take-off reaches its target when its error (the Q_T norm) is at most this.
    pub takeoff_tolerance: f64,
}

/// Parameters of `lbc_jumping`.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Params {
    /// The crouch.
    pub crouch: Crouch,
    /// The PD take-off.
    pub push: Push,
    /// The PD landing.
    pub landing: Landing,
    /// DDP's knot (one RK4 step, s).
    pub knot_dt: f64,
    /// Simulator steps per knot.
    pub substeps: usize,
    /// The take-off's duration (s): the take-off state is the body's at this time.
    pub takeoff_s: f64,
    /// The landing's duration after the take-off (s).
    pub landing_s: f64,
    /// Seconds the PD landing holds the body after the landing tracker (a fall there counts).
    pub hold_s: f64,
    /// The low example's push strength (N m/rad).
    pub low: f64,
    /// The high example's push strength.
    pub high: f64,
    /// Push strengths defining the desired take-off states (between `low` and `high`).
    pub desired: Vec<f64>,
    /// The objective's scales: Q_T on the centre of mass's position and velocity and the
    /// torso's and joints' angles and rates; the running Q on the angles.
    pub cost: super::CostScales,
    /// DDP's iterations at most for the take-off examples.
    pub takeoff_iterations: usize,
    /// DDP stops when an iteration improves the cost by less than this fraction.
    pub tol_cost: f64,
    /// Seconds between the animation's frames.
    pub gif_frame_s: f64,
    /// The verdict's threshold.
    pub rule: Rule,
}

/// The most desired jumps.
pub const MAX_DESIRED: usize = 20;
/// The most DDP iterations.
pub const MAX_ITERATIONS: usize = 500;

impl Validate for Params {
    fn validate(&self) -> Result<(), ParamError> {
        let c = &self.crouch;
        ensure(
            (0.0..1.2).contains(&c.lean) && (0.0..1.2).contains(&c.shin) && c.arm.abs() < 2.0,
            "crouch",
            "lean and shin must be in [0, 1.2) rad, |arm| below 2 rad",
        )?;
        self.push.validate()?;
        self.landing.validate()?;
        crate::families::lbc::knot_dt_on_ground(self.knot_dt)?;
        ensure(
            (1..=100).contains(&self.substeps),
            "substeps",
            "must be 1 to 100",
        )?;
        ensure(
            self.takeoff_s > 0.0 && self.takeoff_s <= 1.0,
            "takeoff_s",
            "must be in (0, 1] s",
        )?;
        ensure(
            self.landing_s > 0.0 && self.landing_s <= 3.0,
            "landing_s",
            "must be in (0, 3] s",
        )?;
        ensure(
            self.hold_s >= 0.0 && self.hold_s <= 10.0,
            "hold_s",
            "must be in [0, 10] s",
        )?;
        ensure(
            self.low > 0.0 && self.low < self.high && self.high <= 1e5,
            "low",
            "need 0 < low < high <= 1e5 (N m/rad)",
        )?;
        ensure(
            !self.desired.is_empty() && self.desired.len() <= MAX_DESIRED,
            "desired",
            format!("1 to {MAX_DESIRED} strengths"),
        )?;
        ensure(
            self.desired.iter().all(|&d| d > self.low && d < self.high),
            "desired",
            "every desired strength must lie strictly between low and high (LBC interpolates)",
        )?;
        self.cost.validate()?;
        ensure(
            (1..=MAX_ITERATIONS).contains(&self.takeoff_iterations),
            "takeoff_iterations",
            format!("must be 1 to {MAX_ITERATIONS}"),
        )?;
        positive("tol_cost", self.tol_cost)?;
        positive("gif_frame_s", self.gif_frame_s)?;
        positive("rule.takeoff_tolerance", self.rule.takeoff_tolerance)?;
        Ok(())
    }
}

impl Family for LbcJumping {
    const KIND: &'static str = "lbc_jumping";
    type Params = Params;
    const CAPTIONS: &'static [(&'static str, &'static str)] = &[
        (
            "takeoff",
            "take-off error (the Q_T norm of the take-off state's distance from the desired one) of LBC, the naive blend with the same weights and each example's tracker alone, against the desired jump height, with the rule's take-off tolerance as a grey band; filled markers landed, a cross did not land.",
        ),
        (
            "heights",
            "jump height (the centre of mass's ballistic apex above its height in the crouch) reached at take-off against the desired height, per method (the dashed line is the desired height), and beside it the take-off error the verdict reads, with the rule's take-off tolerance as a grey band.",
        ),
        (
            "weights",
            "LBC's weight of the low jump's tracker α_low over the take-off, for each desired jump (the projected weight is where each line starts).",
        ),
        (
            "jumps",
            "the jump with the middle desired height: LBC's (top) and the naive blend's (bottom), the body every 0.1 s from the crouch until 1.2 s (take-off, flight and landing; bodies spaced 0.6 m apart), to scale.",
        ),
        (
            "jump_anim",
            "LBC's jump (left) and the naive blend's (right) for the middle desired height, played at real time; the title gives the time and each one's α_low.",
        ),
    ];

    fn figures(&self, fig: &FigureSink, tables: &Tables) -> Result<Vec<PathBuf>, Error> {
        figures::figures(fig, tables)
    }

    fn report(&self, dir: &Path) -> Result<Findings, Error> {
        report::report(dir)
    }
}
