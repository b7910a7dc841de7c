//! `lbc_push_recovery` (LBC Fig. 9): coordination (w = 1) of a "reach forward" and a "reach
//! backward" controller of the push-recovery figure (a body balanced on an ankle pivot with a
//! two-link arm). Each controller is a DDP reach from the upright pose to a hold in front or
//! behind, tracked by LQR; under a scripted sequence of tugs on the hand the LBC blend weight
//! swings between the two, then settles.
//!
//! The motors are torque-limited (`torque_limits`, in DDP and in the closed loop); the ankle's
//! limit comes from the foot: the centre of pressure cannot leave the sole, so the ankle torque
//! is at most m g times the ankle-to-toe lever, and beyond a small lean the ankle alone cannot
//! hold the body. The figure stands between two walls ([`PushScene`]): the reaches end with the
//! hand at a wall, which is what catches a fall (the paper's "grab onto something to maintain
//! balance", §4.2). DDP and the trackers see the figure alone (no walls, smooth); the closed
//! loops run the walled scene, integrated by RK4 in `substeps` steps per control step because
//! the contact is stiff. λ = σ² R from a stated motor-noise intensity σ (eq. 8). The same tug
//! sequence is run three ways: as scripted, mirrored (every force negated) and not at all (the
//! baseline); the mirrored run must choose the mirrored reach (α_forward ↔ α_backward), the
//! weight must settle over a window that ends well before the horizon (where every
//! time-varying tracker's value flattens), and the no-tug baseline must swing less (the swings
//! come from the tugs). The premise is tested by the same tugs with no reach.
//!
//! Tables: `weights` (t, alpha_forward, alpha_backward, force_x, body_angle, arm_angle,
//! hand_x, alpha_forward_mirrored, alpha_forward_baseline, body_angle_mirrored, wall_force,
//! body_angle_no_reach), `reaches` (one row per optimized reach, with its termination), `rule`
//! (the spec's thresholds and the premise's measured lean), `lambda_sweep` (lambda, swings,
//! settle_gap, mirror_gap, mean_entropy, max_lean, settle_range: the checks repeated at each
//! temperature of `lambda_sweep`, not judged, with the mean normalized entropy of α under the
//! tugs, so that no verdict rests on a degenerate α unseen).
//!
//! Here: the parameters and their validation; `job` (reaches, trackers, closed loops, and the
//! rows of the tables read back), `measures` (what the verdict judges), `figures` and `report`
//! hold the rest.
//!
//! [`PushScene`]: crate::physics::push::PushScene

mod figures;
mod job;
mod measures;
mod report;

pub use measures::{mirror_gap, swings, window_gap, window_range};

use crate::experiment::output::Tables;
use crate::experiment::plot::FigureSink;
use crate::experiment::report::Findings;
use crate::experiment::resolve::{distinct, ensure, positive, ParamError, Validate};
use crate::experiment::{Error, Family};
use crate::physics::push::Walls;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// The family.
pub struct LbcPush;

/// A tug: a horizontal force on the hand over a time window.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Tug {
    /// Start (s).
    pub start: f64,
    /// Duration (s).
    pub duration: f64,
    /// Horizontal force (N; positive pulls forward, towards +x).
    pub force: f64,
}

/// Parameters of `lbc_push_recovery`.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Params {
    /// Controller horizon (s).
    pub horizon: f64,
    /// RK4 time step (s).
    pub dt: f64,
    /// Lean of the body at the hold (rad): forward reach ends at π/2 − lean, backward at π/2 + lean.
    pub lean: f64,
    /// Terminal weights (body angle, shoulder, elbow, then each rate).
    pub terminal_weights: [f64; 6],
    /// Control weight R (per N²·m²).
    pub control_weight: f64,
    /// DDP iteration limit (the reaches run to convergence within it, or the run fails).
    pub max_iterations: usize,
    /// Motor limits |τ| of the ankle, shoulder and elbow (N·m), in DDP and the closed loop.
    pub torque_limits: [f64; 3],
    /// Intensity σ of the white motor-torque noise (N·m·√s); λ = σ² R (eq. 8: noise λR⁻¹).
    pub torque_noise: f64,
    /// The scripted tugs.
    pub tugs: Vec<Tug>,
    /// Held needs the forward weight to cross 0.5 at least this many times while tugged.
    pub min_swings: usize,
    /// Window (s) over which the tugged weight must match the no-tug baseline.
    pub settle_window: [f64; 2],
    /// Settled when |α_forward − α_forward(baseline)| stays below this over the window.
    pub settle_tolerance: f64,
    /// Mirrored when |α_forward(tugs) − α_backward(mirrored tugs)| stays below this throughout.
    pub mirror_tolerance: f64,
    /// The body has fallen when its lean from upright exceeds this (rad).
    pub fall_angle: f64,
    /// Temperatures λ at which the checks are repeated (not judged; the noise model's λ is).
    #[serde(default)]
    pub lambda_sweep: Vec<f64>,
    /// The walls the hand can catch the body on.
    pub walls: Walls,
    /// Running state weights (body angle, shoulder, elbow, then each rate) pulling each reach
    /// to its hold pose from the start, so that it gets there early and holds; absent: the
    /// terminal cost alone.
    #[serde(default)]
    pub hold_weights: Option<[f64; 6]>,
    /// At rest: the body's angular rate stays below this over the settling window (rad/s).
    #[serde(default = "default_rest_rate")]
    pub rest_rate: f64,
    /// RK4 steps per control step in the closed loops (the hand–wall contact is stiff).
    #[serde(default = "default_substeps")]
    pub substeps: usize,
    /// Scales of the reaches' state weights (`terminal_weights` and `hold_weights` × scale:
    /// a slower, less decisive reach as the scale falls) tried in the listed order:
    /// the run uses the first at which, with the first tug alone, LBC's weights have not
    /// committed (both below [`COMMITTED`]) before the second tug starts
    /// ([`choose_reach_scale`]); the first listed when none (premise not reproduced). Empty:
    /// scale 1 alone, as before.
    #[serde(default)]
    pub reach_scales: Vec<f64>,
}

/// A weight has committed to one reach once it exceeds this (the side threshold of
/// [`swings`]: above 0.75 is a side).
pub const COMMITTED: f64 = 0.75;

/// The reach-scale rule (ours, written in the spec before the run): of the trials
/// `(scale, largest weight of either reach before the second tug)` in the order tried, the
/// index of the first whose weight stayed below `threshold` (NaN: committed); `None` when the
/// weights committed at every scale.
pub fn choose_reach_scale(trials: &[(f64, f64)], threshold: f64) -> Option<usize> {
    trials.iter().position(|&(_, w)| w < threshold)
}

fn default_substeps() -> usize {
    10
}

fn default_rest_rate() -> f64 {
    f64::INFINITY
}

impl Validate for Params {
    fn validate(&self) -> Result<(), ParamError> {
        positive("horizon", self.horizon)?;
        positive("dt", self.dt)?;
        ensure(
            self.horizon >= 2.0 * self.dt,
            "horizon",
            "must cover at least two steps",
        )?;
        ensure(
            self.lean.is_finite() && self.lean.abs() < 1.0,
            "lean",
            "must be in (-1, 1) rad",
        )?;
        for (i, w) in self.terminal_weights.iter().enumerate() {
            positive(&format!("terminal_weights[{i}]"), *w)?;
        }
        positive("control_weight", self.control_weight)?;
        for (i, l) in self.torque_limits.iter().enumerate() {
            positive(&format!("torque_limits[{i}]"), *l)?;
        }
        positive("torque_noise", self.torque_noise)?;
        ensure(
            self.settle_window[0] >= 0.0
                && self.settle_window[0] < self.settle_window[1]
                && self.settle_window[1] <= self.horizon,
            "settle_window",
            "must be [start, end] with 0 <= start < end <= horizon",
        )?;
        positive("settle_tolerance", self.settle_tolerance)?;
        positive("mirror_tolerance", self.mirror_tolerance)?;
        positive("fall_angle", self.fall_angle)?;
        ensure(
            self.max_iterations >= 1,
            "max_iterations",
            "must be at least 1",
        )?;
        for (i, l) in self.lambda_sweep.iter().enumerate() {
            positive(&format!("lambda_sweep[{i}]"), *l)?;
        }
        distinct("lambda_sweep", &self.lambda_sweep)?;
        if let Some(w) = &self.hold_weights {
            for (i, v) in w.iter().enumerate() {
                ensure(
                    *v >= 0.0 && v.is_finite(),
                    &format!("hold_weights[{i}]"),
                    "must be >= 0",
                )?;
            }
        }
        positive("rest_rate", self.rest_rate)?;
        positive("walls.distance", self.walls.distance)?;
        positive("walls.stiffness", self.walls.stiffness)?;
        ensure(
            self.walls.damping >= 0.0 && self.walls.damping.is_finite(),
            "walls.damping",
            "must be >= 0",
        )?;
        ensure(
            (1..=1000).contains(&self.substeps),
            "substeps",
            "must be in 1..=1000",
        )?;
        for (i, v) in self.reach_scales.iter().enumerate() {
            positive(&format!("reach_scales[{i}]"), *v)?;
        }
        distinct("reach_scales", &self.reach_scales)?;
        ensure(
            self.reach_scales.is_empty() || self.tugs.len() >= 2,
            "reach_scales",
            "the reach-scale rule needs at least two tugs (it watches the weights until the second)",
        )?;
        for (i, t) in self.tugs.iter().enumerate() {
            ensure(
                t.start >= 0.0 && t.start.is_finite(),
                &format!("tugs[{i}].start"),
                "must be >= 0",
            )?;
            positive(&format!("tugs[{i}].duration"), t.duration)?;
            ensure(
                t.force.is_finite(),
                &format!("tugs[{i}].force"),
                "must be finite",
            )?;
        }
        Ok(())
    }
}

impl Family for LbcPush {
    const CAPTIONS: &'static [(&'static str, &'static str)] = &[
        ("entropy", "the normalized entropy of LBC's weights α at every control step (1: uniform, 0: one controller takes over), per run; where α stays at the fixed weights LBC is the naive blend by construction."),
        (
            "weights",
            "under scripted tugs on the hand: LBC's blend weight of the forward reach, the hand's position, and the body's lean with LBC and with no reach beside the fall angle.",
        ),
    ];
    const KIND: &'static str = "lbc_push_recovery";
    type Params = Params;

    fn figures(&self, fig: &FigureSink, tables: &Tables) -> Result<Vec<PathBuf>, Error> {
        figures::figures(fig, tables)
    }

    fn report(&self, dir: &Path) -> Result<Findings, Error> {
        report::report(dir)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bellman::combine::{BlendMode, TrackerBlend};
    use crate::experiment::other;
    use std::f64::consts::FRAC_PI_2;

    fn spec_params() -> Params {
        let text = std::fs::read_to_string(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/experiments/lbc_push_recovery.toml"
        ))
        .unwrap();
        let spec: toml::Table = toml::from_str(&text).unwrap();
        spec["params"].clone().try_into().unwrap()
    }

    /// The spec's calibration of the tug force by the premise alone (no LBC run): the tugs'
    /// force is the smallest candidate whose no-reach runs lean the body beyond the fall angle.
    /// Prints the no-reach lean of each candidate (`-- --nocapture`).
    #[test]
    fn the_tug_force_is_the_smallest_candidate_that_topples_the_body() {
        let p = spec_params();
        let toppling = [40.0, 80.0, 120.0, 160.0, 200.0, 250.0, 300.0]
            .into_iter()
            .find(|&f| {
                let mut q = p.clone();
                for (g, o) in q.tugs.iter_mut().zip(&p.tugs) {
                    g.force = f * o.force.signum();
                }
                let lean = q.no_reach_lean().unwrap();
                println!(
                    "force {f} N: no-reach lean {lean:.4} rad (fall angle {})",
                    p.fall_angle
                );
                lean > p.fall_angle
            });
        assert!(
            p.tugs.iter().all(|g| Some(g.force.abs()) == toppling),
            "{toppling:?}"
        );
    }

    #[test]
    fn the_reach_scale_is_the_first_whose_weights_have_not_committed_by_the_second_tug() {
        let trials = [(1.0, 1.0), (0.3, 0.8), (0.1, 0.74), (0.03, 0.6)];
        assert_eq!(choose_reach_scale(&trials, COMMITTED), Some(2));
        // Exactly at the threshold is committed; NaN is committed.
        assert_eq!(
            choose_reach_scale(&[(1.0, 0.75), (0.5, f64::NAN)], COMMITTED),
            None
        );
        assert_eq!(choose_reach_scale(&[], COMMITTED), None);
    }

    #[test]
    fn reach_scales_validate_and_default_to_none() {
        let p = spec_params();
        for (bad, key) in [
            (vec![1.0, 0.0], "reach_scales[1]"),
            (vec![f64::NAN], "reach_scales[0]"),
            (vec![1.0, f64::INFINITY], "reach_scales[1]"),
            (vec![0.5, 0.5], "reach_scales[1]"),
        ] {
            let q = Params {
                reach_scales: bad,
                ..p.clone()
            };
            assert_eq!(q.validate().unwrap_err().key, key);
        }
        let q = Params {
            reach_scales: vec![1.0, 0.5],
            tugs: p.tugs[..1].to_vec(),
            ..p.clone()
        };
        assert_eq!(q.validate().unwrap_err().key, "reach_scales");
        let json = serde_json::to_value(&p).unwrap();
        let mut obj = json.as_object().unwrap().clone();
        obj.remove("reach_scales");
        let back: Params = serde_json::from_value(obj.into()).unwrap();
        assert!(back.reach_scales.is_empty());
        // The scale multiplies every state weight of the reaches, and nothing else.
        let s = p.scaled(0.5);
        assert_eq!(s.terminal_weights[0], 0.5 * p.terminal_weights[0]);
        assert_eq!(
            s.hold_weights.map(|w| w[1]),
            p.hold_weights.map(|w| 0.5 * w[1])
        );
        assert!(s.reach_scales.is_empty() && s.control_weight == p.control_weight);
    }

    #[test]
    fn swings_need_both_sides_and_ignore_wobbles_at_one_half() {
        let t: Vec<f64> = (0..8).map(|k| k as f64).collect();
        // Rounding wobbles at a symmetric start, then one decision: no swing.
        let a = [0.5, 0.5 + 1e-15, 0.5 - 1e-15, 0.5, 0.9, 1.0, 1.0, 1.0];
        assert_eq!(swings(&t, &a, 10.0), 0);
        // Forward, undecided, backward, forward: two swings; the last one after `before`.
        let b = [0.9, 0.6, 0.1, 0.4, 0.8, 0.2, 0.2, 0.2];
        assert_eq!(swings(&t, &b, 10.0), 3);
        assert_eq!(swings(&t, &b, 5.0), 2);
    }

    #[test]
    fn closed_loop_torques_respect_the_limits() {
        let p = spec_params();
        let (trackers, _) = p.reaches().unwrap();
        let blend = TrackerBlend {
            trackers: &trackers,
            weights: vec![1.0, 1.0],
            lambda: p.lambda(),
            limits: Some(&p.torque_limits),
            mode: BlendMode::Lbc,
        };
        let mut peak = [0.0f64; 3];
        let mut ui = [0.0; 3];
        p.rollout(1.0, |x, k, u, alpha| {
            blend.control(x, k, u, alpha, &mut ui).map_err(other)?;
            for i in 0..3 {
                peak[i] = peak[i].max(u[i].abs());
            }
            Ok(())
        })
        .unwrap();
        for i in 0..3 {
            assert!(
                peak[i] <= p.torque_limits[i] + 1e-12,
                "motor {i}: {}",
                peak[i]
            );
        }
        // The limits bind somewhere (a check of clamping, not of idle motors).
        assert!(
            (0..3).any(|i| peak[i] > 0.99 * p.torque_limits[i]),
            "{peak:?}"
        );
    }

    #[test]
    fn without_a_reach_the_tugs_topple_the_body() {
        let p = spec_params();
        assert!(p.no_reach_lean().unwrap() > p.fall_angle);
        // And with no tugs the held pose stands.
        let mut still = p.clone();
        still.tugs.clear();
        assert!(still.no_reach_lean().unwrap() < 0.01);
    }

    #[test]
    fn a_pose_towards_the_front_hold_prefers_the_forward_reach() {
        let text = std::fs::read_to_string(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/experiments/lbc_push_recovery.toml"
        ))
        .unwrap();
        let spec: toml::Table = toml::from_str(&text).unwrap();
        let p: Params = spec["params"].clone().try_into().unwrap();
        let (trackers, _) = p.reaches().unwrap();
        let x0 = p.start();
        for k in [0, p.steps() / 4, p.steps() / 2, 3 * p.steps() / 4] {
            let mut x = x0.clone();
            x[1] += 0.5; // arm rotated forward
            let (vf, vb) = (
                trackers[0].value(x.as_slice(), k),
                trackers[1].value(x.as_slice(), k),
            );
            // Mirror-image reaches: equal values on the reference, lower forward value when the
            // arm is displaced towards the front hold.
            assert!(
                (trackers[0].value_ref[k] - trackers[1].value_ref[k]).abs()
                    < 1e-6 * trackers[0].value_ref[k]
            );
            assert!(vf < vb, "step {k}: forward {vf} backward {vb}");
        }
    }

    #[test]
    fn mirrored_tugs_give_mirrored_choices_within_the_torque_limits() {
        let text = std::fs::read_to_string(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/experiments/lbc_push_recovery.toml"
        ))
        .unwrap();
        let spec: toml::Table = toml::from_str(&text).unwrap();
        let p: Params = spec["params"].clone().try_into().unwrap();
        let (trackers, _) = p.reaches().unwrap();
        let tugged = p.closed_loop(&trackers, 1.0, p.lambda()).unwrap();
        let mirrored = p.closed_loop(&trackers, -1.0, p.lambda()).unwrap();
        // The tugs move the choice (so the mirror check is not about a constant 1/2).
        assert!(tugged.iter().any(|r| r[0] > 0.75 || r[0] < 0.25));
        for (k, (a, m)) in tugged.iter().zip(&mirrored).enumerate() {
            assert!(
                (a[0] - m[1]).abs() < 1e-6,
                "step {k}: forward {} vs mirrored backward {}",
                a[0],
                m[1]
            );
            // The body's lean is mirrored too.
            assert!(
                (a[3] - FRAC_PI_2 + (m[3] - FRAC_PI_2)).abs() < 1e-6,
                "step {k}"
            );
            assert_eq!(a[2], -m[2]);
        }
    }
}
