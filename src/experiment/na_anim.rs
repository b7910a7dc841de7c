//! # Animations of the control tasks (NeuroAnimator Fig. 13)
//!
//! Animated GIFs of learned motions: the motion driven by the emulator and its replay on the
//! physical simulator, played together over the goal, on fixed axes fitted once to the whole
//! trajectory and the goal (one metre has the same length on both axes).
//!
//! The emulator makes one super-step of Δt = n δt per state; as in NeuroAnimator §3 the motion
//! is resampled at the frame rate by linear interpolation between super-steps, with up to
//! [`FRAMES_PER_STEP`] frames per super-step and frames at least [`MIN_FRAME_DELAY`] apart
//! (played in real time when the GIF's centisecond delays allow it; otherwise the caption says
//! the speed). Interpolated quaternions are renormalised.
//!
//! Each model has a frame drawer ([`draw_pendulum`], [`draw_truck`], [`draw_lander`],
//! [`draw_dolphin_side`]) that draws one frame onto a plotters drawing area, and a [`Scene`]
//! variant that says how its states interpolate, which views it has and how to fit them;
//! [`write_animation`] writes the GIF atomically.
//!
//! Body sizes are the models' own where they have them (pendulum link lengths, truck axle
//! positions, lander leg length and the box with the lander's mass and principal inertia);
//! the truck's overhangs and width are drawing choices ([`TRUCK_OVERHANG`], [`TRUCK_WIDTH`]).

use super::ms_draw::perr;
use super::output::temp_path;
use super::plot::{ensure_fonts, tick};
use super::Error;
use crate::emulator::catalog::NetModel;
use crate::physics::dolphin::{Dolphin, N_MASSES, N_POS};
use crate::physics::lander::{Lander, QUAT};
use crate::physics::pendulum::{Pendulum3, PendulumVariant};
use crate::physics::truck::Truck;
use nalgebra::Vector3;
use plotters::coord::types::RangedCoordf64;
use plotters::coord::Shift;
use plotters::element::{Drawable, PointCollection};
use plotters::prelude::*;
use std::iter::once;
use std::path::{Path, PathBuf};

/// Colour of the emulator-driven motion.
pub const EMULATOR: RGBColor = RGBColor(128, 40, 170);
/// Colour of the simulator replay.
pub const SIMULATOR: RGBColor = RGBColor(120, 120, 120);
/// Colour of the goal (drawn translucent).
pub const GOAL: RGBColor = RGBColor(30, 170, 60);
/// Opacity of the goal pose.
const GOAL_ALPHA: f64 = 0.35;

/// Most frames drawn per emulator super-step.
pub const FRAMES_PER_STEP: usize = 10;
/// Most frames in one animation (before the held last frame): bounds the GIF's size (each
/// frame is quantised and compressed on its own, some 10-20 kB) and the time to write it.
pub const MAX_FRAMES: usize = 200;
/// Shortest delay between frames (s): at most 25 frames per second.
pub const MIN_FRAME_DELAY: f64 = 0.04;
/// How long the last frame is held before the animation loops (s), in at most 10 frames.
const HOLD: f64 = 0.5;

/// The truck model has axles but no body: the body reaches this far beyond each axle (m).
pub const TRUCK_OVERHANG: f64 = 1.0;
/// Drawn width of the truck body (m).
pub const TRUCK_WIDTH: f64 = 2.0;

const MARGIN: u32 = 8;
const X_LABEL_AREA: u32 = 40;
const Y_LABEL_AREA: u32 = 52;
const TITLE_HEIGHT: u32 = 42;

/// One motion of an animation: a state per emulator super-step.
#[derive(Debug, Clone)]
pub struct Track {
    /// Legend label.
    pub label: String,
    /// Colour.
    pub color: RGBColor,
    /// States, one per super-step.
    pub states: Vec<Vec<f64>>,
}

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

fn joints(p: &Pendulum3, s: &[f64]) -> Vec<(f64, f64)> {
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
    legend(&mut c, SeriesLabelPosition::UpperRight)
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
    legend(&mut c, SeriesLabelPosition::UpperRight)
}

// ---------------------------------------------------------------------------------------------
// Scenes and GIFs

/// A model that can be animated, with the parameters its drawing needs.
///
/// To animate another model (e.g. the dolphin, whose frames [`draw_dolphin_side`] draws), add
/// a variant and its arms in [`Scene::for_model`], [`Scene::size`], [`Scene::views`] and
/// [`Scene::draw`]; [`Scene::interpolate`] is linear unless the state needs more.
#[derive(Debug, Clone)]
#[non_exhaustive]
pub enum Scene {
    /// The three-link pendulum, side view.
    Pendulum(Pendulum3),
    /// The truck, top view.
    Truck(Truck),
    /// The lander, side and top views.
    Lander(Lander),
    /// The dolphin (mass state: 69 positions, 69 velocities), side view.
    Dolphin(Box<Dolphin>),
}

impl Scene {
    /// The scene of an emulated model, with the model's default parameters.
    pub fn for_model(model: NetModel) -> Self {
        match model {
            NetModel::PendulumPassive => Self::Pendulum(Pendulum3::new(PendulumVariant::Passive)),
            NetModel::PendulumActive => Self::Pendulum(Pendulum3::new(PendulumVariant::Active)),
            NetModel::PendulumExt => Self::Pendulum(Pendulum3::new(PendulumVariant::ExtForce)),
            NetModel::Truck => Self::Truck(Truck::default()),
            NetModel::Lander => Self::Lander(Lander::default()),
        }
    }

    /// GIF size in pixels.
    pub fn size(&self) -> (u32, u32) {
        match self {
            Self::Pendulum(_) => (480, 440),
            Self::Truck(_) => (560, 440),
            Self::Lander(_) => (760, 440),
            Self::Dolphin(_) => (760, 360),
        }
    }

    /// The state a fraction `f` of the way from `a` to `b`: linear, with the lander's
    /// quaternion renormalised (and taken on `a`'s side of the double cover).
    pub fn interpolate(&self, a: &[f64], b: &[f64], f: f64) -> Vec<f64> {
        let mut s: Vec<f64> = a.iter().zip(b).map(|(a, b)| a + f * (b - a)).collect();
        if let Self::Lander(l) = self {
            if s.len() >= QUAT + 4 {
                let dot: f64 = (QUAT..QUAT + 4).map(|k| a[k] * b[k]).sum();
                if dot < 0.0 {
                    for k in QUAT..QUAT + 4 {
                        s[k] = a[k] + f * (-b[k] - a[k]);
                    }
                }
                l.normalize_state(&mut s);
            }
        }
        s
    }

    /// The fixed axes of each view for a drawing area of `size` pixels, fitted to the goal
    /// and every state of every track.
    pub fn views(&self, size: (u32, u32), goal: &[f64], tracks: &[Track]) -> Vec<Axes> {
        let states = || {
            once(goal).chain(
                tracks
                    .iter()
                    .flat_map(|t| t.states.iter().map(Vec::as_slice)),
            )
        };
        match self {
            Self::Pendulum(p) => {
                let pts = states().flat_map(|s| joints(p, s));
                vec![Axes::fit(pts, 0.15, size, "x (m)", "y (m)")]
            }
            Self::Truck(t) => {
                let reach =
                    (t.front_axle.max(t.rear_axle) + TRUCK_OVERHANG).hypot(0.5 * TRUCK_WIDTH);
                let pts = states().map(|s| (s[0], s[1]));
                vec![Axes::fit(pts, reach + 0.5, size, "x (m)", "y (m)")]
            }
            Self::Lander(l) => {
                let [hx, hy, _] = lander_box(l);
                let reach = (1.3 * hx).hypot(1.3 * hy).hypot(l.leg_length) + 0.5;
                let half = (size.0 / 2, size.1);
                let side = states()
                    .map(|s| (s[0], s[2]))
                    .chain(once((goal[0], l.ground_height - 1.0)));
                let top = states().map(|s| (s[0], s[1]));
                let mut side = Axes::fit(side, reach, half, "x (m)", "z (m)");
                // Spare room goes above, not under the ground.
                let lift = (l.ground_height - 1.0 - reach - side.y.0).max(0.0);
                side.y = (side.y.0 + lift, side.y.1 + lift);
                vec![side, Axes::fit(top, reach, half, "x (m)", "y (m)")]
            }
            Self::Dolphin(_) => {
                let pts = states()
                    .filter(|s| s.len() >= N_POS)
                    .flat_map(|s| (0..N_POS / 3).map(move |i| (s[3 * i], s[3 * i + 2])));
                vec![Axes::fit(pts, 0.3, size, "x (m)", "z (m)")]
            }
        }
    }

    /// Draws one frame: the goal and `bodies` on `views` (from [`Scene::views`]).
    pub fn draw<DB: DrawingBackend>(
        &self,
        area: &DrawingArea<DB, Shift>,
        views: &[Axes],
        goal: &[f64],
        bodies: &[Body],
    ) -> Result<(), String> {
        let view = |i: usize| views.get(i).ok_or_else(|| format!("no view {i}"));
        match self {
            Self::Pendulum(p) => draw_pendulum(area, view(0)?, p, goal, bodies),
            Self::Truck(t) => draw_truck(area, view(0)?, t, goal, bodies),
            Self::Lander(l) => draw_lander(area, view(0)?, view(1)?, l, goal, bodies),
            Self::Dolphin(d) => draw_dolphin_side(area, view(0)?, d, goal, bodies),
        }
    }
}

/// Frames per super-step of `step` seconds over `steps` super-steps, and the frame delay in
/// centiseconds: as many frames as fit (at most [`FRAMES_PER_STEP`] per step and
/// [`MAX_FRAMES`] in all, at least [`MIN_FRAME_DELAY`] apart), preferring a count whose delay
/// is a whole number of centiseconds (GIF's unit) so that the motion plays in real time.
pub fn frame_timing(step: f64, steps: usize) -> (usize, u32) {
    let cs = 100.0 * step;
    let most = ((step / MIN_FRAME_DELAY + 1e-9).floor() as usize)
        .min(FRAMES_PER_STEP)
        .min(MAX_FRAMES / steps.max(1))
        .max(1);
    let per = (1..=most)
        .rev()
        .find(|&p| {
            let d = cs / p as f64;
            (d - d.round()).abs() < 1e-6
        })
        .unwrap_or(most);
    let delay = ((cs / per as f64).round() as u32).max((100.0 * MIN_FRAME_DELAY) as u32);
    (per, delay)
}

/// `states` (one per super-step) resampled at `per` frames per step.
pub fn resample(scene: &Scene, states: &[Vec<f64>], per: usize) -> Vec<Vec<f64>> {
    let mut out = Vec::with_capacity(states.len().saturating_sub(1) * per + 1);
    for w in states.windows(2) {
        out.extend((0..per).map(|j| scene.interpolate(&w[0], &w[1], j as f64 / per as f64)));
    }
    out.extend(states.last().cloned());
    out
}

/// Writes `<dir>/<stem>.gif` atomically: `tracks` (one state per super-step of `step`
/// seconds, starting at t = 0) played together over `goal`, resampled by [`resample`] with
/// [`frame_timing`], the last frame held briefly. Each frame is headed by `title`, the time and
/// the playback speed, with `caption` (e.g. which colour is which source) below. Returns the
/// path and the number of frames.
#[allow(clippy::too_many_arguments)]
pub fn write_animation(
    dir: &Path,
    stem: &str,
    scene: &Scene,
    title: &str,
    caption: &str,
    step: f64,
    goal: &[f64],
    tracks: &[Track],
) -> Result<(PathBuf, usize), Error> {
    std::fs::create_dir_all(dir).map_err(|e| Error::Io {
        path: dir.to_path_buf(),
        source: e,
    })?;
    ensure_fonts();
    let gif = dir.join(format!("{stem}.gif"));
    let steps = tracks.iter().map(|t| t.states.len()).max().unwrap_or(1);
    let (per, cs) = frame_timing(step, steps.saturating_sub(1));
    let speed = step / per as f64 / (cs as f64 / 100.0);
    let played: Vec<Vec<Vec<f64>>> = tracks
        .iter()
        .map(|t| resample(scene, &t.states, per))
        .collect();
    let len = played.iter().map(Vec::len).max().unwrap_or(0).max(1);
    let hold = ((HOLD * 100.0 / cs as f64).ceil() as usize).min(10);
    let size = scene.size();
    let tmp = temp_path(&gif);
    let e = |m: String| perr(&gif, m);
    {
        let root = BitMapBackend::gif(&tmp, size, cs * 10)
            .map_err(|x| e(x.to_string()))?
            .into_drawing_area();
        let (head, body) = root.split_vertically(TITLE_HEIGHT);
        let views = scene.views(body.dim_in_pixel(), goal, tracks);
        let note = if (speed - 1.0).abs() > 0.01 {
            format!("   (played at {speed:.2}× speed)")
        } else {
            String::new()
        };
        for k in 0..len + hold {
            let k = k.min(len - 1);
            root.fill(&WHITE).map_err(|x| e(x.to_string()))?;
            let t = k as f64 * step / per as f64;
            head.draw(&Text::new(
                format!("{title}   t = {t:.2} s{note}"),
                (10, 4),
                ("sans-serif", 16).into_font().color(&BLACK),
            ))
            .map_err(|x| e(x.to_string()))?;
            head.draw(&Text::new(
                caption,
                (10, 23),
                ("sans-serif", 13).into_font().color(&RGBColor(60, 60, 60)),
            ))
            .map_err(|x| e(x.to_string()))?;
            let bodies: Vec<Body> = tracks
                .iter()
                .zip(&played)
                .map(|(t, p)| Body {
                    label: &t.label,
                    color: t.color,
                    history: &p[..(k + 1).min(p.len())],
                })
                .collect();
            scene.draw(&body, &views, goal, &bodies).map_err(e)?;
            root.present().map_err(|x| e(x.to_string()))?;
        }
    }
    std::fs::rename(&tmp, &gif).map_err(|x| Error::Io {
        path: gif.clone(),
        source: x,
    })?;
    Ok((gif, len + hold))
}

#[cfg(test)]
mod tests {
    use super::*;

    const SIZE: (u32, u32) = (320, 240);

    /// Renders `draw` into an in-memory bitmap; returns how many pixels are not white.
    fn render(draw: impl Fn(&DrawingArea<BitMapBackend, Shift>) -> Result<(), String>) -> usize {
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

    fn tracks(a: Vec<f64>, b: Vec<f64>) -> Vec<Track> {
        vec![Track {
            label: "emulator".into(),
            color: EMULATOR,
            states: vec![a, b],
        }]
    }

    fn frame(scene: &Scene, goal: &[f64], tr: &[Track]) -> usize {
        let views = scene.views(SIZE, goal, tr);
        let bodies: Vec<Body> = tr
            .iter()
            .map(|t| Body {
                label: &t.label,
                color: t.color,
                history: &t.states,
            })
            .collect();
        render(|a| scene.draw(a, &views, goal, &bodies))
    }

    #[test]
    fn pendulum_frame_renders() {
        let scene = Scene::for_model(NetModel::PendulumActive);
        let goal = [0.6, 0.0, 0.0, 0.0, 0.0, 0.0];
        let tr = tracks(vec![0.0; 6], vec![0.3, 0.2, -0.1, 0.0, 0.0, 0.0]);
        assert!(frame(&scene, &goal, &tr) > 1000);
    }

    #[test]
    fn truck_frame_renders() {
        let scene = Scene::for_model(NetModel::Truck);
        let tr = tracks(
            vec![-15.0, -8.0, 0.4, 0.0, 0.0, 0.0],
            vec![-10.0, -5.0, 0.2, 1.0, 0.0, 0.0],
        );
        assert!(frame(&scene, &[0.0; 6], &tr) > 1000);
    }

    #[test]
    fn lander_frame_renders() {
        let scene = Scene::for_model(NetModel::Lander);
        let goal = Lander::upright_at_rest([0.0, 0.0, 1.5]);
        let mut tilted = Lander::upright_at_rest([12.0, -8.0, 60.0]);
        tilted[QUAT + 1] = 0.2;
        Lander::default().normalize_state(&mut tilted);
        let tr = tracks(
            tilted.to_vec(),
            Lander::upright_at_rest([6.0, -4.0, 30.0]).to_vec(),
        );
        assert!(frame(&scene, &goal, &tr) > 1000);
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
    fn interpolated_quaternions_are_unit() {
        let scene = Scene::for_model(NetModel::Lander);
        let a = Lander::upright_at_rest([0.0; 3]);
        let mut b = a;
        b[QUAT] = 0.0;
        b[QUAT + 3] = 1.0; // a half turn about z
        let s = scene.interpolate(&a, &b, 0.5);
        let n: f64 = s[QUAT..QUAT + 4].iter().map(|c| c * c).sum();
        assert!((n - 1.0).abs() < 1e-12, "{n}");
        // The pendulum interpolates linearly.
        let p = Scene::for_model(NetModel::PendulumActive);
        assert_eq!(
            p.interpolate(&[0.0, 2.0], &[1.0, 4.0], 0.25),
            vec![0.25, 2.5]
        );
    }

    #[test]
    fn timing_and_resampling() {
        // Few steps: truck and lander super-steps (0.5 s): 10 frames 5 cs apart; pendulum
        // (0.1 s): 2 frames 5 cs apart; shorter steps play slowed down.
        assert_eq!(frame_timing(0.5, 10), (10, 5));
        assert_eq!(frame_timing(0.1, 10), (2, 5));
        assert_eq!(frame_timing(0.01, 10), (1, 4));
        // 40 steps: at most MAX_FRAMES = 200 frames.
        assert_eq!(frame_timing(0.5, 40), (5, 10));
        assert_eq!(frame_timing(0.1, 40), (2, 5));
        // 0.3 s: 7 frames would not be whole centiseconds, 6 are.
        assert_eq!(frame_timing(0.3, 1), (6, 5));
        // 0.35 s over 25 steps: at most 8 frames a step; 7 make whole centiseconds.
        assert_eq!(frame_timing(0.35, 25), (7, 5));
        let scene = Scene::for_model(NetModel::Truck);
        let r = resample(&scene, &[vec![0.0], vec![1.0], vec![3.0]], 4);
        assert_eq!(r.len(), 9);
        assert_eq!(r[2], vec![0.5]);
        assert_eq!(r[6], vec![2.0]);
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

    #[test]
    fn animation_gif_is_written_atomically() {
        let dir = tempfile::tempdir().unwrap();
        let scene = Scene::for_model(NetModel::PendulumActive);
        let tr = tracks(vec![0.0; 6], vec![0.3, 0.0, 0.0, 0.0, 0.0, 0.0]);
        let (p, frames) = write_animation(
            dir.path(),
            "anim",
            &scene,
            "pendulum",
            "test",
            0.1,
            &[0.6, 0.0, 0.0, 0.0, 0.0, 0.0],
            &tr,
        )
        .unwrap();
        assert_eq!(p, dir.path().join("anim.gif"));
        // 2 frames per 0.1 s step + the final state, held for 0.5 s (10 frames of 5 cs).
        assert_eq!(frames, 2 + 1 + 10);
        let bytes = std::fs::read(&p).unwrap();
        assert_eq!(&bytes[..6], b"GIF89a");
        let names: Vec<_> = std::fs::read_dir(dir.path()).unwrap().collect();
        assert_eq!(names.len(), 1, "no temp file left behind");
    }
}
