//! The figure: blend weights, tug forces and poses over time (Fig. 9).

use super::job::WeightRow;
use crate::experiment::output::Tables;
use crate::experiment::plot::{Figure, FigureSink, Mark, Panel, Series};
use crate::experiment::rows::TableRow;
use crate::experiment::Error;
use crate::families::lbc::rule_setting;
use std::f64::consts::FRAC_PI_2;
use std::path::PathBuf;

/// Fig. 9: the blend weights under the tugs (scripted, mirrored, none), the forces and the poses.
pub(super) fn figures(fig: &FigureSink, tables: &Tables) -> Result<Vec<PathBuf>, Error> {
    let w = WeightRow::from_table(tables.require("weights")?);
    // One quantity over time.
    let over_t =
        |f: fn(&WeightRow) -> f64| -> Vec<(f64, f64)> { w.iter().map(|r| (r.t_s, f(r))).collect() };
    let (t0, t1) = (
        w.first().map_or(0.0, |r| r.t_s),
        w.last().map_or(1.0, |r| r.t_s),
    );
    // The walls the reaches end on, in the hand's frame (x = ± the wall distance).
    let mut hand = vec![Series::line("hand x", over_t(|r| r.hand_x_m), 2)];
    if let Some(d) = rule_setting(tables, "walls_distance") {
        for (sgn, label) in [(1.0, "walls (the hand's reach stops there)"), (-1.0, "")] {
            hand.push(
                Series::line(label, vec![(t0, sgn * d), (t1, sgn * d)], 5)
                    .mark(Mark::Pattern { dash: 10, gap: 4 }),
            );
        }
    }
    let mut panels = vec![
        Panel {
            title: "LBC blend weight under tugs on the hand".into(),
            x_label: "time (s)".into(),
            y_label: "weight".into(),
            series: vec![
                Series::line("alpha forward reach", over_t(|r| r.alpha_forward), 0),
                Series::line(
                    "alpha forward, mirrored tugs",
                    over_t(|r| r.alpha_forward_mirrored),
                    1,
                )
                .mark(Mark::Dashed),
                Series::line(
                    "alpha forward, no tugs",
                    over_t(|r| r.alpha_forward_baseline),
                    7,
                )
                .mark(Mark::Dashed),
            ],
            y_range: Some((-0.05, 1.05)),
            ..Default::default()
        },
        Panel {
            title: "the scripted tugs on the hand".into(),
            x_label: "time (s)".into(),
            y_label: "tug force (N, + pulls forward)".into(),
            series: vec![Series::line(
                "tug force, as scripted",
                over_t(|r| r.force_x_n),
                3,
            )],
            ..Default::default()
        },
        Panel {
            title: "hand position".into(),
            x_label: "time (s)".into(),
            y_label: "hand x (m, + is forward)".into(),
            series: hand,
            ..Default::default()
        },
    ];
    // The body's lean (+ forward) with LBC and with no reach, and the fall angle.
    let lean = |f: fn(&WeightRow) -> f64| -> Vec<(f64, f64)> {
        w.iter().map(|r| (r.t_s, FRAC_PI_2 - f(r))).collect()
    };
    let mut series = vec![
        Series::line("LBC, tugs as scripted", lean(|r| r.body_angle_rad), 0),
        Series::line("LBC, mirrored tugs", lean(|r| r.body_angle_mirrored_rad), 1)
            .mark(Mark::Dashed),
        Series::line(
            "no reach (arm held), tugs as scripted",
            lean(|r| r.body_angle_no_reach_rad),
            3,
        ),
    ];
    if let Some(fall) = rule_setting(tables, "fall_angle") {
        for (sgn, label) in [(1.0, "fall angle"), (-1.0, "")] {
            series.push(
                Series::line(label, vec![(t0, sgn * fall), (t1, sgn * fall)], 7).mark(Mark::Dashed),
            );
        }
    }
    panels.push(Panel {
        title: "body lean from upright".into(),
        x_label: "time (s)".into(),
        y_label: "lean (rad, + is forward)".into(),
        series,
        ..Default::default()
    });
    let mut files = fig.draw("weights", &Figure::grid(panels, 1))?;
    files.extend(crate::families::lbc::entropy_figure(
        fig,
        tables,
        "push recovery: entropy of LBC's weights α over time",
    )?);
    Ok(files)
}
