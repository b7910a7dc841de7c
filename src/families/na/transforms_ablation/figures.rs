//! The figures of `na_transforms_ablation`: rollout errors and the per-variant summary.

use super::job::{ControlRow, ErrorsRow, NetRow, RolloutRow};
use super::report::words;
use crate::experiment::output::Tables;
use crate::experiment::plot::{Figure, FigureSink, Mark, Panel, Series};
use crate::experiment::rows::TableRow;
use crate::experiment::Error;
use std::path::PathBuf;

pub(super) fn figures(fig: &FigureSink, tables: &Tables) -> Result<Vec<PathBuf>, Error> {
    let rollout = RolloutRow::from_table(tables.require("rollout")?);
    let mut tasks: Vec<String> = Vec::new();
    let mut variants: Vec<String> = Vec::new();
    for n in NetRow::from_table(tables.require("nets")?) {
        if !tasks.contains(&n.task) {
            tasks.push(n.task);
        }
        if !variants.contains(&n.variant) {
            variants.push(n.variant);
        }
    }
    let panels: Vec<Panel> = tasks
        .iter()
        .map(|t| Panel {
            title: format!("{t}: rollout error of each variant"),
            x_label: "emulator step (super-step)".into(),
            y_label: "mean squared error (units of each variable's spread²)".into(),
            log_y: true,
            series: variants
                .iter()
                .enumerate()
                .map(|(k, v)| {
                    let pts = rollout
                        .iter()
                        .filter(|r| r.task == *t && r.variant == *v)
                        .map(|r| (r.step as f64, r.error))
                        .filter(|p| p.1 > 0.0)
                        .collect();
                    Series::line(words(v), pts, k)
                })
                .collect(),
            ..Panel::default()
        })
        .collect();
    let mut files = fig.draw("rollout", &Figure::grid(panels, 2))?;
    let e = ErrorsRow::from_table(tables.require("errors")?);
    let c = ControlRow::from_table(tables.require("control")?);
    let x_of = |v: &str| variants.iter().position(|x| x == v).unwrap_or(0) as f64;
    // One panel of a measure: per row its task, variant and value.
    let metric = |title: &str, y: &str, rows: Vec<(&str, &str, f64)>, tol: bool, floor: f64| {
        let mut series: Vec<Series> = tasks
            .iter()
            .enumerate()
            .map(|(k, t)| {
                let pts = rows
                    .iter()
                    .filter(|r| r.0 == t)
                    .map(|r| (x_of(r.1), r.2.max(floor)))
                    .filter(|p| p.1 > 0.0 && p.1.is_finite())
                    .collect();
                Series::line(t.clone(), pts, k)
            })
            .collect();
        if tol {
            series.push(
                Series::line(
                    "tolerance (1)",
                    vec![(-0.2, 1.0), (variants.len() as f64 - 0.8, 1.0)],
                    tasks.len(),
                )
                .mark(Mark::Dashed),
            );
        }
        Panel {
            title: title.into(),
            x_label: "transforms (operators added left to right)".into(),
            y_label: y.into(),
            log_y: true,
            series,
            x_categories: variants.iter().map(|v| words(v).to_string()).collect(),
            x_range: Some((-0.5, variants.len() as f64 - 0.5)),
            ..Panel::default()
        }
    };
    let panels = vec![
        metric(
            "one-step error",
            "squared error (spread² units)",
            e.iter()
                .map(|r| (r.task.as_str(), r.variant.as_str(), r.rollout1_error))
                .collect(),
            false,
            0.0,
        ),
        metric(
            "40-step rollout error (mean)",
            "squared error (spread² units)",
            e.iter()
                .map(|r| (r.task.as_str(), r.variant.as_str(), r.rollout40_error_mean))
                .collect(),
            false,
            0.0,
        ),
        metric(
            "zero-control drift from the Fig. 13 start",
            "emulator - simulator end position (m; below 1 mm drawn at 1 mm)",
            e.iter()
                .map(|r| (r.task.as_str(), r.variant.as_str(), r.drift_gap_m))
                .collect(),
            false,
            1e-3,
        ),
        metric(
            "Fig. 13 control replayed on the simulator",
            "final error (1 = tolerance; dolphin: half the wave's distance)",
            c.iter()
                .map(|r| (r.task.as_str(), r.variant.as_str(), r.simulator_error))
                .collect(),
            true,
            0.0,
        ),
    ];
    let mut f = Figure::grid(panels, 2);
    f.panel_size.0 = 720;
    files.extend(fig.draw("summary", &f)?);
    Ok(files)
}
