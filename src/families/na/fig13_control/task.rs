//! One control-learning task of `na_fig13_control` ([`Task`]): its control box, rest control,
//! objective and final error, and the final-state Jacobian rows the conditioning study reads.

use super::Sweep;
use crate::control::bptt::{Bounds, Bptt, DifferentiableStep, StepRule};
use crate::control::conditioning::largest_weighted_eigenvalue;
use crate::control::objective::{ControlEffort, FinalState, Objective};
use crate::emulator::catalog::{NetModel, NetSpec};
use crate::families::na::control_task::{keyed, ControlTask};
use crate::params::{ensure, positive};
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
    /// The optimizer's unit of each actuator ([`ControlUnits`]; default `box`). Left out of the
    /// serialized task when `box` (cache keys as before the field existed).
    #[serde(default, skip_serializing_if = "ControlUnits::is_box")]
    pub control_units: ControlUnits,
    /// The final-state term's weights ([`FinalWeights`]; default `tolerance`). Left out of the
    /// serialized task when `tolerance` (cache keys as before the field existed).
    #[serde(default, skip_serializing_if = "FinalWeights::is_tolerance")]
    pub final_weights: FinalWeights,
    /// The actuator gains and final-state weights [`Task::calibrated`] measured (none until
    /// then: unit gains, 1/σ² weights). Never read from or written to a spec.
    #[serde(skip)]
    pub calibration: Option<Calibration>,
}

/// The optimizer's unit of each actuator: what one unit of a normalized knot value is.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ControlUnits {
    /// The half-width of the actuator's box (ours; the default).
    #[default]
    Box,
    /// Box units times a gain per actuator chosen so every actuator's knots move the weighted
    /// final state equally at the initial knots: g_j = sqrt(max_i t_i / t_j), t_j the trace of
    /// actuator j's block of the terminal Gauss-Newton matrix J^T W J (W the 1/σ² weights)
    /// through the net the task learns through (ours; for actuators of different
    /// physical units, e.g. the truck's m/s² and rad, where the paper's own unit, a rate of
    /// turning, is not our model's control).
    EqualSensitivity,
}

impl ControlUnits {
    /// Whether it is `box`.
    pub fn is_box(&self) -> bool {
        *self == ControlUnits::Box
    }
}

/// The weights of the final-state term ½ Σ_k w_k (s_{M,k} − s_{d,k})².
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FinalWeights {
    /// w_k = 1/σ_k², σ_k the tolerance (ours; the default).
    #[default]
    Tolerance,
    /// Each weighted variable weighs by its sensitivity to the knots: w_k = c/|∂s_{M,k}/∂v|²
    /// at the initial knots (after the actuator gains), so each moves the objective comparably
    /// (the terminal Gauss-Newton matrix's diagonal in final-state space is constant); c sets
    /// its largest eigenvalue to that of the 1/σ² weights, so the effort term weighs as much
    /// against the fastest direction as before. The variables weighted are still those with a
    /// tolerance, and success is still judged by the tolerances (ours).
    Sensitivity,
}

impl FinalWeights {
    /// Whether it is `tolerance`.
    pub fn is_tolerance(&self) -> bool {
        *self == FinalWeights::Tolerance
    }
}

/// What [`Task::calibrated`] measured at the initial knots.
#[derive(Debug, Clone, PartialEq)]
pub struct Calibration {
    /// Gain per actuator ([`ControlUnits`]).
    pub gains: Vec<f64>,
    /// Weight per state variable ([`FinalWeights`]; 0 where not weighted).
    pub weights: Vec<f64>,
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
        let bounds = Bounds::new(low, high);
        match &self.calibration {
            Some(c) => bounds.with_gain(c.gains.clone()),
            None => bounds,
        }
    }

    /// The task with its [`Calibration`] measured at the initial knots through `step` (the net
    /// it learns through) from `x0`: the actuator gains of its [`ControlUnits`], then the
    /// final-state weights of its [`FinalWeights`] under those gains. A task of box units and
    /// tolerance weights gets unit gains and its 1/σ² weights (the same objective and bounds as
    /// without one).
    pub fn calibrated<D: DifferentiableStep>(&self, step: &D, x0: &[f64]) -> Result<Task, String> {
        use crate::control::bptt::Knots;
        let mut t = self.clone();
        t.calibration = None;
        let m = t.net.model.control_dim();
        let knots = Knots {
            steps: t.task.horizon,
            per_actuator: t.task.knots,
            m,
        };
        let tol = t.weights();
        let vars = t.independent_final_vars();
        let rows = |task: &Task| -> Result<Vec<Vec<f64>>, String> {
            let objective = task.objective();
            let mut b =
                Bptt::new(step, &objective, knots, task.bounds(), x0).map_err(|e| e.to_string())?;
            let v0 = b.from_controls(&task.initial_knots());
            Ok(task.final_rows(&mut b, &v0))
        };
        let mut gains = vec![1.0; m];
        if t.control_units == ControlUnits::EqualSensitivity {
            let r = rows(&t)?;
            let trace: Vec<f64> = (0..m)
                .map(|j| {
                    r.iter()
                        .zip(&vars)
                        .map(|(row, &k)| {
                            tol[k] * row.iter().skip(j).step_by(m).map(|x| x * x).sum::<f64>()
                        })
                        .sum()
                })
                .collect();
            let top = trace.iter().copied().fold(0.0, f64::max);
            if !(top > 0.0 && top.is_finite()) || trace.iter().any(|&x| !(x > 0.0)) {
                return Err(format!(
                    "{}: an actuator moves no weighted final-state variable at the initial knots (traces {trace:?}); equal_sensitivity units need every actuator to",
                    t.name
                ));
            }
            gains = trace.iter().map(|&x| (top / x).sqrt()).collect();
        }
        t.calibration = Some(Calibration {
            gains: gains.clone(),
            weights: tol.clone(),
        });
        if t.final_weights == FinalWeights::Sensitivity {
            // Only independent variables can be weighed by their own sensitivity (the lander's
            // quaternion scalar part follows the vector part's).
            if let Some(k) = (0..tol.len()).find(|&k| tol[k] > 0.0 && !vars.contains(&k)) {
                return Err(format!(
                    "{}: sensitivity weights weigh independent variables only; state variable {k} has a tolerance but follows the others (give it tolerance 0)",
                    t.name
                ));
            }
            let r = rows(&t)?;
            let mut w = vec![0.0; tol.len()];
            for (row, &k) in r.iter().zip(&vars) {
                let s: f64 = row.iter().map(|x| x * x).sum();
                if !(s > 0.0 && s.is_finite()) {
                    return Err(format!(
                        "{}: state variable {k} does not move with the knots at the initial knots; sensitivity weights need every weighted variable to",
                        t.name
                    ));
                }
                w[k] = 1.0 / s;
            }
            let at = |w: &[f64]| -> Vec<f64> { vars.iter().map(|&k| w[k]).collect() };
            let c = largest_weighted_eigenvalue(&r, &at(&tol))
                / largest_weighted_eigenvalue(&r, &at(&w));
            w.iter_mut().for_each(|x| *x *= c);
            t.calibration = Some(Calibration { gains, weights: w });
        }
        Ok(t)
    }

    /// The checks of a task listed as `tasks[i]` of a spec (keys named so): a controlled model,
    /// the shared [`ControlTask`] checks, limit fraction in (0, 1], tolerances >= 0 with one
    /// > 0, effort >= 0, η > 0, α in [0, 1), the step rule and the initial knots.
    pub fn validate_at(&self, i: usize) -> Result<(), crate::params::ParamError> {
        let t = self;
        let key = |k: &str| format!("tasks[{i}].{k}");
        let n = t.net.model.state_dim();
        ensure(
            t.net.model.control_dim() > 0,
            &key("net.model"),
            "needs a controlled model",
        )?;
        t.task
            .validate(n)
            .map_err(|e| e.prefixed(&format!("tasks[{i}]")))?;
        ensure(
            t.limit_fraction > 0.0 && t.limit_fraction <= 1.0,
            &key("limit_fraction"),
            "must be in (0, 1]",
        )?;
        ensure(
            t.task.final_tolerance.iter().all(|&x| x >= 0.0)
                && t.task.final_tolerance.iter().any(|&x| x > 0.0),
            &key("final_tolerance"),
            "must be >= 0 with at least one > 0",
        )?;
        ensure(t.task.effort_mu >= 0.0, &key("effort_mu"), "must be >= 0")?;
        positive(&key("eta"), t.eta)?;
        ensure(
            (0.0..1.0).contains(&t.alpha),
            &key("alpha"),
            "must be in [0, 1)",
        )?;
        t.step_rule.validate(&key("step_rule"))?;
        t.validate_initial_knots()
            .map_err(|e| e.prefixed(&format!("tasks[{i}]")))?;
        Ok(())
    }

    /// The start state descent and the simulator replay begin from: the spec's `start`, the
    /// lander's attitude quaternion normalized.
    pub fn start_state(&self) -> Vec<f64> {
        let mut x = self.task.start.clone();
        if self.net.model == NetModel::Lander {
            Lander::default().normalize_state(&mut x);
        }
        x
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

    /// The objective's final-state weights: the calibration's, else 1/σ².
    fn objective_weights(&self) -> Vec<f64> {
        match &self.calibration {
            Some(c) => c.weights.clone(),
            None => self.weights(),
        }
    }

    /// 1/σ² per state variable (0 where σ = 0): the weights success is judged by.
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
                weights: self.objective_weights(),
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
                ("lander_13", Formulation::Ours),
                ("pendulum_200steps", Formulation::Ours),
            ]
        );
        // The paper's pendulum animates 20 s in 40 N50 steps of 0.5 s (2,000 physical steps of
        // 0.01 s, section 6), ours 4 s, and `pendulum_200steps` 20 s in 200 steps of 0.1 s.
        let seconds = |t: &Task| t.task.horizon as f64 * t.net.physical_dt * p.steps as f64;
        assert!((seconds(&p.tasks[0]) - 20.0).abs() < 1e-9);
        assert_eq!(p.tasks[0].task.horizon * p.steps, 2000);
        assert_eq!(p.tasks[0].task.horizon, 40);
        assert!((seconds(&p.tasks[3]) - 4.0).abs() < 1e-9);
        assert!((seconds(&p.tasks[6]) - 20.0).abs() < 1e-9);
        assert_eq!(p.net_seeds_ours, ["pendulum_200steps"]);
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
        // net_seeds_ours names tasks of ours only: a paper task or an unknown name is refused.
        use crate::experiment::resolve::Validate;
        assert!(p.validate().is_ok());
        for name in ["truck", "no_such_task"] {
            let mut q = p.clone();
            q.net_seeds_ours = vec![name.into()];
            let e = q.validate().unwrap_err();
            assert_eq!(e.key, "net_seeds_ours", "{e}");
            assert!(e.to_string().contains(name), "{e}");
        }
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

    /// The spec's paper tasks: the truck and the lander learn in equal-sensitivity
    /// units under sensitivity weights, the lander's final state is the paper's target set
    /// (position, attitude, descent velocity: 7 independent variables) from an upright, still
    /// start; our earlier lander stays as `lander_13`, box units, 1/σ² weights, all 13.
    #[test]
    fn the_truck_and_the_lander_state_the_papers_targets_units_and_weights() {
        let file =
            SpecFile::load(std::path::Path::new("experiments/na_fig13_control.toml")).unwrap();
        let p: super::super::Params =
            parse_params(&toml::Value::Table(file.raw.params.clone())).unwrap();
        let get = |n: &str| p.tasks.iter().find(|t| t.name == n).unwrap().clone();
        for name in ["truck", "lander"] {
            let t = get(name);
            assert_eq!(t.control_units, ControlUnits::EqualSensitivity, "{name}");
            assert_eq!(t.final_weights, FinalWeights::Sensitivity, "{name}");
            let json = serde_json::to_value(&t).unwrap();
            assert_eq!(json["control_units"], "equal_sensitivity");
            assert_eq!(json["final_weights"], "sensitivity");
        }
        let lander = get("lander");
        assert_eq!(lander.independent_final_vars(), [0, 1, 2, 4, 5, 6, 9]);
        assert_eq!(
            &lander.task.start[3..],
            &[1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]
        );
        let ours = get("lander_13");
        assert_eq!(ours.formulation, Formulation::Ours);
        assert_eq!(ours.final_dof(), 12);
        let json = serde_json::to_value(&ours).unwrap();
        assert!(json.get("control_units").is_none() && json.get("final_weights").is_none());
        assert!(get("pendulum").control_units.is_box());
    }

    /// [`Task::calibrated`] through the truck's physics: equal-sensitivity gains make every
    /// actuator's trace of Jᵀ W J (1/σ² weights) the same, the largest actuator keeping gain
    /// 1; sensitivity weights make the diagonal of the final-state form R W Rᵀ constant with
    /// the 1/σ² weights' largest eigenvalue; a task of box units and tolerance weights keeps
    /// unit gains and 1/σ²; a start where the steering moves nothing is refused.
    #[test]
    fn calibration_equalizes_the_actuators_and_the_weighted_variables() {
        use crate::control::bptt::{Knots, Substepped};
        use crate::control::Rk4Map;
        use crate::physics::linearize::FiniteDifference;
        use crate::physics::truck::Truck;
        let file =
            SpecFile::load(std::path::Path::new("experiments/na_fig13_control.toml")).unwrap();
        let p: super::super::Params =
            parse_params(&toml::Value::Table(file.raw.params.clone())).unwrap();
        let truck = p.tasks.iter().find(|t| t.name == "truck").unwrap().clone();
        let step = Substepped {
            inner: Rk4Map::new(FiniteDifference::new(Truck::default()), 0.01).unwrap(),
            substeps: p.steps,
        };
        let x0 = truck.task.start.clone();
        let rows_of = |t: &Task| {
            let objective = t.objective();
            let knots = Knots {
                steps: t.task.horizon,
                per_actuator: t.task.knots,
                m: 2,
            };
            let mut b = Bptt::new(&step, &objective, knots, t.bounds(), &x0).unwrap();
            let v0 = b.from_controls(&t.initial_knots());
            t.final_rows(&mut b, &v0)
        };
        let tol = truck.weights();
        let vars = truck.independent_final_vars();
        let c = truck.calibrated(&step, &x0).unwrap();
        let cal = c.calibration.clone().unwrap();
        let rows = rows_of(&c);
        let trace = |j: usize| -> f64 {
            rows.iter()
                .zip(&vars)
                .map(|(r, &k)| tol[k] * r.iter().skip(j).step_by(2).map(|x| x * x).sum::<f64>())
                .sum()
        };
        assert!(
            (trace(0) - trace(1)).abs() < 1e-9 * trace(0),
            "{} vs {}",
            trace(0),
            trace(1)
        );
        assert!(cal.gains.contains(&1.0) && cal.gains.iter().all(|&g| g >= 1.0));
        assert!(
            cal.gains[1] > 5.0,
            "steering moves the final state far less per box unit"
        );
        let diag: Vec<f64> = rows
            .iter()
            .zip(&vars)
            .map(|(r, &k)| cal.weights[k] * r.iter().map(|x| x * x).sum::<f64>())
            .collect();
        for d in &diag {
            assert!((d - diag[0]).abs() < 1e-9 * diag[0], "{diag:?}");
        }
        let at = |w: &[f64]| -> Vec<f64> { vars.iter().map(|&k| w[k]).collect() };
        let top_tol = largest_weighted_eigenvalue(&rows, &at(&tol));
        let top = largest_weighted_eigenvalue(&rows, &at(&cal.weights));
        assert!((top - top_tol).abs() < 1e-9 * top_tol, "{top} vs {top_tol}");
        assert!(cal.weights[3..].iter().all(|&w| w == 0.0));
        // Box units and tolerance weights: the task as it was.
        let mut plain = truck.clone();
        plain.control_units = ControlUnits::Box;
        plain.final_weights = FinalWeights::Tolerance;
        let pc = plain.calibrated(&step, &x0).unwrap();
        assert_eq!(pc.calibration.as_ref().unwrap().gains, vec![1.0, 1.0]);
        assert_eq!(pc.calibration.as_ref().unwrap().weights, tol);
        assert_eq!(pc.bounds(), plain.bounds());
        // Parked with zero controls the steering moves nothing: no gain equalizes that.
        let mut parked = truck.clone();
        parked.initial_knots = None;
        let e = parked.calibrated(&step, &x0).unwrap_err();
        assert!(e.contains("moves no weighted final-state variable"), "{e}");
    }

    /// The ladder from our truck (from rest, six variables, box units, 1/σ²) to the paper's:
    /// one rung per change that differs, in the fixed order, the last rung the paper's task.
    #[test]
    fn the_ladder_applies_the_papers_changes_one_at_a_time() {
        let file =
            SpecFile::load(std::path::Path::new("experiments/na_fig13_control.toml")).unwrap();
        let p: super::super::Params =
            parse_params(&toml::Value::Table(file.raw.params.clone())).unwrap();
        let get = |n: &str| p.tasks.iter().find(|t| t.name == n).unwrap().clone();
        let rungs = super::super::conditioning::ladder(&get("truck_rest"), &get("truck"));
        let names: Vec<&str> = rungs.iter().map(|(c, _)| *c).collect();
        assert_eq!(
            names,
            [
                "ours",
                "initial controls",
                "target set and tolerances",
                "control units",
                "final-state weights"
            ]
        );
        let last = serde_json::to_value(&rungs.last().unwrap().1).unwrap();
        assert_eq!(last, serde_json::to_value(get("truck")).unwrap());
        // The pendulum: 20 s on our net first (exactly our 200-step task), then the paper's
        // net and step count (exactly the paper's task).
        let rungs = super::super::conditioning::ladder(&get("pendulum_4s"), &get("pendulum"));
        let names: Vec<&str> = rungs.iter().map(|(c, _)| *c).collect();
        assert_eq!(names, ["ours", "horizon and knots", "super-step"]);
        let mut ours_20s = get("pendulum_200steps");
        ours_20s.name = "pendulum".into();
        ours_20s.formulation = Formulation::Paper;
        assert_eq!(
            serde_json::to_value(&rungs[1].1).unwrap(),
            serde_json::to_value(ours_20s).unwrap()
        );
        let last = serde_json::to_value(&rungs[2].1).unwrap();
        assert_eq!(last, serde_json::to_value(get("pendulum")).unwrap());
    }
}
