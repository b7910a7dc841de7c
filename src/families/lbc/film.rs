//! Filmstrips and animated GIFs of the LBC characters: the acrobot swing-up (LBC Fig. 7) and
//! the diver (Fig. 6), drawn as [`Figure`]s with one metre the same length on both axes and
//! animated through [`crate::experiment::plot::FigureSink::gif`] (25 frames per second, in
//! real time, the time on every frame).

use crate::experiment::plot::{Figure, Legend, Mark, Panel, Series};
use crate::physics::acrobot::Acrobot;
use crate::physics::diver::entry_angle;
use crate::physics::planar::PlanarTree;

/// Time between GIF frames (s).
pub const GIF_FRAME_DT: f64 = 0.04;
/// GIF frame delay (hundredths of a second): [`GIF_FRAME_DT`], so the motion plays in real time.
pub const GIF_DELAY_CS: u32 = 4;
/// Times the last frame is repeated before the animation loops (about half a second).
const GIF_HOLD: usize = 12;

/// Pixels a [`Panel`] spends outside its plot area horizontally and vertically (tick labels,
/// title, the y-label strip, margins), approximately.
const PANEL_CHROME: (f64, f64) = (82.0, 116.0);

/// Colour of the body's torso and of reference marks (palette index: grey).
const MARK: usize = 7;
/// Colour of the feet-to-hands line at entry in the filmstrip (palette index: olive).
const ENTRY: usize = 8;

/// x and y ranges covering `x` and `y`, the shorter widened about its centre so that one metre
/// has (about) the same length on both axes of a panel of `size` pixels.
pub fn equal_aspect(x: (f64, f64), y: (f64, f64), size: (u32, u32)) -> ((f64, f64), (f64, f64)) {
    let w = (size.0 as f64 - PANEL_CHROME.0).max(1.0);
    let h = (size.1 as f64 - PANEL_CHROME.1).max(1.0);
    let per_m = (w / (x.1 - x.0)).min(h / (y.1 - y.0));
    let widen = |r: (f64, f64), px: f64| {
        let (c, half) = (0.5 * (r.0 + r.1), 0.5 * px / per_m);
        (c - half, c + half)
    };
    (widen(x, w), widen(y, h))
}

/// A panel `height` pixels high and as wide as `x` and `y` need at one scale (at least
/// `MIN_WIDTH`), with those ranges widened by [`equal_aspect`] to fill it.
pub fn fitted(x: (f64, f64), y: (f64, f64), height: u32) -> ((u32, u32), (f64, f64), (f64, f64)) {
    let per_m = (height as f64 - PANEL_CHROME.1).max(1.0) / (y.1 - y.0);
    let width = ((x.1 - x.0) * per_m + PANEL_CHROME.0)
        .ceil()
        .max(MIN_WIDTH as f64) as u32;
    let size = (width, height);
    let (xr, yr) = equal_aspect(x, y, size);
    (size, xr, yr)
}

/// A figure of `panels` (title, series) in one column, drawn to scale: each panel of the
/// `size` and the x and height ranges [`fitted`] gives, `x_label` under its x axis, the
/// height (m) up, the legend upper left.
pub fn to_scale(
    (size, xr, yr): ((u32, u32), (f64, f64), (f64, f64)),
    x_label: &str,
    panels: Vec<(String, Vec<Series>)>,
) -> Figure {
    let panels = panels
        .into_iter()
        .map(|(title, series)| Panel {
            title,
            x_label: x_label.into(),
            y_label: "height (m)".into(),
            series,
            x_range: Some(xr),
            y_range: Some(yr),
            legend: Legend::UpperLeft,
            ..Panel::default()
        })
        .collect();
    let mut f = Figure::grid(panels, 1);
    f.panel_size = size;
    f
}

/// Narrowest panel (pixels), for the legend and the title.
const MIN_WIDTH: u32 = 720;

/// The row among `rows` whose time `t[row]` is closest to `tk`.
pub fn nearest(rows: &[usize], t: &[f64], tk: f64) -> Option<usize> {
    rows.iter()
        .copied()
        .min_by(|&a, &b| (t[a] - tk).abs().total_cmp(&(t[b] - tk).abs()))
}

/// Times of the GIF frames: every [`GIF_FRAME_DT`] from 0, then `t_end`, repeated to hold
/// the last frame.
pub fn gif_times(t_end: f64) -> Vec<f64> {
    let n = (t_end / GIF_FRAME_DT + 1e-9).floor() as usize;
    let mut v: Vec<f64> = (0..=n).map(|k| k as f64 * GIF_FRAME_DT).collect();
    if t_end - n as f64 * GIF_FRAME_DT > 1e-9 {
        v.push(t_end);
    }
    v.extend(std::iter::repeat_n(t_end, GIF_HOLD));
    v
}

/// The acrobot's links as the polyline bar → hip → feet (m), shifted `off` along x.
pub fn acrobot_pose(acro: &Acrobot, off: f64, th1: f64, th2: f64) -> Vec<(f64, f64)> {
    let [e, h] = acro.positions(&[th1, th2, 0.0, 0.0]);
    vec![(off, 0.0), (off + e[0], e[1]), (off + h[0], h[1])]
}

/// One motion of an animation: its label, palette colour and rows in the columns (t, …).
pub struct Motion<'a> {
    /// Legend label.
    pub label: String,
    /// Palette index.
    pub color: usize,
    /// Its rows in the table columns, in time order.
    pub rows: &'a [usize],
}

/// GIF frames of acrobot motions side by side, `gap` metres apart (columns t, θ1, θ2 in
/// radians), each with the handstand dashed, the bar and the feet's trail so far; `caption`
/// and the time head every frame.
pub fn acrobot_frames(
    acro: &Acrobot,
    motions: &[Motion],
    (t, a1, a2): (&[f64], &[f64], &[f64]),
    gap: f64,
    caption: &str,
) -> Vec<Figure> {
    let reach = acro.l1 + acro.l2;
    let right = gap * (motions.len().max(1) - 1) as f64;
    let (size, xr, yr) = fitted(
        (-reach - 0.3, right + reach + 0.3),
        (-reach - 0.3, reach + 0.9),
        470,
    );
    let t_end = motions
        .iter()
        .flat_map(|m| m.rows.iter().map(|&r| t[r]))
        .fold(0.0, f64::max);
    gif_times(t_end)
        .into_iter()
        .map(|tk| {
            let mut series = Vec::new();
            for (i, m) in motions.iter().enumerate() {
                let off = i as f64 * gap;
                let ghost = if i == 0 { "handstand" } else { "" };
                series.push(
                    Series::line(ghost, vec![(off, 0.0), (off, acro.l1), (off, reach)], MARK)
                        .mark(Mark::Dashed),
                );
                let now: Vec<usize> = m.rows.iter().copied().filter(|&r| t[r] <= tk).collect();
                let trail = now
                    .iter()
                    .map(|&r| acrobot_pose(acro, off, a1[r], a2[r])[2])
                    .collect();
                series.push(Series::line("", trail, m.color));
                if let Some(r) = nearest(m.rows, t, tk) {
                    series.push(
                        Series::line(
                            m.label.clone(),
                            acrobot_pose(acro, off, a1[r], a2[r]),
                            m.color,
                        )
                        .mark(Mark::LinePoints),
                    );
                }
            }
            let bars = (0..motions.len()).map(|i| (i as f64 * gap, 0.0)).collect();
            series.push(Series::line("bar (pivot)", bars, MARK).mark(Mark::Points));
            let mut f = Figure::grid(
                vec![Panel {
                    title: format!("{caption}   t = {tk:.2} s"),
                    x_label: format!("x (m), acrobats {gap} m apart"),
                    y_label: "height above the bar (m)".into(),
                    series,
                    x_range: Some(xr),
                    y_range: Some(yr),
                    legend: Legend::LowerRight,
                    ..Default::default()
                }],
                1,
            );
            f.panel_size = size;
            f
        })
        .collect()
}

/// Index of the diver's joint coordinates in the `motion` table's columns x, y, torso, neck,
/// shoulder, elbow, hip, knee, ankle (generalized coordinates of [`crate::physics::diver`]).
pub const DIVER_COORDS: usize = 9;

/// The diver's body at configuration `q` (m), shifted by `off`: the torso (hip → neck) and the
/// limbs (neck → head top, shoulder → elbow → hands, hip → knee → ankle → toes).
pub fn diver_body(tree: &PlanarTree, q: &[f64], off: (f64, f64)) -> [Vec<(f64, f64)>; 4] {
    let p = |i: usize, r: f64| {
        let v = tree.point(q, i, r);
        (v[0] + off.0, v[1] + off.1)
    };
    let len = |i: usize| tree.links[i].length;
    [
        vec![p(0, 0.0), p(0, len(0))],
        vec![p(1, 0.0), p(1, len(1))],
        vec![p(2, 0.0), p(3, 0.0), p(3, len(3))],
        vec![p(0, 0.0), p(5, 0.0), p(6, 0.0), p(6, len(6))],
    ]
}

/// Series drawing the diver's body (torso in grey with dots, limbs in `color`; only the first
/// limb labelled `label`, the torso `torso_label`).
fn diver_series(
    body: [Vec<(f64, f64)>; 4],
    label: &str,
    torso_label: &str,
    color: usize,
) -> Vec<Series> {
    let [torso, head, arm, leg] = body;
    vec![
        Series::line(label, leg, color),
        Series::line("", arm, color),
        Series::line("", head, color).mark(Mark::LinePoints),
        Series::line(torso_label, torso, MARK).mark(Mark::LinePoints),
    ]
}

/// Lowest point of the body (m).
fn lowest(body: &[Vec<(f64, f64)>; 4]) -> f64 {
    body.iter()
        .flatten()
        .map(|p| p.1)
        .fold(f64::INFINITY, f64::min)
}

/// The feet-to-hands line of a body (the line the entry angle measures).
fn entry_line(body: &[Vec<(f64, f64)>; 4]) -> Vec<(f64, f64)> {
    vec![body[3][3], body[2][2]]
}

/// A diver's motion: rows of the `motion` table and the coordinates q of each row.
pub struct Dive<'a> {
    /// Name (legend and panel titles).
    pub label: String,
    /// Palette index.
    pub color: usize,
    /// Time of each row (s).
    pub t: Vec<f64>,
    /// Generalized coordinates of each row ([`DIVER_COORDS`] values).
    pub q: Vec<&'a [f64]>,
}

impl Dive<'_> {
    fn entry(&self, tree: &PlanarTree) -> f64 {
        self.q.last().map_or(f64::NAN, |q| entry_angle(tree, q))
    }
    fn start_x(&self) -> f64 {
        self.q.first().map_or(0.0, |q| q[0])
    }
    fn t_end(&self) -> f64 {
        self.t.last().copied().unwrap_or(0.0)
    }
    fn at(&self, tk: f64) -> Option<&[f64]> {
        let rows: Vec<usize> = (0..self.t.len()).collect();
        nearest(&rows, &self.t, tk).map(|r| self.q[r])
    }
}

/// Height of the water line: the lowest point of any dive's last pose (entry is the end of the
/// flight; the model has no water).
fn water(tree: &PlanarTree, dives: &[Dive]) -> f64 {
    dives
        .iter()
        .filter_map(|d| d.q.last().map(|q| lowest(&diver_body(tree, q, (0.0, 0.0)))))
        .fold(f64::INFINITY, f64::min)
}

/// Vertical range of every pose of every dive, and the water line.
fn heights(tree: &PlanarTree, dives: &[Dive]) -> (f64, f64) {
    let mut r = (water(tree, dives), f64::NEG_INFINITY);
    for q in dives.iter().flat_map(|d| &d.q) {
        for p in diver_body(tree, q, (0.0, 0.0)).iter().flatten() {
            r = (r.0.min(p.1), r.1.max(p.1));
        }
    }
    r
}

/// Largest forward drift of the hip over any dive (m).
fn drift(dives: &[Dive]) -> f64 {
    dives
        .iter()
        .map(|d| d.q.last().map_or(0.0, |q| q[0]) - d.start_x())
        .fold(0.0, f64::max)
}

/// The water line from `x0` to `x1` at height `y`, labelled.
fn water_series(x0: f64, x1: f64, y: f64, t_end: f64) -> Series {
    Series::line(
        format!("water (height of the lowest entry pose, t = {t_end:.2} s)"),
        vec![(x0, y), (x1, y)],
        9,
    )
    .mark(Mark::Dashed)
}

/// The diver filmstrip: one panel per dive, its pose every `frame_dt` seconds left to right
/// (`gap` metres apart plus its own forward drift, true heights), the torso in grey, the
/// water line, and the feet-to-hands line at entry with its angle from vertical.
pub fn diver_filmstrip(tree: &PlanarTree, dives: &[Dive], frame_dt: f64, gap: f64) -> Figure {
    let t_end = dives.iter().map(Dive::t_end).fold(0.0, f64::max);
    let frames = (t_end / frame_dt + 1e-9).floor() as usize + 1;
    let (lo, hi) = heights(tree, dives);
    let y_water = water(tree, dives);
    let (size, xr, yr) = fitted(
        (-1.2, (frames - 1) as f64 * gap + drift(dives) + 1.2),
        (lo - 0.3, hi + 0.3),
        520,
    );
    let panels = dives
        .iter()
        .map(|d| {
            let mut series = vec![water_series(xr.0, xr.1, y_water, t_end)];
            let mut ticks = Vec::new();
            for k in 0..frames {
                let tk = (k as f64 * frame_dt).min(t_end);
                ticks.push((k as f64 * gap, format!("{tk:.1} s")));
                let Some(q) = d.at(tk) else { continue };
                let body = diver_body(tree, q, (k as f64 * gap - d.start_x(), 0.0));
                let first = k == 0;
                series.extend(diver_series(
                    body.clone(),
                    if first { &d.label } else { "" },
                    if first { "torso (hip to neck)" } else { "" },
                    d.color,
                ));
                if k + 1 == frames {
                    series.push(
                        Series::line(
                            format!(
                                "feet-to-hands line at entry: {:.3} rad from vertical",
                                d.entry(tree)
                            ),
                            entry_line(&body),
                            ENTRY,
                        )
                        .mark(Mark::Dashed),
                    );
                }
            }
            Panel {
                title: format!(
                    "{}: pose every {frame_dt} s, t = 0 to {t_end:.2} s left to right",
                    d.label
                ),
                x_label: format!(
                    "time of each frame (s); frames drawn {gap} m apart plus the forward drift, to the scale of the height axis"
                ),
                y_label: "height above the take-off hip (m)".into(),
                series,
                x_range: Some(xr),
                y_range: Some(yr),
                x_ticks: ticks,
                legend: Legend::UpperRight,
                ..Default::default()
            }
        })
        .collect();
    let mut f = Figure::grid(panels, 1);
    f.panel_size = size;
    f
}

/// One final pose of a row of [`diver_pose_rows`]: the pose's coordinates and its caption.
pub struct Pose<'a> {
    /// Generalized coordinates ([`DIVER_COORDS`] values; NaN: none, the cell stays empty).
    pub q: &'a [f64],
    /// Caption written above the pose.
    pub caption: String,
}

/// Rows of final poses (one panel per row, e.g. per method), the k-th pose of every row `gap`
/// metres right of the (k−1)-th with its hip at x = k·gap, true heights above the take-off
/// hip, each with its feet-to-hands line (dashed) and caption; every panel on the same scale.
pub fn diver_pose_rows(tree: &PlanarTree, rows: &[(String, usize, Vec<Pose>)], gap: f64) -> Figure {
    let bodies: Vec<Vec<Option<[Vec<(f64, f64)>; 4]>>> = rows
        .iter()
        .map(|(_, _, poses)| {
            poses
                .iter()
                .enumerate()
                .map(|(k, p)| {
                    p.q.iter()
                        .all(|v| v.is_finite())
                        .then(|| diver_body(tree, p.q, (k as f64 * gap - p.q[0], 0.0)))
                })
                .collect()
        })
        .collect();
    let pts = bodies
        .iter()
        .flatten()
        .flatten()
        .flat_map(|b| b.iter().flatten());
    let (lo, hi) = pts.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), p| {
        (a.min(p.1), b.max(p.1))
    });
    let (lo, hi) = if lo <= hi { (lo, hi) } else { (-1.0, 1.0) };
    let n = rows.iter().map(|r| r.2.len()).max().unwrap_or(1).max(1);
    let (size, xr, yr) = fitted(
        (-0.5 * gap, (n as f64 - 0.5) * gap),
        (lo - 0.2, hi + 1.0),
        420,
    );
    let panels = rows
        .iter()
        .zip(&bodies)
        .map(|((title, color, poses), bodies)| {
            let mut series = Vec::new();
            for (k, (p, body)) in poses.iter().zip(bodies).enumerate() {
                let Some(body) = body else { continue };
                let top = body
                    .iter()
                    .flatten()
                    .map(|q| q.1)
                    .fold(f64::NEG_INFINITY, f64::max);
                let first = series.is_empty();
                series.extend(diver_series(
                    body.clone(),
                    "",
                    if first { "torso (hip to neck)" } else { "" },
                    *color,
                ));
                series.push(
                    Series::line(
                        if first {
                            "feet-to-hands line (the entry angle's)"
                        } else {
                            ""
                        },
                        entry_line(body),
                        ENTRY,
                    )
                    .mark(Mark::Dashed),
                );
                series.push(
                    Series::line("", vec![(k as f64 * gap, top + 0.15)], *color)
                        .mark(Mark::Points)
                        .labelled(vec![p.caption.clone()]),
                );
            }
            Panel {
                title: title.clone(),
                x_label: format!("x (m), poses {gap} m apart"),
                y_label: "height above the take-off hip (m)".into(),
                series,
                x_range: Some(xr),
                y_range: Some(yr),
                legend: Legend::UpperRight,
                ..Default::default()
            }
        })
        .collect();
    let mut f = Figure::grid(panels, 1);
    f.panel_size = size;
    f
}

/// GIF frames of dives side by side (`gap` metres apart plus their forward drift), the torso
/// in grey, the water line, the entry line and angle on the held last frames; `caption` and
/// the time head every frame.
pub fn diver_frames(tree: &PlanarTree, dives: &[Dive], gap: f64, caption: &str) -> Vec<Figure> {
    let t_end = dives.iter().map(Dive::t_end).fold(0.0, f64::max);
    let (lo, hi) = heights(tree, dives);
    let y_water = water(tree, dives);
    let (size, xr, yr) = fitted(
        (
            -1.2,
            (dives.len().max(1) - 1) as f64 * gap + drift(dives) + 1.2,
        ),
        // Headroom above the dives' apex for the legend.
        (lo - 0.3, hi + 2.8),
        620,
    );
    gif_times(t_end)
        .into_iter()
        .map(|tk| {
            let mut series = vec![water_series(xr.0, xr.1, y_water, t_end)];
            for (i, d) in dives.iter().enumerate() {
                let Some(q) = d.at(tk) else { continue };
                let body = diver_body(tree, q, (i as f64 * gap - d.start_x(), 0.0));
                let label = if tk >= t_end {
                    format!("{}: entry {:.3} rad from vertical", d.label, d.entry(tree))
                } else {
                    d.label.clone()
                };
                let torso = if i == 0 { "torso (hip to neck)" } else { "" };
                if tk >= t_end {
                    series.push(Series::line("", entry_line(&body), d.color).mark(Mark::Dashed));
                }
                series.extend(diver_series(body, &label, torso, d.color));
            }
            let mut f = Figure::grid(
                vec![Panel {
                    title: format!("{caption}   t = {tk:.2} s"),
                    x_label: format!("x (m), divers {gap} m apart"),
                    y_label: "height above the take-off hip (m)".into(),
                    series,
                    x_range: Some(xr),
                    y_range: Some(yr),
                    legend: Legend::UpperRight,
                    ..Default::default()
                }],
                1,
            );
            f.panel_size = size;
            f
        })
        .collect()
}

/// The biped's body at configuration `q` as five polylines: torso, left leg (hip, knee,
/// ankle), left sole (heel to toe), right leg, right sole (sole and leg apart: a polyline that
/// turns back on itself draws spikes).
pub fn biped_body(b: &crate::physics::biped::Biped, q: &[f64]) -> [Vec<(f64, f64)>; 5] {
    use crate::physics::biped::{FOOT_HEEL, FOOT_TOE};
    let t = &b.tree;
    let p = |i: usize, r: f64| {
        let v = t.point(q, i, r);
        (v[0], v[1])
    };
    let leg = |th: usize| vec![p(th, 0.0), p(th + 1, 0.0), p(th + 2, 0.0)];
    let sole = |th: usize| vec![p(th + 2, -FOOT_HEEL), p(th + 2, FOOT_TOE)];
    [
        vec![p(0, 0.0), p(0, t.links[0].length)],
        leg(1),
        sole(1),
        leg(4),
        sole(4),
    ]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::physics::diver::diver;
    use std::f64::consts::{FRAC_PI_2, PI};

    #[test]
    fn equal_aspect_gives_a_metre_the_same_pixels_on_both_axes() {
        let size = (900, 500);
        let (x, y) = equal_aspect((0.0, 10.0), (-1.0, 1.0), size);
        let px = (x.1 - x.0) / (size.0 as f64 - PANEL_CHROME.0);
        let py = (y.1 - y.0) / (size.1 as f64 - PANEL_CHROME.1);
        assert!((px - py).abs() < 1e-12 * px, "{px} vs {py}");
        // Covers the request, widened only on the short axis.
        assert_eq!(x, (0.0, 10.0));
        assert!(y.0 < -1.0 && y.1 > 1.0);
        // A fitted panel is as wide as the ranges need at its height's scale.
        let (size, x, y) = fitted((0.0, 10.0), (-1.0, 1.0), 400);
        let px = (x.1 - x.0) / (size.0 as f64 - PANEL_CHROME.0);
        let py = (y.1 - y.0) / (size.1 as f64 - PANEL_CHROME.1);
        assert!((px - py).abs() < 1e-3 * px, "{px} vs {py}");
        assert!(x.1 - x.0 < 10.1 && y == (-1.0, 1.0), "{x:?} {y:?}");
    }

    #[test]
    fn gif_times_step_in_real_time_and_hold_the_end() {
        let v = gif_times(0.1);
        assert_eq!(&v[..3], &[0.0, GIF_FRAME_DT, 2.0 * GIF_FRAME_DT]);
        assert_eq!(v[3], 0.1);
        assert_eq!(v.len(), 4 + GIF_HOLD);
        assert!(v[4..].iter().all(|&t| t == 0.1));
        assert_eq!(gif_times(0.08).len(), 3 + GIF_HOLD);
        assert_eq!(GIF_DELAY_CS as f64, 100.0 * GIF_FRAME_DT);
    }

    #[test]
    fn bodies_are_drawn_where_the_models_put_them() {
        // The handstand: both acrobot links straight up.
        let a = Acrobot::default();
        let p = acrobot_pose(&a, 3.0, FRAC_PI_2, 0.0);
        assert!((p[2].0 - 3.0).abs() < 1e-12 && (p[2].1 - a.l1 - a.l2).abs() < 1e-12);
        // The diver at take-off: torso up from the hip, legs straight down, arms overhead;
        // hands above the head, toes below the hip, the entry line pointing straight up.
        let tree = diver();
        let mut q = [0.0; DIVER_COORDS];
        q[2] = FRAC_PI_2;
        q[6] = PI;
        let [torso, head, arm, leg] = diver_body(&tree, &q, (1.0, 0.0));
        assert!((torso[1].1 - 0.52).abs() < 1e-12 && (torso[1].0 - 1.0).abs() < 1e-12);
        assert!(
            arm[2].1 > head[1].1,
            "hands {:?} head {:?}",
            arm[2],
            head[1]
        );
        assert!(leg[3].1 < -1.0);
        assert!((entry_angle(&tree, &q).abs() - PI).abs() < 1e-9);
        let line = entry_line(&diver_body(&tree, &q, (0.0, 0.0)));
        assert!(line[1].1 > line[0].1);
    }
}
