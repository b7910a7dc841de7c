//! `na_fig14_momentum` (NeuroAnimator §4.3, §6, Fig. 14): control learning for the lunar
//! lander through its N50 emulator, gradient descent with momentum (eq. 14–15) against plain
//! gradient descent (eq. 13), and a sweep of the plain learning rate.
//!
//! Task: soft landing. From a start state above and beside the pad, 40 emulator steps (20 s)
//! of piecewise-constant controls (20 knots per actuator, 80 in all, within the training
//! limits: thrust in [0, 2 m g], attitude torques within ±400 N·m) should bring the lander to
//! the target position on the ground (the gear touching it), upright, at rest. Objective
//! ([`crate::control::objective`]):
//!
//! ```text
//! J = μ_u/2 Σ_i |(u_i − u_hover)/c|² + ½ Σ_k (s_{M,k} − s_{d,k})²/σ_k² + ½ Σ_{i>M−w} v_{z,i}²/σ_v²
//! ```
//!
//! (effort about hover in units of the limits' half-widths c; the final state with a tolerance
//! σ_k per variable; the descent velocity over the last w states before touchdown).
//!
//! **Learning-rate units.** The paper's η refer to its own (unstated) normalization. Here the
//! knots are normalized to [−1, 1] within their bounds and the step is η ∇J / λ, where λ is the
//! largest Hessian eigenvalue magnitude of J at the initial controls (hover), measured once per
//! problem by power iteration ([`crate::control::bptt::Bptt::curvature`]). On a quadratic this
//! makes plain descent stable for η < 2 and momentum with α = 0.5 for η < 3; the sweep shows
//! where plain descent actually stops converging on this non-quadratic problem. λ is not tuned
//! to make η = 1 the limit.
//!
//! Tables: `objective` (method, eta, alpha, iteration, objective), `gradient` (method, eta,
//! alpha, iteration, grad_norm) and `runs` (method, eta, alpha, scale, initial_objective,
//! final_objective, min_objective, emulator_landing_error, simulator_landing_error,
//! emulator_final_speed, simulator_final_speed, final_gap): landing errors are the distance of
//! the final centre of mass to the target (m) when the learned controls drive the emulator and
//! the physical simulator; the gap is |s_emulated − s_simulated| at the end. `trajectory`
//! (method, eta, step, t, source, x, y, z, vz, tilt): every run's states at the emulator step
//! times, emulated and simulated (tilt: angle of the thrust axis from vertical, rad).
//! `unclipped` ([`UnclippedRow`]) and `unclipped_objective` (method, eta, alpha,
//! iteration, objective): every descent again with its knots free of the actuators' boxes
//! (ours), drawn as the figure's last panel.
//!
//! **Through the DAgger net (ours).** With `[params.dagger]`, momentum and plain
//! descent (same η, α, iterations) also learn through the lander's final-round DAgger net of
//! `na_fig13_control` ([`crate::families::na::fig13_control::dagger`]; its task, learner and
//! settings are rebuilt here from this spec so its cache key is Fig. 13's), λ re-measured at
//! hover on that net, and both runs' controls are replayed on the simulator. `dagger`
//! (net, round, method, eta, alpha, the `runs` columns from scale to final_gap,
//! emulator_final_error, simulator_final_error): the Table 1 net's two runs (round 0) and the
//! DAgger net's; final error = RMS over the weighted state variables of (s_M − s_d)/σ (Fig. 13's
//! measure, ≤ 1: within tolerance). `dagger_objective` (method, eta, alpha, iteration,
//! objective): the DAgger-net curves.
//!
//! **Over the Table 1 net seeds (ours).** One trained net is one draw of the training's
//! randomness, so the headline's descents (momentum and plain descent at every rate of the
//! sweep) are learned again through the Table 1 lander net trained under each of
//! [`Params::net_seeds`] (each calibrated at hover and λ measured there, as a run under that
//! seed would): `net_seeds` ([`NetSeedRow`]), the run's own seed included.
//! The verdict reads the median over the seeds of momentum's iterations to plain's final J
//! over plain's, with its 95% bootstrap interval, and counts the seeds at which plain's rate
//! converges and is the limit (report.rs). The other tables are the run's own net's.

mod figures;
mod job;
mod params;
mod report;
mod rows;

pub use params::{Converged, DaggerNet, Fig14Rule, MomentumDagger, Params};
pub use report::iterations_to;
pub use rows::{
    ConvergedRow, DaggerRow, GradientRow, Method, NetSeedRow, ObjectiveRow, RunRow, Scores,
    UnclippedRow,
};

use crate::experiment::output::Tables;
use crate::experiment::plot::FigureSink;
use crate::experiment::report::Findings;
use crate::experiment::{Error, Family};
use std::path::{Path, PathBuf};

/// The family.
pub struct NaMomentum;

impl Family for NaMomentum {
    const CAPTIONS: &'static [(&'static str, &'static str)] = &[
        (
            "objective",
            "the lander's objective J (log scale) vs iteration: momentum (η 1.5, α 0.5) beside plain descent at each η, with the knots clipped to their boxes and without.",
        ),
        (
            "net_seeds",
            "per Table 1 lander net seed (dots, labelled with the seed), momentum's iterations to plain descent's final J over plain's iterations, the verdict's measure; the median over the seeds with its 95% bootstrap interval, the held bar and plain descent itself (1, the null).",
        ),
    ];
    const KIND: &'static str = "na_fig14_momentum";
    type Params = Params;

    fn figures(&self, fig: &FigureSink, tables: &Tables) -> Result<Vec<PathBuf>, Error> {
        figures::figures(fig, tables)
    }

    fn report(&self, dir: &Path) -> Result<Findings, Error> {
        report::report(dir)
    }
}
