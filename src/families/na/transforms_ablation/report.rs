//! The report of `na_transforms_ablation`: the verdict's rule over the tasks and net seeds.

use super::{AblationRule, WITHIN_TOLERANCE};
use crate::emulator::catalog::TransformSet;
use crate::experiment::output::{df_f64, df_str, read_csv};
use crate::experiment::report::{sig, Findings};
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

/// Each task's rows per net seed: the tasks in `net_seeds.csv` from it (every seed, the run's
/// own first), the others (the dolphin) from the run's own tables ([`task_rows`]), one seed. A
/// task whose seeds have different variants (a truncated or edited table) is an error naming
/// the file.
pub(super) fn seeded_rows(dir: &Path) -> Result<Vec<Vec<TaskRows>>, Error> {
    let own = task_rows(dir)?;
    let path = dir.join("net_seeds.csv");
    let df = read_csv(&path)?;
    let (seed, task, variant) = (
        df_f64(&df, "net_seed")?,
        df_str(&df, "task")?,
        df_str(&df, "variant")?,
    );
    let (e40, best, sim, start, failed) = (
        df_f64(&df, "rollout40_error_mean")?,
        df_f64(&df, "best_iteration")?,
        df_f64(&df, "simulator_error")?,
        df_f64(&df, "start_simulator_error")?,
        df_f64(&df, "failed")?,
    );
    let mut out = Vec::new();
    for t in own {
        let rows: Vec<usize> = (0..task.len()).filter(|&i| task[i] == t.task).collect();
        if rows.is_empty() {
            out.push(vec![t]);
            continue;
        }
        let mut seeds: Vec<f64> = Vec::new();
        for &i in &rows {
            if !seeds.contains(&seed[i]) {
                seeds.push(seed[i]);
            }
        }
        let mut per_seed = Vec::new();
        for s in seeds {
            let mine: Vec<usize> = rows.iter().copied().filter(|&i| seed[i] == s).collect();
            let rows_here: Vec<VariantRow> = mine
                .iter()
                .map(|&i| {
                    let measure = |x: f64| if failed[i] != 0.0 { f64::INFINITY } else { x };
                    VariantRow {
                        variant: variant[i].clone(),
                        rollout40: measure(e40[i]),
                        simulator: measure(sim[i]),
                        best_iteration: best[i] as usize,
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
                start: start[mine[0]],
            });
        }
        out.push(per_seed);
    }
    Ok(out)
}

/// The rule's rows from the `errors` and `control` tables of a run folder, one per task of
/// `nets`; a variant missing from a table (its training failed) has infinite errors.
fn task_rows(dir: &Path) -> Result<Vec<TaskRows>, Error> {
    let nets = read_csv(&dir.join("nets.csv"))?;
    let (nt, nv) = (df_str(&nets, "task")?, df_str(&nets, "variant")?);
    let errors = read_csv(&dir.join("errors.csv"))?;
    let (et, ev, e40) = (
        df_str(&errors, "task")?,
        df_str(&errors, "variant")?,
        df_f64(&errors, "rollout40_error_mean")?,
    );
    let control = read_csv(&dir.join("control.csv"))?;
    let (ct, cv, cs, cb, c0) = (
        df_str(&control, "task")?,
        df_str(&control, "variant")?,
        df_f64(&control, "simulator_error")?,
        df_f64(&control, "best_iteration")?,
        df_f64(&control, "start_simulator_error")?,
    );
    let mut out: Vec<TaskRows> = Vec::new();
    for (t, v) in nt.iter().zip(&nv) {
        let at = |ts: &[String], vs: &[String]| (0..ts.len()).find(|&i| &ts[i] == t && &vs[i] == v);
        let (ei, ci) = (at(&et, &ev), at(&ct, &cv));
        let start = (0..ct.len())
            .find(|&i| &ct[i] == t)
            .map_or(f64::NAN, |i| c0[i]);
        let r = VariantRow {
            variant: v.clone(),
            rollout40: ei.map_or(f64::INFINITY, |i| e40[i]),
            simulator: ci.map_or(f64::INFINITY, |i| cs[i]),
            best_iteration: ci.map_or(0, |i| cb[i] as usize),
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
    let e = read_csv(&dir.join("errors.csv"))?;
    let c = read_csv(&dir.join("control.csv"))?;
    let nets = read_csv(&dir.join("nets.csv"))?;
    let (nt, nv, nf) = (
        df_str(&nets, "task")?,
        df_str(&nets, "variant")?,
        df_f64(&nets, "failed")?,
    );
    let (et, ev) = (df_str(&e, "task")?, df_str(&e, "variant")?);
    let (e1, e40, gap) = (
        df_f64(&e, "rollout1_error")?,
        df_f64(&e, "rollout40_error_mean")?,
        df_f64(&e, "drift_gap_m")?,
    );
    let (ct, cv) = (df_str(&c, "task")?, df_str(&c, "variant")?);
    let (ce, cs) = (
        df_f64(&c, "emulator_error")?,
        df_f64(&c, "simulator_error")?,
    );
    let mut md = String::from(
        "| task | transforms | one-step error | 40-step error (mean) | zero-control drift gap (m) | Fig. 13 control: final error, emulator | final error, simulator |\n| --- | --- | --- | --- | --- | --- | --- |\n",
    );
    for i in 0..nt.len() {
        let (t, v) = (&nt[i], &nv[i]);
        if nf[i] != 0.0 {
            md.push_str(&format!(
                "| {t} | {} | training failed | | | | |\n",
                words(v)
            ));
            continue;
        }
        let ei = (0..et.len()).find(|&j| &et[j] == t && &ev[j] == v);
        let ci = (0..ct.len()).find(|&j| &ct[j] == t && &cv[j] == v);
        let g = |o: Option<usize>, x: &[f64]| o.map_or("–".into(), |j| sig(x[j]));
        md.push_str(&format!(
            "| {t} | {} | {} | {} | {} | {} | {} |\n",
            words(v),
            g(ei, &e1),
            g(ei, &e40),
            g(ei, &gap),
            g(ci, &ce),
            g(ci, &cs)
        ));
    }
    let seeded = seeded_rows(dir)?;
    let rows: Vec<TaskRows> = seeded.iter().filter_map(|s| s.first().cloned()).collect();
    if seeded.iter().any(|s| s.len() > 1) {
        md.push_str("\nPer net seed (`net_seeds.csv`; every variant built and measured again through the nets of each seed, the run's own first), the values the checks take the median of:\n\n| task | net seed | full chain's 40-step error / plain's | worst operator ratio | full chain's control, simulator final error | / plain net's control's |\n| --- | --- | --- | --- | --- | --- |\n");
        let ids = read_csv(&dir.join("net_seeds.csv"))?;
        let (it, is) = (df_str(&ids, "task")?, df_f64(&ids, "net_seed")?);
        for per_seed in seeded.iter().filter(|s| s.len() > 1) {
            let mut seen: Vec<f64> = Vec::new();
            for i in (0..it.len()).filter(|&i| it[i] == per_seed[0].task) {
                if !seen.contains(&is[i]) {
                    seen.push(is[i]);
                }
            }
            for (t, s) in per_seed.iter().zip(seen) {
                let (v, _) = task_values(t);
                md.push_str(&format!(
                    "| {} | {} | {} | {} | {} | {} |\n",
                    t.task,
                    s as u64,
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
