//! Figures of `na_fig14_momentum`: `objective` (momentum against plain descent, the same through
//! the DAgger net, and the plain learning-rate sweep) and `net_seeds` (the verdict's ratio per
//! Table 1 lander net seed).

use super::rows::{Method, NetSeedRow, ObjectiveRow, RunRow};
use crate::experiment::output::Tables;
use crate::experiment::plot::{Figure, FigureSink, Legend, Mark, Panel, Series};
use crate::experiment::report::sig;
use crate::experiment::rows::TableRow;
use crate::experiment::rule::rule_setting;
use crate::experiment::Error;
use std::path::PathBuf;

/// The (iteration, objective) points of descent `method` at rate `eta` among `rows` (of
/// `objective`, `dagger_objective` or `unclipped_objective`).
fn curve(rows: &[ObjectiveRow], method: Method, eta: f64) -> Vec<(f64, f64)> {
    rows.iter()
        .filter(|r| method.is(&r.method) && r.eta == eta)
        .map(|r| (r.iteration as f64, r.objective))
        .collect()
}

/// Every figure of the experiment ([`crate::experiment::Family::figures`]).
pub(super) fn figures(fig: &FigureSink, tables: &Tables) -> Result<Vec<PathBuf>, Error> {
    let objective = ObjectiveRow::from_table(tables.require("objective")?);
    let runs = RunRow::from_table(tables.require("runs")?);
    let plain_eta = runs
        .iter()
        .filter(|r| Method::Plain.is(&r.method))
        .map(|r| r.eta)
        .collect::<Vec<_>>();
    let pick = |m: Method, e: f64| curve(&objective, m, e);
    let mom_eta = objective
        .iter()
        .find(|r| Method::Momentum.is(&r.method))
        .map(|r| r.eta);
    let mut main = vec![];
    if let Some(e) = mom_eta {
        main.push(Series::line(
            format!("momentum (eta {e})"),
            pick(Method::Momentum, e),
            0,
        ));
    }
    // The plain rate of the comparison is the one nearest 1.0.
    if let Some(&e) = plain_eta
        .iter()
        .min_by(|a, b| (*a - 1.0).abs().total_cmp(&(*b - 1.0).abs()))
    {
        let plain = pick(Method::Plain, e);
        // The verdict's bar: momentum must reach plain's final J within half the iterations.
        if let (Some(&(x_end, j_end)), Some(&(x0, _))) = (plain.last(), plain.first()) {
            let hi = main
                .iter()
                .chain(std::iter::once(&Series::line("", plain.clone(), 1)))
                .flat_map(|s| s.points.iter().map(|p| p.1))
                .filter(|v| v.is_finite() && *v > 0.0)
                .fold(j_end, f64::max);
            main.push(
                Series::line(
                    "held bar: plain's final J, reached within half the iterations",
                    vec![(x0, j_end), (0.5 * x_end, j_end), (0.5 * x_end, hi)],
                    2,
                )
                .mark(Mark::Dashed),
            );
        }
        main.push(Series::line(format!("plain (eta {e})"), plain, 1).mark(Mark::Dashed));
    }
    // The same two runs through the lander's DAgger net (ours), a panel of their own (the
    // curves lie almost on the Table 1 net's), same colours and line styles.
    let mut dagger = vec![];
    if let Some(dt) = tables.get("dagger_objective").filter(|t| !t.is_empty()) {
        let rows = ObjectiveRow::from_table(dt);
        for (c, (m, mark)) in [
            (Method::Momentum, Mark::Line),
            (Method::Plain, Mark::Dashed),
        ]
        .into_iter()
        .enumerate()
        {
            let Some(e) = rows.iter().find(|r| m.is(&r.method)).map(|r| r.eta) else {
                continue;
            };
            let pts = curve(&rows, m, e);
            let label = format!("{} (eta {e}), DAgger net", m.name());
            dagger.push(Series::line(label, pts, c).mark(mark));
        }
    }
    let sweep = plain_eta
        .iter()
        .enumerate()
        .map(|(i, &e)| Series::line(format!("eta {e}"), pick(Method::Plain, e), i))
        .collect();
    let mut panels = vec![
        Panel {
            title: "lander soft landing: momentum vs plain descent".into(),
            x_label: "iteration".into(),
            y_label: "objective J".into(),
            log_y: true,
            series: main,
            ..Panel::default()
        },
        Panel {
            title: "plain descent, learning-rate sweep".into(),
            x_label: "iteration".into(),
            y_label: "objective J".into(),
            log_y: true,
            series: sweep,
            ..Panel::default()
        },
    ];
    if !dagger.is_empty() {
        panels.insert(
            1,
            Panel {
                title: "the same through the lander's DAgger net (ours)".into(),
                x_label: "iteration".into(),
                y_label: "objective J".into(),
                log_y: true,
                series: dagger,
                ..Panel::default()
            },
        );
    }
    // The same sweep with the knots free of the actuators' boxes (ours: the boxes
    // can hide divergence above the stability limit), the start's J drawn as the rule's line.
    if let Some(ut) = tables.get("unclipped_objective").filter(|t| !t.is_empty()) {
        let rows = ObjectiveRow::from_table(ut);
        let mut series: Vec<Series> = plain_eta
            .iter()
            .enumerate()
            .map(|(i, &e)| Series::line(format!("eta {e}"), curve(&rows, Method::Plain, e), i))
            .collect();
        let start = rows.iter().find(|r| r.iteration == 0).map(|r| r.objective);
        let last = rows.iter().map(|r| r.iteration as f64).fold(0.0, f64::max);
        if let Some(j0) = start {
            series.push(
                Series::line(
                    "start's J (diverged if the last J ends above)".to_string(),
                    vec![(0.0, j0), (last, j0)],
                    plain_eta.len(),
                )
                .mark(Mark::Dashed),
            );
        }
        panels.push(Panel {
            title: "plain descent, knots not clipped to the boxes (ours)".into(),
            x_label: "iteration".into(),
            y_label: "objective J".into(),
            log_y: true,
            series,
            ..Panel::default()
        });
    }
    let cols = panels.len().min(2);
    let mut out = fig.draw("objective", &Figure::grid(panels, cols))?;
    out.extend(net_seeds_figure(fig, tables)?);
    Ok(out)
}

/// Figure `net_seeds` (none without `net_seeds.csv` or with one seed): per Table 1 lander net
/// seed, momentum's iterations to plain descent's final J over plain's (the verdict's (a),
/// [`super::report::seed_ratio`]) as a dot labelled with the seed, the median over the seeds
/// with its 95% bootstrap interval in the legend, the held bar and plain descent itself (1).
fn net_seeds_figure(fig: &FigureSink, tables: &Tables) -> Result<Vec<PathBuf>, Error> {
    let Some(t) = tables.get("net_seeds").filter(|t| !t.is_empty()) else {
        return Ok(vec![]);
    };
    let rows = NetSeedRow::from_table(t);
    let mut seeds: Vec<i64> = Vec::new();
    for r in &rows {
        if !seeds.contains(&r.net_seed) {
            seeds.push(r.net_seed);
        }
    }
    if seeds.len() < 2 {
        return Ok(vec![]);
    }
    let find = |s: i64, m: Method| {
        rows.iter()
            .find(|r| r.net_seed == s && m.is(&r.method) && r.compared())
    };
    let points: Vec<(f64, f64)> = seeds
        .iter()
        .filter_map(|&s| {
            let (rm, rp) = (find(s, Method::Momentum)?, find(s, Method::Plain)?);
            let ends = (rm.final_objective, rp.final_objective);
            let ratio = super::report::seed_ratio(rm.reach(), ends, rp.iterations as usize);
            Some((s as f64, ratio))
        })
        .collect();
    let ratios: Vec<f64> = points.iter().map(|p| p.1).collect();
    let (med, lo, hi) = super::report::ratio_median(&ratios);
    let x0 = seeds
        .iter()
        .map(|&s| s as f64)
        .fold(f64::INFINITY, f64::min)
        - 0.5;
    let x1 = seeds
        .iter()
        .map(|&s| s as f64)
        .fold(f64::NEG_INFINITY, f64::max)
        + 0.5;
    // Headroom above the null's line for the legend, where it hides no dot; a seed where
    // momentum never gets there (+∞) sits on the top edge, labelled "never".
    let top = ratios
        .iter()
        .copied()
        .filter(|r| r.is_finite())
        .fold(1.0, f64::max)
        * 1.7;
    let shown: Vec<(f64, f64)> = points.iter().map(|p| (p.0, p.1.min(top))).collect();
    let labels = points
        .iter()
        .map(|p| {
            if p.1.is_finite() {
                format!("{}", p.0)
            } else {
                format!("{} (never)", p.0)
            }
        })
        .collect();
    let mut series = vec![Series::line(
        format!(
            "median over {} seeds {} [95% interval {} to {}]",
            points.len(),
            sig(med),
            sig(lo),
            sig(hi)
        ),
        vec![(x0, med.min(top)), (x1, med.min(top))],
        1,
    )];
    if let Some(bar) = rule_setting(tables, "iteration_ratio") {
        series.push(
            Series::line("held bar (median at most)", vec![(x0, bar), (x1, bar)], 2)
                .mark(Mark::Dashed),
        );
    }
    series.push(
        Series::line(
            "plain descent itself (the null)",
            vec![(x0, 1.0), (x1, 1.0)],
            7,
        )
        .mark(Mark::Dashed),
    );
    // The seeds' dots last, over the lines (the median passes through the middle ones).
    series.push(
        Series::line(
            "momentum's iterations to plain's final J / plain's, per net seed",
            shown,
            0,
        )
        .mark(Mark::Points)
        .labelled(labels),
    );
    let panel = Panel {
        title: "lander: momentum's pace over plain descent's, per Table 1 net seed".into(),
        x_label: "Table 1 lander net seed".into(),
        y_label: "momentum's iterations to plain's final J / plain's".into(),
        x_integer: true,
        x_range: Some((x0, x1)),
        y_range: Some((0.0, top)),
        legend: Legend::UpperRight,
        series,
        ..Panel::default()
    };
    fig.draw("net_seeds", &Figure::grid(vec![panel], 1))
}
