//! Parameters of `x_lbc_emulator` ([`Params`]) and their validation, and what they define: the
//! Fig. 13 task per target, the control map, the tracker cost and LBC's λ.

use crate::control::bptt::StepRule;
use crate::control::step_tracker::AffineControls;
use crate::control::QuadraticCost;
use crate::emulator::catalog::{NetModel, NetSpec, TrainSettings};
use crate::emulator::Emulator;
use crate::experiment::resolve::{ensure, positive, ParamError, Validate};
use crate::families::na::control_task::{keyed, ControlTask};
use crate::families::na::fig13_control::{Formulation, Task};
use crate::families::na::table1_structure::{validate_nets, validate_training};
use crate::physics::lander::Lander;
use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};

/// Parameters of `x_lbc_emulator`.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Params {
    /// Physical steps per emulator step n (N50: 50).
    pub steps: usize,
    /// Multiplies the net's example count.
    pub example_scale: f64,
    /// The emulator net (lander or truck).
    pub net: NetSpec,
    /// Training settings (those of `na_table1_structure`, so the net comes from the cache).
    pub training: TrainSettings,
    /// The task: `horizon` emulator steps M, `knots` per actuator K, BPTT `iterations` of
    /// each learning run, `start`, `target` (its `axis` component is replaced by each
    /// target's value), `final_tolerance` and `effort_mu` (keys beside the others).
    #[serde(flatten, deserialize_with = "keyed")]
    pub task: ControlTask,
    /// BPTT step rule (e.g. Levenberg–Marquardt).
    pub step_rule: StepRule,
    /// Index of the state variable the targets differ in.
    pub axis: usize,
    /// The two components' targets on the axis.
    pub components: [f64; 2],
    /// Desired targets on the axis.
    pub desired: Vec<f64>,
    /// Intensity σ_u of white noise on the normalized controls (√s); λ = σ_u² μ_u/Δt.
    pub control_noise: f64,
    /// Ours: the fraction of strictly in-between targets on which LBC's simulator error must
    /// be ≤ 1.
    pub within_fraction: f64,
    /// Ours: LBC's mean simulator error over the in-between targets may exceed naive's by at
    /// most this (tolerance units).
    pub naive_margin: f64,
    /// Ours: LBC's mean distance of the final position on the axis from the desired target
    /// (simulator, in-between targets) may exceed naive's by at most this (m).
    pub axis_margin: f64,
    /// Further seeds of the lander net (beside the run's own) through which the whole
    /// comparison is repeated (`net_seeds.csv`); the rule reads the median over all of them. At
    /// most [`MAX_NET_SEEDS`].
    #[serde(default)]
    pub net_seeds: Vec<u64>,
}

/// The most net seeds a run may name (each is a lander net to train when not cached).
pub const MAX_NET_SEEDS: usize = 16;

impl Validate for Params {
    fn validate(&self) -> Result<(), ParamError> {
        ensure(self.steps >= 1, "steps", "must be >= 1")?;
        let model = self.net.model;
        ensure(
            matches!(model, NetModel::Lander | NetModel::Truck),
            "net.model",
            "must be lander or truck",
        )?;
        let n = model.state_dim();
        self.task.validate(n)?;
        self.step_rule.validate("step_rule")?;
        ensure(
            self.task.final_tolerance.iter().all(|&x| x >= 0.0),
            "final_tolerance",
            "must be >= 0",
        )?;
        ensure(self.axis < n, "axis", format!("must be < {n}"))?;
        ensure(
            self.task.final_tolerance[self.axis] > 0.0,
            "final_tolerance",
            "the axis needs a tolerance > 0",
        )?;
        positive("effort_mu", self.task.effort_mu)?;
        ensure(
            self.components[0] < self.components[1],
            "components",
            "must be increasing",
        )?;
        ensure(!self.desired.is_empty(), "desired", "needs at least one")?;
        ensure(
            self.desired.iter().all(|d| d.is_finite()),
            "desired",
            "must be finite",
        )?;
        positive("control_noise", self.control_noise)?;
        ensure(
            (0.0..=1.0).contains(&self.within_fraction),
            "within_fraction",
            "must be in [0, 1]",
        )?;
        ensure(self.naive_margin >= 0.0, "naive_margin", "must be >= 0")?;
        ensure(self.axis_margin >= 0.0, "axis_margin", "must be >= 0")?;
        ensure(
            self.net_seeds.len() <= MAX_NET_SEEDS,
            "net_seeds",
            format!("at most {MAX_NET_SEEDS}"),
        )?;
        validate_nets(std::slice::from_ref(&self.net), self.example_scale)?;
        validate_training(&self.training)
    }
}

impl Params {
    pub(super) fn super_dt(&self) -> f64 {
        self.net.physical_dt * self.steps as f64
    }

    /// The Fig. 13 task reaching `value` on the axis.
    pub(super) fn target_task(&self, value: f64) -> Task {
        let mut target = self.task.target.clone();
        target[self.axis] = value;
        Task {
            name: format!("target {value}"),
            net: self.net.clone(),
            task: ControlTask {
                target,
                ..self.task.clone()
            },
            limit_fraction: 1.0,
            eta: 1.0,
            alpha: 0.0,
            step_rule: self.step_rule,
            formulation: Formulation::Paper,
            initial_knots: None,
            control_units: Default::default(),
            final_weights: Default::default(),
            calibration: None,
        }
    }

    pub(super) fn start_state(&self) -> Vec<f64> {
        let mut x0 = self.task.start.clone();
        if self.net.model == NetModel::Lander {
            Lander::default().normalize_state(&mut x0);
        }
        x0
    }

    /// Centre and half-width of each actuator's box: u = centre + half-width ⊙ v.
    pub(super) fn control_map<'a>(&self, emu: &'a Emulator) -> AffineControls<'a, Emulator> {
        let l = self.net.model.control_limits();
        AffineControls {
            inner: emu,
            offset: (0..l.low.len())
                .map(|j| 0.5 * (l.low[j] + l.high[j]))
                .collect(),
            scale: (0..l.low.len())
                .map(|j| 0.5 * (l.high[j] - l.low[j]))
                .collect(),
        }
    }

    /// R = μ_u/Δt in normalized controls.
    pub(super) fn control_weight(&self) -> f64 {
        self.task.effort_mu / self.super_dt()
    }

    /// λ = σ_u² R (eq. 8).
    pub(super) fn lambda(&self) -> f64 {
        self.control_noise * self.control_noise * self.control_weight()
    }

    /// Terminal weight Q_k = 1/(2σ_k²) of variable k (0 without a tolerance).
    pub(super) fn terminal_weight(&self, k: usize) -> f64 {
        let s = self.task.final_tolerance[k];
        if s > 0.0 {
            0.5 / (s * s)
        } else {
            0.0
        }
    }

    /// The tracker cost for the target `value` (the BPTT objective per super-step).
    pub(super) fn cost(&self, value: f64, m: usize) -> QuadraticCost {
        let n = self.task.target.len();
        let task = self.target_task(value);
        QuadraticCost {
            dt: self.super_dt(),
            r: DMatrix::identity(m, m) * self.control_weight(),
            state: None,
            q_final: DMatrix::from_fn(
                n,
                n,
                |i, j| {
                    if i == j {
                        self.terminal_weight(i)
                    } else {
                        0.0
                    }
                },
            ),
            x_final: DVector::from_column_slice(&task.task.target),
        }
    }
}
