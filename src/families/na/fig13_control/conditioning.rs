//! The conditioning study beside the headline: the physics sweep (descent through the physical
//! model itself), the terminal Gauss-Newton spectrum of each task, and the best-weights run.

use super::rows::{BestWeightsRow, ConditioningRow, LadderRow, SpectrumRow, SweepRow};
use super::{Params, Sweep, Task};
use crate::control::bptt::{learn_with, Bptt, Knots, Substepped};
use crate::control::conditioning::{
    best_weighting, iterations_per_decade, terminal_spectrum, weighting_bound, Spectrum,
    WeightingBound,
};
use crate::control::objective::Objective;
use crate::control::Rk4Map;
use crate::emulator::catalog::{NetModel, NetSpec};
use crate::experiment::rows::TableRow;
use crate::experiment::{other, Error};
use crate::physics::lander::Lander;

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
pub const CONDITIONING_COLUMNS: &[&str] = ConditioningRow::COLUMNS;

/// Columns of `best_weights.csv` (ours): per task run under the best-conditioned weights and
/// independent weighted final-state variable (its state index), the task's tolerance, the
/// tolerance those weights amount to (1/sqrt(w), w scaled so the largest Gauss-Newton
/// eigenvalue is the task's), the condition of the task's and of the best weights, and the
/// iterations per tenfold reduction the headline's eta and alpha need at the latter.
pub const BEST_WEIGHTS_COLUMNS: &[&str] = BestWeightsRow::COLUMNS;

/// The tables the physics sweep writes to.
pub(super) struct PhysicsTables<'a> {
    pub(super) sweep: &'a mut Vec<SweepRow>,
    pub(super) conditioning: &'a mut Vec<ConditioningRow>,
    pub(super) spectrum: &'a mut Vec<SpectrumRow>,
    pub(super) best_sweep: &'a mut Vec<SweepRow>,
    pub(super) best_weights: &'a mut Vec<BestWeightsRow>,
}

/// Rows of `conditioning.csv` and `spectrum.csv` for one task on one substrate.
pub(super) fn record_spectrum(
    task: &Task,
    substrate: &str,
    (spectrum, bound): (&Spectrum, &WeightingBound),
    lambda: f64,
    (cond, table): (&mut Vec<ConditioningRow>, &mut Vec<SpectrumRow>),
) {
    let h = task.eta * spectrum.slowest() / lambda;
    cond.push(ConditioningRow {
        task: task.name.clone(),
        substrate: substrate.into(),
        knots: spectrum.eigenvalues.len() as i64,
        dof: spectrum.dof as i64,
        step_scale: lambda,
        eigen_largest: spectrum.largest(),
        eigen_slowest: spectrum.slowest(),
        condition: spectrum.condition(),
        eta: task.eta,
        iterations_per_decade: iterations_per_decade(h, task.alpha),
        condition_equilibrated: bound.condition_equilibrated,
        condition_any_weighting: bound.condition_any_weighting,
        iterations_per_decade_any_weighting: iterations_per_decade(
            task.eta / bound.condition_any_weighting,
            task.alpha,
        ),
        paper_iterations: task.task.iterations as i64,
    });
    for (i, e) in spectrum.eigenvalues.iter().enumerate() {
        table.push(SpectrumRow {
            task: task.name.clone(),
            substrate: substrate.into(),
            index: (i + 1) as i64,
            eigenvalue: *e,
        });
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
                        t.best_weights.push(BestWeightsRow {
                            task: task.name.clone(),
                            variable: k as i64,
                            tolerance: task.task.final_tolerance[k],
                            tolerance_best: best.task.final_tolerance[k],
                            condition: spec.condition(),
                            condition_best: kappa,
                            iterations_per_decade_best: iterations_per_decade(
                                task.eta / kappa,
                                task.alpha,
                            ),
                        });
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

/// One iterate of a descent through the physics: its iteration, final error (1 = tolerance),
/// normalized knots and the gradient of J there.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct PhysicsIterate {
    pub(super) iteration: usize,
    pub(super) error: f64,
    pub(super) knots: Vec<f64>,
    pub(super) gradient: Vec<f64>,
}

/// A calibrated `task`'s headline descent (its η, α and step rule, λ measured at the initial
/// knots) through the physical model itself (its RK4 step with finite-difference Jacobians,
/// `steps` RK4 steps per emulator step), continued to [`super::job::TO_GOAL_FACTOR`] times the
/// task's iteration count or until an iterate ends within tolerance (the physics is its own
/// simulator): what the same descent needs without an emulator. Returns the first iteration
/// at the goal (`None`: none is) and every iterate up to it. An error for a model without a
/// physics step here or a λ that is not finite and positive.
pub(super) fn physics_descent(
    task: &Task,
    steps: usize,
    curvature_iterations: usize,
) -> Result<(Option<usize>, Vec<PhysicsIterate>), Error> {
    fn go<M: crate::physics::linearize::Linearize>(
        model: M,
        task: &Task,
        steps: usize,
        curvature_iterations: usize,
    ) -> Result<(Option<usize>, Vec<PhysicsIterate>), Error> {
        let step = Substepped {
            inner: Rk4Map::new(model, task.net.physical_dt).map_err(other)?,
            substeps: steps,
        };
        let knots = Knots {
            steps: task.task.horizon,
            per_actuator: task.task.knots,
            m: task.net.model.control_dim(),
        };
        let objective = task.objective();
        let x0 = task.start_state();
        let mut bptt = Bptt::new(&step, &objective, knots, task.bounds(), &x0).map_err(other)?;
        let v0 = bptt.from_controls(&task.initial_knots());
        let lambda = bptt.curvature(&v0, curvature_iterations);
        if !(lambda.is_finite() && lambda > 0.0) {
            return Err(other(format!(
                "{} (physics): step scale λ = {lambda}",
                task.name
            )));
        }
        let schedule = super::job::schedule(
            task.eta,
            task.alpha,
            task.step_rule,
            lambda,
            curvature_iterations,
        );
        let at = task.task.horizon * task.net.model.state_dim();
        let mut iterates = Vec::new();
        let cap = super::job::TO_GOAL_FACTOR * task.task.iterations;
        learn_with(&mut bptt, &v0, &schedule, cap, &mut |trace, v, states| {
            let error = task.final_error(&states[at..]);
            iterates.push(PhysicsIterate {
                iteration: trace.iteration,
                error,
                knots: v.to_vec(),
                gradient: Vec::new(),
            });
            error <= 1.0
        });
        for it in &mut iterates {
            it.gradient = vec![0.0; it.knots.len()];
            bptt.gradient(&it.knots, &mut it.gradient);
        }
        let reached = iterates
            .last()
            .filter(|it| it.error <= 1.0)
            .map(|it| it.iteration);
        Ok((reached, iterates))
    }
    use crate::physics::linearize::FiniteDifference;
    use crate::physics::pendulum::{Pendulum3, PendulumVariant};
    use crate::physics::truck::Truck;
    let (ci, model) = (curvature_iterations, task.net.model);
    match model {
        NetModel::Truck => go(FiniteDifference::new(Truck::default()), task, steps, ci),
        NetModel::Lander => go(FiniteDifference::new(Lander::default()), task, steps, ci),
        NetModel::PendulumActive => {
            let pendulum = Pendulum3::new(PendulumVariant::Active);
            go(FiniteDifference::new(pendulum), task, steps, ci)
        }
        _ => Err(other(format!(
            "{}: no physics step for {}",
            task.name,
            model.name()
        ))),
    }
}

/// The report's table and sentence from `physics_path.csv` in `dir` (empty without it): per
/// paper task, over the net seeds, where the descent through the physics reaches its goal and
/// how far each net's gradient is from the physics' at its start and at its last iterate.
pub(super) fn physics_path_md(
    dir: &std::path::Path,
    control: &[&str],
) -> Result<(String, String), Error> {
    use super::rows::PhysicsPathRow;
    use crate::experiment::output::unique;
    use crate::experiment::report::sig;
    use crate::experiment::stats::median;
    let Some(rows) =
        crate::experiment::rows::written_rows::<PhysicsPathRow>(dir, "physics_path.csv")?
    else {
        return Ok(Default::default());
    };
    // The run measures every control task of the paper's formulation (`control`) through the
    // physics: a written table without one's rows was cut or edited.
    if let Some(t) = control.iter().find(|t| !rows.iter().any(|r| r.task == **t)) {
        return Err(other(format!(
            "{}: no rows for {t}, of the paper's formulation in final.csv (a truncated or edited table)",
            dir.join("physics_path.csv").display()
        )));
    }
    let tasks = unique(&rows.iter().map(|r| r.task.clone()).collect::<Vec<_>>());
    if tasks.is_empty() {
        return Ok(Default::default());
    }
    let mut md = String::from("\nThe same descent through the physics (ours; `physics_path.csv`): each paper task's headline through the physical model under each net seed's calibration, to its goal or twice the paper's iterations, with each net's gradient of J at the physics' iterates beside the physics' own (relative error: the norm of the difference over the physics' norm; 1 or more: the net's gradient points as much elsewhere as along the physics').\n\n| task | net seeds | physics at the goal (median over calibrations) | its final error at the last iterate | gradient relative error at the start (median) | at the last iterate | gradient cosine at the last iterate |\n| --- | --- | --- | --- | --- | --- | --- |\n");
    let mut why = Vec::new();
    for name in tasks {
        let of: Vec<&PhysicsPathRow> = rows.iter().filter(|r| r.task == name).collect();
        let seeds = unique(
            &of.iter()
                .map(|r| r.net_seed.to_string())
                .collect::<Vec<_>>(),
        );
        // Per seed: its first and last iterates (rows are in iteration order per seed).
        let (mut first, mut last) = (Vec::new(), Vec::new());
        for s in &seeds {
            let mine: Vec<&&PhysicsPathRow> =
                of.iter().filter(|r| r.net_seed.to_string() == *s).collect();
            if let (Some(a), Some(b)) = (mine.first(), mine.last()) {
                first.push(**a);
                last.push(**b);
            }
        }
        let med = |f: &dyn Fn(&PhysicsPathRow) -> f64, set: &[&PhysicsPathRow]| {
            median(&set.iter().map(|r| f(r)).collect::<Vec<_>>())
        };
        let at_goal: Vec<f64> = last
            .iter()
            .filter(|r| r.physics_error <= 1.0)
            .map(|r| r.iteration as f64)
            .collect();
        let goal_words = if at_goal.len() == last.len() {
            format!(
                "at iteration {}",
                super::seeds::iteration_words(median(&at_goal))
            )
        } else {
            format!(
                "under {} of {} calibrations within twice the paper's iterations",
                at_goal.len(),
                last.len()
            )
        };
        let start_rel = med(&|r| r.gradient_relative_error, &first);
        let last_rel = med(&|r| r.gradient_relative_error, &last);
        md.push_str(&format!(
            "| {name} | {} | {goal_words} | {} | {} | {} | {} |\n",
            seeds.len(),
            sig(med(&|r| r.physics_error, &last)),
            sig(start_rel),
            sig(last_rel),
            sig(med(&|r| r.gradient_cosine, &last)),
        ));
        why.push(format!(
            "{name}: through the physics at the goal {goal_words} (median over the seeds' calibrations); the nets' gradient error relative to the physics' {} at the start, {} at the physics' last iterate",
            sig(start_rel),
            sig(last_rel)
        ));
    }
    Ok((
        md,
        format!(
            " The same descents through the physics (physics_path.csv): {}.",
            why.join("; ")
        ),
    ))
}

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
    table: &mut Vec<LadderRow>,
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
        table.push(LadderRow {
            task: t.name.clone(),
            rung: i as i64,
            change: change.to_string(),
            dof: spec.dof as i64,
            condition: spec.condition(),
            eta: t.eta,
            iterations_per_decade: iterations_per_decade(t.eta / spec.condition(), t.alpha),
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::experiment::output::write_table;
    use crate::experiment::rows::table_of;
    use crate::families::na::fig13_control::rows::PhysicsPathRow;

    /// A `physics_path.csv` without the rows of a paper control task (cut or edited) is an
    /// error naming it; no file (a run without net seeds' descents) is nothing to say.
    #[test]
    fn a_physics_path_without_a_paper_tasks_rows_is_an_error() {
        let dir = tempfile::tempdir().unwrap();
        assert_eq!(
            physics_path_md(dir.path(), &["lander"]).unwrap(),
            (String::new(), String::new())
        );
        let row = PhysicsPathRow {
            task: "lander".into(),
            net_seed: 1,
            iteration: 0,
            physics_error: 3.0,
            gradient_cosine: 0.9,
            gradient_relative_error: 0.2,
        };
        write_table(dir.path(), "physics_path", &table_of(&[row])).unwrap();
        physics_path_md(dir.path(), &["lander"]).unwrap();
        let e = physics_path_md(dir.path(), &["lander", "truck"])
            .unwrap_err()
            .to_string();
        assert!(e.contains("physics_path.csv") && e.contains("truck"), "{e}");
    }
}
