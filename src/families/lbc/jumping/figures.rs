//! `lbc_jumping`'s figures and animation.

use super::job::METHODS;
use super::report::Jumps;
use super::rows::{JumpRow, MotionRow, WeightRow};
use crate::experiment::output::Tables;
use crate::experiment::plot::{Figure, FigureSink, Legend, Mark, Panel, Series};
use crate::experiment::report::sig;
use crate::experiment::rows::TableRow;
use crate::experiment::Error;
use crate::families::lbc::film::{diver_body, fitted, to_scale};
use crate::families::lbc::{alpha_panel, rule_setting};
use crate::physics::jumper::Jumper;
use std::path::PathBuf;

pub(super) fn figures(fig: &FigureSink, tables: &Tables) -> Result<Vec<PathBuf>, Error> {
    let mut files = Vec::new();
    let t = Jumps::of(tables.require("jumps")?);
    // Take-off error and height reached per method.
    let mut errors = Vec::new();
    let mut heights = Vec::new();
    for (k, m) in METHODS.iter().enumerate() {
        let rows: Vec<&JumpRow> = t.rows(m).collect();
        let marks: Vec<String> = rows
            .iter()
            .map(|r| {
                if r.landed == 0.0 {
                    "✗".into()
                } else {
                    String::new()
                }
            })
            .collect();
        let mut s = Series::line(
            *m,
            rows.iter()
                .map(|r| (r.desired_height_m, r.takeoff_error))
                .collect(),
            k,
        )
        .mark(Mark::LinePoints);
        s.point_labels = marks.clone();
        errors.push(s);
        let mut h = Series::line(
            *m,
            rows.iter()
                .map(|r| (r.desired_height_m, r.height_m))
                .collect(),
            k,
        )
        .mark(Mark::LinePoints);
        h.point_labels = marks;
        heights.push(h);
    }
    let (lo, hi) =
        t.0.iter()
            .map(|r| r.desired_height_m)
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
                (a.min(v), b.max(v))
            });
    // The rule's take-off tolerance as a band: a take-off inside it reaches its target.
    if let Some(tol) = rule_setting(tables, "takeoff_tolerance") {
        errors.insert(
            0,
            Series::band(
                "take-off tolerance (rule)",
                &[(lo, 0.0), (hi, 0.0)],
                &[(lo, tol), (hi, tol)],
                7,
            ),
        );
    }
    let takeoff = Panel {
        title: "take-off error (✗: did not land)".into(),
        x_label: "desired jump height (m)".into(),
        y_label: "take-off error (Q_T norm)".into(),
        series: errors,
        legend: Legend::Auto,
        ..Panel::default()
    };
    files.extend(fig.draw("takeoff", &Figure::grid(vec![takeoff.clone()], 1))?);
    // Drawn last, so the reference (which the desired take-off is built from, and nearly
    // equals) does not hide it.
    heights.push(Series::line("desired", vec![(lo, lo), (hi, hi)], 7).mark(Mark::Dashed));
    let panel = Panel {
        title: "jump height at take-off (✗: did not land)".into(),
        x_label: "desired jump height (m)".into(),
        y_label: "jump height reached (m)".into(),
        series: heights,
        legend: Legend::Auto,
        ..Panel::default()
    };
    // Beside the heights, the take-off error the verdict reads, with its tolerance.
    files.extend(fig.draw("heights", &Figure::grid(vec![panel, takeoff], 2))?);
    // LBC's weights over the take-off.
    let w = WeightRow::from_table(tables.require("weights")?);
    let wd: Vec<f64> = w.iter().map(|r| r.desired_height_m).collect();
    let wt: Vec<f64> = w.iter().map(|r| r.t_s).collect();
    let wa: Vec<f64> = w.iter().map(|r| r.alpha_low).collect();
    let panel = alpha_panel(
        "LBC's weight of the low jump's tracker over the take-off",
        "time from the crouch (s)",
        "α_low",
        &wd,
        &wt,
        &wa,
    );
    files.extend(fig.draw("weights", &Figure::grid(vec![panel], 1))?);
    // The middle desired jump: LBC's and the naive blend's bodies over time.
    let m = MotionRow::from_table(tables.require("motion")?);
    let state = |i: usize| -> Vec<f64> { m[i].q().to_vec() };
    let tree = Jumper::default().tree;
    let middle = rule_setting(tables, "middle_desired").unwrap_or(f64::NAN);
    let rows_of =
        |name: &str| -> Vec<usize> { (0..m.len()).filter(|&i| m[i].method == name).collect() };
    let (lbc_rows, naive_rows) = (rows_of("lbc"), rows_of("naive"));
    // One panel per controller (each drawn solid): the body every 0.1 s until 1.2 s (take-off,
    // flight and landing; the hold that follows is still).
    let spacing = 0.6;
    let mut panels = Vec::new();
    let mut size = (0, 0);
    for (name, rows, color) in [("LBC", &lbc_rows, 0usize), ("naive blend", &naive_rows, 1)] {
        let mut strip = Vec::new();
        let mut n = 0usize;
        let mut last = f64::NEG_INFINITY;
        for &i in rows.iter() {
            if m[i].t_s - last < 0.1 - 1e-9 || m[i].t_s > 1.2 + 1e-9 {
                continue;
            }
            last = m[i].t_s;
            let off = (n as f64 * spacing, 0.0);
            let pose = body(&tree, &state(i), off, if n == 0 { name } else { "" }, color);
            // Frames in flight (no point of the body within 1 cm of the ground) are marked
            // "air", since a 0.2 m jump is hard to see at this scale.
            let lowest = pose
                .iter()
                .flat_map(|s| s.points.iter().map(|p| p.1))
                .fold(f64::INFINITY, f64::min);
            if lowest > 0.01 {
                let mut air = Series::line("", vec![(off.0, 1.85)], 7).mark(Mark::Points);
                air.point_labels = vec!["air".into()];
                strip.push(air);
            }
            strip.extend(pose);
            n += 1;
        }
        // Room on the right for the legend, past the last pose.
        let x_hi = n as f64 * spacing + 1.4;
        strip.insert(0, Series::line("ground", vec![(-0.4, 0.0), (x_hi, 0.0)], 7));
        let (sz, xr, yr) = fitted((-0.4, x_hi), (-0.1, 2.0), 260);
        size = sz;
        panels.push(Panel {
            title: format!(
                "{name}: the {} m jump every 0.1 s from the crouch (left) to 1.2 s",
                sig(middle)
            ),
            x_label: "frame position (m; bodies spaced 0.6 m apart)".into(),
            y_label: "height (m)".into(),
            series: strip,
            x_range: Some(xr),
            y_range: Some(yr),
            legend: Legend::UpperRight,
            ..Panel::default()
        });
    }
    let mut f = Figure::grid(panels, 1);
    f.panel_size = size;
    files.extend(fig.draw("jumps", &f)?);
    // The animation: both side by side.
    let mut frames = Vec::new();
    for (k, &i) in lbc_rows.iter().enumerate() {
        let mut series = vec![Series::line("ground", vec![(-0.6, 0.0), (1.8, 0.0)], 7)];
        series.extend(body(&tree, &state(i), (0.0, 0.0), "LBC", 0));
        let other = naive_rows
            .get(k)
            .copied()
            .or_else(|| naive_rows.last().copied());
        let mut title = format!("t = {:.2} s   α_low: LBC {:.2}", m[i].t_s, m[i].alpha_low);
        if let Some(o) = other {
            series.extend(body(&tree, &state(o), (1.1, 0.0), "naive blend", 1));
            title.push_str(&format!(", naive {:.2}", m[o].alpha_low));
        }
        frames.push(to_scale(
            fitted((-0.6, 1.8), (-0.1, 2.1), 300),
            "x (m; the naive blend's body drawn 1.1 m to the right)",
            vec![(title, series)],
        ));
    }
    if !frames.is_empty() {
        let dt = if lbc_rows.len() > 1 {
            m[lbc_rows[1]].t_s - m[lbc_rows[0]].t_s
        } else {
            0.1
        };
        files.push(fig.gif("jump_anim", &frames, ((dt * 100.0).round() as u32).max(2))?);
    }
    Ok(files)
}

/// The body's series at configuration `q` shifted by `off`, labelled once.
fn body(
    tree: &crate::physics::planar::PlanarTree,
    q: &[f64],
    off: (f64, f64),
    label: &str,
    color: usize,
) -> Vec<Series> {
    diver_body(tree, q, off)
        .into_iter()
        .enumerate()
        .map(|(k, seg)| {
            // Dots at the joints; solid whatever else the panel holds.
            Series::line(if k == 0 { label } else { "" }, seg, color).mark(Mark::LinePoints)
        })
        .collect()
}
