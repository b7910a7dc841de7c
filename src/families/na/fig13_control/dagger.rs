//! The DAgger stage of `na_fig13_control` (ours; [`crate::emulator::dagger`]): per
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
    anchor_of, rollout_windows, stop_name, training_data, BuildSpec, TrainSettings, Trained,
    TrainingData,
};
use crate::emulator::dagger::{
    aggregate, collect, fine_tune_aggregated, DaggerSettings, Plan, Visits,
};
use crate::emulator::dataset::Windows;
use crate::emulator::train::mse;
use crate::emulator::Emulator;
use crate::experiment::resolve::ParamError;
use crate::experiment::{other, Error};
use crate::families::na::table1_structure::position_part;
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
            p.training.rollout_k >= 1 || self.settings.rollout_k >= 1,
            "dagger.settings.rollout_k",
            "needs a k-step rollout loss: dagger.settings.rollout_k >= 1 (or training.rollout_k)",
        )?;
        crate::experiment::resolve::ensure(
            p.training.rollout_weight > 0.0 || self.settings.rollout_weight > 0.0,
            "dagger.settings.rollout_weight",
            "needs a positive weight of the k-step rollout loss",
        )
    }
}

crate::result_rows! {
    /// One task's DAgger round: a row of `dagger.csv` (and of `na_fig14_momentum`'s
    /// `momentum_dagger_rounds.csv`).
    pub struct DaggerRoundRow {
        /// The task.
        task: String = "task",
        /// The round (0: the Table 1 net).
        round: i64 = "round",
        /// The learner's step rule ([`StepRule::name`]).
        optimizer: String = "optimizer",
        /// The learned controls' final error on the round's net (RMS of (s_M − s_d)/σ over
        /// the weighted state variables; ≤ 1: within tolerance).
        final_error_emulator: f64 = "final_error_emulator",
        /// The same replayed on the simulator.
        final_error_simulator: f64 = "final_error_simulator",
        /// The iterations the learner ran (the task's own learner: its budget, the paper's
        /// count).
        iterations: i64 = "iterations",
        /// The first iteration at the goal on the net (NaN: never).
        iterations_to_goal: f64 = "iterations_to_goal",
        /// The iterate scored (the best so far).
        best_iteration: i64 = "best_iteration",
        /// The examples the round's net was trained on, base data included.
        examples: i64 = "examples",
        /// Of these, the examples aggregated from visited states.
        dagger_examples: i64 = "dagger_examples",
        /// The rollout windows aggregated.
        dagger_windows: i64 = "dagger_windows",
        /// The fine-tune's iterations per round.
        fine_tune_iterations: i64 = "fine_tune_iterations",
        /// The net's drift from the start under the neutral control over the horizon (m).
        drift_emulator: f64 = "drift_emulator",
        /// The simulator's (m).
        drift_simulator: f64 = "drift_simulator",
        /// The distance between the two drifted positions (m).
        drift_gap: f64 = "drift_gap",
        /// The range of the simulator's final error over [`SPREAD_REPLAYS`] replays of the
        /// controls perturbed by up to [`SPREAD_FRACTION`] of each channel's half-range.
        simulator_error_spread: f64 = "simulator_error_spread",
    }
}

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

/// Replays behind `simulator_error_spread`.
pub const SPREAD_REPLAYS: usize = 8;
/// Size of the control perturbations behind `simulator_error_spread`, as a fraction of each
/// channel's half-range within the task's bounds.
pub const SPREAD_FRACTION: f64 = 0.01;

/// One round's learned controls, scored.
pub(crate) struct Round {
    /// Per-step controls (M m).
    pub controls: Vec<f64>,
    /// Final error of the task on the net learned through.
    pub emulator_error: f64,
    /// Final error of the controls replayed on the simulator.
    pub simulator_error: f64,
    /// Range (max − min) of the simulator final error over [`SPREAD_REPLAYS`] replays of the
    /// controls each perturbed by uniform noise of up to [`SPREAD_FRACTION`] of its channel's
    /// half-range (clamped to the bounds): how much the open-loop outcome moves under control
    /// changes far smaller than any emulator's error, i.e. how exactly a net would have to
    /// predict the task for its learned controls to transfer.
    pub simulator_spread: f64,
    /// Iterations run.
    pub iterations: usize,
    /// First iteration at the goal on the net, if known and reached.
    pub to_goal: Option<usize>,
    /// The iterate scored.
    pub best_iteration: usize,
}

/// A DAgger learner other than the task's own (Fig. 14's momentum descent on its landing
/// objective): `key` identifies it in the cache keys of the chain's nets, `learn` learns and
/// scores one round through the given net (seeded by the second argument).
pub(crate) struct ChainLearner<'a> {
    /// What identifies the learner (added to the derived nets' keys).
    pub key: serde_json::Value,
    /// One round's learning and scoring through a net.
    pub learn: &'a mut dyn FnMut(&Emulator, u64) -> Result<Round, Error>,
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
        seed: u64,
    ) -> Result<Round, Error> {
        let model = task.net.model;
        let (n, m) = (model.state_dim(), model.control_dim());
        let objective = task.objective();
        let knots = Knots {
            steps: task.task.horizon,
            per_actuator: task.task.knots,
            m,
        };
        let mut bptt = Bptt::new(net, &objective, knots, task.bounds(), x0).map_err(other)?;
        let init = task.initial_knots();
        let v0 = bptt.from_controls(&init);
        let lambda = bptt.curvature(&v0, self.curvature_iterations);
        let schedule = self.schedule(task.eta, task.alpha, d.learner, lambda);
        let mut to_goal = None;
        let (run, best) = learn_best(
            &mut bptt,
            &v0,
            &schedule,
            task.task.iterations,
            &mut |e, _, st| {
                if to_goal.is_none() && task.final_error(&st[task.task.horizon * n..]) <= 1.0 {
                    to_goal = Some(e.iteration);
                }
                false
            },
        );
        let emu_final = &best.states[task.task.horizon * n..];
        let mut sim = model.simulator();
        let rep = replay(
            sim.as_mut(),
            x0,
            &best.controls,
            task.net.physical_dt,
            self.steps,
            emu_final,
        );
        let simulator_spread = self.open_loop_spread(task, x0, &best.controls, emu_final, seed);
        Ok(Round {
            emulator_error: task.final_error(emu_final),
            simulator_error: task.final_error(&rep.states[task.task.horizon * n..]),
            simulator_spread,
            iterations: run.trace.last().map_or(0, |t| t.iteration),
            to_goal,
            best_iteration: run.best_iteration,
            controls: best.controls,
        })
    }

    /// Range of the simulator final error of `task` over [`SPREAD_REPLAYS`] replays of
    /// `controls` from `x0`, each perturbed uniformly by up to [`SPREAD_FRACTION`] of its
    /// channel's half-range within the task's bounds (stream `seed`): see [`Round`].
    pub(crate) fn open_loop_spread(
        &self,
        task: &Task,
        x0: &[f64],
        controls: &[f64],
        emu_final: &[f64],
        seed: u64,
    ) -> f64 {
        let model = task.net.model;
        let (n, m) = (model.state_dim(), model.control_dim());
        let mut sim = model.simulator();
        let bounds = task.bounds();
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
        let mut perturbed = controls.to_vec();
        for _ in 0..SPREAD_REPLAYS {
            for (i, (v, c)) in perturbed.iter_mut().zip(controls).enumerate() {
                let j = i % m;
                let h = 0.5 * (bounds.high[j] - bounds.low[j]);
                let e: f64 = rand::Rng::random_range(&mut rng, -1.0..=1.0);
                *v = (c + SPREAD_FRACTION * h * e).clamp(bounds.low[j], bounds.high[j]);
            }
            let r = replay(
                sim.as_mut(),
                x0,
                &perturbed,
                task.net.physical_dt,
                self.steps,
                emu_final,
            );
            let err = task.final_error(&r.states[task.task.horizon * n..]);
            (lo, hi) = (lo.min(err), hi.max(err));
        }
        hi - lo
    }

    /// The DAgger rounds of `task` from its base net `base` (built from `spec`), one row each
    /// into `table`; returns the last round's net (the one whose row comes last). Every
    /// fine-tuned net is loaded from the cache when there, so a warm call only learns and
    /// replays (`na_fig14_momentum` uses this to get the lander's final-round net).
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn run_dagger(
        &self,
        ctx: &crate::experiment::RunContext,
        d: &DaggerControl,
        task: &Task,
        spec: &BuildSpec,
        base: &Trained,
        x0: &[f64],
        table: &mut Vec<DaggerRoundRow>,
    ) -> Result<Emulator, Error> {
        self.run_dagger_with(ctx, d, task, spec, base, x0, table, None)
    }

    /// [`Params::run_dagger`] with the rounds learned by `chain` instead of the task's own
    /// learner (its key joins the nets' cache keys; `d.learner` is then only part of the key).
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn run_dagger_with(
        &self,
        ctx: &crate::experiment::RunContext,
        d: &DaggerControl,
        task: &Task,
        spec: &BuildSpec,
        base: &Trained,
        x0: &[f64],
        table: &mut Vec<DaggerRoundRow>,
        mut chain: Option<ChainLearner<'_>>,
    ) -> Result<Emulator, Error> {
        let model = task.net.model;
        let (n, m) = (model.state_dim(), model.control_dim());
        // The fine-tuning's k-step loss: DAgger's own where it sets one (the base net trained
        // one step ahead), so its windows are sampled under a spec that carries it.
        let tuned = BuildSpec {
            settings: d.settings.fine_tune_settings(&spec.settings),
            ..spec.clone()
        };
        let spec = &tuned;
        let k = spec.settings.rollout_k;
        let cache = EmulatorCache::from_env();
        let settings = spec.effective_settings();
        let limits = model.control_limits();
        let neutral = task.rest_control();
        let mut sim = model.simulator();
        let mut net = base.emulator.clone();
        let mut fine_tune_iterations = 0usize;
        let (mut train, mut held) = (Visits::empty(n, m, k), Visits::empty(n, m, k));
        let mut base_data: Option<(TrainingData, Windows)> = None;
        let stream = mix_seed(
            spec.seed,
            crate::emulator::cache::fnv1a(tag(task).as_bytes()),
        );
        for round in 0..=d.settings.rounds {
            let seed = mix_seed(stream, 1000 + round as u64);
            let r = ctx.stage(
                &format!("dagger {} round {round}: learn", task.name),
                || match chain.as_mut() {
                    Some(c) => (c.learn)(&net, seed),
                    None => self.dagger_learn(task, d, &net, x0, seed),
                },
            )?;
            // Drift under the neutral control from the start: emulator vs simulator.
            let plan = Plan {
                x0,
                controls: &r.controls,
                neutral: &neutral,
                limits: &limits,
                physical_dt: task.net.physical_dt,
                substeps: self.steps,
            };
            let held_u: Vec<f64> = (0..task.task.horizon)
                .flat_map(|_| neutral.iter().copied())
                .collect();
            let sim_drift = plan.rollout(sim.as_mut(), &held_u).map_err(other)?;
            let (mut xe, mut next, mut sc) = (x0.to_vec(), vec![0.0; n], net.scratch());
            for _ in 0..task.task.horizon {
                net.predict(&xe, &neutral, &mut sc, &mut next);
                xe.copy_from_slice(&next);
            }
            let xs = &sim_drift[task.task.horizon * n..];
            let p = position_part(model);
            let dist =
                |a: &[f64], b: &[f64]| p.clone().map(|i| (a[i] - b[i]).powi(2)).sum::<f64>().sqrt();
            table.push(DaggerRoundRow {
                task: task.name.clone(),
                round: round as i64,
                optimizer: d.learner.name().into(),
                final_error_emulator: r.emulator_error,
                final_error_simulator: r.simulator_error,
                iterations: r.iterations as i64,
                iterations_to_goal: r.to_goal.map_or(f64::NAN, |i| i as f64),
                best_iteration: r.best_iteration as i64,
                examples: (spec.net.examples + train.len()) as i64,
                dagger_examples: train.len() as i64,
                dagger_windows: train.windows.len() as i64,
                fine_tune_iterations: fine_tune_iterations as i64,
                drift_emulator: dist(&xe, x0),
                drift_simulator: dist(xs, x0),
                drift_gap: dist(&xe, xs),
                simulator_error_spread: r.simulator_spread,
            });
            if round == d.settings.rounds {
                break;
            }
            // Aggregate the states these controls visit, then fine-tune the next net.
            let mut rng = ChaCha8Rng::seed_from_u64(mix_seed(stream, 2 * round as u64));
            let (t, h) = collect(sim.as_mut(), &plan, &d.settings, k, round == 0, &mut rng)
                .map_err(other)?;
            train.extend(&t);
            held.extend(&h);
            let mut key = derived_key(task, d, self.curvature_iterations, round + 1);
            if let Some(c) = &chain {
                key["chain_learner"] = c.key.clone();
            }
            let next = match cache.load_derived(spec, &tag(task), &key) {
                Some(t) => t,
                None => {
                    let file = cache.derived_path(spec, &tag(task), &key);
                    let what = format!(
                        "the {} DAgger round {} net ({})",
                        spec.net.model.name(),
                        round + 1,
                        file.file_name()
                            .map_or(String::new(), |f| f.to_string_lossy().into_owned())
                    );
                    let trained = crate::emulator::cache::training(&what, || {
                        fine_tune_round(
                            ctx,
                            d,
                            task,
                            spec,
                            &net,
                            &mut base_data,
                            (&train, &held),
                            &settings,
                            (stream, round),
                        )
                    })?;
                    cache
                        .store_derived(spec, &tag(task), &key, &trained)
                        .map_err(other)?;
                    trained
                }
            };
            fine_tune_iterations = next.trace.last().map_or(0, |t| t.iteration);
            net = next.emulator;
        }
        Ok(net)
    }
}

/// Round `round`'s fine-tune of `net` for `task` on the base data and windows (built once
/// into `base_data`) and the visits aggregated so far, timed from the start of the round's
/// training; the aggregation's randomness is stream `2 round + 1` of `stream`.
#[allow(clippy::too_many_arguments)]
fn fine_tune_round(
    ctx: &crate::experiment::RunContext,
    d: &DaggerControl,
    task: &Task,
    spec: &BuildSpec,
    net: &Emulator,
    base_data: &mut Option<(TrainingData, Windows)>,
    (train, held): (&Visits, &Visits),
    settings: &TrainSettings,
    (stream, round): (u64, usize),
) -> Result<Trained, Error> {
    let t0 = std::time::Instant::now();
    if base_data.is_none() {
        let data = ctx.stage(&format!("dagger {}: base data", task.name), || {
            training_data(spec)
        });
        *base_data = Some((
            data.map_err(other)?,
            rollout_windows(spec).map_err(other)?.0,
        ));
    }
    let (data, windows) = base_data.as_ref().expect("just built");
    let mut rng = ChaCha8Rng::seed_from_u64(mix_seed(stream, 2 * round as u64 + 1));
    let agg = aggregate(net, data, windows, train, held, settings, &mut rng).map_err(other)?;
    let mut emulator = net.clone();
    let anchor = anchor_of(spec, emulator.transforms());
    let report = ctx.stage(
        &format!("dagger {} round {}: fine-tune", task.name, round + 1),
        || {
            fine_tune_aggregated(
                &mut emulator,
                &agg,
                &data.sigma,
                settings,
                d.settings.iters,
                anchor.as_ref(),
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
    Ok(trained)
}

/// The DAgger figure: per task, the learned controls' final error on the simulator (solid) and
/// on the net learned through (dashed) against the round, log y, with the tolerance (1).
pub fn figure(
    fig: &crate::experiment::plot::FigureSink,
    tables: &crate::experiment::output::Tables,
) -> Result<Vec<std::path::PathBuf>, Error> {
    use crate::experiment::output::unique;
    use crate::experiment::plot::{Figure, Mark, Panel, Series};
    use crate::experiment::rows::TableRow;
    // Written only where the spec runs DAgger on some task.
    let Some(t) = tables.get("dagger") else {
        return Ok(vec![]);
    };
    let rows = DaggerRoundRow::from_table(t);
    if rows.is_empty() {
        return Err(other("dagger: the DAgger rounds have no rows"));
    }
    let tasks: Vec<String> = rows.iter().map(|r| r.task.clone()).collect();
    let mut series = vec![];
    let last = rows.iter().map(|r| r.round as f64).fold(0.0, f64::max);
    for (c, name) in unique(&tasks).into_iter().enumerate() {
        let pts = |v: fn(&DaggerRoundRow) -> f64| -> Vec<(f64, f64)> {
            rows.iter()
                // Log axis: an exact zero has no place on it and is left out.
                .filter(|r| r.task == name && v(r) > 0.0)
                .map(|r| (r.round as f64, v(r)))
                .collect()
        };
        let (sim, emu) = (
            pts(|r| r.final_error_simulator),
            pts(|r| r.final_error_emulator),
        );
        // Solid with dots on the simulator, dashed on the net, in the task's colour.
        series.push(Series::line(format!("{name}: simulator"), sim, c).mark(Mark::LinePoints));
        series.push(Series::line(format!("{name}: DAgger net"), emu, c).mark(Mark::Dashed));
    }
    let dots = (0..=20).map(|i| (last * i as f64 / 20.0, 1.0)).collect();
    series.push(Series::line("tolerance (final error 1)", dots, 7).mark(Mark::Points));
    let panel = Panel {
        title: "DAgger (ours): final error of the LM-learned controls by round".into(),
        x_label: "DAgger round (0: the Table 1 net)".into(),
        y_label: "final error, RMS of (s_M - s_d)/tolerance (1)".into(),
        log_y: true,
        series,
        ..Panel::default()
    };
    fig.draw("dagger", &Figure::grid(vec![panel], 1))
}

/// The report's DAgger paragraph and its verdict (rule in the spec): per task the rounds'
/// simulator errors, and at the last round whether the goal is reached on the net within the
/// paper's iteration count and on the simulator. `None` when the run wrote no `dagger.csv` (a
/// spec without DAgger); a written one without rows is an error naming it (every task DAgger
/// runs on has round 0 at least).
pub fn summary(dir: &std::path::Path) -> Result<Option<(String, String)>, Error> {
    use crate::experiment::output::unique;
    use crate::experiment::report::sig;
    use crate::experiment::rule::{shown, Check, Cmp, Null, Partly, Rule};
    let Some(rows) = crate::experiment::rows::written_rows::<DaggerRoundRow>(dir, "dagger.csv")?
    else {
        return Ok(None);
    };
    if rows.is_empty() {
        return Err(other(format!(
            "{}: the DAgger rounds have no rows",
            dir.join("dagger.csv").display()
        )));
    }
    let mut md = format!(
        "\nControl through DAgger emulators (ours, `dagger.csv`; Levenberg-Marquardt through each round's net, controls replayed on the simulator; round 0 is the Table 1 net). The last column is the range of the simulator's final error over {SPREAD_REPLAYS} replays of the same controls, each perturbed by up to {}% of its channel's half-range: how far the open-loop outcome moves under control changes far smaller than a net's error (near or above 1, the tolerance, no emulator short of exact can make the learned controls land reliably).\n\n| task | round | examples | iterations to goal (budget) | final error, net | final error, simulator | neutral drift gap (m) | simulator error spread, controls ±{}% |\n| --- | --- | --- | --- | --- | --- | --- | --- |\n",
        SPREAD_FRACTION * 100.0,
        SPREAD_FRACTION * 100.0
    );
    for r in &rows {
        md.push_str(&format!(
            "| {} | {} | {} | {} ({}) | {} | {} | {} | {} |\n",
            r.task,
            r.round,
            r.examples,
            if r.iterations_to_goal.is_finite() {
                r.iterations_to_goal.to_string()
            } else {
                "never".into()
            },
            r.iterations,
            sig(r.final_error_emulator),
            sig(r.final_error_simulator),
            sig(r.drift_gap),
            sig(r.simulator_error_spread)
        ));
    }
    let tasks: Vec<String> = rows.iter().map(|r| r.task.clone()).collect();
    let names = unique(&tasks);
    let mut ok = 0;
    let mut checks = Vec::new();
    let mut groups = Vec::new();
    let parts: Vec<String> = names
        .iter()
        .map(|name| {
            let of_task: Vec<&DaggerRoundRow> = rows.iter().filter(|r| &r.task == name).collect();
            let last = *of_task
                .iter()
                .max_by_key(|r| r.round)
                .expect("a task has rows");
            let budget = last.iterations as f64;
            let on_net = last.iterations_to_goal.is_finite() && last.iterations_to_goal <= budget;
            let on_sim = last.final_error_simulator <= 1.0;
            ok += usize::from(on_net && on_sim);
            // The last round's controls, judged as the headline's: at the goal on the net
            // within the paper's iterations (null: never reaching it) and within tolerance on
            // the simulator (null: round 0, the Table 1 net's controls).
            let first = *of_task
                .iter()
                .min_by_key(|r| r.round)
                .expect("a task has rows");
            groups.push(vec![checks.len(), checks.len() + 1]);
            checks.push(Check::new(
                format!("{name}: iterations to the goal on the last round's net"),
                last.iterations_to_goal,
                Cmp::AtMost,
                budget,
                Null::new("never reaching it", f64::INFINITY),
            ));
            checks.push(Check::new(
                format!("{name}: final error on the simulator, in tolerances"),
                last.final_error_simulator,
                Cmp::AtMost,
                1.0,
                Null::new("round 0, the Table 1 net's controls", first.final_error_simulator),
            ));
            let by_round: Vec<String> = of_task.iter().map(|r| sig(r.final_error_simulator)).collect();
            // The open loop's sensitivity: the spread of the simulator's final error under
            // ±SPREAD_FRACTION control changes, at round 0 (the Table 1 net's controls) and
            // at the last round.
            let spreads: Vec<String> = of_task
                .iter()
                .filter(|r| r.simulator_error_spread.is_finite())
                .map(|r| sig(r.simulator_error_spread))
                .collect();
            let sensitivity = match (spreads.first(), spreads.last()) {
                (Some(a), Some(b)) => format!(
                    "; the simulator's final error moves over a range of {a} (round 0) and {b} (round {}) under ±{}% control changes",
                    last.round,
                    SPREAD_FRACTION * 100.0
                ),
                _ => String::new(),
            };
            format!(
                "{name}: simulator error by round {} (net {} at round {}; goal on the net within {} iterations: {}; on the simulator: {}{sensitivity})",
                by_round.join(" -> "),
                sig(last.final_error_emulator),
                last.round,
                last.iterations,
                if on_net { "yes" } else { "no" },
                if on_sim { "yes" } else { "no" }
            )
        })
        .collect();
    let rule = Rule::gated(vec![], checks, Partly::AnyOf(groups));
    let (v, lines, text) = shown(
        rule.as_ref(),
        "none: a check's null passes it (round 0, the Table 1 net's controls, already ends within tolerance on the simulator), so DAgger has nothing to show here",
    );
    Ok(Some((
        md,
        format!(
            " Control through DAgger emulators (ours), LM, judged at the last round (rule fixed in the spec): {} ({ok} of {} tasks reach their goal on the net within the paper's iteration count and end within tolerance on the simulator); {}.{lines} Rule: {text}",
            v.label(),
            names.len(),
            parts.join("; ")
        ),
    )))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::experiment::spec::SpecFile;

    /// A `dagger.csv` that lost its rows is an error naming it, not a report without the
    /// DAgger line; no file (a spec without DAgger) is nothing to say.
    #[test]
    fn an_emptied_dagger_table_is_an_error() {
        use crate::experiment::output::write_table;
        use crate::experiment::rows::table_of;
        let dir = tempfile::tempdir().unwrap();
        assert!(summary(dir.path()).unwrap().is_none());
        write_table(dir.path(), "dagger", &table_of::<DaggerRoundRow>(&[])).unwrap();
        let e = summary(dir.path()).unwrap_err().to_string();
        assert!(e.contains("dagger.csv"), "{e}");
        std::fs::write(dir.path().join("dagger.csv"), "task,round\npendulum,0\n").unwrap();
        let e = summary(dir.path()).unwrap_err().to_string();
        assert!(e.contains("dagger.csv"), "{e}");
    }

    #[test]
    fn the_dagger_cache_key_changes_with_every_setting_round_task_and_base_net() {
        let file =
            SpecFile::load(std::path::Path::new("experiments/na_fig13_control.toml")).unwrap();
        let p: Params = toml::Value::Table(file.raw.params).try_into().unwrap();
        let d = p.dagger.clone().expect("the spec runs DAgger");
        let task = &p.tasks[0];
        let base = crate::families::na::table1_structure::build_spec(
            1,
            &task.net,
            p.steps,
            p.example_scale,
            &p.training,
        );
        let cache = EmulatorCache::new("/nonexistent");
        let path = |b: &BuildSpec, t: &Task, d: &DaggerControl, ci: usize, r: usize| {
            cache.derived_path(b, &tag(t), &derived_key(t, d, ci, r))
        };
        let here = path(&base, task, &d, p.curvature_iterations, 1);
        assert_eq!(here, path(&base, task, &d, p.curvature_iterations, 1));
        let s = d.settings;
        let mut variants: Vec<DaggerControl> = [
            DaggerSettings {
                rounds: s.rounds + 1,
                ..s
            },
            DaggerSettings {
                perturbations: s.perturbations + 1,
                ..s
            },
            DaggerSettings {
                perturbed_rollouts: s.perturbed_rollouts + 1,
                ..s
            },
            DaggerSettings {
                control_noise: s.control_noise * 2.0,
                ..s
            },
            DaggerSettings {
                iters: s.iters + 1,
                ..s
            },
        ]
        .into_iter()
        .map(|settings| DaggerControl {
            settings,
            ..d.clone()
        })
        .collect();
        variants.push(DaggerControl {
            learner: StepRule::Fixed,
            ..d.clone()
        });
        for v in &variants {
            assert_ne!(
                path(&base, task, v, p.curvature_iterations, 1),
                here,
                "{v:?}"
            );
        }
        assert_ne!(path(&base, task, &d, p.curvature_iterations, 2), here);
        assert_ne!(path(&base, task, &d, p.curvature_iterations + 1, 1), here);
        assert_ne!(
            path(&base, &p.tasks[1], &d, p.curvature_iterations, 1),
            here
        );
        let other_seed = BuildSpec {
            seed: base.seed + 1,
            ..base.clone()
        };
        assert_ne!(path(&other_seed, task, &d, p.curvature_iterations, 1), here);
    }
}
