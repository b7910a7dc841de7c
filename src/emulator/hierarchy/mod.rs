//! # The hierarchical dolphin NeuroAnimator (§3.3, Fig. 7, Table 1)
//!
//! The dolphin ([`crate::physics::dolphin`]) has 138 state variables (23 masses × position and
//! velocity). Rather than one monolithic net, the paper emulates it with a hierarchy: a
//! **global net** over the rigid motion of the 6 body segments, and one **local net** per
//! segment for the deformation of its masses in the segment's own centre-of-mass frame, which
//! takes part of its input from the global net.
//!
//! ## Global net (Table 1: 78 + 6 → 50 → 78)
//! Its state is the 6 segment frames ([`crate::physics::dolphin::SegmentFrame::to_array`]):
//! centroid, orientation quaternion, velocity and angular velocity, 13 numbers each, 78 in all
//! ([`global_state`]; quaternion signs follow the reference segment, and in training targets
//! the previous step, so they never jump between q and −q). It is an ordinary [`Emulator`] with the standard transforms: the state
//! change is predicted, everything is expressed in the frame of the middle segment
//! ([`REF_SEGMENT`]) and normalized ([`global_transforms`]). Controllers are learned through
//! this net alone (§6: the local deformation does not matter for locomotion).
//!
//! ## Local nets (Table 1: 72 + 6 → 40 → 36; ours 48–70 inputs, 12–30 outputs)
//! Segment s owns the masses [`crate::physics::dolphin::segment_of_mass`] assigns to it and
//! fits its frame to [`segment_frame_masses`] (its two bounding stations). Its net sees, all in
//! the segment's *current* frame F₀ = (c₀, R₀, v₀, ω₀):
//! - the positions Rᵀ₀(pᵢ − c₀) and velocities Rᵀ₀(vᵢ − v₀) of the frame masses (6 each),
//! - its angular velocity Rᵀ₀ω₀ (3),
//! - the *next* frame F₁ the global net predicts, relative to F₀: Rᵀ₀(c₁ − c₀), q₀⁻¹ ⊗ q₁,
//!   Rᵀ₀v₁, Rᵀ₀ω₁ (13) — the input from the parent network,
//! - the 6 muscle controls;
//!
//! and predicts, for each mass it owns, the change of its local position and velocity from
//! frame F₀ to frame F₁: R₁ᵀ(p′ᵢ − c₁) − R₀ᵀ(pᵢ − c₀) and R₁ᵀ(v′ᵢ − v₁) − R₀ᵀ(vᵢ − v₀). Inputs
//! and outputs are normalized by quantity groups ([`LocalLayout::input_groups`]). The segment sizes differ (the nose segment owns 5
//! masses, the fluke 2), so the local nets differ slightly in shape; the paper's Table 1 gives
//! one representative.
//!
//! [`DolphinEmulator`] composes them into one step of the 138-variable mass state: frames F₀
//! → global net → F₁ → each local net → world positions and velocities
//! p′ᵢ = c₁ + R₁(local), v′ᵢ = v₁ + R₁(local). The first step of a rollout takes F₀ fitted to
//! the start state; every later step carries the global net's own previous output
//! ([`DolphinEmulator::predict_carried`]), so the segments move exactly as the global net alone
//! does (what controllers are learned through) and the local nets refine that motion (§6:
//! "sub-networks refine the motion produced by the global network"). Refitting the frames to
//! the emulated masses instead fed the local nets' velocity errors back into the global net as
//! frame angular velocities: on Table 1's nets the refitted frames' 40-step error was
//! 4.1 of their spread against 0.32 for the global net alone. During training each local net
//! is given the true next frame (teacher forcing); at run time the predicted one. With the
//! settings' `input_noise`, each local net trains on local coordinates perturbed as the global
//! net's inputs are, its targets the change to the true next state, so that it pulls its own
//! deformation errors back instead of compounding them over a rollout.
//!
//! ## Regularization (§5.3)
//! [`Regularizer`] performs spring-only Euler steps v ← v + δt a(x, v, u), x ← x + δt (v − v̄)
//! (§5.3's step, with v̄ the centre-of-mass velocity taken out of the position update so that
//! regularizing deforms the body without advancing its flight, i.e. animation time), with
//! softer springs and more damping than the simulator, and no hydrodynamics. A [`Schedule`] says how many such steps follow which emulation steps.
//!
//! ## Training data (§3.4)
//! Episodes of 20 s from the rest shape at a random position, heading, pitch and roll, swimming
//! at U[−0.5, 1] m/s along its axis, driven by travelling muscle waves of random frequency,
//! lag, amplitude and direction held piecewise constant
//! ([`super::dataset::ControlProcess::TravellingWave`]); samples at lags U[Δt, 5Δt]. Sampling runs in parallel chunks, each from its own seeded stream, so the data
//! do not depend on the thread count. The local nets use the first `local.examples` of the
//! global net's examples.
//!
//! This module holds the encodings (global state, segment frames, local layouts) and the
//! composed emulator; `regularize` the §5.3 steps; `training` the sampling, training and
//! caching of the seven nets.

pub mod dagger;
mod regularize;
mod training;

pub use regularize::{BoundRegularizer, Regularizer, Schedule};
pub use training::{
    build_dolphin, build_global, control_limits, control_process, global_heldout_errors,
    global_training_data, global_transitions, head, hierarchy_rollout_error, net_name,
    sample_dolphin, simulator, start_state, train_hierarchy, BuiltDolphin, HierarchyNet,
    HierarchySpec, NetReport, EPISODE_S,
};

use super::catalog::TransformSet;
use super::mlp::{Mlp, MlpScratch};
use super::transform::{Attitude, Normalizer, SpatialFrame};
use super::{Emulator, EmulatorScratch, TransformConfig};
use crate::physics::dolphin::{
    segment_frame_masses, segment_of_mass, Dolphin, SegmentFrame, N_MASSES, N_POS, N_SEGMENTS,
};
use crate::physics::Dynamics;
use nalgebra::{Quaternion, UnitQuaternion, Vector3};

/// Numbers per segment frame in the global state.
pub const FRAME_DIM: usize = 13;
/// Size of the global state (6 frames).
pub const GLOBAL_DIM: usize = FRAME_DIM * N_SEGMENTS;
/// Size of the dolphin's mass state.
pub const MASS_DIM: usize = 2 * N_POS;
/// The segment whose frame the global net works in.
pub const REF_SEGMENT: usize = 2;
/// Bumped whenever the hierarchy's sampling, transforms or training code changes meaning, so
/// cached nets are retrained.
pub const HIERARCHY_FORMAT: u32 = 6;
/// Writes the global state (6 segment frames, 13 numbers each) of the mass state `x`.
///
/// Quaternion signs: the reference segment's has w ≥ 0 and every other segment's the sign
/// that agrees with it (non-negative dot product), so that in the reference frame every
/// segment's relative quaternion has w ≥ 0 whatever the heading (a per-segment w ≥ 0 would
/// flip some segments' relative quaternions to w ≈ −1 near a half-turn heading).
pub fn global_state(d: &Dolphin, x: &[f64], out: &mut [f64]) {
    write_frames(&d.segment_frames(x), out);
}

/// The global state of `frames` with the signs of [`global_state`].
fn write_frames(frames: &[SegmentFrame; N_SEGMENTS], out: &mut [f64]) {
    let r = frames[REF_SEGMENT].to_array();
    let q_ref = [r[3], r[4], r[5], r[6]];
    for (s, f) in frames.iter().enumerate() {
        out[FRAME_DIM * s..FRAME_DIM * (s + 1)].copy_from_slice(&f.to_array_aligned(q_ref));
    }
}

/// Writes the global state of the mass state `x1` one step after the global state `prev`,
/// each segment's quaternion signed to agree with its own quaternion in `prev`: the change
/// from `prev` is then continuous (no ±q jump), which is what the global net is trained on.
pub fn global_state_after(d: &Dolphin, x1: &[f64], prev: &[f64], out: &mut [f64]) {
    for s in 0..N_SEGMENTS {
        let q = FRAME_DIM * s + 3;
        let reference = [prev[q], prev[q + 1], prev[q + 2], prev[q + 3]];
        out[FRAME_DIM * s..FRAME_DIM * (s + 1)]
            .copy_from_slice(&d.segment_frame(x1, s).to_array_aligned(reference));
    }
}

/// The transforms of the global net: state change, the frame of [`REF_SEGMENT`] for every
/// centroid, quaternion, velocity and angular velocity, and normalization by quantity groups
/// ([`global_groups`]).
pub fn global_transforms() -> TransformConfig {
    global_transforms_of(TransformSet::Full)
}

/// The global net's chain reduced to the operators of `set` ([`TransformSet::reduce`]).
pub fn global_transforms_of(set: TransformSet) -> TransformConfig {
    let base = FRAME_DIM * REF_SEGMENT;
    let tri = |a: usize| [a, a + 1, a + 2];
    // The swimmer is neutrally buoyant: no direction is special, the whole attitude goes.
    let frame = SpatialFrame {
        attitude: Attitude::Full,
        origin: tri(base),
        orientation: [base + 3, base + 4, base + 5, base + 6],
        points: (0..N_SEGMENTS).map(|s| tri(FRAME_DIM * s)).collect(),
        vectors: (0..N_SEGMENTS)
            .flat_map(|s| [tri(FRAME_DIM * s + 7), tri(FRAME_DIM * s + 10)])
            .collect(),
        quaternions: (0..N_SEGMENTS)
            .map(|s| {
                let q = FRAME_DIM * s + 3;
                [q, q + 1, q + 2, q + 3]
            })
            .collect(),
    };
    let (input_groups, output_groups) = global_groups();
    set.reduce(TransformConfig {
        input_groups: Some(input_groups),
        output_groups: Some(output_groups),
        ..TransformConfig::standard(Some(frame.into()))
    })
}

/// Normalization groups of the global net by physical quantity (Appendix A normalizes groups
/// of variables, not variables one by one): every segment's centroid (0), quaternion (1),
/// velocity (2) and angular velocity (3) share a mean and a deviation, and the controls form
/// group 4. Per variable, the near-rigid spacings of the segments (a few millimetres of
/// spread in the reference frame) would be divided by their own tiny deviations, so that
/// millimetre errors of a rollout became many deviations of input within a few steps and the
/// net left its training distribution.
pub fn global_groups() -> (Vec<usize>, Vec<usize>) {
    let state: Vec<usize> = (0..GLOBAL_DIM)
        .map(|k| match k % FRAME_DIM {
            0..=2 => 0,
            3..=6 => 1,
            7..=9 => 2,
            _ => 3,
        })
        .collect();
    let mut input = state.clone();
    input.extend([4; N_SEGMENTS]);
    (input, state)
}

/// A segment frame as vectors and a unit rotation.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Frame {
    c: Vector3<f64>,
    r: UnitQuaternion<f64>,
    v: Vector3<f64>,
    w: Vector3<f64>,
}

impl Frame {
    fn from_segment(f: &SegmentFrame) -> Self {
        Self {
            c: f.centroid,
            r: f.orientation,
            v: f.velocity,
            w: f.angular_velocity,
        }
    }

    /// From 13 numbers of a global state (the quaternion is normalized).
    fn from_slice(a: &[f64]) -> Self {
        Self {
            c: Vector3::new(a[0], a[1], a[2]),
            r: UnitQuaternion::from_quaternion(Quaternion::new(a[3], a[4], a[5], a[6])),
            v: Vector3::new(a[7], a[8], a[9]),
            w: Vector3::new(a[10], a[11], a[12]),
        }
    }
}

fn point(x: &[f64], i: usize) -> Vector3<f64> {
    Vector3::new(x[3 * i], x[3 * i + 1], x[3 * i + 2])
}

fn put(x: &mut [f64], i: usize, p: &Vector3<f64>) {
    x[3 * i] = p.x;
    x[3 * i + 1] = p.y;
    x[3 * i + 2] = p.z;
}

/// Which masses a local net sees and which it predicts.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct LocalLayout {
    /// The segment (0 = nose … 5 = fluke).
    pub segment: usize,
    /// Masses its frame is fitted to (inputs).
    pub frame_masses: &'static [usize],
    /// Masses it owns (outputs).
    pub owned: Vec<usize>,
}

impl LocalLayout {
    /// The layout of segment `s`.
    pub fn new(segment: usize) -> Self {
        Self {
            segment,
            frame_masses: segment_frame_masses(segment),
            owned: (0..N_MASSES)
                .filter(|&i| segment_of_mass(i) == segment)
                .collect(),
        }
    }

    /// Network inputs: 6 per frame mass, ω₀ (3), the relative next frame (13), controls (6).
    pub fn n_in(&self) -> usize {
        6 * self.frame_masses.len() + 3 + FRAME_DIM + N_SEGMENTS
    }

    /// Network outputs: 6 per owned mass.
    pub fn n_out(&self) -> usize {
        6 * self.owned.len()
    }

    /// Normalization group of each input, by physical quantity (as the global net's,
    /// [`global_groups`]): frame-mass positions (0) and velocities (1), ω₀ (2), the next
    /// frame's centroid (3), quaternion (4), velocity (5) and angular velocity (6), controls (7).
    pub fn input_groups(&self) -> Vec<usize> {
        let mut g: Vec<usize> = (0..6 * self.frame_masses.len())
            .map(|k| usize::from(k % 6 >= 3))
            .collect();
        for (group, len) in [(2, 3), (3, 3), (4, 4), (5, 3), (6, 3), (7, N_SEGMENTS)] {
            g.extend(std::iter::repeat_n(group, len));
        }
        g
    }

    /// Normalization group of each output: position changes (0), velocity changes (1).
    pub fn output_groups(&self) -> Vec<usize> {
        (0..self.n_out()).map(|k| usize::from(k % 6 >= 3)).collect()
    }

    /// Raw (unnormalized) input for mass state `x` with current frame `f0`, next frame `f1`
    /// and controls `u`.
    fn input(&self, x: &[f64], f0: &Frame, f1: &Frame, u: &[f64], z: &mut [f64]) {
        let (q, v) = x.split_at(N_POS);
        let inv = f0.r.inverse();
        let mut k = 0;
        fn push(z: &mut [f64], a: Vector3<f64>, k: &mut usize) {
            z[*k..*k + 3].copy_from_slice(a.as_slice());
            *k += 3;
        }
        for &i in self.frame_masses {
            push(z, inv * (point(q, i) - f0.c), &mut k);
            push(z, inv * (point(v, i) - f0.v), &mut k);
        }
        push(z, inv * f0.w, &mut k);
        push(z, inv * (f1.c - f0.c), &mut k);
        let mut rel = (inv * f1.r).into_inner();
        if rel.w < 0.0 {
            rel = -rel;
        }
        z[k..k + 4].copy_from_slice(&[rel.w, rel.i, rel.j, rel.k]);
        k += 4;
        push(z, inv * f1.v, &mut k);
        push(z, inv * f1.w, &mut k);
        z[k..k + N_SEGMENTS].copy_from_slice(&u[..N_SEGMENTS]);
    }

    /// Raw target: change of each owned mass's local position and velocity from `f0` to `f1`.
    fn target(&self, x: &[f64], f0: &Frame, x1: &[f64], f1: &Frame, y: &mut [f64]) {
        let (q0, v0) = x.split_at(N_POS);
        let (q1, v1) = x1.split_at(N_POS);
        let (inv0, inv1) = (f0.r.inverse(), f1.r.inverse());
        for (j, &i) in self.owned.iter().enumerate() {
            let dp = inv1 * (point(q1, i) - f1.c) - inv0 * (point(q0, i) - f0.c);
            let dv = inv1 * (point(v1, i) - f1.v) - inv0 * (point(v0, i) - f0.v);
            y[6 * j..6 * j + 3].copy_from_slice(dp.as_slice());
            y[6 * j + 3..6 * j + 6].copy_from_slice(dv.as_slice());
        }
    }

    /// Writes the owned masses of the next state from a raw output `y` (inverse of
    /// [`LocalLayout::target`]).
    fn decode(&self, x: &[f64], f0: &Frame, f1: &Frame, y: &[f64], x1: &mut [f64]) {
        let (q0, v0) = x.split_at(N_POS);
        let (q1, v1) = x1.split_at_mut(N_POS);
        let inv0 = f0.r.inverse();
        for (j, &i) in self.owned.iter().enumerate() {
            let dp = Vector3::new(y[6 * j], y[6 * j + 1], y[6 * j + 2]);
            let dv = Vector3::new(y[6 * j + 3], y[6 * j + 4], y[6 * j + 5]);
            let lp = inv0 * (point(q0, i) - f0.c) + dp;
            let lv = inv0 * (point(v0, i) - f0.v) + dv;
            put(q1, i, &(f1.c + f1.r * lp));
            put(v1, i, &(f1.v + f1.r * lv));
        }
    }
}

/// One trained local net with its normalization.
#[derive(Debug, Clone, PartialEq)]
pub struct LocalNet {
    /// Its inputs and outputs.
    pub layout: LocalLayout,
    /// The network.
    pub mlp: Mlp,
    /// Input normalization.
    pub input_norm: Normalizer,
    /// Output normalization.
    pub output_norm: Normalizer,
}

impl LocalNet {
    /// Writes the owned masses of `x1` given the current state `x`, its frame `f0`, the next
    /// frame `f1` and the controls. `z`, `y`, `tmp` are scratch of the net's sizes.
    #[allow(clippy::too_many_arguments)]
    fn apply(
        &self,
        x: &[f64],
        f0: &Frame,
        f1: &Frame,
        u: &[f64],
        buf: &mut LocalScratch,
        x1: &mut [f64],
    ) {
        self.layout.input(x, f0, f1, u, &mut buf.raw_in);
        self.input_norm.normalize(&buf.raw_in, &mut buf.z);
        self.mlp.forward(&buf.z, &mut buf.mlp, &mut buf.y);
        self.output_norm.denormalize(&buf.y, &mut buf.raw_out);
        self.layout.decode(x, f0, f1, &buf.raw_out, x1);
    }
}

#[derive(Debug, Clone)]
struct LocalScratch {
    raw_in: Vec<f64>,
    z: Vec<f64>,
    y: Vec<f64>,
    raw_out: Vec<f64>,
    mlp: MlpScratch,
}

/// Scratch of one [`DolphinEmulator`] step.
#[derive(Debug, Clone)]
pub struct DolphinScratch {
    g0: Vec<f64>,
    g1: Vec<f64>,
    /// The last state [`Dynamics::step`] produced (empty before the first) and the global
    /// state carried with it.
    last_x: Vec<f64>,
    last_g: Vec<f64>,
    global: EmulatorScratch,
    local: Vec<LocalScratch>,
    next: Vec<f64>,
}

/// The composed hierarchical emulator: one super timestep of the 138-variable mass state.
#[derive(Debug, Clone)]
pub struct DolphinEmulator {
    dolphin: Dolphin,
    global: Emulator,
    locals: Vec<LocalNet>,
    /// Scratch of [`Dynamics::step`] (taken out while stepping).
    scratch: Option<Box<DolphinScratch>>,
}

impl DolphinEmulator {
    /// Composes a global emulator (78 + 6 → 78) and six local nets.
    ///
    /// # Panics
    /// When the shapes do not fit the dolphin (a programming error, not bad input).
    pub fn new(dolphin: Dolphin, global: Emulator, locals: Vec<LocalNet>) -> Self {
        assert_eq!(Dynamics::state_dim(&global), GLOBAL_DIM);
        assert_eq!(Dynamics::control_dim(&global), N_SEGMENTS);
        assert_eq!(locals.len(), N_SEGMENTS);
        for (s, l) in locals.iter().enumerate() {
            assert_eq!(l.layout.segment, s);
            assert_eq!(l.mlp.n_in(), l.layout.n_in());
            assert_eq!(l.mlp.n_out(), l.layout.n_out());
        }
        let scratch = DolphinScratch {
            g0: vec![0.0; GLOBAL_DIM],
            g1: vec![0.0; GLOBAL_DIM],
            last_x: Vec::new(),
            last_g: vec![0.0; GLOBAL_DIM],
            global: global.scratch(),
            local: locals
                .iter()
                .map(|l| LocalScratch {
                    raw_in: vec![0.0; l.layout.n_in()],
                    z: vec![0.0; l.layout.n_in()],
                    y: vec![0.0; l.layout.n_out()],
                    raw_out: vec![0.0; l.layout.n_out()],
                    mlp: l.mlp.scratch(),
                })
                .collect(),
            next: vec![0.0; MASS_DIM],
        };
        Self {
            dolphin,
            global,
            locals,
            scratch: Some(Box::new(scratch)),
        }
    }

    /// The same hierarchy with `global` in place of its global net (the local nets kept).
    pub fn with_global(&self, global: Emulator) -> Self {
        Self::new(self.dolphin.clone(), global, self.locals.clone())
    }

    /// The dolphin it emulates.
    pub fn dolphin(&self) -> &Dolphin {
        &self.dolphin
    }

    /// The global net (the emulator controllers are learned through).
    pub fn global(&self) -> &Emulator {
        &self.global
    }

    /// The local net of segment `s`.
    pub fn local(&self, s: usize) -> &LocalNet {
        &self.locals[s]
    }

    /// Super timestep Δt (s).
    pub fn dt(&self) -> f64 {
        self.global.dt()
    }

    /// Fresh scratch for [`DolphinEmulator::predict`].
    pub fn scratch(&self) -> DolphinScratch {
        (**self
            .scratch
            .as_ref()
            .expect("scratch is put back after each step"))
        .clone()
    }

    /// Writes the next mass state from a mass state alone: the segment frames fitted to `x`
    /// → global net → local nets (the first step of a rollout; later steps carry the global
    /// net's own frames, [`DolphinEmulator::predict_carried`]).
    pub fn predict(&self, x: &[f64], u: &[f64], sc: &mut DolphinScratch, x1: &mut [f64]) {
        let mut g0 = std::mem::take(&mut sc.g0);
        let mut g1 = std::mem::take(&mut sc.g1);
        global_state(&self.dolphin, x, &mut g0);
        self.predict_carried(x, &g0, u, sc, x1, &mut g1);
        sc.g0 = g0;
        sc.g1 = g1;
    }

    /// One step of the hierarchy carrying the global state `g` (6 segment frames) along with
    /// the mass state `x`: the global net advances `g` to `g1`, and each local net places its
    /// masses between frame F₀ of `g` and F₁ of `g1`. Along a rollout `g` is the global net's
    /// own previous output, so the composed hierarchy's segments move exactly as the global net
    /// alone does (the nets controllers are learned through), and the local nets refine that
    /// motion with the deformation; frames refitted to the emulated masses instead would feed
    /// the local nets' velocity errors back into the global net as frame angular velocities.
    #[allow(clippy::too_many_arguments)]
    pub fn predict_carried(
        &self,
        x: &[f64],
        g: &[f64],
        u: &[f64],
        sc: &mut DolphinScratch,
        x1: &mut [f64],
        g1: &mut [f64],
    ) {
        self.global.predict(g, u, &mut sc.global, g1);
        for (s, net) in self.locals.iter().enumerate() {
            let f0 = Frame::from_slice(&g[FRAME_DIM * s..FRAME_DIM * (s + 1)]);
            let f1 = Frame::from_slice(&g1[FRAME_DIM * s..FRAME_DIM * (s + 1)]);
            net.apply(x, &f0, &f1, u, &mut sc.local[s], x1);
        }
    }
}

impl DolphinEmulator {
    /// Emulates from `x0` under per-step `controls` (m each), carrying the global state from
    /// the frames of `x0` ([`DolphinEmulator::predict_carried`]), following each emulation step
    /// with `schedule`'s regularization steps of `reg` when due (they deform the masses, not
    /// the carried frames), and calls `visit(k, x)` with the state after step k = 1, 2, ….
    /// Returns the final state.
    pub fn emulate(
        &self,
        reg: &mut BoundRegularizer,
        schedule: Schedule,
        x0: &[f64],
        controls: &[f64],
        scratch: &mut DolphinScratch,
        mut visit: impl FnMut(usize, &[f64]),
    ) -> Vec<f64> {
        let mut x = x0.to_vec();
        let mut y = x0.to_vec();
        let mut g = vec![0.0; GLOBAL_DIM];
        let mut g1 = vec![0.0; GLOBAL_DIM];
        global_state(&self.dolphin, x0, &mut g);
        for (k, u) in controls.chunks_exact(N_SEGMENTS).enumerate() {
            self.predict_carried(&x, &g, u, scratch, &mut y, &mut g1);
            std::mem::swap(&mut x, &mut y);
            std::mem::swap(&mut g, &mut g1);
            if schedule.due(k + 1) {
                reg.apply(&mut x, u, schedule.steps);
            }
            visit(k + 1, &x);
        }
        x
    }
}

impl Dynamics for DolphinEmulator {
    fn state_dim(&self) -> usize {
        MASS_DIM
    }

    fn control_dim(&self) -> usize {
        N_SEGMENTS
    }

    /// One super timestep. When `x` is the state the previous step produced, the global state
    /// that step carried continues ([`DolphinEmulator::predict_carried`]); any other state
    /// starts afresh from its fitted frames ([`DolphinEmulator::predict`]).
    ///
    /// # Panics
    /// When `dt` is not the emulator's Δt.
    fn step(&mut self, x: &mut [f64], u: &[f64], dt: f64) {
        let own = self.dt();
        assert!(
            (dt - own).abs() <= 1e-9 * own.abs().max(1.0),
            "dolphin emulator trained for Δt = {own} s was stepped with dt = {dt} s"
        );
        let mut sc = self
            .scratch
            .take()
            .expect("scratch is put back after each step");
        let mut next = std::mem::take(&mut sc.next);
        let (mut g0, mut g1) = (std::mem::take(&mut sc.g0), std::mem::take(&mut sc.g1));
        if sc.last_x.as_slice() == x {
            g0.copy_from_slice(&sc.last_g);
        } else {
            global_state(&self.dolphin, x, &mut g0);
        }
        self.predict_carried(x, &g0, u, &mut sc, &mut next, &mut g1);
        x.copy_from_slice(&next);
        sc.last_x.clear();
        sc.last_x.extend_from_slice(&next);
        sc.last_g.copy_from_slice(&g1);
        (sc.g0, sc.g1) = (g0, g1);
        sc.next = next;
        self.scratch = Some(sc);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::emulator::mlp::WeightInit;
    use crate::emulator::Transforms;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    fn swim_state(d: &Dolphin, secs: f64) -> (Vec<f64>, Vec<f64>) {
        let mut sim = simulator(d);
        let mut x = d.rest_state();
        let mut u = [0.0; N_SEGMENTS];
        let mut t = 0.0;
        while t < secs {
            for (s, a) in u.iter_mut().enumerate() {
                *a = (std::f64::consts::TAU * t - 0.5 * s as f64).sin();
            }
            sim.step(&mut x, &u, 0.002);
            t += 0.002;
        }
        (x, u.to_vec())
    }

    #[test]
    fn layouts_partition_the_masses_and_match_table_1_scale() {
        let mut seen = [0; N_MASSES];
        for s in 0..N_SEGMENTS {
            let l = LocalLayout::new(s);
            for &i in &l.owned {
                seen[i] += 1;
                assert!(
                    l.frame_masses.contains(&i),
                    "owned mass {i} outside frame {s}"
                );
            }
            assert!(
                l.n_in() <= 72 && l.n_out() <= 36,
                "segment {s}: {} -> {}",
                l.n_in(),
                l.n_out()
            );
        }
        assert!(seen.iter().all(|&c| c == 1));
        assert_eq!(LocalLayout::new(2).n_in(), 70);
        assert_eq!(LocalLayout::new(2).n_out(), 24);
    }

    /// Encoding the true next state as local targets and decoding them with the true next
    /// frames gives the next state back exactly (up to rounding).
    #[test]
    fn local_transforms_invert_exactly() {
        let d = Dolphin::default();
        let (x0, u) = swim_state(&d, 0.7);
        let mut x1 = x0.clone();
        let mut sim = simulator(&d);
        for _ in 0..50 {
            sim.step(&mut x1, &u, 0.002);
        }
        let mut rebuilt = vec![f64::NAN; MASS_DIM];
        for s in 0..N_SEGMENTS {
            let l = LocalLayout::new(s);
            let f0 = Frame::from_segment(&d.segment_frame(&x0, s));
            let f1 = Frame::from_segment(&d.segment_frame(&x1, s));
            let mut y = vec![0.0; l.n_out()];
            l.target(&x0, &f0, &x1, &f1, &mut y);
            l.decode(&x0, &f0, &f1, &y, &mut rebuilt);
        }
        for (a, b) in rebuilt.iter().zip(&x1) {
            assert!((a - b).abs() < 1e-12, "{a} vs {b}");
        }
    }

    /// The global state is invariant in the frame of the reference segment: rotating and
    /// translating the whole body leaves the global net's encoded input unchanged.
    #[test]
    fn global_encoding_is_invariant_to_rigid_motion() {
        let d = Dolphin::default();
        let (x, u) = swim_state(&d, 0.5);
        let r = UnitQuaternion::from_euler_angles(0.3, -0.2, 1.1);
        let t = Vector3::new(3.0, -1.0, 2.0);
        let mut y = x.clone();
        for i in 0..N_MASSES {
            put(&mut y[..N_POS], i, &(t + r * point(&x[..N_POS], i)));
            put(&mut y[N_POS..], i, &(r * point(&x[N_POS..], i)));
        }
        let tf = Transforms::unfitted(&global_transforms(), GLOBAL_DIM, N_SEGMENTS).unwrap();
        let (mut gx, mut gy) = (vec![0.0; GLOBAL_DIM], vec![0.0; GLOBAL_DIM]);
        global_state(&d, &x, &mut gx);
        global_state(&d, &y, &mut gy);
        let (mut zx, mut zy) = (vec![0.0; GLOBAL_DIM + 6], vec![0.0; GLOBAL_DIM + 6]);
        tf.encode_input(&gx, &u, &mut zx);
        tf.encode_input(&gy, &u, &mut zy);
        for k in 0..GLOBAL_DIM + 6 {
            // Signs follow the reference segment, so even the quaternions agree exactly.
            assert!(
                (zx[k] - zy[k]).abs() < 1e-9,
                "input {k}: {} vs {}",
                zx[k],
                zy[k]
            );
        }
    }

    /// A random global net and six random local nets with made-up normalizations.
    fn random_nets(seed: u64) -> (Emulator, Vec<LocalNet>) {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let tf = Transforms::unfitted(&global_transforms(), GLOBAL_DIM, N_SEGMENTS).unwrap();
        let gmlp = Mlp::new(GLOBAL_DIM + 6, 7, GLOBAL_DIM, WeightInit::FanIn, &mut rng);
        let global = Emulator::new(tf, gmlp, 0.1).unwrap();
        let locals = (0..N_SEGMENTS)
            .map(|s| {
                let layout = LocalLayout::new(s);
                let mlp = Mlp::new(
                    layout.n_in(),
                    5,
                    layout.n_out(),
                    WeightInit::FanIn,
                    &mut rng,
                );
                let input_norm = Normalizer {
                    mean: (0..layout.n_in()).map(|k| 0.01 * k as f64).collect(),
                    std: vec![2.0; layout.n_in()],
                };
                let output_norm = Normalizer {
                    mean: vec![0.001; layout.n_out()],
                    std: vec![0.05; layout.n_out()],
                };
                LocalNet {
                    layout,
                    mlp,
                    input_norm,
                    output_norm,
                }
            })
            .collect();
        (global, locals)
    }

    /// Along a rollout the composed hierarchy carries the global net's own frames: its steps
    /// (through `Dynamics::step` and `emulate`) are the local nets placed between consecutive
    /// states of the global net's rollout alone, from the frames fitted to the start; a state
    /// the emulator did not produce starts again from its own fitted frames.
    #[test]
    fn the_composed_hierarchy_carries_the_global_nets_rollout() {
        let d = Dolphin::default();
        let (global, locals) = random_nets(6);
        let mut emu = DolphinEmulator::new(d.clone(), global.clone(), locals);
        let (x0, u) = swim_state(&d, 0.4);
        let mut sc = emu.scratch();
        // By hand: the global net's rollout, and the masses placed along it.
        let mut g = vec![0.0; GLOBAL_DIM];
        global_state(&d, &x0, &mut g);
        let (mut x, mut g1, mut x1) = (x0.clone(), vec![0.0; GLOBAL_DIM], vec![0.0; MASS_DIM]);
        let mut by_hand = Vec::new();
        for _ in 0..3 {
            let mut g_alone = vec![0.0; GLOBAL_DIM];
            global.predict(&g, &u, &mut global.scratch(), &mut g_alone);
            emu.predict_carried(&x, &g, &u, &mut sc, &mut x1, &mut g1);
            assert_eq!(
                g1, g_alone,
                "the carried frames are the global net's own rollout"
            );
            (x, g) = (x1.clone(), g1.clone());
            by_hand.push(x.clone());
        }
        // The first carried step is `predict` (frames fitted to the start).
        let mut first = vec![0.0; MASS_DIM];
        emu.predict(&x0, &u, &mut sc, &mut first);
        assert_eq!(first, by_hand[0]);
        // `Dynamics::step` continues the carried frames along its own rollout.
        let mut xs = x0.clone();
        for expect in &by_hand {
            emu.step(&mut xs, &u, 0.1);
            assert_eq!(&xs, expect);
        }
        // ... and so does `emulate`, without regularization.
        let controls: Vec<f64> = u.iter().cycle().take(3 * N_SEGMENTS).copied().collect();
        let mut reg = Regularizer {
            dt: 0.001,
            stiffness_scale: 1.0,
            damping_scale: 1.0,
        }
        .bind(&d)
        .unwrap();
        let none = Schedule { steps: 0, every: 1 };
        let mut seen = Vec::new();
        let end = emu.emulate(&mut reg, none, &x0, &controls, &mut sc, |_, x| {
            seen.push(x.to_vec())
        });
        assert_eq!(seen, by_hand);
        assert_eq!(end, by_hand[2]);
        // A state it did not produce is stepped from its own fitted frames.
        let mut other = by_hand[0].clone();
        other[0] += 1e-3;
        let mut fresh = vec![0.0; MASS_DIM];
        emu.predict(&other, &u, &mut sc, &mut fresh);
        emu.step(&mut other, &u, 0.1);
        assert_eq!(other, fresh);
        // Carrying matters: the second carried step differs from one refitted to the masses.
        let mut refit = vec![0.0; MASS_DIM];
        emu.predict(&by_hand[0], &u, &mut sc, &mut refit);
        assert_ne!(refit, by_hand[1]);
    }

    /// The composed step equals running its parts by hand: frames, global net, local nets.
    #[test]
    fn hierarchical_emulator_equals_its_parts() {
        let d = Dolphin::default();
        let (global, locals) = random_nets(5);
        let mut emu = DolphinEmulator::new(d.clone(), global.clone(), locals.clone());
        let (x, u) = swim_state(&d, 0.4);
        // By hand.
        let mut g0 = vec![0.0; GLOBAL_DIM];
        global_state(&d, &x, &mut g0);
        let mut g1 = vec![0.0; GLOBAL_DIM];
        global.predict(&g0, &u, &mut global.scratch(), &mut g1);
        let mut expect = vec![f64::NAN; MASS_DIM];
        for (s, l) in locals.iter().enumerate() {
            let f0 = Frame::from_segment(&d.segment_frame(&x, s));
            let q = &g1[13 * s + 3..13 * s + 7];
            let n = q.iter().map(|a| a * a).sum::<f64>().sqrt();
            let f1 = Frame {
                c: Vector3::new(g1[13 * s], g1[13 * s + 1], g1[13 * s + 2]),
                r: UnitQuaternion::new_unchecked(Quaternion::new(
                    q[0] / n,
                    q[1] / n,
                    q[2] / n,
                    q[3] / n,
                )),
                v: Vector3::new(g1[13 * s + 7], g1[13 * s + 8], g1[13 * s + 9]),
                w: Vector3::new(g1[13 * s + 10], g1[13 * s + 11], g1[13 * s + 12]),
            };
            let mut z = vec![0.0; l.layout.n_in()];
            l.layout.input(&x, &f0, &f1, &u, &mut z);
            let zn: Vec<f64> = z
                .iter()
                .enumerate()
                .map(|(k, v)| (v - l.input_norm.mean[k]) / l.input_norm.std[k])
                .collect();
            let mut y = vec![0.0; l.layout.n_out()];
            l.mlp.forward(&zn, &mut l.mlp.scratch(), &mut y);
            let raw: Vec<f64> = y
                .iter()
                .enumerate()
                .map(|(k, v)| v * l.output_norm.std[k] + l.output_norm.mean[k])
                .collect();
            l.layout.decode(&x, &f0, &f1, &raw, &mut expect);
        }
        let mut got = x.clone();
        emu.step(&mut got, &u, 0.1);
        assert!(expect.iter().all(|v| v.is_finite()), "every mass written");
        for (a, b) in got.iter().zip(&expect) {
            assert!((a - b).abs() <= 1e-12 * (1.0 + b.abs()), "{a} vs {b}");
        }
        // The global part of the step is the global net's prediction.
        let mut g_got = vec![0.0; GLOBAL_DIM];
        global_state(&d, &got, &mut g_got);
        assert!(g_got.iter().all(|v| v.is_finite()));
    }
}
