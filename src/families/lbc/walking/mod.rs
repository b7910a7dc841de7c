//! # `lbc_walking` (LBC §6.2 "Stepping"): two SIMBICON walkers coordinated by LBC on a hill
//!
//! The paper combines two SIMBICON walkers, one tuned for flat ground and one for a 10° incline
//! ("when placed on an incline of ten degrees, the flat ground walker does not fall, but fails
//! to advance up the hill"), into one controller that walks on flat and hilly terrain, its
//! blend weights shifting to the hill walker on the hill. Here:
//!
//! - **Walkers**: the flat walker is the SIMBICON applet's published walk
//!   ([`crate::control::simbicon::Gait::walk`], copied into the spec); the hill walker is the
//!   same state machine with the torso's target leaned and the swing hip's target raised by the
//!   offsets of a stated grid, the grid point that walks furthest up the incline in
//!   `hill_search.seconds` without falling (ties: the first in grid order).
//! - **Value functions** ([`crate::control::gait_value`]): SIMBICON has none, so each walker gets
//!   the cost of the time-varying LQR that tracks its own periodic gait on its own ground over
//!   the next `horizon_s`, in coordinates that include the ground's slope under the pelvis.
//! - **LBC** (eq. 11 with weights one): u = Σ α_i u_i, α_i ∝ exp(−v_i(x)/λ), both state machines
//!   running on the same body, α recomputed every `blend_every_s`. The naive blend averages the
//!   two walkers' torques with fixed weights ½, ½.
//! - **λ** is chosen by the rule in the spec from `lambdas` (the smallest at which LBC walks all
//!   three terrains without falling); every λ's walks are in `lambda_sweep.csv`.
//!
//! Tables: `search` (torso_offset, hip_offset, distance_m, fell, chosen), `cycles` (walker,
//! terrain, knots, half_period_s, speed_m_s, horizon_knots), `walks` (terrain, controller,
//! distance_m, fell, mean_speed_m_s, steps, fell_at_s, lambda), `weights` (terrain, t, x,
//! slope_deg, alpha_flat, alpha_hill, v_flat, v_hill; LBC at the chosen λ), `lambda_sweep`
//! (lambda, terrain, distance_m, fell, alpha_hill_flat_part, alpha_hill_hill_part), `motion`
//! (controller, t, q0..q8 on the flat-then-hill track, for the GIF), `rule`.

mod figures;
mod job;
mod report;
mod rows;

use crate::control::gait_value::GaitCost;
use crate::control::simbicon::Gait;
use crate::experiment::output::Tables;
use crate::experiment::plot::FigureSink;
use crate::experiment::report::Findings;
use crate::experiment::resolve::{all_positive, ensure, positive, ParamError, Validate};
use crate::experiment::{Error, Family};
use crate::physics::ground::Terrain;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

pub use report::{verdict_of, WalkingFacts};

/// The family.
pub struct LbcWalking;

/// The hill walker's search (module docs).
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct HillSearch {
    /// Seconds each candidate walks up the incline.
    pub seconds: f64,
    /// Added to both states' torso target (rad; negative leans forward).
    pub torso_offsets: Vec<f64>,
    /// Added to both states' swing-hip target (rad; positive forward).
    pub hip_offsets: Vec<f64>,
}

/// The verdict's thresholds (ours; the spec states the rule).
#[derive(Debug, Clone, Copy, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Rule {
    /// The flat walker "fails to advance" on the incline when it falls or covers less than this
    /// fraction of the hill walker's distance there.
    pub advance_fraction: f64,
    /// LBC must climb at least this far (m, along x) past the hill's start.
    pub climb_m: f64,
    /// The weights' shift: mean α_hill on the hill at least ½ and at least this much above its
    /// mean on the flat part.
    pub shift: f64,
    /// The flat and hill parts of the track: pelvis this far (m) before / after the hill's
    /// start.
    pub margin_m: f64,
}

/// Parameters of `lbc_walking`.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Params {
    /// The flat walker (the applet's walk).
    pub flat_gait: Gait,
    /// The incline (degrees) of the hill walker's terrain, the `incline` terrain and the hill.
    pub incline_degrees: f64,
    /// Where the flat-then-hill track's hill begins (m) and its corner's rounding (m).
    pub hill_start_m: f64,
    /// Rounding of the hill's corner (m).
    pub hill_smoothing_m: f64,
    /// The hill walker's search.
    pub hill_search: HillSearch,
    /// Cost rates of the value functions' tracking LQR.
    pub cost: GaitCost,
    /// Seconds walked before a gait is recorded.
    pub warmup_s: f64,
    /// Seconds between the gait's knots.
    pub knot_dt: f64,
    /// The value functions' horizon (s).
    pub horizon_s: f64,
    /// Seconds between LBC's weight updates.
    pub blend_every_s: f64,
    /// Seconds of every walk.
    pub walk_s: f64,
    /// LBC temperatures tried; the rule picks one.
    pub lambdas: Vec<f64>,
    /// Seconds between the GIF's frames.
    pub gif_frame_s: f64,
    /// The verdict's thresholds.
    pub rule: Rule,
}

impl Params {
    /// The three terrains, by name: level, the incline, the flat-then-hill track.
    pub fn terrains(&self) -> [(&'static str, Terrain); 3] {
        [
            ("flat", Terrain::Flat),
            (
                "incline",
                Terrain::Slope {
                    degrees: self.incline_degrees,
                },
            ),
            (
                "flat_then_hill",
                Terrain::FlatThenHill {
                    start_m: self.hill_start_m,
                    degrees: self.incline_degrees,
                    smoothing_m: self.hill_smoothing_m,
                },
            ),
        ]
    }
}

/// The most seconds a walk, a search walk or a warm-up may last (each costs about 0.1 s of one
/// core per simulated second).
pub const MAX_SECONDS: f64 = 120.0;
/// The most grid points or temperatures.
pub const MAX_GRID: usize = 400;

impl Validate for Params {
    fn validate(&self) -> Result<(), ParamError> {
        let g = &self.flat_gait;
        ensure(
            g.kp > 0.0 && g.kd >= 0.0 && g.torque_limit > 0.0,
            "flat_gait",
            "kp and torque_limit must be positive, kd non-negative",
        )?;
        ensure(
            g.states[0].duration.is_some_and(|d| d > 0.0) && g.states[1].duration.is_none(),
            "flat_gait.states",
            "state 0 needs a positive duration, state 1 none (it ends at heel strike)",
        )?;
        ensure(
            self.incline_degrees.is_finite() && self.incline_degrees.abs() < 30.0,
            "incline_degrees",
            "must be within ±30°",
        )?;
        ensure(
            self.hill_start_m.is_finite() && self.hill_start_m > 1.0,
            "hill_start_m",
            "must be finite and beyond the start (> 1 m)",
        )?;
        positive("hill_smoothing_m", self.hill_smoothing_m)?;
        let s = &self.hill_search;
        for (key, v) in [
            ("hill_search.seconds", s.seconds),
            ("warmup_s", self.warmup_s),
            ("walk_s", self.walk_s),
        ] {
            positive(key, v)?;
            ensure(v <= MAX_SECONDS, key, format!("at most {MAX_SECONDS} s"))?;
        }
        ensure(
            !s.torso_offsets.is_empty()
                && !s.hip_offsets.is_empty()
                && s.torso_offsets.len() * s.hip_offsets.len() <= MAX_GRID,
            "hill_search",
            format!("a grid of 1 to {MAX_GRID} points"),
        )?;
        ensure(
            s.torso_offsets
                .iter()
                .chain(&s.hip_offsets)
                .all(|v| v.is_finite() && v.abs() < 1.0),
            "hill_search",
            "offsets must be finite and below 1 rad",
        )?;
        self.cost
            .validate()
            .map_err(|m| ParamError::new("cost", m))?;
        positive("knot_dt", self.knot_dt)?;
        ensure(
            self.knot_dt <= 0.05 && self.knot_dt >= 0.001,
            "knot_dt",
            "must be in [0.001, 0.05] s",
        )?;
        positive("horizon_s", self.horizon_s)?;
        ensure(self.horizon_s <= 10.0, "horizon_s", "at most 10 s")?;
        positive("blend_every_s", self.blend_every_s)?;
        positive("gif_frame_s", self.gif_frame_s)?;
        all_positive("lambdas", &self.lambdas)?;
        ensure(
            !self.lambdas.is_empty() && self.lambdas.len() <= MAX_GRID,
            "lambdas",
            format!("1 to {MAX_GRID} temperatures"),
        )?;
        ensure(
            self.lambdas.windows(2).all(|w| w[0] < w[1]),
            "lambdas",
            "must increase (the rule takes the smallest that walks)",
        )?;
        let r = &self.rule;
        ensure(
            (0.0..=1.0).contains(&r.advance_fraction),
            "rule.advance_fraction",
            "must be in [0, 1]",
        )?;
        positive("rule.climb_m", r.climb_m)?;
        ensure(
            (0.0..=1.0).contains(&r.shift),
            "rule.shift",
            "must be in [0, 1]",
        )?;
        positive("rule.margin_m", r.margin_m)?;
        Ok(())
    }
}

impl Family for LbcWalking {
    const KIND: &'static str = "lbc_walking";
    type Params = Params;
    const CAPTIONS: &'static [(&'static str, &'static str)] = &[
        (
            "walks",
            "distance walked in the walk's seconds by each controller on each terrain (a cross: it fell, at the distance where it fell).",
        ),
        (
            "weights",
            "LBC's weight of the hill walker α_hill against the pelvis' position on each terrain, with the flat-then-hill track's height profile; the hill begins at the dashed line.",
        ),
        (
            "lambda",
            "the temperature sweep: distance walked on each terrain and α_hill's mean on the flat and the hill part of the flat-then-hill track against λ; the rule's λ is the smallest at which LBC walks all three terrains.",
        ),
        (
            "filmstrip",
            "LBC's body every 0.5 s over the first 9 s on the flat-then-hill track (blue while the flat walker's weight leads, red once the hill walker's does) and the flat walker alone (grey) until it falls, to scale.",
        ),
        (
            "track",
            "LBC of the flat and hill walkers (colour) on the flat-then-hill track beside the flat walker alone (grey, until it falls), every `gif_frame_s` (0.1 s) of the walk, played in real time, the view following LBC's pelvis; the title gives LBC's weight of the hill walker.",
        ),
        (
            "search",
            "the hill walker's search: distance up the incline of each grid point (torso lean and swing-hip offsets; negative: it walked backwards down the incline), fallen points marked at their fall distance, the chosen point labelled.",
        ),
    ];

    fn figures(&self, fig: &FigureSink, tables: &Tables) -> Result<Vec<PathBuf>, Error> {
        figures::figures(fig, tables)
    }

    fn report(&self, dir: &Path) -> Result<Findings, Error> {
        report::report(dir)
    }
}
