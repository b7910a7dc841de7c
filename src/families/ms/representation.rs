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
use crate::experiment::output::{df_f64, df_str, read_csv, Table, Tables};
use crate::experiment::plot::{Figure, Panel, Series};
use crate::experiment::plot::{FigureSink, Mark};
use crate::experiment::report::{sig, Findings, Verdict};
use crate::experiment::resolve::{ensure, ParamError, Validate};
use crate::experiment::stats::median;
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

/// The representations compared, as written in the tables.
pub const REPRESENTATIONS: [&str; 2] = ["reflexes", "free_rest_lengths"];

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
            !self.motions.is_empty(),
            "motions",
            "need at least one motion",
        )?;
        for (name, p) in &self.motions {
            p.check()
                .map_err(|e| ParamError::new(&format!("motions.{name}.{}", e.key), e.message))?;
            ensure(
                p.anneal.is_none(),
                &format!("motions.{name}.anneal"),
                "the representation comparison runs hill climbing only",
            )?;
        }
        Ok(())
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
        let mut curves = Table::new(&["motion", "representation", "search", "evaluations", "best"]);
        let mut runs = Table::new(&[
            "motion",
            "representation",
            "search",
            "evaluations",
            "blowups",
            "initial_best",
            "best_objective",
            "seconds",
        ]);
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
            for rep in REPRESENTATIONS {
                // The best controller over the seeds: its trajectory gives the measures.
                let mut best: Option<(f64, crate::synthesis::controller::Trajectory)> = None;
                for k in 0..self.seeds {
                    let seed = mix_seed(ctx.seed, k as u64);
                    let base = done;
                    let progress = |d: usize| pb.set_position((base + p.set_size + d) as u64);
                    let t0 = Instant::now();
                    let (curve, best_value, traj) = if rep == "reflexes" {
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
                        curves.push(row![name.as_str(), rep, k, n, b]);
                    }
                    let blowups = curve.iter().filter(|e| e.value == BLOWUP_OBJECTIVE).count();
                    let initial_best = curve
                        .iter()
                        .filter(|e| e.iteration == 0)
                        .map(|e| e.value)
                        .fold(f64::NEG_INFINITY, f64::max);
                    runs.push(row![
                        name.as_str(),
                        rep,
                        k,
                        curve.len(),
                        blowups,
                        initial_best,
                        best_value,
                        seconds
                    ]);
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
            ("curves", curves),
            ("runs", runs),
            ("measures", meas),
        ]))
    }
}

/// The median over seeds of the best-so-far curves of one motion and representation:
/// `(evaluations, median, lowest, highest)` at every evaluation count all seeds have.
fn median_curve(
    motions: &[String],
    reps: &[String],
    seeds: &[f64],
    evals: &[f64],
    best: &[f64],
    motion: &str,
    rep: &str,
) -> Vec<(f64, f64, f64, f64)> {
    let mut by_n: BTreeMap<u64, Vec<f64>> = BTreeMap::new();
    let mut seed_set: Vec<u64> = Vec::new();
    for i in 0..motions.len() {
        if motions[i] == motion && reps[i] == rep {
            by_n.entry(evals[i] as u64).or_default().push(best[i]);
            let s = seeds[i] as u64;
            if !seed_set.contains(&s) {
                seed_set.push(s);
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
    /// The rule: reflexes end higher and reach free's final within half the budget.
    pub fn supports(&self) -> bool {
        self.reflex_final > self.free_final
            && self
                .reflex_reaches_free_at
                .is_some_and(|n| n <= 0.5 * self.budget)
    }
}

/// The rule's judgement of each motion in a `curves` table.
pub fn judge(curves: &Table) -> Vec<MotionJudgement> {
    let (m, r) = (curves.strs("motion"), curves.strs("representation"));
    let (s, n, b) = (
        curves.f64s("search"),
        curves.f64s("evaluations"),
        curves.f64s("best"),
    );
    judge_columns(&m, &r, &s, &n, &b)
}

fn judge_columns(
    m: &[String],
    r: &[String],
    s: &[f64],
    n: &[f64],
    b: &[f64],
) -> Vec<MotionJudgement> {
    let mut names: Vec<String> = Vec::new();
    for x in m {
        if !names.contains(x) {
            names.push(x.clone());
        }
    }
    names
        .into_iter()
        .map(|name| {
            let refl = median_curve(m, r, s, n, b, &name, REPRESENTATIONS[0]);
            let free = median_curve(m, r, s, n, b, &name, REPRESENTATIONS[1]);
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

/// The verdict of the judgements: held when every motion supports the claim, partly when some
/// do, did not hold when none does.
pub fn verdict_of(j: &[MotionJudgement]) -> Verdict {
    let k = j.iter().filter(|x| x.supports()).count();
    Verdict::graded(!j.is_empty() && k == j.len(), k > 0)
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
        "hill climbing with the 12 canonical reflexes and with free rest lengths, same search and budget: the best objective so far against evaluations, median over the seeds (solid or long dashes) with the lowest and highest seed (thin dots for the reflexes, short dashes for free rest lengths, same colours).",
    )];

    fn figures(&self, fig: &FigureSink, tables: &Tables) -> Result<Vec<PathBuf>, Error> {
        let c = tables.require("curves")?;
        let (m, r) = (c.strs("motion"), c.strs("representation"));
        let (s, n, b) = (c.f64s("search"), c.f64s("evaluations"), c.f64s("best"));
        let mut names: Vec<String> = Vec::new();
        for x in &m {
            if !names.contains(x) {
                names.push(x.clone());
            }
        }
        let label = |rep: &str| {
            if rep == REPRESENTATIONS[0] {
                "12 canonical reflexes"
            } else {
                "free rest lengths"
            }
        };
        let panels: Vec<Panel> = names
            .iter()
            .map(|name| {
                let mut series = Vec::new();
                for (k, rep) in REPRESENTATIONS.iter().enumerate() {
                    let mc = median_curve(&m, &r, &s, &n, &b, name, rep);
                    series.push(Series::line(
                        format!("{}: median over seeds", label(rep)),
                        mc.iter().map(|p| (p.0, p.1)).collect(),
                        k,
                    ));
                    for pick in [2usize, 3] {
                        let pts = mc
                            .iter()
                            .map(|p| (p.0, if pick == 2 { p.2 } else { p.3 }))
                            .collect();
                        let lab = if pick == 2 {
                            format!("{}: lowest and highest seed", label(rep))
                        } else {
                            String::new()
                        };
                        series.push(Series::line(lab, pts, k).mark(Mark::Pattern {
                            dash: 2 + 4 * k as u32,
                            gap: 5,
                        }));
                    }
                }
                // The rule's bar: free's median final, to be reached by the reflexes' median
                // within half the evaluations.
                let free = median_curve(&m, &r, &s, &n, &b, name, REPRESENTATIONS[1]);
                if let Some(&(n_end, f_end, _, _)) = free.last() {
                    series.push(
                        Series::line(
                            "rule: free's median final, reached by half the evaluations",
                            vec![(0.0, f_end), (0.5 * n_end, f_end)],
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
        let c = read_csv(&dir.join("curves.csv"))?;
        let (m, r) = (df_str(&c, "motion")?, df_str(&c, "representation")?);
        let (s, n, b) = (
            df_f64(&c, "search")?,
            df_f64(&c, "evaluations")?,
            df_f64(&c, "best")?,
        );
        let j = judge_columns(&m, &r, &s, &n, &b);
        let runs = read_csv(&dir.join("runs.csv"))?;
        let (rm, rr) = (df_str(&runs, "motion")?, df_str(&runs, "representation")?);
        let (blow, evals, secs) = (
            df_f64(&runs, "blowups")?,
            df_f64(&runs, "evaluations")?,
            df_f64(&runs, "seconds")?,
        );
        let finals = df_f64(&runs, "best_objective")?;
        let mut md = String::from(
            "| motion | representation | median final best | lowest | highest | evaluations per run | blow-ups | seconds per run |\n| --- | --- | --- | --- | --- | --- | --- | --- |\n",
        );
        for x in &j {
            for rep in REPRESENTATIONS {
                let idx: Vec<usize> = (0..rm.len())
                    .filter(|&i| rm[i] == x.motion && rr[i] == rep)
                    .collect();
                let f: Vec<f64> = idx.iter().map(|&i| finals[i]).collect();
                let lo = f.iter().copied().fold(f64::INFINITY, f64::min);
                let hi = f.iter().copied().fold(f64::NEG_INFINITY, f64::max);
                let bl: f64 = idx.iter().map(|&i| blow[i]).sum();
                let ev: f64 = idx.iter().map(|&i| evals[i]).sum();
                let sec: f64 = idx.iter().map(|&i| secs[i]).sum::<f64>() / idx.len().max(1) as f64;
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
        let mut lines = Vec::new();
        for x in &j {
            lines.push(format!(
                "{}: reflexes {} vs free {} (median final best); the reflexes' median curve reaches free's final {} ({}): {}",
                title_of(&x.motion),
                sig(x.reflex_final),
                sig(x.free_final),
                match x.reflex_reaches_free_at {
                    Some(e) => format!("after {e} of {} evaluations", x.budget),
                    None => "never".into(),
                },
                if x.reflex_final > x.free_final {
                    "reflexes end higher"
                } else {
                    "free rest lengths end at least as high"
                },
                if x.supports() {
                    "supports the claim"
                } else {
                    "does not support it"
                }
            ));
        }
        let verdict = verdict_of(&j);
        Ok(Findings {
            ours: md,
            verdict,
            why: format!(
                "{}. Rule (fixed before the run, thresholds ours): a motion supports the claim when the reflexes' median final best exceeds free rest lengths' and their median curve reaches free's median final within half the evaluations (free at least twice as slow); held needs both motions, partly one. \"Less coordinated\" is not measured apart from the objective: the measures table gives each representation's best motion.",
                lines.join("; ")
            ),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rows(data: &[(&str, &str, f64, f64, f64)]) -> Vec<MotionJudgement> {
        let m: Vec<String> = data.iter().map(|d| d.0.to_string()).collect();
        let r: Vec<String> = data.iter().map(|d| d.1.to_string()).collect();
        let s: Vec<f64> = data.iter().map(|d| d.2).collect();
        let n: Vec<f64> = data.iter().map(|d| d.3).collect();
        let b: Vec<f64> = data.iter().map(|d| d.4).collect();
        judge_columns(&m, &r, &s, &n, &b)
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
        assert!(good[0].supports());
        assert_eq!(verdict_of(&good), Verdict::Held);
        // Higher at the end but only after 80 of 100: free is not twice as slow.
        let slow = rows(&[
            ("a", "reflexes", 0.0, 40.0, 4.0),
            ("a", "reflexes", 0.0, 80.0, 5.0),
            ("a", "reflexes", 0.0, 100.0, 6.0),
            ("a", "free_rest_lengths", 0.0, 100.0, 5.0),
        ]);
        assert!(!slow[0].supports());
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
