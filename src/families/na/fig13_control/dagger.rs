//! The DAgger stage of `na_fig13_control` (ours, issue 11; [`crate::emulator::dagger`]): per
//! task with a catalog net, R rounds of (learn controls through the current net with the
//! learner, replay them on the simulator, aggregate the visited states' examples, fine-tune
//! the net from the previous round's weights). One `dagger.csv` row per task and round: the
//! learned controls' final error on the net and on the simulator, iterations to the goal, the
//! examples the net was trained on, and its drift from the task start under the neutral
//! control beside the simulator's. Round r's net is cached under the base net's key plus the
//! task, the learner, the DAgger settings and r, so reruns are warm.

use super::{learn_best, Params, Task};
use crate::control::bptt::{replay, Bptt, Knots, StepRule};
use crate::emulator::cache::EmulatorCache;
use crate::emulator::catalog::{
    rollout_windows, stop_name, training_data, BuildSpec, Trained, TrainingData,
};
use crate::emulator::dagger::{
    aggregate, collect, fine_tune_aggregated, DaggerSettings, Plan, Visits,
};
use crate::emulator::dataset::Windows;
use crate::emulator::train::mse;
use crate::emulator::Emulator;
use crate::experiment::output::Table;
use crate::experiment::resolve::ParamError;
use crate::experiment::{other, Error};
use crate::families::na::table1_structure::position_part;
use crate::row;
use crate::seed::mix_seed;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

/// `[params.dagger]`: the learner and the aggregation settings.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DaggerControl {
    /// The learner's step rule (Levenberg–Marquardt: momentum stalls even on the physics).
    pub learner: StepRule,
    /// Rounds, perturbations, fine-tuning budget.
    pub settings: DaggerSettings,
}

impl DaggerControl {
    /// Checks the settings.
    pub fn validate(&self, p: &Params) -> Result<(), ParamError> {
        self.learner.validate("dagger.learner")?;
        self.settings.validate("dagger.settings")?;
        crate::experiment::resolve::ensure(
            p.training.rollout_k >= 1,
            "dagger",
            "needs training.rollout_k >= 1 (the fine-tuning's k-step rollout loss)",
        )
    }
}

/// Columns of `dagger.csv`.
pub const COLUMNS: [&str; 15] = [
    "task",
    "round",
    "optimizer",
    "final_error_emulator",
    "final_error_simulator",
    "iterations",
    "iterations_to_goal",
    "best_iteration",
    "examples",
    "dagger_examples",
    "dagger_windows",
    "fine_tune_iterations",
    "drift_emulator",
    "drift_simulator",
    "drift_gap",
];

/// The cache tag of `task`'s DAgger nets.
fn tag(task: &Task) -> String {
    format!("dagger-{}", task.name)
}

/// Everything besides the base net that determines round `round`'s net.
pub fn derived_key(
    task: &Task,
    d: &DaggerControl,
    curvature_iterations: usize,
    round: usize,
) -> serde_json::Value {
    serde_json::json!({
        "task": task,
        "learner": d.learner,
        "settings": d.settings,
        "curvature_iterations": curvature_iterations,
        "round": round,
    })
}

/// One round's learned controls, scored.
struct Round {
    controls: Vec<f64>,
    emulator_error: f64,
    simulator_error: f64,
    iterations: usize,
    to_goal: Option<usize>,
    best_iteration: usize,
}

impl Params {
    /// Learns `task` through `net` with the learner from the rest control; scores the best
    /// iterate on the net and replayed on the simulator.
    fn dagger_learn(
        &self,
        task: &Task,
        d: &DaggerControl,
        net: &Emulator,
        x0: &[f64],
    ) -> Result<Round, Error> {
        let model = task.net.model;
        let (n, m) = (model.state_dim(), model.control_dim());
        let objective = task.objective();
        let knots = Knots {
            steps: task.horizon,
            per_actuator: task.knots,
            m,
        };
        let mut bptt = Bptt::new(net, &objective, knots, task.bounds(), x0).map_err(other)?;
        let rest = task.rest_control();
        let init: Vec<f64> = (0..knots.len()).map(|i| rest[i % m]).collect();
        let v0 = bptt.from_controls(&init);
        let lambda = bptt.curvature(&v0, self.curvature_iterations);
        let schedule = self.schedule(task.eta, task.alpha, d.learner, lambda);
        let mut to_goal = None;
        let (run, best) = learn_best(&mut bptt, &v0, &schedule, task.iterations, &mut |e, _, st| {
            if to_goal.is_none() && task.final_error(&st[task.horizon * n..]) <= 1.0 {
                to_goal = Some(e.iteration);
            }
            false
        });
        let emu_final = &best.states[task.horizon * n..];
        let mut sim = model.simulator();
        let rep = replay(
            sim.as_mut(),
            x0,
            &best.controls,
            task.net.physical_dt,
            self.steps,
            emu_final,
        );
        Ok(Round {
            emulator_error: task.final_error(emu_final),
            simulator_error: task.final_error(&rep.states[task.horizon * n..]),
            iterations: run.trace.last().map_or(0, |t| t.iteration),
            to_goal,
            best_iteration: run.best_iteration,
            controls: best.controls,
        })
    }

    /// The DAgger rounds of `task` from its base net `base` (built from `spec`), one row each
    /// into `table`.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn run_dagger(
        &self,
        ctx: &crate::experiment::RunContext,
        d: &DaggerControl,
        task: &Task,
        spec: &BuildSpec,
        base: &Trained,
        x0: &[f64],
        table: &mut Table,
    ) -> Result<(), Error> {
        let model = task.net.model;
        let (n, m) = (model.state_dim(), model.control_dim());
        let k = self.training.rollout_k;
        let cache = EmulatorCache::from_env();
        let settings = spec.effective_settings();
        let limits = model.control_limits();
        let neutral = task.rest_control();
        let mut sim = model.simulator();
        let mut net = base.emulator.clone();
        let mut fine_tune_iterations = 0usize;
        let (mut train, mut held) = (Visits::empty(n, m, k), Visits::empty(n, m, k));
        let mut base_data: Option<(TrainingData, Windows)> = None;
        let stream = mix_seed(spec.seed, crate::emulator::cache::fnv1a(tag(task).as_bytes()));
        for round in 0..=d.settings.rounds {
            let r = ctx.stage(&format!("dagger {} round {round}: learn", task.name), || {
                self.dagger_learn(task, d, &net, x0)
            })?;
            // Drift under the neutral control from the start: emulator vs simulator.
            let plan = Plan {
                x0,
                controls: &r.controls,
                neutral: &neutral,
                limits: &limits,
                physical_dt: task.net.physical_dt,
                substeps: self.steps,
            };
            let held_u: Vec<f64> = (0..task.horizon)
                .flat_map(|_| neutral.iter().copied())
                .collect();
            let sim_drift = plan.rollout(sim.as_mut(), &held_u).map_err(other)?;
            let (mut xe, mut next, mut sc) = (x0.to_vec(), vec![0.0; n], net.scratch());
            for _ in 0..task.horizon {
                net.predict(&xe, &neutral, &mut sc, &mut next);
                xe.copy_from_slice(&next);
            }
            let xs = &sim_drift[task.horizon * n..];
            let p = position_part(model);
            let dist = |a: &[f64], b: &[f64]| {
                p.clone()
                    .map(|i| (a[i] - b[i]).powi(2))
                    .sum::<f64>()
                    .sqrt()
            };
            table.push(row![
                task.name.as_str(),
                round as i64,
                d.learner.name(),
                r.emulator_error,
                r.simulator_error,
                r.iterations as i64,
                r.to_goal.map_or(f64::NAN, |i| i as f64),
                r.best_iteration as i64,
                (spec.net.examples + train.len()) as i64,
                train.len() as i64,
                train.windows.len() as i64,
                fine_tune_iterations as i64,
                dist(&xe, x0),
                dist(xs, x0),
                dist(&xe, xs)
            ]);
            if round == d.settings.rounds {
                break;
            }
            // Aggregate the states these controls visit, then fine-tune the next net.
            let mut rng = ChaCha8Rng::seed_from_u64(mix_seed(stream, 2 * round as u64));
            let (t, h) =
                collect(sim.as_mut(), &plan, &d.settings, k, round == 0, &mut rng).map_err(other)?;
            train.extend(&t);
            held.extend(&h);
            let key = derived_key(task, d, self.curvature_iterations, round + 1);
            let next = match cache.load_derived(spec, &tag(task), &key) {
                Some(t) => t,
                None => {
                    let t0 = std::time::Instant::now();
                    if base_data.is_none() {
                        let data = ctx.stage(&format!("dagger {}: base data", task.name), || {
                            training_data(spec)
                        });
                        base_data = Some((data.map_err(other)?, rollout_windows(spec).map_err(other)?.0));
                    }
                    let (data, windows) = base_data.as_ref().expect("just built");
                    let mut rng = ChaCha8Rng::seed_from_u64(mix_seed(stream, 2 * round as u64 + 1));
                    let agg = aggregate(&net, data, windows, &train, &held, &settings, &mut rng)
                        .map_err(other)?;
                    let mut emulator = net.clone();
                    let report = ctx.stage(
                        &format!("dagger {} round {}: fine-tune", task.name, round + 1),
                        || {
                            fine_tune_aggregated(
                                &mut emulator,
                                &agg,
                                &data.sigma,
                                &settings,
                                d.settings.iters,
                            )
                        },
                    );
                    let report = report.map_err(other)?;
                    let trained = Trained {
                        train_error: mse(emulator.mlp(), &agg.clean),
                        heldout_error: mse(emulator.mlp(), &agg.held),
                        emulator,
                        trace: report.trace,
                        train_s: t0.elapsed().as_secs_f64(),
                        stop: stop_name(&report.stop),
                        from_cache: false,
                        rollout_trace: Vec::new(),
                    };
                    cache
                        .store_derived(spec, &tag(task), &key, &trained)
                        .map_err(other)?;
                    trained
                }
            };
            fine_tune_iterations = next.trace.last().map_or(0, |t| t.iteration);
            net = next.emulator;
        }
        Ok(())
    }
}
