//! `ms_fig6_learning_plot` (MS Fig. 6): the `ms_learning` family. Every evaluation's
//! objective over the hill-climbing iterations with the best so far, for the poodle, beside
//! simulated annealing with the same budget, run side by side by [`LearningJob`] (in
//! [`super::search`], with the parameters shared with `ms_motion`).
//!
//! Tables: `learning` (method, iteration, objective, best) and `summary` (method, evaluations,
//! seconds, best_objective). Figure: `<id>_learning.png/svg`, the scatter of every evaluation
//! with best-so-far lines.

use super::rows::{LearningRow, LearningSummaryRow, SearchRow};
use super::search::{learning_panel_on, LearningJob, Params, Search};
use crate::experiment::output::Tables;
use crate::experiment::plot::FigureSink;
use crate::experiment::plot::{Figure, Mark, Series};
use crate::experiment::report::{sig, Findings};
use crate::experiment::resolve::{distinct, ensure, ParamError, Validate};
use crate::experiment::rows::{read_rows, table_of, TableRow};
use crate::experiment::rule::{read_rule, rule_table_of, shown, Check, Cmp, Null, Partly, Rule};
use crate::experiment::stats::median_interval;
use crate::experiment::{Error, Family, Job, RunContext};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// The learning-plot family.
pub struct MsLearning;

crate::result_rows! {
    /// One row of `seed_curves.csv`: one search's curve statistics ([`Curve`]) on one seed.
    pub struct SeedCurveRow {
        /// The seed.
        seed: i64 = "seed",
        /// The search ([`Search::name`]).
        method: String = "method",
        /// The best objective of the initial random controllers.
        init_best: f64 = "init_best",
        /// The best by the end of the early iterations.
        at_early: f64 = "at_early",
        /// The final best.
        end_best: f64 = "end_best",
        /// The share of the late evaluations below `init_best`.
        poor_late: f64 = "poor_late",
        /// The search's iterations.
        iterations: f64 = "iterations",
    }
}

/// `ms_learning` parameters: the search and annealing, and the verdict's bars.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct LearningSpec {
    /// The motion, its search and the annealing beside it.
    #[serde(flatten)]
    pub learning: Params,
    /// The seeds the verdict judges together: the run's own seed draws the figure and writes
    /// `learning.csv`; every seed's curve statistics go to `seed_curves.csv`.
    #[serde(default)]
    pub seeds: Vec<u64>,
    /// The verdict's bars (ours; [`learning_rule`]).
    pub rule: LearningRule,
}

/// The most seeds a run judges (each is a whole search).
const MAX_SEEDS: usize = 20;

/// The verdict's thresholds (ours: the paper describes the curve's shape, "improves quickly
/// through the first 5,000 iterations and slowly after", and "many evaluated controllers are
/// poor" at the end, without numbers).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LearningRule {
    /// The early iterations, as a share of all (the paper: 5,000 of 25,000).
    pub early_fraction: f64,
    /// Fast, then slow: at least this share of hill climbing's total gain is made early.
    pub early_gain_share: f64,
    /// The end of the search, as a share of the iterations.
    pub late_fraction: f64,
    /// Many stay poor: at least this share of the late evaluations score below the best
    /// random controller.
    pub late_poor_share: f64,
}

impl Validate for LearningRule {
    fn validate(&self) -> Result<(), ParamError> {
        for (key, v) in [
            ("rule.early_fraction", self.early_fraction),
            ("rule.early_gain_share", self.early_gain_share),
            ("rule.late_fraction", self.late_fraction),
            ("rule.late_poor_share", self.late_poor_share),
        ] {
            ensure(v > 0.0 && v < 1.0, key, "must be in (0, 1)")?;
        }
        Ok(())
    }
}

impl Validate for LearningSpec {
    fn validate(&self) -> Result<(), ParamError> {
        LearningJob(self.learning.clone()).validate()?;
        ensure(
            self.seeds.len() <= MAX_SEEDS,
            "seeds",
            format!("at most {MAX_SEEDS} seeds (each is a whole search)"),
        )?;
        distinct("seeds", &self.seeds)?;
        self.rule.validate()
    }
}

impl Job for LearningSpec {
    fn params_json(&self) -> serde_json::Value {
        serde_json::to_value(self).unwrap_or_default()
    }

    fn run(&self, ctx: &RunContext) -> Result<Tables, Error> {
        let job = LearningJob(self.learning.clone());
        let mut tables = job.run(ctx)?;
        let mut seed_curves = Vec::new();
        let mut add = |seed: u64, t: &Tables| -> Result<(), Error> {
            let learning = LearningRow::from_table(t.require("learning")?);
            for search in Search::ALL {
                let c = curve(search, &learning, &self.rule);
                seed_curves.push(SeedCurveRow {
                    seed: seed as i64,
                    method: search.name().to_string(),
                    init_best: c.init_best,
                    at_early: c.at_early,
                    end_best: c.end_best,
                    poor_late: c.poor_late,
                    iterations: c.iterations,
                });
            }
            Ok(())
        };
        add(ctx.seed, &tables)?;
        // The other seeds' searches keep only their curves' statistics (each learning table
        // is megabytes).
        for &seed in self.seeds.iter().filter(|&&s| s != ctx.seed) {
            let own = RunContext::new(seed, ctx.quick, false);
            let t = job.run(&own)?;
            for (stage, secs) in own.stages() {
                ctx.record(&format!("{stage}, seed {seed}"), secs);
            }
            add(seed, &t)?;
        }
        tables.insert("seed_curves", table_of(&seed_curves));
        tables.insert("rule", rule_table_of(&self.rule)?);
        Ok(tables)
    }
}

/// Bootstrap seed of the medians over seeds (fixed, so a report is the same on every machine).
const BOOTSTRAP_SEED: u64 = 1;

/// The verdict's rule on hill climbing's curves `cs`, one per seed, each measure the median
/// over the seeds with its 95% bootstrap interval: (a) the share of its gain made in the early
/// iterations (null: a search gaining at a constant rate, the early fraction itself), (b) its
/// gain over the best random controller (null: the random controllers alone, 0), (c) the share
/// of late evaluations below that controller (null: a search whose perturbations never
/// disrupt, 0). Held when all pass; partly when (a) and (b) do, or (c).
fn learning_rule(cs: &[Curve], r: &LearningRule) -> Option<Rule> {
    let over = |f: &dyn Fn(&Curve) -> f64| {
        let v: Vec<f64> = cs.iter().map(f).collect();
        median_interval(&v, BOOTSTRAP_SEED)
    };
    let seeds = cs.len();
    let checks = [
        (
            format!("share of hill climbing's gain made in the early iterations, median over {seeds} seeds"),
            over(&Curve::early_share),
            Cmp::AtLeast,
            r.early_gain_share,
            Null::new("a search gaining at a constant rate", r.early_fraction),
        ),
        (
            format!("hill climbing's gain over the best random controller, median over {seeds} seeds"),
            over(&|c| c.end_best - c.init_best),
            Cmp::Above,
            0.0,
            Null::new("the random controllers alone", 0.0),
        ),
        (
            format!("share of the late evaluations below the best random controller, median over {seeds} seeds"),
            over(&|c| c.poor_late),
            Cmp::AtLeast,
            r.late_poor_share,
            Null::new("a search whose perturbations never disrupt", 0.0),
        ),
    ];
    let held = checks
        .into_iter()
        .map(|(label, (median, lo, hi), cmp, bar, null)| {
            Check::new(label, median, cmp, bar, null).map(|c| c.with_interval(lo, hi))
        })
        .collect();
    Rule::gated(vec![], held, Partly::AnyOf(vec![vec![0, 1], vec![2]]))
}

/// Learning-curve statistics of one method from `learning.csv` columns.
struct Curve {
    init_best: f64,
    at_early: f64,
    end_best: f64,
    poor_late: f64,
    iterations: f64,
}

impl Curve {
    /// The share of the total gain made by the end of the early iterations.
    fn early_share(&self) -> f64 {
        (self.at_early - self.init_best) / (self.end_best - self.init_best).max(1e-12)
    }
}

/// The curve of `search` in a run's `learning` rows, its early and late iterations as `r`
/// says.
fn curve(search: Search, learning: &[LearningRow], r: &LearningRule) -> Curve {
    let rows: Vec<&LearningRow> = learning
        .iter()
        .filter(|l| l.method == search.name())
        .collect();
    let iterations = rows.iter().map(|l| l.iteration as f64).fold(0.0, f64::max);
    let best_at = |limit: f64| {
        rows.iter()
            .filter(|l| l.iteration as f64 <= limit)
            .map(|l| l.best)
            .fold(f64::NEG_INFINITY, f64::max)
    };
    let init_best = best_at(0.0);
    let late: Vec<&&LearningRow> = rows
        .iter()
        .filter(|l| l.iteration as f64 > (1.0 - r.late_fraction) * iterations)
        .collect();
    let poor = late.iter().filter(|l| l.objective < init_best).count() as f64;
    Curve {
        init_best,
        at_early: best_at(r.early_fraction * iterations),
        end_best: best_at(iterations),
        poor_late: poor / late.len().max(1) as f64,
        iterations,
    }
}

impl Family for MsLearning {
    const KIND: &'static str = "ms_learning";
    const CAPTIONS: &'static [(&'static str, &'static str)] = &[
        (
            "learning",
            "every evaluation's objective over the hill-climbing iterations with the best so far (the paper's Fig. 6), beside simulated annealing with the same budget.",
        ),
    ];
    type Params = LearningSpec;

    fn figures(&self, fig: &FigureSink, tables: &Tables) -> Result<Vec<PathBuf>, Error> {
        let learning = LearningRow::from_table(tables.require("learning")?);
        let split = |search: Search| -> Vec<SearchRow> {
            learning
                .iter()
                .filter(|l| l.method == search.name())
                .map(|l| SearchRow {
                    iteration: l.iteration,
                    objective: l.objective,
                    best: l.best,
                })
                .collect()
        };
        let (h, s) = (
            split(Search::HillClimbing),
            split(Search::SimulatedAnnealing),
        );
        // Hill climbing's scatter alone, as the paper's Fig. 6, with annealing's best so far
        // beside it; annealing's own scatter in a second panel on the same axes.
        let x_label = "iteration (0: initial random controllers)";
        let both: [(&str, &[SearchRow]); 2] = [("hill climbing", &h), ("simulated annealing", &s)];
        let mut hill = learning_panel_on(
            "hill climbing (the paper's Fig. 6): poodle somersault",
            &both[..1],
            x_label,
            &both,
        );
        let anneal = learning_panel_on(
            "simulated annealing, same budget",
            &both[1..],
            x_label,
            &both,
        );
        if let Some(best) = anneal.series.last() {
            hill.series.push(
                Series::line("simulated annealing: best so far", best.points.clone(), 3)
                    .mark(Mark::Dashed),
            );
        }
        let mut fig6 = Figure::grid(vec![hill, anneal], 1);
        fig6.panel_size = (960, 480);
        fig.draw("learning", &fig6)
    }

    fn report(&self, dir: &Path) -> Result<Findings, Error> {
        let learning: Vec<LearningRow> = read_rows(&dir.join("learning.csv"))?;
        let summary: Vec<LearningSummaryRow> = read_rows(&dir.join("summary.csv"))?;
        let wall = summary.first().map_or(f64::NAN, |s| s.wall_seconds_both);
        let r: LearningRule = read_rule(dir)?;
        let h = curve(Search::HillClimbing, &learning, &r);
        let a = curve(Search::SimulatedAnnealing, &learning, &r);
        let mut md = format!(
            "| method | evaluations | seconds | best of initial set | best after {}% of the iterations | final best | share of the gain by then | evaluations in the last {}% worse than the initial best |\n| --- | --- | --- | --- | --- | --- | --- | --- |\n",
            sig(100.0 * r.early_fraction),
            sig(100.0 * r.late_fraction)
        );
        for (search, c) in [(Search::HillClimbing, &h), (Search::SimulatedAnnealing, &a)] {
            let k = summary.iter().find(|s| s.method == search.name());
            md.push_str(&format!(
                "| {} | {} | {} | {} | {} | {} | {} | {} |\n",
                search.name(),
                k.map_or(f64::NAN, |k| k.evaluations as f64),
                sig(k.map_or(f64::NAN, |k| k.seconds)),
                sig(c.init_best),
                sig(c.at_early),
                sig(c.end_best),
                sig(c.early_share()),
                sig(c.poor_late)
            ));
        }
        md.push_str(&format!(
            "\nBoth searches ran side by side in {} s of wall time ({} iterations each; the paper: 25,000 iterations in 66 min on a DEC 3000/400 AXP).\n",
            sig(wall),
            h.iterations
        ));
        // Every seed's curves.
        let (hills, anneals) = {
            let rows: Vec<SeedCurveRow> = read_rows(&dir.join("seed_curves.csv"))?;
            let of = |search: Search| -> Vec<(f64, Curve)> {
                rows.iter()
                    .filter(|c| c.method == search.name())
                    .map(|c| {
                        (
                            c.seed as f64,
                            Curve {
                                init_best: c.init_best,
                                at_early: c.at_early,
                                end_best: c.end_best,
                                poor_late: c.poor_late,
                                iterations: c.iterations,
                            },
                        )
                    })
                    .collect()
            };
            (of(Search::HillClimbing), of(Search::SimulatedAnnealing))
        };
        md.push_str(&format!(
            "\nOver the seeds (`seed_curves.csv`; the table above and the figure are the first seed's):\n\n| seed | hill climbing: share of the gain by {}% | its gain over the initial best | late evaluations worse than it | final best | annealing's final best |\n| --- | --- | --- | --- | --- | --- |\n",
            sig(100.0 * r.early_fraction)
        ));
        for ((seed, c), (_, an)) in hills.iter().zip(&anneals) {
            md.push_str(&format!(
                "| {seed} | {} | {} | {} | {} | {} |\n",
                sig(c.early_share()),
                sig(c.end_best - c.init_best),
                sig(c.poor_late),
                sig(c.end_best),
                sig(an.end_best)
            ));
        }
        let curves: Vec<Curve> = hills.into_iter().map(|(_, c)| c).collect();
        let anneal_ahead = anneals
            .iter()
            .zip(&curves)
            .filter(|((_, an), c)| an.end_best > c.end_best)
            .count();
        let rule = learning_rule(&curves, &r);
        let (verdict, lines, text) = shown(rule.as_ref(), " No rule: a bar its null meets.");
        let median_of = |i: usize| rule.as_ref().map_or(f64::NAN, |x| x.held[i].value);
        Ok(Findings {
            ours: md,
            verdict,
            rule: rule.clone(),
            why: format!(
                "Over {} seeds hill climbing made a median {}% of its total gain in the first {}% of the iterations; a median {}% of its evaluations in the last {}% were worse than the best random controller; simulated annealing with the same budget ended ahead of it for {anneal_ahead} of the seeds. Checks:{lines} Rule (thresholds ours, in the spec's [params.rule]): {text}",
                curves.len(),
                sig(100.0 * median_of(0)),
                sig(100.0 * r.early_fraction),
                sig(100.0 * median_of(2)),
                sig(100.0 * r.late_fraction),
            ),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::experiment::report::Verdict;

    const BARS: LearningRule = LearningRule {
        early_fraction: 0.2,
        early_gain_share: 0.6,
        late_fraction: 0.2,
        late_poor_share: 0.2,
    };

    fn curve_of(at_early: f64, end_best: f64, poor_late: f64) -> Curve {
        Curve {
            init_best: 1.0,
            at_early,
            end_best,
            poor_late,
            iterations: 100.0,
        }
    }

    #[test]
    fn fast_then_slow_with_poor_late_evaluations_is_held_and_each_half_partly() {
        let verdict =
            |c: &Curve| learning_rule(std::slice::from_ref(c), &BARS).map(|r| r.verdict());
        assert_eq!(verdict(&curve_of(8.0, 10.0, 0.5)), Some(Verdict::Held));
        // A constant-rate search (a fifth of its gain in a fifth of the iterations) is not
        // fast then slow.
        assert_eq!(verdict(&curve_of(2.8, 10.0, 0.5)), Some(Verdict::Partly));
        assert_eq!(verdict(&curve_of(8.0, 10.0, 0.0)), Some(Verdict::Partly));
        // No gain at all, with every late evaluation above the start: not held.
        assert_eq!(verdict(&curve_of(1.0, 1.0, 0.0)), Some(Verdict::NotHeld));
        // A gain-share bar that a constant-rate search meets is refused.
        let low = LearningRule {
            early_gain_share: 0.15,
            ..BARS
        };
        assert!(learning_rule(&[curve_of(8.0, 10.0, 0.5)], &low).is_none());
    }

    /// Over seeds each check reads the median with its interval: one seed in five that makes
    /// no early progress leaves the median early share above the bar but its interval
    /// straddling it.
    #[test]
    fn over_seeds_the_medians_and_their_intervals_decide() {
        let five = |early: [f64; 5]| -> Vec<Curve> {
            early.iter().map(|&e| curve_of(e, 10.0, 0.5)).collect()
        };
        let r = learning_rule(&five([8.0, 8.5, 9.0, 7.5, 8.2]), &BARS).unwrap();
        assert_eq!(r.verdict(), Verdict::Held);
        assert!((r.held[0].value - 0.8).abs() < 1e-12);
        let r = learning_rule(&five([8.0, 8.5, 9.0, 7.5, 1.5]), &BARS).unwrap();
        assert!((r.held[0].value - 7.0 / 9.0).abs() < 1e-12);
        assert_eq!(
            r.held[0].outcome(),
            crate::experiment::rule::Outcome::Inconclusive
        );
    }

    #[test]
    fn the_curve_reads_the_early_and_late_iterations_of_one_method() {
        let best = [0.0, 5.0, 8.0, 9.0, 9.0, 9.0, 9.0, 9.0, 9.0, 9.0, 10.0];
        let obj = [0.0, 5.0, 8.0, 9.0, 1.0, 1.0, 1.0, 1.0, 1.0, -1.0, 10.0];
        let mut rows: Vec<LearningRow> = (0..11)
            .map(|i| LearningRow {
                method: Search::HillClimbing.name().to_string(),
                iteration: i as i64,
                objective: obj[i],
                best: best[i],
            })
            .collect();
        // Another search's rows are not read.
        rows.push(LearningRow {
            method: Search::SimulatedAnnealing.name().to_string(),
            iteration: 10,
            objective: 99.0,
            best: 99.0,
        });
        let c = curve(Search::HillClimbing, &rows, &BARS);
        assert_eq!((c.init_best, c.at_early, c.end_best), (0.0, 8.0, 10.0));
        // The last 20% of 10 iterations: 9 and 10; one of the two is below the start.
        assert_eq!(c.poor_late, 0.5);
        assert_eq!(c.early_share(), 0.8);
    }
}
