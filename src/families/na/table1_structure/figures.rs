//! Figures: each net's training curves (`training`) and its rollout error against the
//! simulator over 40 super-steps (`rollout`).

use crate::experiment::output::{unique, Tables};
use crate::experiment::plot::{Figure, FigureSink, Mark, Panel, Series};
use crate::experiment::Error;
use std::path::PathBuf;

/// Draws the `training` and `rollout` figures.
pub(super) fn draw(fig: &FigureSink, tables: &Tables) -> Result<Vec<PathBuf>, Error> {
    let t = tables.require("training")?;
    let (net, it, tr, ho) = (
        t.strs("net"),
        t.f64s("iteration"),
        t.f64s("train_error"),
        t.f64s("heldout_error"),
    );
    let names = unique(&net);
    let panels = names
        .iter()
        .map(|name| {
            let pick = |v: &[f64]| -> Vec<(f64, f64)> {
                (0..net.len())
                    .filter(|&r| &net[r] == name)
                    .map(|r| (it[r], v[r]))
                    .collect()
            };
            Panel {
                title: name.clone(),
                x_label: "iteration (CG) or epoch (momentum)".into(),
                y_label: "MSE per output (normalized)".into(),
                log_y: true,
                series: vec![
                    Series::line("train", pick(&tr), 0),
                    Series::line("held-out", pick(&ho), 1).mark(Mark::Dashed),
                ],
                ..Panel::default()
            }
        })
        .collect();
    let mut files = fig.draw("training", &Figure::grid(panels, 3))?;
    let r = tables.require("rollout")?;
    let (net, step, err) = (r.strs("net"), r.f64s("step"), r.f64s("error"));
    let series = unique(&net)
        .iter()
        .enumerate()
        .map(|(c, name)| {
            let pts = (0..net.len())
                .filter(|&k| &net[k] == name && err[k] > 0.0)
                .map(|k| (step[k], err[k]))
                .collect();
            Series::line(name, pts, c)
        })
        .collect();
    let panel = Panel {
        title: "emulator vs simulator over 40 super-steps (fresh episodes)".into(),
        x_label: "super-steps k".into(),
        y_label: "mean squared error / state variance".into(),
        log_y: true,
        series,
        ..Panel::default()
    };
    files.extend(fig.draw("rollout", &Figure::grid(vec![panel], 1))?);
    Ok(files)
}
