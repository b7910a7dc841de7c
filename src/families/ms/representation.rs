//! # `ms_representation` (MS §2.2): the 12 canonical reflexes against free rest lengths
//!
//! The paper's claim: "an earlier, less-compact representation in which an actuation reflex
//! could be an arbitrary combination of spring rest lengths produced less coordinated motions,
//! and the search process was much slower." For each motion of `[params.motions]` (the spider
//! leap and the poodle somersault, each a full `ms_motion` setup) the job runs parallel hill
//! climbing with the reflex representation and with free rest lengths
//! ([`crate::synthesis::free`]): the same search set, iterations, batches, perturbation mix and
//! seeds (seed k of both representations is `mix_seed(seed, k)`).
//!
//! Tables: `curves` (motion, representation, search, evaluations, best: the best objective so
//! far, every `curve_every` evaluations and at the end; `search` k is the k-th independent
//! search, seeded `mix_seed(seed, k)`), `runs` (motion, representation, search,
//! evaluations, blowups, initial_best, best_objective, seconds) and `measures` (motion,
//! representation, measure, value: [`super::search::measures`] of each representation's best
//! controller over the seeds). Figure `<id>_search.png/svg`: median best-so-far over the seeds
//! against evaluations, with the lowest and highest seed, one panel per motion.
//!
//! The verdict rule (fixed in `experiments/ms_representation.toml` before the first run;
//! thresholds ours): a motion supports the claim when the reflexes' median final best exceeds the
//! free representation's **and** the reflexes' median curve reaches the free representation's
//! median final best within half the evaluations (free at least twice as slow). Held: both
//! motions; partly: one; did not hold: none.

use super::search::{measure_values, Params};
use crate::experiment::output::{Table, Tables};
use crate::experiment::plot::{Figure, Panel, Series};
use crate::experiment::plot::{FigureSink, Mark};
use crate::experiment::report::{sig, Findings};
use crate::experiment::resolve::{ensure, ParamError, Validate};
use crate::experiment::rows::{read_rows, table_of, TableRow};
use crate::experiment::rule::{
    read_rule, rule_setting, rule_table_of, shown, Check, Cmp, Null, Outcome, Partly, Rule,
};
use crate::experiment::stats::{median, median_difference_interval};
use crate::experiment::{Error, Family, Job, RunContext};
use crate::row;
use crate::seed::mix_seed;
use crate::synthesis::search::{hill_climb, hill_climb_free, learning_curve};
use crate::synthesis::BLOWUP_OBJECTIVE;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// The family.
pub struct MsRepresentation;

/// A controller representation compared.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Representation {
    /// The 12 canonical deformation reflexes (the paper's).
    Reflexes,
    /// Free rest lengths: each regime an arbitrary vector of spring rest lengths.
    FreeRestLengths,
}

impl Representation {
    /// Both, in table order.
    pub const ALL: [Representation; 2] =
        [Representation::Reflexes, Representation::FreeRestLengths];

    /// Its name in the tables.
    pub const fn name(self) -> &'static str {
        match self {
            Representation::Reflexes => "reflexes",
            Representation::FreeRestLengths => "free_rest_lengths",
        }
    }

    /// Its name in figure legends.
    fn label(self) -> &'static str {
        match self {
            Representation::Reflexes => "12 canonical reflexes",
            Representation::FreeRestLengths => "free rest lengths",
        }
    }
}

/// The representations compared, as written in the tables.
pub const REPRESENTATIONS: [&str; 2] =
    [Representation::ALL[0].name(), Representation::ALL[1].name()];
/// The reflexes' name in the tables.
const REFLEXES: &str = Representation::Reflexes.name();
/// Free rest lengths' name in the tables.
const FREE: &str = Representation::FreeRestLengths.name();

/// Parameters of `ms_representation`.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RepresentationParams {
    /// Independent searches per motion and representation.
    pub seeds: usize,
    /// Evaluations between two points of the `curves` table.
    pub curve_every: usize,
    /// The motions, by name, each a full `ms_motion` setup (its search settings are used for
    /// both representations).
    pub motions: BTreeMap<String, Params>,
    /// The verdict's bar (ours; [`representation_rule`]).
    pub rule: RepresentationRule,
}

/// The verdict's bar (ours: the paper says the free representation's "search process was much
/// slower", without a number).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RepresentationRule {
    /// Much slower: the reflexes' median curve reaches free's median final best within this
    /// share of the evaluations.
    pub reach_fraction: f64,
}

/// The most seeds per motion and representation.
pub const MAX_SEEDS: usize = 32;

impl Validate for RepresentationParams {
    fn validate(&self) -> Result<(), ParamError> {
        ensure(
            (1..=MAX_SEEDS).contains(&self.seeds),
            "seeds",
            format!("must be 1 to {MAX_SEEDS}"),
        )?;
        ensure(self.curve_every >= 1, "curve_every", "must be at least 1")?;
        ensure(
            self.rule.reach_fraction > 0.0 && self.rule.reach_fraction < 1.0,
            "rule.reach_fraction",
            "must be in (0, 1): free rest lengths reach their own final at the end (1)",
        )?;
        ensure(
            !self.motions.is_empty(),
            "motions",
            "need at least one motion",
        )?;
        for (name, p) in &self.motions {
            p.check()
                .map_err(|e| ParamError::new(format!("motions.{name}.{}", e.key), e.message))?;
            ensure(
                p.anneal.is_none(),
                &format!("motions.{name}.anneal"),
                "the representation comparison runs hill climbing only",
            )?;
        }
        Ok(())
    }
}

crate::result_rows! {
    /// One row of `curves.csv`: one search's best so far after some evaluations.
    pub struct CurvePointRow {
        /// The motion's name (a key of the spec's `motions`).
        motion: String = "motion",
        /// The representation ([`REPRESENTATIONS`]).
        representation: String = "representation",
        /// The search's index among the seeds.
        search: i64 = "search",
        /// Evaluations so far.
        evaluations: i64 = "evaluations",
        /// The best objective after them.
        best: f64 = "best",
    }
}

crate::result_rows! {
    /// One row of `runs.csv`: one search.
    pub struct RunRow {
        /// The motion's name.
        motion: String = "motion",
        /// The representation ([`REPRESENTATIONS`]).
        representation: String = "representation",
        /// The search's index among the seeds.
        search: i64 = "search",
        /// Controllers evaluated.
        evaluations: i64 = "evaluations",
        /// Evaluations whose simulation diverged.
        blowups: i64 = "blowups",
        /// The best of the initial random set.
        initial_best: f64 = "initial_best",
        /// The final best.
        best_objective: f64 = "best_objective",
        /// The search's wall time (s).
        seconds: f64 = "seconds",
    }
}

/// `(evaluations, best so far)` of one run at every `every` evaluations and the last.
fn thin(curve: &[(usize, f64)], every: usize) -> Vec<(usize, f64)> {
    curve
        .iter()
        .enumerate()
        .filter(|(i, _)| (i + 1) % every == 0 || i + 1 == curve.len())
        .map(|(_, p)| *p)
        .collect()
}

impl Job for RepresentationParams {
    fn params_json(&self) -> serde_json::Value {
        serde_json::to_value(self).unwrap_or_default()
    }

    fn run(&self, ctx: &RunContext) -> Result<Tables, Error> {
        let (mut curves, mut runs) = (Vec::new(), Vec::new());
        let mut meas = Table::new(&["motion", "representation", "measure", "value"]);
        let total: usize = self
            .motions
            .values()
            .map(|p| 2 * self.seeds * (p.iterations + p.set_size))
            .sum();
        let pb = ctx.progress(total as u64, "hill climbing, both representations");
        let mut done = 0usize;
        for (name, p) in &self.motions {
            let problem = p.problem()?;
            let cfg = p.hill_config();
            let springs = problem.setup.model.lattice.springs.len();
            for representation in Representation::ALL {
                let rep = representation.name();
                // The best controller over the seeds: its trajectory gives the measures.
                let mut best: Option<(f64, crate::synthesis::controller::Trajectory)> = None;
                for k in 0..self.seeds {
                    let seed = mix_seed(ctx.seed, k as u64);
                    let base = done;
                    let progress = |d: usize| pb.set_position((base + p.set_size + d) as u64);
                    let t0 = Instant::now();
                    let (curve, best_value, traj) = if representation == Representation::Reflexes {
                        let eval =
                            |c: &crate::synthesis::controller::Controller| problem.evaluate(c);
                        let r = ctx
                            .stage(&format!("{name}: reflexes"), || {
                                hill_climb(&eval, &cfg, seed, &progress)
                            })
                            .map_err(super::other)?;
                        let tr = problem.trajectory(&r.best).ok();
                        (learning_curve(&r), -r.best_value, tr)
                    } else {
                        let eval =
                            |c: &crate::synthesis::free::FreeController| problem.evaluate_free(c);
                        let r = ctx
                            .stage(&format!("{name}: free rest lengths"), || {
                                hill_climb_free(&eval, &cfg, springs, seed, &progress)
                            })
                            .map_err(super::other)?;
                        let tr = problem.trajectory_free(&r.best).ok();
                        (learning_curve(&r), -r.best_value, tr)
                    };
                    let seconds = t0.elapsed().as_secs_f64();
                    done += p.set_size + p.iterations;
                    let points: Vec<(usize, f64)> = curve
                        .iter()
                        .enumerate()
                        .map(|(i, e)| (i + 1, e.best))
                        .collect();
                    for (n, b) in thin(&points, self.curve_every) {
                        curves.push(CurvePointRow {
                            motion: name.clone(),
                            representation: rep.to_string(),
                            search: k as i64,
                            evaluations: n as i64,
                            best: b,
                        });
                    }
                    let blowups = curve.iter().filter(|e| e.value == BLOWUP_OBJECTIVE).count();
                    let initial_best = curve
                        .iter()
                        .filter(|e| e.iteration == 0)
                        .map(|e| e.value)
                        .fold(f64::NEG_INFINITY, f64::max);
                    runs.push(RunRow {
                        motion: name.clone(),
                        representation: rep.to_string(),
                        search: k as i64,
                        evaluations: curve.len() as i64,
                        blowups: blowups as i64,
                        initial_best,
                        best_objective: best_value,
                        seconds,
                    });
                    if let Some(tr) = traj {
                        if best.as_ref().is_none_or(|(v, _)| best_value > *v) {
                            best = Some((best_value, tr));
                        }
                    }
                }
                if let Some((_, tr)) = best {
                    for (m, v) in measure_values(&problem.objective, &tr) {
                        meas.push(row![name.as_str(), rep, m, v]);
                    }
                }
            }
        }
        pb.finish_and_clear();
        Ok(Tables::from([
            ("curves", table_of(&curves)),
            ("runs", table_of(&runs)),
            ("measures", meas),
            ("rule", rule_table_of(&self.rule)?),
        ]))
    }
}

/// The median over seeds of the best-so-far curves of one motion and representation:
/// `(evaluations, median, lowest, highest)` at every evaluation count all seeds have.
fn median_curve(curves: &[CurvePointRow], motion: &str, rep: &str) -> Vec<(f64, f64, f64, f64)> {
    let mut by_n: BTreeMap<u64, Vec<f64>> = BTreeMap::new();
    let mut seed_set: Vec<i64> = Vec::new();
    for c in curves {
        if c.motion == motion && c.representation == rep {
            by_n.entry(c.evaluations as u64).or_default().push(c.best);
            if !seed_set.contains(&c.search) {
                seed_set.push(c.search);
            }
        }
    }
    by_n.into_iter()
        .filter(|(_, v)| v.len() == seed_set.len())
        .map(|(n, v)| {
            let lo = v.iter().copied().fold(f64::INFINITY, f64::min);
            let hi = v.iter().copied().fold(f64::NEG_INFINITY, f64::max);
            (n as f64, median(&v), lo, hi)
        })
        .collect()
}

/// One motion's judgement under the rule: (reflex median final, free median final, evaluations
/// the reflex median curve needs to reach free's final, the budget, supports the claim).
#[derive(Debug, Clone, PartialEq)]
pub struct MotionJudgement {
    /// The motion.
    pub motion: String,
    /// Median final best objective of the reflexes.
    pub reflex_final: f64,
    /// Median final best objective of free rest lengths.
    pub free_final: f64,
    /// Evaluations at which the reflexes' median curve first reaches `free_final` (None: never).
    pub reflex_reaches_free_at: Option<f64>,
    /// Evaluations per run.
    pub budget: f64,
}

impl MotionJudgement {
    /// The share of the evaluations the reflexes' median curve needs to reach free's median
    /// final best (infinite: never).
    pub fn reach_share(&self) -> f64 {
        self.reflex_reaches_free_at
            .map_or(f64::INFINITY, |n| n / self.budget)
    }
}

/// The verdict's rule, per motion `j[k]` (with `intervals[k]`, the 95% bootstrap interval of
/// the reflexes' median final best minus free's): (a) the reflexes end higher than free rest
/// lengths (median over seeds; null: free rest lengths themselves, 0), (b) their median curve
/// reaches free's median final within `r.reach_fraction` of the evaluations (null: free rest
/// lengths, which reach their own final at the end, 1). Held needs every motion's checks;
/// partly one motion's.
pub fn representation_rule(
    j: &[MotionJudgement],
    intervals: &[(f64, f64)],
    r: &RepresentationRule,
) -> Option<Rule> {
    let mut held = Vec::new();
    let mut groups = Vec::new();
    for (k, x) in j.iter().enumerate() {
        let free = "free rest lengths themselves";
        let (lo, hi) = intervals.get(k).copied().unwrap_or((f64::NAN, f64::NAN));
        let higher = Check::new(
            format!(
                "{}: reflexes' median final best minus free's",
                title_of(&x.motion)
            ),
            x.reflex_final - x.free_final,
            Cmp::Above,
            0.0,
            Null::new(free, 0.0),
        )
        .map(|c| {
            if lo.is_finite() && hi.is_finite() {
                c.with_interval(lo, hi)
            } else {
                c
            }
        });
        held.push(higher);
        held.push(Check::new(
            format!(
                "{}: share of the evaluations the reflexes' median curve needs to reach free's median final",
                title_of(&x.motion)
            ),
            x.reach_share(),
            Cmp::AtMost,
            r.reach_fraction,
            Null::new(free, 1.0),
        ));
        groups.push(vec![2 * k, 2 * k + 1]);
    }
    if held.is_empty() {
        return None;
    }
    Rule::gated(vec![], held, Partly::AnyOf(groups))
}

/// The rule's judgement of each motion in a `curves` table.
pub fn judge(curves: &Table) -> Vec<MotionJudgement> {
    judge_rows(&CurvePointRow::from_table(curves))
}

/// The motions of `curves`, in order of first appearance.
fn motions_of(curves: &[CurvePointRow]) -> Vec<String> {
    let mut names: Vec<String> = Vec::new();
    for c in curves {
        if !names.contains(&c.motion) {
            names.push(c.motion.clone());
        }
    }
    names
}

/// The rule's judgement of each motion in `curves.csv`'s rows.
fn judge_rows(curves: &[CurvePointRow]) -> Vec<MotionJudgement> {
    motions_of(curves)
        .into_iter()
        .map(|name| {
            let refl = median_curve(curves, &name, REFLEXES);
            let free = median_curve(curves, &name, FREE);
            let last = |c: &[(f64, f64, f64, f64)]| c.last().map_or(f64::NAN, |p| p.1);
            let free_final = last(&free);
            MotionJudgement {
                reflex_final: last(&refl),
                free_final,
                reflex_reaches_free_at: refl.iter().find(|p| p.1 >= free_final).map(|p| p.0),
                budget: refl.last().map_or(f64::NAN, |p| p.0),
                motion: name,
            }
        })
        .collect()
}

fn title_of(motion: &str) -> String {
    match motion {
        "spider" => "Spider leap (pyramid)".into(),
        "poodle" => "Poodle somersault (cube)".into(),
        other => other.to_string(),
    }
}

impl Family for MsRepresentation {
    const KIND: &'static str = "ms_representation";
    type Params = RepresentationParams;
    const CAPTIONS: &'static [(&'static str, &'static str)] = &[(
        "search",
        "hill climbing with the 12 canonical reflexes and with free rest lengths, same search and budget: the best objective so far against evaluations, median over the seeds (solid for the reflexes, dashed for free rest lengths) over a shaded band from the lowest to the highest seed, in the same colour.",
    )];

    fn figures(&self, fig: &FigureSink, tables: &Tables) -> Result<Vec<PathBuf>, Error> {
        let curves = CurvePointRow::from_table(tables.require("curves")?);
        let names = motions_of(&curves);

        let panels: Vec<Panel> = names
            .iter()
            .map(|name| {
                let mut series = Vec::new();
                for (k, representation) in Representation::ALL.iter().enumerate() {
                    let rep = representation.name();
                    let mc = median_curve(&curves, name, rep);
                    series.push(Series::line(
                        format!("{}: median over seeds", representation.label()),
                        mc.iter().map(|p| (p.0, p.1)).collect(),
                        k,
                    ));
                    // The seeds' spread as a band under the median.
                    let lower: Vec<(f64, f64)> = mc.iter().map(|p| (p.0, p.2)).collect();
                    let upper: Vec<(f64, f64)> = mc.iter().map(|p| (p.0, p.3)).collect();
                    series.insert(
                        0,
                        Series::band(
                            format!("{}: lowest to highest seed", representation.label()),
                            &lower,
                            &upper,
                            k,
                        ),
                    );
                }
                // The rule's bar: free's median final, to be reached by the reflexes' median
                // within the rule's share of the evaluations.
                let free = median_curve(&curves, name, FREE);
                if let (Some(&(n_end, f_end, _, _)), Some(share)) =
                    (free.last(), rule_setting(tables, "reach_fraction"))
                {
                    series.push(
                        Series::line(
                            format!(
                                "rule: free's median final, reached within {}% of the evaluations",
                                sig(100.0 * share)
                            ),
                            vec![(0.0, f_end), (share * n_end, f_end)],
                            7,
                        )
                        .mark(Mark::Dashed),
                    );
                }
                Panel {
                    title: title_of(name),
                    x_label: "evaluations".into(),
                    y_label: "best objective so far (larger is better)".into(),
                    series,
                    ..Panel::default()
                }
            })
            .collect();
        fig.draw("search", &Figure::grid(panels, 2))
    }

    fn report(&self, dir: &Path) -> Result<Findings, Error> {
        let curves: Vec<CurvePointRow> = read_rows(&dir.join("curves.csv"))?;
        let j = judge_rows(&curves);
        let runs: Vec<RunRow> = read_rows(&dir.join("runs.csv"))?;
        let runs_of = |motion: &str, rep: &str| -> Vec<&RunRow> {
            runs.iter()
                .filter(|r| r.motion == motion && r.representation == rep)
                .collect()
        };
        let mut md = String::from(
            "| motion | representation | median final best | lowest | highest | evaluations per run | blow-ups | seconds per run |\n| --- | --- | --- | --- | --- | --- | --- | --- |\n",
        );
        for x in &j {
            for rep in REPRESENTATIONS {
                let idx = runs_of(&x.motion, rep);
                let f: Vec<f64> = idx.iter().map(|r| r.best_objective).collect();
                let lo = f.iter().copied().fold(f64::INFINITY, f64::min);
                let hi = f.iter().copied().fold(f64::NEG_INFINITY, f64::max);
                let bl: f64 = idx.iter().map(|r| r.blowups as f64).sum();
                let ev: f64 = idx.iter().map(|r| r.evaluations as f64).sum();
                let sec: f64 = idx.iter().map(|r| r.seconds).sum::<f64>() / idx.len().max(1) as f64;
                md.push_str(&format!(
                    "| {} | {} | {} | {} | {} | {} | {} of {} | {} |\n",
                    title_of(&x.motion),
                    rep.replace('_', " "),
                    sig(median(&f)),
                    sig(lo),
                    sig(hi),
                    ev / idx.len().max(1) as f64,
                    bl,
                    ev,
                    sig(sec)
                ));
            }
        }
        let bars: RepresentationRule = read_rule(dir)?;
        // Per motion: the reflexes' median final best minus free's, with its interval over
        // the seeds (seeded by the motion's place, so the report is the same everywhere).
        let intervals: Vec<(f64, f64)> = j
            .iter()
            .enumerate()
            .map(|(k, x)| {
                let of = |rep: &str| -> Vec<f64> {
                    runs_of(&x.motion, rep)
                        .iter()
                        .map(|r| r.best_objective)
                        .collect()
                };
                let (_, lo, hi) = median_difference_interval(&of(REFLEXES), &of(FREE), k as u64);
                (lo, hi)
            })
            .collect();
        let rule = representation_rule(&j, &intervals, &bars);
        let (verdict, lines, text) = shown(rule.as_ref(), " No rule: a bar its null meets.");
        let seeds = j.first().map_or(0, |x| runs_of(&x.motion, REFLEXES).len());
        let mut summary = Vec::new();
        for (k, x) in j.iter().enumerate() {
            let supports = rule.as_ref().is_some_and(|r| {
                r.held[2 * k..2 * k + 2]
                    .iter()
                    .all(|c| c.outcome() == Outcome::Pass)
            });
            summary.push(format!(
                "{}: reflexes {} vs free {} (median final best); the reflexes' median curve reaches free's final {}: {}",
                title_of(&x.motion),
                sig(x.reflex_final),
                sig(x.free_final),
                match x.reflex_reaches_free_at {
                    Some(e) => format!("after {e} of {} evaluations", x.budget),
                    None => "never".into(),
                },
                if supports {
                    "supports the claim"
                } else {
                    "does not support it"
                }
            ));
        }
        Ok(Findings {
            ours: md,
            verdict,
            rule: rule.clone(),
            why: format!(
                "{}. Checks over {} seeds per motion and representation:{lines} Rule (fixed before the run, bar ours, in the spec's [params.rule]): {text} \"Less coordinated\" is not measured apart from the objective: the measures table gives each representation's best motion.",
                summary.join("; "),
                seeds
            ),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    use crate::experiment::report::Verdict;

    fn verdict_of(j: &[MotionJudgement]) -> Verdict {
        let bars = RepresentationRule {
            reach_fraction: 0.5,
        };
        representation_rule(j, &[], &bars).unwrap().verdict()
    }

    fn rows(data: &[(&str, &str, f64, f64, f64)]) -> Vec<MotionJudgement> {
        let curves: Vec<CurvePointRow> = data
            .iter()
            .map(|d| CurvePointRow {
                motion: d.0.to_string(),
                representation: d.1.to_string(),
                search: d.2 as i64,
                evaluations: d.3 as i64,
                best: d.4,
            })
            .collect();
        judge_rows(&curves)
    }

    #[test]
    fn the_rule_needs_higher_and_twice_as_fast_and_contradicting_rows_fail() {
        // Reflexes reach free's final (5) by 40 of 100 evaluations and end higher: supports.
        let good = rows(&[
            ("a", "reflexes", 0.0, 40.0, 5.0),
            ("a", "reflexes", 0.0, 100.0, 9.0),
            ("a", "free_rest_lengths", 0.0, 40.0, 1.0),
            ("a", "free_rest_lengths", 0.0, 100.0, 5.0),
        ]);
        assert_eq!(verdict_of(&good), Verdict::Held);
        // Higher at the end but only after 80 of 100: free is not twice as slow.
        let slow = rows(&[
            ("a", "reflexes", 0.0, 40.0, 4.0),
            ("a", "reflexes", 0.0, 80.0, 5.0),
            ("a", "reflexes", 0.0, 100.0, 6.0),
            ("a", "free_rest_lengths", 0.0, 100.0, 5.0),
        ]);
        assert_eq!(verdict_of(&slow), Verdict::NotHeld);
        // Free ends higher (the contradicting data): the lowest tier.
        let worse = rows(&[
            ("a", "reflexes", 0.0, 100.0, 3.0),
            ("a", "free_rest_lengths", 0.0, 100.0, 5.0),
            ("b", "reflexes", 0.0, 100.0, 3.0),
            ("b", "free_rest_lengths", 0.0, 100.0, 5.0),
        ]);
        assert_eq!(verdict_of(&worse), Verdict::NotHeld);
        // One motion each way: partly.
        let mixed = rows(&[
            ("a", "reflexes", 0.0, 40.0, 5.0),
            ("a", "reflexes", 0.0, 100.0, 9.0),
            ("a", "free_rest_lengths", 0.0, 100.0, 5.0),
            ("b", "reflexes", 0.0, 100.0, 3.0),
            ("b", "free_rest_lengths", 0.0, 100.0, 5.0),
        ]);
        assert_eq!(verdict_of(&mixed), Verdict::Partly);
    }

    #[test]
    fn median_curves_use_every_seed() {
        let j = rows(&[
            ("a", "reflexes", 0.0, 10.0, 1.0),
            ("a", "reflexes", 1.0, 10.0, 3.0),
            ("a", "reflexes", 2.0, 10.0, 8.0),
            ("a", "free_rest_lengths", 0.0, 10.0, 2.0),
            ("a", "free_rest_lengths", 1.0, 10.0, 2.0),
            ("a", "free_rest_lengths", 2.0, 10.0, 9.0),
        ]);
        assert_eq!(j[0].reflex_final, 3.0);
        assert_eq!(j[0].free_final, 2.0);
        assert_eq!(median(&[1.0, 4.0]), 2.5);
    }
}
