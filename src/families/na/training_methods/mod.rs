//! # `na_training_methods` (NeuroAnimator §3.5, §2.3 and Fig. 2): how the emulator nets are trained
//!
//! Two measurements the paper rests its training recipe on:
//!
//! 1. **Optimizers.** "We use the conjugate gradient method to train networks of small and
//!    moderate size. This method converges faster than gradient descent, but the efficiency
//!    becomes less significant when training large networks. [...] we use gradient descent with
//!    the momentum term when training large networks", on mini-batches of about 30 examples.
//!    For a small and a large Table 1 net (`[[params.nets]]`, each with its `size`), every method
//!    of `methods` (conjugate gradient, momentum mini-batches, and the L-BFGS this project
//!    trains with) fits the same one-step data from the same initial weights (`inits` of them)
//!    for the same budget of data passes. One pass is one forward and backward sweep over every
//!    training example: a full-batch cost-and-gradient evaluation (conjugate gradient and L-BFGS
//!    count each distinct point their line searches ask for), or one epoch of mini-batches.
//!    Every iteration (epoch) records the passes so far, the wall-clock seconds since training
//!    began and the training and held-out errors.
//! 2. **Examples per weight.** "We use 8-10 times as many examples as there are weights in the
//!    network, which seems sufficient to avoid serious overfitting or underfitting" (Fig. 2). The
//!    `[params.examples]` net is trained by L-BFGS on the first `ratio × weights` examples of one
//!    sampled training set (fewer examples are fewer episodes; the normalization is fitted once on
//!    the whole set), for each ratio of `ratios`, until its *training* error stops improving (the
//!    paper's Xerion stopping rule, no early stopping on held-out data, which would hide
//!    overfitting), and is then scored on a test set sampled from separate episodes.
//!
//! Tables: `nets` (part, net, size, model, inputs, hidden, outputs, weights, examples,
//! examples_per_weight, passes), `curves` (net, method, init, iteration, passes, seconds,
//! train_error, held_out_error), `methods` (net, method, init, target_factor, target, passes_to_target,
//! seconds_to_target, best_held_out_error, final_train_error, passes, seconds, seconds_per_pass,
//! stop), `examples` (net, init, examples_per_weight, examples, weights, train_error,
//! test_error, test_train_ratio, rule_ratio, iterations, stop). Errors are mean squared errors per output in
//! the net's normalized space. `seconds*` columns are wall-clock measurements and change from
//! run to run; every other column is the same for a seed.
//!
//! Verdict rule (fixed in `experiments/na_training_methods.toml` before the first run;
//! thresholds ours). Optimizers: per net and initial weights, the target is `target_factor` ×
//! the lowest held-out error any method reaches in the budget; a method's cost is the passes it
//! needs to first reach the target (never: infinite), its median over the inits. Check (a), the
//! small net: conjugate gradient needs fewer passes than momentum. Check (b), the large net:
//! momentum needs at most as many passes as conjugate gradient (the advantage gone, as the
//! paper's switch implies). Examples per weight, on the median over inits of each ratio's
//! test/train error ratio: the premise, that the sweep can show overfitting at all, is a ratio of
//! at least 2 at the smallest examples-per-weight; check (c): at `rule_ratio` (8) the test error
//! is at most 1.25 × the training error (no serious overfitting); check (d): the test error at
//! `rule_ratio` is at most 1.5 × the test error at the largest ratio (more data buys little: no
//! serious underfitting of the data). Held: all four checks; partly: at least two; did not hold:
//! fewer; premise not reproduced when the premise fails.

mod figures;
mod job;
mod report;

pub use report::{optimizer_ratios, training_rule, ExampleFacts};

use crate::emulator::catalog::{NetSpec, TrainMethod, TrainSettings};
use crate::experiment::output::Tables;
use crate::experiment::plot::FigureSink;
use crate::experiment::report::Findings;
use crate::experiment::resolve::{ensure, ParamError, Validate};
use crate::experiment::{Error, Family};
use crate::families::na::table1_structure::{validate_nets, validate_training};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// The family.
pub struct NaTrainingMethods;

/// The most initial weights per net (a size limit).
pub const MAX_INITS: usize = 10;
/// The most data passes of one method's run (a size limit).
pub const MAX_PASSES: usize = 5000;
/// The largest examples-per-weight ratio (a size limit: 64 × a Table 1 net's weights).
pub const MAX_RATIO: f64 = 64.0;

/// Whether a net is the small or the large one of the comparison.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum NetSize {
    /// Small or moderate (the paper: conjugate gradient).
    Small,
    /// Large (the paper: momentum mini-batches).
    Large,
}

impl NetSize {
    /// Its name in the tables.
    pub fn name(self) -> &'static str {
        match self {
            Self::Small => "small",
            Self::Large => "large",
        }
    }
}

/// One net of the optimizer comparison.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MethodsNet {
    /// Its name in the tables.
    pub name: String,
    /// Small or large.
    pub size: NetSize,
    /// The net (a Table 1 net: model, hidden units, examples, normalization).
    pub net: NetSpec,
    /// Data passes each method is given.
    pub passes: usize,
}

/// The examples-per-weight sweep.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ExamplesSweep {
    /// Its name in the tables.
    pub name: String,
    /// The net; its `examples` is ignored (the largest ratio sets the sample).
    pub net: NetSpec,
    /// Examples per weight, increasing.
    pub ratios: Vec<f64>,
    /// The ratio of the paper's rule (8).
    pub rule_ratio: f64,
    /// Test examples as a fraction of the largest training set (separate episodes).
    pub test_fraction: f64,
    /// L-BFGS iteration limit.
    pub max_iters: u64,
    /// Stop after this many iterations without a `min_improvement` relative decrease of the
    /// training error.
    pub patience: usize,
    /// Relative decrease of the training error that counts.
    pub min_improvement: f64,
}

/// Parameters of `na_training_methods`.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Params {
    /// Physical steps per emulator step (N50, as Table 1).
    pub steps: usize,
    /// The optimizers compared.
    pub methods: Vec<TrainMethod>,
    /// Initial weights per net (init k draws from its own stream of the seed).
    pub inits: usize,
    /// The target of the pass count: this factor × the lowest held-out error of any method.
    pub target_factor: f64,
    /// The nets of the optimizer comparison (one small, one large).
    pub nets: Vec<MethodsNet>,
    /// The examples-per-weight sweep.
    pub examples: ExamplesSweep,
    /// Training settings: held-out fraction and the momentum method's rate, momentum and batch
    /// size (Table 1's); the iteration limits and patience are replaced by the pass budget.
    pub training: TrainSettings,
    /// The verdict's thresholds (ours; [`training_rule`]).
    pub rule: TrainingRule,
}

/// The examples-per-weight thresholds of the verdict (ours: the paper says 8-10 examples per
/// weight "seem sufficient to avoid serious overfitting or underfitting", without numbers).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TrainingRule {
    /// Premise: the sweep can show overfitting, a test/training error ratio of at least this
    /// at the smallest examples per weight.
    pub overfit_ratio: f64,
    /// No serious overfitting: at the rule's ratio the test error is at most this multiple
    /// of the training error.
    pub test_train_max: f64,
    /// No serious underfitting of the data: the test error at the rule's ratio is at most
    /// this multiple of the test error at the largest ratio.
    pub more_data_max: f64,
}

impl Validate for Params {
    fn validate(&self) -> Result<(), ParamError> {
        ensure(self.steps >= 1, "steps", "must be >= 1")?;
        ensure(
            !self.methods.is_empty(),
            "methods",
            "need at least one method",
        )?;
        for (i, m) in self.methods.iter().enumerate() {
            ensure(
                !self.methods[..i].contains(m),
                &format!("methods[{i}]"),
                "is listed twice",
            )?;
        }
        ensure(
            (1..=MAX_INITS).contains(&self.inits),
            "inits",
            format!("must be in 1..={MAX_INITS}"),
        )?;
        ensure(
            self.target_factor >= 1.0 && self.target_factor.is_finite(),
            "target_factor",
            "must be >= 1",
        )?;
        for (key, v) in [
            ("rule.overfit_ratio", self.rule.overfit_ratio),
            ("rule.test_train_max", self.rule.test_train_max),
            ("rule.more_data_max", self.rule.more_data_max),
        ] {
            ensure(
                v > 1.0 && v.is_finite(),
                key,
                "must be above 1: a net that generalizes perfectly scores 1",
            )?;
        }
        let nets: Vec<NetSpec> = self.nets.iter().map(|n| n.net.clone()).collect();
        validate_nets(&nets, 1.0)?;
        for (i, n) in self.nets.iter().enumerate() {
            ensure(
                (1..=MAX_PASSES).contains(&n.passes),
                &format!("nets[{i}].passes"),
                format!("must be in 1..={MAX_PASSES}"),
            )?;
            ensure(
                !n.name.is_empty() && !self.nets[..i].iter().any(|m| m.name == n.name),
                &format!("nets[{i}].name"),
                "must be non-empty and unique",
            )?;
        }
        let e = &self.examples;
        validate_nets(std::slice::from_ref(&e.net), 1.0)?;
        ensure(!e.ratios.is_empty(), "examples.ratios", "need at least one")?;
        ensure(
            e.ratios.windows(2).all(|w| w[0] < w[1])
                && e.ratios.iter().all(|&r| r > 0.0 && r <= MAX_RATIO),
            "examples.ratios",
            format!("must increase, each in (0, {MAX_RATIO}]"),
        )?;
        ensure(
            e.ratios.contains(&e.rule_ratio),
            "examples.rule_ratio",
            "must be one of `ratios`",
        )?;
        ensure(
            e.test_fraction > 0.0 && e.test_fraction <= 1.0,
            "examples.test_fraction",
            "must be in (0, 1]",
        )?;
        ensure(e.max_iters >= 1, "examples.max_iters", "must be >= 1")?;
        ensure(e.patience >= 1, "examples.patience", "must be >= 1")?;
        ensure(
            (0.0..1.0).contains(&e.min_improvement),
            "examples.min_improvement",
            "must be in [0, 1)",
        )?;
        validate_training(&self.training)
    }
}

/// The passes (and seconds) at which a curve first reaches `target`: `None` if never.
pub fn first_reach(curve: &[(f64, f64, f64)], target: f64) -> Option<(f64, f64)> {
    curve.iter().find(|p| p.2 <= target).map(|p| (p.0, p.1))
}

/// The median of `xs` (NaN counted as +∞; the upper middle of an even count).
pub fn median_inf(xs: &[f64]) -> f64 {
    let mut v: Vec<f64> = xs
        .iter()
        .map(|&x| if x.is_nan() { f64::INFINITY } else { x })
        .collect();
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// A method's name in the tables.
pub fn method_name(m: TrainMethod) -> &'static str {
    match m {
        TrainMethod::Cg => "cg",
        TrainMethod::Lbfgs => "lbfgs",
        TrainMethod::Momentum => "momentum",
    }
}

/// A method's name in words, from its name in the tables; a name no method has is an error
/// (a table edited or from another experiment), never a label made up from it.
pub(super) fn method_words(name: &str) -> Result<&'static str, Error> {
    let method = [TrainMethod::Cg, TrainMethod::Lbfgs, TrainMethod::Momentum]
        .into_iter()
        .find(|&m| method_name(m) == name)
        .ok_or_else(|| crate::experiment::other(format!("unknown training method `{name}`")))?;
    Ok(match method {
        TrainMethod::Cg => "conjugate gradient (batch)",
        TrainMethod::Lbfgs => "L-BFGS (batch, ours)",
        TrainMethod::Momentum => "momentum, mini-batches of 30",
    })
}

impl Family for NaTrainingMethods {
    const KIND: &'static str = "na_training_methods";
    type Params = Params;
    const CAPTIONS: &'static [(&'static str, &'static str)] = &[
        (
            "curves",
            "held-out error of each training method against wall-clock seconds (left) and against data passes (right), one row per net, every initial weight set drawn in its method's stroke; the dashed line is the first init's target (the rule's pass count is to reach it).",
        ),
        (
            "examples",
            "left: training and test error of the same net trained to convergence on more and more examples (median over initial weights), against examples per weight; right: test/training error ratio with the rule's thresholds (overfitting visible; none serious; values in the legend) and the paper's 8-10 examples per weight between two dashed verticals, the axis cut a few times above the larger threshold.",
        ),
    ];

    fn figures(&self, fig: &FigureSink, tables: &Tables) -> Result<Vec<PathBuf>, Error> {
        figures::figures(fig, tables)
    }

    fn report(&self, dir: &Path) -> Result<Findings, Error> {
        report::report(dir)
    }
}

#[cfg(test)]
mod tests {
    use super::job::{initial_net, run_method};
    use super::report::{rule_over_inits, InitExamples};
    use super::*;
    use crate::emulator::train::Dataset;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn the_optimizer_rule_reads_the_medians_and_contradicting_rows_fail() {
        let nan = f64::NAN;
        let rows = |small: [f64; 2], large: [f64; 2]| {
            vec![
                (
                    NetSize::Small,
                    "cg".to_string(),
                    vec![small[0], small[0], 99.0],
                ),
                (
                    NetSize::Small,
                    "momentum".to_string(),
                    vec![small[1], small[1], 1.0],
                ),
                (
                    NetSize::Large,
                    "cg".to_string(),
                    vec![large[0], large[0], 1.0],
                ),
                (
                    NetSize::Large,
                    "momentum".to_string(),
                    vec![large[1], large[1], 99.0],
                ),
            ]
        };
        let passes = |r: (f64, f64)| (r.0 < 1.0, r.1 <= 1.0);
        // The paper's picture: CG faster on the small net, momentum on the large one.
        assert_eq!(
            passes(optimizer_ratios(&rows([10.0, 40.0], [60.0, 5.0]))),
            (true, true)
        );
        // The contradicting data: momentum faster on the small net, CG on the large one.
        assert_eq!(
            passes(optimizer_ratios(&rows([40.0, 10.0], [5.0, 60.0]))),
            (false, false)
        );
        // Never reaching the target counts as infinitely many passes; never against never
        // says nothing.
        assert_eq!(
            passes(optimizer_ratios(&rows([nan, 10.0], [nan, nan]))),
            (false, false)
        );
        assert_eq!(
            passes(optimizer_ratios(&rows([10.0, nan], [nan, 3.0]))),
            (true, true)
        );
        // A missing method: not measured, so it fails.
        assert_eq!(
            passes(optimizer_ratios(&rows([10.0, 40.0], [60.0, 5.0])[..2])),
            (true, false)
        );
    }

    const BARS: TrainingRule = TrainingRule {
        overfit_ratio: 2.0,
        test_train_max: 1.25,
        more_data_max: 1.5,
    };

    #[test]
    fn the_examples_rule_needs_visible_overfitting_and_fails_on_contradicting_rows() {
        use crate::experiment::report::Verdict;
        let verdict = |opt: (f64, f64), rows: &[(f64, f64, f64)]| {
            training_rule(opt, &ExampleFacts::of(rows, 8.0), &BARS).map(|r| r.verdict())
        };
        let (fast, slow) = ((0.25, 0.1), (4.0, 12.0));
        // Overfitting at 0.5 per weight, none at 8, little to gain beyond.
        let good = [(0.5, 10.0, 1.0), (8.0, 1.1, 0.012), (32.0, 1.0, 0.01)];
        assert_eq!(verdict(fast, &good), Some(Verdict::Held));
        assert_eq!(verdict(slow, &good), Some(Verdict::Partly));
        // Still overfitting at 8 and much to gain: both examples checks fail.
        let bad = [(0.5, 10.0, 1.0), (8.0, 3.0, 0.1), (32.0, 1.0, 0.01)];
        assert_eq!(verdict(fast, &bad), Some(Verdict::Partly));
        assert_eq!(verdict(slow, &bad), Some(Verdict::NotHeld));
        assert_eq!(verdict((0.25, 12.0), &bad), Some(Verdict::NotHeld));
        // No overfitting even at the smallest ratio: the premise fails.
        let flat = [(0.5, 1.2, 0.02), (8.0, 1.0, 0.01), (32.0, 1.0, 0.01)];
        assert_eq!(verdict(fast, &flat), Some(Verdict::PremiseNotReproduced));
        // A more-data bar that the fewest-examples net itself meets cannot fail: refused.
        let lax = TrainingRule {
            more_data_max: 200.0,
            ..BARS
        };
        assert!(training_rule(fast, &ExampleFacts::of(&good, 8.0), &lax).is_none());
    }

    /// Over several initial weight sets each check carries its bootstrap interval over the
    /// sets; one set alone carries none; one set of five that contradicts the rest reaches
    /// into the intervals and leaves the verdict inconclusive.
    #[test]
    fn the_rule_over_inits_carries_intervals_over_the_sets() {
        use crate::experiment::report::Verdict;
        let opt = |small_cg: Vec<f64>| {
            vec![
                (NetSize::Small, "cg".to_string(), small_cg),
                (NetSize::Small, "momentum".to_string(), vec![40.0; 5]),
                (NetSize::Large, "cg".to_string(), vec![60.0; 5]),
                (NetSize::Large, "momentum".to_string(), vec![5.0; 5]),
            ]
        };
        // Examples: (test/training, test error, training error) per set at 0.25, 8 and 32 examples per weight.
        let examples: InitExamples = vec![
            (0.25, vec![(50.0, 0.03, 0.0006); 5]),
            (8.0, vec![(1.1, 0.0012, 0.0011); 5]),
            (32.0, vec![(1.05, 0.001, 0.00095); 5]),
        ];
        let rule = rule_over_inits(&opt(vec![10.0; 5]), &examples, 8.0, &BARS).unwrap();
        assert_eq!(rule.verdict(), Verdict::Held, "{}", rule.table());
        assert!(rule.held.iter().all(|c| c.interval.is_some()));
        let one: Vec<(NetSize, String, Vec<f64>)> = opt(vec![10.0; 5])
            .into_iter()
            .map(|(s, m, v)| (s, m, v[..1].to_vec()))
            .collect();
        let rule = rule_over_inits(&one, &examples, 8.0, &BARS).unwrap();
        assert!(rule.held.iter().all(|c| c.interval.is_none()));
        // Two sets of five where CG is the slower on the small net: the median passes (a),
        // its interval reaches past 1.
        let rule = rule_over_inits(
            &opt(vec![10.0, 10.0, 10.0, 80.0, 80.0]),
            &examples,
            8.0,
            &BARS,
        )
        .unwrap();
        assert_eq!(rule.verdict(), Verdict::Inconclusive, "{}", rule.table());
    }

    #[test]
    fn medians_count_never_as_infinite_and_first_reach_finds_the_first_point() {
        assert_eq!(median_inf(&[3.0, 1.0, 2.0]), 2.0);
        assert_eq!(median_inf(&[f64::NAN, 1.0, 2.0]), 2.0);
        assert_eq!(median_inf(&[f64::NAN, f64::NAN, 2.0]), f64::INFINITY);
        let curve = [(0.0, 0.0, 5.0), (3.0, 0.1, 1.0), (5.0, 0.2, 0.5)];
        assert_eq!(first_reach(&curve, 1.0), Some((3.0, 0.1)));
        assert_eq!(first_reach(&curve, 0.1), None);
    }

    /// The pass counter counts each distinct point once and stops the optimizer at the budget,
    /// and a run of each method records a curve that starts at the initial net.
    #[test]
    fn every_method_runs_to_its_pass_budget() {
        use rand::Rng;
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let x = ndarray::Array2::from_shape_fn((120, 3), |_| rng.random_range(-1.0..1.0));
        let y = x.map_axis(ndarray::Axis(1), |r| (r[0] * 2.0_f64).sin() + r[1] * r[2]);
        let y = y.insert_axis(ndarray::Axis(1));
        let data = Dataset::new(x, y).unwrap();
        let (train, held) = data.split(0.25, 1).unwrap();
        let s = TrainSettings::for_tests(100, 100, 10);
        for m in [TrainMethod::Cg, TrainMethod::Lbfgs, TrainMethod::Momentum] {
            let mlp = initial_net(5, 1, (3, 6, 1));
            let r = run_method(mlp, &train, &held, m, &s, 25, 7).unwrap();
            let passes: Vec<usize> = r.curve.iter().map(|p| p.0).collect();
            assert!(passes.windows(2).all(|w| w[0] <= w[1]), "{m:?}: {passes:?}");
            assert!(*passes.last().unwrap() <= 25, "{m:?}: {passes:?}");
            assert!(
                *passes.last().unwrap() >= 20,
                "{m:?} used its budget: {passes:?}"
            );
            let first = r.curve[0].3;
            let best = r.curve.iter().map(|p| p.3).fold(f64::INFINITY, f64::min);
            assert!(best < 0.5 * first, "{m:?} learns: {first} -> {best}");
            assert!(
                r.stop == "budget" || r.stop == "max_iterations",
                "{m:?}: {}",
                r.stop
            );
        }
    }
}
