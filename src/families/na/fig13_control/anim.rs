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
//! Each model has a frame drawer in [`super::frames`] that draws one frame onto a plotters
//! drawing area, and a [`Scene`] variant that says how its states interpolate, which views it
//! has and how to fit them; [`write_animation`] writes the GIF atomically.

// Animation frames: a last-bit difference moves no table.
#![allow(clippy::disallowed_methods)]

use super::frames::{
    draw_dolphin_side, draw_lander, draw_pendulum, draw_truck, joints, lander_box, Axes, Body,
    TRUCK_OVERHANG, TRUCK_WIDTH,
};
use crate::emulator::catalog::NetModel;
use crate::experiment::plot::{ensure_fonts, write_gif_atomically};
use crate::experiment::Error;
use crate::physics::dolphin::{Dolphin, N_POS};
use crate::physics::lander::{Lander, QUAT};
use crate::physics::pendulum::{Pendulum3, PendulumVariant};
use crate::physics::truck::Truck;
use plotters::coord::Shift;
use plotters::prelude::*;
use std::iter::once;
use std::path::{Path, PathBuf};

/// Colour of the emulator-driven motion.
pub const EMULATOR: RGBColor = RGBColor(128, 40, 170);
/// Colour of the simulator replay.
pub const SIMULATOR: RGBColor = RGBColor(120, 120, 120);

/// Most frames drawn per emulator super-step.
pub const FRAMES_PER_STEP: usize = 10;
/// Most frames in one animation (before the held last frame): bounds the GIF's size (each
/// frame is quantised and compressed on its own, some 10-20 kB) and the time to write it.
pub const MAX_FRAMES: usize = 200;
/// Shortest delay between frames (s): at most 25 frames per second.
pub const MIN_FRAME_DELAY: f64 = 0.04;
/// How long the last frame is held before the animation loops (s), in at most 10 frames.
const HOLD: f64 = 0.5;

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
    write_gif_atomically(&gif, size, cs * 10, |root| {
        let (head, body) = root.split_vertically(TITLE_HEIGHT);
        let views = scene.views(body.dim_in_pixel(), goal, tracks);
        let note = if (speed - 1.0).abs() > 0.01 {
            format!("   (played at {speed:.2}× speed)")
        } else {
            String::new()
        };
        for k in 0..len + hold {
            let k = k.min(len - 1);
            root.fill(&WHITE).map_err(|x| x.to_string())?;
            let t = k as f64 * step / per as f64;
            head.draw(&Text::new(
                format!("{title}   t = {t:.2} s{note}"),
                (10, 4),
                ("sans-serif", 16).into_font().color(&BLACK),
            ))
            .map_err(|x| x.to_string())?;
            head.draw(&Text::new(
                caption,
                (10, 23),
                ("sans-serif", 13).into_font().color(&RGBColor(60, 60, 60)),
            ))
            .map_err(|x| x.to_string())?;
            let bodies: Vec<Body> = tracks
                .iter()
                .zip(&played)
                .map(|(t, p)| Body {
                    label: &t.label,
                    color: t.color,
                    history: &p[..(k + 1).min(p.len())],
                })
                .collect();
            scene.draw(&body, &views, goal, &bodies)?;
            root.present().map_err(|x| x.to_string())?;
        }
        Ok(())
    })?;
    Ok((gif, len + hold))
}

#[cfg(test)]
mod tests {
    use super::super::frames::tests::{render, SIZE};
    use super::*;

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
