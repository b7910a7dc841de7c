//! The figures of `na_training_methods`: training curves and the examples-per-weight sweep.

use super::job::{CurveRow, ExamplesRow, MethodRow};
use super::{median_inf, method_words};
use crate::experiment::output::Tables;
use crate::experiment::plot::{Figure, FigureSink, Mark, Panel, Series};
use crate::experiment::report::sig;
use crate::experiment::rows::TableRow;
use crate::experiment::rule::rule_setting;
use crate::experiment::Error;
use std::path::PathBuf;

/// The `curves` figure (one row per net: held-out error against seconds and against passes)
/// and the `examples` figure (errors and their ratio against examples per weight).
pub(super) fn figures(fig: &FigureSink, tables: &Tables) -> Result<Vec<PathBuf>, Error> {
    let mut files = fig.draw("curves", &Figure::grid(curve_panels(tables)?, 2))?;
    files.extend(fig.draw("examples", &Figure::grid(example_panels(tables)?, 2))?);
    Ok(files)
}

/// Per net, its held-out error curves against wall-clock seconds and against data passes,
/// every init in its method's stroke, with the first init's target dashed.
fn curve_panels(tables: &Tables) -> Result<Vec<Panel>, Error> {
    let curves = CurveRow::from_table(tables.require("curves")?);
    let methods = MethodRow::from_table(tables.require("methods")?);
    let mut net_names: Vec<String> = Vec::new();
    let mut method_names: Vec<String> = Vec::new();
    for c in &curves {
        if !net_names.contains(&c.net) {
            net_names.push(c.net.clone());
        }
        if !method_names.contains(&c.method) {
            method_names.push(c.method.clone());
        }
    }
    let seconds = |c: &CurveRow| c.seconds;
    let passes = |c: &CurveRow| c.passes as f64;
    let mut panels = Vec::new();
    for net in &net_names {
        let target = methods
            .iter()
            .find(|m| m.net == *net && m.init == 1)
            .map(|m| m.target);
        let x_axes: [(&str, &dyn Fn(&CurveRow) -> f64); 2] = [
            ("wall-clock seconds since training began (s)", &seconds),
            (
                "data passes (forward + backward sweeps over the training set)",
                &passes,
            ),
        ];
        for (x_label, x_of) in x_axes {
            let mut series = Vec::new();
            let mut x_max: f64 = 0.0;
            for (k, me) in method_names.iter().enumerate() {
                let mine: Vec<&CurveRow> = curves
                    .iter()
                    .filter(|c| c.net == *net && c.method == *me)
                    .collect();
                let mut inits: Vec<i64> = mine.iter().map(|c| c.init).collect();
                inits.dedup();
                for (j, init) in inits.iter().enumerate() {
                    let pts: Vec<(f64, f64)> = mine
                        .iter()
                        .filter(|c| c.init == *init)
                        .map(|c| (x_of(c), c.held_out_error))
                        .filter(|p| p.1 > 0.0 && p.1.is_finite())
                        .collect();
                    x_max = pts.iter().map(|p| p.0).fold(x_max, f64::max);
                    let label = if j == 0 { method_words(me)? } else { "" };
                    series.push(Series::line(label, pts, k).mark(Mark::stroke_of(k)));
                }
            }
            if let Some(t) = target {
                series.push(
                    Series::line(
                        "target (init 1)",
                        vec![(0.0, t), (x_max, t)],
                        method_names.len(),
                    )
                    .mark(Mark::Dashed),
                );
            }
            panels.push(Panel {
                title: format!("{net}: held-out error while training"),
                x_label: x_label.into(),
                y_label: "held-out mean squared error (normalized units)".into(),
                log_y: true,
                series,
                ..Panel::default()
            });
        }
    }
    Ok(panels)
}

/// The examples figure's panels: the training and test errors, and their ratio against the
/// rule's bars.
fn example_panels(tables: &Tables) -> Result<Vec<Panel>, Error> {
    let examples = ExamplesRow::from_table(tables.require("examples")?);
    let mut ratios: Vec<f64> = examples.iter().map(|e| e.examples_per_weight).collect();
    ratios.sort_by(f64::total_cmp);
    ratios.dedup();
    let med = |col: fn(&ExamplesRow) -> f64, x: f64| {
        let v: Vec<f64> = examples
            .iter()
            .filter(|e| e.examples_per_weight == x)
            .map(col)
            .collect();
        median_inf(&v)
    };
    let test: Vec<(f64, f64)> = ratios
        .iter()
        .map(|&x| (x, med(|e| e.test_error, x)))
        .collect();
    let train: Vec<(f64, f64)> = ratios
        .iter()
        .map(|&x| (x, med(|e| e.train_error, x)))
        .collect();
    let ratio: Vec<(f64, f64)> = test
        .iter()
        .zip(&train)
        .map(|(a, b)| (a.0, a.1 / b.1))
        .collect();
    let (lo, hi) = (
        ratios.first().copied().unwrap_or(1.0),
        ratios.last().copied().unwrap_or(1.0),
    );
    let errs: Vec<f64> = test
        .iter()
        .chain(&train)
        .map(|p| p.1)
        .filter(|v| *v > 0.0)
        .collect();
    let (emin, emax) = (
        errs.iter().copied().fold(f64::INFINITY, f64::min),
        errs.iter().copied().fold(0.0, f64::max),
    );
    let vline = |x: f64, y0: f64, y1: f64, label: &str, color: usize| {
        Series::line(label, vec![(x, y0), (x, y1)], color).mark(Mark::Dashed)
    };
    let left = Panel {
        title: "training and test error against the data".into(),
        x_label: "training examples per network weight".into(),
        y_label: "mean squared error (normalized units)".into(),
        log_x: true,
        log_y: true,
        series: vec![
            Series::line("test error (separate episodes)", test, 0).mark(Mark::LinePoints),
            Series::line("training error", train, 1).mark(Mark::LinePoints),
            vline(8.0, emin, emax, "the paper's 8-10 per weight", 2),
            vline(10.0, emin, emax, "", 2),
        ],
        ..Panel::default()
    };
    // The rule's bars from the run's rule table; the axis stops a few times above the
    // larger bar so the bars, which decide the verdict, are not squeezed by the smallest
    // ratios' overfitting (hundreds; their values are in the table).
    let overfit = rule_setting(tables, "overfit_ratio").unwrap_or(f64::NAN);
    let serious = rule_setting(tables, "test_train_max").unwrap_or(f64::NAN);
    let top = 5.0 * overfit.max(serious).max(1.0);
    let rmax = ratio.iter().map(|p| p.1).fold(2.5, f64::max).min(top);
    let cut = ratio.iter().filter(|p| p.1 > top).count();
    let ratio: Vec<(f64, f64)> = ratio.into_iter().filter(|p| p.1 <= top).collect();
    let right = Panel {
        title: format!(
            "test / training error (cut at {}{})",
            sig(top),
            if cut > 0 {
                format!(": {cut} points above")
            } else {
                String::new()
            }
        ),
        x_label: "training examples per network weight".into(),
        y_label: "test error / training error".into(),
        log_x: true,
        log_y: true,
        y_range: Some((0.8, top)),
        series: vec![
            Series::line("test / training", ratio, 0).mark(Mark::LinePoints),
            Series::line(
                format!("{}: overfitting visible (premise)", sig(overfit)),
                vec![(lo, overfit), (hi, overfit)],
                3,
            )
            .mark(Mark::Dashed),
            Series::line(
                format!("{}: none serious (rule)", sig(serious)),
                vec![(lo, serious), (hi, serious)],
                4,
            )
            .mark(Mark::Pattern { dash: 3, gap: 3 }),
            vline(8.0, 0.8, rmax, "the paper's 8-10 per weight", 2),
            vline(10.0, 0.8, rmax, "", 2),
        ],
        ..Panel::default()
    };
    Ok(vec![left, right])
}
