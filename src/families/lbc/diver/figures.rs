//! The figures of both dive families.

use super::coordination::POSE_COLUMNS;
use super::interpolation::{MOTION_COLUMNS, MOTION_DIVES};
use crate::experiment::output::Tables;
use crate::experiment::plot::{Figure, FigureSink, Mark, Panel, Series};
use crate::experiment::Error;
use crate::families::lbc::film;
use crate::physics::diver::diver;
use std::path::PathBuf;

/// Per-method column of rows `m == name` as (x, y) points.
fn method_points(x: &[f64], m: &[String], y: &[f64], name: &str) -> Vec<(f64, f64)> {
    (0..x.len())
        .filter(|&r| m[r] == name)
        .map(|r| (x[r], y[r]))
        .collect()
}

/// The interpolation's figures: entry angles and objectives over the desired entry, the dives.
pub(super) fn interpolation(fig: &FigureSink, tables: &Tables) -> Result<Vec<PathBuf>, Error> {
    let t = tables.require("interpolation")?;
    let (g, m, a, e) = (
        t.f64s("desired_angle"),
        t.strs("method"),
        t.f64s("reached_angle"),
        t.f64s("excess_objective"),
    );
    let lo = g.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = g.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let mut series = vec![Series::line("desired", vec![(lo, lo), (hi, hi)], 7).mark(Mark::Dashed)];
    let mut excess = Vec::new();
    for (c, name) in ["lbc", "naive", "direct"].iter().enumerate() {
        series.push(Series::line(*name, method_points(&g, &m, &a, name), c).mark(Mark::LinePoints));
        if *name != "direct" {
            excess.push(
                Series::line(*name, method_points(&g, &m, &e, name), c).mark(Mark::LinePoints),
            );
        }
    }
    let panels = vec![
        Panel {
            title: "diver: entry angle reached vs desired".into(),
            x_label: "desired entry angle (rad from vertical)".into(),
            y_label: "reached entry angle (rad)".into(),
            series,
            ..Default::default()
        },
        Panel {
            title: "objective with the reconstructed cost, excess over direct DDP".into(),
            x_label: "desired entry angle (rad from vertical)".into(),
            y_label: "(J - J*) / J*".into(),
            series: excess,
            ..Default::default()
        },
    ];
    let mut files = fig.draw("entry", &Figure::grid(panels, 2))?;
    // Filmstrip and GIF of the component dives, the naive average and LBC.
    if let Some(mt) = tables.get("motion") {
        let (names, t) = (mt.strs("dive"), mt.f64s("t"));
        let cols: Vec<Vec<f64>> = MOTION_COLUMNS[2..].iter().map(|c| mt.f64s(c)).collect();
        let q: Vec<Vec<f64>> = (0..t.len())
            .map(|r| cols.iter().map(|c| c[r]).collect())
            .collect();
        let dives: Vec<film::Dive> = MOTION_DIVES
            .iter()
            .enumerate()
            .map(|(c, name)| {
                let rows: Vec<usize> = (0..names.len()).filter(|&r| names[r] == *name).collect();
                film::Dive {
                    label: match *name {
                        "naive" | "lbc" => format!("{name}, weights for vertical"),
                        other => format!("{other} component"),
                    },
                    color: c,
                    t: rows.iter().map(|&r| t[r]).collect(),
                    q: rows.iter().map(|&r| q[r].as_slice()).collect(),
                }
            })
            .filter(|d| !d.t.is_empty())
            .collect();
        if !dives.is_empty() {
            let tree = diver();
            files.extend(fig.draw("filmstrip", &film::diver_filmstrip(&tree, &dives, 0.2, 1.6))?);
            let frames = film::diver_frames(
                &tree,
                &dives,
                2.0,
                "One take-off; naive and LBC weights projected for vertical",
            );
            files.push(fig.gif("dives", &frames, film::GIF_DELAY_CS)?);
        }
    }
    files.extend(crate::families::lbc::entropy_figure(
        fig,
        tables,
        "diver interpolation: entropy of LBC's weights α over the dive",
    )?);
    Ok(files)
}

/// The coordination's figure: entry errors and objectives over the take-off rate.
pub(super) fn coordination(fig: &FigureSink, tables: &Tables) -> Result<Vec<PathBuf>, Error> {
    let t = tables.require("coordination")?;
    let (w, m, e, j) = (
        t.f64s("initial_omega"),
        t.strs("method"),
        t.f64s("entry_error"),
        t.f64s("objective"),
    );
    let series = |col: &[f64]| -> Vec<Series> {
        [
            ("lbc", "LBC of three trackers"),
            ("single", "single 1 rad/s tracker"),
        ]
        .iter()
        .enumerate()
        .map(|(c, (name, words))| {
            Series::line(*words, method_points(&w, &m, col, name), c).mark(if c == 0 {
                Mark::LinePoints
            } else {
                Mark::Dashed
            })
        })
        .collect()
    };
    // The verdict's vertical-entry tolerance, from the run's rule table.
    let tolerance = crate::families::lbc::rule_setting(tables, "entry_tolerance");
    let mut entry_series = series(&e);
    let (lo, hi) = w
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| {
            (a.min(x), b.max(x))
        });
    if let Some(tol) = tolerance.filter(|_| lo.is_finite()) {
        entry_series.push(
            Series::line(
                format!("vertical-entry tolerance ({tol} rad)"),
                vec![(lo, tol), (hi, tol)],
                7,
            )
            .mark(Mark::Pattern { dash: 3, gap: 4 }),
        );
    }
    let panels = vec![
        Panel {
            title: "entry error vs take-off angular velocity".into(),
            x_label: "initial angular velocity (rad/s)".into(),
            y_label: "|entry angle| (rad, log scale)".into(),
            series: entry_series,
            // One far miss would flatten the rest on a linear axis.
            log_y: true,
            ..Default::default()
        },
        Panel {
            title: "objective of the executed dive".into(),
            x_label: "initial angular velocity (rad/s)".into(),
            y_label: "objective".into(),
            series: series(&j),
            log_y: true,
            ..Default::default()
        },
    ];
    let mut files = fig.draw("entry", &Figure::grid(panels, 2))?;
    files.extend(coordination_poses(fig, tables)?);
    files.extend(crate::families::lbc::entropy_figure(
        fig,
        tables,
        "diver coordination: entropy of LBC's weights α over the dive",
    )?);
    Ok(files)
}

/// Figure `poses` (Fig. 8 as the paper shows it): the final pose at every take-off rate, LBC
/// above the single tracker, each captioned with its rate and entry error.
fn coordination_poses(fig: &FigureSink, tables: &Tables) -> Result<Vec<PathBuf>, Error> {
    let Some(t) = tables.get("poses").filter(|t| !t.is_empty()) else {
        return Ok(vec![]);
    };
    let (w, m, e) = (
        t.f64s("initial_omega"),
        t.strs("method"),
        t.f64s("entry_error"),
    );
    let cols: Vec<Vec<f64>> = POSE_COLUMNS[3..].iter().map(|c| t.f64s(c)).collect();
    let q: Vec<Vec<f64>> = (0..w.len())
        .map(|r| cols.iter().map(|c| c[r]).collect())
        .collect();
    let rows: Vec<(String, usize, Vec<film::Pose>)> = [
        ("lbc", "LBC of the three dive trackers (w = 1)"),
        ("single", "the single tracker of the 1 rad/s dive"),
    ]
    .iter()
    .enumerate()
    .map(|(c, (name, title))| {
        let poses = (0..w.len())
            .filter(|&r| m[r] == *name)
            .map(|r| film::Pose {
                q: &q[r],
                caption: format!("{} rad/s: {:.2} rad", w[r], e[r]),
            })
            .collect();
        (
            format!("{title}: final pose per take-off rate (caption: |entry angle|)"),
            c,
            poses,
        )
    })
    .collect();
    let tree = diver();
    fig.draw("poses", &film::diver_pose_rows(&tree, &rows, 2.0))
}
