//! The figures of both dive families.

use super::rows::{
    CoordinationRow, InterpolationRow, Method, MotionDive, MotionRow, PoseRow, Tracking,
};
use crate::experiment::output::Tables;
use crate::experiment::plot::{Figure, FigureSink, Mark, Panel, Series};
use crate::experiment::rows::TableRow;
use crate::experiment::Error;
use crate::families::lbc::film;
use crate::physics::diver::diver;
use std::path::PathBuf;

/// (x, y) of the interpolation's rows of method `m`.
fn interpolation_points(
    rows: &[InterpolationRow],
    m: Method,
    xy: impl Fn(&InterpolationRow) -> (f64, f64),
) -> Vec<(f64, f64)> {
    rows.iter()
        .filter(|r| r.method == m.name())
        .map(xy)
        .collect()
}

/// (x, y) of the coordination's rows of dive `m`.
fn coordination_points(
    rows: &[CoordinationRow],
    m: Tracking,
    xy: impl Fn(&CoordinationRow) -> (f64, f64),
) -> Vec<(f64, f64)> {
    rows.iter()
        .filter(|r| r.method == m.name())
        .map(xy)
        .collect()
}

/// The interpolation's figures: entry angles and objectives over the desired entry, the dives.
pub(super) fn interpolation(fig: &FigureSink, tables: &Tables) -> Result<Vec<PathBuf>, Error> {
    let rows = InterpolationRow::from_table(tables.require("interpolation")?);
    let desired = rows.iter().map(|r| r.desired_angle);
    let lo = desired.clone().fold(f64::INFINITY, f64::min);
    let hi = desired.fold(f64::NEG_INFINITY, f64::max);
    let mut series = vec![Series::line("desired", vec![(lo, lo), (hi, hi)], 7).mark(Mark::Dashed)];
    let mut excess = Vec::new();
    for (c, m) in Method::COMPARED.into_iter().enumerate() {
        let reached = interpolation_points(&rows, m, |r| (r.desired_angle, r.reached_angle));
        series.push(Series::line(m.name(), reached, c).mark(Mark::LinePoints));
        if m != Method::Direct {
            let e = interpolation_points(&rows, m, |r| (r.desired_angle, r.excess_objective));
            excess.push(Series::line(m.name(), e, c).mark(Mark::LinePoints));
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
        let motion = MotionRow::from_table(mt);
        let q: Vec<[f64; film::DIVER_COORDS]> = motion.iter().map(MotionRow::coords).collect();
        let dives: Vec<film::Dive> = MotionDive::ALL
            .into_iter()
            .enumerate()
            .map(|(c, dive)| {
                let rows: Vec<usize> = (0..motion.len())
                    .filter(|&r| motion[r].dive == dive.name())
                    .collect();
                film::Dive {
                    label: dive.label(),
                    color: c,
                    t: rows.iter().map(|&r| motion[r].t_s).collect(),
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
    let rows = CoordinationRow::from_table(tables.require("coordination")?);
    let series = |y: fn(&CoordinationRow) -> f64| -> Vec<Series> {
        [
            (Tracking::Lbc, "LBC of three trackers"),
            (Tracking::Single, "single 1 rad/s tracker"),
        ]
        .into_iter()
        .enumerate()
        .map(|(c, (m, words))| {
            let pts = coordination_points(&rows, m, |r| (r.initial_omega, y(r)));
            Series::line(words, pts, c).mark(if c == 0 {
                Mark::LinePoints
            } else {
                Mark::Dashed
            })
        })
        .collect()
    };
    // The verdict's vertical-entry tolerance, from the run's rule table.
    let tolerance = crate::families::lbc::rule_setting(tables, "entry_tolerance");
    let mut entry_series = series(|r| r.entry_error);
    let (lo, hi) = rows
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), r| {
            (a.min(r.initial_omega), b.max(r.initial_omega))
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
            series: series(|r| r.objective),
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
    let poses = PoseRow::from_table(t);
    let q: Vec<[f64; film::DIVER_COORDS]> = poses.iter().map(PoseRow::coords).collect();
    let rows: Vec<(String, usize, Vec<film::Pose>)> = [
        (Tracking::Lbc, "LBC of the three dive trackers (w = 1)"),
        (Tracking::Single, "the single tracker of the 1 rad/s dive"),
    ]
    .into_iter()
    .enumerate()
    .map(|(c, (m, title))| {
        let poses = poses
            .iter()
            .zip(&q)
            .filter(|(p, _)| p.method == m.name())
            .map(|(p, q)| film::Pose {
                q,
                caption: format!("{} rad/s: {:.2} rad", p.initial_omega, p.entry_error),
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
