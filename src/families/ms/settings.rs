//! # `ms_search_settings` (MS §2.3): which search settings matter, as a shipped sweep
//!
//! The paper: "the particular values given here for the parameters of the search algorithm
//! (e.g., the size of the search set, the number of iterations, and the probabilities of the
//! various perturbations) are not essential to its correct operation." The experiment file
//! sweeps the search set size N and the perturbation mix (`perturbations`, a spec key: a named
//! mix or the ten probabilities, [`crate::synthesis::perturb::PerturbationMix`]) over seeds with
//! the harness's `[sweep]`; each unit is one hill climb of an `ms_motion` setup. The number of
//! iterations needs no axis: a climb of I iterations is the first I of a longer one (tested in
//! [`crate::synthesis::search`]), so each run reports its best after an eighth, a quarter, half
//! and all of its iterations.
//!
//! Tables: `curve` (iteration, best: about [`CURVE_POINTS`] iterations and the last) and `summary`
//! (one row: set_size, perturbations, iterations, evaluations, blowups, initial_best,
//! best_at_eighth, best_at_quarter, best_at_half, best_objective, seconds); the harness adds the
//! `seed` and sweep columns and `seed_summary.csv`. Figures: `<id>_curves.png/svg` (first seed:
//! best so far against iterations, the set sizes at the paper's mix and the mixes at the paper's
//! N = 100) and the harness's `<id>_seeds.png/svg` (mean and spread over seeds per setting).
//!
//! Verdict ([`settings_rule`], a [`Rule`]; the spec's `[[history]]` gives the rule before it):
//! each run's *gain* is its final best over the best of its initial random set, so a search
//! that makes no progress gains 0 (the null). Premise: the paper's setting (N = 100, Table 2)
//! gains. A setting keeps the search working when its median gain over the seeds is at least
//! `rule.gain_fraction` of the paper's setting's; held when every other setting does, partly
//! when some do. Each median carries a 95% bootstrap interval; a check whose interval straddles
//! the threshold is inconclusive.

use super::search::{MotionJob, Params};
use crate::experiment::output::Tables;
use crate::experiment::plot::FigureSink;
use crate::experiment::plot::{Figure, Panel, Series};
use crate::experiment::report::{sig, Findings, Verdict};
use crate::experiment::resolve::{ensure, ParamError, Validate};
use crate::experiment::rows::{read_rows, table_of, Swept, TableRow};
use crate::experiment::rule::{rule_settings, rule_table, Check, Cmp, Null, Partly, Rule};
use crate::experiment::seeds::SeedMetric;
use crate::experiment::stats::median_interval;
use crate::experiment::{Error, Family, Job, RunContext};
use crate::synthesis::perturb::MixSpec;
use crate::synthesis::search::{hill_climb, learning_curve};
use crate::synthesis::BLOWUP_OBJECTIVE;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// The family.
pub struct MsSearchSettings;

/// The paper's search set size.
pub const PAPER_SET_SIZE: usize = 100;
/// The paper's perturbation mix, by name.
pub const PAPER_MIX: &str = "table2";

/// Parameters: an `ms_motion` setup, whose `set_size`, `iterations` and `perturbations` are
/// the settings swept, and the verdict's thresholds.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct SettingsParams {
    /// The motion and its search.
    #[serde(flatten)]
    pub motion: Params,
    /// The verdict's thresholds (ours).
    pub rule: SettingsRule,
}

/// The verdict's thresholds ([`settings_rule`]).
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SettingsRule {
    /// A setting keeps the search working when its median gain over the initial best is at
    /// least this fraction of the paper's setting's.
    pub gain_fraction: f64,
}

/// Points kept of each run's curve (every ⌈iterations / CURVE_POINTS⌉-th iteration and the last).
pub const CURVE_POINTS: usize = 150;

impl Validate for SettingsParams {
    fn validate(&self) -> Result<(), ParamError> {
        MotionJob(self.motion.clone()).validate()?;
        ensure(
            self.motion.iterations >= 8,
            "iterations",
            "must be at least 8 (the best is read after an eighth of them)",
        )?;
        let f = self.rule.gain_fraction;
        ensure(
            f > 0.0 && f <= 1.0,
            "rule.gain_fraction",
            "must be in (0, 1]: a fraction of the paper's setting's gain (0 would pass a search that makes no progress)",
        )
    }
}

crate::result_rows! {
    /// One row of `curve.csv`: hill climbing's best so far at one iteration.
    pub struct CurveRow {
        /// The iteration (0: the initial set).
        iteration: i64 = "iteration",
        /// The best objective after it.
        best: f64 = "best",
    }
}

crate::result_rows! {
    /// A row of `curve` as the figure reads it: the sweep's setting, when swept, before the
    /// job's [`CurveRow`].
    struct SweptCurveRow {
        /// Search set size N (the `set_size` axis).
        set_size: Swept<f64> = "set_size",
        /// The perturbation mix's name (the `perturbations` axis).
        perturbations: Swept<String> = "perturbations",
        /// The iteration (0: the initial set).
        iteration: i64 = "iteration",
        /// The best objective after it.
        best: f64 = "best",
    }
}

crate::result_rows! {
    /// The row of `summary.csv` of one setting's search.
    pub struct SettingsSummaryRow {
        /// Search set size N.
        set_size: i64 = "set_size",
        /// The perturbation mix's name.
        perturbations: String = "perturbations",
        /// Hill-climbing iterations.
        iterations: i64 = "iterations",
        /// Controllers evaluated.
        evaluations: i64 = "evaluations",
        /// Evaluations whose simulation diverged.
        blowups: i64 = "blowups",
        /// The best of the initial random set.
        initial_best: f64 = "initial_best",
        /// The best after an eighth of the iterations.
        best_at_eighth: f64 = "best_at_eighth",
        /// The best after a quarter.
        best_at_quarter: f64 = "best_at_quarter",
        /// The best after half.
        best_at_half: f64 = "best_at_half",
        /// The final best.
        best_objective: f64 = "best_objective",
        /// The search's wall time (s).
        seconds: f64 = "seconds",
    }
}

/// The name of a mix as written in the tables (`custom` for explicit probabilities).
fn mix_name(m: &MixSpec) -> String {
    match m {
        MixSpec::Named(n) => n.clone(),
        MixSpec::Explicit(_) => "custom".into(),
    }
}

impl Job for SettingsParams {
    fn params_json(&self) -> serde_json::Value {
        serde_json::to_value(self).unwrap_or_default()
    }

    fn run(&self, ctx: &RunContext) -> Result<Tables, Error> {
        let p = &self.motion;
        let problem = p.problem()?;
        let eval = |c: &crate::synthesis::controller::Controller| problem.evaluate(c);
        let pb = ctx.progress(p.iterations as u64, "hill climbing");
        let t0 = Instant::now();
        let res = ctx
            .stage("hill climbing", || {
                hill_climb(&eval, &p.hill_config(), ctx.seed, &|d| {
                    pb.set_position(d as u64)
                })
            })
            .map_err(super::other)?;
        let seconds = t0.elapsed().as_secs_f64();
        pb.finish_and_clear();
        let lc = learning_curve(&res);
        let initial: Vec<f64> = lc
            .iter()
            .filter(|e| e.iteration == 0)
            .map(|e| e.value)
            .collect();
        let initial_best = initial.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        // Best after iteration i (i = 0: the initial set).
        let best_after = |i: usize| {
            lc.iter()
                .filter(|e| e.iteration <= i)
                .map(|e| e.best)
                .fold(f64::NEG_INFINITY, f64::max)
        };
        let it = p.iterations;
        let every = it.div_ceil(CURVE_POINTS).max(1);
        let curve: Vec<CurveRow> = (0..=it)
            .filter(|i| i % every == 0 || *i == it)
            .map(|i| CurveRow {
                iteration: i as i64,
                best: best_after(i),
            })
            .collect();
        let blowups = lc.iter().filter(|e| e.value == BLOWUP_OBJECTIVE).count();
        let summary = SettingsSummaryRow {
            set_size: p.set_size as i64,
            perturbations: mix_name(&p.perturbations),
            iterations: it as i64,
            evaluations: lc.len() as i64,
            blowups: blowups as i64,
            initial_best,
            best_at_eighth: best_after(it / 8),
            best_at_quarter: best_after(it / 4),
            best_at_half: best_after(it / 2),
            best_objective: -res.best_value,
            seconds,
        };
        let rule = rule_table(&[("gain_fraction", self.rule.gain_fraction)]);
        Ok(Tables::from([
            ("curve", table_of(&curve)),
            ("summary", table_of(&[summary])),
            ("rule", rule),
        ]))
    }
}

/// One setting's bests over the seeds.
#[derive(Debug, Clone, PartialEq)]
pub struct Setting {
    /// Search set size N.
    pub set_size: usize,
    /// Mix name.
    pub mix: String,
    /// Best of the initial random set, each seed (what no search keeps).
    pub initials: Vec<f64>,
    /// Final best objective of each seed.
    pub finals: Vec<f64>,
    /// Best after half the iterations, each seed.
    pub halves: Vec<f64>,
}

fn mean(v: &[f64]) -> f64 {
    v.iter().sum::<f64>() / v.len().max(1) as f64
}

/// The bootstrap stream of the report's intervals (any fixed value: the report is the same on
/// every machine).
const BOOTSTRAP_SEED: u64 = 1;

impl Setting {
    /// Whether this is the paper's setting.
    pub fn is_paper(&self) -> bool {
        self.set_size == PAPER_SET_SIZE && self.mix == PAPER_MIX
    }
    fn label(&self) -> String {
        format!("N = {}, {}", self.set_size, mix_words(&self.mix))
    }
    /// Each seed's gain: final best over the initial set's best.
    pub fn gains(&self) -> Vec<f64> {
        self.finals
            .iter()
            .zip(&self.initials)
            .map(|(f, i)| f - i)
            .collect()
    }
    /// The median gain over the seeds with its 95% bootstrap interval.
    pub fn gain(&self) -> (f64, f64, f64) {
        median_interval(&self.gains(), BOOTSTRAP_SEED)
    }
}

fn mix_words(m: &str) -> String {
    match m {
        "table2" => "Table 2 mix".into(),
        "new_values_only" => "new values only (no adjustments)".into(),
        "one_regime_only" => "one regime at a time".into(),
        other => other.replace('_', " "),
    }
}

/// One row of the merged `summary` table: set size, mix, initial best, final best, best after
/// half the iterations.
pub type SummaryRow = (usize, String, f64, f64, f64);

/// The settings of a merged `summary` table's rows, in order of first appearance.
pub fn settings_of(rows: &[SummaryRow]) -> Vec<Setting> {
    let mut out: Vec<Setting> = Vec::new();
    for (n, m, initial, fin, half) in rows {
        let i = match out.iter().position(|s| s.set_size == *n && s.mix == *m) {
            Some(i) => i,
            None => {
                out.push(Setting {
                    set_size: *n,
                    mix: m.clone(),
                    initials: vec![],
                    finals: vec![],
                    halves: vec![],
                });
                out.len() - 1
            }
        };
        out[i].initials.push(*initial);
        out[i].finals.push(*fin);
        out[i].halves.push(*half);
    }
    out
}

/// The verdict's rule over `settings` (module docs): `None` without the paper's setting or
/// another to compare. Without a gain of the paper's setting only the premise is checked.
pub fn settings_rule(settings: &[Setting], gain_fraction: f64) -> Option<Rule> {
    let paper = settings.iter().find(|x| x.is_paper())?;
    let others: Vec<&Setting> = settings.iter().filter(|x| !x.is_paper()).collect();
    if others.is_empty() {
        return None;
    }
    let no_search = |v: f64| Null::new("no search (the initial best kept)", v);
    let (g, lo, hi) = paper.gain();
    let premise = Check::new(
        format!(
            "the paper's setting ({}) gains over its initial best",
            paper.label()
        ),
        g,
        Cmp::Above,
        0.0,
        no_search(0.0),
    )
    .ok()?
    .with_interval(lo, hi);
    let mut held = Vec::new();
    if g > 0.0 {
        for x in others {
            let (m, lo, hi) = x.gain();
            let c = Check::new(
                format!(
                    "{} gains as much as the paper's setting (median gain / the paper's)",
                    x.label()
                ),
                m / g,
                Cmp::AtLeast,
                gain_fraction,
                no_search(0.0),
            )
            .ok()?
            .with_interval(lo / g, hi / g);
            held.push(c);
        }
    }
    Some(Rule {
        premise: vec![premise],
        held,
        partly: Partly::Any,
    })
}

impl Family for MsSearchSettings {
    const KIND: &'static str = "ms_search_settings";
    type Params = SettingsParams;
    // The rule compares each setting's mean over the seeds with the seed spread.
    const SEEDS_POOLED: bool = true;
    const SEED_METRICS: &'static [SeedMetric] = &[
        SeedMetric {
            table: "summary",
            column: "best_objective",
            row: None,
            label: "best objective after all iterations",
        },
        SeedMetric {
            table: "summary",
            column: "best_at_half",
            row: None,
            label: "best objective after half the iterations",
        },
    ];
    const CAPTIONS: &'static [(&'static str, &'static str)] = &[
        (
            "curves",
            "hill climbing's best objective so far against iterations for each search setting (first seed): left, the search set size N with the paper's Table 2 mix; right, the perturbation mixes with the paper's N = 100.",
        ),
        (
            "seeds",
            "each setting's best objective after all and after half the iterations: mean over the seeds with the lowest and highest seed.",
        ),
    ];

    fn figures(&self, fig: &FigureSink, tables: &Tables) -> Result<Vec<PathBuf>, Error> {
        // The setting of each row: the sweep's columns, which the harness prepends to the
        // job's (absent without a sweep: one setting).
        let curve = SweptCurveRow::from_table(tables.require("curve")?);
        let (it, best): (Vec<f64>, Vec<f64>) =
            curve.iter().map(|r| (r.iteration as f64, r.best)).unzip();
        let summary = SettingsSummaryRow::from_table(tables.require("summary")?);
        let (n0, m0) = (
            summary.first().map_or(f64::NAN, |s| s.set_size as f64),
            summary
                .first()
                .map(|s| s.perturbations.clone())
                .unwrap_or_default(),
        );
        let size_at = |i: usize| curve[i].set_size.0.unwrap_or(n0) as usize;
        let mix_at = |i: usize| {
            curve[i]
                .perturbations
                .0
                .clone()
                .unwrap_or_else(|| m0.clone())
        };
        let mut keys: Vec<(usize, String)> = Vec::new();
        for i in 0..it.len() {
            let k = (size_at(i), mix_at(i));
            if !keys.contains(&k) {
                keys.push(k);
            }
        }
        let series_of = |pred: &dyn Fn(&(usize, String)) -> bool| -> Vec<Series> {
            keys.iter()
                .filter(|k| pred(k))
                .enumerate()
                .map(|(j, k)| {
                    let pts = (0..it.len())
                        .filter(|&i| size_at(i) == k.0 && mix_at(i) == k.1)
                        .map(|i| (it[i], best[i]))
                        .collect();
                    let label = Setting {
                        set_size: k.0,
                        mix: k.1.clone(),
                        initials: vec![],
                        finals: vec![],
                        halves: vec![],
                    }
                    .label();
                    Series::line(label, pts, j)
                })
                .collect()
        };
        let panel = |title: &str, series: Vec<Series>| Panel {
            title: title.into(),
            x_label: "iteration".into(),
            y_label: "best objective so far (larger is better)".into(),
            series,
            ..Panel::default()
        };
        let mut panels = vec![panel(
            "search set size (Table 2 mix)",
            series_of(&|k| k.1 == PAPER_MIX),
        )];
        let mixes_panel = series_of(&|k| k.0 == PAPER_SET_SIZE);
        if !mixes_panel.is_empty() {
            panels.push(panel("perturbation mix (N = 100)", mixes_panel));
        }
        panels.retain(|p| !p.series.is_empty());
        if panels.is_empty() {
            panels.push(panel("every setting", series_of(&|_| true)));
        }
        let cols = panels.len();
        fig.draw("curves", &Figure::grid(panels, cols))
    }

    fn report(&self, dir: &Path) -> Result<Findings, Error> {
        let summary: Vec<SettingsSummaryRow> = read_rows(&dir.join("summary.csv"))?;
        let rows: Vec<SummaryRow> = summary
            .into_iter()
            .map(|s| {
                let n = s.set_size as usize;
                (
                    n,
                    s.perturbations,
                    s.initial_best,
                    s.best_objective,
                    s.best_at_half,
                )
            })
            .collect();
        let settings = settings_of(&rows);
        let fraction = rule_settings(dir)?("gain_fraction");
        let mut md = String::from(
            "| setting | seeds | median gain over the initial best [95% interval] | mean initial best | mean final best | lowest final | highest final | mean best after half the iterations |\n| --- | --- | --- | --- | --- | --- | --- | --- |\n",
        );
        for x in &settings {
            let lo = x.finals.iter().copied().fold(f64::INFINITY, f64::min);
            let hi = x.finals.iter().copied().fold(f64::NEG_INFINITY, f64::max);
            let (g, glo, ghi) = x.gain();
            md.push_str(&format!(
                "| {}{} | {} | {} [{}-{}] | {} | {} | {} | {} | {} |\n",
                x.label(),
                if x.is_paper() { " (the paper's)" } else { "" },
                x.finals.len(),
                sig(g),
                sig(glo),
                sig(ghi),
                sig(mean(&x.initials)),
                sig(mean(&x.finals)),
                sig(lo),
                sig(hi),
                sig(mean(&x.halves)),
            ));
        }
        let seeds = settings.iter().map(|x| x.finals.len()).min().unwrap_or(0);
        let Some(rule) = settings_rule(&settings, fraction) else {
            return Ok(Findings {
                ours: md,
                verdict: Verdict::NotAssessed,
                rule: None,
                why: "The run lacks the paper's setting (N = 100, Table 2) or another setting to compare it with.".into(),
            });
        };
        let kept = rule
            .held
            .iter()
            .filter(|c| c.outcome() == crate::experiment::rule::Outcome::Pass)
            .count();
        Ok(Findings {
            ours: md,
            verdict: rule.verdict(),
            rule: rule.clone().into(),
            why: format!(
                "{kept} of {} other settings gain at least {} of the paper's setting's median gain over the initial best (over {seeds} seeds each, medians with 95% bootstrap intervals).{} Rule (ours): {}",
                rule.held.len(),
                sig(fraction),
                rule.lines(),
                rule.text()
            ),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn setting(n: usize, mix: &str, initials: &[f64], finals: &[f64]) -> Setting {
        Setting {
            set_size: n,
            mix: mix.into(),
            initials: initials.to_vec(),
            finals: finals.to_vec(),
            halves: finals.to_vec(),
        }
    }

    #[test]
    fn the_rule_judges_gains_over_the_initial_best_and_no_search_fails_it() {
        let paper = setting(100, "table2", &[2.0; 5], &[10.0, 11.0, 12.0, 10.5, 11.5]);
        let good = setting(25, "table2", &[3.0; 5], &[9.0, 10.0, 11.0, 9.5, 10.5]);
        // A search that makes no progress ends at its initial best, however high that is:
        // above the paper's final best minus any seed spread, so a rule on final bests alone
        // passed it.
        let stuck = setting(400, "table2", &[9.0; 5], &[9.0; 5]);
        let r = settings_rule(&[paper.clone(), good.clone()], 0.5).unwrap();
        assert_eq!(r.verdict(), Verdict::Held);
        let r = settings_rule(&[paper.clone(), good.clone(), stuck.clone()], 0.5).unwrap();
        assert_eq!(r.verdict(), Verdict::Partly);
        assert_eq!(r.held[1].outcome(), crate::experiment::rule::Outcome::Fail);
        let r = settings_rule(&[paper.clone(), stuck.clone()], 0.5).unwrap();
        assert_eq!(r.verdict(), Verdict::NotHeld);
        // The paper's setting itself stuck: the premise fails.
        let r = settings_rule(
            &[stuck.clone(), setting(100, "table2", &[9.0; 5], &[9.0; 5])],
            0.5,
        )
        .unwrap();
        assert_eq!(r.verdict(), Verdict::PremiseNotReproduced);
        // Seeds that disagree leave an interval across the threshold: inconclusive.
        let mixed = setting(25, "new_values_only", &[0.0; 5], &[0.0, 1.0, 5.0, 9.0, 9.5]);
        let r = settings_rule(&[paper.clone(), mixed], 0.5).unwrap();
        assert_eq!(r.verdict(), Verdict::Inconclusive, "{}", r.lines());
        assert!(settings_rule(&[paper], 0.5).is_none());
    }

    #[test]
    fn settings_group_rows_by_size_and_mix() {
        let row = |n: usize, f: f64| (n, "table2".to_string(), 0.0, f, f / 2.0);
        let s = settings_of(&[row(100, 1.0), row(25, 2.0), row(100, 3.0), row(25, 4.0)]);
        assert_eq!(s.len(), 2);
        assert_eq!(s[0].finals, vec![1.0, 3.0]);
        assert_eq!(s[0].gains(), vec![1.0, 3.0]);
        assert!(s[0].is_paper() && !s[1].is_paper());
    }
}
