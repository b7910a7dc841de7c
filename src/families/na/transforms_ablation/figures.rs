//! The figures of `na_transforms_ablation`: rollout errors and the per-variant summary.

use super::report::words;
use crate::experiment::output::Tables;
use crate::experiment::plot::{Figure, FigureSink, Mark, Panel, Series};
use crate::experiment::Error;
use std::path::PathBuf;

pub(super) fn figures(fig: &FigureSink, tables: &Tables) -> Result<Vec<PathBuf>, Error> {
    let r = tables.require("rollout")?;
    let (rt, rv, rk, re) = (
        r.strs("task"),
        r.strs("variant"),
        r.f64s("step"),
        r.f64s("error"),
    );
    let mut tasks: Vec<String> = Vec::new();
    let mut variants: Vec<String> = Vec::new();
    let n = tables.require("nets")?;
    for (t, v) in n.strs("task").iter().zip(n.strs("variant")) {
        if !tasks.contains(t) {
            tasks.push(t.clone());
        }
        if !variants.contains(&v) {
            variants.push(v);
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
                    let pts = (0..rt.len())
                        .filter(|&i| &rt[i] == t && &rv[i] == v)
                        .map(|i| (rk[i], re[i]))
                        .filter(|p| p.1 > 0.0)
                        .collect();
                    Series::line(words(v), pts, k)
                })
                .collect(),
            ..Panel::default()
        })
        .collect();
    let mut files = fig.draw("rollout", &Figure::grid(panels, 2))?;
    let e = tables.require("errors")?;
    let c = tables.require("control")?;
    let (et, ev) = (e.strs("task"), e.strs("variant"));
    let (ct, cv) = (c.strs("task"), c.strs("variant"));
    let x_of = |v: &str| variants.iter().position(|x| x == v).unwrap_or(0) as f64;
    let metric = |title: &str,
                  y: &str,
                  ts: &[String],
                  vs: &[String],
                  col: Vec<f64>,
                  tol: bool,
                  floor: f64| {
        let mut series: Vec<Series> = tasks
            .iter()
            .enumerate()
            .map(|(k, t)| {
                let pts = (0..ts.len())
                    .filter(|&i| &ts[i] == t)
                    .map(|i| (x_of(&vs[i]), col[i].max(floor)))
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
            &et,
            &ev,
            e.f64s("rollout1_error"),
            false,
            0.0,
        ),
        metric(
            "40-step rollout error (mean)",
            "squared error (spread² units)",
            &et,
            &ev,
            e.f64s("rollout40_error_mean"),
            false,
            0.0,
        ),
        metric(
            "zero-control drift from the Fig. 13 start",
            "emulator - simulator end position (m; below 1 mm drawn at 1 mm)",
            &et,
            &ev,
            e.f64s("drift_gap_m"),
            false,
            1e-3,
        ),
        metric(
            "Fig. 13 control replayed on the simulator",
            "final error (1 = tolerance; dolphin: half the wave's distance)",
            &ct,
            &cv,
            c.f64s("simulator_error"),
            true,
            0.0,
        ),
    ];
    let mut f = Figure::grid(panels, 2);
    f.panel_size.0 = 720;
    files.extend(fig.draw("summary", &f)?);
    Ok(files)
}
