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
//! ([`global_state`]). It is an ordinary [`Emulator`] with the standard transforms: the state
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
//! and outputs are normalized per variable. The segment sizes differ (the nose segment owns 5
//! masses, the fluke 2), so the local nets differ slightly in shape; the paper's Table 1 gives
//! one representative.
//!
//! [`DolphinEmulator`] composes them into one step of the 138-variable mass state: frames of
//! the current state → global net → each local net → world positions and velocities
//! p′ᵢ = c₁ + R₁(local), v′ᵢ = v₁ + R₁(local). During training each local net is given the
//! true next frame (teacher forcing); at run time the predicted one.
//!
//! ## Regularization (§5.3)
//! [`Regularizer`] performs spring-only Euler steps v ← v + δt a(x, v, u), x ← x + δt (v − v̄)
//! (§5.3's step, with v̄ the centre-of-mass velocity taken out of the position update so that
//! regularizing deforms the body without advancing its flight, i.e. animation time), with
//! softer springs and more damping than the simulator, and no hydrodynamics. A [`Schedule`] says how many such steps follow which emulation steps.
//!
//! ## Training data (§3.4)
//! Episodes of 20 s from the rest shape at a random position, heading, pitch and roll, swimming
//! at U[−0.5, 1] m/s along its axis, driven by travelling muscle waves of random frequency, lag, amplitude and
//! direction held piecewise constant ([`ControlProcess::TravellingWave`]); samples at lags
//! U[Δt, 5Δt]. Sampling runs in parallel chunks, each from its own seeded stream, so the data
//! do not depend on the thread count. The local nets use the first `local.examples` of the
//! global net's examples.

use super::cache::{fnv1a, read_record, write_record, EmulatorCache, NetRecord};
use super::catalog::{stop_name, train_mlp, BuildError, TrainMethod, TrainSettings};
use super::dataset::{sample_transitions, ControlLimits, ControlProcess, SamplingConfig};
use super::mlp::{Mlp, MlpScratch, WeightInit};
use super::train::{mse, Dataset, TracePoint};
use super::transform::{Normalizer, SpatialFrame};
use super::{Emulator, EmulatorScratch, TransformConfig, Transforms, Transitions};
use crate::physics::dolphin::{
    segment_frame_masses, segment_of_mass, Dolphin, DolphinParams, SegmentFrame, N_MASSES, N_POS,
    N_SEGMENTS,
};
use crate::physics::{Dynamics, IntegratorKind, Ode, Simulator};
use nalgebra::{Quaternion, UnitQuaternion, Vector3};
use ndarray::{s, Array2};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::f64::consts::PI;
use std::path::PathBuf;
use std::time::Instant;

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
pub const HIERARCHY_FORMAT: u32 = 2;
/// Examples per sampling chunk (each chunk is simulated from its own seeded stream).
const CHUNK: usize = 2000;

/// Writes the global state (6 segment frames, 13 numbers each) of the mass state `x`.
pub fn global_state(d: &Dolphin, x: &[f64], out: &mut [f64]) {
    for s in 0..N_SEGMENTS {
        out[FRAME_DIM * s..FRAME_DIM * (s + 1)].copy_from_slice(&d.segment_frame(x, s).to_array());
    }
}

/// The transforms of the global net: state change, the frame of [`REF_SEGMENT`] for every
/// centroid, quaternion, velocity and angular velocity, and per-variable normalization.
pub fn global_transforms() -> TransformConfig {
    let base = FRAME_DIM * REF_SEGMENT;
    let tri = |a: usize| [a, a + 1, a + 2];
    let frame = SpatialFrame {
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
    TransformConfig::standard(Some(frame.into()))
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

    /// Writes the next mass state: frames of `x` → global net → local nets.
    pub fn predict(&self, x: &[f64], u: &[f64], sc: &mut DolphinScratch, x1: &mut [f64]) {
        let frames = self.dolphin.segment_frames(x);
        for (s, f) in frames.iter().enumerate() {
            sc.g0[FRAME_DIM * s..FRAME_DIM * (s + 1)].copy_from_slice(&f.to_array());
        }
        self.global.predict(&sc.g0, u, &mut sc.global, &mut sc.g1);
        for (s, net) in self.locals.iter().enumerate() {
            let f0 = Frame::from_segment(&frames[s]);
            let f1 = Frame::from_slice(&sc.g1[FRAME_DIM * s..FRAME_DIM * (s + 1)]);
            net.apply(x, &f0, &f1, u, &mut sc.local[s], x1);
        }
    }
}

impl DolphinEmulator {
    /// Emulates from `x0` under per-step `controls` (m each), following each emulation step
    /// with `schedule`'s regularization steps of `reg` when due, and calls `visit(k, x)` with
    /// the state after step k = 1, 2, …. Returns the final state.
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
        for (k, u) in controls.chunks_exact(N_SEGMENTS).enumerate() {
            self.predict(&x, u, scratch, &mut y);
            std::mem::swap(&mut x, &mut y);
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

    /// One super timestep.
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
        self.predict(x, u, &mut sc, &mut next);
        x.copy_from_slice(&next);
        sc.next = next;
        self.scratch = Some(sc);
    }
}

/// Regularization steps of §5.3 (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Regularizer {
    /// Step δt (s).
    pub dt: f64,
    /// Spring stiffness relative to the simulator's.
    pub stiffness_scale: f64,
    /// Spring damping relative to the simulator's.
    pub damping_scale: f64,
}

/// A [`Regularizer`] bound to a dolphin: its softened, drag-free body.
#[derive(Debug, Clone)]
pub struct BoundRegularizer {
    soft: Dolphin,
    dt: f64,
    dx: Vec<f64>,
}

impl Regularizer {
    /// The softened body of `d` (no drag, no gravity) that the steps use.
    pub fn bind(
        &self,
        d: &Dolphin,
    ) -> Result<BoundRegularizer, crate::physics::dolphin::DolphinError> {
        let mut p: DolphinParams = d.params().clone();
        p.stiffness *= self.stiffness_scale;
        p.muscle_stiffness *= self.stiffness_scale;
        p.damping *= self.damping_scale;
        p.drag = 0.0;
        p.gravity = 0.0;
        Ok(BoundRegularizer {
            soft: Dolphin::new(p)?,
            dt: self.dt,
            dx: vec![0.0; MASS_DIM],
        })
    }
}

impl BoundRegularizer {
    /// Applies `steps` spring-only Euler steps to the mass state `x` under muscle controls `u`.
    pub fn apply(&mut self, x: &mut [f64], u: &[f64], steps: usize) {
        let h = self.dt;
        for _ in 0..steps {
            self.soft.derivative(x, u, &mut self.dx);
            let (q, v) = x.split_at_mut(N_POS);
            for (vk, ak) in v.iter_mut().zip(&self.dx[N_POS..]) {
                *vk += h * ak;
            }
            // Internal forces leave the centre-of-mass velocity unchanged; moving by the
            // velocity relative to it deforms the body without advancing its flight.
            let masses = self.soft.masses();
            let mut vc = [0.0; 3];
            for (i, m) in masses.iter().enumerate() {
                for a in 0..3 {
                    vc[a] += m * v[3 * i + a];
                }
            }
            let total = self.soft.total_mass();
            vc.iter_mut().for_each(|c| *c /= total);
            for i in 0..N_MASSES {
                for a in 0..3 {
                    q[3 * i + a] += h * (v[3 * i + a] - vc[a]);
                }
            }
        }
    }
}

/// When to regularize: `steps` regularization steps after every `every`-th emulation step.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Schedule {
    /// Regularization steps each time.
    pub steps: usize,
    /// Emulation steps between regularizations (1 = after each).
    pub every: usize,
}

impl Schedule {
    /// Whether to regularize after emulation step `k` (1-based count of steps taken).
    pub fn due(&self, k: usize) -> bool {
        self.steps > 0 && self.every > 0 && k.is_multiple_of(self.every)
    }
}

/// Size and data of one net of the hierarchy.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct HierarchyNet {
    /// Hidden units.
    pub hidden: usize,
    /// Training examples.
    pub examples: usize,
    /// How to train.
    pub method: TrainMethod,
}

/// Everything that determines the trained dolphin hierarchy.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct HierarchySpec {
    /// The global net (Table 1: 50 hidden, 64,000 examples).
    pub global: HierarchyNet,
    /// Each local net (Table 1: 40 hidden, 32,000 examples).
    pub local: HierarchyNet,
    /// Physical step δt of the simulator (s).
    pub physical_dt: f64,
    /// Physical steps per emulator step n.
    pub steps: usize,
    /// Training settings.
    pub settings: TrainSettings,
    /// Seed of sampling, initialization and shuffles.
    pub seed: u64,
}

impl HierarchySpec {
    /// Super timestep Δt = n δt (s).
    pub fn super_dt(&self) -> f64 {
        self.steps as f64 * self.physical_dt
    }

    fn held_out(&self) -> usize {
        ((self.global.examples as f64 * self.settings.held_out_fraction).round() as usize).max(2)
    }
}

/// Muscle activations: [−1, 1] each.
pub fn control_limits() -> ControlLimits {
    ControlLimits::symmetric(&[1.0; N_SEGMENTS])
}

/// The typical controls of §3.4 for the dolphin: travelling waves of 0.3–1.5 Hz, up to 60° of
/// lag per segment either way, held for 0.1–0.4 s, with 20% knot noise.
pub fn control_process() -> ControlProcess {
    ControlProcess::TravellingWave {
        hold_min: 0.1,
        hold_max: 0.4,
        freq_min: 0.3,
        freq_max: 1.5,
        lag_max: 60f64.to_radians(),
        noise: 0.2,
    }
}

/// Episode length of the sampling runs (s).
pub const EPISODE_S: f64 = 20.0;

/// An episode start: the rest shape at a random position (±20 m), heading, pitch (±0.5 rad)
/// and roll (±0.3 rad), moving along its axis at U[−0.5, 1] m/s.
pub fn start_state(d: &Dolphin, rng: &mut ChaCha8Rng) -> Vec<f64> {
    let yaw = rng.random_range(-PI..PI);
    let pitch = rng.random_range(-0.5..0.5);
    let roll = rng.random_range(-0.3..0.3);
    let r = UnitQuaternion::from_euler_angles(roll, pitch, yaw);
    let t = Vector3::new(
        rng.random_range(-20.0..20.0),
        rng.random_range(-20.0..20.0),
        rng.random_range(-20.0..20.0),
    );
    let speed = rng.random_range(-0.5..1.0);
    let v = r * Vector3::new(speed, 0.0, 0.0);
    let rest = d.rest_state();
    let mut x = vec![0.0; MASS_DIM];
    for i in 0..N_MASSES {
        put(&mut x[..N_POS], i, &(t + r * point(&rest, i)));
        put(&mut x[N_POS..], i, &v);
    }
    x
}

/// The dolphin's physical simulator: semi-implicit Euler.
pub fn simulator(d: &Dolphin) -> Simulator<Dolphin> {
    Simulator::new(d.clone(), IntegratorKind::SemiImplicitEuler)
}

/// Samples `examples` transitions of the mass state over `steps` physical steps of `dt`, in
/// parallel chunks seeded from `seed` (independent of the thread count).
pub fn sample_dolphin(
    d: &Dolphin,
    dt: f64,
    steps: usize,
    examples: usize,
    seed: u64,
) -> Result<Transitions, BuildError> {
    let chunks: Vec<usize> = (0..examples.div_ceil(CHUNK))
        .map(|k| CHUNK.min(examples - k * CHUNK))
        .collect();
    let cfg = |n: usize| SamplingConfig {
        dt,
        steps_per_sample: steps,
        examples: n,
        episode_duration: EPISODE_S.max(6.0 * steps as f64 * dt),
        control: control_process(),
    };
    let parts: Vec<Transitions> = chunks
        .par_iter()
        .enumerate()
        .map(|(k, &n)| {
            let mut sim = simulator(d);
            let mut rng = ChaCha8Rng::seed_from_u64(crate::experiment::mix_seed(seed, k as u64));
            let start = |r: &mut ChaCha8Rng| start_state(d, r);
            sample_transitions(&mut sim, &start, &control_limits(), &cfg(n), &mut rng)
                .map(|s| s.transitions)
        })
        .collect::<Result<_, _>>()?;
    let cat = |f: fn(&Transitions) -> &Array2<f64>| -> Array2<f64> {
        let views: Vec<_> = parts.iter().map(|p| f(p).view()).collect();
        ndarray::concatenate(ndarray::Axis(0), &views).expect("equal widths")
    };
    Ok(Transitions::new(
        cat(|t| &t.states),
        cat(|t| &t.controls),
        cat(|t| &t.next_states),
    )?)
}

/// The global-state transitions of mass-state transitions.
pub fn global_transitions(d: &Dolphin, data: &Transitions) -> Transitions {
    let rows = data.len();
    let mut g0 = Array2::zeros((rows, GLOBAL_DIM));
    let mut g1 = Array2::zeros((rows, GLOBAL_DIM));
    let mut buf = vec![0.0; GLOBAL_DIM];
    for r in 0..rows {
        global_state(
            d,
            data.states.row(r).as_slice().expect("standard layout"),
            &mut buf,
        );
        g0.row_mut(r).assign(&ndarray::ArrayView1::from(&buf));
        global_state(
            d,
            data.next_states.row(r).as_slice().expect("standard layout"),
            &mut buf,
        );
        g1.row_mut(r).assign(&ndarray::ArrayView1::from(&buf));
    }
    Transitions::new(g0, data.controls.clone(), g1).expect("rows agree")
}

/// Raw (input, target) rows of segment `layout` for the first `rows` transitions, with the
/// true next frame as the parent input.
fn local_raw(
    d: &Dolphin,
    layout: &LocalLayout,
    data: &Transitions,
    rows: usize,
) -> (Array2<f64>, Array2<f64>) {
    let rows = rows.min(data.len());
    let mut inp = Array2::zeros((rows, layout.n_in()));
    let mut out = Array2::zeros((rows, layout.n_out()));
    let (mut z, mut y) = (vec![0.0; layout.n_in()], vec![0.0; layout.n_out()]);
    for r in 0..rows {
        let x0 = data.states.row(r);
        let x1 = data.next_states.row(r);
        let (x0, x1) = (
            x0.as_slice().expect("layout"),
            x1.as_slice().expect("layout"),
        );
        let f0 = Frame::from_segment(&d.segment_frame(x0, layout.segment));
        let f1 = Frame::from_segment(&d.segment_frame(x1, layout.segment));
        let u = data.controls.row(r);
        layout.input(x0, &f0, &f1, u.as_slice().expect("layout"), &mut z);
        layout.target(x0, &f0, x1, &f1, &mut y);
        inp.row_mut(r).assign(&ndarray::ArrayView1::from(&z));
        out.row_mut(r).assign(&ndarray::ArrayView1::from(&y));
    }
    (inp, out)
}

fn normalized(norm: &Normalizer, raw: &Array2<f64>) -> Array2<f64> {
    let mut out = raw.clone();
    let mut buf = vec![0.0; raw.ncols()];
    for (mut o, r) in out.rows_mut().into_iter().zip(raw.rows()) {
        norm.normalize(r.as_slice().expect("layout"), &mut buf);
        o.assign(&ndarray::ArrayView1::from(&buf));
    }
    out
}

/// Training record of one net of the hierarchy (a Table 1 row).
#[derive(Debug, Clone, PartialEq)]
pub struct NetReport {
    /// `dolphin_global` or `dolphin_local1` … `dolphin_local6`.
    pub name: String,
    /// Network inputs.
    pub inputs: usize,
    /// Hidden units.
    pub hidden: usize,
    /// Network outputs.
    pub outputs: usize,
    /// Training examples.
    pub examples: usize,
    /// Training MSE per output (normalized space).
    pub train_error: f64,
    /// Held-out MSE per output (normalized space).
    pub heldout_error: f64,
    /// Wall time of its training (the shared sampling time is added to the global net) (s).
    pub train_s: f64,
    /// Why training stopped.
    pub stop: String,
    /// Whether it came from the cache.
    pub from_cache: bool,
    /// Training trace.
    pub trace: Vec<TracePoint>,
}

/// The trained hierarchy with a record per net.
#[derive(Debug, Clone)]
pub struct BuiltDolphin {
    /// The composed emulator.
    pub emulator: DolphinEmulator,
    /// Global net first, then the six local nets.
    pub nets: Vec<NetReport>,
}

/// Name of net `k` of the hierarchy (0 = global, 1..=6 local).
pub fn net_name(k: usize) -> String {
    if k == 0 {
        "dolphin_global".into()
    } else {
        format!("dolphin_local{k}")
    }
}

fn cache_key(spec: &HierarchySpec, d: &Dolphin, k: usize) -> String {
    let mut rng = ChaCha8Rng::seed_from_u64(0);
    let starts: Vec<Vec<f64>> = (0..2).map(|_| start_state(d, &mut rng)).collect();
    serde_json::json!({
        "format": super::cache::CACHE_FORMAT,
        "hierarchy_format": HIERARCHY_FORMAT,
        "hierarchy": spec,
        "net": net_name(k),
        "physics": d,
        "recipe": {
            "process": control_process(),
            "episode": EPISODE_S,
            "chunk": CHUNK,
            "transforms": format!("{:?}", global_transforms()),
            "starts": starts,
        },
    })
    .to_string()
}

fn cache_path(cache: &EmulatorCache, spec: &HierarchySpec, key: &str, k: usize) -> PathBuf {
    cache.dir.join(format!(
        "{}-n{}-{:016x}.json",
        net_name(k),
        spec.steps,
        fnv1a(key.as_bytes())
    ))
}

fn shape(spec: &HierarchySpec, k: usize) -> [usize; 3] {
    if k == 0 {
        [GLOBAL_DIM + N_SEGMENTS, spec.global.hidden, GLOBAL_DIM]
    } else {
        let l = LocalLayout::new(k - 1);
        [l.n_in(), spec.local.hidden, l.n_out()]
    }
}

fn assemble(
    d: &Dolphin,
    spec: &HierarchySpec,
    recs: Vec<NetRecord>,
) -> Result<DolphinEmulator, BuildError> {
    let mut it = recs.into_iter();
    let g = it.next().expect("seven records");
    let mut t = Transforms::unfitted(&global_transforms(), GLOBAL_DIM, N_SEGMENTS)?;
    t.input_norm = g.input_norm;
    t.output_norm = g.output_norm;
    let global = Emulator::new(t, g.mlp, spec.super_dt())?;
    let locals = it
        .enumerate()
        .map(|(s, r)| LocalNet {
            layout: LocalLayout::new(s),
            mlp: r.mlp,
            input_norm: r.input_norm,
            output_norm: r.output_norm,
        })
        .collect();
    Ok(DolphinEmulator::new(d.clone(), global, locals))
}

fn report(k: usize, spec: &HierarchySpec, r: &NetRecord, from_cache: bool) -> NetReport {
    let [inputs, hidden, outputs] = shape(spec, k);
    NetReport {
        name: net_name(k),
        inputs,
        hidden,
        outputs,
        examples: if k == 0 {
            spec.global.examples
        } else {
            spec.local.examples.min(spec.global.examples)
        },
        train_error: r.train_error,
        heldout_error: r.heldout_error,
        train_s: r.train_s,
        stop: r.stop.clone(),
        from_cache,
        trace: r.trace.clone(),
    }
}

/// The trained hierarchy of `spec` for the default dolphin, from `cache` when all seven nets
/// are there, else sampled and trained now (and stored).
pub fn build_dolphin(
    spec: &HierarchySpec,
    cache: &EmulatorCache,
) -> Result<BuiltDolphin, BuildError> {
    let d = Dolphin::default();
    let keys: Vec<String> = (0..=N_SEGMENTS).map(|k| cache_key(spec, &d, k)).collect();
    let cached: Option<Vec<NetRecord>> = (0..=N_SEGMENTS)
        .map(|k| {
            read_record(
                &cache_path(cache, spec, &keys[k], k),
                &keys[k],
                shape(spec, k),
            )
        })
        .collect();
    if let Some(recs) = cached {
        let nets = recs
            .iter()
            .enumerate()
            .map(|(k, r)| report(k, spec, r, true))
            .collect();
        return Ok(BuiltDolphin {
            emulator: assemble(&d, spec, recs)?,
            nets,
        });
    }
    let recs = train_hierarchy(&d, spec)?;
    for (k, r) in recs.iter().enumerate() {
        write_record(&cache_path(cache, spec, &keys[k], k), &keys[k], r)?;
    }
    let nets = recs
        .iter()
        .enumerate()
        .map(|(k, r)| report(k, spec, r, false))
        .collect();
    Ok(BuiltDolphin {
        emulator: assemble(&d, spec, recs)?,
        nets,
    })
}

/// Samples the data and trains the global net and the six local nets (in parallel).
pub fn train_hierarchy(d: &Dolphin, spec: &HierarchySpec) -> Result<Vec<NetRecord>, BuildError> {
    let t0 = Instant::now();
    let mix = |k: u64| crate::experiment::mix_seed(spec.seed, k);
    let train = sample_dolphin(
        d,
        spec.physical_dt,
        spec.steps,
        spec.global.examples,
        mix(1),
    )?;
    let held = sample_dolphin(d, spec.physical_dt, spec.steps, spec.held_out(), mix(2))?;
    let sampling_s = t0.elapsed().as_secs_f64();
    let s = &spec.settings;
    let jobs: Vec<usize> = (0..=N_SEGMENTS).collect();
    let recs: Vec<NetRecord> = jobs
        .par_iter()
        .map(|&k| -> Result<NetRecord, BuildError> {
            let t1 = Instant::now();
            let mut rng = ChaCha8Rng::seed_from_u64(mix(10 + k as u64));
            if k == 0 {
                let (gt, gh) = (global_transitions(d, &train), global_transitions(d, &held));
                let transforms = Transforms::fit(&global_transforms(), &gt)?;
                let (tr, ho) = (transforms.encode(&gt), transforms.encode(&gh));
                let mut mlp = Mlp::new(
                    GLOBAL_DIM + N_SEGMENTS,
                    spec.global.hidden,
                    GLOBAL_DIM,
                    WeightInit::FanIn,
                    &mut rng,
                );
                let rep = train_mlp(&mut mlp, &tr, &ho, spec.global.method, s, mix(20))?;
                Ok(NetRecord {
                    train_error: mse(&mlp, &tr),
                    heldout_error: mse(&mlp, &ho),
                    mlp,
                    input_norm: transforms.input_norm,
                    output_norm: transforms.output_norm,
                    dt: spec.super_dt(),
                    train_s: sampling_s + t1.elapsed().as_secs_f64(),
                    stop: stop_name(&rep.stop),
                    trace: rep.trace,
                })
            } else {
                let layout = LocalLayout::new(k - 1);
                let rows = spec.local.examples;
                let held_rows = ((rows as f64 * s.held_out_fraction).round() as usize).max(2);
                let (ti, tt) = local_raw(d, &layout, &train, rows);
                let (hi, ht) = local_raw(d, &layout, &held, held_rows);
                let in_norm = Normalizer::fit(ti.view(), &(0..layout.n_in()).collect::<Vec<_>>())?;
                let out_norm =
                    Normalizer::fit(tt.view(), &(0..layout.n_out()).collect::<Vec<_>>())?;
                let tr = Dataset::new(normalized(&in_norm, &ti), normalized(&out_norm, &tt))?;
                let ho = Dataset::new(normalized(&in_norm, &hi), normalized(&out_norm, &ht))?;
                let mut mlp = Mlp::new(
                    layout.n_in(),
                    spec.local.hidden,
                    layout.n_out(),
                    WeightInit::FanIn,
                    &mut rng,
                );
                let rep = train_mlp(&mut mlp, &tr, &ho, spec.local.method, s, mix(20 + k as u64))?;
                Ok(NetRecord {
                    train_error: mse(&mlp, &tr),
                    heldout_error: mse(&mlp, &ho),
                    mlp,
                    input_norm: in_norm,
                    output_norm: out_norm,
                    dt: spec.super_dt(),
                    train_s: t1.elapsed().as_secs_f64(),
                    stop: stop_name(&rep.stop),
                    trace: rep.trace,
                })
            }
        })
        .collect::<Result<_, _>>()?;
    Ok(recs)
}

/// The `rows`-row slice of a transitions table (for tests and small experiments).
pub fn head(data: &Transitions, rows: usize) -> Transitions {
    let r = rows.min(data.len());
    Transitions::new(
        data.states.slice(s![..r, ..]).to_owned(),
        data.controls.slice(s![..r, ..]).to_owned(),
        data.next_states.slice(s![..r, ..]).to_owned(),
    )
    .expect("rows agree")
}

#[cfg(test)]
mod tests {
    use super::*;

    fn spec(examples: usize) -> HierarchySpec {
        HierarchySpec {
            global: HierarchyNet {
                hidden: 8,
                examples,
                method: TrainMethod::Lbfgs,
            },
            local: HierarchyNet {
                hidden: 6,
                examples: examples / 2,
                method: TrainMethod::Lbfgs,
            },
            physical_dt: 0.002,
            steps: 10,
            settings: TrainSettings {
                held_out_fraction: 0.25,
                cg_max_iters: 5,
                max_epochs: 2,
                patience: 3,
                min_improvement: 0.001,
                learning_rate: 0.05,
                momentum: 0.9,
                batch_size: 30,
            },
            seed: 3,
        }
    }

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
            // Quaternions are defined up to sign: compare the relative ones' absolute values.
            assert!(
                (zx[k].abs() - zy[k].abs()).abs() < 1e-9,
                "input {k}: {} vs {}",
                zx[k],
                zy[k]
            );
        }
    }

    /// The composed step equals running its parts by hand: frames, global net, local nets.
    #[test]
    fn hierarchical_emulator_equals_its_parts() {
        let d = Dolphin::default();
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let tf = Transforms::unfitted(&global_transforms(), GLOBAL_DIM, N_SEGMENTS).unwrap();
        let gmlp = Mlp::new(GLOBAL_DIM + 6, 7, GLOBAL_DIM, WeightInit::FanIn, &mut rng);
        let global = Emulator::new(tf, gmlp, 0.1).unwrap();
        let locals: Vec<LocalNet> = (0..N_SEGMENTS)
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

    /// Regularization pulls a distorted body back toward its rest lengths without moving its
    /// centre of mass, and the schedule fires when due.
    #[test]
    fn regularizer_reduces_shape_error() {
        let d = Dolphin::default();
        let mut x = d.rest_state();
        let mut rng = ChaCha8Rng::seed_from_u64(9);
        for q in x[..N_POS].iter_mut() {
            *q += rng.random_range(-0.03..0.03);
        }
        let e0 = d.shape_error(&x);
        let c0 = d.centre_of_mass(&x);
        let mut reg = Regularizer {
            dt: 0.005,
            stiffness_scale: 0.1,
            damping_scale: 1.5,
        }
        .bind(&d)
        .unwrap();
        reg.apply(&mut x, &[0.0; 6], 30);
        assert!(
            d.shape_error(&x) < 0.7 * e0,
            "{} vs {e0}",
            d.shape_error(&x)
        );
        assert!((d.centre_of_mass(&x) - c0).norm() < 1e-9);
        let s = Schedule {
            steps: 25,
            every: 5,
        };
        assert!(!s.due(4) && s.due(5) && s.due(10));
        assert!(!Schedule { steps: 0, every: 1 }.due(1));
    }

    /// A tiny hierarchy trains end to end, deterministically, and round-trips the cache.
    #[test]
    fn tiny_hierarchy_trains_and_caches() {
        let dir = tempfile::tempdir().unwrap();
        let cache = EmulatorCache::new(dir.path());
        let sp = spec(60);
        let a = build_dolphin(&sp, &cache).unwrap();
        assert_eq!(a.nets.len(), 7);
        assert!(a
            .nets
            .iter()
            .all(|n| !n.from_cache && n.heldout_error.is_finite()));
        let b = build_dolphin(&sp, &cache).unwrap();
        assert!(b.nets.iter().all(|n| n.from_cache));
        let d = Dolphin::default();
        let x = start_state(&d, &mut ChaCha8Rng::seed_from_u64(1));
        let u = [0.3; 6];
        let (mut xa, mut xb) = (x.clone(), x.clone());
        let (mut ea, mut eb) = (a.emulator.clone(), b.emulator.clone());
        ea.step(&mut xa, &u, sp.super_dt());
        eb.step(&mut xb, &u, sp.super_dt());
        assert_eq!(xa, xb, "a cached hierarchy is bit-identical");
        assert!(xa.iter().all(|v| v.is_finite()));
    }
}
