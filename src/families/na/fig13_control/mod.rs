//! `na_fig13_control` (NeuroAnimator §4, §6, Fig. 13): control learning by backpropagation
//! through time through trained N50 emulators ([`crate::control::bptt`]), one task per model:
//!
//! - **pendulum** (active, 3 joint torques): from hanging at rest, reach a pose with zero
//!   velocity at the end, under torque limits far below what holding the pose statically needs,
//!   so the controller must swing to build momentum (the paper: 20 iterations);
//! - **truck** (drive acceleration, steering): park at a position and heading (15), descent
//!   starting from a drive-then-brake (`initial_knots`; at rest the steering moves nothing);
//! - **lander** (thrust, 3 attitude torques): land softly at the pad, level (the paper's target
//!   set: position, attitude, descent velocity), from upright and still 60 m up beside it.
//!
//! The truck and the lander learn in equal-sensitivity control units under sensitivity weights
//! ([`ControlUnits`], [`FinalWeights`]), measured once per task through its Table 1 net
//! ([`Task::calibrated`]; `calibration.csv`); `conditioning_ladder.csv` shows the conditioning
//! from each formulation of ours to the paper's, one change at a time.
//!
//! Each task runs the paper's 20 s of animation (the pendulum 200 N50 steps of 0.1 s, the truck
//! and the lander 40 of 0.5 s) unless its `formulation` is `ours`: an earlier formulation of
//! this project (the 4 s pendulum, the truck from rest with all six variables weighted) kept
//! as a second line, reported and never counted in the
//! headline ([`Formulation`]).
//!
//! Each task: M emulator steps, K piecewise-constant knots per actuator within box bounds (a
//! fraction of the training limits), objective μ_u/2 Σ |(u − u_0)/c|² + ½ Σ_k (s_{M,k} −
//! s_{d,k})²/σ_k² (eq. 12 with a tolerance σ_k per state variable; u_0 is zero, or hover thrust
//! for the lander; c the training limits' half-widths), descent with momentum (eq. 14–15) with
//! η in units of 1/λ, λ the largest Hessian eigenvalue magnitude of J at the initial controls
//! (see [`crate::families::na::fig14_momentum`]).
//!
//! Tables: `objective` (task, iteration, objective), `final` (task, emulator_error,
//! simulator_error, best_iteration, formulation): the RMS of (s_M − s_d)/σ over the weighted state variables when the learned
//! controls drive the emulator and the physical simulator (≤ 1: within tolerance), and
//! `trajectory` (task, step, t, source, state variables s0 …) for both, and `goal` (task, model,
//! target state s0 …). Over the Table 1 net seeds ([`seeds`]): `net_seeds` and `net_lines`
//! (each with how many iterations the descent, continued, needs to reach the goal through the
//! net and through the physics), `path` (the descent through each net, replayed) and
//! `physics_path` (the descent through the physics, each net's gradient beside the physics').
//!
//! Figures: `control` (objectives and two state variables over time) and, per task of the
//! paper's formulation, an
//! animated GIF `<id>_<task>.gif` of the emulator-driven motion and its simulator replay over
//! the goal ([`anim`]).

pub mod anim;
mod conditioning;
pub mod dagger;
mod dolphin;
pub mod dolphin_dagger;
mod figures;
pub mod frames;
mod job;
mod params;
mod report;
pub mod rows;
pub mod seeds;
mod task;

pub use conditioning::{BEST_WEIGHTS_COLUMNS, CONDITIONING_COLUMNS};
pub use dolphin::learn_swim;
pub use job::{
    learn_and_replay, learn_best, stable_curvature_ratio, start_simulator_error, BestRollout,
    PATH_COLUMNS,
};
pub use params::{DolphinControl, Fig13Rule, Params, Sweep};
pub use task::{Calibration, ControlUnits, FinalWeights, Formulation, Task};

use crate::experiment::output::Tables;
use crate::experiment::plot::FigureSink;
use crate::experiment::report::Findings;
use crate::experiment::{Error, Family};
use std::path::{Path, PathBuf};

/// The family.
pub struct NaControl;

impl Family for NaControl {
    const CAPTIONS: &'static [(&'static str, &'static str)] = &[
        (
            "control",
            "per paper task (pendulum, truck, lander, dolphin): its objective over the iterations, then each goal variable's deviation from the goal in units of its tolerance along the emulator-driven motion and along the same controls replayed on the simulator (same colours), with the ±1 tolerance band (the dolphin: its mean centroid).",
        ),
        (
            "control_ours",
            "the same for our second formulations (not counted): the 4 s and 200-step pendulums, the truck from rest, the 13-variable lander and the 4 s dolphin.",
        ),
        (
            "spectrum",
            "eigenvalues of the terminal Gauss-Newton matrix over the knots at the start, through the emulator and the physics (log scale): the spread decides how many fixed-step iterations descent needs.",
        ),
        (
            "dagger",
            "final error (log scale) vs DAgger round, on the net and on the simulator replay, per task; 1 is the tolerance.",
        ),
        (
            "dolphin_dagger",
            "the dolphin's learned swim distance vs DAgger round on the net and on the simulator, beside the hand-made wave's distance and half of it.",
        ),
        (
            "net_seeds",
            "one panel per task: each net seed's final error through the emulator against its controls' final error replayed on the simulator, for the paper's pendulum, truck and lander tasks (and our 200-step pendulum, not counted) through Table 1 nets trained under five seeds; dots labelled by seed, 1 is the tolerance (lower left: at the goal on both).",
        ),
        (
            "pendulum",
            "the pendulum's learned swing-up: emulator-driven motion (purple), its simulator replay (grey), the goal pose (green).",
        ),
        (
            "truck",
            "the truck's learned parking: emulator-driven motion (purple), its simulator replay (grey), the goal (green).",
        ),
        (
            "lander",
            "the lander's learned landing: emulator-driven motion (purple), its simulator replay (grey), the pad (green).",
        ),
        (
            "dolphin",
            "the dolphin's learned swim: emulator-driven motion (purple) and its simulator replay (grey).",
        ),
    ];
    const KIND: &'static str = "na_fig13_control";
    type Params = Params;

    fn figures(&self, fig: &FigureSink, tables: &Tables) -> Result<Vec<PathBuf>, Error> {
        figures::figures(fig, tables)
    }

    fn report(&self, dir: &Path) -> Result<Findings, Error> {
        report::report(dir)
    }
}
