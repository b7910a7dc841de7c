//! The report of `na_transforms_ablation`: the verdict's rule over the tasks and net seeds.

use super::job::{ControlRow, ErrorsRow, NetRow, SeedRow};
use super::{AblationRule, WITHIN_TOLERANCE};
use crate::emulator::catalog::TransformSet;
use crate::experiment::report::{sig, Findings};
use crate::experiment::rows::read_rows;
use crate::experiment::rule::{rule_settings, shown, Check, Cmp, Null, Partly, Rule};
use crate::experiment::stats::{bootstrap_intervals, median_with_infinities};
use crate::experiment::{other, Error};
use std::path::Path;

/// One variant's measures: its name, 40-step mean rollout error, the simulator final error of
/// the control learned through it and that descent's best iteration (0: it never improved on
/// its start).
#[derive(Debug, Clone, PartialEq)]
pub struct VariantRow {
    /// The variant's name.
    pub variant: String,
    /// 40-step mean rollout error (infinite when training failed).
    pub rollout40: f64,
    /// Simulator final error of its control (infinite when nothing was learned).
    pub simulator: f64,
    /// The descent's best iteration.
    pub best_iteration: usize,
}

/// One task's measures per variant, in the spec's variant order, and the simulator final
/// error of the start's controls (the control checks' null).
#[derive(Debug, Clone, PartialEq)]
pub struct TaskRows {
    /// The task.
    pub task: String,
    /// Each variant's measures.
    pub rows: Vec<VariantRow>,
    /// The start's controls replayed on the simulator: their final error.
    pub start: f64,
}

impl TaskRows {
    fn get(&self, v: TransformSet) -> Option<&VariantRow> {
        self.rows.iter().find(|r| r.variant == v.name())
    }

    /// The 40-step errors along plain → delta → delta_frame → full (infinite where missing).
    fn chain(&self) -> Vec<f64> {
        TransformSet::ALL
            .iter()
            .map(|&v| self.get(v).map_or(f64::INFINITY, |r| finite(r.rollout40)))
            .collect()
    }

    /// The largest ratio of an added operator's 40-step error to the previous variant's.
    pub fn worst_operator_ratio(&self) -> f64 {
        self.chain()
            .windows(2)
            .map(|w| ratio(w[1], w[0]))
            .fold(f64::NEG_INFINITY, f64::max)
    }

    /// The simulator final error of the control learned through `v` (infinite where missing).
    fn simulator(&self, v: TransformSet) -> f64 {
        self.get(v).map_or(f64::INFINITY, |r| finite(r.simulator))
    }

    /// The variants whose descent never improved on its start (best iteration 0).
    pub fn stuck(&self) -> Vec<&str> {
        self.rows
            .iter()
            .filter(|r| r.best_iteration == 0 && r.simulator.is_finite())
            .map(|r| r.variant.as_str())
            .collect()
    }
}

/// NaN (a failed measure) as infinite.
fn finite(x: f64) -> f64 {
    if x.is_nan() {
        f64::INFINITY
    } else {
        x
    }
}

/// a / b, infinite over infinite is NaN (fails every check), finite over infinite 0.
fn ratio(a: f64, b: f64) -> f64 {
    if b.is_infinite() && a.is_finite() {
        0.0
    } else {
        a / b
    }
}

/// Bootstrap seed of the intervals over net seeds (fixed, so a report is the same everywhere).
const BOOTSTRAP_SEED: u64 = 1;

/// One task's values of checks (a)-(d) at one net seed, and each check's null there.
fn task_values(t: &TaskRows) -> ([f64; 4], [f64; 4]) {
    let e = t.chain();
    let (plain, full) = (e[0], e[e.len() - 1]);
    let (sf, sp) = (
        t.simulator(TransformSet::Full),
        t.simulator(TransformSet::Plain),
    );
    (
        [
            ratio(full, plain),
            t.worst_operator_ratio(),
            sf,
            ratio(sf, sp),
        ],
        [1.0, 1.0, t.start, 1.0],
    )
}

/// The verdict's rule (module docs): per task, (a) the full chain's 40-step error over the
/// plain net's, (b) the largest added operator's ratio, (c) the full chain's control within
/// tolerance on the simulator, (d) that control's error over the plain net's control's; held
/// needs every check, partly every task's (a). `tasks` holds each task's rows per net seed:
/// with more than one, each check reads the median over the seeds (a failed measure, +∞,
/// counted as the worst) with its 95% bootstrap interval over them, and its null the median
/// of the nulls. `None` when a check's null passes (a start already within tolerance).
pub fn ablation_rule(tasks: &[Vec<TaskRows>], r: &AblationRule) -> Option<Rule> {
    let mut held = Vec::new();
    let mut training = Vec::new();
    for seeds in tasks {
        let Some(first) = seeds.first() else {
            continue;
        };
        let k = seeds.len();
        let values: Vec<([f64; 4], [f64; 4])> = seeds.iter().map(task_values).collect();
        let median_of = |j: usize, idx: &mut dyn Iterator<Item = usize>, null: bool| {
            let v: Vec<f64> = idx
                .map(|i| if null { values[i].1[j] } else { values[i].0[j] })
                .collect();
            median_with_infinities(&v)
        };
        let value = [0, 1, 2, 3].map(|j| median_of(j, &mut (0..k), false));
        let null = [0, 1, 2, 3].map(|j| median_of(j, &mut (0..k), true));
        let intervals = (k > 1).then(|| {
            bootstrap_intervals(k, BOOTSTRAP_SEED, 4, |idx, out| {
                for (j, o) in out.iter_mut().enumerate() {
                    *o = median_of(j, &mut idx.iter().copied(), false);
                }
            })
        });
        let over = if k > 1 {
            format!(", median over {k} net seeds")
        } else {
            String::new()
        };
        let t = &first.task;
        let checks = [
            (
                format!("{t}: the full chain's 40-step error over the plain net's{over}"),
                Cmp::AtMost,
                r.full_over_plain,
                "the plain net itself",
            ),
            (
                format!(
                    "{t}: the largest ratio of an added operator's 40-step error to the previous variant's{over}"
                ),
                Cmp::Below,
                r.operator_ratio,
                "an operator that changes nothing",
            ),
            (
                format!(
                    "{t}: the control learned through the full chain, final error on the simulator{over}"
                ),
                Cmp::AtMost,
                WITHIN_TOLERANCE,
                "the start's controls",
            ),
            (
                format!("{t}: that control's simulator error over the plain net's control's{over}"),
                Cmp::Below,
                r.control_over_plain,
                "the plain net's control itself",
            ),
        ];
        training.push(held.len());
        for (j, (label, cmp, bar, null_label)) in checks.into_iter().enumerate() {
            let c = Check::new(label, value[j], cmp, bar, Null::new(null_label, null[j]));
            held.push(match &intervals {
                Some(iv) if !iv[j].0.is_nan() && !iv[j].1.is_nan() => {
                    c.map(|c| c.with_interval(iv[j].0, iv[j].1))
                }
                _ => c,
            });
        }
    }
    if held.is_empty() {
        return None;
    }
    Rule::gated(vec![], held, Partly::All(training))
}

/// Each task's rows per net seed ([`seeded_rows`]).
#[derive(Debug)]
pub(super) struct Seeded {
    /// Per task, its rows under each net seed (the run's own first).
    pub tasks: Vec<Vec<TaskRows>>,
    /// Per task, the ids of those net seeds (empty for a task of the run's own tables only).
    pub seeds: Vec<Vec<i64>>,
}

/// Each task's rows per net seed: the tasks in `net_seeds.csv` from it (every seed, the run's
/// own first), the others (the dolphin) from the run's own tables ([`task_rows`]), one seed. A
/// task whose seeds have different variants (a truncated or edited table) is an error naming
/// the file.
pub(super) fn seeded_rows(dir: &Path) -> Result<Seeded, Error> {
    let own = task_rows(dir)?;
    let path = dir.join("net_seeds.csv");
    let table: Vec<SeedRow> = read_rows(&path)?;
    let mut out = Seeded {
        tasks: Vec::new(),
        seeds: Vec::new(),
    };
    for t in own {
        let rows: Vec<&SeedRow> = table.iter().filter(|r| r.task == t.task).collect();
        let mut seeds: Vec<i64> = Vec::new();
        for r in &rows {
            if !seeds.contains(&r.net_seed) {
                seeds.push(r.net_seed);
            }
        }
        if rows.is_empty() {
            out.tasks.push(vec![t]);
            out.seeds.push(seeds);
            continue;
        }
        let mut per_seed = Vec::new();
        for &s in &seeds {
            let mine: Vec<&SeedRow> = rows.iter().copied().filter(|r| r.net_seed == s).collect();
            let rows_here: Vec<VariantRow> = mine
                .iter()
                .map(|r| {
                    let measure = |x: f64| if r.failed != 0 { f64::INFINITY } else { x };
                    VariantRow {
                        variant: r.variant.clone(),
                        rollout40: measure(r.rollout40_error_mean),
                        simulator: measure(r.simulator_error),
                        best_iteration: r.best_iteration as usize,
                    }
                })
                .collect();
            if rows_here.len() != t.rows.len() {
                return Err(other(format!(
                    "{}: net seed {s} of {} has {} variants, the run's own {} (a truncated or edited table)",
                    path.display(),
                    t.task,
                    rows_here.len(),
                    t.rows.len()
                )));
            }
            per_seed.push(TaskRows {
                task: t.task.clone(),
                rows: rows_here,
                start: mine[0].start_simulator_error,
            });
        }
        out.tasks.push(per_seed);
        out.seeds.push(seeds);
    }
    Ok(out)
}

/// The rule's rows from the `errors` and `control` tables of a run folder, one per task of
/// `nets`; a variant missing from a table (its training failed) has infinite errors.
fn task_rows(dir: &Path) -> Result<Vec<TaskRows>, Error> {
    let nets: Vec<NetRow> = read_rows(&dir.join("nets.csv"))?;
    let errors: Vec<ErrorsRow> = read_rows(&dir.join("errors.csv"))?;
    let control: Vec<ControlRow> = read_rows(&dir.join("control.csv"))?;
    let mut out: Vec<TaskRows> = Vec::new();
    for n in &nets {
        let (t, v) = (&n.task, &n.variant);
        let e = errors.iter().find(|e| e.task == *t && e.variant == *v);
        let c = control.iter().find(|c| c.task == *t && c.variant == *v);
        let start = control
            .iter()
            .find(|c| c.task == *t)
            .map_or(f64::NAN, |c| c.start_simulator_error);
        let r = VariantRow {
            variant: v.clone(),
            rollout40: e.map_or(f64::INFINITY, |e| e.rollout40_error_mean),
            simulator: c.map_or(f64::INFINITY, |c| c.simulator_error),
            best_iteration: c.map_or(0, |c| c.best_iteration as usize),
        };
        match out.iter_mut().find(|x| &x.task == t) {
            Some(x) => x.rows.push(r),
            None => out.push(TaskRows {
                task: t.clone(),
                rows: vec![r],
                start,
            }),
        }
    }
    Ok(out)
}

pub(super) fn words(v: &str) -> &str {
    match v {
        "plain" => "plain net (next state)",
        "delta" => "+ state change",
        "delta_frame" => "+ local frame",
        "full" => "+ normalization (full)",
        other => other,
    }
}

/// The findings ([`crate::experiment::Family::report`]).
pub(super) fn report(dir: &Path) -> Result<Findings, Error> {
    let errors: Vec<ErrorsRow> = read_rows(&dir.join("errors.csv"))?;
    let control: Vec<ControlRow> = read_rows(&dir.join("control.csv"))?;
    let nets: Vec<NetRow> = read_rows(&dir.join("nets.csv"))?;
    let mut md = String::from(
        "| task | transforms | one-step error | 40-step error (mean) | zero-control drift gap (m) | Fig. 13 control: final error, emulator | final error, simulator |\n| --- | --- | --- | --- | --- | --- | --- |\n",
    );
    for n in &nets {
        let (t, v) = (&n.task, &n.variant);
        if n.failed != 0 {
            md.push_str(&format!(
                "| {t} | {} | training failed | | | | |\n",
                words(v)
            ));
            continue;
        }
        let e = errors.iter().find(|e| e.task == *t && e.variant == *v);
        let c = control.iter().find(|c| c.task == *t && c.variant == *v);
        let g = |x: Option<f64>| x.map_or("–".into(), sig);
        md.push_str(&format!(
            "| {t} | {} | {} | {} | {} | {} | {} |\n",
            words(v),
            g(e.map(|e| e.rollout1_error)),
            g(e.map(|e| e.rollout40_error_mean)),
            g(e.map(|e| e.drift_gap_m)),
            g(c.map(|c| c.emulator_error)),
            g(c.map(|c| c.simulator_error))
        ));
    }
    let Seeded {
        tasks: seeded,
        seeds,
    } = seeded_rows(dir)?;
    let rows: Vec<TaskRows> = seeded.iter().filter_map(|s| s.first().cloned()).collect();
    if seeded.iter().any(|s| s.len() > 1) {
        md.push_str("\nPer net seed (`net_seeds.csv`; every variant built and measured again through the nets of each seed, the run's own first), the values the checks take the median of:\n\n| task | net seed | full chain's 40-step error / plain's | worst operator ratio | full chain's control, simulator final error | / plain net's control's |\n| --- | --- | --- | --- | --- | --- |\n");
        for (per_seed, ids) in seeded.iter().zip(&seeds).filter(|s| s.0.len() > 1) {
            for (t, s) in per_seed.iter().zip(ids) {
                let (v, _) = task_values(t);
                md.push_str(&format!(
                    "| {} | {} | {} | {} | {} | {} |\n",
                    t.task,
                    s,
                    sig(v[0]),
                    sig(v[1]),
                    sig(v[2]),
                    sig(v[3])
                ));
            }
        }
    }
    let settings = rule_settings(dir)?;
    let thresholds = AblationRule {
        operator_ratio: settings("operator_ratio"),
        full_over_plain: settings("full_over_plain"),
        control_over_plain: settings("control_over_plain"),
    };
    let rule = ablation_rule(&seeded, &thresholds);
    let (verdict, lines, text) = shown(
        rule.as_ref(),
        " No rule: a check's null passes (a start already within tolerance).",
    );
    let mut parts = Vec::new();
    let mut stuck = Vec::new();
    for t in &rows {
        let e = t.chain();
        parts.push(format!(
            "{}: 40-step error plain {} → full {}, control on the simulator through the full chain {} (plain net's {}, the start's {})",
            t.task,
            sig(e[0]),
            sig(e[e.len() - 1]),
            sig(t.simulator(TransformSet::Full)),
            sig(t.simulator(TransformSet::Plain)),
            sig(t.start)
        ));
        let s = t.stuck();
        if !s.is_empty() {
            stuck.push(format!("{} ({})", t.task, s.join(", ")));
        }
    }
    let stuck = if stuck.is_empty() {
        String::new()
    } else {
        format!(
            " The descent through these variants never improved on its start (best iteration 0), so their control is the start's: {}.",
            stuck.join("; ")
        )
    };
    Ok(Findings {
        ours: md,
        verdict,
        rule: rule.clone(),
        why: format!(
            "{}. Checks:{lines}{stuck} Rule (thresholds ours, in the spec; the spec's history gives the rule before): {text} Same data, net size, training and budget for every variant; the full chain is Fig. 13's net. The dolphin's rows are its global net's (composed with the whole chain's local nets for the rollouts); its control is the 20 s swim, whose final error is the distance it falls short of the hand-made wave's on the simulator in units of half that distance (1 = Fig. 13's bar), its start the dolphin at rest.",
            parts.join("; ")
        ),
    })
}
