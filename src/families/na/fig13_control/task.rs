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
    /// Whose formulation the task is: `paper` (default; the headline counts it) or `ours`
    /// (an earlier formulation of this project kept beside the paper's as a second line, so a
    /// change is visible; reported, never counted in the headline, no DAgger chain). Left out
    /// of the serialized task when `paper`, so the DAgger nets' cache keys of the paper's tasks
    /// are those of the tasks before the field existed.
    #[serde(default, skip_serializing_if = "Formulation::is_paper")]
    pub formulation: Formulation,
}

/// Whose task formulation a [`Task`] follows.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Formulation {
    /// The paper's (horizon, targets, units as the paper gives them; our rule where it is
    /// silent, written in the spec): the headline's tasks.
    #[default]
    Paper,
    /// One of ours that departs from the paper, kept as a second line for comparison.
    Ours,
}

impl Formulation {
    /// Whether it is the paper's.
    pub fn is_paper(&self) -> bool {
        *self == Formulation::Paper
    }

    /// The name in `final.csv`'s `formulation` column.
    pub fn name(self) -> &'static str {
        match self {
            Formulation::Paper => "paper",
            Formulation::Ours => "ours",
        }
    }
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::experiment::resolve::parse_params;
    use crate::experiment::spec::SpecFile;

    /// The spec's tasks: the paper's formulation by default, our earlier one only where the
    /// file says `formulation = "ours"`; a paper task serializes as before the field existed
    /// (the DAgger nets' cache keys), one of ours names its formulation.
    #[test]
    fn formulation_defaults_to_the_papers_and_is_serialized_only_when_ours() {
        let file = SpecFile::load(std::path::Path::new("experiments/na_fig13_control.toml"))
            .unwrap();
        let p: super::super::Params =
            parse_params(&toml::Value::Table(file.raw.params.clone())).unwrap();
        let names: Vec<(&str, Formulation)> = p
            .tasks
            .iter()
            .map(|t| (t.name.as_str(), t.formulation))
            .collect();
        assert_eq!(
            names,
            [
                ("pendulum", Formulation::Paper),
                ("truck", Formulation::Paper),
                ("lander", Formulation::Paper),
                ("pendulum_4s", Formulation::Ours),
            ]
        );
        // The paper's pendulum animates 20 s (200 N50 steps of 0.1 s), ours 4 s.
        let seconds = |t: &Task| t.task.horizon as f64 * t.net.physical_dt * p.steps as f64;
        assert!((seconds(&p.tasks[0]) - 20.0).abs() < 1e-9);
        assert!((seconds(&p.tasks[3]) - 4.0).abs() < 1e-9);
        let paper = serde_json::to_value(&p.tasks[0]).unwrap();
        assert!(paper.get("formulation").is_none(), "{paper}");
        let ours = serde_json::to_value(&p.tasks[3]).unwrap();
        assert_eq!(ours["formulation"], "ours");
        let mut raw = file.raw.params.clone();
        raw["tasks"].as_array_mut().unwrap()[0]
            .as_table_mut()
            .unwrap()
            .insert("formulation".into(), toml::Value::String("mine".into()));
        let e = parse_params::<super::super::Params>(&toml::Value::Table(raw)).unwrap_err();
        assert_eq!(e.key, "tasks[0].formulation", "{e}");
    }
}
