//! `x_lbc_emulator` (beyond the papers): linear Bellman combination (da Silva et al. 2009) of
//! controllers learned by backpropagation through time through a NeuroAnimator emulator
//! (Grzeszczuk et al. 1998).
//!
//! The lunar lander (N50 catalog net, the one `na_fig13_control` uses) lands softly from the
//! Fig. 13 start at two targets that differ only along one axis (`axis`, x by default) at
//! `components[0]` and `components[1]`. Each is learned by BPTT with Levenberg–Marquardt
//! steps through the emulator (the Fig. 13 objective: μ_u/2 Σ |v|² + ½ Σ_k (s_M,k − s_d,k)²/σ_k²
//! in normalized controls v = (u − u_c)/c, |v| ≤ 1 the actuator box). Along each emulated tape
//! the emulator is linearized by its exact Jacobians and an LQR tracker with the eq. 12 value
//! function built for the same objective ([`crate::control::step_tracker`]): cost
//! dt·½ vᵀ(μ_u/Δt)v per super-step of Δt, terminal Σ_k (s_k − s_d,k)²/(2σ_k²).
//!
//! **Noise model and λ.** With control cost ½ vᵀRv, R = μ_u/Δt, the linear Bellman equation
//! holds for white noise on v of covariance λR⁻¹ (LBC eq. 8); the spec states its intensity σ_u
//! (half-widths·√s), so λ = σ_u² R. The weights w for a desired target d on the axis come from
//! projecting exp(−q (x − d)²) onto exp(−q (x − c_i)²) with q = Q_axis/λ (§4.1; the components'
//! other terminal terms are equal and drop out).
//!
//! **Compared on the physical simulator** (RK4, the control held over each super-step, the state
//! fed back once per super-step), per desired target: `lbc` (α_i ∝ w_i exp(−v̂_i/λ)), `naive`
//! (fixed w/Σw), `tracker1`, `tracker2` (each component alone, closed loop), `open_loop1`,
//! `open_loop2` (each component's tape replayed), `bptt` (BPTT re-optimized from scratch for the
//! desired target, its tape replayed: the ground truth of what the emulator can learn, with its
//! wall time) and `bptt_tracked` (that tape with its own emulator tracker, closed loop). The
//! same policies are also run on the emulator (`final_error_emulator`). Final error: RMS of
//! (s_M − s_d)/σ over the state (≤ 1: within tolerance), s_d the desired target.
//!
//! Tables: `targets` (desired_target, method, final_error_emulator, final_error_simulator,
//! effort, seconds, weight1, weight2, final_axis_value, mean_entropy), `components` (component,
//! target, learn_seconds, tracker_seconds, iterations, objective, emulator_error,
//! open_loop_simulator_error, tracked_simulator_error), `trajectory` (desired_target, method,
//! step, t, s0 … on the simulator), `goal` (desired_target, s0 …: the target state), `rule`. `effort` is ½ Σ_k |v_k|² over the super-steps,
//! `seconds` the wall time to obtain the controller for that target (BPTT: learning; LBC and
//! naive: projecting the weights; the components' own costs are in `components`),
//! `final_axis_value` the simulator's final value along the axis (m),
//! `mean_entropy` the mean normalized entropy of the blend weights α over the super-steps on the
//! simulator (0: one component, 1: even; NaN for the open-loop replays and where extrapolation
//! makes a weight negative).

mod figures;
mod job;
mod params;
mod report;

pub use params::Params;

use crate::experiment::output::Tables;
use crate::experiment::plot::FigureSink;
use crate::experiment::report::Findings;
use crate::experiment::{Error, Family};
use std::path::{Path, PathBuf};

/// The family.
pub struct XLbcEmulator;

/// The compared methods ([module docs](self)), in table order.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Method {
    /// LBC's blend of the two trackers.
    Lbc,
    /// The blend with the projected weights held fixed.
    Naive,
    /// Component 1's tracker alone.
    Tracker1,
    /// Component 2's tracker alone.
    Tracker2,
    /// Component 1's tape replayed.
    OpenLoop1,
    /// Component 2's tape replayed.
    OpenLoop2,
    /// BPTT re-optimized for the desired target, its tape replayed.
    Bptt,
    /// That tape with its own emulator tracker.
    BpttTracked,
}

impl Method {
    /// Every method, in table order.
    const ALL: [Method; 8] = [
        Method::Lbc,
        Method::Naive,
        Method::Tracker1,
        Method::Tracker2,
        Method::OpenLoop1,
        Method::OpenLoop2,
        Method::Bptt,
        Method::BpttTracked,
    ];

    /// The name the tables write (`method`).
    fn name(self) -> &'static str {
        match self {
            Method::Lbc => "lbc",
            Method::Naive => "naive",
            Method::Tracker1 => "tracker1",
            Method::Tracker2 => "tracker2",
            Method::OpenLoop1 => "open_loop1",
            Method::OpenLoop2 => "open_loop2",
            Method::Bptt => "bptt",
            Method::BpttTracked => "bptt_tracked",
        }
    }
}

impl Family for XLbcEmulator {
    const CAPTIONS: &'static [(&'static str, &'static str)] = &[
        ("entropy", "the normalized entropy of LBC's weights α at every control step (1: uniform, 0: one controller takes over), per run; where α stays at the fixed weights LBC is the naive blend by construction."),
        (
            "error",
            "final error vs the desired landing x, on the physical simulator and on the emulator, for LBC, the naive blend, each tracker, each open-loop tape and BPTT re-optimized (1 is the tolerance), and on the simulator how far along x from the desired target each lands (the verdict's third measure).",
        ),
        (
            "lbc",
            "LBC's landing on the simulator at the in-between target nearest the middle, in real time.",
        ),
    ];
    const KIND: &'static str = "x_lbc_emulator";
    type Params = Params;
    const BEYOND: bool = true;

    fn figures(&self, fig: &FigureSink, tables: &Tables) -> Result<Vec<PathBuf>, Error> {
        figures::figures(fig, tables)
    }

    fn report(&self, dir: &Path) -> Result<Findings, Error> {
        report::report(dir)
    }
}
