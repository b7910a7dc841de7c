//! `ms_fig6_learning_plot` (MS Fig. 6): the `ms_learning` family. Every evaluation's
//! objective over the hill-climbing iterations with the best so far, for the poodle, beside
//! simulated annealing with the same budget, run side by side by [`LearningJob`] (in
//! [`super::search`], with the parameters shared with `ms_motion`).
//!
//! Tables: `learning` (method, iteration, objective, best) and `summary` (method, evaluations,
//! seconds, best_objective). Figure: `<id>_learning.png/svg`, the scatter of every evaluation
//! with best-so-far lines.

use super::search::{learning_panel_on, LearningJob};
use crate::experiment::output::{df_f64, df_str, read_csv, Table, Tables};
use crate::experiment::plot::FigureSink;
use crate::experiment::plot::{Figure, Mark, Series};
use crate::experiment::report::{sig, Findings, Verdict};
use crate::experiment::{Error, Family};
use crate::row;
use std::path::{Path, PathBuf};

/// The learning-plot family.
pub struct MsLearning;

/// Learning-curve statistics of one method from `learning.csv` columns.
struct Curve {
    init_best: f64,
    at_fifth: f64,
    end_best: f64,
    poor_late: f64,
    iterations: f64,
}

fn curve(method: &str, m: &[String], it: &[f64], obj: &[f64], best: &[f64]) -> Curve {
    let rows: Vec<usize> = (0..m.len()).filter(|&i| m[i] == method).collect();
    let iterations = rows.iter().map(|&i| it[i]).fold(0.0, f64::max);
    let best_at = |limit: f64| {
        rows.iter()
            .filter(|&&i| it[i] <= limit)
            .map(|&i| best[i])
            .fold(f64::NEG_INFINITY, f64::max)
    };
    let init_best = best_at(0.0);
    let late: Vec<usize> = rows
        .iter()
        .copied()
        .filter(|&i| it[i] > 0.8 * iterations)
        .collect();
    let poor = late.iter().filter(|&&i| obj[i] < init_best).count() as f64;
    Curve {
        init_best,
        at_fifth: best_at(iterations / 5.0),
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
    type Params = LearningJob;

    fn figures(&self, fig: &FigureSink, tables: &Tables) -> Result<Vec<PathBuf>, Error> {
        let t = tables.require("learning")?;
        let methods = t.strs("method");
        let split = |name: &str| {
            let mut out = Table::new(&["iteration", "objective", "best"]);
            let (it, o, b) = (t.f64s("iteration"), t.f64s("objective"), t.f64s("best"));
            for i in 0..methods.len() {
                if methods[i] == name {
                    out.push(row![it[i], o[i], b[i]]);
                }
            }
            out
        };
        let (h, s) = (split("hill_climbing"), split("simulated_annealing"));
        // Hill climbing's scatter alone, as the paper's Fig. 6, with annealing's best so far
        // beside it; annealing's own scatter in a second panel on the same axes.
        let x_label = "iteration (0: initial random controllers)";
        let both = [("hill climbing", &h), ("simulated annealing", &s)];
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
        let df = read_csv(&dir.join("learning.csv"))?;
        let (m, it, obj, best) = (
            df_str(&df, "method")?,
            df_f64(&df, "iteration")?,
            df_f64(&df, "objective")?,
            df_f64(&df, "best")?,
        );
        let s = read_csv(&dir.join("summary.csv"))?;
        let (sm, secs, evals) = (
            df_str(&s, "method")?,
            df_f64(&s, "seconds")?,
            df_f64(&s, "evaluations")?,
        );
        let wall = df_f64(&s, "wall_seconds_both")?
            .first()
            .copied()
            .unwrap_or(f64::NAN);
        let h = curve("hill_climbing", &m, &it, &obj, &best);
        let a = curve("simulated_annealing", &m, &it, &obj, &best);
        let frac = |c: &Curve| (c.at_fifth - c.init_best) / (c.end_best - c.init_best).max(1e-12);
        let mut md = String::from(
            "| method | evaluations | seconds | best of initial set | best at 1/5 of the iterations | final best | share of the gain by 1/5 | evaluations in the last 1/5 worse than the initial best |\n| --- | --- | --- | --- | --- | --- | --- | --- |\n",
        );
        for (name, c) in [("hill_climbing", &h), ("simulated_annealing", &a)] {
            let k = sm.iter().position(|x| x == name);
            md.push_str(&format!(
                "| {name} | {} | {} | {} | {} | {} | {} | {} |\n",
                k.map(|k| evals[k]).unwrap_or(f64::NAN),
                sig(k.map(|k| secs[k]).unwrap_or(f64::NAN)),
                sig(c.init_best),
                sig(c.at_fifth),
                sig(c.end_best),
                sig(frac(c)),
                sig(c.poor_late)
            ));
        }
        md.push_str(&format!(
            "\nBoth searches ran side by side in {} s of wall time ({} iterations each; the paper: 25,000 iterations in 66 min on a DEC 3000/400 AXP).\n",
            sig(wall),
            h.iterations
        ));
        let fast_then_slow = frac(&h) >= 0.6 && h.end_best > h.init_best;
        let many_poor = h.poor_late >= 0.2;
        let verdict = Verdict::from_checks(&[fast_then_slow, many_poor]);
        Ok(Findings {
            ours: md,
            verdict,
            why: format!(
                "Hill climbing made {}% of its total gain in the first fifth of the iterations (fast, then slow: {}); {}% of its evaluations in the last fifth were worse than the best random controller (many stay poor: {}); simulated annealing with the same budget ended at {} vs {}. Rule (thresholds ours): held when both checks pass, fast then slow (at least 60% of hill climbing's gain in the first fifth of the iterations, and some gain) and many stay poor (at least 20% of the last fifth's evaluations worse than the best random controller); partly when one does.",
                sig(100.0 * frac(&h)),
                fast_then_slow,
                sig(100.0 * h.poor_late),
                many_poor,
                sig(a.end_best),
                sig(h.end_best)
            ),
        })
    }
}
