//! The job of `x_lbc_emulator`: the two components learned by BPTT through the emulator with
//! their trackers, and every method run per desired target on the emulator and the simulator.

use super::{Method, Params};
use crate::bellman::combine::{normalized_entropy, BlendMode, CombineError, TrackerBlend};
use crate::bellman::projection::{project, GaussianReward};
use crate::control::bptt::{learn_with, Bptt, Descent, Knots, Schedule};
use crate::control::step_tracker::StepTracker;
use crate::control::tracker::ValueTracker;
use crate::emulator::Emulator;
use crate::experiment::output::{Cell, Table, Tables};
use crate::experiment::rows::{table_of, TableRow};
use crate::experiment::{other, Error, Job, RunContext};
use crate::families::lbc::{alpha_deviation, push_entropy, rule_table, ENTROPY_COLUMNS};
use crate::families::na::table1_structure::{build_emulator, build_spec};
use crate::physics::DifferentiableStep;
use nalgebra::DVector;
use std::time::Instant;

/// A learned component: its tape (normalized controls) and emulated states, and its tracker.
struct Component {
    tape: Vec<DVector<f64>>,
    tracker: StepTracker,
    learn_seconds: f64,
    tracker_seconds: f64,
    iterations: usize,
    objective: f64,
    emulator_final: Vec<f64>,
}

/// Where a policy runs: the emulator (one step per super-step) or the simulator (`steps` RK4
/// steps of δt with the control held).
#[derive(Clone, Copy)]
enum Substrate {
    Emulator,
    Simulator,
}

/// A run's final state, effort ½ Σ |v|² and states per super-step.
struct Outcome {
    states: Vec<Vec<f64>>,
    effort: f64,
}

impl Params {
    /// Learns the tape for `value` by BPTT through `emu` and builds its tracker.
    fn learn(&self, emu: &Emulator, value: f64) -> Result<Component, Error> {
        let task = self.target_task(value);
        let (n, m) = (self.net.model.state_dim(), self.net.model.control_dim());
        let objective = task.objective();
        let knots = Knots {
            steps: self.task.horizon,
            per_actuator: self.task.knots,
            m,
        };
        let x0 = self.start_state();
        let t0 = Instant::now();
        let mut bptt = Bptt::new(emu, &objective, knots, task.bounds(), &x0).map_err(other)?;
        let init = task.initial_knots();
        let v0 = bptt.from_controls(&init);
        let schedule = Schedule {
            descent: Descent::Plain { eta: 1.0 },
            rule: self.step_rule,
            scale: 1.0,
            curvature_iterations: 1,
        };
        let run = learn_with(
            &mut bptt,
            &v0,
            &schedule,
            self.task.iterations,
            &mut |_, _, _| false,
        );
        bptt.rollout(&run.best_knots);
        let learn_seconds = t0.elapsed().as_secs_f64();
        let map = self.control_map(emu);
        let xs: Vec<DVector<f64>> = bptt
            .states()
            .chunks_exact(n)
            .map(DVector::from_column_slice)
            .collect();
        let tape: Vec<DVector<f64>> = bptt
            .controls()
            .chunks_exact(m)
            .map(|u| DVector::from_fn(m, |j, _| (u[j] - map.offset[j]) / map.scale[j]))
            .collect();
        let t1 = Instant::now();
        let tracker = StepTracker::build(&map, &self.cost(value, m), &xs, &tape, self.super_dt())
            .map_err(other)?;
        Ok(Component {
            tracker_seconds: t1.elapsed().as_secs_f64(),
            emulator_final: xs[self.task.horizon].as_slice().to_vec(),
            tape,
            tracker,
            learn_seconds,
            iterations: run.best_iteration,
            objective: run.best_objective(),
        })
    }

    /// Runs `policy` (normalized controls, clamped to |v| ≤ 1) from the start on `substrate`.
    fn execute(
        &self,
        emu: &Emulator,
        substrate: Substrate,
        policy: &mut dyn FnMut(&[f64], usize, &mut [f64]) -> Result<(), Error>,
    ) -> Result<Outcome, Error> {
        let (n, m) = (self.net.model.state_dim(), self.net.model.control_dim());
        let map = self.control_map(emu);
        let mut sim = self.net.model.simulator();
        let mut scratch = DifferentiableStep::scratch(&map);
        let mut x = self.start_state();
        let (mut v, mut u, mut next) = (vec![0.0; m], vec![0.0; m], vec![0.0; n]);
        let mut states = vec![x.clone()];
        let mut effort = 0.0;
        for k in 0..self.task.horizon {
            policy(&x, k, &mut v)?;
            for vj in v.iter_mut() {
                *vj = vj.clamp(-1.0, 1.0);
            }
            effort += 0.5 * v.iter().map(|a| a * a).sum::<f64>();
            match substrate {
                Substrate::Emulator => {
                    DifferentiableStep::step(&map, &x, &v, &mut scratch, &mut next);
                    x.copy_from_slice(&next);
                }
                Substrate::Simulator => {
                    map.to_controls(&v, &mut u);
                    for _ in 0..self.steps {
                        sim.step(&mut x, &u, self.net.physical_dt);
                    }
                }
            }
            if x.iter().any(|a| !a.is_finite()) {
                return Err(other(format!("non-finite state at super-step {k}")));
            }
            states.push(x.clone());
        }
        Ok(Outcome { states, effort })
    }
}

/// A blend of the component trackers as a policy.
///
/// Where LBC's combined reward Σ w_i z_i is not positive (extrapolating weights, one w_i < 0,
/// whose negative term dominates at the state reached) the blend is undefined there: `undefined`
/// is set and the run stops with an error, which the caller records as a failed run.
fn blend_policy<'a>(
    blend: &'a TrackerBlend<'a, StepTracker>,
    alpha_log: &'a mut Vec<(f64, f64)>,
    undefined: &'a std::cell::Cell<bool>,
) -> impl FnMut(&[f64], usize, &mut [f64]) -> Result<(), Error> + 'a {
    let n = blend.trackers.len();
    let m = blend.trackers[0].control_dim();
    let (mut alpha, mut ui) = (vec![0.0; n], vec![0.0; m]);
    move |x, k, v| {
        blend.control(x, k, v, &mut alpha, &mut ui).map_err(|e| {
            if matches!(e, CombineError::NonPositiveReward(_)) {
                undefined.set(true);
            }
            other(format!("super-step {k}: {e}"))
        })?;
        // Entropy is defined for α ≥ 0; extrapolating weights (one w_i < 0) give NaN. Beside
        // it, α's distance from the fixed weights normalized.
        let h = if alpha.iter().all(|&a| a > -1e-12) {
            normalized_entropy(&alpha).max(0.0)
        } else {
            f64::NAN
        };
        alpha_log.push((h, alpha_deviation(&alpha, &blend.weights)));
        Ok(())
    }
}

crate::result_rows! {
    /// One row of `targets.csv`: one method at one desired target.
    pub struct TargetRow {
        /// The desired landing x (m).
        desired_target: f64 = "desired_target",
        /// The method's name ([`Method::name`]).
        method: String = "method",
        /// Final error on the emulator (RMS of (s − s_d)/tolerance; NaN where the blend was
        /// undefined along the run).
        final_error_emulator: f64 = "final_error_emulator",
        /// Final error on the simulator (likewise).
        final_error_simulator: f64 = "final_error_simulator",
        /// ½ Σ_k |v_k|² over the super-steps on the simulator.
        effort: f64 = "effort",
        /// Wall time to obtain the controller for this target (s).
        seconds: f64 = "seconds",
        /// The projected weight of component 1.
        weight1: f64 = "weight1",
        /// The projected weight of component 2.
        weight2: f64 = "weight2",
        /// The simulator's final value along the axis (m).
        final_axis_value: f64 = "final_axis_value",
        /// Mean normalized entropy of α over the super-steps on the simulator (NaN without a
        /// blend).
        mean_entropy: f64 = "mean_entropy",
    }
}

crate::result_rows! {
    /// One row of `net_seeds.csv`: a [`TargetRow`] of the comparison through one net seed's
    /// lander net.
    pub struct NetSeedRow {
        /// The seed of the net the comparison ran through.
        net_seed: i64 = "net_seed",
        /// As [`TargetRow::desired_target`].
        desired_target: f64 = "desired_target",
        /// As [`TargetRow::method`].
        method: String = "method",
        /// As [`TargetRow::final_error_emulator`].
        final_error_emulator: f64 = "final_error_emulator",
        /// As [`TargetRow::final_error_simulator`].
        final_error_simulator: f64 = "final_error_simulator",
        /// As [`TargetRow::effort`].
        effort: f64 = "effort",
        /// As [`TargetRow::seconds`].
        seconds: f64 = "seconds",
        /// As [`TargetRow::weight1`].
        weight1: f64 = "weight1",
        /// As [`TargetRow::weight2`].
        weight2: f64 = "weight2",
        /// As [`TargetRow::final_axis_value`].
        final_axis_value: f64 = "final_axis_value",
        /// As [`TargetRow::mean_entropy`].
        mean_entropy: f64 = "mean_entropy",
    }
}

impl NetSeedRow {
    /// `row` of the comparison through net seed `seed`.
    fn of(seed: u64, row: TargetRow) -> Self {
        Self {
            net_seed: seed as i64,
            desired_target: row.desired_target,
            method: row.method,
            final_error_emulator: row.final_error_emulator,
            final_error_simulator: row.final_error_simulator,
            effort: row.effort,
            seconds: row.seconds,
            weight1: row.weight1,
            weight2: row.weight2,
            final_axis_value: row.final_axis_value,
            mean_entropy: row.mean_entropy,
        }
    }
}

crate::result_rows! {
    /// One row of `components.csv`: one learned component.
    pub struct ComponentRow {
        /// The component's number (`1`, `2`).
        component: String = "component",
        /// Its target along the axis (m).
        target: f64 = "target",
        /// BPTT's learning time (s).
        learn_seconds: f64 = "learn_seconds",
        /// The tracker's build time (s).
        tracker_seconds: f64 = "tracker_seconds",
        /// The iteration of BPTT's best.
        iterations: i64 = "iterations",
        /// BPTT's best objective.
        objective: f64 = "objective",
        /// Final error of the learned tape on the emulator.
        emulator_error: f64 = "emulator_error",
        /// Final error of the tape replayed on the simulator.
        open_loop_simulator_error: f64 = "open_loop_simulator_error",
        /// Final error of its tracker in closed loop on the simulator.
        tracked_simulator_error: f64 = "tracked_simulator_error",
    }
}

crate::result_rows! {
    /// The leading columns of a row of `trajectory.csv`: one method's state at one
    /// super-step on the simulator; the state follows in one column per state variable, named
    /// as `describe` names them ([`states_of`]).
    pub struct TrajectoryRow {
        /// The desired landing x (m).
        desired_target: f64 = "desired_target",
        /// The method ([`Method::name`]).
        method: String = "method",
        /// The super-step.
        step: i64 = "step",
        /// Its time (s).
        t_s: f64 = "t",
    }
}

crate::result_rows! {
    /// The leading column of a row of `goal.csv`: one desired target's goal state, which
    /// follows as in `trajectory.csv`.
    pub struct GoalRow {
        /// The desired landing x (m).
        desired_target: f64 = "desired_target",
    }
}

/// A table of rows `R`, each followed by a state in one column per name of `names`.
fn with_states<R: TableRow>(names: &[String]) -> Table {
    let mut cols: Vec<&str> = R::COLUMNS.to_vec();
    cols.extend(names.iter().map(String::as_str));
    Table::new(&cols)
}

/// `row`'s cells followed by the state `x`, a row of a [`with_states`] table.
fn cells_with_state<R: TableRow>(row: &R, x: &[f64]) -> Vec<Cell> {
    let mut cells = row.cells();
    cells.extend(x.iter().map(|&v| Cell::F(v)));
    cells
}

/// The states of a [`with_states`] table's rows, their variables named `names`.
pub(super) fn states_of(t: &Table, names: &[String]) -> Vec<Vec<f64>> {
    let columns: Vec<Vec<f64>> = names.iter().map(|c| t.f64s(c)).collect();
    (0..t.len())
        .map(|r| columns.iter().map(|c| c[r]).collect())
        .collect()
}

/// The tables one net's comparison writes.
struct Outputs {
    components: Vec<ComponentRow>,
    targets: Vec<TargetRow>,
    trajectory: Table,
    goal: Table,
    entropy: Table,
}

impl Outputs {
    fn new(params: &Params) -> Self {
        // The state variables by their `describe` names.
        let names = params.net.model.state_names();
        Self {
            components: Vec::new(),
            targets: Vec::new(),
            trajectory: with_states::<TrajectoryRow>(&names),
            goal: with_states::<GoalRow>(&names),
            entropy: Table::new(&ENTROPY_COLUMNS),
        }
    }
}

impl Params {
    /// The lander net of `seed` (from the cache, or trained).
    fn net(&self, seed: u64) -> Result<crate::emulator::catalog::Trained, Error> {
        build_emulator(&build_spec(
            seed,
            &self.net,
            self.steps,
            self.example_scale,
            &self.training,
        ))
    }

    /// The components learned through `emu`, their trackers, and every method at every desired
    /// target on the emulator and the simulator, into `out`.
    fn compare(&self, emu: &Emulator, comps: &[Component], out: &mut Outputs) -> Result<(), Error> {
        let trackers: Vec<StepTracker> = comps.iter().map(|c| c.tracker.clone()).collect();
        let lambda = self.lambda();
        let q = self.terminal_weight(self.axis) / lambda;
        let dt = self.super_dt();
        self.component_rows(emu, comps, out)?;
        for &d in &self.desired {
            let task = self.target_task(d);
            let goal = GoalRow { desired_target: d };
            out.goal.push(cells_with_state(&goal, &task.task.target));
            let t0 = Instant::now();
            let w = self.projected_weights(d, q)?;
            let projection_seconds = t0.elapsed().as_secs_f64();
            let fresh = self.learn(emu, d)?;
            let limits = None;
            for method in Method::ALL {
                let blend = |mode| TrackerBlend {
                    trackers: &trackers,
                    weights: w.clone(),
                    lambda,
                    mode,
                    limits,
                };
                let own = [fresh.tracker.clone()];
                let (blend, seconds) = match method {
                    Method::Lbc => (Some(blend(BlendMode::Lbc)), projection_seconds),
                    Method::Naive => (Some(blend(BlendMode::Naive)), projection_seconds),
                    Method::Tracker1 => (Some(blend(BlendMode::Single(0))), 0.0),
                    Method::Tracker2 => (Some(blend(BlendMode::Single(1))), 0.0),
                    Method::BpttTracked => (
                        Some(TrackerBlend {
                            trackers: &own,
                            weights: vec![1.0],
                            lambda,
                            mode: BlendMode::Single(0),
                            limits,
                        }),
                        fresh.learn_seconds + fresh.tracker_seconds,
                    ),
                    Method::Bptt => (None, fresh.learn_seconds),
                    Method::OpenLoop1 | Method::OpenLoop2 => (None, 0.0),
                };
                let tape = match method {
                    Method::OpenLoop1 => &comps[0].tape,
                    Method::OpenLoop2 => &comps[1].tape,
                    // The blends run their trackers; `bptt` replays the fresh tape.
                    Method::Lbc
                    | Method::Naive
                    | Method::Tracker1
                    | Method::Tracker2
                    | Method::Bptt
                    | Method::BpttTracked => &fresh.tape,
                };
                let mut entropy = Vec::new();
                let undefined = std::cell::Cell::new(false);
                let mut run = |substrate| -> Result<Outcome, Error> {
                    match &blend {
                        Some(b) => {
                            let mut log = Vec::new();
                            let r = self.execute(
                                emu,
                                substrate,
                                &mut blend_policy(b, &mut log, &undefined),
                            );
                            if matches!(substrate, Substrate::Simulator) {
                                entropy = log;
                            }
                            r
                        }
                        None => self.execute(emu, substrate, &mut |_, k, v| {
                            v.copy_from_slice(tape[k].as_slice());
                            Ok(())
                        }),
                    }
                };
                // A blend undefined along a run (above) is a failed run on that substrate:
                // its row has NaN final errors, effort and axis value.
                let mut outcome = |substrate| match run(substrate) {
                    Ok(o) => Ok(Some(o)),
                    Err(_) if undefined.replace(false) => Ok(None),
                    Err(e) => Err(e),
                };
                let on_emu = outcome(Substrate::Emulator)?;
                let on_sim = outcome(Substrate::Simulator)?;
                let (Some(on_emu), Some(on_sim)) = (&on_emu, on_sim) else {
                    let emu_error = on_emu
                        .as_ref()
                        .map_or(f64::NAN, |o| task.final_error(&o.states[self.task.horizon]));
                    out.targets.push(TargetRow {
                        desired_target: d,
                        method: method.name().to_string(),
                        final_error_emulator: emu_error,
                        final_error_simulator: f64::NAN,
                        effort: f64::NAN,
                        seconds,
                        weight1: w[0],
                        weight2: w[1],
                        final_axis_value: f64::NAN,
                        mean_entropy: f64::NAN,
                    });
                    continue;
                };
                let end = &on_sim.states[self.task.horizon];
                let mean_entropy = if entropy.is_empty() {
                    f64::NAN
                } else {
                    entropy.iter().map(|e| e.0).sum::<f64>() / entropy.len() as f64
                };
                if matches!(method, Method::Lbc | Method::Naive) {
                    let (h, dev): (Vec<f64>, Vec<f64>) = entropy.iter().copied().unzip();
                    let run = format!("desired {d} m");
                    push_entropy(&mut out.entropy, &run, method.name(), dt, &h, &dev);
                }
                out.targets.push(TargetRow {
                    desired_target: d,
                    method: method.name().to_string(),
                    final_error_emulator: task.final_error(&on_emu.states[self.task.horizon]),
                    final_error_simulator: task.final_error(end),
                    effort: on_sim.effort,
                    seconds,
                    weight1: w[0],
                    weight2: w[1],
                    final_axis_value: end[self.axis],
                    mean_entropy,
                });
                for (k, s) in on_sim.states.iter().enumerate() {
                    let row = TrajectoryRow {
                        desired_target: d,
                        method: method.name().to_string(),
                        step: k as i64,
                        t_s: k as f64 * dt,
                    };
                    out.trajectory.push(cells_with_state(&row, s));
                }
            }
        }
        Ok(())
    }

    /// Per component: its learning, and the final errors on the emulator, open loop and
    /// tracked on the simulator.
    fn component_rows(
        &self,
        emu: &Emulator,
        comps: &[Component],
        out: &mut Outputs,
    ) -> Result<(), Error> {
        for (i, (c, &value)) in comps.iter().zip(&self.components).enumerate() {
            let task = self.target_task(value);
            let open = self.execute(emu, Substrate::Simulator, &mut |_, k, v| {
                v.copy_from_slice(c.tape[k].as_slice());
                Ok(())
            })?;
            let tracked = self.execute(emu, Substrate::Simulator, &mut |x, k, v| {
                c.tracker.policy_into(x, k, v);
                Ok(())
            })?;
            out.components.push(ComponentRow {
                component: format!("{}", i + 1),
                target: value,
                learn_seconds: c.learn_seconds,
                tracker_seconds: c.tracker_seconds,
                iterations: c.iterations as i64,
                objective: c.objective,
                emulator_error: task.final_error(&c.emulator_final),
                open_loop_simulator_error: task.final_error(&open.states[self.task.horizon]),
                tracked_simulator_error: task.final_error(&tracked.states[self.task.horizon]),
            });
        }
        Ok(())
    }

    /// The components' weights projected for desired value `d` (reward precision `q`),
    /// projection round-off set to zero.
    fn projected_weights(&self, d: f64, q: f64) -> Result<Vec<f64>, Error> {
        let comp_rewards: Vec<GaussianReward> = self
            .components
            .iter()
            .map(|&c| GaussianReward::isotropic(&[c], q))
            .collect();
        let mut w = project(&comp_rewards, &GaussianReward::isotropic(&[d], q))
            .map_err(other)?
            .weights;
        // Projection round-off: at a component's own target the other weight comes out
        // as ±1e-16, and a negative one makes Σ w_i z_i ≤ 0 wherever that component's
        // z dominates. A weight within 1e-12 of the largest's magnitude is zero.
        let largest = w.iter().fold(0.0f64, |a, b| a.max(b.abs()));
        for wi in &mut w {
            if wi.abs() <= 1e-12 * largest {
                *wi = 0.0;
            }
        }
        Ok(w)
    }

    /// The components learned through `emu`.
    fn learn_components(&self, emu: &Emulator) -> Result<Vec<Component>, Error> {
        self.components
            .iter()
            .map(|&c| self.learn(emu, c))
            .collect()
    }
}

impl Job for Params {
    fn params_json(&self) -> serde_json::Value {
        serde_json::to_value(self).unwrap_or_default()
    }

    fn run(&self, ctx: &RunContext) -> Result<Tables, Error> {
        let model = self.net.model;
        let trained = ctx.stage(&format!("train {} N{}", model.name(), self.steps), || {
            self.net(ctx.seed)
        })?;
        let emu = &trained.emulator;
        let comps = ctx.stage("learn components", || self.learn_components(emu))?;
        let mut out = Outputs::new(self);
        ctx.stage("compare", || self.compare(emu, &comps, &mut out))?;
        // The same comparison through the lander net of each further seed: `net_seeds.csv` is
        // every seed's `targets.csv` rows, the run's own first, under its `net_seed`.
        let own = std::iter::once((ctx.seed, out.targets.clone()));
        let further = ctx.stage("net seeds", || {
            crate::experiment::seeds::further_seeds(&self.net_seeds, ctx.seed)
                .into_iter()
                .map(|s| -> Result<(u64, Vec<TargetRow>), Error> {
                    let net = self.net(s)?;
                    let comps = self.learn_components(&net.emulator)?;
                    let mut o = Outputs::new(self);
                    self.compare(&net.emulator, &comps, &mut o)?;
                    Ok((s, o.targets))
                })
                .collect::<Result<Vec<_>, Error>>()
        })?;
        let seed_rows: Vec<NetSeedRow> = own
            .chain(further)
            .flat_map(|(s, rows)| rows.into_iter().map(move |r| NetSeedRow::of(s, r)))
            .collect();
        let lambda = self.lambda();
        let q = self.terminal_weight(self.axis) / lambda;
        let spacing = self.components[1] - self.components[0];
        let rule = rule_table(&[
            ("lambda", lambda),
            ("control_noise", self.control_noise),
            ("q_spacing2", q * spacing * spacing),
            ("component1", self.components[0]),
            ("component2", self.components[1]),
            ("within_fraction", self.within_fraction),
            ("naive_margin", self.naive_margin),
            ("axis_margin", self.axis_margin),
            ("super_step_s", self.super_dt()),
        ]);
        Ok(Tables::from([
            ("targets", table_of(&out.targets)),
            ("components", table_of(&out.components)),
            ("trajectory", out.trajectory),
            ("goal", out.goal),
            ("entropy", out.entropy),
            ("net_seeds", table_of(&seed_rows)),
            ("rule", rule),
        ]))
    }
}
