//! The job of `na_fig13_control`: every task's emulator trained, its controls learned and
//! replayed on the simulator, and the step-size sweep; [`learn_best`] scores a run.

use super::conditioning::{ladder, record_ladder, record_spectrum, PhysicsTables};
use super::dagger::DaggerRoundRow;
use super::rows::{
    BestWeightsRow, ConditioningRow, DolphinDaggerRow, FinalRow, LadderRow, NetLineRow, NetSeedRow,
    ObjectiveRow, PathRow, PhysicsPathRow, SpectrumRow, StateRow, SweepRow, SwimRow,
};
use super::seeds::{HeadlineRun, ToGoal};
use super::{Formulation, Params, Sweep, Task};
use crate::control::bptt::{
    learn_with, replay, Bptt, Descent, DifferentiableStep, Knots, Learned, Schedule, StepRule,
};
use crate::control::conditioning::{terminal_spectrum, weighting_bound};
use crate::control::objective::Objective;
use crate::emulator::catalog::{BuildSpec, NetSpec, Trained};
use crate::experiment::output::{Table, Tables};
use crate::experiment::rows::{table_of, TableRow};
use crate::experiment::rule::{rule_table, rule_table_of};
use crate::experiment::{other, Error, Job, RunContext};
use crate::families::na::table1_structure::{build_emulators, build_spec};
use crate::physics::dolphin::N_POS;
use crate::row;
use rayon::prelude::*;

impl Job for Params {
    fn params_json(&self) -> serde_json::Value {
        serde_json::to_value(self).unwrap_or_default()
    }

    fn run(&self, ctx: &RunContext) -> Result<Tables, Error> {
        let mut t = RunTables::new(self);
        let specs: Vec<BuildSpec> = self
            .tasks
            .iter()
            .map(|task| {
                build_spec(
                    ctx.seed,
                    &task.net,
                    self.steps,
                    self.example_scale,
                    &self.training,
                )
            })
            .collect();
        let built = ctx.stage(
            &format!("train N{} emulators (side by side)", self.steps),
            || build_emulators(&specs),
        )?;
        // Tasks are independent (each seeds its own randomness from its spec), so they and the
        // further net seeds run side by side, each into tables of its own, appended in the
        // spec's order: the same rows as one after another.
        let (tasks, seeds) = rayon::join(
            || {
                (0..self.tasks.len())
                    .into_par_iter()
                    .map(|i| {
                        let mut own = RunTables::new(self);
                        let (task, spec) = (&self.tasks[i], &specs[i]);
                        self.run_task(ctx, task, spec, &built[i], &built, &mut own)?;
                        Ok(own)
                    })
                    .collect::<Result<Vec<RunTables>, Error>>()
            },
            || {
                let mut own = RunTables::new(self);
                self.run_seeds(ctx, &mut own.seeds, &mut own.path, &mut own.physics_path)?;
                Ok::<_, Error>(own)
            },
        );
        for own in tasks? {
            t.append(own)?;
        }
        t.append(seeds?)?;
        let lines_t = self.run_lines(ctx)?;
        let dolphin = self.run_dolphin_tables(ctx, &mut t)?;
        t.into_tables(self, lines_t, dolphin)
    }
}

/// The tables the paper's tasks fill, task by task, and the widths of their wide columns.
struct RunTables {
    objective: Vec<ObjectiveRow>,
    final_: Vec<FinalRow>,
    /// `sweep` and `physics_sweep`: `rollout_error` is the final error on the substrate
    /// learned through (emulator or differentiable physics), `simulator_error` the same
    /// controls replayed on the simulator; both at the run's best-so-far iterate.
    sweep: Vec<SweepRow>,
    physics: Vec<SweepRow>,
    /// The headline through the physics under the best-conditioned final-state weights
    /// (ours; `best_weights*.csv`), where conditioning.csv does not rule them out.
    best: Vec<SweepRow>,
    best_tol: Vec<BestWeightsRow>,
    best_emulator: Vec<SweepRow>,
    /// The terminal Gauss-Newton spectrum at the start knots on both substrates
    /// (src/control/conditioning.rs): why fixed-step descent is slow.
    cond: Vec<ConditioningRow>,
    spectrum: Vec<SpectrumRow>,
    dagger: Vec<DaggerRoundRow>,
    /// Per task, the actuator gains and final-state weights its objective and bounds use
    /// ([`Task::calibrated`]): kind `gain` (index = actuator) or `weight` (index = state
    /// variable).
    calibration: Table,
    ladder: Vec<LadderRow>,
    /// The headline of the paper's tasks per Table 1 net seed (seeds.rs), this run's first.
    seeds: Vec<NetSeedRow>,
    path: Vec<PathRow>,
    /// The headline's descent through the physics per paper task and net seed, with each
    /// net's gradient beside the physics' at its iterates (ours).
    physics_path: Vec<PhysicsPathRow>,
    trajectory: Table,
    /// The learned controls (physical units, one row per emulator step, held over it).
    controls: Table,
    goal: Table,
    /// The generic state columns (one table holds tasks of different models) by name.
    /// Each variable's final-state tolerance (0: not part of the goal).
    states: Vec<StateRow>,
    /// The largest state dimension over the tasks (the `s` columns).
    width: usize,
    /// The largest control dimension over the tasks (the `u` columns).
    u_width: usize,
}

/// The dolphin's tables (empty without `[params.dolphin]`).
struct DolphinTables {
    swim: Vec<SwimRow>,
    motion: Table,
    restarts: Table,
    dagger: Vec<DolphinDaggerRow>,
}

impl RunTables {
    /// The empty tables of `p`'s tasks, `states` already filled.
    fn new(p: &Params) -> Self {
        let width = p
            .tasks
            .iter()
            .map(|t| t.net.model.state_dim())
            .max()
            .unwrap_or(0);
        let cols = wide_columns(&["task", "step", "t", "source"], "s", width);
        let col_refs: Vec<&str> = cols.iter().map(String::as_str).collect();
        let u_width = p
            .tasks
            .iter()
            .map(|t| t.net.model.control_dim())
            .max()
            .unwrap_or(0);
        let u_cols = wide_columns(&["task", "step", "t"], "u", u_width);
        let u_refs: Vec<&str> = u_cols.iter().map(String::as_str).collect();
        let mut goal_cols = vec!["task", "model"];
        goal_cols.extend_from_slice(&col_refs[4..]);
        let mut states = Vec::new();
        for task in &p.tasks {
            for (k, name) in task.net.model.state_names().into_iter().enumerate() {
                states.push(StateRow {
                    task: task.name.clone(),
                    column: format!("s{k}"),
                    name: name.to_string(),
                    tolerance: task.task.final_tolerance.get(k).copied().unwrap_or(0.0),
                });
            }
        }
        RunTables {
            objective: Vec::new(),
            final_: Vec::new(),
            sweep: Vec::new(),
            physics: Vec::new(),
            best: Vec::new(),
            best_tol: Vec::new(),
            best_emulator: Vec::new(),
            cond: Vec::new(),
            spectrum: Vec::new(),
            dagger: Vec::new(),
            calibration: Table::new(&["task", "kind", "index", "value"]),
            ladder: Vec::new(),
            seeds: Vec::new(),
            path: Vec::new(),
            physics_path: Vec::new(),
            trajectory: Table::new(&col_refs),
            controls: Table::new(&u_refs),
            goal: Table::new(&goal_cols),
            states,
            width,
            u_width,
        }
    }

    /// Appends the rows of `more` (tables of the same run, from [`RunTables::new`]) after this
    /// one's; `states` and the widths are the run's, the same in both.
    fn append(&mut self, more: RunTables) -> Result<(), Error> {
        self.objective.extend(more.objective);
        self.final_.extend(more.final_);
        self.sweep.extend(more.sweep);
        self.physics.extend(more.physics);
        self.best.extend(more.best);
        self.best_tol.extend(more.best_tol);
        self.best_emulator.extend(more.best_emulator);
        self.cond.extend(more.cond);
        self.spectrum.extend(more.spectrum);
        self.dagger.extend(more.dagger);
        self.ladder.extend(more.ladder);
        self.seeds.extend(more.seeds);
        self.path.extend(more.path);
        self.physics_path.extend(more.physics_path);
        for (mine, theirs) in [
            (&mut self.calibration, &more.calibration),
            (&mut self.trajectory, &more.trajectory),
            (&mut self.controls, &more.controls),
            (&mut self.goal, &more.goal),
        ] {
            mine.append(theirs).map_err(other)?;
        }
        Ok(())
    }

    /// Every table of the run under its file name, with `net_lines`, the dolphin's and the rule.
    /// The sweeps' and the DAgger lines' tables are written only where the spec asks for them,
    /// so the report can tell a study not run (no file) from a table that lost its rows (an
    /// error).
    fn into_tables(
        self,
        p: &Params,
        lines: Vec<NetLineRow>,
        d: DolphinTables,
    ) -> Result<Tables, Error> {
        let dolphin_dagger = p.dolphin.as_ref().is_some_and(|d| d.dagger.is_some());
        let mut tables = Tables::from([
            ("dolphin_motion", d.motion),
            ("sweep", table_of(&self.sweep)),
            ("physics_sweep", table_of(&self.physics)),
            ("best_weights", table_of(&self.best_tol)),
            ("best_weights_sweep", table_of(&self.best)),
            ("best_weights_emulator_sweep", table_of(&self.best_emulator)),
            ("conditioning", table_of(&self.cond)),
            ("calibration", self.calibration),
            ("conditioning_ladder", table_of(&self.ladder)),
            ("spectrum", table_of(&self.spectrum)),
            ("dagger", table_of(&self.dagger)),
            ("dolphin_restarts", d.restarts),
            ("dolphin_dagger", table_of(&d.dagger)),
            ("swim", table_of(&d.swim)),
            ("objective", table_of(&self.objective)),
            ("final", table_of(&self.final_)),
            ("net_seeds", table_of(&self.seeds)),
            ("net_lines", table_of(&lines)),
            ("path", table_of(&self.path)),
            ("physics_path", table_of(&self.physics_path)),
            ("trajectory", self.trajectory),
            ("controls", self.controls),
            ("goal", self.goal),
            ("states", table_of(&self.states)),
            (
                "rule",
                match &p.rule {
                    Some(r) => rule_table_of(r)?,
                    None => rule_table(&[]),
                },
            ),
        ]);
        tables.0.retain(|(name, _)| match name.as_str() {
            "sweep" => p.sweep.is_some(),
            "physics_sweep" => p.physics_sweep.is_some(),
            "dagger" => {
                let paper = p.tasks.iter().any(|t| t.formulation == Formulation::Paper);
                p.dagger.is_some() && paper
            }
            "dolphin_dagger" => dolphin_dagger,
            _ => true,
        });
        Ok(tables)
    }
}

/// Where a task's descents start: its knot layout, start state, normalized initial knots and
/// the step scale λ measured there.
struct Start<'a> {
    knots: Knots,
    x0: &'a [f64],
    v0: &'a [f64],
    lambda: f64,
}

impl Params {
    /// One task through its trained Table 1 net: the conditioning ladder, the calibration,
    /// the start's spectrum, the headline descent, the sweeps, the DAgger rounds and the best
    /// iterate replayed on the simulator.
    fn run_task(
        &self,
        ctx: &RunContext,
        task: &Task,
        spec: &BuildSpec,
        trained: &Trained,
        built: &[Trained],
        t: &mut RunTables,
    ) -> Result<(), Error> {
        let knots = Knots {
            steps: task.task.horizon,
            per_actuator: task.task.knots,
            m: task.net.model.control_dim(),
        };
        let x0 = task.start_state();
        // The task's actuator gains and final-state weights, measured once at its initial
        // knots through its Table 1 net and then fixed for every run of the task (the
        // physics sweep and the DAgger rounds included).
        self.record_task_ladder(task, built, &mut t.ladder)?;
        let task = &task.calibrated(&trained.emulator, &x0).map_err(other)?;
        push_calibration(task, &mut t.calibration);
        let objective = task.objective();
        let mut bptt =
            Bptt::new(&trained.emulator, &objective, knots, task.bounds(), &x0).map_err(other)?;
        let init = task.initial_knots();
        let v0 = bptt.from_controls(&init);
        let lambda = bptt.curvature(&v0, self.curvature_iterations);
        if !(lambda.is_finite() && lambda > 0.0) {
            return Err(other(format!("{}: step scale λ = {lambda}", task.name)));
        }
        record_start_spectrum(task, &objective, &mut bptt, &v0, lambda, t)?;
        let schedule = self.schedule(task.eta, task.alpha, task.step_rule, lambda);
        let record = self.over_net_seeds(task) && task.formulation == Formulation::Paper;
        let (r, best, iterates) = ctx.stage(&format!("learn {}", task.name), || {
            learn_recording(&mut bptt, &v0, &schedule, task.task.iterations, record)
        });
        push_path(
            &mut t.path,
            task,
            ctx.seed,
            &mut bptt,
            &iterates,
            lambda,
            self.steps,
            self.curvature_iterations,
        );
        t.objective.extend(r.trace.iter().map(|tr| ObjectiveRow {
            task: task.name.clone(),
            iteration: tr.iteration as i64,
            objective: tr.objective,
        }));
        let start = Start {
            knots,
            x0: &x0,
            v0: &v0,
            lambda,
        };
        self.run_task_sweeps(ctx, task, trained, &objective, &mut bptt, &start, t)?;
        // DAgger refines the nets of the paper's tasks; a formulation of ours kept for
        // comparison gets the headline and the sweeps only.
        if let Some(d) = self
            .dagger
            .as_ref()
            .filter(|_| task.formulation == Formulation::Paper)
        {
            self.run_dagger(ctx, d, task, spec, trained, &x0, &mut t.dagger)?;
        }
        self.record_headline(ctx, task, trained, &x0, &r, &best, t)
    }

    /// The conditioning ladder of `task` when it is the first formulation of ours beside a
    /// paper one of the same model: the conditioning as the paper's changes are applied to
    /// ours one at a time, each rung through its own trained net of `built`.
    fn record_task_ladder(
        &self,
        task: &Task,
        built: &[Trained],
        ladder_t: &mut Vec<LadderRow>,
    ) -> Result<(), Error> {
        let model = task.net.model;
        // The trained emulator of a task's net spec (the conditioning ladder's rungs).
        let net_of = |net: &NetSpec| {
            self.tasks
                .iter()
                .position(|t| &t.net == net)
                .map(|i| &built[i].emulator)
        };
        let same_model = |t: &&Task| t.net.model == model;
        let first_ours = self
            .tasks
            .iter()
            .filter(same_model)
            .find(|t| t.formulation == Formulation::Ours);
        if first_ours.is_some_and(|t| std::ptr::eq(t, task)) {
            if let Some(paper) = self
                .tasks
                .iter()
                .filter(same_model)
                .find(|p| p.formulation == Formulation::Paper)
            {
                let rungs = ladder(task, paper);
                record_ladder(net_of, &rungs, ladder_t)?;
            }
        }
        Ok(())
    }

    /// The step-size sweep through the task's net and the physics sweep (with, under the best
    /// final-state weights it finds, the headline again through the net).
    #[allow(clippy::too_many_arguments)]
    fn run_task_sweeps(
        &self,
        ctx: &RunContext,
        task: &Task,
        trained: &Trained,
        objective: &Objective,
        bptt: &mut Bptt<'_, crate::emulator::Emulator>,
        start: &Start<'_>,
        t: &mut RunTables,
    ) -> Result<(), Error> {
        let Start {
            knots,
            x0,
            v0,
            lambda,
        } = *start;
        if let Some(sw) = &self.sweep {
            ctx.stage(&format!("sweep {}", task.name), || {
                self.sweep_task(task, sw, bptt, v0, lambda, x0, &mut t.sweep)
            });
        }
        if let Some(sw) = &self.physics_sweep {
            let best_tolerance = ctx.stage(&format!("physics sweep {}", task.name), || {
                let tables = PhysicsTables {
                    sweep: &mut t.physics,
                    conditioning: &mut t.cond,
                    spectrum: &mut t.spectrum,
                    best_sweep: &mut t.best,
                    best_weights: &mut t.best_tol,
                };
                self.physics_sweep_task(task, sw, objective, knots, x0, tables)
            })?;
            // The same headline through the Table 1 net under the best weights (the
            // spec's reading: data beside the physics' run).
            if let Some(tolerance) = best_tolerance {
                let mut best = task.clone();
                best.task.final_tolerance = tolerance;
                let objective = best.objective();
                let mut b = Bptt::new(&trained.emulator, &objective, knots, task.bounds(), x0)
                    .map_err(other)?;
                let lambda = b.curvature(v0, self.curvature_iterations);
                let headline = task.headline_sweep(sw.iterations);
                let table = &mut t.best_emulator;
                self.sweep_task(task, &headline, &mut b, v0, lambda, x0, table);
            }
        }
        Ok(())
    }

    /// The headline's best iterate replayed on the simulator: its `final` row (and `net_seeds`
    /// row where the task runs over the seeds), goal, controls and both trajectories.
    #[allow(clippy::too_many_arguments)]
    fn record_headline(
        &self,
        ctx: &RunContext,
        task: &Task,
        trained: &Trained,
        x0: &[f64],
        r: &Learned,
        best: &BestRollout,
        t: &mut RunTables,
    ) -> Result<(), Error> {
        let model = task.net.model;
        let (n, m) = (model.state_dim(), model.control_dim());
        let (width, u_width) = (t.width, t.u_width);
        let mut sim = model.simulator();
        let dt_phys = task.net.physical_dt;
        let emu_final = &best.states[task.task.horizon * n..];
        let rep = replay(
            sim.as_mut(),
            x0,
            &best.controls,
            dt_phys,
            self.steps,
            emu_final,
        );
        let sim_final = &rep.states[task.task.horizon * n..];
        let run = HeadlineRun {
            emulator_error: task.final_error(emu_final),
            simulator_error: task.final_error(sim_final),
            best_iteration: r.best_iteration,
        };
        t.final_.push(FinalRow {
            task: task.name.clone(),
            emulator_error: run.emulator_error,
            simulator_error: run.simulator_error,
            best_iteration: r.best_iteration as i64,
            formulation: task.formulation.name().into(),
            start_simulator_error: start_simulator_error(task, &trained.emulator, self.steps)?,
        });
        if self.over_net_seeds(task) {
            let paper = task.formulation == Formulation::Paper;
            let path = paper.then_some((&mut t.physics_path, ctx.seed));
            let to_goal = ctx.stage(&format!("{} to its goal", task.name), || {
                let ci = self.curvature_iterations;
                ToGoal::measure(task, &trained.emulator, self.steps, ci, path)
            })?;
            run.push(&mut t.seeds, task, ctx.seed, to_goal);
        }
        let mut row = row![task.name.as_str(), model.name()];
        row.extend((0..width).map(|k| task.task.target.get(k).copied().unwrap_or(f64::NAN).into()));
        t.goal.push(row);
        let dt = task.net.physical_dt * self.steps as f64;
        for (k, u) in best.controls.chunks_exact(m.max(1)).enumerate() {
            let mut row = row![task.name.as_str(), k as i64, k as f64 * dt];
            row.extend((0..u_width).map(|c| u.get(c).copied().unwrap_or(f64::NAN).into()));
            t.controls.push(row);
        }
        for (source, states) in [("emulator", &best.states), ("simulator", &rep.states)] {
            for (i, s) in states.chunks_exact(n).enumerate() {
                let mut row = row![task.name.as_str(), i as i64, i as f64 * dt, source];
                row.extend((0..width).map(|k| s.get(k).copied().unwrap_or(f64::NAN).into()));
                t.trajectory.push(row);
            }
        }
        Ok(())
    }

    /// The dolphin's tables: filled by [`Params::run_dolphin`] under `[params.dolphin]` (its
    /// headline rows also go to `objective`, `final` and `trajectory`), empty otherwise.
    fn run_dolphin_tables(
        &self,
        ctx: &RunContext,
        t: &mut RunTables,
    ) -> Result<DolphinTables, Error> {
        let mut swim_t = Vec::new();
        let mut motion_cols = vec!["source".to_string(), "step".into(), "t".into()];
        motion_cols.extend((0..N_POS).map(|k| format!("p{k}")));
        let motion_refs: Vec<&str> = motion_cols.iter().map(String::as_str).collect();
        let mut motion_t = Table::new(&motion_refs);
        let mut restarts_t = Table::new(&[
            "restart",
            "scale",
            "initial_objective",
            "best_iteration",
            "best_objective",
            "distance_emulator_m",
            "distance_simulator_m",
        ]);
        let mut dolphin_dagger_t = Vec::new();
        if let Some(d) = &self.dolphin {
            self.run_dolphin(
                ctx,
                d,
                t.width,
                &mut restarts_t,
                &mut t.objective,
                &mut t.final_,
                &mut t.trajectory,
                &mut swim_t,
                &mut motion_t,
                &mut dolphin_dagger_t,
            )?;
        }
        Ok(DolphinTables {
            swim: swim_t,
            motion: motion_t,
            restarts: restarts_t,
            dagger: dolphin_dagger_t,
        })
    }
}

/// `calibration.csv`'s rows of a calibrated `task`: its actuator gains and final-state weights.
fn push_calibration(task: &Task, calibration_t: &mut Table) {
    let c = task.calibration.as_ref().expect("calibrated");
    for (j, g) in c.gains.iter().enumerate() {
        calibration_t.push(row![task.name.as_str(), "gain", j as i64, *g]);
    }
    for (k, w) in c.weights.iter().enumerate() {
        calibration_t.push(row![task.name.as_str(), "weight", k as i64, *w]);
    }
}

/// The terminal Gauss-Newton spectrum and weighting bound of `task` at its start knots `v0`
/// through the emulator, recorded beside the step scale `lambda`.
fn record_start_spectrum(
    task: &Task,
    objective: &Objective,
    bptt: &mut Bptt<'_, crate::emulator::Emulator>,
    v0: &[f64],
    lambda: f64,
    t: &mut RunTables,
) -> Result<(), Error> {
    let curvature = objective
        .gauss_newton()
        .ok_or_else(|| other(format!("{}: objective without curvature", task.name)))?;
    let spectrum = terminal_spectrum(bptt, v0, &curvature, task.final_dof());
    let bound = weighting_bound(&task.final_rows(bptt, v0));
    record_spectrum(
        task,
        "emulator",
        (&spectrum, &bound),
        lambda,
        (&mut t.cond, &mut t.spectrum),
    );
    Ok(())
}

/// Columns `lead` then `prefix`0 … `prefix`(width − 1): one table for tasks of models of
/// different sizes (NaN past a model's own).
fn wide_columns(lead: &[&str], prefix: &str, width: usize) -> Vec<String> {
    let mut cols: Vec<String> = lead.iter().map(|s| s.to_string()).collect();
    cols.extend((0..width).map(|k| format!("{prefix}{k}")));
    cols
}

/// The headline of a calibrated `task` through `net` (N`steps` emulator): its descent (the
/// task's η, α and step rule, λ from `curvature_iterations` power iterations at the initial
/// knots) for its iteration count, scored at the best iterate on the emulator and with the same
/// controls replayed on the simulator. `None` when λ is not finite and positive (nothing can
/// be learned at a fixed step then).
pub fn learn_and_replay(
    task: &Task,
    net: &crate::emulator::Emulator,
    steps: usize,
    curvature_iterations: usize,
) -> Result<Option<(HeadlineRun, Learned)>, Error> {
    learn_and_replay_path(task, net, steps, curvature_iterations, None)
}

/// The final error (1 = tolerance) of a calibrated `task`'s initial knots replayed on the
/// simulator, each held for `steps` physical steps: what doing nothing scores, the null of
/// a check on a learned control's simulator error. `net` only expands the knots into
/// per-step controls, as the descent does.
pub fn start_simulator_error(
    task: &Task,
    net: &crate::emulator::Emulator,
    steps: usize,
) -> Result<f64, Error> {
    with_start(task, net, |bptt, v0| {
        bptt.rollout(&v0);
        let at = task.task.horizon * task.net.model.state_dim();
        simulator_error(task, bptt.controls(), &bptt.states()[at..], steps)
    })
}

/// Runs `f` on the descent of a calibrated `task` through `net` (its objective, knots, bounds
/// and start) and the task's initial knots, normalized: the set-up every headline shares.
fn with_start<R>(
    task: &Task,
    net: &crate::emulator::Emulator,
    f: impl FnOnce(&mut Bptt<'_, crate::emulator::Emulator>, Vec<f64>) -> R,
) -> Result<R, Error> {
    let model = task.net.model;
    let knots = Knots {
        steps: task.task.horizon,
        per_actuator: task.task.knots,
        m: model.control_dim(),
    };
    let objective = task.objective();
    let mut bptt =
        Bptt::new(net, &objective, knots, task.bounds(), &task.start_state()).map_err(other)?;
    let v0 = bptt.from_controls(&task.initial_knots());
    Ok(f(&mut bptt, v0))
}

/// [`with_start`] with the headline's schedule: λ measured at the initial knots and the task's
/// η, α and step rule; `None` when λ is not finite and positive (nothing can be learned at a
/// fixed step then).
fn with_schedule<R>(
    task: &Task,
    net: &crate::emulator::Emulator,
    curvature_iterations: usize,
    f: impl FnOnce(&mut Bptt<'_, crate::emulator::Emulator>, Vec<f64>, f64, &Schedule) -> Option<R>,
) -> Result<Option<R>, Error> {
    with_start(task, net, |bptt, v0| {
        let lambda = bptt.curvature(&v0, curvature_iterations);
        if !(lambda.is_finite() && lambda > 0.0) {
            return None;
        }
        let schedule = schedule(
            task.eta,
            task.alpha,
            task.step_rule,
            lambda,
            curvature_iterations,
        );
        f(bptt, v0, lambda, &schedule)
    })
}

/// The final error of per-step `controls` replayed on `task`'s simulator from its start, each
/// emulator step `steps` physical steps (`emu_final`, the emulator's final state, is what the
/// replay is compared with in its record).
fn simulator_error(task: &Task, controls: &[f64], emu_final: &[f64], steps: usize) -> f64 {
    let model = task.net.model;
    let mut sim = model.simulator();
    let rep = replay(
        sim.as_mut(),
        &task.start_state(),
        controls,
        task.net.physical_dt,
        steps,
        emu_final,
    );
    task.final_error(&rep.states[task.task.horizon * model.state_dim()..])
}

/// How many times the paper's iteration count [`iterations_to_goal`] continues a descent
/// (ours): far enough to tell a descent that is slow from one that never arrives.
pub const TO_GOAL_FACTOR: usize = 2;

/// The first iteration of a calibrated `task`'s headline descent through `net` (as
/// [`learn_and_replay`] runs it), continued to [`TO_GOAL_FACTOR`] times the task's iteration
/// count, whose iterate ends within tolerance on the net and with its controls replayed on the
/// simulator; `None` when no iterate does (or λ is not finite and positive).
pub fn iterations_to_goal(
    task: &Task,
    net: &crate::emulator::Emulator,
    steps: usize,
    curvature_iterations: usize,
) -> Result<Option<usize>, Error> {
    with_schedule(task, net, curvature_iterations, |bptt, v0, _, schedule| {
        let cap = TO_GOAL_FACTOR * task.task.iterations;
        let (_, _, iterates) = learn_recording(bptt, &v0, schedule, cap, true);
        let at = task.task.horizon * task.net.model.state_dim();
        iterates.iter().find_map(|(iteration, _, v)| {
            bptt.rollout(v);
            let emu_final = bptt.states()[at..].to_vec();
            let on_net = task.final_error(&emu_final) <= 1.0;
            (on_net && simulator_error(task, bptt.controls(), &emu_final, steps) <= 1.0)
                .then_some(*iteration)
        })
    })
}

/// Per iterate of `iterates` (through the physics), the cosine between the gradient of a
/// calibrated `task`'s J through `net` and the physics' gradient there, and the norm of their
/// difference over the physics' norm.
pub(super) fn gradient_fidelity(
    task: &Task,
    net: &crate::emulator::Emulator,
    iterates: &[super::conditioning::PhysicsIterate],
) -> Result<Vec<(f64, f64)>, Error> {
    with_start(task, net, |bptt, _| {
        let mut g = Vec::new();
        iterates
            .iter()
            .map(|it| {
                g.resize(it.knots.len(), 0.0);
                bptt.gradient(&it.knots, &mut g);
                let p = &it.gradient;
                let dot: f64 = g.iter().zip(p).map(|(a, b)| a * b).sum();
                let diff: f64 = g.iter().zip(p).map(|(a, b)| (a - b) * (a - b)).sum();
                let (ng, np) = (
                    crate::control::bptt::norm(&g),
                    crate::control::bptt::norm(p),
                );
                (dot / (ng * np), diff.sqrt() / np)
            })
            .collect()
    })
}

/// Columns of `path.csv` (ours): every iterate of the headline's descent of a paper task
/// through the Table 1 net of `net_seed`: J on the net, the final error of the iterate's
/// controls on the net and replayed on the simulator, and the largest Hessian eigenvalue of J
/// through the net there over the one at the initial knots (λ, the fixed step's scale). The
/// momentum descent with step η/λ is stable along a quadratic direction of curvature μ only
/// while η μ/λ < 2(1 + α) ([`stable_curvature_ratio`]), so a ratio above that limit marks an
/// iterate where the fixed step overshoots (`stable_ratio`, the task's limit); the two errors
/// side by side show whether the net follows the physics along the whole descent or only at
/// its end.
pub const PATH_COLUMNS: &[&str] = PathRow::COLUMNS;

/// The largest curvature over the start's λ at which the heavy-ball step η/λ with momentum α
/// still contracts along a quadratic direction: 2(1 + α)/η.
pub fn stable_curvature_ratio(eta: f64, alpha: f64) -> f64 {
    2.0 * (1.0 + alpha) / eta
}

/// One iterate of a descent: its iteration, J and normalized knots.
type Iterate = (usize, f64, Vec<f64>);

/// `path.csv`'s rows of `task`'s `iterates` through `bptt` (the net of `seed`, whose λ at the
/// initial knots is `lambda`): each iterate rolled out on the net, its controls replayed on
/// the simulator, and its curvature measured as λ was.
#[allow(clippy::too_many_arguments)]
fn push_path<D: DifferentiableStep>(
    table: &mut Vec<PathRow>,
    task: &Task,
    seed: u64,
    bptt: &mut Bptt<'_, D>,
    iterates: &[Iterate],
    lambda: f64,
    steps: usize,
    curvature_iterations: usize,
) {
    let at = task.task.horizon * task.net.model.state_dim();
    for (iteration, objective, v) in iterates {
        bptt.rollout(v);
        let emu_final = bptt.states()[at..].to_vec();
        let sim_error = simulator_error(task, bptt.controls(), &emu_final, steps);
        let ratio = bptt.curvature(v, curvature_iterations) / lambda;
        table.push(PathRow {
            task: task.name.clone(),
            net_seed: seed as i64,
            iteration: *iteration as i64,
            objective: *objective,
            emulator_error: task.final_error(&emu_final),
            simulator_error: sim_error,
            curvature_ratio: ratio,
            stable_ratio: stable_curvature_ratio(task.eta, task.alpha),
        });
    }
}

/// [`learn_and_replay`], and where `path` is given, `path.csv`'s rows of the descent (through
/// the net of the given seed) pushed to its table.
pub(super) fn learn_and_replay_path(
    task: &Task,
    net: &crate::emulator::Emulator,
    steps: usize,
    curvature_iterations: usize,
    path: Option<(&mut Vec<PathRow>, u64)>,
) -> Result<Option<(HeadlineRun, Learned)>, Error> {
    with_schedule(
        task,
        net,
        curvature_iterations,
        |bptt, v0, lambda, schedule| {
            let (r, best, iterates) =
                learn_recording(bptt, &v0, schedule, task.task.iterations, path.is_some());
            if let Some((table, seed)) = path {
                push_path(
                    table,
                    task,
                    seed,
                    bptt,
                    &iterates,
                    lambda,
                    steps,
                    curvature_iterations,
                );
            }
            let emu_final = &best.states[task.task.horizon * task.net.model.state_dim()..];
            let run = HeadlineRun {
                emulator_error: task.final_error(emu_final),
                simulator_error: simulator_error(task, &best.controls, emu_final, steps),
                best_iteration: r.best_iteration,
            };
            Some((run, r))
        },
    )
}

/// [`learn_best`] for `iterations`, and where `record`, every iterate (for `path.csv`).
fn learn_recording<D: DifferentiableStep>(
    bptt: &mut Bptt<'_, D>,
    v0: &[f64],
    schedule: &Schedule,
    iterations: usize,
    record: bool,
) -> (Learned, BestRollout, Vec<Iterate>) {
    let mut iterates: Vec<Iterate> = Vec::new();
    let (r, best) = learn_best(bptt, v0, schedule, iterations, &mut |t, v, _| {
        if record {
            iterates.push((t.iteration, t.objective, v.to_vec()));
        }
        false
    });
    (r, best, iterates)
}

/// Runs [`learn_with`] and rolls the best-so-far iterate out again: the run and the best
/// iterate's rollout (its states and controls), which is what every task scores.
pub fn learn_best<D: DifferentiableStep>(
    bptt: &mut Bptt<'_, D>,
    v0: &[f64],
    schedule: &Schedule,
    iterations: usize,
    stop: &mut dyn FnMut(&crate::control::bptt::IterationTrace, &[f64], &[f64]) -> bool,
) -> (Learned, BestRollout) {
    let r = learn_with(bptt, v0, schedule, iterations, stop);
    bptt.rollout(&r.best_knots);
    let best = BestRollout {
        states: bptt.states().to_vec(),
        controls: bptt.controls().to_vec(),
    };
    (r, best)
}

/// The rollout of a run's best iterate.
#[derive(Debug, Clone, PartialEq)]
pub struct BestRollout {
    /// Emulated states s_0 … s_M.
    pub states: Vec<f64>,
    /// Per-step controls (control units).
    pub controls: Vec<f64>,
}

impl Params {
    /// Every rule × η of `sw` for `task` through `bptt` (start `v0`, initial λ), each run
    /// stopped at the goal; the best iterate replayed on the simulator; one row each.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn sweep_task<D: DifferentiableStep>(
        &self,
        task: &Task,
        sw: &Sweep,
        bptt: &mut Bptt<'_, D>,
        v0: &[f64],
        lambda: f64,
        x0: &[f64],
        table: &mut Vec<SweepRow>,
    ) {
        let n = task.net.model.state_dim();
        let mut sim = task.net.model.simulator();
        for rule in &sw.rules {
            // Levenberg–Marquardt uses neither η nor α: one run, both reported as NaN.
            let lm = matches!(rule, StepRule::LevenbergMarquardt { .. });
            let etas = if lm { &sw.eta[..1] } else { &sw.eta[..] };
            for &eta in etas {
                let schedule = self.schedule(eta, sw.alpha, *rule, lambda);
                let (eta, alpha) = if lm {
                    (f64::NAN, f64::NAN)
                } else {
                    (eta, sw.alpha)
                };
                let mut hit: Option<(usize, usize)> = None;
                let (run, b) = learn_best(bptt, v0, &schedule, sw.iterations, &mut |e, _, st| {
                    let reached = task.final_error(&st[task.task.horizon * n..]) <= 1.0;
                    if reached {
                        hit = Some((e.iteration, e.evaluations));
                    }
                    reached
                });
                let last = run.trace.last().expect("iteration 0 is traced");
                let end = &b.states[task.task.horizon * n..];
                let rep = replay(
                    sim.as_mut(),
                    x0,
                    &b.controls,
                    task.net.physical_dt,
                    self.steps,
                    end,
                );
                let to = |k: Option<usize>| k.map_or(f64::NAN, |k| k as f64);
                table.push(SweepRow {
                    task: task.name.clone(),
                    rule: rule.name().into(),
                    eta,
                    alpha,
                    iterations: last.iteration as i64,
                    evaluations: last.evaluations as i64,
                    iterations_to_goal: to(hit.map(|h| h.0)),
                    evaluations_to_goal: to(hit.map(|h| h.1)),
                    best_iteration: run.best_iteration as i64,
                    best_objective: run.best_objective(),
                    rollout_error: task.final_error(end),
                    simulator_error: task.final_error(&rep.states[task.task.horizon * n..]),
                });
            }
        }
    }

    /// The schedule of η, α (plain descent when α = 0), `rule` and initial λ.
    pub(super) fn schedule(&self, eta: f64, alpha: f64, rule: StepRule, lambda: f64) -> Schedule {
        schedule(eta, alpha, rule, lambda, self.curvature_iterations)
    }
}

/// The schedule of η, α (plain descent when α = 0), `rule`, initial λ and the power iterations
/// of its re-estimates.
pub(super) fn schedule(
    eta: f64,
    alpha: f64,
    rule: StepRule,
    lambda: f64,
    curvature_iterations: usize,
) -> Schedule {
    let descent = if alpha > 0.0 {
        Descent::Momentum { eta, alpha }
    } else {
        Descent::Plain { eta }
    };
    Schedule {
        descent,
        rule,
        scale: lambda,
        curvature_iterations,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::control::bptt::DescentState;

    /// |x| after `n` steps of `descent` (λ = 1) on J = μ x²/2 from x = 1.
    fn after(descent: Descent, mu: f64, n: usize) -> f64 {
        let (mut x, mut state) = (1.0, DescentState::default());
        for _ in 0..n {
            let (step, next) = descent.update(&[mu * x], 1.0, state);
            x += step[0];
            state = next;
        }
        x.abs()
    }

    #[test]
    fn the_momentum_step_contracts_exactly_below_the_stable_curvature_ratio() {
        for (eta, alpha) in [(1.5, 0.5), (1.0, 0.0), (0.5, 0.9)] {
            let limit = stable_curvature_ratio(eta, alpha);
            let descent = if alpha > 0.0 {
                Descent::Momentum { eta, alpha }
            } else {
                Descent::Plain { eta }
            };
            assert!(
                after(descent, 0.97 * limit, 300) < 1e-3,
                "eta {eta} alpha {alpha}"
            );
            assert!(
                after(descent, 1.03 * limit, 300) > 1e3,
                "eta {eta} alpha {alpha}"
            );
        }
    }
}
