//! # Physics models and their integration
//!
//! Every model is a continuous-time system ẋ = f(x, u) ([`Ode`]) described by a [`Model`]
//! (names of its state and control variables, its parameters with units, its natural time step).
//! A [`Simulator`] pairs an [`Ode`] with an [`Integrator`] and implements the discrete
//! [`Dynamics`] trait: `step(x, u, dt)` advances the state by `dt` seconds. Learned emulators
//! implement [`Dynamics`] as well, so controllers and searches run unchanged on either.
//! [`DifferentiableStep`] ([`differentiable`]) is a discrete step with its vector–Jacobian
//! product, what backpropagation through time needs; emulators implement it, and so does the
//! RK4 step of any [`linearize::Linearize`] model (`control::Rk4Map`).
//!
//! Physics knows nothing of learning, control or files.
//!
//! Models: [`pendulum::Pendulum3`] (NeuroAnimator's 3-link pendulum), [`truck::Truck`] (its
//! rear-wheel-drive truck, a planar bicycle-model rigid body), [`lander::Lander`] (its lunar
//! lander, a 3-D rigid body with a main thruster and attitude jets), [`dolphin::Dolphin`] (its
//! muscle-driven mass-spring-damper dolphin), [`acrobot::Acrobot`] (the
//! two-link gymnast of linear Bellman combination), and general planar articulated trees
//! ([`planar::PlanarTree`]) with two instances: the seven-link [`diver::diver`] and the
//! [`push::push_figure`] of the push-recovery experiment; 3-D articulated trees with a floating
//! base ([`body3d::Tree3d`]: ball and revolute joints, Featherstone's algorithms) with the
//! [`body3d::chain3d()`] instance checked against MuJoCo.

pub mod acrobot;
pub mod biped;
pub mod body3d;
pub mod differentiable;
pub mod diver;
pub mod dolphin;
pub mod ground;
pub mod integrate;
pub mod jumper;
pub mod lander;
pub mod lattice;
pub mod linearize;
pub mod pendulum;
pub mod planar;
pub mod push;
pub mod reflex;
pub mod truck;

pub use differentiable::DifferentiableStep;
pub use integrate::{Integrator, IntegratorKind, Rk45Stats};

use serde::Serialize;

/// A physical parameter of a model, as `motionlab describe` prints it.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct Parameter {
    /// Parameter name, e.g. `link1.mass`.
    pub name: String,
    /// Current value.
    pub value: f64,
    /// SI unit, e.g. `kg`, `m`, `kg*m^2`, `N*m*s/rad`.
    pub unit: &'static str,
    /// One-line meaning.
    pub description: &'static str,
}

impl Parameter {
    /// Shorthand constructor.
    pub fn new(
        name: impl Into<String>,
        value: f64,
        unit: &'static str,
        description: &'static str,
    ) -> Self {
        Self {
            name: name.into(),
            value,
            unit,
            description,
        }
    }

    /// Gravitational acceleration g (m/s²); `description` says along what, or what it loads.
    pub fn gravity(value: f64, description: &'static str) -> Self {
        Self::new("gravity", value, "m/s^2", description)
    }

    /// The parameters of rigid link `link`: mass, length (meaning `length_description`),
    /// centre-of-mass distance from its joint, and moment of inertia about the centre of mass.
    pub fn rigid_link(
        link: &str,
        [mass, length, com, inertia]: [f64; 4],
        length_description: &'static str,
    ) -> [Self; 4] {
        [
            Self::new(format!("{link}.mass"), mass, "kg", "link mass"),
            Self::new(format!("{link}.length"), length, "m", length_description),
            Self::new(
                format!("{link}.com"),
                com,
                "m",
                "centre of mass distance from the link's joint",
            ),
            Self::new(
                format!("{link}.inertia"),
                inertia,
                "kg*m^2",
                "moment of inertia about the centre of mass",
            ),
        ]
    }

    /// Viscous friction of link `link`'s joint (N·m·s/rad).
    pub fn joint_damping(link: &str, value: f64) -> Self {
        Self::new(
            format!("{link}.damping"),
            value,
            "N*m*s/rad",
            "viscous friction at the link's joint",
        )
    }
}

/// What a model is: its variables, parameters and natural time step.
pub trait Model: Send + Sync {
    /// Registry name, e.g. `pendulum3`.
    fn name(&self) -> &str;
    /// Names of the state variables, in order.
    fn state_names(&self) -> Vec<String>;
    /// Names of the control variables, in order (empty for passive models).
    fn control_names(&self) -> Vec<String>;
    /// Physical parameters with units.
    fn parameters(&self) -> Vec<Parameter>;
    /// The model's natural simulation time step in seconds.
    fn default_dt(&self) -> f64;
    /// Number of state variables.
    fn state_dim(&self) -> usize {
        self.state_names().len()
    }
    /// Number of control variables.
    fn control_dim(&self) -> usize {
        self.control_names().len()
    }
}

/// A continuous-time system ẋ = f(x, u).
///
/// Second-order mechanical systems order their state as `[q, q̇]` and return
/// `Some(q.len())` from [`Ode::position_dim`], which the semi-implicit Euler integrator needs.
pub trait Ode: Model {
    /// Writes ẋ = f(x, u) into `dx` (same length as `x`). Must not allocate.
    fn derivative(&self, x: &[f64], u: &[f64], dx: &mut [f64]);
    /// Number of generalized positions when the state is `[q, q̇]`.
    fn position_dim(&self) -> Option<usize> {
        None
    }
    /// Total mechanical energy in joules, when the model defines it.
    fn energy(&self, _x: &[f64]) -> Option<f64> {
        None
    }
}

/// Discrete-time dynamics: advance a state by `dt` seconds under a control held constant.
///
/// Implemented by [`Simulator`] for physical models and by learned emulators.
pub trait Dynamics: Send {
    /// Number of state variables.
    fn state_dim(&self) -> usize;
    /// Number of control variables.
    fn control_dim(&self) -> usize;
    /// Advances `x` in place by `dt` seconds with control `u` held constant.
    fn step(&mut self, x: &mut [f64], u: &[f64], dt: f64);
}

/// A simulation that produced NaN or infinity.
#[derive(Debug, Clone, thiserror::Error, PartialEq)]
#[error("simulation of `{model}` blew up at step {step} (t = {t} s): state = {state:?}")]
pub struct BlowUp {
    /// Model name.
    pub model: String,
    /// Step index (0-based) whose result was not finite.
    pub step: usize,
    /// Simulated time at the end of that step, in seconds.
    pub t: f64,
    /// The non-finite state.
    pub state: Vec<f64>,
}

/// A physical model integrated by one of the [`Integrator`]s.
#[derive(Debug, Clone)]
pub struct Simulator<M> {
    /// The model.
    pub model: M,
    integrator: Integrator,
}

impl<M: Ode> Simulator<M> {
    /// Pairs a model with an integrator of the given kind (scratch buffers sized once here).
    pub fn new(model: M, kind: IntegratorKind) -> Self {
        let n = model.state_dim();
        Self {
            model,
            integrator: Integrator::new(kind, n),
        }
    }

    /// The integrator in use, with its statistics.
    pub fn integrator(&self) -> &Integrator {
        &self.integrator
    }

    /// Simulates `steps` steps of `dt` from `x0`, calling `control(step, t, x, u)` to fill the
    /// control before each step and `observe(step, t, x)` after each step (and once at step 0
    /// before any integration). Stops with [`BlowUp`] when the state becomes non-finite.
    pub fn rollout(
        &mut self,
        x0: &[f64],
        dt: f64,
        steps: usize,
        control: impl FnMut(usize, f64, &[f64], &mut [f64]),
        mut observe: impl FnMut(usize, f64, &[f64]),
    ) -> Result<Vec<f64>, BlowUp> {
        self.try_rollout(x0, dt, steps, control, |k, t, x| {
            observe(k, t, x);
            Ok(())
        })
    }

    /// [`Simulator::rollout`] with an observer that may fail (a writer whose reader went away):
    /// its first error stops the rollout and is returned; a blow-up comes back as `E`.
    pub fn try_rollout<E: From<BlowUp>>(
        &mut self,
        x0: &[f64],
        dt: f64,
        steps: usize,
        mut control: impl FnMut(usize, f64, &[f64], &mut [f64]),
        mut observe: impl FnMut(usize, f64, &[f64]) -> Result<(), E>,
    ) -> Result<Vec<f64>, E> {
        let mut x = x0.to_vec();
        let mut u = vec![0.0; self.model.control_dim()];
        observe(0, 0.0, &x)?;
        for k in 0..steps {
            let t = k as f64 * dt;
            control(k, t, &x, &mut u);
            self.step(&mut x, &u, dt);
            let t1 = (k + 1) as f64 * dt;
            check_finite(self.model.name(), k, t1, &x)?;
            observe(k + 1, t1, &x)?;
        }
        Ok(x)
    }
}

impl<M: Ode> Dynamics for Simulator<M> {
    fn state_dim(&self) -> usize {
        self.model.state_dim()
    }
    fn control_dim(&self) -> usize {
        self.model.control_dim()
    }
    fn step(&mut self, x: &mut [f64], u: &[f64], dt: f64) {
        self.integrator.step(&self.model, x, u, dt);
    }
}

/// Returns [`BlowUp`] when any component of `x` is NaN or infinite.
pub fn check_finite(model: &str, step: usize, t: f64, x: &[f64]) -> Result<(), BlowUp> {
    if x.iter().all(|v| v.is_finite()) {
        Ok(())
    } else {
        Err(BlowUp {
            model: model.to_string(),
            step,
            t,
            state: x.to_vec(),
        })
    }
}

/// Names of every model `motionlab describe` and `simulate` know.
pub const MODEL_NAMES: &[&str] = &[
    "pendulum3",
    "pendulum3_passive",
    "pendulum3_ext",
    "acrobot",
    "biped",
    "diver",
    "jumper",
    "push_recovery",
    "truck",
    "lander",
    "dolphin",
    "chain3d",
    "leaper3d",
];

/// Builds a model by registry name.
pub fn model_by_name(name: &str) -> Option<Box<dyn Ode>> {
    use pendulum::{Pendulum3, PendulumVariant};
    Some(match name {
        "pendulum3" => Box::new(Pendulum3::new(PendulumVariant::Active)),
        "pendulum3_passive" => Box::new(Pendulum3::new(PendulumVariant::Passive)),
        "pendulum3_ext" => Box::new(Pendulum3::new(PendulumVariant::ExtForce)),
        "acrobot" => Box::new(acrobot::Acrobot::default()),
        "biped" => Box::new(biped::Biped::default()),
        "diver" => Box::new(diver::diver()),
        "jumper" => Box::new(jumper::Jumper::default()),
        "push_recovery" => Box::new(push::push_figure()),
        "truck" => Box::new(truck::Truck::default()),
        "lander" => Box::new(lander::Lander::default()),
        "dolphin" => Box::new(dolphin::Dolphin::default()),
        "chain3d" => Box::new(body3d::chain3d()),
        "leaper3d" => Box::new(body3d::leaper3d()),
        _ => return None,
    })
}

impl Model for Box<dyn Ode> {
    fn name(&self) -> &str {
        (**self).name()
    }
    fn state_names(&self) -> Vec<String> {
        (**self).state_names()
    }
    fn control_names(&self) -> Vec<String> {
        (**self).control_names()
    }
    fn parameters(&self) -> Vec<Parameter> {
        (**self).parameters()
    }
    fn default_dt(&self) -> f64 {
        (**self).default_dt()
    }
    fn state_dim(&self) -> usize {
        (**self).state_dim()
    }
    fn control_dim(&self) -> usize {
        (**self).control_dim()
    }
}

impl Ode for Box<dyn Ode> {
    fn derivative(&self, x: &[f64], u: &[f64], dx: &mut [f64]) {
        (**self).derivative(x, u, dx)
    }
    fn position_dim(&self) -> Option<usize> {
        (**self).position_dim()
    }
    fn energy(&self, x: &[f64]) -> Option<f64> {
        (**self).energy(x)
    }
}

/// `motionlab describe`'s JSON for a model.
pub fn describe(model: &dyn Ode) -> serde_json::Value {
    serde_json::json!({
        "model": model.name(),
        "state": model.state_names(),
        "controls": model.control_names(),
        "parameters": model.parameters(),
        "dt": model.default_dt(),
        "dt_unit": "s",
    })
}
