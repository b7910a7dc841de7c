//! # The emulated models of NeuroAnimator's Table 1, and how each is built
//!
//! [`NetModel`] names a physical model together with everything needed to emulate it: its
//! physical simulator (RK4 at δt), the distribution of episode start states and the typical
//! controls used to sample training data (§3.4, [`super::dataset`]), and the transforms the paper
//! recommends (§3.2–3.3: the state change and normalization for all, the local frame for the
//! rigid bodies that move freely, the truck and the lander). [`NetSpec`] adds the network size,
//! the super timestep n and the number of examples; [`train_emulator`] samples, fits the
//! transforms, trains with early stopping on a held-out set and returns the emulator.
//!
//! Adding a model (e.g. the dolphin) means adding a variant here: its simulator, start states,
//! control limits and transforms; experiments then list it in their `nets` tables.
//!
//! ## Where the data come from: typical manoeuvres, or the whole box
//! §4 samples "those state, force, and control inputs that typically occur as a physics-based
//! model is used in practice", under "typical control input functions" (Fig. 8). A net's
//! [`DataRegime`] says which data it is trained on:
//!
//! - **Typical** (the default; [`NetModel::control_process_in`], [`NetModel::sampling_limits`],
//!   [`NetModel::typical_start_state`]): paired manoeuvres ([`ControlProcess::Manoeuvre`]), each
//!   knot held U[0.5, 2] s (pendulums U[0.5, 1.5] s) and followed by its mirror image about the
//!   box's centre, a quarter idle, the truck's drive and the lander's channels at an amplitude
//!   log-uniform over two decades of their half-range per episode (the truck's steering and
//!   the pendulums' torques and forces always over their whole box, which for the pendulums is
//!   the swing-up task's torque limit). Starts: the pendulums
//!   hanging at rest in a quarter of the episodes, else swinging link 1 in the swing mode at an
//!   amplitude U[0, 1] rad, the elbows at U[−0.2, 0.2] rad and U[−1, 1] rad/s; the truck anywhere
//!   at any heading, at rest in half the episodes, else at U[−2, 2] m/s along its heading; the
//!   lander upright within 0.1 rad, velocity U[−5, 5] m/s per axis, body rates zero in half,
//!   else U[−0.05, 0.05] rad/s.
//! - **Box** ([`NetModel::control_process`], [`NetModel::start_state`]; ours before, kept as a
//!   second line): knots uniform over the whole control box from wide starts, as follows.
//!   - Pendulum (all variants): joint angles q_i ~ U[−0.7, 0.7] rad, joint rates
//!     q̇_i ~ U[−1, 1] rad/s; episodes of 20 s. Active: motor torques within ±(2.5, 1.5, 0.5) N·m
//!     (about a fifth of the gravity torque each joint holds horizontal: 12.3, 7.4, 2.5 N·m);
//!     ext. force: also link forces within ±2 N. Controls are smooth random functions with knots
//!     every 0.3–1.5 s.
//!   - Truck: centre of mass uniform in a 100 m square, heading uniform, no sideways or yaw
//!     rate; forward speed 0 (at rest) in a quarter of the episodes, U[−1, 1.5] m/s
//!     (manoeuvring) in a third, else U[−3, 8] m/s; drive acceleration within ±3 m/s² and
//!     steering within ±0.5 rad, piecewise constant for 0.5–2 s, with a quarter of the knots
//!     idle (no drive, wheels straight) and half of the first knots; episodes of 10 s.
//!   - Lander: centre of mass uniform in a 100 m square at 20–200 m height, yaw uniform, tilt up
//!     to 0.4 rad about a random horizontal axis, velocity U[−5, 5] m/s per axis, body rates
//!     U[−0.2, 0.2] rad/s (zero in a quarter of the episodes); thrust within [0, 2 m g] (twice
//!     hover), attitude torques within ±400 N·m (a fifth of the jets' limit), piecewise
//!     constant for 0.5–2 s, with a quarter of the knots' torques idle; episodes of 10 s.
//!
//! - **Regime** (ours; the Table 1 truck's and lander's data, which their experiment files
//!   name): the typical manoeuvres with each control channel that the Fig. 13 tasks' regime
//!   bounds ([`NetModel::regime_control_box`]: the truck's drive, the lander's thrust and roll
//!   and pitch torques) sampled inside that bound instead of the whole box, the same amplitudes
//!   relative to it; the starts are the typical ones. Table 1's fidelity on the tasks' inputs
//!   is measured on it ([`regime_fidelity`]).
//!
//! The regimes share the control box of the control tasks' limits (the regime's data lie inside
//! it) and the episode lengths.

use super::anchor::Anchor;
use super::dataset::{
    draw_lag, run_signal, sample_transitions, sample_windows, ControlLimits, ControlProcess,
    ControlSignal, SamplingConfig, Windows,
};
use super::mlp::{Mlp, WeightInit};
use super::rollout::{change_spread, fine_tune, FineTune};
use super::train::{
    mse, train_full_batch, train_momentum, Dataset, FullBatchConfig, FullBatchMethod,
    MomentumConfig, StopReason, TracePoint, TrainReport,
};
use super::transform::{Attitude, PlanarFrame, SpatialFrame};
use super::{Emulator, EmulatorError, TransformConfig, Transforms, Transitions};
use crate::physics::lander::{Lander, NormalizedLander};
use crate::physics::pendulum::{Pendulum3, PendulumVariant};
use crate::physics::truck::Truck;
use crate::physics::{BlowUp, Dynamics, IntegratorKind, Simulator};
use nalgebra::{UnitQuaternion, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};
use std::f64::consts::PI;
use std::time::Instant;

/// A physical model that NeuroAnimator emulates (Table 1; the dolphin is not yet here).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum NetModel {
    /// Passive three-link pendulum (6 states, no inputs).
    PendulumPassive,
    /// Active pendulum: 3 joint torques.
    PendulumActive,
    /// Active pendulum with a force on each link: 3 torques + 3 forces.
    PendulumExt,
    /// The truck: 6 states, 2 controls.
    Truck,
    /// The lunar lander: 13 states, 4 controls.
    Lander,
}

impl NetModel {
    /// Every model, in Table 1 order.
    pub const ALL: [NetModel; 5] = [
        Self::PendulumPassive,
        Self::PendulumActive,
        Self::PendulumExt,
        Self::Lander,
        Self::Truck,
    ];

    /// Its name in experiment files and tables.
    pub fn name(self) -> &'static str {
        match self {
            Self::PendulumPassive => "pendulum_passive",
            Self::PendulumActive => "pendulum_active",
            Self::PendulumExt => "pendulum_ext",
            Self::Truck => "truck",
            Self::Lander => "lander",
        }
    }

    /// The physical model's name in `motionlab describe` / `simulate` (same state and controls).
    pub fn physics_name(self) -> &'static str {
        match self {
            Self::PendulumPassive => "pendulum3_passive",
            Self::PendulumActive => "pendulum3",
            Self::PendulumExt => "pendulum3_ext",
            Self::Truck => "truck",
            Self::Lander => "lander",
        }
    }

    /// Names of the state variables, as `motionlab describe` gives them for the physical model.
    pub fn state_names(self) -> Vec<String> {
        crate::physics::model_by_name(self.physics_name())
            .map(|m| m.state_names())
            .unwrap_or_else(|| (0..self.state_dim()).map(|k| format!("s{k}")).collect())
    }

    /// Number of state variables.
    pub fn state_dim(self) -> usize {
        match self {
            Self::Lander => 13,
            _ => 6,
        }
    }

    /// Number of control (and external force) inputs.
    pub fn control_dim(self) -> usize {
        match self {
            Self::PendulumPassive => 0,
            Self::PendulumActive => 3,
            Self::PendulumExt => 6,
            Self::Truck => 2,
            Self::Lander => 4,
        }
    }

    fn pendulum(self) -> Option<Pendulum3> {
        match self {
            Self::PendulumPassive => Some(Pendulum3::new(PendulumVariant::Passive)),
            Self::PendulumActive => Some(Pendulum3::new(PendulumVariant::Active)),
            Self::PendulumExt => Some(Pendulum3::new(PendulumVariant::ExtForce)),
            _ => None,
        }
    }

    /// The physical model's parameters as JSON (part of the emulator cache key).
    pub fn physics_json(self) -> serde_json::Value {
        let parameters = match self {
            Self::Truck => serde_json::to_value(Truck::default()),
            Self::Lander => serde_json::to_value(Lander::default()),
            _ => serde_json::to_value(self.pendulum().expect("a pendulum")),
        }
        .unwrap_or_default();
        match self {
            // The lander's simulator calls no library function whose bits depend on the
            // processor; the truck's and the pendulum's trigonometry went through the C library
            // before it went through `crate::portable`, so their nets are keyed by the arithmetic
            // too and retrain with the portable bits.
            Self::Lander => parameters,
            _ => serde_json::json!({ "parameters": parameters, "arithmetic": "portable" }),
        }
    }

    /// A fingerprint of the sampling recipe (control limits and process, episode length,
    /// transforms, and three start states drawn with a fixed seed), part of the emulator cache
    /// key so that a change to any of them retrains.
    pub fn recipe_json(self, data: DataRegime) -> serde_json::Value {
        let mut rng = ChaCha8Rng::seed_from_u64(0);
        let starts: Vec<Vec<f64>> = (0..3)
            .map(|_| self.start_state_in(data, &mut rng))
            .collect();
        serde_json::json!({
            "limits": self.sampling_limits(data),
            "process": self.control_process_in(data),
            "episode": self.episode_duration(),
            "transforms": format!("{:?}", self.transform_config()),
            "starts": starts,
        })
    }

    /// Draws an episode start state of the data regime `data`: [`Self::start_state`] for the
    /// box, [`Self::typical_start_state`] for the typical manoeuvres.
    pub fn start_state_in(self, data: DataRegime, rng: &mut ChaCha8Rng) -> Vec<f64> {
        match data {
            DataRegime::Box => self.start_state(rng),
            DataRegime::Typical | DataRegime::Regime => self.typical_start_state(rng),
        }
    }

    /// The control box with, for the typical manoeuvres, each channel's smallest amplitude
    /// (module docs): two decades below the whole box for the truck's drive and the lander's
    /// thrust and torques (their tasks make small corrections); the truck's steering spans its
    /// whole range in every episode (parking uses full lock), and so do the pendulums' torques
    /// and forces (their box is the swing-up task's torque limit, which the task's swing uses
    /// throughout: its learned torques average a third of the limits).
    pub fn sampling_limits(self, data: DataRegime) -> ControlLimits {
        let limits = self.control_limits();
        match data {
            DataRegime::Box => limits,
            DataRegime::Typical | DataRegime::Regime => {
                let amplitude: Vec<f64> = match self {
                    Self::Truck => vec![TYPICAL_AMPLITUDE_MIN, 1.0],
                    Self::Lander => vec![TYPICAL_AMPLITUDE_MIN; self.control_dim()],
                    _ => vec![1.0; self.control_dim()],
                };
                let mut limits = limits;
                if data == DataRegime::Regime {
                    for (c, bound) in self.regime_control_box().into_iter().enumerate() {
                        if let Some((low, high)) = bound {
                            (limits.low[c], limits.high[c]) = (low, high);
                        }
                    }
                }
                limits.with_amplitude_min(&amplitude)
            }
        }
    }

    /// How the controls of the data regime `data` vary in time: [`Self::control_process`] for
    /// the box; for the typical data, paired manoeuvres held 0.5–1.5 s for the pendulums (the
    /// control tasks hold each knot 1 s) and 0.5–2 s for the truck and the lander, a quarter
    /// of them idle.
    pub fn control_process_in(self, data: DataRegime) -> ControlProcess {
        match data {
            DataRegime::Box => self.control_process(),
            DataRegime::Typical | DataRegime::Regime => ControlProcess::Manoeuvre {
                hold_min: 0.5,
                hold_max: match self {
                    Self::Truck | Self::Lander => 2.0,
                    _ => 1.5,
                },
                idle: 0.25,
                paired: true,
            },
        }
    }

    /// A typical episode start (module docs): the pendulums hanging at rest in a quarter of
    /// the episodes (the control tasks' start), else swinging: link 1 in the swing (the
    /// slowest mode, [`Pendulum3::modes`]) at an amplitude U[0, 1] rad and a uniform phase
    /// (the swing-up task must swing to its 0.6 rad target), the elbows at U[−0.2, 0.2] rad
    /// and U[−1, 1] rad/s; the truck
    /// anywhere in the 100 m square at any heading, at rest in half of the episodes, else
    /// manoeuvring at U[−2, 2] m/s along its heading; the lander upright within 0.1 rad,
    /// velocity U[−5, 5] m/s per axis, body rates zero in half of the episodes, else
    /// U[−0.05, 0.05] rad/s.
    pub fn typical_start_state(self, rng: &mut ChaCha8Rng) -> Vec<f64> {
        match self {
            Self::Truck => {
                let (x, y) = (rng.random_range(-50.0..50.0), rng.random_range(-50.0..50.0));
                let th: f64 = rng.random_range(-PI..PI);
                let moving = rng.random_range(0.0..1.0) < 0.5;
                let v: f64 = rng.random_range(-2.0..2.0);
                let v = if moving { v } else { 0.0 };
                let (s, c) = crate::portable::sin_cos(th);
                vec![x, y, th, v * c, v * s, 0.0]
            }
            Self::Lander => lander_start(rng, 0.1, 0.5, 0.05),
            _ => {
                // Drawn either way, so the stream does not depend on which start it is.
                let hanging = rng.random_range(0.0..1.0) < 0.25;
                let amplitude: f64 = rng.random_range(0.0..1.0);
                let phase: f64 = rng.random_range(0.0..std::f64::consts::TAU);
                let elbows: Vec<f64> = (0..2).map(|_| rng.random_range(-0.2..0.2)).collect();
                let rates: Vec<f64> = (0..2).map(|_| rng.random_range(-1.0..1.0)).collect();
                if hanging {
                    return vec![0.0; 6];
                }
                let pendulum = self.pendulum().expect("a pendulum");
                let swing = pendulum.swing().expect("the chain swings");
                let omega = std::f64::consts::TAU / swing.period_s;
                let (s, c) = crate::portable::sin_cos(phase);
                vec![
                    amplitude * c,
                    elbows[0],
                    elbows[1],
                    -amplitude * omega * s,
                    rates[0],
                    rates[1],
                ]
            }
        }
    }

    /// Whether an example `(state, control)` lies in the regime the Fig. 13 control tasks
    /// use (a description of the data, `regime_share` in `structure.csv`; ours, from the
    /// tasks' learned paths): the truck below 2 m/s with drive within ±0.3 m/s²; the lander
    /// tilted less than 0.2 rad, thrust within 0.5–1.5 × hover and roll and pitch torques
    /// within ±30 N·m; the pendulums (whose swing-up uses its whole torque range) within the
    /// swing-up's states: link 1 within 1 rad of hanging at most 3 rad/s, the elbows within
    /// 0.3 rad.
    pub fn in_task_regime(self, state: &[f64], control: &[f64]) -> bool {
        let controls_in = self
            .regime_control_box()
            .iter()
            .zip(control)
            .all(|(bound, u)| bound.is_none_or(|(low, high)| (low..=high).contains(u)));
        controls_in
            && match self {
                Self::PendulumPassive | Self::PendulumActive | Self::PendulumExt => {
                    state[0].abs() <= 1.0
                        && state[3].abs() <= 3.0
                        && state[1].abs() <= 0.3
                        && state[2].abs() <= 0.3
                }
                Self::Truck => (state[3] * state[3] + state[4] * state[4]).sqrt() <= 2.0,
                Self::Lander => {
                    // The body z axis's world z component is 1 − 2(x² + y²) for a unit
                    // quaternion.
                    let up = 1.0 - 2.0 * (state[4] * state[4] + state[5] * state[5]);
                    up >= crate::portable::cos(0.2)
                }
            }
    }

    /// Per control channel, the interval the Fig. 13 tasks' regime ([`Self::in_task_regime`])
    /// keeps it in, `None` where the regime does not bound it: the truck's drive within
    /// ±0.3 m/s² (its steering free), the lander's thrust within 0.5–1.5 × hover and its roll and
    /// pitch torques within ±30 N·m (its yaw torque free); the pendulums' channels are free (the
    /// swing-up uses its whole torque range).
    pub fn regime_control_box(self) -> Vec<Option<(f64, f64)>> {
        match self {
            Self::Truck => vec![Some((-0.3, 0.3)), None],
            Self::Lander => {
                let l = Lander::default();
                let hover = l.mass * l.gravity;
                vec![
                    Some((0.5 * hover, 1.5 * hover)),
                    Some((-30.0, 30.0)),
                    Some((-30.0, 30.0)),
                    None,
                ]
            }
            _ => vec![None; self.control_dim()],
        }
    }

    /// The physical simulator: RK4 at the caller's δt (the lander renormalizes its quaternion).
    pub fn simulator(self) -> Box<dyn Dynamics> {
        match self {
            Self::Truck => Box::new(Simulator::new(Truck::default(), IntegratorKind::Rk4)),
            Self::Lander => Box::new(NormalizedLander::new(
                Lander::default(),
                IntegratorKind::Rk4,
            )),
            _ => Box::new(Simulator::new(
                self.pendulum().expect("a pendulum"),
                IntegratorKind::Rk4,
            )),
        }
    }

    /// Draws an episode start state (see the module docs).
    pub fn start_state(self, rng: &mut ChaCha8Rng) -> Vec<f64> {
        match self {
            Self::Truck => {
                let (x, y) = (rng.random_range(-50.0..50.0), rng.random_range(-50.0..50.0));
                let th: f64 = rng.random_range(-PI..PI);
                let kind: f64 = rng.random_range(0.0..1.0);
                let v = if kind < 0.25 {
                    0.0
                } else if kind < 0.25 + 1.0 / 3.0 {
                    rng.random_range(-1.0..1.5)
                } else {
                    rng.random_range(-3.0..8.0)
                };
                let (s, c) = crate::portable::sin_cos(th);
                vec![x, y, th, v * c, v * s, 0.0]
            }
            // A quarter of the episodes start with the jets' rates at zero (the tasks'
            // starts), which idle jets then keep.
            Self::Lander => lander_start(rng, 0.4, 0.25, 0.2),
            _ => {
                let mut s: Vec<f64> = (0..3).map(|_| rng.random_range(-0.7..0.7)).collect();
                s.extend((0..3).map(|_| rng.random_range(-1.0..1.0)));
                s
            }
        }
    }

    /// Limits of the typical controls used for sampling (see the module docs).
    pub fn control_limits(self) -> ControlLimits {
        match self {
            Self::PendulumPassive => ControlLimits::none(),
            Self::PendulumActive => ControlLimits::symmetric(&[2.5, 1.5, 0.5]),
            Self::PendulumExt => ControlLimits::symmetric(&[2.5, 1.5, 0.5, 2.0, 2.0, 2.0]),
            Self::Truck => ControlLimits::symmetric(&[3.0, 0.5]),
            Self::Lander => {
                let l = Lander::default();
                ControlLimits {
                    low: vec![0.0, -400.0, -400.0, -400.0],
                    high: vec![2.0 * l.mass * l.gravity, 400.0, 400.0, 400.0],
                    amplitude_min: vec![],
                }
            }
        }
    }

    /// How the typical controls vary in time.
    pub fn control_process(self) -> ControlProcess {
        match self {
            Self::Truck => ControlProcess::PiecewiseConstant {
                hold_min: 0.5,
                hold_max: 2.0,
                idle: 0.25,
                idle_first: 0.5,
            },
            Self::Lander => ControlProcess::PiecewiseConstant {
                hold_min: 0.5,
                hold_max: 2.0,
                idle: 0.25,
                idle_first: 0.0,
            },
            _ => ControlProcess::Smooth {
                hold_min: 0.3,
                hold_max: 1.5,
            },
        }
    }

    /// An equilibrium of the model with its neutral control, `(state, control)`: the simulator
    /// leaves the state unchanged over any step (a test checks it). The truck parked with no
    /// drive and straight wheels; the pendulums hanging at rest with no torque or force; the
    /// lander level and still at 100 m under hover thrust (the frame removes position and
    /// heading, so every pose of it encodes alike). For [`NetSpec::anchor`].
    pub fn equilibrium(self) -> (Vec<f64>, Vec<f64>) {
        let n = self.state_dim();
        let m = self.control_dim();
        match self {
            Self::Lander => {
                let l = Lander::default();
                let mut s = vec![0.0; n];
                s[2] = 100.0;
                s[3] = 1.0;
                let mut u = vec![0.0; m];
                u[0] = l.mass * l.gravity;
                (s, u)
            }
            _ => (vec![0.0; n], vec![0.0; m]),
        }
    }

    /// Episode length of the sampling runs (s).
    pub fn episode_duration(self) -> f64 {
        match self {
            Self::Truck | Self::Lander => 10.0,
            _ => 20.0,
        }
    }

    /// Normalization groups of the network's inputs ([local state, controls]) and outputs
    /// (state change) under `norm` (Appendix A); `None` for per-variable normalization.
    /// [`Normalization::Quantities`]: one group per physical quantity (the pendulums' angles,
    /// angular velocities, torques, link forces; the truck's position, heading, velocity, yaw
    /// rate, drive, steering; the lander's position, attitude quaternion, velocity, body rates,
    /// thrust, torques), as the dolphin's nets. [`Normalization::StateControl`]: Appendix A's
    /// letter, one group for the state, one for the controls, one for the external forces.
    pub fn groups(self, norm: Normalization) -> Option<(Vec<usize>, Vec<usize>)> {
        let n = self.state_dim();
        let (state, controls): (Vec<usize>, Vec<usize>) = match norm {
            Normalization::Variable => return None,
            Normalization::StateControl => (
                vec![0; n],
                match self {
                    Self::PendulumExt => vec![1, 1, 1, 2, 2, 2],
                    _ => vec![1; self.control_dim()],
                },
            ),
            Normalization::Quantities => match self {
                Self::PendulumPassive => (vec![0, 0, 0, 1, 1, 1], vec![]),
                Self::PendulumActive => (vec![0, 0, 0, 1, 1, 1], vec![2, 2, 2]),
                Self::PendulumExt => (vec![0, 0, 0, 1, 1, 1], vec![2, 2, 2, 3, 3, 3]),
                Self::Truck => (vec![0, 0, 1, 2, 2, 3], vec![4, 5]),
                Self::Lander => (
                    vec![0, 0, 0, 1, 1, 1, 1, 2, 2, 2, 3, 3, 3],
                    vec![4, 5, 5, 5],
                ),
            },
        };
        let inputs = state.iter().chain(&controls).copied().collect();
        Some((inputs, state))
    }

    /// The transforms of §3.2–3.3 with the normalization `norm`: state change and normalization
    /// for all; the local frame for the truck (planar) and the lander (spatial).
    pub fn transform_config_with(self, norm: Normalization) -> TransformConfig {
        let mut c = self.transform_config();
        if let Some((inputs, outputs)) = self.groups(norm) {
            c.input_groups = Some(inputs);
            c.output_groups = Some(outputs);
        }
        c
    }

    /// The transforms of §3.2–3.3: state change and per-variable normalization for all; the
    /// local frame for the truck (planar) and the lander (spatial).
    pub fn transform_config(self) -> TransformConfig {
        match self {
            Self::Truck => {
                TransformConfig::standard(Some(PlanarFrame::rigid_body(0, 1, 2, 3, 4).into()))
            }
            Self::Lander => {
                // Gravity points along −z: the frame removes position and heading only, so the
                // net still sees the tilt. Angular velocity is already in the body frame: only
                // position, attitude and linear velocity go to the local frame.
                let mut f = SpatialFrame::rigid_body(0, 3, 7, 10);
                f.attitude = Attitude::Heading;
                f.vectors.truncate(1);
                TransformConfig::standard(Some(f.into()))
            }
            _ => TransformConfig::standard(None),
        }
    }
}

/// A lander start: the centre of mass uniform in a 100 m square at 20–200 m height, yaw
/// uniform, tilted up to `tilt_max` rad about a random horizontal axis, velocity U[−5, 5] m/s
/// per axis, body rates U[−`rate_max`, `rate_max`] rad/s, all zero in a share `still` of the
/// episodes (the rates are drawn either way, so the stream does not depend on it).
fn lander_start(rng: &mut ChaCha8Rng, tilt_max: f64, still: f64, rate_max: f64) -> Vec<f64> {
    let yaw = rng.random_range(-PI..PI);
    let axis_angle: f64 = rng.random_range(-PI..PI);
    let tilt = rng.random_range(0.0..tilt_max);
    let (s, c) = crate::portable::sin_cos(axis_angle);
    let axis = Vector3::new(c, s, 0.0);
    let q = axis_angle_quaternion(&nalgebra::Unit::new_normalize(axis), tilt)
        * axis_angle_quaternion(&Vector3::z_axis(), yaw);
    let q = q.quaternion();
    let mut x = vec![
        rng.random_range(-50.0..50.0),
        rng.random_range(-50.0..50.0),
        rng.random_range(20.0..200.0),
        q.w,
        q.i,
        q.j,
        q.k,
    ];
    x.extend((0..3).map(|_| rng.random_range(-5.0..5.0)));
    let is_still = rng.random_range(0.0..1.0) < still;
    x.extend((0..3).map(|_| {
        let w = rng.random_range(-rate_max..rate_max);
        if is_still {
            0.0
        } else {
            w
        }
    }));
    x
}

/// Smallest per-episode amplitude of the typical manoeuvres, as a fraction of a channel's
/// half-range (ours): two decades, so a task's small corrections are sampled as densely per
/// decade as the box's large moves.
pub const TYPICAL_AMPLITUDE_MIN: f64 = 0.01;

/// Where a net's training data come from (§4: "concentrating [sampling] on those state, force,
/// and control inputs that typically occur as a physics-based model is used in practice").
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum DataRegime {
    /// Each model's typical manoeuvres ([`NetModel::control_process_in`],
    /// [`NetModel::typical_start_state`]), every channel over its whole box: the paper's
    /// reading, the default (the pendulums' Table 1 data).
    #[default]
    Typical,
    /// Knots uniform over the whole control box from wide starts ([`NetModel::control_process`],
    /// [`NetModel::start_state`]): ours before, kept as a second line.
    Box,
    /// The typical manoeuvres with each control channel that the Fig. 13 tasks' regime bounds
    /// kept inside it ([`NetModel::regime_control_box`]): the data concentrated further on the
    /// tasks' inputs (ours; the Table 1 truck's and lander's data).
    Regime,
}

impl DataRegime {
    /// Its name in experiment files and tables.
    pub fn name(self) -> &'static str {
        match self {
            Self::Typical => "typical",
            Self::Box => "box",
            Self::Regime => "regime",
        }
    }

    fn is_typical(&self) -> bool {
        *self == Self::Typical
    }
}

/// How a network is trained (§3.5).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TrainMethod {
    /// Full-batch nonlinear conjugate gradient (argmin), for small nets.
    Cg,
    /// Full-batch L-BFGS (argmin), an alternative for small nets.
    Lbfgs,
    /// Gradient descent with momentum on mini-batches, for large nets.
    Momentum,
}

/// How a net's inputs and outputs are normalized (NeuroAnimator Appendix A; see
/// [`NetModel::groups`]).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Normalization {
    /// Each variable its own mean and deviation (ours, the catalog nets' first setting).
    #[default]
    Variable,
    /// One group per physical quantity, as the dolphin's nets (our reading of Appendix A).
    Quantities,
    /// Appendix A's letter: one group for all state variables, one for the controls, one for
    /// the external forces.
    StateControl,
}

impl Normalization {
    /// Every normalization, in `normalization.csv` order.
    pub const ALL: [Normalization; 3] = [Self::Variable, Self::Quantities, Self::StateControl];

    /// Its name in experiment files and tables.
    pub fn name(self) -> &'static str {
        match self {
            Self::Variable => "variable",
            Self::Quantities => "quantities",
            Self::StateControl => "state_control",
        }
    }

    fn is_variable(&self) -> bool {
        *self == Self::Variable
    }
}

#[cfg(test)]
impl TrainSettings {
    /// Test settings: plain one-step training (no noise, no rollout fine-tuning) with the
    /// given iteration limits and patience, the other settings at the specs' values.
    pub(crate) fn for_tests(cg_max_iters: u64, max_epochs: usize, patience: usize) -> Self {
        Self {
            held_out_fraction: 0.25,
            cg_max_iters,
            max_epochs,
            patience,
            min_improvement: 0.001,
            learning_rate: 0.05,
            momentum: 0.9,
            batch_size: 30,
            input_noise: 0.0,
            rollout_k: 0,
            rollout_weight: 0.0,
            rollout_iters: 0,
        }
    }
}

#[cfg(test)]
impl NetSpec {
    /// A test net of `model`: the physical step 0.01 s, no input noise, no anchor, the default
    /// normalization, transforms and data.
    pub(crate) fn for_tests(
        model: NetModel,
        hidden: usize,
        examples: usize,
        method: TrainMethod,
    ) -> Self {
        Self {
            model,
            hidden,
            examples,
            method,
            physical_dt: 0.01,
            input_noise: None,
            anchor: false,
            normalization: Default::default(),
            transforms: Default::default(),
            data: Default::default(),
        }
    }
}

/// One emulator network to build: model, super timestep, size, data.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NetSpec {
    /// The emulated model.
    pub model: NetModel,
    /// Hidden units.
    pub hidden: usize,
    /// Training examples (Table 1).
    pub examples: usize,
    /// How to train.
    pub method: TrainMethod,
    /// Physical time step δt of the simulator it emulates (s); Δt = n δt.
    pub physical_dt: f64,
    /// This net's input noise, overriding the training settings' `input_noise` (left out of
    /// cache keys when absent).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub input_noise: Option<f64>,
    /// Equilibrium anchoring (ours; [`super::anchor`]): the net reproduces the
    /// model's [`NetModel::equilibrium`] exactly, its output bias following the other weights.
    /// False (the default, left out of cache keys) is the paper's free net.
    #[serde(default, skip_serializing_if = "is_false")]
    pub anchor: bool,
    /// Normalization of its inputs and outputs ([`Normalization`]); per variable (the default)
    /// is left out of cache keys.
    #[serde(default, skip_serializing_if = "Normalization::is_variable")]
    pub normalization: Normalization,
    /// Which transforms of §3.2 wrap the net ([`TransformSet`]); `full` (the default, the
    /// model's chain) is left out of cache keys.
    #[serde(default, skip_serializing_if = "TransformSet::is_full")]
    pub transforms: TransformSet,
    /// Where its training data come from ([`DataRegime`]); typical (the default) is left out
    /// of cache keys (the recipe in the key says which data it is).
    #[serde(default, skip_serializing_if = "DataRegime::is_typical")]
    pub data: DataRegime,
}

impl NetSpec {
    /// The transforms this net is built with: its model's, normalized as `normalization` says,
    /// or the reduced chain `transforms` names.
    pub fn transform_config(&self) -> TransformConfig {
        self.transforms
            .reduce(self.model.transform_config_with(self.normalization))
    }
}

/// Which of NeuroAnimator's §3.2 transforms wrap a net (Fig. 6): the operators added one at a
/// time, as `na_transforms_ablation` compares them.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TransformSet {
    /// The model's whole chain: state change T^Δ, the local frame T' where the model has one,
    /// normalization T^σ as the net's `normalization` says.
    #[default]
    Full,
    /// No transform: the bare net maps [s, u] to the next state s'.
    Plain,
    /// The net predicts the state change (T^Δ), in world coordinates, unnormalized.
    Delta,
    /// State change and the model's local frame (T^Δ, T'), unnormalized.
    DeltaFrame,
}

impl TransformSet {
    /// Every set, operators added in the order of §3.2.
    pub const ALL: [TransformSet; 4] = [Self::Plain, Self::Delta, Self::DeltaFrame, Self::Full];

    /// Its name in experiment files and tables.
    pub fn name(self) -> &'static str {
        match self {
            Self::Full => "full",
            Self::Plain => "plain",
            Self::Delta => "delta",
            Self::DeltaFrame => "delta_frame",
        }
    }

    /// Whether it is the whole chain (the default, left out of cache keys).
    pub fn is_full(&self) -> bool {
        *self == Self::Full
    }

    /// The chain `full` (a model's whole chain) reduced to this set's operators.
    pub fn reduce(self, full: TransformConfig) -> TransformConfig {
        match self {
            Self::Full => full,
            Self::Plain => TransformConfig::none(),
            Self::Delta => TransformConfig {
                delta: true,
                ..TransformConfig::none()
            },
            Self::DeltaFrame => TransformConfig {
                normalize: false,
                input_groups: None,
                output_groups: None,
                ..full
            },
        }
    }
}

fn is_false(v: &bool) -> bool {
    !*v
}

/// Training settings shared by the nets of an experiment.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TrainSettings {
    /// Held-out examples as a fraction of the training examples (sampled separately).
    pub held_out_fraction: f64,
    /// Conjugate-gradient iteration limit.
    pub cg_max_iters: u64,
    /// Mini-batch epoch limit.
    pub max_epochs: usize,
    /// Stop after this many checks without a significant held-out improvement.
    pub patience: usize,
    /// Relative held-out improvement that counts as significant.
    pub min_improvement: f64,
    /// Momentum learning rate η_w.
    pub learning_rate: f64,
    /// Momentum α_w.
    pub momentum: f64,
    /// Mini-batch size (the paper: about 30).
    pub batch_size: usize,
    /// Rollout-faithful training: Gaussian noise on the training state
    /// inputs, as a fraction of each input's spread, with targets corrected back to the true
    /// next state ([`Transforms::perturb`], Sanchez-Gonzalez et al. 2020). 0 (the default, left
    /// out of cache keys) is the paper's plain one-step training.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub input_noise: f64,
    /// k-step rollout fine-tuning ([`super::rollout`]): after one-step
    /// training, the net is fine-tuned by L-BFGS on its one-step loss plus `rollout_weight`
    /// times its k-step rollout loss on simulated windows of k = `rollout_k` super-steps
    /// (examples / k windows, held out as the examples), for at most `rollout_iters`
    /// iterations with the settings' patience. 0 (the default, left out of cache keys) is off.
    #[serde(default, skip_serializing_if = "is_zero_usize")]
    pub rollout_k: usize,
    /// Weight of the k-step rollout loss against the one-step loss.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub rollout_weight: f64,
    /// L-BFGS iteration limit of the rollout fine-tuning.
    #[serde(default, skip_serializing_if = "is_zero_u64")]
    pub rollout_iters: u64,
}

fn is_zero(v: &f64) -> bool {
    *v == 0.0
}

fn is_zero_usize(v: &usize) -> bool {
    *v == 0
}

fn is_zero_u64(v: &u64) -> bool {
    *v == 0
}

/// Everything that determines a trained emulator.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BuildSpec {
    /// The network.
    pub net: NetSpec,
    /// Physical steps per emulator step, n (δt is the net's `physical_dt`).
    pub steps: usize,
    /// Training settings.
    pub settings: TrainSettings,
    /// Seed of the data sampling, weight initialization and shuffles.
    pub seed: u64,
}

impl BuildSpec {
    /// The emulator's super timestep Δt = n δt (s).
    pub fn super_dt(&self) -> f64 {
        self.steps as f64 * self.net.physical_dt
    }

    /// Number of held-out examples.
    pub fn held_out(&self) -> usize {
        ((self.net.examples as f64 * self.settings.held_out_fraction).round() as usize).max(2)
    }

    /// The training settings with this net's own input noise, if it has one.
    pub fn effective_settings(&self) -> TrainSettings {
        TrainSettings {
            input_noise: self.net.input_noise.unwrap_or(self.settings.input_noise),
            ..self.settings
        }
    }

    /// Sampling settings for `examples` examples.
    pub fn sampling(&self, examples: usize) -> SamplingConfig {
        let m = self.net.model;
        SamplingConfig {
            dt: self.net.physical_dt,
            steps_per_sample: self.steps,
            examples,
            episode_duration: m.episode_duration().max(6.0 * self.super_dt()),
            control: self.control_process(),
        }
    }

    /// How its data's controls vary ([`NetModel::control_process_in`] of its regime).
    pub fn control_process(&self) -> ControlProcess {
        self.net.model.control_process_in(self.net.data)
    }

    /// Its data's control box and amplitudes ([`NetModel::sampling_limits`] of its regime).
    pub fn sampling_limits(&self) -> ControlLimits {
        self.net.model.sampling_limits(self.net.data)
    }

    /// Draws one of its data's episode starts ([`NetModel::start_state_in`]).
    pub fn start_state(&self, rng: &mut ChaCha8Rng) -> Vec<f64> {
        self.net.model.start_state_in(self.net.data, rng)
    }
}

/// A trained emulator with its training record.
#[derive(Debug, Clone)]
pub struct Trained {
    /// The emulator.
    pub emulator: Emulator,
    /// Training trace (iteration or epoch, errors in normalized network space).
    pub trace: Vec<TracePoint>,
    /// Mean squared error per output on the training set at the kept weights.
    pub train_error: f64,
    /// Mean squared error per output on the held-out set at the kept weights.
    pub heldout_error: f64,
    /// Wall time of data sampling and training when it was built (s).
    pub train_s: f64,
    /// Why training stopped.
    pub stop: String,
    /// Whether it came from the cache.
    pub from_cache: bool,
    /// Trace of the k-step rollout fine-tuning (errors: one-step loss + weight · rollout loss,
    /// training and held-out); empty when it is off.
    pub rollout_trace: Vec<TracePoint>,
}

/// Errors of building an emulator.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum BuildError {
    /// Training or construction failed.
    #[error(transparent)]
    Emulator(#[from] EmulatorError),
    /// The physical simulation blew up while sampling.
    #[error(transparent)]
    BlowUp(#[from] BlowUp),
    /// The cache could not be written or read.
    #[error("emulator cache {path}: {message}")]
    Cache {
        /// The file.
        path: String,
        /// The cause.
        message: String,
    },
}

/// Trains `mlp` on `train` with early stopping on `held` by `method` (§3.5): full-batch CG or
/// L-BFGS, or momentum mini-batches shuffled from `seed`. The net is left at its best
/// held-out weights.
pub fn train_mlp(
    mlp: &mut Mlp,
    train: &Dataset,
    held: &Dataset,
    method: TrainMethod,
    s: &TrainSettings,
    seed: u64,
    anchor: Option<&Anchor>,
) -> Result<TrainReport, EmulatorError> {
    match method {
        TrainMethod::Cg | TrainMethod::Lbfgs => train_full_batch(
            mlp,
            train,
            held,
            &FullBatchConfig {
                method: if method == TrainMethod::Cg {
                    FullBatchMethod::ConjugateGradient { restart_iters: 50 }
                } else {
                    FullBatchMethod::Lbfgs { memory: 20 }
                },
                max_iters: s.cg_max_iters,
                patience: s.patience,
                min_improvement: s.min_improvement,
            },
            anchor,
        ),
        TrainMethod::Momentum => train_momentum(
            mlp,
            train,
            held,
            &MomentumConfig {
                learning_rate: s.learning_rate,
                momentum: s.momentum,
                batch_size: s.batch_size,
                max_epochs: s.max_epochs,
                patience: s.patience,
                min_improvement: s.min_improvement,
                seed,
            },
            anchor,
        ),
    }
}

/// The anchor of `spec`'s net in the network space of `transforms`, when it is anchored.
pub fn anchor_of(spec: &BuildSpec, transforms: &Transforms) -> Option<Anchor> {
    spec.net.anchor.then(|| {
        let (s, u) = spec.net.model.equilibrium();
        Anchor::equilibrium(transforms, &s, &u)
    })
}

/// The training set as trained on: `clean` with the settings' input noise, if any.
pub fn noisy(t: &Transforms, clean: &Dataset, s: &TrainSettings, rng: &mut ChaCha8Rng) -> Dataset {
    if s.input_noise > 0.0 {
        t.perturb(clean, s.input_noise, rng)
    } else {
        clean.clone()
    }
}

/// The name of a stop reason in tables and cache files.
pub fn stop_name(stop: &StopReason) -> String {
    match stop {
        StopReason::NoImprovement => "no_improvement".to_string(),
        StopReason::MaxIterations => "max_iterations".to_string(),
        StopReason::Converged => "converged".to_string(),
        StopReason::OptimizerFailed(e) => format!("optimizer_failed: {e}"),
    }
}

/// The true rollouts a candidate (an emulator, or the simulator at a coarser step) is scored
/// against by [`rollout_errors`].
#[derive(Debug, Clone)]
pub struct RolloutReference {
    spec: BuildSpec,
    episodes: usize,
    horizon: usize,
    /// Start states, row-major (episode, variable).
    starts: Vec<f64>,
    /// Controls held over each super-step, row-major (episode, step, control).
    controls: Vec<f64>,
    /// True states at the end of each super-step, row-major (episode, step, variable).
    truth: Vec<f64>,
}

impl RolloutReference {
    /// Simulates the true rollouts of `spec`'s model: `episodes` start states drawn as the
    /// training examples' states are (a stream of its own): an episode start, then one lag
    /// ([`draw_lag`]) under the episode's control signal, so a rollout starts where examples do
    /// and not at a start state no example holds (an episode start's fast modes, e.g. the
    /// pendulum elbows' velocities, which friction damps within the first super-step); each
    /// then runs `horizon` super-steps under the same signal, read at each super-step's start
    /// and held over it.
    pub fn sample(spec: &BuildSpec, episodes: usize, horizon: usize) -> Result<Self, BuildError> {
        let model = spec.net.model;
        let (n, m) = (model.state_dim(), model.control_dim());
        let limits = spec.sampling_limits();
        let mut rng = ChaCha8Rng::seed_from_u64(crate::seed::mix_seed(spec.seed, 3));
        let mut sim = model.simulator();
        let mut u = vec![0.0; m];
        let mut starts = Vec::with_capacity(episodes * n);
        let mut controls = Vec::with_capacity(episodes * horizon * m);
        let mut truth = Vec::with_capacity(episodes * horizon * n);
        let dt = spec.net.physical_dt;
        for _ in 0..episodes {
            let mut xs = spec.start_state(&mut rng);
            let lag = draw_lag(spec.steps, &mut rng);
            let signal = ControlSignal::sample(
                spec.control_process(),
                &limits,
                (lag + horizon * spec.steps) as f64 * dt,
                &mut rng,
            );
            run_signal(sim.as_mut(), &mut xs, &signal, &mut u, 0..lag, dt);
            crate::physics::check_finite(model.name(), lag, lag as f64 * dt, &xs)?;
            starts.extend_from_slice(&xs);
            for k in 0..horizon {
                let at = lag + k * spec.steps;
                signal.at(at as f64 * dt, &mut u);
                controls.extend_from_slice(&u);
                for i in 0..spec.steps {
                    sim.step(&mut xs, &u, dt);
                    let step = at + i + 1;
                    crate::physics::check_finite(model.name(), step, step as f64 * dt, &xs)?;
                }
                truth.extend_from_slice(&xs);
            }
        }
        Ok(Self {
            spec: spec.clone(),
            episodes,
            horizon,
            starts,
            controls,
            truth,
        })
    }

    /// Per super-step error of a candidate that advances a state by one super-step under a
    /// control (`advance(x, u)`, in place).
    pub fn errors(&self, mut advance: impl FnMut(&mut [f64], &[f64])) -> Vec<f64> {
        let model = self.spec.net.model;
        let (n, m) = (model.state_dim(), model.control_dim());
        let mut guess = Vec::with_capacity(self.truth.len());
        let mut x = vec![0.0; n];
        for e in 0..self.episodes {
            x.copy_from_slice(&self.starts[e * n..(e + 1) * n]);
            for k in 0..self.horizon {
                let r = (e * self.horizon + k) * m;
                advance(&mut x, &self.controls[r..r + m]);
                guess.extend_from_slice(&x);
            }
        }
        rollout_errors(&self.truth, &guess, self.episodes, self.horizon, n)
    }

    /// Per episode, the candidate's error (guess − truth) in every variable after the last
    /// super-step.
    pub fn final_errors(&self, mut advance: impl FnMut(&mut [f64], &[f64])) -> Vec<Vec<f64>> {
        let model = self.spec.net.model;
        let (n, m) = (model.state_dim(), model.control_dim());
        let mut x = vec![0.0; n];
        (0..self.episodes)
            .map(|e| {
                x.copy_from_slice(&self.starts[e * n..(e + 1) * n]);
                for k in 0..self.horizon {
                    let r = (e * self.horizon + k) * m;
                    advance(&mut x, &self.controls[r..r + m]);
                }
                let t = (e * self.horizon + self.horizon - 1) * n;
                (0..n).map(|v| x[v] - self.truth[t + v]).collect()
            })
            .collect()
    }

    /// Mean over the super-steps of [`Self::errors`]; a candidate that blew up (NaN) scores +∞.
    pub fn mean_error(&self, advance: impl FnMut(&mut [f64], &[f64])) -> f64 {
        let e = self.errors(advance);
        let mean = e.iter().sum::<f64>() / e.len().max(1) as f64;
        if mean.is_nan() {
            f64::INFINITY
        } else {
            mean
        }
    }

    /// The spec whose model and steps it simulates.
    pub fn spec(&self) -> &BuildSpec {
        &self.spec
    }

    /// Mean error of the emulator (one prediction per super-step).
    pub fn emulator_error(&self, emulator: &Emulator) -> f64 {
        let mut scratch = emulator.scratch();
        let mut next = vec![0.0; emulator.state_dim()];
        self.mean_error(|x, u| {
            emulator.predict(x, u, &mut scratch, &mut next);
            x.copy_from_slice(&next);
        })
    }
}

/// A net's fidelity on the inputs the control tasks use, in tolerance units (what control
/// learning needs, §6), per state variable with a positive tolerance; see [`regime_fidelity`].
#[derive(Debug, Clone, PartialEq)]
pub struct RegimeFidelity {
    /// The state variable's index.
    pub variable: usize,
    /// Its tolerance (the control tasks' final tolerance).
    pub tolerance: f64,
    /// Mean one-step error over the test examples, over the tolerance.
    pub bias_tol: f64,
    /// Root-mean-square one-step error, over the tolerance.
    pub rms_tol: f64,
    /// Median over the episodes of |error| after `horizon` super-steps of open loop, over the
    /// tolerance.
    pub rollout_tol: f64,
}

/// The task-regime twin of `spec` ([`DataRegime::Regime`], everything else the same): the
/// data every variant of a net is measured on, the inputs its control tasks use (for the
/// pendulums the typical manoeuvres: their regime bounds no control).
pub fn regime_twin(spec: &BuildSpec) -> BuildSpec {
    let mut t = spec.clone();
    t.net.data = DataRegime::Regime;
    t
}

/// [`RegimeFidelity`] of `emulator` (built from `spec`, any data regime) for every variable
/// whose `tolerance` is positive: one-step errors on a fresh set of `spec.held_out()`
/// examples of the tasks' regime ([`regime_twin`]; stream 21 of the spec's seed, separate from
/// every training and held-out set), and open-loop errors after `horizon` super-steps on
/// `episodes` episodes of it (the rollout reference of [`rollout_error`], so every variant of
/// a net is measured on the same examples and episodes).
pub fn regime_fidelity(
    emulator: &Emulator,
    spec: &BuildSpec,
    tolerance: &[f64],
    episodes: usize,
    horizon: usize,
) -> Result<Vec<RegimeFidelity>, BuildError> {
    let twin = regime_twin(spec);
    let model = twin.net.model;
    let n = model.state_dim();
    assert_eq!(tolerance.len(), n, "one tolerance per state variable");
    let test = sampled(&twin, twin.held_out(), 21)?;
    let (mut scratch, mut next) = (emulator.scratch(), vec![0.0; n]);
    let (mut sum, mut sum_sq) = (vec![0.0; n], vec![0.0; n]);
    let (mut s, mut u) = (vec![0.0; n], vec![0.0; model.control_dim()]);
    for r in 0..test.len() {
        copy_row(&test.states, r, &mut s);
        copy_row(&test.controls, r, &mut u);
        emulator.predict(&s, &u, &mut scratch, &mut next);
        for v in 0..n {
            let e = next[v] - test.next_states[(r, v)];
            sum[v] += e;
            sum_sq[v] += e * e;
        }
    }
    let reference = RolloutReference::sample(&twin, episodes, horizon)?;
    let finals = reference.final_errors(|x, u| {
        emulator.predict(x, u, &mut scratch, &mut next);
        x.copy_from_slice(&next);
    });
    let rows = test.len().max(1) as f64;
    Ok((0..n)
        .filter(|&v| tolerance[v] > 0.0)
        .map(|v| {
            let mut abs: Vec<f64> = finals.iter().map(|e| e[v].abs()).collect();
            abs.sort_by(f64::total_cmp);
            let median = if abs.is_empty() {
                f64::NAN
            } else if abs.len() % 2 == 1 {
                abs[abs.len() / 2]
            } else {
                0.5 * (abs[abs.len() / 2 - 1] + abs[abs.len() / 2])
            };
            RegimeFidelity {
                variable: v,
                tolerance: tolerance[v],
                bias_tol: sum[v] / rows / tolerance[v],
                rms_tol: (sum_sq[v] / rows).sqrt() / tolerance[v],
                rollout_tol: median / tolerance[v],
            }
        })
        .collect())
}

/// Row `r` of `a` into `out` (whatever `a`'s memory layout).
fn copy_row(a: &ndarray::Array2<f64>, r: usize, out: &mut [f64]) {
    for (o, v) in out.iter_mut().zip(a.row(r)) {
        *o = *v;
    }
}

/// The share of `data`'s examples in `model`'s task regime ([`NetModel::in_task_regime`]).
pub fn regime_share(model: NetModel, data: &Transitions) -> f64 {
    let (mut s, mut u) = (vec![0.0; model.state_dim()], vec![0.0; model.control_dim()]);
    let inside = (0..data.len())
        .filter(|&r| {
            copy_row(&data.states, r, &mut s);
            copy_row(&data.controls, r, &mut u);
            model.in_task_regime(&s, &u)
        })
        .count();
    inside as f64 / data.len().max(1) as f64
}

/// Multi-step fidelity of a trained emulator of `spec` (what control learning needs, §6): from
/// `episodes` start states drawn as for training (a stream of its own), the emulator and the
/// simulator run `horizon` super-steps side by side under the same controls — the training
/// control process, read at each super-step's start and held over it ([`RolloutReference`]).
/// Returns, for k = 1 … `horizon`, the mean over episodes and state variables of
/// ((ŝ_k − s_k)/σ)², σ the spread of that variable over the simulated states (the emulator
/// never sees the simulator's state after the start). Deterministic for a given spec.
pub fn rollout_error(
    emulator: &Emulator,
    spec: &BuildSpec,
    episodes: usize,
    horizon: usize,
) -> Result<Vec<f64>, BuildError> {
    let reference = RolloutReference::sample(spec, episodes, horizon)?;
    let (mut scratch, mut next) = (emulator.scratch(), vec![0.0; spec.net.model.state_dim()]);
    Ok(reference.errors(|x, u| {
        emulator.predict(x, u, &mut scratch, &mut next);
        x.copy_from_slice(&next);
    }))
}

/// Per step k = 1 … `horizon`, the mean over `episodes` and the `n` variables of
/// ((ŝ_k − s_k)/σ)², σ the spread of each variable over all of `truth`; `truth` and `guess`
/// hold the states row-major by (episode, step, variable).
pub fn rollout_errors(
    truth: &[f64],
    guess: &[f64],
    episodes: usize,
    horizon: usize,
    n: usize,
) -> Vec<f64> {
    let rows = episodes * horizon;
    let sigma: Vec<f64> = (0..n)
        .map(|v| {
            let mean = (0..rows).map(|r| truth[r * n + v]).sum::<f64>() / rows as f64;
            let var = (0..rows)
                .map(|r| (truth[r * n + v] - mean).powi(2))
                .sum::<f64>()
                / rows as f64;
            var.sqrt().max(1e-6)
        })
        .collect();
    (0..horizon)
        .map(|k| {
            let mut sum = 0.0;
            for e in 0..episodes {
                let r = (e * horizon + k) * n;
                for v in 0..n {
                    sum += ((guess[r + v] - truth[r + v]) / sigma[v]).powi(2);
                }
            }
            sum / (episodes * n) as f64
        })
        .collect()
}

/// The data a net of `spec` is trained on, as [`train_emulator`] samples it (the same seeded
/// streams, so the same examples): the DAgger stage ([`super::dagger`]) aggregates onto it.
#[derive(Debug, Clone)]
pub struct TrainingData {
    /// The one-step training transitions (simulator space).
    pub train: Transitions,
    /// The one-step held-out transitions.
    pub held: Transitions,
    /// The transforms fitted on `train`.
    pub transforms: Transforms,
    /// `train` encoded, with the settings' input noise (as trained on).
    pub train_ds: Dataset,
    /// `train` encoded, clean.
    pub clean_ds: Dataset,
    /// `held` encoded.
    pub held_ds: Dataset,
    /// Per-variable scales of the rollout loss ([`change_spread`] of `train`).
    pub sigma: Vec<f64>,
}

/// `examples` one-step transitions of `spec`'s data, from stream `stream` of its seed.
fn sampled(spec: &BuildSpec, examples: usize, stream: u64) -> Result<Transitions, BuildError> {
    let mut sim = spec.net.model.simulator();
    let start = |r: &mut ChaCha8Rng| spec.start_state(r);
    let mut rng = ChaCha8Rng::seed_from_u64(crate::seed::mix_seed(spec.seed, stream));
    Ok(sample_transitions(
        sim.as_mut(),
        &start,
        &spec.sampling_limits(),
        &spec.sampling(examples),
        &mut rng,
    )?
    .transitions)
}

/// The one-step training transitions of `spec`, as [`training_data`] samples them (stream 1),
/// without the held-out set or the transforms.
pub fn training_transitions(spec: &BuildSpec) -> Result<Transitions, BuildError> {
    sampled(spec, spec.net.examples, 1)
}

/// Samples the one-step data of `spec` and fits its transforms (streams 1, 2 and 5 of the
/// spec's seed).
pub fn training_data(spec: &BuildSpec) -> Result<TrainingData, BuildError> {
    let train = sampled(spec, spec.net.examples, 1)?;
    let held = sampled(spec, spec.held_out(), 2)?;
    let stream = |k: u64| ChaCha8Rng::seed_from_u64(crate::seed::mix_seed(spec.seed, k));
    let transforms = Transforms::fit(&spec.net.transform_config(), &train)?;
    let (clean_ds, held_ds) = (transforms.encode(&train), transforms.encode(&held));
    let train_ds = noisy(
        &transforms,
        &clean_ds,
        &spec.effective_settings(),
        &mut stream(5),
    );
    let sigma = change_spread(&train);
    Ok(TrainingData {
        train,
        held,
        transforms,
        train_ds,
        clean_ds,
        held_ds,
        sigma,
    })
}

/// The k-step rollout windows of `spec` (k = `rollout_k` ≥ 1), training and held-out, as
/// [`train_emulator`] samples them (streams 6 and 7).
pub fn rollout_windows(spec: &BuildSpec) -> Result<(Windows, Windows), BuildError> {
    let model = spec.net.model;
    let mut sim = model.simulator();
    let limits = spec.sampling_limits();
    let start = |r: &mut ChaCha8Rng| spec.start_state(r);
    let stream = |k: u64| ChaCha8Rng::seed_from_u64(crate::seed::mix_seed(spec.seed, k));
    let k = spec.settings.rollout_k.max(1);
    let mut windows = |count: usize, seed: u64| {
        let mut cfg = spec.sampling(count);
        cfg.episode_duration = cfg.episode_duration.max((k + 6) as f64 * spec.super_dt());
        sample_windows(sim.as_mut(), &start, &limits, &cfg, k, &mut stream(seed))
    };
    let count = spec.net.examples.div_ceil(k).max(2);
    let held_count = ((count as f64 * spec.settings.held_out_fraction).round() as usize).max(2);
    Ok((windows(count, 6)?, windows(held_count, 7)?))
}

/// The k-step rollout fine-tuning after one-step training ([`fine_tune`]): on `data`'s
/// one-step sets and the (training, held-out) `windows`, with `settings`' weight, iteration
/// limit, patience and threshold; appends its stop to `stop` and returns its trace.
pub(crate) fn rollout_phase(
    emulator: &mut Emulator,
    data: &TrainingData,
    windows: &(Windows, Windows),
    settings: &TrainSettings,
    anchor: Option<&Anchor>,
    stop: &mut String,
) -> Result<Vec<TracePoint>, BuildError> {
    let report = fine_tune(
        emulator,
        &FineTune {
            train: &data.train_ds,
            held: &data.held_ds,
            train_windows: &windows.0,
            held_windows: &windows.1,
            sigma: &data.sigma,
            weight: settings.rollout_weight,
            max_iters: settings.rollout_iters,
            patience: settings.patience,
            min_improvement: settings.min_improvement,
            anchor,
        },
    )?;
    *stop = format!("{stop}; rollout: {}", stop_name(&report.stop));
    Ok(report.trace)
}

/// Samples training and held-out data, fits the transforms and trains the network of `spec`.
/// Deterministic for a given spec (the wall time aside).
pub fn train_emulator(spec: &BuildSpec) -> Result<Trained, BuildError> {
    let t0 = Instant::now();
    let model = spec.net.model;
    let stream = |k: u64| ChaCha8Rng::seed_from_u64(crate::seed::mix_seed(spec.seed, k));
    let data = training_data(spec)?;
    let (n, m) = (model.state_dim(), model.control_dim());
    let mut mlp = Mlp::new(n + m, spec.net.hidden, n, WeightInit::FanIn, &mut stream(3));
    let anchor = anchor_of(spec, &data.transforms);
    let report = train_mlp(
        &mut mlp,
        &data.train_ds,
        &data.held_ds,
        spec.net.method,
        &spec.settings,
        crate::seed::mix_seed(spec.seed, 4),
        anchor.as_ref(),
    )?;
    let mut emulator = Emulator::new(data.transforms.clone(), mlp, spec.super_dt())?;
    let mut stop = stop_name(&report.stop);
    let rollout_trace = if spec.settings.rollout_k > 0 {
        let windows = rollout_windows(spec)?;
        let s = &spec.settings;
        rollout_phase(
            &mut emulator,
            &data,
            &windows,
            s,
            anchor.as_ref(),
            &mut stop,
        )?
    } else {
        Vec::new()
    };
    // Errors on the clean examples (the held-out set is clean too).
    let train_error = mse(emulator.mlp(), &data.clean_ds);
    let heldout_error = mse(emulator.mlp(), &data.held_ds);
    Ok(Trained {
        emulator,
        trace: report.trace,
        train_error,
        heldout_error,
        train_s: t0.elapsed().as_secs_f64(),
        stop,
        from_cache: false,
        rollout_trace,
    })
}

/// nalgebra's `UnitQuaternion::from_axis_angle` (cos ½θ, sin ½θ · axis) with the sine and
/// cosine of [`crate::portable`] instead of the C library's, so the same bits on every machine.
fn axis_angle_quaternion(axis: &nalgebra::Unit<Vector3<f64>>, angle: f64) -> UnitQuaternion<f64> {
    let (s, c) = crate::portable::sin_cos(angle / 2.0);
    UnitQuaternion::new_unchecked(nalgebra::Quaternion::from_parts(c, axis.into_inner() * s))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::emulator::transform::FrameMap;

    /// A lander at rest at 100 m, tilted by `tilt` about x after a heading `yaw` about z.
    fn tilted(tilt: f64, yaw: f64) -> Vec<f64> {
        let q = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), yaw)
            * UnitQuaternion::from_axis_angle(&Vector3::x_axis(), tilt);
        let q = q.quaternion();
        let mut s = vec![3.0, -4.0, 100.0, q.w, q.i, q.j, q.k];
        s.extend([0.0; 6]);
        s
    }

    fn to_local(s: &[f64]) -> Vec<f64> {
        let cfg = NetModel::Lander.transform_config();
        let frame = cfg.frame.expect("the lander has a local frame");
        let mut l = vec![0.0; s.len()];
        frame.apply_at(FrameMap::ToLocal, s, s, &mut l);
        l
    }

    /// A small net of `model` trained by L-BFGS with early stopping, δt = 0.01 s.
    fn small(model: NetModel, hidden: usize, examples: usize, steps: usize) -> BuildSpec {
        BuildSpec {
            net: NetSpec::for_tests(model, hidden, examples, TrainMethod::Lbfgs),
            steps,
            settings: TrainSettings {
                held_out_fraction: 0.2,
                cg_max_iters: 300,
                max_epochs: 0,
                patience: 30,
                min_improvement: 1e-4,
                learning_rate: 0.0,
                momentum: 0.0,
                batch_size: 30,
                input_noise: 0.0,
                rollout_k: 0,
                rollout_weight: 0.0,
                rollout_iters: 0,
            },
            seed: 11,
        }
    }

    /// 3,000 examples of `model`'s box data (N50, seed 4).
    fn catalog_data(model: NetModel, hidden: usize) -> Transitions {
        let mut spec = small(model, hidden, 3000, 50);
        spec.net.data = DataRegime::Box;
        let mut sim = model.simulator();
        let start = |r: &mut ChaCha8Rng| model.start_state(r);
        sample_transitions(
            sim.as_mut(),
            &start,
            &model.control_limits(),
            &spec.sampling(3000),
            &mut ChaCha8Rng::seed_from_u64(4),
        )
        .unwrap()
        .transitions
    }

    /// 3,000 examples of `model`'s training data in the regime `data` (N50, seed 4).
    fn regime_data(model: NetModel, data: DataRegime) -> Transitions {
        let mut spec = small(model, 10, 3000, 50);
        spec.net.data = data;
        let mut sim = model.simulator();
        let start = |r: &mut ChaCha8Rng| spec.start_state(r);
        sample_transitions(
            sim.as_mut(),
            &start,
            &spec.sampling_limits(),
            &spec.sampling(3000),
            &mut ChaCha8Rng::seed_from_u64(4),
        )
        .unwrap()
        .transitions
    }

    /// The regime's data keep every channel the tasks' regime bounds inside that bound, still
    /// reach 70 % of the way to both of its ends, leave the other channels as the typical
    /// data's, and put more of their examples in the tasks' regime than the typical data do.
    #[test]
    fn regime_data_stay_in_the_regimes_box_and_concentrate_further() {
        for model in [NetModel::Truck, NetModel::Lander] {
            let regime = regime_data(model, DataRegime::Regime);
            let typical = regime_data(model, DataRegime::Typical);
            for (c, bound) in model.regime_control_box().into_iter().enumerate() {
                let (col, typical_col) = (regime.controls.column(c), typical.controls.column(c));
                let range = |x: ndarray::ArrayView1<f64>| {
                    x.iter()
                        .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), &v| {
                            (l.min(v), h.max(v))
                        })
                };
                let ((lo, hi), (tlo, thi)) = (range(col), range(typical_col));
                match bound {
                    Some((low, high)) => {
                        let (mid, half) = (0.5 * (low + high), 0.5 * (high - low));
                        assert!(
                            lo >= low && hi <= high,
                            "{} {c}: [{lo}, {hi}]",
                            model.name()
                        );
                        assert!(
                            lo <= mid - 0.7 * half && hi >= mid + 0.7 * half,
                            "{} {c}: [{lo}, {hi}]",
                            model.name()
                        );
                    }
                    // A free channel samples the typical box (the pendulums' all are free).
                    None => assert!(
                        lo < 0.5 * tlo && hi > 0.5 * thi,
                        "{} {c}: [{lo}, {hi}] vs [{tlo}, {thi}]",
                        model.name()
                    ),
                }
            }
            let (r, t) = (regime_share(model, &regime), regime_share(model, &typical));
            assert!(r > t, "{}: regime {r}, typical {t}", model.name());
        }
        assert!(NetModel::PendulumActive
            .regime_control_box()
            .iter()
            .all(Option::is_none));
    }

    /// §4's typical controls concentrate the data where the control tasks work: for every
    /// model with controls, at least 30 % of the typical examples lie in the tasks' regime, at
    /// least three times the box's share for the truck and the lander (our thresholds; their
    /// box shares are a few per cent) and more than the box's for the pendulums, while the
    /// typical controls still reach 70 % of the way to both ends of every channel's box.
    #[test]
    fn typical_data_concentrate_on_the_tasks_regime_and_still_span_the_box() {
        for model in [
            NetModel::PendulumActive,
            NetModel::PendulumExt,
            NetModel::Truck,
            NetModel::Lander,
        ] {
            let typical = regime_data(model, DataRegime::Typical);
            let boxed = regime_data(model, DataRegime::Box);
            let (a, b) = (regime_share(model, &typical), regime_share(model, &boxed));
            // The pendulums' typical torques span their whole box (the swing-up uses it), so
            // only their states concentrate: more than the box's, not three times.
            let factor = match model {
                NetModel::Truck | NetModel::Lander => 3.0,
                _ => 1.0,
            };
            assert!(
                a >= 0.3 && a > factor * b,
                "{}: typical {a}, box {b}",
                model.name()
            );
            let limits = model.control_limits();
            for c in 0..model.control_dim() {
                let col = typical.controls.column(c);
                let (lo, hi) = col
                    .iter()
                    .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), &v| {
                        (l.min(v), h.max(v))
                    });
                let half = 0.5 * (limits.high[c] - limits.low[c]);
                assert!(
                    lo <= limits.centre(c) - 0.7 * half && hi >= limits.centre(c) + 0.7 * half,
                    "{} channel {c}: [{lo}, {hi}]",
                    model.name()
                );
            }
        }
        // The typical lander flies near upright: no example upside down (the box's data had
        // 15 % upside down).
        let lander = regime_data(NetModel::Lander, DataRegime::Typical);
        let upside_down = (0..lander.len())
            .filter(|&r| {
                let (x, y) = (lander.states[[r, 4]], lander.states[[r, 5]]);
                1.0 - 2.0 * (x * x + y * y) < 0.0
            })
            .count();
        assert!(
            upside_down * 100 <= lander.len(),
            "{upside_down} upside down"
        );
        // A quarter of the pendulum's typical episodes start hanging at rest (the tasks' start).
        let mut rng = ChaCha8Rng::seed_from_u64(2);
        let hanging = (0..400)
            .filter(|_| {
                NetModel::PendulumActive
                    .typical_start_state(&mut rng)
                    .iter()
                    .all(|&v| v == 0.0)
            })
            .count();
        assert!((60..=140).contains(&hanging), "{hanging} of 400 hanging");
    }

    /// [`regime_fidelity`] measures in tolerance units: one row per positive tolerance, in
    /// order, finite, RMS at least |bias|; doubling a tolerance halves that row's numbers and
    /// leaves the others; every data regime of a net is measured on the same (typical) test.
    #[test]
    fn regime_fidelity_is_in_tolerance_units() {
        let spec = small(NetModel::Truck, 6, 200, 10);
        let trained = train_emulator(&spec).unwrap();
        let tol = [0.5, 0.5, 0.05, 0.0, 0.0, 0.0];
        let rows = regime_fidelity(&trained.emulator, &spec, &tol, 4, 6).unwrap();
        assert_eq!(
            rows.iter().map(|r| r.variable).collect::<Vec<_>>(),
            [0, 1, 2]
        );
        for r in &rows {
            assert!(r.bias_tol.is_finite() && r.rms_tol.is_finite() && r.rollout_tol.is_finite());
            assert!(
                r.rms_tol >= r.bias_tol.abs() && r.rollout_tol >= 0.0,
                "{r:?}"
            );
        }
        let wider = [1.0, 0.5, 0.05, 0.0, 0.0, 0.0];
        let again = regime_fidelity(&trained.emulator, &spec, &wider, 4, 6).unwrap();
        assert!((again[0].rms_tol * 2.0 - rows[0].rms_tol).abs() < 1e-12);
        assert!((again[0].rollout_tol * 2.0 - rows[0].rollout_tol).abs() < 1e-12);
        assert_eq!(again[1], rows[1]);
        let mut boxed = spec.clone();
        boxed.net.data = DataRegime::Box;
        let same = regime_fidelity(&trained.emulator, &boxed, &tol, 4, 6).unwrap();
        assert_eq!(
            same, rows,
            "measured on the typical test whatever the net's data"
        );
    }

    /// A rollout reference starts where the examples do, one lag into an episode, not at an
    /// episode's start: the passive pendulum's starts lie about as near the training examples'
    /// states as held-out examples do (median distance to the nearest example, in units of
    /// each variable's spread; a start is always an episode's first example, where the swing
    /// is largest and the examples sparsest, so a little farther), while the episodes' raw
    /// starts (the null), whose elbow velocities friction damps within the first super-step,
    /// lie more than ten times farther still.
    #[test]
    fn rollout_references_start_where_the_examples_do() {
        let spec = small(NetModel::PendulumPassive, 4, 800, 50);
        let examples = training_transitions(&spec).unwrap();
        let rows = |t: &Transitions| -> Vec<Vec<f64>> {
            t.states.rows().into_iter().map(|r| r.to_vec()).collect()
        };
        let data = rows(&examples);
        let spread: Vec<f64> = (0..6)
            .map(|v| {
                let mean = data.iter().map(|x| x[v]).sum::<f64>() / data.len() as f64;
                (data.iter().map(|x| (x[v] - mean).powi(2)).sum::<f64>() / data.len() as f64).sqrt()
            })
            .collect();
        let median_nearest = |points: &[Vec<f64>]| {
            let mut d: Vec<f64> = points
                .iter()
                .map(|p| {
                    data.iter()
                        .map(|x| {
                            (0..6)
                                .map(|v| ((p[v] - x[v]) / spread[v]).powi(2))
                                .sum::<f64>()
                        })
                        .fold(f64::INFINITY, f64::min)
                        .sqrt()
                })
                .collect();
            d.sort_by(f64::total_cmp);
            d[d.len() / 2]
        };
        let held = median_nearest(&rows(&sampled(&spec, 200, 2).unwrap()));
        let reference = RolloutReference::sample(&spec, 200, 1).unwrap();
        let starts: Vec<Vec<f64>> = reference.starts.chunks(6).map(<[f64]>::to_vec).collect();
        let ours = median_nearest(&starts);
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let raw: Vec<Vec<f64>> = (0..200).map(|_| spec.start_state(&mut rng)).collect();
        let null = median_nearest(&raw);
        eprintln!("median distance to the nearest example: held-out {held:.4}, reference starts {ours:.4}, raw starts {null:.4}");
        assert!(
            ours < 4.0 * held,
            "reference starts {ours} against held-out {held}"
        );
        assert!(
            null > 10.0 * ours,
            "the null: raw starts {null} against ours {ours}"
        );
    }

    /// The data regime is part of the cache key: a box net and a typical net of the same spec
    /// are different nets, and typical (the default) is left out of the serialized spec.
    #[test]
    fn the_data_regime_keys_the_cache() {
        let spec = small(NetModel::Truck, 5, 100, 10);
        let mut boxed = spec.clone();
        boxed.net.data = DataRegime::Box;
        let (a, b) = (
            super::super::cache::EmulatorCache::key(&spec),
            super::super::cache::EmulatorCache::key(&boxed),
        );
        assert_ne!(a, b);
        assert!(serde_json::to_value(&spec.net)
            .unwrap()
            .get("data")
            .is_none());
        assert_eq!(serde_json::to_value(&boxed.net).unwrap()["data"], "box");
    }

    #[test]
    fn truck_data_show_the_rest_the_parking_task_starts_and_ends_in() {
        // §3.4: sample the states the tasks visit. Parking starts and ends at rest, so at-rest
        // examples under idle controls (and low speeds) must be a real share of the data, not
        // the measure-zero set uniform speeds in [−3, 8] m/s would give.
        let data = catalog_data(NetModel::Truck, 20);
        let speed = |r: usize| data.states[[r, 3]].hypot(data.states[[r, 4]]);
        let idle = |r: usize| data.controls.row(r).iter().all(|&u| u == 0.0);
        let rows = data.states.nrows();
        let at_rest = (0..rows).filter(|&r| speed(r) < 1e-9 && idle(r)).count();
        let slow = (0..rows).filter(|&r| speed(r) < 1.0).count();
        // Our thresholds: at least 1 % (30 of 3,000) at exact rest with idle controls (a quarter
        // of the episodes start at rest and half of those stay parked through an idle first
        // knot of 0.5-2 s: 45 here; 23 before the idle first knots), and
        // at least 15 % below 1 m/s (a third of the episodes start below 1.5 m/s).
        assert!(at_rest * 100 >= rows, "{at_rest} of {rows} at rest");
        assert!(slow * 100 >= 15 * rows, "{slow} of {rows} below 1 m/s");
        // At rest under idle controls the simulator stays exactly put.
        for r in (0..rows).filter(|&r| speed(r) < 1e-9 && idle(r)) {
            for k in 0..6 {
                assert_eq!(data.states[[r, k]], data.next_states[[r, k]]);
            }
        }
    }

    #[test]
    fn lander_data_show_idle_jets_and_still_starts_at_every_thrust() {
        // §3.4 again: the landing task starts with the jets still (zero body rates) and its
        // neutral control is hover thrust with zero torque, under which the attitude coasts.
        // Uniform torques never show the net zero torque; idle knots must, at any thrust.
        let data = &catalog_data(NetModel::Lander, 50);
        let rows = data.states.nrows();
        let idle = |r: usize| (1..4).all(|j| data.controls[[r, j]] == 0.0);
        let still = |r: usize| (10..13).all(|k| data.states[[r, k]] == 0.0);
        let idle_rows: Vec<usize> = (0..rows).filter(|&r| idle(r)).collect();
        // Our thresholds: at least 15 % of the examples with idle jets (a quarter of the knots),
        // their thrusts spread over the range (not all at one end), and some still and idle.
        assert!(
            idle_rows.len() * 100 >= 15 * rows,
            "{} of {rows} idle",
            idle_rows.len()
        );
        let thrust: Vec<f64> = idle_rows.iter().map(|&r| data.controls[[r, 0]]).collect();
        let hover = {
            let l = Lander::default();
            l.mass * l.gravity
        };
        let (below, above) = (
            thrust.iter().filter(|&&t| t < hover).count(),
            thrust.iter().filter(|&&t| t > hover).count(),
        );
        assert!(
            below * 4 >= thrust.len() && above * 4 >= thrust.len(),
            "idle thrusts {below} below and {above} above hover"
        );
        let still_idle: Vec<usize> = idle_rows.iter().copied().filter(|&r| still(r)).collect();
        assert!(
            still_idle.len() >= 10,
            "{} still and idle",
            still_idle.len()
        );
        // Still jets under zero torque stay still on the simulator (Euler's equations).
        for &r in &still_idle {
            for k in 10..13 {
                assert_eq!(data.next_states[[r, k]], 0.0, "row {r}");
            }
        }
    }

    /// Every normalization's groups cover the net's inputs and outputs; quantity groups share
    /// one mean and deviation within a group and differ from per-variable statistics where a
    /// group pools variables; per variable is left out of the serialized spec (so the cache
    /// keys of the nets built before the field existed do not change).
    #[test]
    fn normalization_groups_cover_the_nets_and_pool_their_members() {
        for model in NetModel::ALL {
            let (n, m) = (model.state_dim(), model.control_dim());
            assert!(model.groups(Normalization::Variable).is_none());
            for norm in [Normalization::Quantities, Normalization::StateControl] {
                let (inputs, outputs) = model.groups(norm).expect("grouped");
                assert_eq!(
                    (inputs.len(), outputs.len()),
                    (n + m, n),
                    "{model:?} {norm:?}"
                );
                assert_eq!(&inputs[..n], &outputs[..], "{model:?} {norm:?}");
                // Controls never share a group with the state.
                assert!(inputs[n..].iter().all(|g| !outputs.contains(g)));
            }
        }
        let model = NetModel::Lander;
        let spec = |normalization| BuildSpec {
            net: NetSpec {
                model,
                hidden: 4,
                examples: 200,
                method: TrainMethod::Lbfgs,
                physical_dt: 0.01,
                input_noise: None,
                anchor: false,
                normalization,
                transforms: Default::default(),
                data: Default::default(),
            },
            steps: 5,
            settings: TrainSettings::for_tests(1, 1, 1),
            seed: 3,
        };
        let json = serde_json::to_string(&spec(Normalization::Variable).net).unwrap();
        assert!(!json.contains("normalization"), "{json}");
        let t = training_data(&spec(Normalization::Quantities))
            .unwrap()
            .transforms;
        let per_var = training_data(&spec(Normalization::Variable))
            .unwrap()
            .transforms;
        let (inputs, _) = model.groups(Normalization::Quantities).unwrap();
        for (a, b) in (0..inputs.len()).flat_map(|a| (0..inputs.len()).map(move |b| (a, b))) {
            if inputs[a] == inputs[b] {
                assert_eq!(t.input_norm.std[a], t.input_norm.std[b], "inputs {a}, {b}");
                assert_eq!(
                    t.input_norm.mean[a], t.input_norm.mean[b],
                    "inputs {a}, {b}"
                );
            }
        }
        // The velocity group (world velocity in the heading frame: 7..10) pools three spreads.
        assert!((7..10).any(|k| t.input_norm.std[k] != per_var.input_norm.std[k]));
    }

    #[test]
    #[ignore = "a known limitation, kept as its record: an \
                unanchored net's drift at rest is its bias at one point: here 3.4 m one-step without noise, 0.94 m with 0.05 (0.46 m and 0.05 m \
                at 1,000 iterations); with na_table1_structure's k = 8 rollout fine-tuning \
                (600 iterations, no noise) 0.72 m (1.3 m with noise 0.05); full scale 0.99 m \
                with the idle first knots (1.81 m before them, 5.95 m before the rest starts); \
                slow (25 s). The experiments now anchor their nets (anchor = true): a step from \
                rest is then exact by construction (staying there needs a net stable at rest): \
                an_anchored_net_reproduces_its_equilibrium_whichever_trainer_made_it. Off the \
                anchor the bias remains: na_table1_structure's drift.csv reports a parked truck \
                steered (1.06 m in 20 s, tolerance 0.5 m) and a coasting one (0.53 m gap)"]
    fn a_truck_emulator_parked_with_zero_controls_stays_parked() {
        // The parking task's start, at rest; 20 s of zero controls in 0.5 s super-steps, from
        // a net trained as na_table1_structure's truck: no input noise, k = 8 rollout
        // fine-tuning.
        let mut spec = small(NetModel::Truck, 40, 5200, 50);
        spec.settings.rollout_k = 8;
        spec.settings.rollout_weight = 1.0;
        spec.settings.rollout_iters = 600;
        let e = train_emulator(&spec).unwrap().emulator;
        let x0 = [-15.0, -8.0, 0.4, 0.0, 0.0, 0.0];
        let (mut x, mut next, mut scratch) = (x0.to_vec(), vec![0.0; 6], e.scratch());
        for _ in 0..40 {
            e.predict(&x, &[0.0, 0.0], &mut scratch, &mut next);
            x.copy_from_slice(&next);
        }
        // The simulator stays exactly put; the emulator must stay within the task's final
        // tolerance (0.5 m, 0.05 rad).
        let moved = (x[0] - x0[0]).hypot(x[1] - x0[1]);
        let turned = (x[2] - x0[2]).abs();
        assert!(
            moved < 0.5 && turned < 0.05,
            "moved {moved} m, turned {turned} rad: {x:?}"
        );
    }

    /// The noise injection's corrected targets lead back to the true next state: decoding a
    /// perturbed example's target at its perturbed state gives the simulated next state
    /// (truck: planar frame; lander: heading frame), and the perturbation is real.
    #[test]
    fn noisy_examples_target_the_true_next_state() {
        for model in [NetModel::Truck, NetModel::Lander] {
            let spec = small(model, 5, 200, 10);
            let mut sim = model.simulator();
            let start = |r: &mut ChaCha8Rng| model.start_state(r);
            let data = sample_transitions(
                sim.as_mut(),
                &start,
                &model.control_limits(),
                &spec.sampling(200),
                &mut ChaCha8Rng::seed_from_u64(6),
            )
            .unwrap()
            .transitions;
            let t = Transforms::fit(&model.transform_config(), &data).unwrap();
            let clean = t.encode(&data);
            let noisy = t.perturb(&clean, 0.1, &mut ChaCha8Rng::seed_from_u64(7));
            let (n, m) = (model.state_dim(), model.control_dim());
            let (mut s, mut u) = (vec![0.0; n], vec![0.0; m]);
            let (mut tmp, mut next) = (vec![0.0; n], vec![0.0; n]);
            let mut moved: f64 = 0.0;
            for r in 0..data.len() {
                let ps = data.states.row(r).to_vec();
                t.decode_input(&ps, noisy.inputs.row(r).as_slice().unwrap(), &mut s, &mut u);
                moved = moved.max((0..n).map(|k| (s[k] - ps[k]).abs()).fold(0.0, f64::max));
                t.decode_output(
                    &s,
                    noisy.targets.row(r).as_slice().unwrap(),
                    &mut tmp,
                    &mut next,
                );
                for k in 0..n {
                    let want = data.next_states[[r, k]];
                    assert!(
                        (next[k] - want).abs() < 1e-9 * (1.0 + want.abs()),
                        "{} example {r} variable {k}: {} vs {want}",
                        model.name(),
                        next[k]
                    );
                }
                // Controls are not perturbed.
                assert_eq!(
                    noisy.inputs.row(r).slice(ndarray::s![n..]),
                    clean.inputs.row(r).slice(ndarray::s![n..])
                );
            }
            assert!(moved > 1e-3, "{}: no perturbation", model.name());
        }
    }

    #[test]
    fn the_lander_frame_keeps_the_tilt_and_removes_only_heading() {
        // Heading is a symmetry of the lander under gravity: it must not reach the net.
        let (a, b) = (to_local(&tilted(0.3, 0.0)), to_local(&tilted(0.3, 2.0)));
        for k in 0..13 {
            assert!(
                (a[k] - b[k]).abs() < 1e-12,
                "variable {k}: {} vs {}",
                a[k],
                b[k]
            );
        }
        // Tilt is not a symmetry: an upright and a tilted lander must look different, with the
        // local quaternion the tilt itself.
        let up = to_local(&tilted(0.0, 2.0));
        assert!((up[3] - 1.0).abs() < 1e-12);
        let want = [0.15f64.cos(), 0.15f64.sin(), 0.0, 0.0];
        for k in 0..4 {
            assert!(
                (a[3 + k] - want[k]).abs() < 1e-12,
                "local quaternion {:?}",
                &a[3..7]
            );
        }
    }

    #[test]
    fn a_tilted_lander_at_hover_thrust_drifts_sideways_on_emulator_and_simulator_alike() {
        // A small lander emulator (N = 25, 0.25 s super-steps) trained on the §3.4 data.
        let spec = small(NetModel::Lander, 30, 4000, 25);
        let trained = train_emulator(&spec).unwrap();
        let e = trained.emulator;
        let lander = Lander::default();
        let hover = [lander.mass * lander.gravity, 0.0, 0.0, 0.0];
        let x0 = tilted(0.3, 0.7);
        let mut sim = NetModel::Lander.simulator();
        let mut xs = x0.clone();
        let mut xe = x0.clone();
        let (mut scratch, mut next) = (e.scratch(), vec![0.0; 13]);
        for _ in 0..16 {
            for _ in 0..spec.steps {
                sim.step(&mut xs, &hover, spec.net.physical_dt);
            }
            e.predict(&xe, &hover, &mut scratch, &mut next);
            xe.copy_from_slice(&next);
        }
        let drift = |x: &[f64]| [x[0] - x0[0], x[1] - x0[1]];
        let (ds, de) = (drift(&xs), drift(&xe));
        let norm = |d: [f64; 2]| d[0].hypot(d[1]);
        // The simulator: the thrust's horizontal part, g·sin(0.3) ≈ 0.48 m/s² under lunar
        // gravity, pushes it about 3.8 m in 4 s along the tilt.
        assert!(norm(ds) > 3.0, "simulator drift {ds:?}");
        // The emulator must drift the same way by a similar amount (our tolerance: 40 %).
        let err = norm([de[0] - ds[0], de[1] - ds[1]]);
        assert!(
            err < 0.4 * norm(ds),
            "emulator drift {de:?} vs simulator {ds:?}"
        );
    }

    /// What anchoring rests on: each model's equilibrium with its neutral control is a fixed
    /// point of its simulator (100 RK4 steps of 0.01 s).
    #[test]
    fn every_model_equilibrium_is_a_fixed_point_of_its_simulator() {
        for model in NetModel::ALL {
            let (s0, u) = model.equilibrium();
            let mut sim = model.simulator();
            let mut s = s0.clone();
            for _ in 0..100 {
                sim.step(&mut s, &u, 0.01);
            }
            for (k, (a, b)) in s.iter().zip(&s0).enumerate() {
                assert!(
                    (a - b).abs() < 1e-9,
                    "{}: variable {k} {b} -> {a}",
                    model.name()
                );
            }
        }
    }

    /// An anchored net reproduces its equilibrium exactly whichever trainer made it (L-BFGS,
    /// momentum mini-batches, then the k-step rollout fine-tuning), and through the local
    /// frame a truck parked anywhere with zero controls stays parked over a super-step; the
    /// same net unanchored does not (so the check can fail).
    #[test]
    fn an_anchored_net_reproduces_its_equilibrium_whichever_trainer_made_it() {
        for method in [TrainMethod::Lbfgs, TrainMethod::Momentum] {
            let mut spec = small(NetModel::Truck, 8, 400, 50);
            spec.net.method = method;
            spec.settings.cg_max_iters = 40;
            spec.settings.max_epochs = 3;
            spec.settings.learning_rate = 0.05;
            spec.settings.momentum = 0.9;
            spec.settings.rollout_k = 3;
            spec.settings.rollout_weight = 1.0;
            spec.settings.rollout_iters = 10;
            // One super-step from parked poses (whether rest stays rest over many steps is
            // the fit's stability near the anchor, measured by na_table1_structure).
            let parked = |e: &Emulator| {
                let mut worst = 0.0_f64;
                for pose in [[7.0, -3.0, 2.5], [-40.0, 12.0, -1.0], [0.0, 0.0, 0.0]] {
                    let x0 = [pose[0], pose[1], pose[2], 0.0, 0.0, 0.0];
                    let mut next = vec![0.0; 6];
                    e.predict(&x0, &[0.0, 0.0], &mut e.scratch(), &mut next);
                    for (a, b) in next.iter().zip(&x0) {
                        worst = worst.max((a - b).abs());
                    }
                }
                worst
            };
            let free = train_emulator(&spec).unwrap().emulator;
            spec.net.anchor = true;
            let anchored = train_emulator(&spec).unwrap().emulator;
            let a = anchor_of(&spec, anchored.transforms()).unwrap();
            assert!(a.residual(anchored.mlp()) < 1e-12, "{method:?}");
            assert!(
                parked(&anchored) < 1e-12,
                "{method:?}: {}",
                parked(&anchored)
            );
            assert!(a.residual(free.mlp()) > 1e-6, "{method:?}");
            assert!(parked(&free) > 1e-6, "{method:?}: {}", parked(&free));
        }
    }
}
