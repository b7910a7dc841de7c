//! One control-learning task of `na_fig13_control` ([`Task`]): its control box, rest control,
//! objective and final error, and the final-state Jacobian rows the conditioning study reads.

use super::Sweep;
use crate::control::bptt::{Bounds, Bptt, DifferentiableStep, StepRule};
use crate::control::objective::{ControlEffort, FinalState, Objective};
use crate::emulator::catalog::{NetModel, NetSpec};
use crate::families::na::control_task::{keyed, ControlTask};
use crate::physics::lander::Lander;
use serde::{Deserialize, Serialize};

/// One control-learning task.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Task {
    /// Name in the tables.
    pub name: String,
    /// The emulator net (its model is the task's model).
    pub net: NetSpec,
    /// Horizon, knots, budget, start, target, tolerances and effort weight (keys beside the
    /// others: `tasks[i].horizon`, …).
    #[serde(flatten, deserialize_with = "keyed")]
    pub task: ControlTask,
    /// Control bounds as a fraction of the training limits (about their centre).
    pub limit_fraction: f64,
    /// Learning rate η (units of 1/λ).
    pub eta: f64,
    /// Momentum α (0: plain descent).
    pub alpha: f64,
    /// How the step scale evolves ([`StepRule`]; default `fixed`, the paper's).
    #[serde(default)]
    pub step_rule: StepRule,
}

impl Task {
    /// The control box: the training limits scaled about their centre.
    pub fn bounds(&self) -> Bounds {
        let l = self.net.model.control_limits();
        let (mut low, mut high) = (l.low.clone(), l.high.clone());
        for j in 0..low.len() {
            let (c, h) = (0.5 * (l.low[j] + l.high[j]), 0.5 * (l.high[j] - l.low[j]));
            low[j] = c - self.limit_fraction * h;
            high[j] = c + self.limit_fraction * h;
        }
        Bounds { low, high }
    }

    /// Initial (and effort reference) control: zero, or hover thrust for the lander.
    pub fn rest_control(&self) -> Vec<f64> {
        let mut u = vec![0.0; self.net.model.control_dim()];
        if self.net.model == NetModel::Lander {
            let l = Lander::default();
            u[0] = l.mass * l.gravity;
        }
        u
    }

    fn weights(&self) -> Vec<f64> {
        self.task
            .final_tolerance
            .iter()
            .map(|&t| if t > 0.0 { 1.0 / (t * t) } else { 0.0 })
            .collect()
    }

    /// The objective (see the module docs).
    pub fn objective(&self) -> Objective {
        let l = self.net.model.control_limits();
        let scale = (0..l.low.len())
            .map(|j| 0.5 * (l.high[j] - l.low[j]))
            .collect();
        Objective::default()
            .with(ControlEffort {
                mu: self.task.effort_mu,
                offset: self.rest_control(),
                scale,
            })
            .with(FinalState {
                mu: 1.0,
                target: self.task.target.clone(),
                weights: self.weights(),
            })
    }

    /// Independent final-state variables the objective weighs (the rank its terminal
    /// Gauss-Newton matrix can have).
    pub fn final_dof(&self) -> usize {
        let n = self.net.model.state_dim();
        // The lander's unit quaternion has 3 degrees of freedom, not 4.
        n - usize::from(self.net.model == NetModel::Lander)
    }

    /// The weighted final-state variables that are independent: all with a tolerance but
    /// the lander's quaternion scalar part (the unit norm ties it to the vector part, and at
    /// level attitude it responds only at second order).
    pub fn independent_final_vars(&self) -> Vec<usize> {
        let lander = self.net.model == NetModel::Lander;
        (0..self.task.final_tolerance.len())
            .filter(|&k| self.task.final_tolerance[k] > 0.0 && !(lander && k == 3))
            .collect()
    }

    /// The Jacobian rows ∂s_M/∂v of [`Task::independent_final_vars`] at knots `v`.
    pub(super) fn final_rows<D: DifferentiableStep>(
        &self,
        bptt: &mut Bptt<'_, D>,
        v: &[f64],
    ) -> Vec<Vec<f64>> {
        bptt.state_jacobian(v, self.task.horizon, &self.independent_final_vars())
    }

    /// The headline's rule alone (fixed step, the task's eta and alpha) for `iterations`.
    pub(super) fn headline_sweep(&self, iterations: usize) -> Sweep {
        Sweep {
            eta: vec![self.eta],
            alpha: self.alpha,
            iterations,
            rules: vec![StepRule::Fixed],
        }
    }

    /// RMS of (s − s_d)/σ over the variables with a tolerance.
    pub fn final_error(&self, s: &[f64]) -> f64 {
        let w = self.weights();
        let k = w.iter().filter(|&&w| w > 0.0).count().max(1);
        let sum: f64 = (0..s.len())
            .map(|i| w[i] * (s[i] - self.task.target[i]) * (s[i] - self.task.target[i]))
            .sum();
        (sum / k as f64).sqrt()
    }
}
