//! The report of `na_training_methods`: the verdict's rule on the medians over the initial
//! weight sets, with bootstrap intervals.

use super::job::{ExamplesRow, MethodRow, NetsRow};
use super::{median_inf, method_words, NetSize, TrainingRule};
use crate::experiment::report::{sig, Findings};
use crate::experiment::rows::read_rows;
use crate::experiment::rule::{read_rule, shown, Check, Cmp, Null, Partly, Rule};
use crate::experiment::stats::bootstrap_intervals;
use crate::experiment::Error;
use std::path::Path;

/// The optimizer half of the rule, as (small net: CG's median passes to target over
/// momentum's, large net: momentum's over CG's), NaN where a net or a method is missing or
/// neither reaches the target. Rows: (net size, method, passes to target per init; NaN =
/// never).
pub fn optimizer_ratios(rows: &[(NetSize, String, Vec<f64>)]) -> (f64, f64) {
    let med = |size: NetSize, m: &str| {
        rows.iter()
            .find(|r| r.0 == size && r.1 == m)
            .map_or(f64::NAN, |r| median_inf(&r.2))
    };
    // Never against never says nothing (NaN); never against some count is infinite or 0.
    let ratio = |a: f64, b: f64| {
        if a.is_infinite() && b.is_infinite() {
            f64::NAN
        } else {
            a / b
        }
    };
    (
        ratio(med(NetSize::Small, "cg"), med(NetSize::Small, "momentum")),
        ratio(med(NetSize::Large, "momentum"), med(NetSize::Large, "cg")),
    )
}

/// The examples rows the rule reads, from (ratio, median test/train ratio, median test error)
/// in increasing ratio: the smallest ratio's, the rule ratio's and the largest's.
pub struct ExampleFacts {
    /// Test/training error at the smallest examples per weight.
    pub smallest_ratio: f64,
    /// Its test error over the largest ratio's.
    pub smallest_more_data: f64,
    /// Test/training error at the rule's examples per weight.
    pub at_ratio: f64,
    /// Its test error over the largest ratio's.
    pub at_more_data: f64,
}

impl ExampleFacts {
    /// The facts of `rows` at `rule_ratio` (NaN where a row is missing).
    pub fn of(rows: &[(f64, f64, f64)], rule_ratio: f64) -> Self {
        let nan = (f64::NAN, f64::NAN, f64::NAN);
        let first = rows.first().copied().unwrap_or(nan);
        let at = rows
            .iter()
            .find(|r| r.0 == rule_ratio)
            .copied()
            .unwrap_or(nan);
        let largest = rows.last().copied().unwrap_or(nan);
        Self {
            smallest_ratio: first.1,
            smallest_more_data: first.2 / largest.2,
            at_ratio: at.1,
            at_more_data: at.2 / largest.2,
        }
    }
}

/// The verdict's rule: premise, the sweep shows overfitting at its smallest ratio
/// (test/training at least `overfit_ratio`; null: a net that generalizes perfectly, 1); (a)
/// small net, CG's passes to target over momentum's below 1 (null: CG no faster, 1); (b)
/// large net, momentum's over CG's at most 1 (null: momentum never reaching the target); (c)
/// test/training at the rule's ratio at most `test_train_max` and (d) its test error over the
/// largest ratio's at most `more_data_max` (null for both: the smallest ratio's net). Held:
/// all four; partly: any two.
pub fn training_rule(
    (small, large): (f64, f64),
    e: &ExampleFacts,
    r: &TrainingRule,
) -> Option<Rule> {
    let fewest = "the net with the fewest examples per weight";
    let premise = match Check::new(
        "test/training error at the smallest examples per weight",
        e.smallest_ratio,
        Cmp::AtLeast,
        r.overfit_ratio,
        Null::new("a net that generalizes perfectly", 1.0),
    ) {
        Ok(c) => c,
        Err(_) => return None,
    };
    let held = vec![
        Check::new(
            "small net: conjugate gradient's passes to target over momentum's (NaN: neither reaches it)",
            small,
            Cmp::Below,
            1.0,
            Null::new("conjugate gradient no faster than momentum", 1.0),
        ),
        Check::new(
            "large net: momentum's passes to target over conjugate gradient's",
            large,
            Cmp::AtMost,
            1.0,
            Null::new("momentum never reaching the target", f64::INFINITY),
        ),
        Check::new(
            "test/training error at the rule's examples per weight",
            e.at_ratio,
            Cmp::AtMost,
            r.test_train_max,
            Null::new(fewest, e.smallest_ratio),
        ),
        Check::new(
            "its test error over the largest examples per weight's",
            e.at_more_data,
            Cmp::AtMost,
            r.more_data_max,
            Null::new(fewest, e.smallest_more_data),
        ),
    ];
    Rule::gated(vec![premise], held, Partly::AtLeast(2))
}

/// The size of the net `name` of `nets.csv`'s rows (None: not an optimizer-half net).
fn size_of(nets: &[NetsRow], name: &str) -> Option<NetSize> {
    nets.iter()
        .find(|n| n.net == name)
        .and_then(|n| match n.size.as_str() {
            "small" => Some(NetSize::Small),
            "large" => Some(NetSize::Large),
            _ => None,
        })
}

/// (net size, method, passes to target per init) from `nets.csv`'s and `methods.csv`'s rows.
fn optimizer_rows(nets: &[NetsRow], methods: &[MethodRow]) -> Vec<(NetSize, String, Vec<f64>)> {
    let mut out: Vec<(NetSize, String, Vec<f64>)> = Vec::new();
    for m in methods {
        let Some(size) = size_of(nets, &m.net) else {
            continue;
        };
        match out.iter_mut().find(|r| r.0 == size && r.1 == m.method) {
            Some(r) => r.2.push(m.passes_to_target),
            None => out.push((size, m.method.clone(), vec![m.passes_to_target])),
        }
    }
    out
}

/// Per examples-per-weight ratio, increasing: (ratio, per init in row order (test/training
/// error, test error, training error)) from `examples.csv`.
pub(super) type InitExamples = Vec<(f64, Vec<(f64, f64, f64)>)>;

/// [`InitExamples`] from `examples.csv`'s rows.
fn example_rows(examples: &[ExamplesRow]) -> InitExamples {
    let mut ratios: Vec<f64> = examples.iter().map(|e| e.examples_per_weight).collect();
    ratios.sort_by(f64::total_cmp);
    ratios.dedup();
    ratios
        .into_iter()
        .map(|x| {
            let rows = examples
                .iter()
                .filter(|e| e.examples_per_weight == x)
                .map(|e| (e.test_train_ratio, e.test_error, e.train_error));
            (x, rows.collect())
        })
        .collect()
}

/// Seed of the bootstrap over initial weight sets (fixed, so a report is the same on every
/// machine).
const BOOTSTRAP_SEED: u64 = 1;

/// The verdict's rule ([`training_rule`]) on the medians over the initial weight sets `idx`
/// (indices into each method's and each ratio's per-init values; repeats allowed: a bootstrap
/// resample).
fn rule_of_inits(
    opt: &[(NetSize, String, Vec<f64>)],
    examples: &InitExamples,
    idx: &[usize],
    rule_ratio: f64,
    bars: &TrainingRule,
) -> Option<Rule> {
    let pick = |v: &[f64]| -> Vec<f64> {
        idx.iter()
            .map(|&i| v.get(i).copied().unwrap_or(f64::NAN))
            .collect()
    };
    let opt: Vec<(NetSize, String, Vec<f64>)> = opt
        .iter()
        .map(|(size, m, v)| (*size, m.clone(), pick(v)))
        .collect();
    let triples: Vec<(f64, f64, f64)> = examples
        .iter()
        .map(|(x, rows)| {
            let q: Vec<f64> = rows.iter().map(|r| r.0).collect();
            let te: Vec<f64> = rows.iter().map(|r| r.1).collect();
            (*x, median_inf(&pick(&q)), median_inf(&pick(&te)))
        })
        .collect();
    training_rule(
        optimizer_ratios(&opt),
        &ExampleFacts::of(&triples, rule_ratio),
        bars,
    )
}

/// The verdict's rule on the medians over every initial weight set, each check with its 95%
/// bootstrap interval over the sets (resampled together: one set is one draw of every
/// method's and every ratio's initial weights) where there are several and the interval is
/// finite.
pub(super) fn rule_over_inits(
    opt: &[(NetSize, String, Vec<f64>)],
    examples: &InitExamples,
    rule_ratio: f64,
    bars: &TrainingRule,
) -> Option<Rule> {
    let n = opt.iter().map(|r| r.2.len()).max().unwrap_or(0);
    let all: Vec<usize> = (0..n).collect();
    let mut rule = rule_of_inits(opt, examples, &all, rule_ratio, bars)?;
    if n < 2 {
        return Some(rule);
    }
    let k = rule.premise.len() + rule.held.len();
    let intervals = bootstrap_intervals(n, BOOTSTRAP_SEED, k, |idx, out| {
        if let Some(r) = rule_of_inits(opt, examples, idx, rule_ratio, bars) {
            for (o, c) in out.iter_mut().zip(r.premise.iter().chain(&r.held)) {
                *o = c.value;
            }
        }
    });
    let checks = rule.premise.iter_mut().chain(rule.held.iter_mut());
    for (c, (lo, hi)) in checks.zip(intervals) {
        if lo.is_finite() && hi.is_finite() && c.value.is_finite() {
            *c = c.clone().with_interval(lo, hi);
        }
    }
    Some(rule)
}

/// Per ratio, increasing: (ratio, median test/train ratio, median test error, median train
/// error) over every init ([`example_rows`]).
fn example_medians(per_init: &InitExamples) -> Vec<(f64, f64, f64, f64)> {
    per_init
        .iter()
        .map(|(x, rows)| {
            let col = |f: fn(&(f64, f64, f64)) -> f64| {
                median_inf(&rows.iter().map(f).collect::<Vec<_>>())
            };
            (*x, col(|r| r.0), col(|r| r.1), col(|r| r.2))
        })
        .collect()
}

pub(super) fn report(dir: &Path) -> Result<Findings, Error> {
    let methods: Vec<MethodRow> = read_rows(&dir.join("methods.csv"))?;
    let nets: Vec<NetsRow> = read_rows(&dir.join("nets.csv"))?;
    let examples: Vec<ExamplesRow> = read_rows(&dir.join("examples.csv"))?;
    let mut md = String::from(
        "| net | size: weights, examples | method | passes to target (median over inits) | seconds to target | best held-out error | seconds per pass |\n| --- | --- | --- | --- | --- | --- | --- |\n",
    );
    let mut keys: Vec<(String, String)> = Vec::new();
    for m in &methods {
        if !keys.contains(&(m.net.clone(), m.method.clone())) {
            keys.push((m.net.clone(), m.method.clone()));
        }
    }
    let never = |x: f64| {
        if x.is_finite() {
            sig(x)
        } else {
            "never".to_string()
        }
    };
    for (n, me) in &keys {
        let runs: Vec<&MethodRow> = methods
            .iter()
            .filter(|m| m.net == *n && m.method == *me)
            .collect();
        let col =
            |c: fn(&MethodRow) -> f64| median_inf(&runs.iter().map(|m| c(m)).collect::<Vec<_>>());
        let net = nets.iter().find(|x| x.net == *n);
        let size = net.map_or(String::new(), |x| {
            format!("{}: {}, {}", x.size, x.weights, x.examples)
        });
        md.push_str(&format!(
            "| {} | {} | {} | {} of {} | {} | {} | {} |\n",
            n,
            size,
            method_words(me)?,
            never(col(|m| m.passes_to_target)),
            net.map_or("?".into(), |x| sig(x.passes as f64)),
            never(col(|m| m.seconds_to_target)),
            sig(col(|m| m.best_held_out_error)),
            sig(col(|m| m.seconds_per_pass))
        ));
    }
    let per_init = example_rows(&examples);
    let med = example_medians(&per_init);
    md.push_str("\n| examples per weight | training error | test error | test / training |\n| --- | --- | --- | --- |\n");
    for r in &med {
        md.push_str(&format!(
            "| {} | {} | {} | {} |\n",
            sig(r.0),
            sig(r.3),
            sig(r.2),
            sig(r.1)
        ));
    }
    let rule_ratio = examples.first().map_or(f64::NAN, |e| e.rule_ratio);
    let target_factor = methods.first().map_or(f64::NAN, |m| m.target_factor);
    let opt_rows = optimizer_rows(&nets, &methods);
    let bars: TrainingRule = read_rule(dir)?;
    // The result first: each method's median passes to the target, per net size.
    let passes = |size: NetSize| {
        opt_rows
            .iter()
            .filter(|r| r.0 == size)
            .map(|r| {
                let short = match r.1.as_str() {
                    "cg" => "CG",
                    "lbfgs" => "L-BFGS",
                    other => other,
                };
                format!("{short} {}", never(median_inf(&r.2)))
            })
            .collect::<Vec<_>>()
            .join(", ")
    };
    let rule = rule_over_inits(&opt_rows, &per_init, rule_ratio, &bars);
    let (verdict, lines, text) = shown(rule.as_ref(), " No rule: a bar its null meets.");
    let at = med.iter().find(|r| r.0 == rule_ratio);
    // The small net's best held-out error of a method, median over inits.
    let best_of = |method: &str| {
        let v: Vec<f64> = methods
            .iter()
            .filter(|m| {
                m.method == method
                    && nets
                        .iter()
                        .find(|x| x.net == m.net)
                        .is_some_and(|x| x.size == "small")
            })
            .map(|m| m.best_held_out_error)
            .collect();
        median_inf(&v)
    };
    Ok(Findings {
        ours: md,
        verdict,
        rule: rule.clone(),
        why: format!(
            "Passes to target (median): small net {}; large net {}; test/training error {} at {} examples per weight. Best held-out error in the budget, small net: conjugate gradient {}, momentum {} (median over inits). Checks:{lines} Rule (fixed in the spec before the first run, thresholds ours, in the spec's [params.rule]; target = {} x the lowest held-out error any method reaches in the budget, per init; medians over the inits; the pass budgets and conjugate gradient's line search changed after the first run: see the rule history): {text}",
            passes(NetSize::Small),
            passes(NetSize::Large),
            at.map_or("?".into(), |r| sig(r.1)),
            sig(rule_ratio),
            sig(best_of("cg")),
            sig(best_of("momentum")),
            sig(target_factor),
        ),
    })
}
