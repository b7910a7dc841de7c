//! # motionlab
//!
//! A research harness that reproduces, from scratch, the tables and figures of three papers on
//! physics-based animation control — NeuroAnimator (Grzeszczuk, Terzopoulos, Hinton 1998),
//! mass-spring motion synthesis (Christensen, Marks, Ngo 1995) and linear Bellman combination
//! (da Silva, Durand, Popović 2009) — and goes beyond them.
//!
//! ## Crate map
//!
//! - [`physics`]: the [`physics::Dynamics`] / [`physics::Ode`] traits, the
//!   [`physics::DifferentiableStep`] trait (a discrete step with its vector–Jacobian product,
//!   what BPTT needs; implemented by emulators and by the RK4 step of any
//!   [`physics::linearize::Linearize`] model), integrators (explicit and semi-implicit Euler,
//!   RK4, fixed-step Dormand–Prince, adaptive RK45) and one module per model: [`physics::pendulum::Pendulum3`] (3-link pendulum: passive, active, ext. force),
//!   [`physics::truck::Truck`], [`physics::lander::Lander`], [`physics::acrobot::Acrobot`]
//!   (two-link gymnast), and planar articulated trees ([`physics::planar::PlanarTree`]) for the
//!   diver and the push-recovery figure.
//! - [`physics::lattice`] and [`physics::reflex`]: 3-D mass-spring lattices (cube, pyramid,
//!   chair) with floor contact and directional friction, and the 12 deformation reflexes of
//!   mass-spring motion synthesis; [`physics::dolphin::Dolphin`], the muscle-driven
//!   mass-spring-damper swimmer of NeuroAnimator.
//! - [`synthesis`]: mass-spring motion synthesis — time-based reflex controllers, the Table 1
//!   objective terms, the Table 2 perturbations as a search operator; parallel hill climbing
//!   and simulated annealing come from [`control::search`].
//! - [`emulator`]: NeuroAnimator emulators — a sigmoid MLP with backprop to weights and inputs,
//!   the delta / local-frame / normalization transforms, and training (argmin CG or L-BFGS,
//!   momentum mini-batches) with early stopping; [`emulator::hierarchy`]: the hierarchical
//!   dolphin (a global net over the 6 segment frames, a local net per segment) and the §5.3
//!   regularization steps.
//! - [`control`]: optimal control on the RK4-discretized dynamics of any
//!   [`physics::linearize::Linearize`] model — [`control::ddp`] (iLQR and full second-order
//!   DDP with regularization, line search and box bounds) and [`control::lqr`] (time-varying
//!   LQR tracking with the quadratic value function of linear Bellman combination, eq. 12) and
//!   [`control::step_tracker`] (the same tracker along a tape learned through an emulator,
//!   from the emulator's exact Jacobians);
//!   NeuroAnimator control learning: [`control::objective`] (composable objective terms with
//!   gradients) and [`control::bptt`] (backpropagation through time through any differentiable
//!   step — an emulator or a simulator's RK4 step; plain and momentum descent on bounded
//!   piecewise-constant controls);
//!   [`control::search`]: the one search library, with one trace and budget — simulated
//!   annealing and parallel hill climbing generic over a proposal operator (box steps or the
//!   mass-spring reflex perturbations), Nelder–Mead and BPTT — on emulator or simulator
//!   rollouts of the same controller (§6 baselines) or on reflex controllers.
//! - [`bellman`]: linear Bellman combination; [`bellman::projection`] projects a desired
//!   Gaussian terminal reward onto component rewards (A w = b, analytic inner products),
//!   [`bellman::combine`] computes the blend weights α in log space, [`bellman::grid_dp`]
//!   solves 2-D problems on a grid (linearly-solvable and ordinary Bellman backups);
//!   it combines anything implementing [`control::tracker::ValueTracker`], the
//!   value-function contract DDP/LQR and emulator-derived trackers share.
//! - [`experiment`]: the harness — experiments as data: TOML specs, validation with
//!   file/line/key errors, sweeps, the runner (CSV + Parquet, atomic writes, `run.json`),
//!   figures and `REPORT.md`; the [`experiment::Experiment`] / [`experiment::Job`] traits a
//!   family implements. It runs whatever [`experiment::Registry`] it is handed and names no
//!   family.
//! - [`families`]: the experiment families, one folder per paper, one file (or folder: params,
//!   job, figures, report) per experiment id (without the paper prefix), and the registry of
//!   families `main.rs` hands to the harness ([`families::registry`]; an id → file table is in
//!   the module doc).
//!   - [`families::na`]: NeuroAnimator — the Table 1 nets and their training
//!     ([`families::na::table1_structure`], which also builds the cached emulators the other
//!     `na_*` families use), Table 2 speedups, §5.3 regularization, Fig. 12 error, Fig. 13
//!     BPTT control with animated GIFs ([`families::na::fig13_control`]), Fig. 14 momentum and
//!     the §6 swim baselines; Fig. 13 and the baselines share the dolphin swim task
//!     ([`families::na::swim`]).
//!   - [`families::ms`]: mass-spring motion synthesis — the lattices and reflexes, the
//!     hill-climbing / annealing search jobs ([`families::ms::search`]) behind the three motions
//!     ([`families::ms::motion`]) and the Fig. 6 learning plot, and 3-D lattice drawing
//!     ([`families::ms::lattice_draw`]).
//!   - [`families::lbc`]: linear Bellman combination — reward projection, grid optimality, the
//!     acrobot swing-up, the diver's interpolation and coordination (one folder,
//!     [`families::lbc::diver`]) and push recovery.
//!   - [`families::beyond`]: beyond the papers — `physics_validation` (integrator energy drift
//!     and convergence orders) and `x_lbc_emulator` (linear Bellman combination of
//!     controllers learned through a NeuroAnimator emulator).
//! - [`mod@bench`]: throughput of the hot loops (`motionlab bench`).
//! - [`verbs`]: `motionlab simulate` and `emulate` — their inputs checked before any work
//!   ([`verbs::check_run`], [`verbs::Controls`], [`verbs::MAX_STEPS`]) and their rows streamed
//!   as computed; above [`families`] (it steps a Table 1 emulator), below `main.rs`.
//! - [`linalg`]: the one conversion point between ndarray and nalgebra types.
//! - [`seed`]: deterministic seed splitting ([`seed::mix_seed`]), one random stream per job.
//! - [`params`]: the settings-validation vocabulary every layer uses ([`params::ParamError`]
//!   names the key and says what is wrong; [`params::ensure`]); it imports nothing else of the
//!   crate, so solvers check their own settings without knowing the harness.
//!
//! Imports go downwards only: [`physics`] at the bottom; [`emulator`], [`control`] (whose
//! tracker contract [`bellman`] combines) and [`synthesis`] above it; the harness
//! ([`experiment`]) above those, knowing no family; [`families`] above the harness; `main.rs`
//! on top, handing the harness the registry.
//!
//! ## Models and algorithms
//!
//! | name | where | what |
//! | --- | --- | --- |
//! | `pendulum3`, `pendulum3_passive`, `pendulum3_ext` | [`physics::pendulum`] | planar 3-link pendulum, full articulated dynamics |
//! | `acrobot` | [`physics::acrobot`] | point-mass acrobot, torque at the hip |
//! | `truck` | [`physics::truck`] | bicycle-model truck with saturating tyre forces |
//! | `lander` | [`physics::lander`] | 3-D rigid-body lunar lander, quaternion attitude |
//! | `dolphin` | [`physics::dolphin`] | 23-mass dolphin, 6 muscles, hydrodynamic drag |
//! | `diver`, `push_recovery` | [`physics::diver`], [`physics::push`] | planar articulated trees ([`physics::planar`]) |
//! | `chain3d` | [`physics::body3d`] | 3-D articulated tree (floating base, ball and revolute joints), checked against MuJoCo |
//! | `leaper3d` | [`physics::body3d`] | 3-D human-like biped on the ground (de Leva 1996 segments; stand-in for Laszlo et al. 1996) |
//! | `euler`, `semi_implicit_euler`, `rk4`, `dopri5`, `rk45` | [`physics::integrate`] | time integrators |
//! | DDP / iLQR, LQR tracking | [`control::ddp`], [`control::lqr`] | trajectory optimization, eq. 12 value functions |
//! | LQR trackers of emulator tapes | [`control::step_tracker`], [`control::tracker`] | LBC §5.2 on NeuroAnimator BPTT tapes |
//! | hierarchical dolphin emulator, regularization | [`emulator::hierarchy`] | NeuroAnimator §3.3, §5.3 |
//! | BPTT control learning, plain / momentum descent | [`control::bptt`], [`control::objective`] | NeuroAnimator §4, eq. 11–15 |
//! | simulated annealing, parallel hill climbing (any proposal operator), Nelder–Mead | [`control::search`] | NeuroAnimator §6 baselines; mass-spring Fig. 4, 6 |
//! | Gaussian reward projection | [`bellman::projection`] | LBC §4.1 fixed weights |
//! | z-weights, log-sum-exp | [`bellman::combine`] | LBC eq. 1, 11 |
//! | grid DP (linear / ordinary backup) | [`bellman::grid_dp`] | LBC §5.2, Todorov 2009 |
//!
//! ## Example
//!
//! Simulate the acrobot hanging at rest, and blend two controllers' values the LBC way:
//!
//! ```
//! use motionlab::physics::{acrobot::Acrobot, IntegratorKind, Simulator};
//! use motionlab::bellman::combine::blend_weights;
//!
//! let mut sim = Simulator::new(Acrobot::default(), IntegratorKind::Rk4);
//! let hanging = [-std::f64::consts::FRAC_PI_2, 0.0, 0.0, 0.0];
//! let x = sim.rollout(&hanging, 0.01, 100, |_, _, _, _| {}, |_, _, _| {}).unwrap();
//! assert!((x[0] - hanging[0]).abs() < 1e-12);
//!
//! let mut alpha = [0.0; 2];
//! let v = blend_weights(&[1.0, 1.0], &[1e4, 1e4 + 1.0], 1.0, &mut alpha).unwrap();
//! assert!(alpha[0] > alpha[1] && v < 1e4);
//! ```
#![warn(missing_docs)]
// Tests build inputs and reference values with the platform's elementary functions: the
// portable-math rule (clippy.toml) guards the numbers the library computes, not the tests' own.
#![cfg_attr(test, allow(clippy::disallowed_methods))]

pub mod bellman;
pub mod bench;
pub mod control;
pub mod emulator;
pub mod experiment;
pub mod families;
pub mod fastmath;
pub mod lanes;
pub mod linalg;
pub mod params;
pub mod physics;
pub mod portable;
pub mod seed;
pub mod simd;
pub mod synthesis;
pub mod verbs;
