//! Figures of `x_lbc_emulator`: `error` (final error per desired target and method, on the
//! simulator and the emulator) and the animated GIF of LBC's landing.

use super::job::{states_of, GoalRow, TargetRow, TrajectoryRow};
use super::Method;
use crate::emulator::catalog::NetModel;
use crate::experiment::output::Tables;
use crate::experiment::plot::{Figure, FigureSink, Mark, Panel, Series};
use crate::experiment::report::sig;
use crate::experiment::rows::TableRow;
use crate::experiment::Error;
use crate::families::lbc::rule_setting;
use crate::families::na::fig13_control::anim::{write_animation, Scene, Track, SIMULATOR};
use plotters::style::RGBColor;
use std::path::PathBuf;

/// A method's name in words, for the legend (the CSVs keep the identifiers).
fn words(method: Method) -> &'static str {
    match method {
        Method::Lbc => "LBC",
        Method::Naive => "naive blend",
        Method::Tracker1 => "tracker 1 alone",
        Method::Tracker2 => "tracker 2 alone",
        Method::OpenLoop1 => "tape 1, open loop",
        Method::OpenLoop2 => "tape 2, open loop",
        Method::Bptt => "BPTT re-optimized, open loop",
        Method::BpttTracked => "BPTT re-optimized, tracked",
    }
}

/// Every figure of the experiment ([`crate::experiment::Family::figures`]).
pub(super) fn figures(fig: &FigureSink, tables: &Tables) -> Result<Vec<PathBuf>, Error> {
    let rows = TargetRow::from_table(tables.require("targets")?);
    let (lo, hi) = rows
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), r| {
            (a.min(r.desired_target), b.max(r.desired_target))
        });
    // Every method a plain line: the panel strokes each by its colour (eight strokes for the
    // eight methods), so none hides another by colour alone.
    // The methods' legend once, in the first panel; the others stroke each method the same.
    let panel =
        |title: &str, y: fn(&TargetRow) -> f64, y_label: &str, line: (&str, f64), legend: bool| {
            let mut series: Vec<Series> = Method::ALL
                .iter()
                .enumerate()
                .map(|(c, &mm)| {
                    let pts = rows
                        .iter()
                        .filter(|r| r.method == mm.name())
                        .map(|r| (r.desired_target, y(r).max(1e-3)))
                        .collect();
                    let label = if legend {
                        words(mm).to_string()
                    } else {
                        String::new()
                    };
                    Series::line(label, pts, c).mark(Mark::stroke_of(c))
                })
                .collect();
            series
                .push(Series::line(line.0, vec![(lo, line.1), (hi, line.1)], 9).mark(Mark::Dashed));
            Panel {
                title: title.into(),
                x_label: "desired landing target x (m)".into(),
                y_label: y_label.into(),
                log_y: true,
                series,
                ..Panel::default()
            }
        };
    let error_label = "final error (RMS of (s - s_d)/tolerance)";
    // Tall panels: the nine-entry legend then fits above the data (the plot raises the
    // top of the y range for it) instead of covering it.
    let mut files = fig.draw(
        "error",
        &Figure {
            panel_size: (640, 640),
            ..Figure::grid(
                vec![
                    panel(
                        "on the physical simulator",
                        |r| r.final_error_simulator,
                        error_label,
                        ("tolerance (error 1)", 1.0),
                        true,
                    ),
                    panel(
                        "on the emulator (lines as on the left)",
                        |r| r.final_error_emulator,
                        error_label,
                        ("tolerance (error 1)", 1.0),
                        false,
                    ),
                    panel(
                        "simulator landing: distance from the desired x (lines as on the left)",
                        // The verdict's third measure: how far along x from the desired
                        // target the simulator landing ends (m).
                        |r| (r.final_axis_value - r.desired_target).abs(),
                        "|x_final - x_desired| (m)",
                        ("1 m", 1.0),
                        false,
                    ),
                ],
                3,
            )
        },
    )?;
    files.extend(animation(fig, tables)?);
    files.extend(crate::families::lbc::entropy_figure(
        fig,
        tables,
        "LBC of the emulator-learned landings: entropy of α over time",
    )?);
    Ok(files)
}

/// GIF of the LBC motion on the simulator at the in-between target nearest the middle, with
/// BPTT's re-optimized open-loop replay beside it.
fn animation(fig: &FigureSink, tables: &Tables) -> Result<Vec<PathBuf>, Error> {
    let (Some(tr), Some(_)) = (tables.get("trajectory"), tables.get("rule")) else {
        return Ok(Vec::new());
    };
    let get = |k: &str| rule_setting(tables, k).unwrap_or(f64::NAN);
    let (c1, c2, dt) = (get("component1"), get("component2"), get("super_step_s"));
    let rows = TrajectoryRow::from_table(tr);
    let mid = 0.5 * (c1 + c2);
    let Some(pick) = rows
        .iter()
        .map(|r| r.desired_target)
        .filter(|&x| x > c1 && x < c2)
        .min_by(|a, b| (*a - mid).abs().total_cmp(&(*b - mid).abs()))
    else {
        return Ok(Vec::new());
    };
    // The model whose state names the table's columns are.
    let (model, names) = [NetModel::Lander, NetModel::Truck]
        .into_iter()
        .map(|m| (m, m.state_names()))
        .find(|(_, names)| names.iter().all(|c| tr.column(c).is_some()))
        .ok_or_else(|| {
            crate::experiment::other("trajectory: no model's state variables among its columns")
        })?;
    let states = states_of(tr, &names);
    let track = |method: Method| -> Vec<Vec<f64>> {
        rows.iter()
            .zip(&states)
            .filter(|(r, _)| r.desired_target == pick && r.method == method.name())
            .map(|(_, x)| x.clone())
            .collect()
    };
    let lbc = track(Method::Lbc);
    let g = tables.require("goal")?;
    let Some(gr) = GoalRow::from_table(g)
        .iter()
        .position(|r| r.desired_target == pick)
    else {
        return Ok(Vec::new());
    };
    let goal: Vec<f64> = states_of(g, &names).swap_remove(gr);
    let tracks = vec![
        Track {
            label: "LBC of the two emulator-derived trackers".into(),
            color: RGBColor(200, 60, 30),
            states: lbc,
        },
        Track {
            label: "BPTT re-optimized, open-loop replay".into(),
            color: SIMULATOR,
            states: track(Method::Bptt),
        },
    ];
    let (p, _) = write_animation(
        &fig.dir,
        &format!("{}_lbc", fig.id),
        &Scene::for_model(model),
        &format!("lander: LBC to x = {} m on the simulator", sig(pick)),
        "simulator: LBC closed loop (red), re-optimized BPTT tape open loop (grey), goal (green)",
        dt,
        &goal,
        &tracks,
    )?;
    Ok(vec![p])
}
