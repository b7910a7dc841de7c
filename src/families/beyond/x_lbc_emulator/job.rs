//! The job of `x_lbc_emulator`: the two components learned by BPTT through the emulator with
//! their trackers, and every method run per desired target on the emulator and the simulator.

use super::{Params, METHODS};
use crate::bellman::combine::{normalized_entropy, BlendMode, CombineError, TrackerBlend};
use crate::bellman::projection::{project, GaussianReward};
use crate::control::bptt::{learn_with, Bptt, Descent, Knots, Schedule};
use crate::control::step_tracker::StepTracker;
use crate::control::tracker::ValueTracker;
use crate::emulator::Emulator;
use crate::experiment::output::{Table, Tables};
use crate::experiment::{other, Error, Job, RunContext};
use crate::families::lbc::{alpha_deviation, push_entropy, rule_table, ENTROPY_COLUMNS};
use crate::families::na::table1_structure::{build_emulator, build_spec};
use crate::physics::DifferentiableStep;
use crate::row;
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

/// The tables one net's comparison writes.
struct Outputs {
    components: Table,
    targets: Table,
    trajectory: Table,
    goal: Table,
    entropy: Table,
}

/// Columns of `targets.csv` (and, after `net_seed`, of `net_seeds.csv`).
const TARGET_COLUMNS: [&str; 10] = [
    "desired_target",
    "method",
    "final_error_emulator",
    "final_error_simulator",
    "effort",
    "seconds",
    "weight1",
    "weight2",
    "final_axis_value",
    "mean_entropy",
];

impl Outputs {
    fn new(params: &Params) -> Self {
        let model = params.net.model;
        let mut cols: Vec<String> = ["desired_target", "method", "step", "t"]
            .iter()
            .map(|s| s.to_string())
            .collect();
        // The state variables by their `describe` names.
        cols.extend(model.state_names());
        debug_assert_eq!(cols.len(), 4 + model.state_dim());
        let col_refs: Vec<&str> = cols.iter().map(String::as_str).collect();
        let mut goal_cols = vec!["desired_target"];
        goal_cols.extend_from_slice(&col_refs[4..]);
        Self {
            components: Table::new(&[
                "component",
                "target",
                "learn_seconds",
                "tracker_seconds",
                "iterations",
                "objective",
                "emulator_error",
                "open_loop_simulator_error",
                "tracked_simulator_error",
            ]),
            targets: Table::new(&TARGET_COLUMNS),
            trajectory: Table::new(&col_refs),
            goal: Table::new(&goal_cols),
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
            let mut r = row![d];
            r.extend(task.task.target.iter().map(|&v| v.into()));
            out.goal.push(r);
            let t0 = Instant::now();
            let w = self.projected_weights(d, q)?;
            let projection_seconds = t0.elapsed().as_secs_f64();
            let fresh = self.learn(emu, d)?;
            let limits = None;
            for method in METHODS {
                let blend = |mode| TrackerBlend {
                    trackers: &trackers,
                    weights: w.clone(),
                    lambda,
                    mode,
                    limits,
                };
                let own = [fresh.tracker.clone()];
                let (blend, seconds) = match method {
                    "lbc" => (Some(blend(BlendMode::Lbc)), projection_seconds),
                    "naive" => (Some(blend(BlendMode::Naive)), projection_seconds),
                    "tracker1" => (Some(blend(BlendMode::Single(0))), 0.0),
                    "tracker2" => (Some(blend(BlendMode::Single(1))), 0.0),
                    "bptt_tracked" => (
                        Some(TrackerBlend {
                            trackers: &own,
                            weights: vec![1.0],
                            lambda,
                            mode: BlendMode::Single(0),
                            limits,
                        }),
                        fresh.learn_seconds + fresh.tracker_seconds,
                    ),
                    "bptt" => (None, fresh.learn_seconds),
                    _ => (None, 0.0),
                };
                let tape = match method {
                    "open_loop1" => &comps[0].tape,
                    "open_loop2" => &comps[1].tape,
                    _ => &fresh.tape,
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
                    out.targets.push(row![
                        d,
                        method,
                        emu_error,
                        f64::NAN,
                        f64::NAN,
                        seconds,
                        w[0],
                        w[1],
                        f64::NAN,
                        f64::NAN
                    ]);
                    continue;
                };
                let end = &on_sim.states[self.task.horizon];
                let mean_entropy = if entropy.is_empty() {
                    f64::NAN
                } else {
                    entropy.iter().map(|e| e.0).sum::<f64>() / entropy.len() as f64
                };
                if matches!(method, "lbc" | "naive") {
                    let (h, dev): (Vec<f64>, Vec<f64>) = entropy.iter().copied().unzip();
                    let run = format!("desired {d} m");
                    push_entropy(&mut out.entropy, &run, method, dt, &h, &dev);
                }
                out.targets.push(row![
                    d,
                    method,
                    task.final_error(&on_emu.states[self.task.horizon]),
                    task.final_error(end),
                    on_sim.effort,
                    seconds,
                    w[0],
                    w[1],
                    end[self.axis],
                    mean_entropy
                ]);
                for (k, s) in on_sim.states.iter().enumerate() {
                    let mut r = row![d, method, k as i64, k as f64 * dt];
                    r.extend(s.iter().map(|&v| v.into()));
                    out.trajectory.push(r);
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
            out.components.push(row![
                format!("{}", i + 1),
                value,
                c.learn_seconds,
                c.tracker_seconds,
                c.iterations as i64,
                c.objective,
                task.final_error(&c.emulator_final),
                task.final_error(&open.states[self.task.horizon]),
                task.final_error(&tracked.states[self.task.horizon])
            ]);
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
        let mut seeds_t = Table::new(&[]);
        let own = std::iter::once((ctx.seed, out.targets.clone()));
        let further = ctx.stage("net seeds", || {
            crate::experiment::seeds::further_seeds(&self.net_seeds, ctx.seed)
                .into_iter()
                .map(|s| -> Result<(u64, Table), Error> {
                    let net = self.net(s)?;
                    let comps = self.learn_components(&net.emulator)?;
                    let mut o = Outputs::new(self);
                    self.compare(&net.emulator, &comps, &mut o)?;
                    Ok((s, o.targets))
                })
                .collect::<Result<Vec<_>, Error>>()
        })?;
        for (s, t) in own.chain(further) {
            let t = t.with_prefix(&[("net_seed".to_string(), (s as i64).into())]);
            if seeds_t.names().is_empty() {
                seeds_t = t;
            } else {
                seeds_t.append(&t).map_err(other)?;
            }
        }
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
            ("targets", out.targets),
            ("components", out.components),
            ("trajectory", out.trajectory),
            ("goal", out.goal),
            ("entropy", out.entropy),
            ("net_seeds", seeds_t),
            ("rule", rule),
        ]))
    }
}
