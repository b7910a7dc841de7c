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
    /// The controls descent starts from, per actuator `knots` values in control units (the
    /// spec says by which rule); absent: the rest control ([`Task::rest_control`]) throughout.
    /// Left out of the serialized task when absent (cache keys as before the field existed).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub initial_knots: Option<Vec<Vec<f64>>>,
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

    /// The knot values descent starts from (control units, knot k of actuator j at
    /// `k * m + j`): the spec's `initial_knots`, or the rest control at every knot.
    pub fn initial_knots(&self) -> Vec<f64> {
        let m = self.net.model.control_dim();
        let k = self.task.knots;
        match &self.initial_knots {
            Some(per_actuator) => (0..k * m).map(|i| per_actuator[i % m][i / m]).collect(),
            None => {
                let rest = self.rest_control();
                (0..k * m).map(|i| rest[i % m]).collect()
            }
        }
    }

    /// Checks `initial_knots`: one row per actuator of `knots` finite values within the
    /// task's control box (key `initial_knots`, the caller prefixes it).
    pub fn validate_initial_knots(&self) -> Result<(), crate::params::ParamError> {
        use crate::params::ensure;
        let Some(rows) = &self.initial_knots else {
            return Ok(());
        };
        let m = self.net.model.control_dim();
        ensure(
            rows.len() == m,
            "initial_knots",
            format!("needs one row per actuator ({m})"),
        )?;
        let b = self.bounds();
        for (j, row) in rows.iter().enumerate() {
            let key = format!("initial_knots[{j}]");
            ensure(
                row.len() == self.task.knots,
                &key,
                format!("needs {} values (knots)", self.task.knots),
            )?;
            ensure(
                row.iter()
                    .all(|u| u.is_finite() && *u >= b.low[j] && *u <= b.high[j]),
                &key,
                format!("must be finite and within [{}, {}]", b.low[j], b.high[j]),
            )?;
        }
        Ok(())
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
        // The weighted variables, less the lander's quaternion scalar part (its unit quaternion
        // has 3 degrees of freedom, not 4): a variable with tolerance 0 is not weighed.
        self.independent_final_vars().len()
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
        let file =
            SpecFile::load(std::path::Path::new("experiments/na_fig13_control.toml")).unwrap();
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
                ("truck_rest", Formulation::Ours),
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

    /// The truck's drive-then-brake start (the spec's rule): +a for the first half of the
    /// knots, -a for the second, steering 0, laid out knot by knot; `initial_knots` rows are
    /// checked against the actuators, the knots and the box; a task without them starts at rest.
    #[test]
    fn initial_knots_are_laid_out_by_knot_and_checked_against_the_box() {
        let file =
            SpecFile::load(std::path::Path::new("experiments/na_fig13_control.toml")).unwrap();
        let p: super::super::Params =
            parse_params(&toml::Value::Table(file.raw.params.clone())).unwrap();
        let truck = p.tasks.iter().find(|t| t.name == "truck").unwrap();
        let v = truck.initial_knots();
        assert_eq!(v.len(), 2 * truck.task.knots);
        // 100 a covers the start's 17 m to the target and ends at rest.
        let a = v[0];
        let dist = (truck.task.start[0].powi(2) + truck.task.start[1].powi(2)).sqrt();
        assert!((100.0 * a - dist).abs() < 0.01 * dist, "{a} vs {dist}");
        for k in 0..truck.task.knots {
            let want = if k < truck.task.knots / 2 { a } else { -a };
            assert_eq!((v[2 * k], v[2 * k + 1]), (want, 0.0), "knot {k}");
        }
        // The paper's target: position and heading only.
        assert_eq!(truck.final_dof(), 3);
        let rest = p.tasks.iter().find(|t| t.name == "truck_rest").unwrap();
        assert!(rest.initial_knots().iter().all(|&u| u == 0.0));
        assert_eq!(rest.final_dof(), 6);
        let mut bad = truck.clone();
        bad.initial_knots.as_mut().unwrap().pop();
        assert_eq!(
            bad.validate_initial_knots().unwrap_err().key,
            "initial_knots"
        );
        let mut bad = truck.clone();
        bad.initial_knots.as_mut().unwrap()[1].push(0.0);
        assert_eq!(
            bad.validate_initial_knots().unwrap_err().key,
            "initial_knots[1]"
        );
        let mut bad = truck.clone();
        bad.initial_knots.as_mut().unwrap()[1][3] = 0.6; // steering box +-0.5 rad
        assert_eq!(
            bad.validate_initial_knots().unwrap_err().key,
            "initial_knots[1]"
        );
    }
}
