//! `lbc_stepping`'s figures and animation.

use super::job::gaps;
use super::job::METHODS;
use super::report::Targets;
use super::rows::{MotionRow, StepRow, WalkStepRow, WeightRow};
use crate::experiment::output::Tables;
use crate::experiment::plot::{Figure, FigureSink, Legend, Mark, Panel, Series};
use crate::experiment::rows::TableRow;
use crate::experiment::Error;
use crate::families::lbc::film::{biped_body, fitted, to_scale};
use crate::families::lbc::{alpha_panel, rule_setting};
use crate::physics::biped::Biped;
use std::path::PathBuf;

pub(super) fn figures(fig: &FigureSink, tables: &Tables) -> Result<Vec<PathBuf>, Error> {
    let mut files = Vec::new();
    let t = Targets::of(tables.require("targets")?);
    let tol = rule_setting(tables, "tolerance_m").unwrap_or(0.0);
    let (lo, hi) =
        t.0.iter()
            .map(|r| r.desired_length_m)
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
                (a.min(v), b.max(v))
            });
    // The desired line dashed, the tolerance's edges dotted (both grey).
    let band = |d: f64, label: &str, mark: Mark| {
        Series::line(label, vec![(lo, lo + d), (hi, hi + d)], 7).mark(mark)
    };
    let dotted = Mark::Pattern { dash: 2, gap: 5 };
    let mut series = vec![
        band(0.0, "desired", Mark::Dashed),
        band(tol, "± tolerance", dotted),
        band(-tol, "", dotted),
    ];
    let mut effort = Vec::new();
    for (k, m) in METHODS.iter().enumerate() {
        let rows: Vec<&StepRow> = t.rows(m).collect();
        let mut s = Series::line(
            *m,
            rows.iter()
                .map(|r| (r.desired_length_m, r.reached_length_m))
                .collect(),
            k,
        )
        .mark(Mark::LinePoints);
        s.point_labels = rows
            .iter()
            .map(|r| {
                if r.fell != 0.0 {
                    "✗".into()
                } else {
                    String::new()
                }
            })
            .collect();
        series.push(s);
        effort.push(
            Series::line(
                *m,
                rows.iter()
                    .map(|r| (r.desired_length_m, r.effort))
                    .collect(),
                k,
            )
            .mark(Mark::LinePoints),
        );
    }
    let lengths = Panel {
        title: "step length reached on the simulator (landing heel from the stance heel)".into(),
        x_label: "desired step length (m)".into(),
        y_label: "reached step length (m)".into(),
        series,
        legend: Legend::UpperLeft,
        ..Panel::default()
    };
    files.extend(fig.draw("lengths", &Figure::grid(vec![lengths], 1))?);
    let effort = Panel {
        title: "effort of each controller".into(),
        x_label: "desired step length (m)".into(),
        y_label: "effort ½∫uᵀRu dt".into(),
        series: effort,
        legend: Legend::Auto,
        ..Panel::default()
    };
    files.extend(fig.draw("effort", &Figure::grid(vec![effort], 1))?);
    // LBC's weights over the step.
    let w = WeightRow::from_table(tables.require("weights")?);
    let wd: Vec<f64> = w.iter().map(|r| r.desired_length_m).collect();
    let wt: Vec<f64> = w.iter().map(|r| r.t_s).collect();
    let wa: Vec<f64> = w.iter().map(|r| r.alpha_short).collect();
    let mut weights = alpha_panel(
        "LBC's weight of the short step over the step",
        "time in the step (s)",
        "α_short",
        &wd,
        &wt,
        &wa,
    );
    // Room above the weights for the legend: every corner of [0, 1] holds a curve.
    weights.y_range = Some((-0.02, 1.45));
    weights.legend = Legend::UpperRight;
    files.extend(fig.draw("weights", &Figure::grid(vec![weights], 1))?);
    // The walk: poses at each step's end, the footholds and the gaps.
    let motion = MotionRow::from_table(tables.require("motion")?);
    let walk = WalkStepRow::from_table(tables.require("walk")?);
    let state = |i: usize| -> Vec<f64> { motion[i].q().to_vec() };
    let mut holds = vec![walk.first().map_or(0.0, |r| r.stance_heel_m)];
    holds.extend(walk.iter().map(|r| r.foothold_m));
    let gap = gaps(&holds, tol);
    let b = Biped::default();
    let x_lo = holds[0] - 0.6;
    let x_hi = holds.last().copied().unwrap_or(0.0) + 0.6;
    let scene = |extra: Vec<Series>| -> Vec<Series> {
        let mut s = vec![Series::line("ground", vec![(x_lo, 0.0), (x_hi, 0.0)], 7)];
        for (k, g) in gap.iter().enumerate() {
            s.push(
                Series::line(
                    if k == 0 {
                        "gap (a sole must not touch)"
                    } else {
                        ""
                    },
                    vec![(g.0, -0.01), (g.1, -0.01)],
                    3,
                )
                .mark(Mark::LinePoints),
            );
        }
        s.extend(extra);
        s
    };
    // The last sample of each step, and the first of the walk.
    let mut ends: Vec<usize> = (0..motion.len())
        .filter(|&i| i + 1 == motion.len() || motion[i + 1].step != motion[i].step)
        .collect();
    ends.insert(0, 0);
    let mut poses = Vec::new();
    for (n, &i) in ends.iter().enumerate() {
        for (k, seg) in biped_body(&b, &state(i)).into_iter().enumerate() {
            poses.push(Series::line(
                if n == 0 && k == 0 {
                    "body at the start and at each step's end"
                } else {
                    ""
                },
                seg,
                0,
            ));
        }
    }
    // Headroom above the 1.4 m bodies for the legend, which would hide the first poses.
    let f = to_scale(
        fitted((x_lo, x_hi), (-0.1, 2.2), 420),
        "x (m)",
        vec![(format!("LBC's walk over {} gaps", gap.len()), scene(poses))],
    );
    files.extend(fig.draw("walk", &f)?);
    let mut frames = Vec::new();
    for (i, r) in motion.iter().enumerate() {
        let mut body = Vec::new();
        for (k, seg) in biped_body(&b, &state(i)).into_iter().enumerate() {
            body.push(Series::line(if k == 0 { "LBC" } else { "" }, seg, 0));
        }
        let title = format!(
            "LBC stepping over gaps   step {}   t = {:.2} s   α_short = {:.2}",
            r.step, r.t_s, r.alpha_short
        );
        frames.push(to_scale(
            fitted((x_lo, x_hi), (-0.1, 1.6), 300),
            "x (m)",
            vec![(title, scene(body))],
        ));
    }
    if !frames.is_empty() {
        let dt = if motion.len() > 1 {
            motion[1].t_s - motion[0].t_s
        } else {
            0.1
        };
        files.push(fig.gif("walk_anim", &frames, ((dt * 100.0).round() as u32).max(2))?);
    }
    Ok(files)
}
