//! Figures of `na_fig13_control`: `control` (objectives, and every goal variable's deviation from the goal in tolerances over time),
//! `spectrum`, and the animated GIFs of every task and of the dolphin.

use super::anim::{write_animation, Scene, Track, EMULATOR, SIMULATOR};
use super::rows::{
    DolphinMotionRow, FinalRow, GoalRow, ObjectiveRow, SpectrumRow, StateRow, TrajectoryRow,
};
use super::{dagger, dolphin_dagger};
use crate::emulator::catalog::NetModel;
use crate::experiment::output::{unique, Tables};
use crate::experiment::plot::{Figure, FigureSink, Mark, Panel, Series};
use crate::experiment::rows::TableRow;
use crate::experiment::{other, Error};
use crate::physics::dolphin::N_POS;
use rayon::prelude::*;
use std::path::PathBuf;

/// How far from zero the normalized deviations of figure `control` are drawn: beyond this
/// they are clamped (the start is far from the goal; what matters is the end).
const DEVIATION_CLAMP: f64 = 5.0;

/// Every figure of the experiment ([`crate::experiment::Family::figures`]).
pub(super) fn figures(fig: &FigureSink, tables: &Tables) -> Result<Vec<PathBuf>, Error> {
    let objective = ObjectiveRow::from_table(tables.require("objective")?);
    let task: Vec<String> = objective.iter().map(|r| r.task.clone()).collect();
    let trajectory = TrajectoryRow::from_table(tables.require("trajectory")?);
    let goals = GoalRow::from_table(tables.require("goal")?);
    let states = StateRow::from_table(tables.require("states")?);
    // The paper's four tasks make the main figure; our second lines (formulation "ours") a
    // figure of their own, so neither is a wall of panels.
    let finals = FinalRow::from_table(tables.require("final")?);
    let ours = |name: &str| finals.iter().any(|r| r.task == name && !r.is_paper());
    let (mut panels, mut panels_ours) = (vec![], vec![]);
    for name in unique(&task) {
        let start = panels.len();
        let pts = objective
            .iter()
            .filter(|r| r.task == name)
            .map(|r| (r.iteration as f64, r.objective))
            .collect();
        panels.push(Panel {
            title: format!("{name}: objective"),
            x_label: "iteration".into(),
            y_label: "objective J".into(),
            // The swim objective is a reward (negative): linear axis.
            log_y: !(name == "dolphin" || name.starts_with("dolphin_")),
            series: vec![Series::line("momentum descent", pts, 0)],
            ..Panel::default()
        });
        let rows_of = |s: &str| -> Vec<&TrajectoryRow> {
            trajectory
                .iter()
                .filter(|r| r.task == name && r.source == s)
                .collect()
        };
        if name == "dolphin" || name.starts_with("dolphin_") {
            // The swim's goal is a distance to beat, not a state: its mean centroid (s0, s1).
            // Only the swim whose motion the run keeps (`trajectory` has no rows of the others).
            for s in ["emulator", "simulator"] {
                let rows = rows_of(s);
                if rows.is_empty() {
                    continue;
                }
                let series = ["x", "y"]
                    .into_iter()
                    .enumerate()
                    .map(|(k, var)| {
                        let pts = rows.iter().map(|r| (r.t, r.state[k])).collect();
                        Series::line(format!("centroid {var}"), pts, k)
                    })
                    .collect();
                panels.push(Panel {
                    title: format!("{name}: mean centroid, {s}"),
                    x_label: "time (s)".into(),
                    y_label: "x, y (m)".into(),
                    series,
                    ..Panel::default()
                });
            }
            if ours(&name) {
                panels_ours.extend(panels.drain(start..));
            }
            continue;
        }
        // Every variable of the goal: (s_k - goal_k) / tolerance_k over time.
        let g = goals.iter().find(|g| g.task == name);
        // Each goal variable's index in the state (its column `s<index>`).
        let goal_vars: Vec<(usize, String, f64)> = states
            .iter()
            .filter(|r| r.task == name && r.tolerance > 0.0)
            .map(|r| {
                let k = r.column.strip_prefix('s').and_then(|k| k.parse().ok());
                k.map(|k| (k, r.name.clone(), r.tolerance))
                    .ok_or_else(|| other(format!("states: no state column {}", r.column)))
            })
            .collect::<Result<_, _>>()?;
        for (c, s) in ["emulator", "simulator"].iter().enumerate() {
            let rows = rows_of(s);
            let t_end = rows.iter().map(|r| r.t).fold(0.0, f64::max);
            let mut series: Vec<Series> = Vec::new();
            for (k, (col, var, tol)) in goal_vars.iter().enumerate() {
                let Some(target) = g.and_then(|g| g.target.get(*col)) else {
                    continue;
                };
                let pts = rows
                    .iter()
                    .map(|r| {
                        let d = (r.state[*col] - target) / tol;
                        (r.t, d.clamp(-DEVIATION_CLAMP, DEVIATION_CLAMP))
                    })
                    .collect();
                // One legend per row: the simulator's panel uses the emulator's colours.
                let label = if c == 0 { var.clone() } else { String::new() };
                series.push(Series::line(label, pts, k).mark(Mark::stroke_of(k)));
            }
            for b in [-1.0, 1.0] {
                series.push(
                    Series::line(
                        if b > 0.0 && c == 0 {
                            "tolerance (±1)"
                        } else {
                            ""
                        },
                        vec![(0.0, b), (t_end, b)],
                        7,
                    )
                    .mark(Mark::Dashed),
                );
            }
            panels.push(Panel {
                title: format!(
                    "{name}: {}",
                    if c == 0 {
                        "on the emulator"
                    } else {
                        "replayed on the simulator"
                    }
                ),
                x_label: "time (s)".into(),
                y_label: format!("(state − goal) / tolerance, clamped at ±{DEVIATION_CLAMP}"),
                series,
                y_range: Some((-DEVIATION_CLAMP - 0.3, DEVIATION_CLAMP + 0.3)),
                ..Panel::default()
            });
        }
        if ours(&name) {
            panels_ours.extend(panels.drain(start..));
        }
    }
    // Taller panels than the default leave the variables' legend room beside the data.
    let tall = |panels| Figure {
        panel_size: (640, 560),
        ..Figure::grid(panels, 3)
    };
    let mut files = fig.draw("control", &tall(panels))?;
    if !panels_ours.is_empty() {
        files.extend(fig.draw("control_ours", &tall(panels_ours))?);
    }
    files.extend(spectrum_figure(fig, tables)?);
    files.extend(animations(fig, tables)?);
    files.extend(dolphin_animation(fig, tables)?);
    files.extend(dagger::figure(fig, tables)?);
    files.extend(dolphin_dagger::figure(fig, tables)?);
    files.extend(super::seeds::figure(fig, tables)?);
    Ok(files)
}

/// Figure `spectrum`: per task, the terminal Gauss-Newton eigenvalues at the start knots
/// through the emulator and through the physics (log y; eigenvalues below 1e-14 of the
/// largest, the null space and rounding, are left out; the legend says how many are drawn).
fn spectrum_figure(fig: &FigureSink, tables: &Tables) -> Result<Vec<PathBuf>, Error> {
    let spectrum = SpectrumRow::from_table(tables.require("spectrum")?);
    let series_of = |name: &str, c: usize, s: &str| {
        let rows: Vec<&SpectrumRow> = spectrum
            .iter()
            .filter(|r| r.task == name && r.substrate == s)
            .collect();
        let top = rows.iter().map(|r| r.eigenvalue).fold(0.0, f64::max);
        let total = rows.len();
        let pts: Vec<(f64, f64)> = rows
            .into_iter()
            .filter(|r| r.eigenvalue > 1e-14 * top)
            .map(|r| (r.index as f64, r.eigenvalue))
            .collect();
        let label = format!(
            "through the {s} ({} of {total} above 1e-14 of the largest)",
            pts.len()
        );
        let mark = if c == 0 { Mark::Line } else { Mark::Dashed };
        Series::line(label, pts, c).mark(mark)
    };
    let tasks: Vec<String> = spectrum.iter().map(|r| r.task.clone()).collect();
    let panels: Vec<Panel> = unique(&tasks)
        .into_iter()
        .map(|name| Panel {
            title: format!("{name}: terminal Gauss-Newton spectrum at the start"),
            x_label: "eigenvalue index (largest first)".into(),
            y_label: "eigenvalue of J^T W J (1)".into(),
            log_y: true,
            x_integer: true,
            series: vec![
                series_of(&name, 0, "emulator"),
                series_of(&name, 1, "physics"),
            ],
            ..Panel::default()
        })
        .collect();
    if panels.is_empty() {
        return Ok(vec![]);
    }
    fig.draw("spectrum", &Figure::grid(panels, 3))
}

/// One animated GIF per task (see [`anim`]): the emulator-driven motion and its
/// simulator replay, from the `trajectory` table, over the goal from the `goal` table.
/// `<id>_dolphin.gif` from the `dolphin_motion` table, when it has rows.
fn dolphin_animation(fig: &FigureSink, tables: &Tables) -> Result<Vec<PathBuf>, Error> {
    // No rows without `[params.dolphin]`.
    let motion = DolphinMotionRow::from_table(tables.require("dolphin_motion")?);
    if motion.is_empty() {
        return Ok(vec![]);
    }
    let track = |name: &str| -> Vec<Vec<f64>> {
        motion
            .iter()
            .filter(|r| r.source == name)
            .map(|r| r.positions[..N_POS].to_vec())
            .collect()
    };
    let emu_rows: Vec<&DolphinMotionRow> =
        motion.iter().filter(|r| r.source == "emulator").collect();
    let step = match emu_rows.as_slice() {
        [a, b, ..] => b.t - a.t,
        _ => 1.0,
    };
    let tracks = vec![
        Track {
            label: "simulator replay".into(),
            color: SIMULATOR,
            states: track("simulator"),
        },
        Track {
            label: "emulator (global + local nets)".into(),
            color: EMULATOR,
            states: track("emulator"),
        },
    ];
    let (p, _) = write_animation(
        &fig.dir,
        &format!("{}_dolphin", fig.id),
        &Scene::Dolphin(Box::default()),
        "dolphin: swim forward",
        "learned muscle controls: hierarchical emulator (purple), simulator replay (grey)",
        step,
        &[],
        &tracks,
    )?;
    Ok(vec![p])
}

fn animations(fig: &FigureSink, tables: &Tables) -> Result<Vec<PathBuf>, Error> {
    let goals = GoalRow::from_table(tables.require("goal")?);
    let trajectory = TrajectoryRow::from_table(tables.require("trajectory")?);
    let width = trajectory.first().map_or(0, |r| r.state.len());
    // A GIF for each task of the paper's formulation (one of ours is a second line in the
    // tables and the control figure, not animated).
    let ours: Vec<String> = FinalRow::from_table(tables.require("final")?)
        .into_iter()
        .filter(|r| !r.is_paper())
        .map(|r| r.task)
        .collect();
    let jobs: Vec<(&GoalRow, NetModel)> = goals
        .iter()
        .filter(|g| !ours.contains(&g.task))
        .map(|g| {
            NetModel::ALL
                .into_iter()
                .find(|m| m.name() == g.model)
                .filter(|m| m.state_dim() <= width)
                .map(|m| (g, m))
                .ok_or_else(|| other(format!("goal: unknown model {}", g.model)))
        })
        .collect::<Result<_, _>>()?;
    jobs.par_iter()
        .map(|&(g, model)| {
            let (name, n) = (&g.task, model.state_dim());
            let goal: Vec<f64> = g.target[..n].to_vec();
            let rows = |s: &str| -> Vec<&TrajectoryRow> {
                trajectory
                    .iter()
                    .filter(|r| &r.task == name && r.source == s)
                    .collect()
            };
            let emu = rows("emulator");
            let step = match emu.as_slice() {
                [a, b, ..] => b.t - a.t,
                _ => 1.0,
            };
            let tracks: Vec<Track> = [
                ("simulator replay", SIMULATOR, rows("simulator")),
                ("emulator", EMULATOR, emu),
            ]
            .into_iter()
            .map(|(label, color, rows)| Track {
                label: label.into(),
                color,
                states: rows.iter().map(|r| r.state[..n].to_vec()).collect(),
            })
            .collect();
            write_animation(
                &fig.dir,
                &format!("{}_{name}", fig.id),
                &Scene::for_model(model),
                name,
                "learned controls: emulator (purple), simulator replay (grey), goal (green)",
                step,
                &goal,
                &tracks,
            )
            .map(|(p, _)| p)
        })
        .collect()
}
