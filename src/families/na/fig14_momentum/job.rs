//! The job of `na_fig14_momentum`: the lander net trained, every descent learned through it and
//! replayed on the simulator, and the same through the DAgger nets and to convergence.

use super::rows::{
    ConvergedRow, DaggerRow, GradientRow, Method, NetSeedRow, ObjectiveRow, RunRow, Scores,
    UnclippedRow,
};
use super::{DaggerNet, MomentumDagger, Params};
use crate::control::bptt::{
    learn_until, replay, Bounds, Bptt, Descent, IterationTrace, Knots, Learned, Replay,
};
use crate::control::objective::Objective;
use crate::emulator::catalog::{BuildSpec, NetModel, Trained};
use crate::emulator::Emulator;
use crate::experiment::output::{Table, Tables};
use crate::experiment::rows::table_of;
use crate::experiment::{other, Error, Job, RunContext};
use crate::families::na::fig13_control::dagger::{ChainLearner, DaggerRoundRow, Round};
use crate::families::na::table1_structure::{build_emulator, build_emulators, build_spec};
use crate::physics::lander::{Lander, VEL};
use crate::physics::Dynamics;
use crate::row;

/// The `method` cell of descent `d`.
fn method(d: &Descent) -> &'static str {
    Method::of(d).name()
}

fn distance(a: &[f64], b: &[f64]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y) * (x - y))
        .sum::<f64>()
        .sqrt()
}

impl Job for Params {
    fn params_json(&self) -> serde_json::Value {
        serde_json::to_value(self).unwrap_or_default()
    }

    fn run(&self, ctx: &RunContext) -> Result<Tables, Error> {
        let spec = build_spec(
            ctx.seed,
            &self.net,
            self.steps,
            self.example_scale,
            &self.training,
        );
        let trained = ctx.stage("train lander N50", || build_emulator(&spec))?;
        let x0 = self.start_state();
        // The actuator gains and final-state weights of the task's units and weights, measured
        // once at hover through the Table 1 net and fixed for every net (as na_fig13_control).
        let calibration = self
            .lander_task(self.task.iterations)
            .calibrated(&trained.emulator, &x0)
            .map_err(other)?
            .calibration
            .expect("calibrated");
        let gains = calibration.gains.clone();
        let objective = self.objective_with(Some(&calibration));
        let mut problem = self.problem(ctx, &trained.emulator, &objective, &x0, &gains)?;
        let base = Base {
            spec: &spec,
            trained: &trained,
            objective: &objective,
            x0: &x0,
            gains: &gains,
        };
        let scale = problem.scale;
        let mut t = MomentumTables::new();
        let descents = self.descents();
        let mut sim = NetModel::Lander.simulator();
        let own_curves =
            self.headline_descents(ctx, &mut problem, &descents, sim.as_mut(), &x0, &mut t);
        let net_seeds_t = self.net_seeds_table(ctx, scale, &own_curves, &x0, sim.as_mut())?;
        self.unclipped_descents(ctx, &base, &descents, sim.as_mut(), &mut t)?;
        self.converged_rows(
            ctx,
            &mut problem,
            sim.as_mut(),
            &x0,
            ("table1", 0),
            &mut t.converged,
        );
        if let Some(dn) = &self.dagger {
            self.through_dagger_net(ctx, dn, &base, sim.as_mut(), &mut t)?;
        }
        if let Some(md) = &self.momentum_dagger {
            self.through_momentum_dagger(ctx, md, &base, sim.as_mut(), &mut t)?;
        }
        Ok(Tables::from([
            ("objective", table_of(&t.objective)),
            ("gradient", table_of(&t.gradient)),
            ("runs", table_of(&t.runs)),
            ("trajectory", t.trajectory),
            ("dagger", table_of(&t.dagger)),
            ("dagger_objective", table_of(&t.dagger_objective)),
            ("momentum_dagger_rounds", table_of(&t.chain_rounds)),
            ("converged", table_of(&t.converged)),
            ("unclipped", table_of(&t.unclipped)),
            ("rule", crate::experiment::rule::rule_table_of(&self.rule)?),
            ("unclipped_objective", table_of(&t.unclipped_objective)),
            ("net_seeds", table_of(&net_seeds_t)),
        ]))
    }
}

/// What every descent of the run shares: the Table 1 lander net (its spec and training), the
/// calibrated objective, the start state and the actuator gains.
struct Base<'a> {
    spec: &'a BuildSpec,
    trained: &'a Trained,
    objective: &'a Objective,
    x0: &'a [f64],
    gains: &'a [f64],
}

/// The tables the descents fill (`net_seeds` is built on its own).
struct MomentumTables {
    objective: Vec<ObjectiveRow>,
    gradient: Vec<GradientRow>,
    runs: Vec<RunRow>,
    trajectory: Table,
    dagger: Vec<DaggerRow>,
    dagger_objective: Vec<ObjectiveRow>,
    converged: Vec<ConvergedRow>,
    /// Every descent of the sweep with the knots clipped to the boxes (as the runs above)
    /// and without (ours): whether plain descent above its stability limit
    /// diverges once the boxes no longer hide it.
    unclipped: Vec<UnclippedRow>,
    /// The unclipped descents' objective per iteration (the figure's unclipped panel).
    unclipped_objective: Vec<ObjectiveRow>,
    chain_rounds: Vec<DaggerRoundRow>,
}

impl MomentumTables {
    /// The empty tables.
    fn new() -> Self {
        MomentumTables {
            objective: Vec::new(),
            gradient: Vec::new(),
            runs: Vec::new(),
            trajectory: Table::new(&[
                "method", "eta", "step", "t", "source", "x", "y", "z", "vz", "tilt",
            ]),
            dagger: Vec::new(),
            dagger_objective: Vec::new(),
            converged: Vec::new(),
            unclipped: Vec::new(),
            unclipped_objective: Vec::new(),
            chain_rounds: Vec::new(),
        }
    }
}

/// The objective rows of run `r` of descent `d`.
fn objective_rows<'a>(d: &Descent, r: &'a Learned) -> impl Iterator<Item = ObjectiveRow> + 'a {
    let (method, eta, alpha) = (method(d), d.eta(), d.alpha());
    r.trace.iter().map(move |tr| ObjectiveRow {
        method: method.into(),
        eta,
        alpha,
        iteration: tr.iteration as i64,
        objective: tr.objective,
    })
}

impl Params {
    /// Every descent of the sweep through the Table 1 net (`problem`, step scale taken before
    /// the first), replayed on the simulator: its objective, gradient, trajectory, clipped
    /// `unclipped`, `runs` and (for the compared pair) `dagger` rows. Returns the objective
    /// curves, for `net_seeds.csv`.
    fn headline_descents(
        &self,
        ctx: &RunContext,
        problem: &mut Problem<'_>,
        descents: &[Descent],
        sim: &mut dyn Dynamics,
        x0: &[f64],
        t: &mut MomentumTables,
    ) -> Vec<(Descent, Vec<f64>)> {
        let scale = problem.scale;
        let compared = self.compared();
        let pb = ctx.progress(descents.len() as u64, "control learning");
        // The headline's objective curves through the run's own net, for `net_seeds.csv`.
        let mut own_curves: Vec<(Descent, Vec<f64>)> = Vec::new();
        for d in descents {
            let (r, rep) = self.descend(ctx, problem, d, sim, x0, "");
            own_curves.push((*d, r.trace.iter().map(|t| t.objective).collect()));
            t.objective.extend(objective_rows(d, &r));
            t.gradient.extend(r.trace.iter().map(|tr| GradientRow {
                method: method(d).into(),
                eta: d.eta(),
                alpha: d.alpha(),
                iteration: tr.iteration as i64,
                grad_norm: tr.grad_norm,
            }));
            self.push_trajectory(d, &r, &rep, &mut t.trajectory);
            t.unclipped.push(unclipped_row(d, true, &r));
            let scores = self.scores(scale, &r, &rep);
            t.runs.push(RunRow::new(d, &scores));
            if let (Some(dn), true) = (&self.dagger, compared.contains(d)) {
                t.dagger
                    .push(self.dagger_row(("table1", 0), d, &scores, (&r, &rep), dn));
            }
            pb.inc(1);
        }
        pb.finish_and_clear();
        own_curves
    }

    /// `trajectory.csv`'s rows of descent `d`: its emulated and simulated states at the
    /// emulator step times (tilt: the thrust axis's angle from vertical).
    fn push_trajectory(&self, d: &Descent, r: &Learned, rep: &Replay, trajectory: &mut Table) {
        let n = NetModel::Lander.state_dim();
        let dt = self.net.physical_dt * self.steps as f64;
        for (source, states) in [("emulator", &r.states), ("simulator", &rep.states)] {
            for (i, s) in states.chunks_exact(n).enumerate() {
                let axis = Lander::thrust_axis(s);
                trajectory.push(row![
                    method(d),
                    d.eta(),
                    i as i64,
                    i as f64 * dt,
                    source,
                    s[0],
                    s[1],
                    s[2],
                    s[VEL + 2],
                    {
                        // acos z as atan2(√(1 − z²), z), in portable arithmetic.
                        let z = axis.z.clamp(-1.0, 1.0);
                        crate::portable::atan2(((1.0 - z) * (1.0 + z)).sqrt(), z)
                    }
                ]);
            }
        }
    }

    /// Every descent of the sweep again through the Table 1 net with its knots free of the
    /// actuators' boxes: its `unclipped` row and objective curve.
    fn unclipped_descents(
        &self,
        ctx: &RunContext,
        base: &Base<'_>,
        descents: &[Descent],
        sim: &mut dyn Dynamics,
        t: &mut MomentumTables,
    ) -> Result<(), Error> {
        let x0 = base.x0;
        let emu = &base.trained.emulator;
        let mut free = self.problem_clipped(ctx, emu, base.objective, x0, (false, base.gains))?;
        for d in descents {
            let (r, _) = self.descend(ctx, &mut free, d, sim, x0, "unclipped ");
            t.unclipped.push(unclipped_row(d, false, &r));
            t.unclipped_objective.extend(objective_rows(d, &r));
        }
        Ok(())
    }

    /// The compared pair through the lander's final-round DAgger net of na_fig13_control (cached:
    /// only its rounds' learning and replays run again): their `dagger` rows and curves, and
    /// the `converged` rows there.
    fn through_dagger_net(
        &self,
        ctx: &RunContext,
        dn: &DaggerNet,
        base: &Base<'_>,
        sim: &mut dyn Dynamics,
        t: &mut MomentumTables,
    ) -> Result<(), Error> {
        let x0 = base.x0;
        let (f13, control) = self.fig13(dn);
        let mut rounds = Vec::new();
        let net = f13.run_dagger(
            ctx,
            &control,
            &f13.tasks[0],
            base.spec,
            base.trained,
            x0,
            &mut rounds,
        )?;
        let mut problem = self.problem(ctx, &net, base.objective, x0, base.gains)?;
        let at = ("dagger", dn.settings.rounds as i64);
        let label = "DAgger net ";
        let runs = self.compared_through(ctx, &mut problem, (&mut *sim, x0), at, dn, label);
        for (d, r, row) in runs {
            t.dagger_objective.extend(objective_rows(&d, &r));
            t.dagger.push(row);
        }
        self.converged_rows(ctx, &mut problem, sim, x0, at, &mut t.converged);
        Ok(())
    }

    /// The DAgger chain whose learner is momentum descent from hover (its rounds in
    /// `momentum_dagger_rounds`), and the compared pair through its final net: their `dagger`
    /// rows and the `converged` rows there.
    fn through_momentum_dagger(
        &self,
        ctx: &RunContext,
        md: &MomentumDagger,
        base: &Base<'_>,
        sim: &mut dyn Dynamics,
        t: &mut MomentumTables,
    ) -> Result<(), Error> {
        let x0 = base.x0;
        let dn = self.momentum_chain(md);
        let net = self.momentum_chain_net(ctx, &dn, base, &mut t.chain_rounds)?;
        let mut problem = self.problem(ctx, &net, base.objective, x0, base.gains)?;
        let at = ("momentum_dagger", md.settings.rounds as i64);
        let label = "momentum-DAgger net ";
        let runs = self.compared_through(ctx, &mut problem, (&mut *sim, x0), at, &dn, label);
        t.dagger.extend(runs.into_iter().map(|(_, _, row)| row));
        self.converged_rows(ctx, &mut problem, sim, x0, at, &mut t.converged);
        Ok(())
    }

    /// Each of the compared pair learned through `p` (the net `net` of DAgger round `round`,
    /// of chain `dn`), replayed on `sim` and scored: the descent, its run and its `dagger.csv`
    /// row, in [`Self::compared`]'s order.
    fn compared_through(
        &self,
        ctx: &RunContext,
        p: &mut Problem<'_>,
        (sim, x0): (&mut dyn Dynamics, &[f64]),
        at: (&str, i64),
        dn: &DaggerNet,
        label: &str,
    ) -> Vec<(Descent, Learned, DaggerRow)> {
        self.compared()
            .into_iter()
            .map(|d| {
                let (r, rep) = self.descend(ctx, p, &d, sim, x0, label);
                let scores = self.scores(p.scale, &r, &rep);
                let row = self.dagger_row(at, &d, &scores, (&r, &rep), dn);
                (d, r, row)
            })
            .collect()
    }

    /// The final net of the DAgger chain `dn` whose rounds learn by momentum descent from
    /// hover (on a simulator of their own), its rounds pushed to `chain_rounds`.
    fn momentum_chain_net(
        &self,
        ctx: &RunContext,
        dn: &DaggerNet,
        base: &Base<'_>,
        chain_rounds: &mut Vec<DaggerRoundRow>,
    ) -> Result<Emulator, Error> {
        let n = NetModel::Lander.state_dim();
        let x0 = base.x0;
        let (f13, control) = self.fig13(dn);
        let mut task = f13.tasks[0].clone();
        task.name = "lander_momentum".into();
        let momentum = Descent::Momentum {
            eta: self.momentum_eta,
            alpha: self.momentum_alpha,
        };
        let mut chain_sim = NetModel::Lander.simulator();
        let mut learn = |net: &Emulator, seed: u64| -> Result<Round, Error> {
            let mut p = self.problem(ctx, net, base.objective, x0, base.gains)?;
            let (r, rep) = self.descend(
                ctx,
                &mut p,
                &momentum,
                chain_sim.as_mut(),
                x0,
                "momentum DAgger ",
            );
            let emu_final = &r.states[self.task.horizon * n..];
            Ok(Round {
                emulator_error: task.final_error(emu_final),
                simulator_error: task.final_error(&rep.states[self.task.horizon * n..]),
                simulator_spread: f13.open_loop_spread(&task, x0, &r.controls, emu_final, seed),
                iterations: r.trace.last().map_or(0, |t| t.iteration),
                to_goal: None,
                best_iteration: r.trace.len().saturating_sub(1),
                controls: r.controls,
            })
        };
        let key = serde_json::json!({
            "learner": "na_fig14_momentum momentum descent from hover",
            "momentum_eta": self.momentum_eta,
            "momentum_alpha": self.momentum_alpha,
            "iterations": self.task.iterations,
            "touchdown_states": self.touchdown_states,
            "touchdown_tolerance": self.touchdown_tolerance,
            "effort_mu": self.task.effort_mu,
            "curvature_iterations": self.curvature_iterations,
        });
        f13.run_dagger_with(
            ctx,
            &control,
            &task,
            base.spec,
            base.trained,
            x0,
            chain_rounds,
            Some(ChainLearner {
                key,
                learn: &mut learn,
            }),
        )
    }
}

/// The `unclipped.csv` row of run `r` of descent `d`.
fn unclipped_row(d: &Descent, clipped: bool, r: &Learned) -> UnclippedRow {
    let js: Vec<f64> = r.trace.iter().map(|t| t.objective).collect();
    let first = js.first().copied().unwrap_or(f64::NAN);
    let last = js.last().copied().unwrap_or(f64::NAN);
    // NaN counts as the largest (a run that blew up).
    let max = js.iter().copied().fold(f64::NEG_INFINITY, |a, b| {
        if b.is_nan() {
            f64::NAN
        } else {
            a.max(b)
        }
    });
    let min = js
        .iter()
        .copied()
        .filter(|x| !x.is_nan())
        .fold(f64::INFINITY, f64::min);
    let diverged = !last.is_finite() || last > first;
    UnclippedRow {
        method: method(d).into(),
        eta: d.eta(),
        alpha: d.alpha(),
        clipped: i64::from(clipped),
        initial_objective: first,
        final_objective: last,
        min_objective: min,
        max_objective: max,
        diverged: i64::from(diverged),
    }
}

/// One net's landing problem from hover: BPTT through the net, the hover knots, λ there.
struct Problem<'a> {
    bptt: Bptt<'a, Emulator>,
    v0: Vec<f64>,
    scale: f64,
}

impl Params {
    /// The landing problem through `emu` from hover, λ measured there.
    fn problem<'a>(
        &self,
        ctx: &RunContext,
        emu: &'a Emulator,
        objective: &'a Objective,
        x0: &[f64],
        gains: &[f64],
    ) -> Result<Problem<'a>, Error> {
        self.problem_clipped(ctx, emu, objective, x0, (true, gains))
    }

    /// [`Self::problem`], its knots clipped to the actuators' boxes or (`clip` false) not.
    fn problem_clipped<'a>(
        &self,
        ctx: &RunContext,
        emu: &'a Emulator,
        objective: &'a Objective,
        x0: &[f64],
        (clip, gains): (bool, &[f64]),
    ) -> Result<Problem<'a>, Error> {
        let model = NetModel::Lander;
        let m = model.control_dim();
        let limits = model.control_limits();
        let knots = Knots {
            steps: self.task.horizon,
            per_actuator: self.task.knots,
            m,
        };
        let mut bounds =
            Bounds::new(limits.low.clone(), limits.high.clone()).with_gain(gains.to_vec());
        if !clip {
            bounds = bounds.without_clipping();
        }
        let mut bptt = Bptt::new(emu, objective, knots, bounds, x0).map_err(other)?;
        let l = Lander::default();
        let hover: Vec<f64> = (0..knots.len())
            .map(|i| if i % m == 0 { l.mass * l.gravity } else { 0.0 })
            .collect();
        let v0 = bptt.from_controls(&hover);
        let scale = ctx.stage("curvature", || {
            bptt.curvature(&v0, self.curvature_iterations)
        });
        if !(scale.is_finite() && scale > 0.0) {
            return Err(other(format!("step scale λ = {scale} at hover")));
        }
        Ok(Problem { bptt, v0, scale })
    }

    /// `net_seeds.csv`: the headline's descents through the run's own net (`own`: each
    /// descent's objective curve, `scale` its λ) and again through the Table 1 lander net of
    /// each further net seed (from the cache, or trained side by side), each such net
    /// calibrated at hover and its λ measured there, as a run under that seed would.
    fn net_seeds_table(
        &self,
        ctx: &RunContext,
        scale: f64,
        own: &[(Descent, Vec<f64>)],
        x0: &[f64],
        sim: &mut dyn Dynamics,
    ) -> Result<Vec<NetSeedRow>, Error> {
        let mut table = Vec::new();
        self.net_seed_rows(ctx.seed, scale, own, &mut table);
        let seeds = self.further_net_seeds(ctx.seed);
        if seeds.is_empty() {
            return Ok(table);
        }
        let specs: Vec<BuildSpec> = seeds
            .iter()
            .map(|&s| build_spec(s, &self.net, self.steps, self.example_scale, &self.training))
            .collect();
        let built = ctx.stage(
            &format!("train lander N50 of {} further net seeds", seeds.len()),
            || build_emulators(&specs),
        )?;
        let descents = self.descents();
        for (&seed, trained) in seeds.iter().zip(&built) {
            let calibration = self
                .lander_task(self.task.iterations)
                .calibrated(&trained.emulator, x0)
                .map_err(other)?
                .calibration
                .expect("calibrated");
            let objective = self.objective_with(Some(&calibration));
            let gains = calibration.gains.clone();
            let mut p = self.problem(ctx, &trained.emulator, &objective, x0, &gains)?;
            let label = format!("net seed {seed}: ");
            let curves: Vec<(Descent, Vec<f64>)> = descents
                .iter()
                .map(|d| {
                    let (r, _) = self.descend(ctx, &mut p, d, sim, x0, &label);
                    (*d, r.trace.iter().map(|t| t.objective).collect())
                })
                .collect();
            self.net_seed_rows(seed, p.scale, &curves, &mut table);
        }
        Ok(table)
    }

    /// The `net_seeds.csv` rows of net seed `seed`: each descent's objective curve, λ `scale`.
    fn net_seed_rows(
        &self,
        seed: u64,
        scale: f64,
        curves: &[(Descent, Vec<f64>)],
        t: &mut Vec<NetSeedRow>,
    ) {
        let compared = self.compared();
        let plain_final = curves
            .iter()
            .find(|(d, _)| matches!(d, Descent::Plain { .. }) && compared.contains(d))
            .and_then(|(_, js)| js.last().copied())
            .unwrap_or(f64::NAN);
        for (d, js) in curves {
            let first = js.first().copied().unwrap_or(f64::NAN);
            let last = js.last().copied().unwrap_or(f64::NAN);
            let min = js
                .iter()
                .copied()
                .filter(|x| !x.is_nan())
                .fold(f64::INFINITY, f64::min);
            let reach = super::iterations_to(js, plain_final).map_or(f64::NAN, |k| k as f64);
            t.push(NetSeedRow {
                net_seed: seed as i64,
                method: method(d).into(),
                eta: d.eta(),
                alpha: d.alpha(),
                compared: i64::from(compared.contains(d)),
                scale,
                iterations: js.len().saturating_sub(1) as i64,
                initial_objective: first,
                final_objective: last,
                min_objective: min,
                converges: i64::from(!js.is_empty() && self.rule.converges(js)),
                iterations_to_plain_final: reach,
            });
        }
    }

    /// The two runs of the paper's comparison: momentum and plain descent at `plain_eta`.
    fn compared(&self) -> Vec<Descent> {
        vec![
            Descent::Momentum {
                eta: self.momentum_eta,
                alpha: self.momentum_alpha,
            },
            Descent::Plain {
                eta: self.plain_eta,
            },
        ]
    }

    /// Learns with `d` through the problem's net for `iterations` and replays the learned
    /// controls on `sim`.
    fn descend(
        &self,
        ctx: &RunContext,
        p: &mut Problem<'_>,
        d: &Descent,
        sim: &mut dyn Dynamics,
        x0: &[f64],
        label: &str,
    ) -> (Learned, Replay) {
        self.descend_until(
            ctx,
            p,
            d,
            sim,
            x0,
            label,
            self.task.iterations,
            &mut |_, _| false,
        )
    }

    /// [`Self::descend`] for at most `iterations`, ended early by `stop` ([`learn_until`]).
    #[allow(clippy::too_many_arguments)]
    fn descend_until(
        &self,
        ctx: &RunContext,
        p: &mut Problem<'_>,
        d: &Descent,
        sim: &mut dyn Dynamics,
        x0: &[f64],
        label: &str,
        iterations: usize,
        stop: &mut dyn FnMut(&IterationTrace, &[f64]) -> bool,
    ) -> (Learned, Replay) {
        let r: Learned = ctx.stage(&format!("{label}{} eta {}", method(d), d.eta()), || {
            learn_until(&mut p.bptt, &p.v0, *d, p.scale, iterations, stop)
        });
        let emu_final = &r.states[self.task.horizon * NetModel::Lander.state_dim()..];
        let rep = replay(
            sim,
            x0,
            &r.controls,
            self.net.physical_dt,
            self.steps,
            emu_final,
        );
        (r, rep)
    }

    /// The `runs` columns from `scale` to `final_gap` of one descent and its replay.
    fn scores(&self, scale: f64, r: &Learned, rep: &Replay) -> Scores {
        let n = NetModel::Lander.state_dim();
        let emu_final = &r.states[self.task.horizon * n..];
        let sim_final = &rep.states[self.task.horizon * n..];
        let objs: Vec<f64> = r.trace.iter().map(|t| t.objective).collect();
        Scores {
            scale,
            initial_objective: objs[0],
            final_objective: r.final_objective(),
            min_objective: objs.iter().copied().fold(f64::INFINITY, f64::min),
            emulator_landing_error: distance(&emu_final[..3], &self.task.target[..3]),
            simulator_landing_error: distance(&sim_final[..3], &self.task.target[..3]),
            emulator_final_speed: distance(&emu_final[VEL..VEL + 3], &[0.0; 3]),
            simulator_final_speed: distance(&sim_final[VEL..VEL + 3], &[0.0; 3]),
            final_gap: rep.final_gap,
        }
    }

    /// `converged.csv` rows of the compared descents through problem `p` (net `net` of
    /// round `round`), when `[params.converged]` is set.
    #[allow(clippy::too_many_arguments)]
    fn converged_rows(
        &self,
        ctx: &RunContext,
        p: &mut Problem<'_>,
        sim: &mut dyn Dynamics,
        x0: &[f64],
        (net, round): (&str, i64),
        table: &mut Vec<ConvergedRow>,
    ) {
        let (Some(c), Some(dn)) = (&self.converged, &self.dagger) else {
            return;
        };
        for d in &self.compared() {
            let mut rule = c.rule();
            let mut converged = false;
            let mut stop = |t: &IterationTrace, v: &[f64]| {
                converged = rule(t, v);
                converged
            };
            let label = format!("{net} net to convergence: ");
            let (r, rep) =
                self.descend_until(ctx, p, d, sim, x0, &label, c.max_iterations, &mut stop);
            let scores = self.scores(p.scale, &r, &rep);
            let row = self.dagger_row((net, round), d, &scores, (&r, &rep), dn);
            let iterations = r.trace.last().map_or(0, |t| t.iteration) as i64;
            table.push(ConvergedRow::new(row, iterations, converged));
        }
    }

    /// A `dagger.csv` row: the net and its round, the descent, its scores and the final errors
    /// of its run `r` and replay `rep`.
    fn dagger_row(
        &self,
        at: (&str, i64),
        d: &Descent,
        scores: &Scores,
        (r, rep): (&Learned, &Replay),
        dn: &DaggerNet,
    ) -> DaggerRow {
        let n = NetModel::Lander.state_dim();
        let task = self.dagger_task(dn);
        let errors = (
            task.final_error(&r.states[self.task.horizon * n..]),
            task.final_error(&rep.states[self.task.horizon * n..]),
        );
        DaggerRow::new(at, d, scores, errors)
    }
}
