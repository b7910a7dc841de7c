//! `lbc_walking`'s figures and animation.

use super::report::{track_of, CONTROLLERS, TERRAINS};
use super::rows::{MotionRow, SearchRow, SweepRow, WalkRow, WeightRow};
use crate::experiment::output::Tables;
use crate::experiment::plot::{Figure, FigureSink, Legend, Mark, Panel, Series};
use crate::experiment::report::sig;
use crate::experiment::rows::TableRow;
use crate::experiment::Error;
use crate::families::lbc::film::{biped_body, fitted, to_scale};
use crate::families::lbc::rule_setting;
use crate::physics::biped::Biped;
use crate::physics::ground::{Contact, Terrain};
use std::path::PathBuf;

pub(super) fn figures(fig: &FigureSink, tables: &Tables) -> Result<Vec<PathBuf>, Error> {
    let mut files = Vec::new();
    let walks = WalkRow::from_table(tables.require("walks")?);
    let x_of = |name: &str| CONTROLLERS.iter().position(|x| *x == name).unwrap_or(0) as f64;
    let mut series: Vec<Series> = Vec::new();
    for (k, terrain) in TERRAINS.iter().enumerate() {
        let off = (k as f64 - 1.0) * 0.22;
        let on: Vec<&WalkRow> = walks.iter().filter(|r| r.terrain == *terrain).collect();
        let pts: Vec<(f64, f64)> = on
            .iter()
            .map(|r| (x_of(&r.controller) + off, r.distance_m))
            .collect();
        let labels = on
            .iter()
            .map(|r| {
                if r.fell != 0 {
                    "✗".to_string()
                } else {
                    String::new()
                }
            })
            .collect();
        let mut s =
            Series::line(terrain.replace('_', "-"), pts, k).mark(Mark::Bars { half_width: 0.1 });
        s.point_labels = labels;
        series.push(s);
    }
    let panel = Panel {
        title: "distance walked by each controller on each terrain".into(),
        x_label: "controller".into(),
        y_label: "pelvis advance along x (m)".into(),
        series,
        x_categories: CONTROLLERS.iter().map(|s| s.to_string()).collect(),
        x_range: Some((-0.5, CONTROLLERS.len() as f64 - 0.5)),
        legend: Legend::UpperLeft,
        ..Panel::default()
    };
    files.extend(fig.draw("walks", &Figure::grid(vec![panel], 1))?);
    // Weights against position, with the track's profile.
    let weights = WeightRow::from_table(tables.require("weights")?);
    let hill = track_of(tables);
    let Terrain::FlatThenHill { start_m: start, .. } = hill else {
        unreachable!("track_of builds a flat-then-hill track")
    };
    let mut s: Vec<Series> = TERRAINS
        .iter()
        .enumerate()
        .map(|(k, terrain)| {
            let pts = weights
                .iter()
                .filter(|r| r.terrain == *terrain)
                .map(|r| (r.x_m, r.alpha_hill))
                .collect();
            Series::line(terrain.replace('_', "-"), pts, k)
        })
        .collect();
    s.push(Series::line("hill starts", vec![(start, 0.0), (start, 1.0)], 3).mark(Mark::Dashed));
    let x_max = weights.iter().map(|r| r.x_m).fold(1.0, f64::max);
    let alpha_panel = Panel {
        title: "LBC's weight of the hill walker".into(),
        x_label: "pelvis x (m)".into(),
        y_label: "α_hill".into(),
        series: s,
        y_range: Some((-0.02, 1.02)),
        legend: Legend::Auto,
        ..Panel::default()
    };
    let prof: Vec<(f64, f64)> = (0..=200)
        .map(|i| {
            let x = x_max * i as f64 / 200.0;
            (x, hill.height_slope(x).0)
        })
        .collect();
    let profile = Panel {
        title: "the flat-then-hill track".into(),
        x_label: "x (m)".into(),
        y_label: "ground height (m)".into(),
        series: vec![Series::line("ground", prof, 2)],
        ..Panel::default()
    };
    files.extend(fig.draw("weights", &Figure::grid(vec![alpha_panel, profile], 1))?);
    // The temperature sweep.
    let sweep = SweepRow::from_table(tables.require("lambda_sweep")?);
    let mut ds: Vec<Series> = Vec::new();
    let mut fell_labelled = false;
    for (k, terrain) in TERRAINS.iter().enumerate() {
        let on: Vec<&SweepRow> = sweep.iter().filter(|r| r.terrain == *terrain).collect();
        ds.push(
            Series::line(
                terrain.replace('_', "-"),
                on.iter().map(|r| (r.lambda, r.distance_m)).collect(),
                k,
            )
            .mark(Mark::LinePoints),
        );
        let fell: Vec<(f64, f64)> = on
            .iter()
            .filter(|r| r.fell != 0)
            .map(|r| (r.lambda, r.distance_m))
            .collect();
        if !fell.is_empty() {
            let label = if fell_labelled { "" } else { "fell" };
            fell_labelled = true;
            ds.push(Series::line(label, fell, 3).mark(Mark::Points));
        }
    }
    let lam = rule_setting(tables, "lambda").unwrap_or(f64::NAN);
    let track: Vec<&SweepRow> = sweep
        .iter()
        .filter(|r| r.terrain == "flat_then_hill")
        .collect();
    let panels = vec![
        Panel {
            title: "LBC's distance against λ".into(),
            x_label: "λ (log)".into(),
            y_label: "pelvis advance (m)".into(),
            log_x: true,
            series: ds,
            ..Panel::default()
        },
        Panel {
            title: format!(
                "α_hill on the track against λ (the rule's λ = {})",
                sig(lam)
            ),
            x_label: "λ (log)".into(),
            y_label: "mean α_hill".into(),
            log_x: true,
            y_range: Some((0.0, 1.0)),
            series: vec![
                Series::line(
                    "flat part",
                    track
                        .iter()
                        .map(|r| (r.lambda, r.alpha_hill_flat_part))
                        .collect(),
                    0,
                )
                .mark(Mark::LinePoints),
                Series::line(
                    "hill part",
                    track
                        .iter()
                        .map(|r| (r.lambda, r.alpha_hill_hill_part))
                        .collect(),
                    2,
                )
                .mark(Mark::LinePoints),
                Series::line("rule's λ", vec![(lam, 0.0), (lam, 1.0)], 3).mark(Mark::Dashed),
            ],
            ..Panel::default()
        },
    ];
    files.extend(fig.draw("lambda", &Figure::grid(panels, 2))?);
    // The search grid.
    let search = SearchRow::from_table(tables.require("search")?);
    let mut torsos: Vec<f64> = search.iter().map(|r| r.torso_offset).collect();
    torsos.dedup();
    let mut ss: Vec<Series> = torsos
        .iter()
        .enumerate()
        .map(|(k, &tv)| {
            Series::line(
                format!("torso {tv:+.2} rad"),
                search
                    .iter()
                    .filter(|r| r.torso_offset == tv)
                    .map(|r| (r.hip_offset, r.distance_m))
                    .collect(),
                k,
            )
            .mark(Mark::LinePoints)
        })
        .collect();
    let fell: Vec<(f64, f64)> = search
        .iter()
        .filter(|r| r.fell != 0)
        .map(|r| (r.hip_offset, r.distance_m))
        .collect();
    // Written at their points (dots alone hide under the lines' own markers), one label per
    // hip offset at its highest fall, with the count where several walkers fell there (their
    // points lie too close to label apart).
    let mut fell_s = Series::line("", fell.clone(), 7).mark(Mark::Points);
    fell_s.point_labels = fell
        .iter()
        .enumerate()
        .map(|(i, &(x, _))| {
            let here: Vec<usize> = (0..fell.len()).filter(|&j| fell[j].0 == x).collect();
            let top = here
                .iter()
                .copied()
                .max_by(|&a, &b| fell[a].1.total_cmp(&fell[b].1).then(b.cmp(&a)))
                .unwrap_or(i);
            match (top == i, here.len()) {
                (false, _) => String::new(),
                (true, 1) => "✗ fell".into(),
                (true, n) => format!("✗ {n} fell"),
            }
        })
        .collect();
    ss.push(fell_s);
    let chosen: Vec<(f64, f64)> = search
        .iter()
        .filter(|r| r.chosen != 0)
        .map(|r| (r.hip_offset, r.distance_m))
        .collect();
    let mut chosen_s = Series::line("", chosen.clone(), 7).mark(Mark::Points);
    chosen_s.point_labels = vec!["chosen: the hill walker".into(); chosen.len()];
    ss.push(chosen_s);
    let panel = Panel {
        title: "hill walker search on the incline".into(),
        x_label: "swing-hip offset (rad)".into(),
        y_label: "distance up the incline (m)".into(),
        series: ss,
        legend: Legend::LowerLeft,
        ..Panel::default()
    };
    files.extend(fig.draw("search", &Figure::grid(vec![panel], 1))?);
    if let Some(m) = tables.get("motion") {
        let m = MotionRow::from_table(m);
        files.extend(fig.draw("filmstrip", &track_filmstrip(&m, hill)?)?);
        // In real time: each frame shows for the simulated time between samples.
        let step = m
            .windows(2)
            .map(|w| w[1].t_s - w[0].t_s)
            .find(|d| *d > 0.0)
            .unwrap_or(0.1);
        files.push(fig.gif(
            "track",
            &track_frames(&m, hill)?,
            (100.0 * step).round().max(1.0) as u32,
        )?);
    }
    Ok(files)
}

/// A biped's segments as polylines: torso, each leg hip-knee-ankle, each sole heel-toe (a sole
/// apart from its leg: a polyline that turns back on itself draws a spike at the turn).
/// Seconds between the filmstrip's poses, and the time it covers.
const STRIP_EVERY_S: f64 = 0.5;
const STRIP_END_S: f64 = 9.0;

/// LBC's poses (coloured by α_hill: blue flat walker, red hill walker) and the flat walker's
/// alone (grey, until it falls) every [`STRIP_EVERY_S`] over the first [`STRIP_END_S`] on the
/// flat-then-hill track, to scale.
fn track_filmstrip(m: &[MotionRow], terrain: Terrain) -> Result<Figure, Error> {
    let b = Biped::new(terrain, Contact::default());
    let picked = |name: &str| -> Vec<usize> {
        let rows: Vec<usize> = (0..m.len())
            .filter(|&i| m[i].controller == name && m[i].t_s <= STRIP_END_S + 1e-9)
            .collect();
        let mut next = 0.0;
        rows.into_iter()
            .filter(|&i| {
                let keep = m[i].t_s + 1e-9 >= next;
                if keep {
                    next = m[i].t_s + STRIP_EVERY_S;
                }
                keep
            })
            .collect()
    };
    let (lbc, flat) = (picked("lbc"), picked("flat"));
    let xs: Vec<f64> = lbc.iter().chain(&flat).map(|&i| m[i].q0).collect();
    let (x0, x1) = (
        xs.iter().cloned().fold(f64::INFINITY, f64::min) - 0.6,
        xs.iter().cloned().fold(f64::NEG_INFINITY, f64::max) + 0.6,
    );
    let (h0, h1) = (terrain.height_slope(x0).0, terrain.height_slope(x1).0);
    let (size, xr, yr) = fitted((x0, x1), (h0.min(h1) - 0.2, h0.max(h1) + 1.8), 300);
    let ground: Vec<(f64, f64)> = (0..=200)
        .map(|k| {
            let gx = xr.0 + (xr.1 - xr.0) * k as f64 / 200.0;
            (gx, terrain.height_slope(gx).0)
        })
        .collect();
    let state = |i: usize| -> Vec<f64> { m[i].q().to_vec() };
    let mut flat_series = vec![Series::line("ground", ground.clone(), 2)];
    for (n, &i) in flat.iter().enumerate() {
        for (k, seg) in biped_body(&b, &state(i)).into_iter().enumerate() {
            let label = if n == 0 && k == 0 {
                "flat walker alone"
            } else {
                ""
            };
            flat_series.push(Series::line(label, seg, 7));
        }
    }
    let mut lbc_series = vec![Series::line("ground", ground, 2)];
    for (n, &i) in lbc.iter().enumerate() {
        // Colour 0 (blue) while the flat walker leads, 3 (red) once the hill walker does.
        let color = if m[i].alpha_hill >= 0.5 { 3 } else { 0 };
        for (k, seg) in biped_body(&b, &state(i)).into_iter().enumerate() {
            let first = k == 0
                && lbc[..n]
                    .iter()
                    .all(|&j| (m[j].alpha_hill >= 0.5) != (m[i].alpha_hill >= 0.5));
            let label = match (first, color) {
                (true, 0) => "LBC, α_hill < 0.5",
                (true, _) => "LBC, α_hill ≥ 0.5",
                _ => "",
            };
            lbc_series.push(Series::line(label, seg, color));
        }
    }
    let fell = flat.last().map_or(0.0, |&i| m[i].t_s);
    Ok(to_scale(
        (size, xr, yr),
        "x (m)",
        vec![
            (
                format!(
                    "LBC on the flat-then-hill track, every {STRIP_EVERY_S} s for {STRIP_END_S} s"
                ),
                lbc_series,
            ),
            (
                format!(
                    "the flat walker alone, every {STRIP_EVERY_S} s (its last pose at {fell:.1} s)"
                ),
                flat_series,
            ),
        ],
    ))
}

/// Frames of LBC (colour) and the flat walker alone (grey) on the flat-then-hill track, the view
/// following LBC's pelvis.
fn track_frames(m: &[MotionRow], terrain: Terrain) -> Result<Vec<Figure>, Error> {
    let b = Biped::new(terrain, Contact::default());
    let lbc: Vec<usize> = (0..m.len()).filter(|&i| m[i].controller == "lbc").collect();
    let flat: Vec<usize> = (0..m.len())
        .filter(|&i| m[i].controller == "flat")
        .collect();
    let state = |i: usize| -> Vec<f64> { m[i].q().to_vec() };
    let mut frames = Vec::new();
    for (n, &i) in lbc.iter().enumerate() {
        let x = m[i].q0;
        let (size, xr, yr) = fitted(
            (x - 2.0, x + 2.0),
            (
                b.terrain.height_slope(x).0 - 0.3,
                b.terrain.height_slope(x).0 + 1.9,
            ),
            360,
        );
        let ground: Vec<(f64, f64)> = (0..=80)
            .map(|k| {
                let gx = xr.0 + (xr.1 - xr.0) * k as f64 / 80.0;
                (gx, terrain.height_slope(gx).0)
            })
            .collect();
        let mut series = vec![Series::line("ground", ground, 2)];
        // The flat walker at the same time, while it has not fallen (its samples end there).
        if let Some(&j) = flat.get(n) {
            for (k, seg) in biped_body(&b, &state(j)).into_iter().enumerate() {
                series.push(Series::line(
                    if k == 0 { "flat walker alone" } else { "" },
                    seg,
                    7,
                ));
            }
        } else {
            series.push(Series::line("flat walker alone: fell", vec![], 7));
        }
        for (k, seg) in biped_body(&b, &state(i)).into_iter().enumerate() {
            series.push(Series::line(if k == 0 { "LBC" } else { "" }, seg, 0));
        }
        let title = format!(
            "LBC of the flat and hill walkers   t = {:.1} s   α_hill = {:.2}",
            m[i].t_s, m[i].alpha_hill
        );
        frames.push(to_scale((size, xr, yr), "x (m)", vec![(title, series)]));
    }
    Ok(frames)
}
