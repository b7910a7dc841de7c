//! The job of `na_training_methods`: every method's run on each net from each initial
//! weight set, and the examples-per-weight sweep.

use super::{first_reach, method_name, MethodsNet, Params};
use crate::emulator::anchor::Anchor;
use crate::emulator::catalog::{
    anchor_of, stop_name, training_data, BuildSpec, TrainMethod, TrainSettings, TrainingData,
};
use crate::emulator::mlp::{Mlp, WeightInit};
use crate::emulator::train::{
    minimize_early_stopping, mse, train_momentum_observed, Dataset, FullBatchConfig,
    FullBatchMethod, MomentumConfig, TracePoint, TrainingProblem,
};
use crate::experiment::output::Tables;
use crate::experiment::rows::table_of;
use crate::experiment::runner::one_core_each;
use crate::experiment::{other, Error, Job, RunContext};
use crate::families::na::table1_structure::build_spec;
use crate::seed::mix_seed;
use argmin::core::{CostFunction, Gradient};
use indicatif::ProgressBar;
use ndarray::Array1;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;
use std::time::Instant;

crate::result_rows! {
    /// One row of `nets.csv`: a net of the optimizer half (`methods`) or the examples net.
    pub struct NetsRow {
        /// Which half: `methods` or `examples`.
        part: String = "part",
        /// The net's name.
        net: String = "net",
        /// `small` or `large` for the optimizer half's nets, empty for the examples net.
        size: String = "size",
        /// The model's name.
        model: String = "model",
        /// Net inputs.
        inputs: i64 = "inputs",
        /// Hidden units.
        hidden: i64 = "hidden",
        /// Net outputs.
        outputs: i64 = "outputs",
        /// Weights.
        weights: i64 = "weights",
        /// Training examples.
        examples: i64 = "examples",
        /// examples / weights.
        examples_per_weight: f64 = "examples_per_weight",
        /// The pass budget of each run (0 for the examples net).
        passes: i64 = "passes",
    }
}

crate::result_rows! {
    /// One row of `curves.csv`: one run's errors after one iteration.
    pub struct CurveRow {
        /// The net's name.
        net: String = "net",
        /// The method ([`method_name`]).
        method: String = "method",
        /// The initial weight set (from 1).
        init: i64 = "init",
        /// The iteration.
        iteration: i64 = "iteration",
        /// Data passes so far.
        passes: i64 = "passes",
        /// Wall-clock seconds since training began.
        seconds: f64 = "seconds",
        /// Training error.
        train_error: f64 = "train_error",
        /// Held-out error.
        held_out_error: f64 = "held_out_error",
    }
}

crate::result_rows! {
    /// One row of `methods.csv`: one run (net, method, init) against its init's target.
    pub struct MethodRow {
        /// The net's name.
        net: String = "net",
        /// The method ([`method_name`]).
        method: String = "method",
        /// The initial weight set (from 1).
        init: i64 = "init",
        /// The target's factor over the lowest held-out error any method reached.
        target_factor: f64 = "target_factor",
        /// The init's target held-out error.
        target: f64 = "target",
        /// Data passes to reach the target (NaN: never).
        passes_to_target: f64 = "passes_to_target",
        /// Seconds to reach the target (NaN: never).
        seconds_to_target: f64 = "seconds_to_target",
        /// The lowest held-out error reached.
        best_held_out_error: f64 = "best_held_out_error",
        /// The training error at the end.
        final_train_error: f64 = "final_train_error",
        /// Data passes run.
        passes: i64 = "passes",
        /// Seconds run.
        seconds: f64 = "seconds",
        /// seconds / passes.
        seconds_per_pass: f64 = "seconds_per_pass",
        /// Why the run stopped.
        stop: String = "stop",
    }
}

crate::result_rows! {
    /// One row of `examples.csv`: the examples net of one init trained on one prefix.
    pub struct ExamplesRow {
        /// The net's name.
        net: String = "net",
        /// The initial weight set (from 1).
        init: i64 = "init",
        /// Training examples per weight asked for.
        examples_per_weight: f64 = "examples_per_weight",
        /// Training examples used.
        examples: i64 = "examples",
        /// Weights.
        weights: i64 = "weights",
        /// Training error.
        train_error: f64 = "train_error",
        /// Test error (separate episodes).
        test_error: f64 = "test_error",
        /// test_error / train_error.
        test_train_ratio: f64 = "test_train_ratio",
        /// The rule's examples per weight (the spec's).
        rule_ratio: f64 = "rule_ratio",
        /// Optimizer iterations.
        iterations: i64 = "iterations",
        /// Why training stopped.
        stop: String = "stop",
    }
}

/// A full-batch training problem that counts its data passes (each distinct point asked for is
/// one pass) and refuses to evaluate once `budget` passes are spent, which ends the optimizer's
/// run at the last completed iteration.
struct Counted<'a> {
    inner: TrainingProblem<'a>,
    passes: &'a AtomicUsize,
    budget: usize,
    last: Mutex<Option<Array1<f64>>>,
}

/// The error message of a spent budget (a stop, not a failure).
const BUDGET_SPENT: &str = "pass budget spent";

impl Counted<'_> {
    fn evaluate(&self, w: &Array1<f64>) -> Result<(f64, Array1<f64>), argmin::core::Error> {
        let mut last = self.last.lock().expect("no panics while held");
        if last.as_ref() != Some(w) {
            if self.passes.load(Ordering::Relaxed) >= self.budget {
                return Err(argmin::core::Error::msg(BUDGET_SPENT));
            }
            self.passes.fetch_add(1, Ordering::Relaxed);
            *last = Some(w.clone());
        }
        Ok(self.inner.cost_and_gradient(w))
    }
}

impl CostFunction for Counted<'_> {
    type Param = Array1<f64>;
    type Output = f64;
    fn cost(&self, w: &Self::Param) -> Result<f64, argmin::core::Error> {
        Ok(self.evaluate(w)?.0)
    }
}

impl Gradient for Counted<'_> {
    type Param = Array1<f64>;
    type Gradient = Array1<f64>;
    fn gradient(&self, w: &Self::Param) -> Result<Self::Gradient, argmin::core::Error> {
        Ok(self.evaluate(w)?.1)
    }
}

/// One point of a training curve: (passes, seconds, train error, held-out error).
pub(super) type CurvePoint = (usize, f64, f64, f64);

/// One method's run on one net from one set of initial weights.
pub(super) struct MethodRun {
    pub(super) curve: Vec<CurvePoint>,
    pub(super) stop: String,
}

impl MethodRun {
    /// The lowest finite held-out error of the run (+∞ if none).
    fn best(&self) -> f64 {
        self.curve
            .iter()
            .map(|p| p.3)
            .filter(|e| e.is_finite())
            .fold(f64::INFINITY, f64::min)
    }
}

/// Trains `mlp` by `method` for `passes` data passes, recording the curve.
pub(super) fn run_method(
    mut mlp: Mlp,
    train: &Dataset,
    held: &Dataset,
    method: TrainMethod,
    s: &TrainSettings,
    passes: usize,
    shuffle_seed: u64,
) -> Result<MethodRun, Error> {
    let t0 = Instant::now();
    let mut curve: Vec<CurvePoint> = Vec::new();
    let stop = match method {
        TrainMethod::Momentum => {
            let config = MomentumConfig {
                learning_rate: s.learning_rate,
                momentum: s.momentum,
                batch_size: s.batch_size,
                max_epochs: passes,
                patience: passes + 1,
                min_improvement: 0.0,
                seed: shuffle_seed,
            };
            let mut observe = |p: &TracePoint| {
                curve.push((
                    p.iteration,
                    t0.elapsed().as_secs_f64(),
                    p.train_error,
                    p.held_out_error,
                ));
            };
            let report =
                train_momentum_observed(&mut mlp, train, held, &config, None, &mut observe)
                    .map_err(other)?;
            stop_name(&report.stop)
        }
        TrainMethod::Cg | TrainMethod::Lbfgs => {
            let count = AtomicUsize::new(0);
            let problem = Counted {
                inner: TrainingProblem::new(&mlp, train),
                passes: &count,
                budget: passes,
                last: Mutex::new(None),
            };
            let times: Mutex<Vec<(usize, f64)>> = Mutex::new(Vec::new());
            let held_error = |w: &[f64]| {
                let (p, q, r) = (mlp.n_in(), mlp.n_hidden(), mlp.n_out());
                let e = mse(&Mlp::from_weights(p, q, r, w.to_vec()), held);
                times
                    .lock()
                    .expect("no panics while held")
                    .push((count.load(Ordering::Relaxed), t0.elapsed().as_secs_f64()));
                e
            };
            let config = FullBatchConfig {
                method: if method == TrainMethod::Cg {
                    FullBatchMethod::ConjugateGradient { restart_iters: 50 }
                } else {
                    FullBatchMethod::Lbfgs { memory: 20 }
                },
                max_iters: passes as u64,
                patience: passes + 1,
                min_improvement: 0.0,
            };
            let mut w = mlp.weights().to_vec();
            let report =
                minimize_early_stopping(problem, &mut w, &held_error, &config).map_err(other)?;
            let times = times.into_inner().expect("no panics while held");
            for (p, (passes, secs)) in report.trace.iter().zip(times) {
                curve.push((passes, secs, p.train_error, p.held_out_error));
            }
            let stop = stop_name(&report.stop);
            let spent = curve.last().is_some_and(|p| p.0 >= passes);
            if stop.contains(BUDGET_SPENT) || spent {
                "budget".to_string()
            } else {
                stop
            }
        }
    };
    Ok(MethodRun { curve, stop })
}

/// The initial weights of init `k` for a net of this shape: Table 1's fan-in draw from stream
/// `1000 + k` of the net's seed, the same for every method.
pub(super) fn initial_net(seed: u64, k: usize, shape: (usize, usize, usize)) -> Mlp {
    let mut rng = ChaCha8Rng::seed_from_u64(mix_seed(seed, 1000 + k as u64));
    Mlp::new(shape.0, shape.1, shape.2, WeightInit::FanIn, &mut rng)
}

impl Job for Params {
    fn params_json(&self) -> serde_json::Value {
        serde_json::to_value(self).unwrap_or_default()
    }

    fn run(&self, ctx: &RunContext) -> Result<Tables, Error> {
        let mut t = MethodTables::default();
        let s = TrainSettings {
            input_noise: 0.0,
            rollout_k: 0,
            rollout_weight: 0.0,
            rollout_iters: 0,
            ..self.training
        };
        let runs = self.nets.len() * self.inits * self.methods.len();
        let pb = ctx.progress(
            (runs + self.examples.ratios.len() * self.inits) as u64,
            "training runs",
        );
        for n in &self.nets {
            self.run_net(ctx, n, &s, &pb, &mut t)?;
        }
        let examples = self.run_examples(ctx, &s, &pb, &mut t.nets)?;
        Ok(Tables::from([
            ("nets", table_of(&t.nets)),
            ("curves", table_of(&t.curves)),
            ("methods", table_of(&t.methods)),
            ("examples", table_of(&examples)),
            ("rule", crate::experiment::rule::rule_table_of(&self.rule)?),
        ]))
    }
}

/// The optimizer half's rows (`nets` also gets the examples net's row).
#[derive(Default)]
struct MethodTables {
    nets: Vec<NetsRow>,
    curves: Vec<CurveRow>,
    methods: Vec<MethodRow>,
}

/// The examples net's sampled data and the shape its sweep trains.
struct ExamplesData {
    spec: BuildSpec,
    data: TrainingData,
    anchor: Option<Anchor>,
    n_in: usize,
    n_out: usize,
    weights: usize,
}

impl Params {
    /// One net of the optimizer half: its data sampled, its `nets` row, and every (init,
    /// method) run with its `curves` and `methods` rows.
    fn run_net(
        &self,
        ctx: &RunContext,
        n: &MethodsNet,
        s: &TrainSettings,
        pb: &ProgressBar,
        t: &mut MethodTables,
    ) -> Result<(), Error> {
        let spec = build_spec(ctx.seed, &n.net, self.steps, 1.0, s);
        let data = ctx
            .stage(&format!("sample {}", n.name), || training_data(&spec))
            .map_err(other)?;
        let (train, held) = (&data.clean_ds, &data.held_ds);
        let shape = (train.inputs.ncols(), n.net.hidden, train.targets.ncols());
        let weights = Mlp::weight_count(shape.0, shape.1, shape.2);
        t.nets.push(NetsRow {
            part: "methods".into(),
            net: n.name.clone(),
            size: n.size.name().to_string(),
            model: n.net.model.name().to_string(),
            inputs: shape.0 as i64,
            hidden: shape.1 as i64,
            outputs: shape.2 as i64,
            weights: weights as i64,
            examples: train.len() as i64,
            examples_per_weight: train.len() as f64 / weights as f64,
            passes: n.passes as i64,
        });
        // Every (init, method) run on one thread of its own, as many side by side as the run
        // has threads: each run has a core to itself, so the seconds compare the methods on
        // equal terms (a batch method's gradient gets no more cores than momentum's serial
        // steps) and no core idles. The target needs every method of the init.
        let pairs: Vec<(usize, TrainMethod)> = (1..=self.inits)
            .flat_map(|k| self.methods.iter().map(move |&m| (k, m)))
            .collect();
        let runs = one_core_each(&pairs, |&(k, m)| -> Result<MethodRun, Error> {
            let mlp = initial_net(spec.seed, k, shape);
            let shuffle = mix_seed(spec.seed, 2000 + k as u64);
            let r = ctx.stage(&format!("{} {} init {k}", n.name, method_name(m)), || {
                run_method(mlp, train, held, m, s, n.passes, shuffle)
            })?;
            pb.inc(1);
            Ok(r)
        })?
        .into_iter()
        .collect::<Result<Vec<_>, Error>>()?;
        let mut runs = pairs.iter().map(|p| p.1).zip(runs);
        for k in 1..=self.inits {
            let of_init: Vec<(TrainMethod, MethodRun)> =
                runs.by_ref().take(self.methods.len()).collect();
            self.push_init(n, k, &of_init, t);
        }
        Ok(())
    }

    /// The `curves` and `methods` rows of init `k`'s runs of net `n`, against the init's
    /// target (`target_factor` × the lowest held-out error any method reached).
    fn push_init(
        &self,
        n: &MethodsNet,
        k: usize,
        of_init: &[(TrainMethod, MethodRun)],
        t: &mut MethodTables,
    ) {
        let lowest = of_init
            .iter()
            .map(|(_, r)| r.best())
            .fold(f64::INFINITY, f64::min);
        let target = self.target_factor * lowest;
        for (m, r) in of_init {
            for (i, p) in r.curve.iter().enumerate() {
                t.curves.push(CurveRow {
                    net: n.name.clone(),
                    method: method_name(*m).to_string(),
                    init: k as i64,
                    iteration: i as i64,
                    passes: p.0 as i64,
                    seconds: p.1,
                    train_error: p.2,
                    held_out_error: p.3,
                });
            }
            let pts: Vec<(f64, f64, f64)> =
                r.curve.iter().map(|p| (p.0 as f64, p.1, p.3)).collect();
            let reach = first_reach(&pts, target);
            let last = r
                .curve
                .last()
                .copied()
                .unwrap_or((0, 0.0, f64::NAN, f64::NAN));
            t.methods.push(MethodRow {
                net: n.name.clone(),
                method: method_name(*m).to_string(),
                init: k as i64,
                target_factor: self.target_factor,
                target,
                passes_to_target: reach.map_or(f64::NAN, |x| x.0),
                seconds_to_target: reach.map_or(f64::NAN, |x| x.1),
                best_held_out_error: r.best(),
                final_train_error: last.2,
                passes: last.0 as i64,
                seconds: last.1,
                seconds_per_pass: last.1 / (last.0.max(1) as f64),
                stop: r.stop.clone(),
            });
        }
    }

    /// Examples per weight: the examples net's data sampled (its `nets` row pushed), every
    /// (init, ratio) trained in parallel, and the `examples` table.
    fn run_examples(
        &self,
        ctx: &RunContext,
        s: &TrainSettings,
        pb: &ProgressBar,
        nets: &mut Vec<NetsRow>,
    ) -> Result<Vec<ExamplesRow>, Error> {
        let e = &self.examples;
        let d = self.sample_examples(ctx, s)?;
        let all = &d.data.clean_ds;
        ensure_shape(all.inputs.ncols(), d.n_in, "examples.net inputs")?;
        nets.push(NetsRow {
            part: "examples".into(),
            net: e.name.clone(),
            size: String::new(),
            model: e.net.model.name().to_string(),
            inputs: d.n_in as i64,
            hidden: e.net.hidden as i64,
            outputs: d.n_out as i64,
            weights: d.weights as i64,
            examples: all.len() as i64,
            examples_per_weight: all.len() as f64 / d.weights as f64,
            passes: 0,
        });
        let rows = self.train_examples(ctx, pb, &d);
        pb.finish_and_clear();
        self.examples_rows(rows, d.weights)
    }

    /// The examples net sized for the largest ratio and its one sampled data set (held-out
    /// fraction: the sweep's test fraction).
    fn sample_examples(&self, ctx: &RunContext, s: &TrainSettings) -> Result<ExamplesData, Error> {
        let e = &self.examples;
        let max_ratio = *e.ratios.last().expect("validated");
        let (n_in, n_out) = {
            let m = e.net.model;
            (m.state_dim() + m.control_dim(), m.state_dim())
        };
        let weights = Mlp::weight_count(n_in, e.net.hidden, n_out);
        let mut net = e.net.clone();
        net.examples = (max_ratio * weights as f64).round() as usize;
        let sweep_settings = TrainSettings {
            held_out_fraction: e.test_fraction,
            ..*s
        };
        let spec = build_spec(ctx.seed, &net, self.steps, 1.0, &sweep_settings);
        let data = ctx
            .stage(&format!("sample {}", e.name), || training_data(&spec))
            .map_err(other)?;
        let anchor = anchor_of(&spec, &data.transforms);
        Ok(ExamplesData {
            spec,
            data,
            anchor,
            n_in,
            n_out,
            weights,
        })
    }

    /// Every (init, ratio) of the sweep trained in parallel, in (init, ratio) order.
    fn train_examples(
        &self,
        ctx: &RunContext,
        pb: &ProgressBar,
        d: &ExamplesData,
    ) -> Vec<Result<ExampleRun, Error>> {
        let jobs: Vec<(usize, f64)> = (1..=self.inits)
            .flat_map(|k| self.examples.ratios.iter().map(move |&r| (k, r)))
            .collect();
        ctx.stage("examples per weight", || {
            jobs.par_iter()
                .map(|&(k, ratio)| self.train_example(d, k, ratio, pb))
                .collect()
        })
    }

    /// The examples net of init `k` trained by L-BFGS on the first `ratio` × weights examples
    /// until its training error stops improving, and scored on the test set.
    fn train_example(
        &self,
        d: &ExamplesData,
        k: usize,
        ratio: f64,
        pb: &ProgressBar,
    ) -> Result<ExampleRun, Error> {
        let e = &self.examples;
        let (n_in, n_out, weights) = (d.n_in, d.n_out, d.weights);
        let (all, test) = (&d.data.clean_ds, &d.data.held_ds);
        let anchor = &d.anchor;
        let count = ((ratio * weights as f64).round() as usize).clamp(2, all.len());
        let rows: Vec<usize> = (0..count).collect();
        let sub = all.select(&rows);
        let mut mlp = initial_net(d.spec.seed, k, (n_in, e.net.hidden, n_out));
        let problem = TrainingProblem::new(&mlp, &sub).anchored(anchor.as_ref());
        // Stopping on the training error (Xerion's rule), not on held-out data.
        let train_error = |w: &[f64]| {
            let mut net = Mlp::from_weights(n_in, e.net.hidden, n_out, w.to_vec());
            if let Some(a) = anchor.as_ref() {
                a.project(&mut net);
            }
            mse(&net, &sub)
        };
        let config = FullBatchConfig {
            method: FullBatchMethod::Lbfgs { memory: 20 },
            max_iters: e.max_iters,
            patience: e.patience,
            min_improvement: e.min_improvement,
        };
        let report = minimize_early_stopping(problem, mlp.weights_mut(), &train_error, &config)
            .map_err(other)?;
        if let Some(a) = anchor.as_ref() {
            a.project(&mut mlp);
        }
        pb.inc(1);
        Ok(ExampleRun {
            init: k,
            ratio,
            examples: count,
            train_error: mse(&mlp, &sub),
            test_error: mse(&mlp, test),
            iterations: report.trace.len().saturating_sub(1),
            stop: stop_name(&report.stop),
        })
    }

    /// The `examples` rows of the sweep's `runs` (the first failed run's error, if any).
    fn examples_rows(
        &self,
        runs: Vec<Result<ExampleRun, Error>>,
        weights: usize,
    ) -> Result<Vec<ExamplesRow>, Error> {
        let e = &self.examples;
        runs.into_iter()
            .map(|r| {
                let r = r?;
                Ok(ExamplesRow {
                    net: e.name.clone(),
                    init: r.init as i64,
                    examples_per_weight: r.ratio,
                    examples: r.examples as i64,
                    weights: weights as i64,
                    train_error: r.train_error,
                    test_error: r.test_error,
                    test_train_ratio: r.test_error / r.train_error,
                    rule_ratio: e.rule_ratio,
                    iterations: r.iterations as i64,
                    stop: r.stop,
                })
            })
            .collect()
    }
}

/// One net trained on a prefix of the examples.
struct ExampleRun {
    init: usize,
    ratio: f64,
    examples: usize,
    train_error: f64,
    test_error: f64,
    iterations: usize,
    stop: String,
}

fn ensure_shape(got: usize, want: usize, what: &str) -> Result<(), Error> {
    if got == want {
        Ok(())
    } else {
        Err(other(format!("{what}: {got}, expected {want}")))
    }
}
