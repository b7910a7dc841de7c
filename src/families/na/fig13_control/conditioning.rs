//! The conditioning study beside the headline: the physics sweep (descent through the physical
//! model itself), the terminal Gauss-Newton spectrum of each task, and the best-weights run.

use super::{Params, Sweep, Task};
use crate::control::bptt::{Bptt, Knots, Substepped};
use crate::control::conditioning::{
    best_weighting, iterations_per_decade, terminal_spectrum, weighting_bound, Spectrum,
    WeightingBound,
};
use crate::control::objective::Objective;
use crate::control::Rk4Map;
use crate::emulator::catalog::{NetModel, NetSpec};
use crate::experiment::output::Table;
use crate::experiment::{other, Error};
use crate::physics::lander::Lander;
use crate::row;

/// Columns of `conditioning.csv`: per task and substrate (emulator, physics), the terminal
/// Gauss-Newton matrix G = J^T W J over the normalized knots at the start (state terms only):
/// its knot count, the independent final-state variables r, the headline's step scale lambda,
/// G's largest and r-th eigenvalues, their ratio kappa, and the iterations per tenfold
/// reduction of the residual along the r-th eigenvector at the headline eta, alpha and lambda
/// ([`crate::control::conditioning`]); then whether other final-state weights could help:
/// kappa of the equilibrated K = J J^T over the r independent weighted variables, the bound
/// kappa_eq / r that no diagonal weighting beats (van der Sluis), and the iterations per
/// tenfold reduction at that bound (at least this many under any weights, the headline's eta
/// and alpha, lambda >= mu_1) ([`WeightingBound`]); and the paper's iteration count for the
/// task, which the spec's reading compares that bound with.
pub const CONDITIONING_COLUMNS: [&str; 14] = [
    "task",
    "substrate",
    "knots",
    "dof",
    "step_scale",
    "eigen_largest",
    "eigen_slowest",
    "condition",
    "eta",
    "iterations_per_decade",
    "condition_equilibrated",
    "condition_any_weighting",
    "iterations_per_decade_any_weighting",
    "paper_iterations",
];

/// Columns of `best_weights.csv` (ours): per task run under the best-conditioned weights and
/// independent weighted final-state variable (its state index), the task's tolerance, the
/// tolerance those weights amount to (1/sqrt(w), w scaled so the largest Gauss-Newton
/// eigenvalue is the task's), the condition of the task's and of the best weights, and the
/// iterations per tenfold reduction the headline's eta and alpha need at the latter.
pub const BEST_WEIGHTS_COLUMNS: [&str; 7] = [
    "task",
    "variable",
    "tolerance",
    "tolerance_best",
    "condition",
    "condition_best",
    "iterations_per_decade_best",
];

/// The tables the physics sweep writes to.
pub(super) struct PhysicsTables<'a> {
    pub(super) sweep: &'a mut Table,
    pub(super) conditioning: &'a mut Table,
    pub(super) spectrum: &'a mut Table,
    pub(super) best_sweep: &'a mut Table,
    pub(super) best_weights: &'a mut Table,
}

/// Rows of `conditioning.csv` and `spectrum.csv` for one task on one substrate.
pub(super) fn record_spectrum(
    task: &Task,
    substrate: &str,
    (spectrum, bound): (&Spectrum, &WeightingBound),
    lambda: f64,
    (cond, table): (&mut Table, &mut Table),
) {
    let h = task.eta * spectrum.slowest() / lambda;
    cond.push(row![
        task.name.as_str(),
        substrate,
        spectrum.eigenvalues.len() as i64,
        spectrum.dof as i64,
        lambda,
        spectrum.largest(),
        spectrum.slowest(),
        spectrum.condition(),
        task.eta,
        iterations_per_decade(h, task.alpha),
        bound.condition_equilibrated,
        bound.condition_any_weighting,
        iterations_per_decade(task.eta / bound.condition_any_weighting, task.alpha),
        task.task.iterations as i64
    ]);
    for (i, e) in spectrum.eigenvalues.iter().enumerate() {
        table.push(row![task.name.as_str(), substrate, (i + 1) as i64, *e]);
    }
}

impl Params {
    /// [`Params::sweep_task`] through the task's physical model: `steps` RK4 steps of the
    /// net's physical δt per knot step, Jacobians by central differences. Returns the best
    /// weights' tolerances when the spec's best-weights run ran.
    pub(super) fn physics_sweep_task(
        &self,
        task: &Task,
        sw: &Sweep,
        objective: &Objective,
        knots: Knots,
        x0: &[f64],
        tables: PhysicsTables<'_>,
    ) -> Result<Option<Vec<f64>>, Error> {
        #[allow(clippy::too_many_arguments)]
        fn go<M: crate::physics::linearize::Linearize>(
            p: &Params,
            model: M,
            task: &Task,
            sw: &Sweep,
            objective: &Objective,
            knots: Knots,
            x0: &[f64],
            t: PhysicsTables<'_>,
        ) -> Result<Option<Vec<f64>>, Error> {
            let step = Substepped {
                inner: Rk4Map::new(model, task.net.physical_dt).map_err(other)?,
                substeps: p.steps,
            };
            let mut bptt = Bptt::new(&step, objective, knots, task.bounds(), x0).map_err(other)?;
            let init = task.initial_knots();
            let v0 = bptt.from_controls(&init);
            let lambda = bptt.curvature(&v0, p.curvature_iterations);
            if !(lambda.is_finite() && lambda > 0.0) {
                return Err(other(format!(
                    "{} (physics): step scale λ = {lambda}",
                    task.name
                )));
            }
            let curvature = objective
                .gauss_newton()
                .ok_or_else(|| other(format!("{}: objective without curvature", task.name)))?;
            let spec = terminal_spectrum(&mut bptt, &v0, &curvature, task.final_dof());
            let rows = task.final_rows(&mut bptt, &v0);
            let bound = weighting_bound(&rows);
            let tables = (&mut *t.conditioning, &mut *t.spectrum);
            record_spectrum(task, "physics", (&spec, &bound), lambda, tables);
            p.sweep_task(task, sw, &mut bptt, &v0, lambda, x0, t.sweep);
            // The spec's best-weights run, where no weighting is ruled out: the headline rule
            // (fixed step, the task's eta and alpha, lambda at the start) on the objective with
            // the best-conditioned weights, scored with the task's own tolerances.
            let any_pace =
                iterations_per_decade(task.eta / bound.condition_any_weighting, task.alpha);
            if any_pace <= task.task.iterations as f64 {
                let vars = task.independent_final_vars();
                if let Some((w, kappa)) = best_weighting(&rows) {
                    // W's largest Gauss-Newton eigenvalue set to ours (mu_1), so the effort
                    // term weighs as much against the fastest direction as in the task.
                    let mut best = task.clone();
                    for (&k, wk) in vars.iter().zip(&w) {
                        best.task.final_tolerance[k] = 1.0 / (wk * spec.largest()).sqrt();
                        t.best_weights.push(row![
                            task.name.as_str(),
                            k as i64,
                            task.task.final_tolerance[k],
                            best.task.final_tolerance[k],
                            spec.condition(),
                            kappa,
                            iterations_per_decade(task.eta / kappa, task.alpha)
                        ]);
                    }
                    let objective = best.objective();
                    let mut b =
                        Bptt::new(&step, &objective, knots, task.bounds(), x0).map_err(other)?;
                    let lambda = b.curvature(&v0, p.curvature_iterations);
                    let headline = task.headline_sweep(sw.iterations);
                    p.sweep_task(task, &headline, &mut b, &v0, lambda, x0, t.best_sweep);
                    return Ok(Some(best.task.final_tolerance));
                }
            }
            Ok(None)
        }
        use crate::physics::linearize::FiniteDifference;
        use crate::physics::pendulum::{Pendulum3, PendulumVariant};
        use crate::physics::truck::Truck;
        // One sweep per physical model type (`go` is generic over it).
        macro_rules! sweep_through {
            ($model:expr) => {
                go(
                    self,
                    FiniteDifference::new($model),
                    task,
                    sw,
                    objective,
                    knots,
                    x0,
                    tables,
                )
            };
        }
        match task.net.model {
            NetModel::Truck => sweep_through!(Truck::default()),
            NetModel::Lander => sweep_through!(Lander::default()),
            NetModel::PendulumActive => {
                sweep_through!(Pendulum3::new(PendulumVariant::Active))
            }
            other_model => Err(other(format!(
                "{}: no physics sweep for {}",
                task.name,
                other_model.name()
            ))),
        }
    }
}

/// Columns of `conditioning_ladder.csv` (ours): per task of the paper's formulation
/// that has a formulation of ours on the same net, the terminal Gauss-Newton condition through
/// that net at the initial knots as the paper's changes are applied to ours one at a time
/// ([`ladder`]): rung 0 is ours, the last rung the paper's task; `change` names what the rung
/// changed, `dof` the independent weighted final-state variables, and `iterations_per_decade`
/// the headline's pace along the slowest direction at that condition (the task's eta and
/// alpha, lambda at the largest eigenvalue).
pub const LADDER_COLUMNS: [&str; 7] = [
    "task",
    "rung",
    "change",
    "dof",
    "condition",
    "eta",
    "iterations_per_decade",
];

/// The rungs from `ours` to `paper` (the same model): each changes one thing of ours to the
/// paper's, in a fixed order (horizon and knots, super-step, start, initial controls, target
/// set and tolerances, control units, final-state weights), skipping what does not differ.
/// "horizon and knots" gives ours the paper's duration in ours' own emulator steps (its net
/// unchanged); "super-step" then moves it to the paper's net (its physical δt), with the
/// paper's step count. Returns (change, task) per rung, ours first.
pub(super) fn ladder(ours: &Task, paper: &Task) -> Vec<(&'static str, Task)> {
    let mut t = ours.clone();
    t.name = paper.name.clone();
    t.formulation = paper.formulation;
    t.calibration = None;
    let mut rungs = vec![("ours", t.clone())];
    type Apply = fn(&mut Task, &Task) -> bool;
    let steps: [(&str, Apply); 7] = [
        ("horizon and knots", |t, p| {
            // The paper's duration in ours' steps (both nets take N of their own δt).
            let ratio = p.net.physical_dt / t.net.physical_dt;
            let horizon = (p.task.horizon as f64 * ratio).round() as usize;
            let differs = (t.task.horizon, t.task.knots) != (horizon, p.task.knots);
            t.task.horizon = horizon;
            t.task.knots = p.task.knots;
            differs
        }),
        ("super-step", |t, p| {
            let differs = t.net != p.net;
            t.net = p.net.clone();
            t.task.horizon = p.task.horizon;
            differs
        }),
        ("start state", |t, p| {
            let differs = t.task.start != p.task.start;
            t.task.start = p.task.start.clone();
            differs
        }),
        ("initial controls", |t, p| {
            let differs = t.initial_knots != p.initial_knots;
            t.initial_knots = p.initial_knots.clone();
            differs
        }),
        ("target set and tolerances", |t, p| {
            let differs =
                t.task.target != p.task.target || t.task.final_tolerance != p.task.final_tolerance;
            t.task.target = p.task.target.clone();
            t.task.final_tolerance = p.task.final_tolerance.clone();
            differs
        }),
        ("control units", |t, p| {
            let differs = t.control_units != p.control_units;
            t.control_units = p.control_units;
            differs
        }),
        ("final-state weights", |t, p| {
            let differs = t.final_weights != p.final_weights;
            t.final_weights = p.final_weights;
            differs
        }),
    ];
    for (change, apply) in steps {
        if apply(&mut t, paper) {
            rungs.push((change, t.clone()));
        }
    }
    rungs
}

/// Rows of `conditioning_ladder.csv` for the rungs of [`ladder`], each through its own net
/// (`net_of`: the trained emulator of a rung's net spec) from its own [`Task::start_state`].
pub(super) fn record_ladder<'a, D: crate::control::bptt::DifferentiableStep + 'a>(
    net_of: impl Fn(&NetSpec) -> Option<&'a D>,
    rungs: &[(&'static str, Task)],
    table: &mut Table,
) -> Result<(), Error> {
    for (i, (change, rung)) in rungs.iter().enumerate() {
        let step = net_of(&rung.net)
            .ok_or_else(|| other(format!("{}: no net for ladder rung {change}", rung.name)))?;
        let x0 = rung.start_state();
        let t = rung.calibrated(step, &x0).map_err(other)?;
        let objective = t.objective();
        let m = t.net.model.control_dim();
        let knots = Knots {
            steps: t.task.horizon,
            per_actuator: t.task.knots,
            m,
        };
        let mut bptt = Bptt::new(step, &objective, knots, t.bounds(), &x0).map_err(other)?;
        let v0 = bptt.from_controls(&t.initial_knots());
        let curvature = objective
            .gauss_newton()
            .ok_or_else(|| other(format!("{}: objective without curvature", t.name)))?;
        let spec = terminal_spectrum(&mut bptt, &v0, &curvature, t.final_dof());
        table.push(row![
            t.name.as_str(),
            i as i64,
            *change,
            spec.dof as i64,
            spec.condition(),
            t.eta,
            iterations_per_decade(t.eta / spec.condition(), t.alpha)
        ]);
    }
    Ok(())
}
