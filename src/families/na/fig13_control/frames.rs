//! # One frame of each animated model (NeuroAnimator Fig. 13)
//!
//! A frame drawer per model ([`draw_pendulum`], [`draw_truck`], [`draw_lander`],
//! [`draw_dolphin_side`]) draws the goal and the [`Body`]s of one frame onto a plotters drawing
//! area, on fixed [`Axes`] (one metre has the same length on both axes); the scenes, the
//! resampling and the GIF writer that use them are in [`super::anim`].
//!
//! Body sizes are the models' own where they have them (pendulum link lengths, truck axle
//! positions, lander leg length and the box with the lander's mass and principal inertia);
//! the truck's overhangs and width are drawing choices ([`TRUCK_OVERHANG`], [`TRUCK_WIDTH`]).

// Animation frames: a last-bit difference moves no table.
#![allow(clippy::disallowed_methods)]

use crate::experiment::plot::tick;
use crate::physics::dolphin::{Dolphin, N_MASSES, N_POS};
use crate::physics::lander::Lander;
use crate::physics::pendulum::Pendulum3;
use crate::physics::truck::Truck;
use nalgebra::Vector3;
use plotters::coord::types::RangedCoordf64;
use plotters::coord::Shift;
use plotters::element::{Drawable, PointCollection};
use plotters::prelude::*;
use std::iter::once;

/// Colour of the goal (drawn translucent).
pub const GOAL: RGBColor = RGBColor(30, 170, 60);
/// Opacity of the goal pose.
const GOAL_ALPHA: f64 = 0.35;

/// The truck model has axles but no body: the body reaches this far beyond each axle (m).
pub const TRUCK_OVERHANG: f64 = 1.0;
/// Drawn width of the truck body (m).
pub const TRUCK_WIDTH: f64 = 2.0;

const MARGIN: u32 = 8;
const X_LABEL_AREA: u32 = 40;
const Y_LABEL_AREA: u32 = 52;

/// A body drawn in one frame: its states up to now; the last is drawn, all make its trail.
#[derive(Debug, Clone, Copy)]
pub struct Body<'a> {
    /// Legend label.
    pub label: &'a str,
    /// Colour.
    pub color: RGBColor,
    /// States so far (the last is the current one).
    pub history: &'a [Vec<f64>],
}

impl Body<'_> {
    fn current(&self) -> Option<&[f64]> {
        self.history.last().map(Vec::as_slice)
    }
}

/// Fixed axes of one view (m), equally scaled in the drawing area they were fitted to.
#[derive(Debug, Clone, PartialEq)]
pub struct Axes {
    /// Horizontal range.
    pub x: (f64, f64),
    /// Vertical range.
    pub y: (f64, f64),
    /// Horizontal axis label.
    pub x_label: String,
    /// Vertical axis label.
    pub y_label: String,
}

impl Axes {
    /// Axes covering `points` with `pad` metres to spare on every side, widened so that one
    /// metre has the same length on both axes of this module's chart in a `size` pixel area.
    pub fn fit(
        points: impl IntoIterator<Item = (f64, f64)>,
        pad: f64,
        size: (u32, u32),
        x_label: &str,
        y_label: &str,
    ) -> Self {
        let (mut lo, mut hi) = (
            (f64::INFINITY, f64::INFINITY),
            (f64::NEG_INFINITY, f64::NEG_INFINITY),
        );
        for (x, y) in points {
            if x.is_finite() && y.is_finite() {
                lo = (lo.0.min(x), lo.1.min(y));
                hi = (hi.0.max(x), hi.1.max(y));
            }
        }
        if !lo.0.is_finite() {
            (lo, hi) = ((-1.0, -1.0), (1.0, 1.0));
        }
        let w = size.0.saturating_sub(2 * MARGIN + Y_LABEL_AREA).max(1) as f64;
        let h = size.1.saturating_sub(2 * MARGIN + X_LABEL_AREA).max(1) as f64;
        let span = |a: f64, b: f64| (b - a + 2.0 * pad).max(1e-3);
        let per_m = (w / span(lo.0, hi.0)).min(h / span(lo.1, hi.1));
        let (cx, cy) = (0.5 * (lo.0 + hi.0), 0.5 * (lo.1 + hi.1));
        let (hx, hy) = (0.5 * w / per_m, 0.5 * h / per_m);
        Self {
            x: (cx - hx, cx + hx),
            y: (cy - hy, cy + hy),
            x_label: x_label.into(),
            y_label: y_label.into(),
        }
    }
}

type Chart<'a, DB> = ChartContext<'a, DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>;

fn es(e: impl std::fmt::Display) -> String {
    e.to_string()
}

/// A chart on `area` with the axes, mesh and labels styled like the other figures.
fn chart<'a, DB: DrawingBackend>(
    area: &'a DrawingArea<DB, Shift>,
    axes: &Axes,
) -> Result<Chart<'a, DB>, String> {
    let mut c = ChartBuilder::on(area)
        .margin(MARGIN)
        .x_label_area_size(X_LABEL_AREA)
        .y_label_area_size(Y_LABEL_AREA)
        .build_cartesian_2d(axes.x.0..axes.x.1, axes.y.0..axes.y.1)
        .map_err(es)?;
    let (sx, sy) = (axes.x.1 - axes.x.0, axes.y.1 - axes.y.0);
    c.configure_mesh()
        .x_desc(axes.x_label.as_str())
        .y_desc(axes.y_label.as_str())
        .x_label_formatter(&|v| tick(*v, sx))
        .y_label_formatter(&|v| tick(*v, sy))
        .x_labels(8)
        .y_labels(8)
        .label_style(("sans-serif", 13))
        .axis_desc_style(("sans-serif", 15))
        .light_line_style(TRANSPARENT)
        .bold_line_style(RGBColor(225, 225, 225))
        .draw()
        .map_err(es)?;
    Ok(c)
}

fn legend<'a, DB: DrawingBackend + 'a>(
    c: &mut Chart<'a, DB>,
    at: SeriesLabelPosition,
) -> Result<(), String> {
    c.configure_series_labels()
        .background_style(WHITE.mix(0.85))
        .border_style(RGBColor(180, 180, 180))
        .label_font(("sans-serif", 13))
        .position(at)
        .draw()
        .map_err(es)
}

/// Draws `elements` with a legend entry `label` in `color` (no entry if `label` is empty).
fn labelled<'a, DB, E, I>(
    c: &mut Chart<'a, DB>,
    elements: I,
    label: &str,
    color: RGBAColor,
) -> Result<(), String>
where
    DB: DrawingBackend + 'a,
    I: IntoIterator<Item = E>,
    for<'b> &'b E: PointCollection<'b, (f64, f64)>,
    E: Drawable<DB>,
{
    let anno = c.draw_series(elements).map_err(es)?;
    if !label.is_empty() {
        anno.label(label).legend(move |(x, y)| {
            PathElement::new(vec![(x, y), (x + 18, y)], color.stroke_width(4))
        });
    }
    Ok(())
}

fn path(points: Vec<(f64, f64)>, color: RGBAColor, width: u32) -> PathElement<(f64, f64)> {
    PathElement::new(points, color.stroke_width(width))
}

/// Draws a closed outline `points`, filled with `color` at opacity `fill`.
fn shape<'a, DB: DrawingBackend + 'a>(
    c: &mut Chart<'a, DB>,
    points: Vec<(f64, f64)>,
    color: RGBColor,
    fill: f64,
    label: &str,
) -> Result<(), String> {
    let mut outline = points.clone();
    outline.extend(points.first().copied());
    c.draw_series(once(Polygon::new(points, color.mix(fill).filled())))
        .map_err(es)?;
    labelled(
        c,
        once(path(outline, color.to_rgba(), 2)),
        label,
        color.to_rgba(),
    )
}

// ---------------------------------------------------------------------------------------------
// Pendulum

const LINK_WIDTH: u32 = 7;

/// The pendulum's joint positions (x, y), pivot first.
pub(super) fn joints(p: &Pendulum3, s: &[f64]) -> Vec<(f64, f64)> {
    p.joint_positions(s).iter().map(|q| (q[0], q[1])).collect()
}

/// Draws one frame of the three-link pendulum, side view (x right, y up, pivot at the
/// origin): the goal pose translucent, each body's links as thick lines with joint dots and
/// its tip's path so far.
pub fn draw_pendulum<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    axes: &Axes,
    pendulum: &Pendulum3,
    goal: &[f64],
    bodies: &[Body],
) -> Result<(), String> {
    let mut c = chart(area, axes)?;
    let mount = pendulum.links[0].length * 0.3;
    c.draw_series(once(path(
        vec![(-mount, 0.0), (mount, 0.0)],
        BLACK.to_rgba(),
        3,
    )))
    .map_err(es)?;
    let g = GOAL.mix(GOAL_ALPHA);
    let gj = joints(pendulum, goal);
    labelled(&mut c, once(path(gj.clone(), g, LINK_WIDTH + 4)), "goal", g)?;
    c.draw_series(gj.iter().map(|&q| Circle::new(q, 6, g.filled())))
        .map_err(es)?;
    for b in bodies {
        let Some(s) = b.current() else { continue };
        let tip: Vec<(f64, f64)> = b
            .history
            .iter()
            .map(|s| {
                let q = pendulum.joint_positions(s)[3];
                (q[0], q[1])
            })
            .collect();
        c.draw_series(once(path(tip, b.color.mix(0.6), 1)))
            .map_err(es)?;
        let j = joints(pendulum, s);
        labelled(
            &mut c,
            once(path(j.clone(), b.color.to_rgba(), LINK_WIDTH)),
            b.label,
            b.color.to_rgba(),
        )?;
        c.draw_series(j.iter().map(|&q| Circle::new(q, 4, BLACK.filled())))
            .map_err(es)?;
    }
    legend(&mut c, SeriesLabelPosition::UpperRight)
}

// ---------------------------------------------------------------------------------------------
// Truck

/// A rectangle in the truck's body frame (forward `f0..f1`, left `l0..l1`, m) in the world.
fn truck_rect(s: &[f64], f: (f64, f64), l: (f64, f64)) -> Vec<(f64, f64)> {
    let (sn, cs) = s[2].sin_cos();
    [(f.0, l.0), (f.1, l.0), (f.1, l.1), (f.0, l.1)]
        .iter()
        .map(|&(a, b)| (s[0] + cs * a - sn * b, s[1] + sn * a + cs * b))
        .collect()
}

fn truck_pose<'a, DB: DrawingBackend + 'a>(
    c: &mut Chart<'a, DB>,
    truck: &Truck,
    s: &[f64],
    color: RGBColor,
    fill: f64,
    label: &str,
) -> Result<(), String> {
    let (front, rear, half) = (
        truck.front_axle + TRUCK_OVERHANG,
        -(truck.rear_axle + TRUCK_OVERHANG),
        0.5 * TRUCK_WIDTH,
    );
    // Wheels (0.9 m by 0.3 m) at the axles, under the body.
    for x in [truck.front_axle, -truck.rear_axle] {
        for y in [half - 0.15, -half + 0.15] {
            let w = truck_rect(s, (x - 0.45, x + 0.45), (y - 0.15, y + 0.15));
            c.draw_series(once(Polygon::new(w, BLACK.mix(fill.max(0.3)).filled())))
                .map_err(es)?;
        }
    }
    shape(
        c,
        truck_rect(s, (rear, front), (-half, half)),
        color,
        fill,
        label,
    )?;
    // The cab marks the front.
    let cab = truck_rect(s, (truck.front_axle - 0.4, front), (-half, half));
    c.draw_series(once(Polygon::new(
        cab,
        color.mix(fill.max(0.3) + 0.3).filled(),
    )))
    .map_err(es)?;
    Ok(())
}

/// Draws one frame of the truck, top view (x, y): the parking pose translucent, each body as
/// an oriented rectangle (cab at the front, wheels at the axles) and its path so far.
pub fn draw_truck<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    axes: &Axes,
    truck: &Truck,
    goal: &[f64],
    bodies: &[Body],
) -> Result<(), String> {
    let mut c = chart(area, axes)?;
    truck_pose(&mut c, truck, goal, GOAL, GOAL_ALPHA, "goal")?;
    for b in bodies {
        let Some(s) = b.current() else { continue };
        let trail: Vec<(f64, f64)> = b.history.iter().map(|s| (s[0], s[1])).collect();
        c.draw_series(once(path(trail, b.color.mix(0.8), 2)))
            .map_err(es)?;
        truck_pose(&mut c, truck, s, b.color, 0.5, b.label)?;
    }
    legend(&mut c, SeriesLabelPosition::UpperLeft)
}

// ---------------------------------------------------------------------------------------------
// Lander

/// Half-extents (m) of the uniform box with the lander's mass and principal inertia:
/// I_x = m (h_y² + h_z²) / 3 and so on.
pub fn lander_box(l: &Lander) -> [f64; 3] {
    let k = 3.0 / l.mass;
    let [ix, iy, iz] = l.inertia.map(|i| i * k);
    let sum = 0.5 * (ix + iy + iz);
    [sum - ix, sum - iy, sum - iz].map(|v| v.max(1e-6).sqrt())
}

/// Body-frame outline of the drawn lander: the hull (the inertia box's x, y extents, from
/// half the leg length below the centre of mass to as far above) and four legs from its bottom
/// corners to feet at the landing-gear height.
fn lander_parts(l: &Lander) -> ([Vector3<f64>; 8], [[Vector3<f64>; 2]; 4]) {
    let [hx, hy, _] = lander_box(l);
    let hz = 0.5 * l.leg_length;
    let mut hull = [Vector3::zeros(); 8];
    let mut legs = [[Vector3::zeros(); 2]; 4];
    let mut k = 0;
    for sx in [-1.0, 1.0] {
        for sy in [-1.0, 1.0] {
            hull[k] = Vector3::new(sx * hx, sy * hy, -hz);
            hull[k + 4] = Vector3::new(sx * hx, sy * hy, hz);
            legs[k] = [
                hull[k],
                Vector3::new(1.3 * sx * hx, 1.3 * sy * hy, -l.leg_length),
            ];
            k += 1;
        }
    }
    (hull, legs)
}

/// Convex hull (counter-clockwise) of planar points, Andrew's monotone chain.
fn convex_hull(mut p: Vec<(f64, f64)>) -> Vec<(f64, f64)> {
    p.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.total_cmp(&b.1)));
    if p.len() < 3 {
        return p;
    }
    let cross = |o: (f64, f64), a: (f64, f64), b: (f64, f64)| {
        (a.0 - o.0) * (b.1 - o.1) - (a.1 - o.1) * (b.0 - o.0)
    };
    let mut h: Vec<(f64, f64)> = Vec::with_capacity(2 * p.len());
    for pass in 0..2 {
        let start = h.len();
        for &q in p.iter() {
            while h.len() >= start + 2 && cross(h[h.len() - 2], h[h.len() - 1], q) <= 0.0 {
                h.pop();
            }
            h.push(q);
        }
        h.pop();
        if pass == 0 {
            p.reverse();
        }
    }
    h
}

/// Which plane a lander view shows.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Plane {
    /// x right, z up.
    Side,
    /// x right, y up.
    Top,
}

impl Plane {
    fn project(self, p: Vector3<f64>) -> (f64, f64) {
        match self {
            Self::Side => (p.x, p.z),
            Self::Top => (p.x, p.y),
        }
    }
}

fn lander_pose<'a, DB: DrawingBackend + 'a>(
    c: &mut Chart<'a, DB>,
    l: &Lander,
    plane: Plane,
    s: &[f64],
    color: RGBColor,
    fill: f64,
    label: &str,
) -> Result<(), String> {
    let (hull, legs) = lander_parts(l);
    let q = Lander::attitude(s);
    let at = Vector3::new(s[0], s[1], s[2]);
    let world = |b: &Vector3<f64>| plane.project(at + q * b);
    for leg in &legs {
        c.draw_series(once(path(
            leg.iter().map(world).collect(),
            color.mix(fill.max(0.3) + 0.3),
            2,
        )))
        .map_err(es)?;
    }
    shape(
        c,
        convex_hull(hull.iter().map(world).collect()),
        color,
        fill,
        label,
    )
}

/// A disc of radius `r` about `c` as a polygon.
fn disc(c: (f64, f64), r: f64) -> Vec<(f64, f64)> {
    (0..32)
        .map(|k| {
            let a = k as f64 * std::f64::consts::TAU / 32.0;
            (c.0 + r * a.cos(), c.1 + r * a.sin())
        })
        .collect()
}

fn lander_view<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    axes: &Axes,
    plane: Plane,
    lander: &Lander,
    goal: &[f64],
    bodies: &[Body],
) -> Result<(), String> {
    let mut c = chart(area, axes)?;
    let pad = 1.3 * lander_box(lander)[0] + 0.5;
    let ground = RGBColor(150, 110, 70);
    match plane {
        Plane::Side => {
            let z = lander.ground_height;
            c.draw_series(once(Rectangle::new(
                [(axes.x.0, axes.y.0.min(z)), (axes.x.1, z)],
                ground.mix(0.15).filled(),
            )))
            .map_err(es)?;
            c.draw_series(once(path(
                vec![(axes.x.0, z), (axes.x.1, z)],
                ground.to_rgba(),
                2,
            )))
            .map_err(es)?;
            labelled(
                &mut c,
                once(path(
                    vec![(goal[0] - pad, z), (goal[0] + pad, z)],
                    GOAL.to_rgba(),
                    5,
                )),
                "target pad",
                GOAL.to_rgba(),
            )?;
        }
        Plane::Top => {
            labelled(
                &mut c,
                once(Polygon::new(
                    disc((goal[0], goal[1]), pad),
                    GOAL.mix(0.2).filled(),
                )),
                "target pad",
                GOAL.mix(0.2),
            )?;
        }
    }
    lander_pose(&mut c, lander, plane, goal, GOAL, GOAL_ALPHA, "goal")?;
    for b in bodies {
        let Some(s) = b.current() else { continue };
        let trail: Vec<(f64, f64)> = b
            .history
            .iter()
            .map(|s| plane.project(Vector3::new(s[0], s[1], s[2])))
            .collect();
        c.draw_series(once(path(trail, b.color.mix(0.8), 2)))
            .map_err(es)?;
        lander_pose(&mut c, lander, plane, s, b.color, 0.5, b.label)?;
    }
    // The key goes in the corner farthest from where the tracks start and from the goal: the
    // lander starts high and to one side, where a fixed corner hid it for seconds.
    let marks: Vec<(f64, f64)> = bodies
        .iter()
        .filter_map(|b| b.history.first())
        .map(|s| plane.project(Vector3::new(s[0], s[1], s[2])))
        .chain(once(plane.project(Vector3::new(goal[0], goal[1], goal[2]))))
        .collect();
    legend(&mut c, free_corner(axes, &marks))
}

/// Of the four corners of `axes`, the one farthest from the nearest of `marks`, in units of
/// each axis's span; a lower corner must be a tenth clearer than an upper one to be taken
/// (the ground and the pad lie low).
fn free_corner(axes: &Axes, marks: &[(f64, f64)]) -> SeriesLabelPosition {
    let unit = |(x, y): (f64, f64)| {
        (
            (x - axes.x.0) / (axes.x.1 - axes.x.0),
            (y - axes.y.0) / (axes.y.1 - axes.y.0),
        )
    };
    let corners = [
        (SeriesLabelPosition::UpperRight, (1.0, 1.0)),
        (SeriesLabelPosition::UpperLeft, (0.0, 1.0)),
        (SeriesLabelPosition::LowerRight, (1.0, 0.0)),
        (SeriesLabelPosition::LowerLeft, (0.0, 0.0)),
    ];
    let clearance = |c: (f64, f64)| {
        marks
            .iter()
            .map(|&m| {
                let (dx, dy) = (unit(m).0 - c.0, unit(m).1 - c.1);
                (dx * dx + dy * dy).sqrt()
            })
            .fold(f64::INFINITY, f64::min)
    };
    let mut best = (SeriesLabelPosition::UpperRight, f64::NEG_INFINITY);
    for (at, c) in corners {
        let d = clearance(c) * if c.1 > 0.5 { 1.0 } else { 0.9 };
        if d > best.1 + 1e-9 {
            best = (at, d);
        }
    }
    best.0
}

/// Draws one frame of the lander: a side view (x, z) with the ground and the target pad on
/// the left half of `area`, a top view (x, y) on the right half; the goal pose translucent,
/// each body rotated by its quaternion and projected, and its centre-of-mass path so far.
pub fn draw_lander<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    side: &Axes,
    top: &Axes,
    lander: &Lander,
    goal: &[f64],
    bodies: &[Body],
) -> Result<(), String> {
    let halves = area.split_evenly((1, 2));
    lander_view(&halves[0], side, Plane::Side, lander, goal, bodies)?;
    lander_view(&halves[1], top, Plane::Top, lander, goal, bodies)
}

// ---------------------------------------------------------------------------------------------
// Dolphin

fn dolphin_pose<'a, DB: DrawingBackend + 'a>(
    c: &mut Chart<'a, DB>,
    dolphin: &Dolphin,
    s: &[f64],
    color: RGBAColor,
    label: &str,
) -> Result<(), String> {
    let xz = |i: usize| (s[3 * i], s[3 * i + 2]);
    labelled(
        c,
        dolphin
            .springs()
            .iter()
            .filter(|sp| sp.a < N_MASSES && sp.b < N_MASSES)
            .map(|sp| path(vec![xz(sp.a), xz(sp.b)], color, 1)),
        label,
        color,
    )?;
    c.draw_series((0..N_MASSES).map(|i| Circle::new(xz(i), 2, color.filled())))
        .map_err(es)?;
    // The head: the nose (mass 0) as a large ringed dot.
    c.draw_series([
        Circle::new(xz(0), 6, color.filled()),
        Circle::new(xz(0), 6, BLACK.stroke_width(1)),
    ])
    .map_err(es)?;
    Ok(())
}

/// Draws one frame of the dolphin, side view (x, z): every spring of [`Dolphin::springs`]
/// as a line between its masses' positions (the first 69 state values, x y z per mass), the
/// masses as dots, the goal state translucent (skipped unless it holds 69 positions) and each
/// body's centre-of-mass path so far.
pub fn draw_dolphin_side<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    axes: &Axes,
    dolphin: &Dolphin,
    goal: &[f64],
    bodies: &[Body],
) -> Result<(), String> {
    let mut c = chart(area, axes)?;
    if goal.len() >= N_POS {
        dolphin_pose(&mut c, dolphin, goal, GOAL.mix(GOAL_ALPHA), "goal")?;
    }
    for b in bodies {
        let Some(s) = b.current().filter(|s| s.len() >= N_POS) else {
            continue;
        };
        let trail: Vec<(f64, f64)> = b
            .history
            .iter()
            .filter(|s| s.len() >= N_POS)
            .map(|s| {
                let p = dolphin.centre_of_mass(s);
                (p.x, p.z)
            })
            .collect();
        c.draw_series(once(path(trail, b.color.mix(0.8), 1)))
            .map_err(es)?;
        dolphin_pose(&mut c, dolphin, s, b.color.to_rgba(), b.label)?;
    }
    // Forward (from the centre of mass towards the nose of the first body) as an arrow with a
    // key for the head marker, in the upper left corner.
    if let Some(s) = bodies
        .iter()
        .find_map(|b| b.current().filter(|s| s.len() >= N_POS))
    {
        let com = dolphin.centre_of_mass(s);
        let sign = if s[0] >= com.x { 1.0 } else { -1.0 };
        let (w, h) = (axes.x.1 - axes.x.0, axes.y.1 - axes.y.0);
        let (x0, y0) = (axes.x.0 + 0.04 * w, axes.y.1 - 0.08 * h);
        let len = 0.12 * w;
        let (a, b) = if sign > 0.0 {
            (x0, x0 + len)
        } else {
            (x0 + len, x0)
        };
        let tip = 0.02 * w;
        c.draw_series([
            path(vec![(a, y0), (b, y0)], BLACK.to_rgba(), 2),
            path(
                vec![
                    (b - sign * tip, y0 + 0.4 * tip),
                    (b, y0),
                    (b - sign * tip, y0 - 0.4 * tip),
                ],
                BLACK.to_rgba(),
                2,
            ),
        ])
        .map_err(es)?;
        c.draw_series(once(Text::new(
            "forward (head = large dot)",
            (x0 + len + 0.02 * w, y0 + 0.03 * h),
            ("sans-serif", 13).into_font().color(&BLACK),
        )))
        .map_err(es)?;
    }
    legend(&mut c, SeriesLabelPosition::UpperRight)
}

#[cfg(test)]
pub(super) mod tests {
    use super::super::anim::EMULATOR;
    use super::*;
    use crate::experiment::plot::ensure_fonts;

    pub(in super::super) const SIZE: (u32, u32) = (320, 240);

    #[test]
    fn the_key_takes_the_corner_farthest_from_the_start_and_the_goal() {
        let axes = Axes {
            x: (-25.0, 37.0),
            y: (-5.0, 65.0),
            x_label: String::new(),
            y_label: String::new(),
        };
        // The lander's side view: it starts high on the right, its goal is on the ground.
        let at = free_corner(&axes, &[(12.0, 60.0), (0.0, 0.0)]);
        assert!(matches!(at, SeriesLabelPosition::UpperLeft), "{at:?}");
        // Nothing to avoid: the upper right, as before.
        let at = free_corner(&axes, &[]);
        assert!(matches!(at, SeriesLabelPosition::UpperRight), "{at:?}");
        // A start in the upper left and a goal in the lower right leave the other two
        // corners equally free: the upper one.
        let at = free_corner(&axes, &[(-25.0, 65.0), (37.0, -5.0)]);
        assert!(matches!(at, SeriesLabelPosition::UpperRight), "{at:?}");
    }

    /// Renders `draw` into an in-memory bitmap; returns how many pixels are not white.
    pub(in super::super) fn render(
        draw: impl Fn(&DrawingArea<BitMapBackend, Shift>) -> Result<(), String>,
    ) -> usize {
        ensure_fonts();
        let mut buf = vec![0u8; (SIZE.0 * SIZE.1 * 3) as usize];
        {
            let root = BitMapBackend::with_buffer(&mut buf, SIZE).into_drawing_area();
            root.fill(&WHITE).unwrap();
            draw(&root).unwrap();
            root.present().unwrap();
        }
        buf.chunks(3).filter(|p| p != &[255, 255, 255]).count()
    }

    #[test]
    fn dolphin_side_frame_renders() {
        let d = Dolphin::default();
        let rest = d.rest_state();
        let mut moved = rest.clone();
        for i in 0..N_MASSES {
            moved[3 * i] += 0.5;
        }
        let axes = Axes::fit(
            rest.chunks(3).take(N_MASSES).map(|p| (p[0], p[2])),
            0.6,
            SIZE,
            "x (m)",
            "z (m)",
        );
        let history = vec![rest.clone(), moved];
        let bodies = [Body {
            label: "dolphin",
            color: EMULATOR,
            history: &history,
        }];
        assert!(render(|a| draw_dolphin_side(a, &axes, &d, &rest, &bodies)) > 500);
    }

    #[test]
    fn axes_are_equally_scaled_and_cover_the_points() {
        let a = Axes::fit([(0.0, 0.0), (10.0, 1.0)], 0.5, (400, 300), "x", "y");
        assert!(a.x.0 <= -0.5 && a.x.1 >= 10.5 && a.y.0 <= -0.5 && a.y.1 >= 1.5);
        let w = (400 - 2 * MARGIN - Y_LABEL_AREA) as f64;
        let h = (300 - 2 * MARGIN - X_LABEL_AREA) as f64;
        assert!(((a.x.1 - a.x.0) / w - (a.y.1 - a.y.0) / h).abs() < 1e-9);
    }

    #[test]
    fn convex_hull_of_a_square_with_an_inner_point() {
        let h = convex_hull(vec![
            (0.0, 0.0),
            (1.0, 0.0),
            (0.5, 0.5),
            (1.0, 1.0),
            (0.0, 1.0),
        ]);
        assert_eq!(h.len(), 4);
        assert!(!h.contains(&(0.5, 0.5)));
    }
}
