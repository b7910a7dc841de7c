//! The figures: final poses and filmstrip from the test start (Fig. 7), the showcase GIF, the
//! sweep heat maps and the λ sweep.

use super::rows::{LambdaRow, ShowcaseRow, SweepRow, TrajectoryRow};
use super::setup::POLICIES;
use crate::experiment::output::Tables;
use crate::experiment::plot::{Figure, FigureSink, Heatmap, Mark, Panel, Series};
use crate::experiment::rows::TableRow;
use crate::experiment::Error;
use crate::families::lbc::film;
use crate::physics::acrobot::Acrobot;
use std::path::PathBuf;

/// Fig. 7 as a filmstrip: one row per policy from the test start, the acrobot's pose every
/// `FRAME_DT` seconds left to right (frames `FRAME_GAP` m apart), the bar marked at each frame.
fn filmstrip(acro: &Acrobot, traj: &[TrajectoryRow]) -> Figure {
    const FRAME_DT: f64 = 0.5;
    const FRAME_GAP: f64 = 4.5;
    // Time as one column: film::nearest picks among row indices by it.
    let t: Vec<f64> = traj.iter().map(|r| r.t_s).collect();
    let t_end = t
        .iter()
        .copied()
        .filter(|v| v.is_finite())
        .fold(0.0, f64::max);
    let frames = (t_end / FRAME_DT).floor() as usize + 1;
    let mut panels = Vec::new();
    for (c, name) in POLICIES.iter().enumerate() {
        let rows: Vec<usize> = (0..traj.len())
            .filter(|&r| traj[r].policy == *name)
            .collect();
        if rows.is_empty() {
            continue;
        }
        let mut series = Vec::new();
        let mut bars = Vec::new();
        let mut ticks = Vec::new();
        for k in 0..frames {
            let tk = k as f64 * FRAME_DT;
            let Some(r) = film::nearest(&rows, &t, tk) else {
                continue;
            };
            let r = &traj[r];
            let off = k as f64 * FRAME_GAP;
            let label = if k == 0 {
                format!(
                    "{}: pose every {FRAME_DT} s, t = 0 to {t_end} s left to right",
                    words(name)
                )
            } else {
                String::new()
            };
            series.push(
                Series::line(
                    label,
                    film::acrobot_pose(acro, off, r.theta1_rad, r.theta2_rad),
                    c,
                )
                .mark(Mark::LinePoints),
            );
            bars.push((off, 0.0));
            ticks.push((off, format!("{tk:.1} s")));
        }
        series.push(Series::line("bar (pivot)", bars, 7).mark(Mark::Points));
        panels.push(Panel {
            title: format!(
                "{} from the test start (handstand: both links straight up, 2 m)",
                words(name)
            ),
            x_label: format!(
                "time of each frame (s); frames drawn {FRAME_GAP} m apart, to the scale of the height axis"
            ),
            y_label: "height above the bar (m)".into(),
            series,
            x_range: Some((-2.4, (frames as f64 - 0.5) * FRAME_GAP)),
            y_range: Some((-2.3, 3.6)),
            x_ticks: std::mem::take(&mut ticks),
            ..Default::default()
        });
    }
    let mut f = Figure::grid(panels, 1);
    f.panel_size = ((frames as u32 * 150).max(900), 300);
    f
}

/// A policy's name in words, for legends and titles (the CSVs keep the identifiers).
fn words(policy: &str) -> &str {
    match policy {
        "tracker1" => "tracker 1",
        "tracker2" => "tracker 2",
        "naive" => "naive blend",
        "lbc" => "LBC",
        "naive_sum" => "naive sum",
        other => other,
    }
}

/// Fig. 7 (final poses, filmstrip, the showcase GIF), the sweep heat maps and the λ sweep.
pub(super) fn figures(fig: &FigureSink, tables: &Tables) -> Result<Vec<PathBuf>, Error> {
    let traj = TrajectoryRow::from_table(tables.require("trajectories")?);
    let acro = Acrobot::default();
    let mut files = fig.draw("final_pose", &final_pose(&acro, &traj))?;
    files.extend(fig.draw("filmstrip", &filmstrip(&acro, &traj))?);
    // The showcase GIF: the trackers and LBC from a start where both trackers fail.
    if let Some(sc) = tables.get("showcase") {
        if let Some(file) = showcase_gif(fig, &acro, &ShowcaseRow::from_table(sc))? {
            files.push(file);
        }
    }
    // Sweep heat maps.
    let sweep = SweepRow::from_table(tables.require("sweep")?);
    files.extend(fig.draw("sweep", &sweep_maps(&sweep))?);
    // λ sweep.
    let lambdas = LambdaRow::from_table(tables.require("lambda_sweep")?);
    if let Some(f) = lambda_figure(&lambdas, sweep.len()) {
        files.extend(fig.draw("lambda", &f)?);
    }
    Ok(files)
}

/// Fig. 7's final poses from the test start, the shoulder angle over time and LBC's weight
/// of tracker 1 with α's entropy (from `trajectories`).
fn final_pose(acro: &Acrobot, traj: &[TrajectoryRow]) -> Figure {
    // Final poses.
    let mut series = vec![
        Series::line("handstand", vec![(0.0, 0.0), (0.0, 1.0), (0.0, 2.0)], 7).mark(Mark::Dashed),
    ];
    let mut angle_series = Vec::new();
    // Final poses drawn so far (name, elbow and tip): a pose that lands on an earlier one says
    // so in its label, since it is drawn exactly over it.
    let mut drawn: Vec<(&str, [f64; 2], [f64; 2])> = Vec::new();
    for (c, name) in POLICIES.iter().enumerate() {
        let rows: Vec<&TrajectoryRow> = traj.iter().filter(|r| r.policy == *name).collect();
        let Some(last) = rows.last() else { continue };
        let [p1, p2] = acro.positions(&[last.theta1_rad, last.theta2_rad, 0.0, 0.0]);
        let same = drawn.iter().find(|(_, q1, q2)| {
            (0..2).all(|k| (q1[k] - p1[k]).abs() < 1e-3 && (q2[k] - p2[k]).abs() < 1e-3)
        });
        let label = match same {
            Some((other, _, _)) => format!("{} (the same pose as {})", words(name), words(other)),
            None => words(name).to_string(),
        };
        drawn.push((name, p1, p2));
        series.push(
            Series::line(label, vec![(0.0, 0.0), (p1[0], p1[1]), (p2[0], p2[1])], c)
                .mark(Mark::LinePoints),
        );
        angle_series.push(Series::line(
            words(name),
            rows.iter().map(|r| (r.t_s, r.theta1_rad)).collect(),
            c,
        ));
    }
    let pose = Panel {
        title: "final poses from the test start".into(),
        x_label: "x (m)".into(),
        y_label: "height above the bar (m)".into(),
        series,
        // Equal metres on both axes: the plotting area of a 640 x 440 panel is about
        // 558 x 350 pixels.
        x_range: Some((-3.5, 3.5)),
        y_range: Some((-2.2, 2.2)),
        // The legend in the upper left, where the automatic corner put it over a pose: the
        // final poses end near the handstand (straight up) or hang below the bar.
        legend: crate::experiment::plot::Legend::UpperLeft,
        ..Default::default()
    };
    let lbc_rows: Vec<&TrajectoryRow> = traj
        .iter()
        .filter(|r| r.policy == "lbc" && r.alpha1.is_finite())
        .collect();
    let angles = Panel {
        title: "shoulder angle theta1 (handstand: pi/2)".into(),
        x_label: "time (s)".into(),
        y_label: "theta1 (rad)".into(),
        series: angle_series,
        ..Default::default()
    };
    let weights = Panel {
        title: "LBC: weight of tracker 1 and entropy of alpha".into(),
        x_label: "time (s)".into(),
        y_label: "alpha_1, H(alpha) / ln 2".into(),
        series: vec![
            Series::line(
                "alpha_1",
                lbc_rows.iter().map(|r| (r.t_s, r.alpha1)).collect(),
                3,
            ),
            Series::line(
                "entropy",
                lbc_rows.iter().map(|r| (r.t_s, r.alpha_entropy)).collect(),
                5,
            )
            .mark(Mark::Dashed),
        ],
        y_range: Some((-0.05, 1.05)),
        ..Default::default()
    };
    Figure::grid(vec![pose, angles, weights], 3)
}

/// The showcase GIF (from `showcase`), `None` without rows.
fn showcase_gif(
    fig: &FigureSink,
    acro: &Acrobot,
    sc: &[ShowcaseRow],
) -> Result<Option<PathBuf>, Error> {
    // film::acrobot_frames reads the motions' rows out of these columns.
    let col = |f: fn(&ShowcaseRow) -> f64| sc.iter().map(f).collect::<Vec<f64>>();
    let (st, sa1, sa2) = (col(|r| r.t_s), col(|r| r.theta1_rad), col(|r| r.theta2_rad));
    let rows: Vec<Vec<usize>> = POLICIES
        .iter()
        .map(|name| (0..sc.len()).filter(|&r| sc[r].policy == *name).collect())
        .collect();
    let motions: Vec<film::Motion> = POLICIES
        .iter()
        .enumerate()
        .filter(|(i, _)| !rows[*i].is_empty())
        .map(|(i, name)| film::Motion {
            label: words(name).into(),
            color: i,
            rows: &rows[i],
        })
        .collect();
    if let Some(&r0) = motions.first().and_then(|m| m.rows.first()) {
        let r0 = &sc[r0];
        let caption = if r0.rescued == 1 {
            format!(
                "From ({}, {}) deg at rest: both trackers fail, LBC swings up",
                r0.theta1_deg, r0.theta2_deg
            )
        } else {
            format!(
                "From the test start ({}, {}) deg at rest",
                r0.theta1_deg, r0.theta2_deg
            )
        };
        let frames = film::acrobot_frames(acro, &motions, (&st, &sa1, &sa2), 4.5, &caption);
        return Ok(Some(fig.gif("swingup", &frames, film::GIF_DELAY_CS)?));
    }
    Ok(None)
}

/// The sweep heat maps: per policy, the final distance over the start states (from `sweep`).
fn sweep_maps(sweep: &[SweepRow]) -> Figure {
    const CLAMP: f64 = 3.0;
    let mut maps = Vec::new();
    for name in POLICIES {
        let rows: Vec<&SweepRow> = sweep.iter().filter(|r| r.policy == name).collect();
        if rows.is_empty() {
            continue;
        }
        let nx = rows
            .iter()
            .take_while(|r| r.theta2_deg == rows[0].theta2_deg)
            .count()
            .max(1);
        let ny = rows.len() / nx;
        maps.push(Heatmap {
            title: format!(
                "{}: final distance to handstand (capped at {CLAMP})",
                words(name)
            ),
            x_label: "start theta1 (deg)".into(),
            y_label: "start theta2 (deg)".into(),
            x_range: (rows[0].theta1_deg, rows[nx - 1].theta1_deg),
            y_range: (rows[0].theta2_deg, rows[rows.len() - 1].theta2_deg),
            nx,
            ny,
            values: rows.iter().map(|r| r.final_distance.min(CLAMP)).collect(),
            value_label: "distance".into(),
            diverging: false,
            range: Some((0.0, CLAMP)),
        });
    }
    Figure::heatmaps(maps, 3)
}

/// LBC over λ on the start sweep (from `lambda_sweep`; `sweep_rows`, the sweep's rows, one per
/// start and policy, counts the starts), `None` without rows.
fn lambda_figure(lambdas: &[LambdaRow], sweep_rows: usize) -> Option<Figure> {
    if lambdas.is_empty() {
        return None;
    }
    let pts = |f: &dyn Fn(&LambdaRow) -> f64| lambdas.iter().map(|r| (r.lambda, f(r))).collect();
    let starts = sweep_rows as f64 / POLICIES.len() as f64;
    let frac = |r: &LambdaRow| r.both_fail_successes as f64 / (r.both_fail_starts as f64).max(1.0);
    let cover = |r: &LambdaRow| r.sweep_successes as f64 / starts.max(1.0);
    let panel = Panel {
        title: "LBC vs temperature lambda over the start sweep".into(),
        x_label: "lambda".into(),
        y_label: "fraction / normalized entropy".into(),
        log_x: true,
        series: vec![
            Series::line("success, all starts", pts(&cover), 0).mark(Mark::LinePoints),
            Series::line("success, both trackers fail", pts(&frac), 1).mark(Mark::LinePoints),
            Series::line("mean entropy of alpha", pts(&|r| r.sweep_mean_entropy), 2)
                .mark(Mark::Dashed),
        ],
        y_range: Some((-0.05, 1.05)),
        ..Default::default()
    };
    Some(Figure::grid(vec![panel], 1))
}
