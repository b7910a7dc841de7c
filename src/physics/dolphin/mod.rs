//! # Dolphin: a muscle-driven mass-spring-damper swimmer (NeuroAnimator, Fig. 7, Fig. 13d)
//!
//! The deformable dolphin of NeuroAnimator (Grzeszczuk, Terzopoulos & Hinton 1998, §3.3),
//! built the way Tu & Terzopoulos built their artificial fishes: point masses joined by
//! spring-dampers, muscles that change spring rest lengths, and hydrodynamic forces on the
//! surface faces that turn undulation into propulsion.
//!
//! ## Layout
//! 23 point masses at 7 *stations* along the body axis (x forward, y left, z up/dorsal):
//! the nose (mass 0); five cross-section *rings* of 4 masses each, top (+z), left (+y),
//! bottom (−z), right (−y), ring r ∈ 1..=5 holding masses 4r−3 ..= 4r; and a horizontal
//! tail fluke of two tips, left (21) and right (22). The state is `[positions (69),
//! velocities (69)]`, mass i at indices 3i..3i+3 of each half.
//!
//! The **6 segments** lie between consecutive stations (nose–ring 1, ring 1–2, …, ring 5–fluke).
//! [`segment_of_mass`] partitions the masses (segment 0 owns the nose and ring 1, segment s ≥ 1
//! owns station s + 1); a segment's rigid frame ([`Dolphin::segment_frame`]) is fitted to the
//! masses of both of its stations ([`segment_frame_masses`]).
//!
//! **91 springs**: around each ring (4) and across it (2 diameters); 4 from the nose to ring 1;
//! between consecutive rings 4 longitudinal springs plus the 2 diagonals of each of the 4 side
//! quads (12 per ring pair, so the body resists shear); from each fluke tip to the 4 masses of
//! ring 5, and one between the tips.
//!
//! **26 faces** form a closed outward-oriented surface: 4 nose triangles, 4 quads between each
//! pair of rings (16), and 6 tail triangles (3 above and 3 below the plane of the fluke).
//!
//! ## Forces
//! - Spring a–b with length L = |p_b − p_a|, direction e = (p_b − p_a)/L: the force on a is
//!   (k (L − L₀) + D L̇) e and the opposite on b, with L̇ = (v_b − v_a)·e.
//! - **Muscles** (controls `muscle1`..`muscle6`, signed activation c ∈ [−1, 1], clamped):
//!   muscle s acts on segment s − 1 as an antagonistic pair. c > 0 shortens the rest length of
//!   its *dorsal* longitudinal springs (top line; for the nose segment nose–top, for the fluke
//!   segment top–tips) and lengthens its *ventral* ones (bottom line) by the same amount; c < 0
//!   does the reverse, so the segment bends concave-up or concave-down (see *Muscles in
//!   detail*). Dolphins undulate dorsoventrally, so the body bends in the vertical plane, and a
//!   wave of activation travelling from head to tail swims forward.
//! - **Hydrodynamics**: a face with vector area a = A n (outward unit normal n) moving with the
//!   mean velocity v of its corners feels f = −ρ A |n·v| (n·v) n, shared equally among its
//!   corners. ρ here lumps ½ ρ_water C_d.
//! - **Gravity** g along −z on every mass, 0 by default (neutral buoyancy).
//!
//! Without drag and gravity all forces are internal and central, so linear and angular
//! momentum are conserved; without damping and muscles the energy ½ Σ m|v|² + ½ Σ k (L − L₀)²
//! is too. All forces are invariant to rotating and translating the world frame.
//!
//! ## Swimming
//! Only the faces' normal motion meets resistance, so a body wave travelling tailwards
//! pushes water backwards. With the defaults, a 1 Hz wave lagging 30° per segment from head to
//! tail swims ≈ 1.3 m in 5 s (≈ 8 m in 20 s); the same wave reversed gets ≈ 0.4 m, because
//! the heaving fluke pitches passively and makes some thrust whatever the body does; without
//! drag the centre of mass does not move. The drag law is even in n, so the result does not
//! depend on the faces' orientation; they are outward all the same, which [`Dolphin::volume`]
//! relies on.
//!
//! ## Integration
//! Semi-implicit Euler at `default_dt` = 0.002 s, five times finer than the paper's 0.01 s
//! physical step. The body must be stiff enough that its bending modes (lowest ≈ 7 rad/s,
//! most ≳ 16 rad/s) sit above a ~1 Hz tail beat, or the muscles cannot shape it: with a body
//! soft enough for 0.01 s (fastest mode ≈ 100 rad/s, bending modes ≈ 3–6 rad/s, resonant with
//! the tail beat) swimming direction depended erratically on the wave's phase. With the
//! default parameters the fastest mode is ω ≈ 330 rad/s, so ω δt ≈ 0.66, well inside the
//! symplectic-Euler limit ω δt < 2. A NeuroAnimator super-step of 0.5 s is 250 steps.
//!
//! [`ImplicitDolphin`] steps the same force law by linearized backward Euler (Baraff &
//! Witkin 1998), stable at the paper's δt = 0.01 s; Table 2 times it against the emulator.
//!
//! ## Muscles in detail
//! A muscle commands a bend of its segment by θ = c θ_max about the body's y axis. Each of its
//! springs gets the first-order length change of that bend, rest length L₀ ∓ c θ_max arm
//! (dorsal −, ventral +), where arm = |∂L/∂θ| is computed once from the rest shape, rotating
//! the station behind (for the nose segment: the nose) about the centroid of the segment's
//! front ring. Expressing the command as an angle gives the six muscles similar authority even
//! though the dorsal–ventral spacing shrinks from 0.4 m in mid-body to 0.1 m at the tail stock.
//!
//! Layout: this module holds the parameters, the force law ([`Ode`] for [`Dolphin`]) and the
//! indexing of masses and segments; `body` builds the stations, springs, faces and muscle arms
//! from the parameters ([`Dolphin::new`]); `observe` computes momenta, energies, shape error
//! and the segment frames ([`SegmentFrame`]).
//!
//! ## References
//! - R. Grzeszczuk, D. Terzopoulos, G. Hinton, *NeuroAnimator: Fast Neural Network Emulation
//!   and Control of Physics-Based Models*, SIGGRAPH 1998, §3.3, §5.3, §6.
//! - X. Tu, D. Terzopoulos, *Artificial Fishes: Physics, Locomotion, Perception, Behavior*,
//!   SIGGRAPH 1994, §3 (mass-spring body, muscles, hydrodynamic force).
//! - R. Grzeszczuk, D. Terzopoulos, *Automated Learning of Muscle-Actuated Locomotion Through
//!   Control Abstraction*, SIGGRAPH 1995 (the dolphin and its 6 muscles).

mod body;
mod implicit;
mod observe;

pub use implicit::ImplicitDolphin;
pub use observe::SegmentFrame;

use super::linearize::{finite_difference_jacobians, DEFAULT_FD_STEP};
use super::pendulum::Mode;
use super::{Model, Ode, Parameter};
use nalgebra::{Matrix3, Rotation3, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};

/// Number of point masses.
pub const N_MASSES: usize = 23;
/// Number of position coordinates (3 per mass); velocities follow them in the state.
pub const N_POS: usize = 3 * N_MASSES;
/// Number of body segments (and of muscles).
pub const N_SEGMENTS: usize = 6;
/// Number of cross-section rings.
pub const N_RINGS: usize = 5;
/// Index of the nose mass.
pub const NOSE: usize = 0;
/// Index of the left (+y) fluke tip.
pub const FLUKE_LEFT: usize = 21;
/// Index of the right (−y) fluke tip.
pub const FLUKE_RIGHT: usize = 22;
/// Ring slot of the top (dorsal, +z) mass.
pub const TOP: usize = 0;
/// Ring slot of the left (+y) mass.
pub const LEFT: usize = 1;
/// Ring slot of the bottom (ventral, −z) mass.
pub const BOTTOM: usize = 2;
/// Ring slot of the right (−y) mass.
pub const RIGHT: usize = 3;

/// Index of the mass in slot `k` ([`TOP`], [`LEFT`], [`BOTTOM`], [`RIGHT`]) of ring `r`
/// (0-based: ring 1 of the module docs is `r = 0`).
pub const fn ring_mass(r: usize, k: usize) -> usize {
    1 + 4 * r + k
}

/// Station of mass `i`: 0 the nose, 1..=5 the rings, 6 the fluke.
pub const fn station_of_mass(i: usize) -> usize {
    match i {
        NOSE => 0,
        FLUKE_LEFT | FLUKE_RIGHT => 6,
        _ => 1 + (i - 1) / 4,
    }
}

/// The segment (0..6) that mass `i` belongs to: the nose and ring 1 to segment 0, ring r ≥ 2
/// to segment r − 1, the fluke tips to segment 5.
pub const fn segment_of_mass(i: usize) -> usize {
    let s = station_of_mass(i);
    if s == 0 {
        0
    } else {
        s - 1
    }
}

const SEGMENT_FRAME_MASSES: [&[usize]; N_SEGMENTS] = [
    &[0, 1, 2, 3, 4],
    &[1, 2, 3, 4, 5, 6, 7, 8],
    &[5, 6, 7, 8, 9, 10, 11, 12],
    &[9, 10, 11, 12, 13, 14, 15, 16],
    &[13, 14, 15, 16, 17, 18, 19, 20],
    &[17, 18, 19, 20, 21, 22],
];

/// The masses whose best rigid fit defines segment `s`'s frame: those of the two stations
/// bounding it (a superset of the masses [`segment_of_mass`] assigns to it).
pub fn segment_frame_masses(s: usize) -> &'static [usize] {
    SEGMENT_FRAME_MASSES[s]
}

/// Human-readable name of mass `i`, e.g. `nose`, `r3_left`, `fluke_right`.
pub fn mass_name(i: usize) -> String {
    match i {
        NOSE => "nose".into(),
        FLUKE_LEFT => "fluke_left".into(),
        FLUKE_RIGHT => "fluke_right".into(),
        _ => {
            let slot = ["top", "left", "bottom", "right"][(i - 1) % 4];
            format!("r{}_{slot}", station_of_mass(i))
        }
    }
}

/// The dolphin's physical parameters, as experiment files give them.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DolphinParams {
    /// Position of each station along the body axis, nose first: nose, rings 1–5, fluke tips
    /// (m, strictly decreasing).
    pub station_x: [f64; 7],
    /// Half-height of rings 1–5: the top and bottom masses sit at ±this z (m).
    pub ring_half_height: [f64; 5],
    /// Half-width of rings 1–5: the left and right masses sit at ±this y (m).
    pub ring_half_width: [f64; 5],
    /// Half-span of the fluke: the tips sit at ±this y (m).
    pub fluke_half_span: f64,
    /// Mass of each point mass at each station: nose, each of the 4 of rings 1–5, each fluke
    /// tip (kg).
    pub station_mass: [f64; 7],
    /// Stiffness k of the structural (non-muscle) springs (N/m).
    pub stiffness: f64,
    /// Stiffness k of the dorsal and ventral longitudinal (muscle) springs (N/m).
    pub muscle_stiffness: f64,
    /// Damping coefficient D of every spring, on its rate of extension (N·s/m).
    pub damping: f64,
    /// Bend θ_max of a segment at full muscle activation (rad): a muscle changes the rest
    /// lengths of its springs by the first-order length change of that bend.
    pub max_bend: f64,
    /// Hydrodynamic coefficient ρ in f = −ρ A |n·v| (n·v) n, i.e. ½ ρ_water C_d (kg/m³).
    pub drag: f64,
    /// Gravitational acceleration along −z (m/s²); 0 models neutral buoyancy.
    pub gravity: f64,
}

impl Default for DolphinParams {
    /// A 2 m, 83 kg dolphin whose springs are damped at 150 N·s/m.
    ///
    /// Why the springs are damped that hard: NeuroAnimator's dolphin nets step 0.1 s (N50 at
    /// δt = 0.002 s), and a mode faster than two super-steps that is not damped out within one
    /// is something a 40- or 50-unit net cannot follow (the pendulum's rule,
    /// `experiments/na_table1_structure.toml`). Damped at 20 N·s/m, 47 of the body's 68 modes
    /// linearized at rest ring at 5 to 52 Hz and decay by less than e² in a super-step. Damping
    /// alone cannot pass the rule inside semi-implicit Euler's stability limit (|λ| δt < 2 for a
    /// damped mode), so the damping is the largest of 20, 50, 100, 150, 200, 300 N·s/m that keeps
    /// every mode's |λ| δt ≤ 1.5 (the pendulum's margin): 150, where 6 modes (5.6 to 7.2 Hz,
    /// decaying at 10 to 17/s) still fail it and the hand-made 1 Hz wave swims about as far as
    /// it did (7.9 m in 20 s against 8.3 m). [`Dolphin::modes`] gives the modes.
    fn default() -> Self {
        Self {
            station_x: [1.0, 0.75, 0.4, 0.0, -0.4, -0.7, -1.0],
            ring_half_height: [0.12, 0.2, 0.2, 0.12, 0.05],
            ring_half_width: [0.1, 0.17, 0.17, 0.1, 0.04],
            fluke_half_span: 0.3,
            station_mass: [2.0, 3.0, 6.0, 6.0, 3.0, 1.5, 1.5],
            stiffness: 10_000.0,
            muscle_stiffness: 40_000.0,
            damping: 150.0,
            max_bend: 0.15,
            drag: 500.0,
            gravity: 0.0,
        }
    }
}

/// An invalid [`DolphinParams`] value.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum DolphinError {
    /// A quantity that must be positive and finite is not.
    #[error("dolphin parameter `{name}` must be positive and finite, got {value}")]
    NotPositive {
        /// Parameter name.
        name: &'static str,
        /// The bad value.
        value: f64,
    },
    /// A quantity that must be non-negative and finite is not.
    #[error("dolphin parameter `{name}` must be non-negative and finite, got {value}")]
    Negative {
        /// Parameter name.
        name: &'static str,
        /// The bad value.
        value: f64,
    },
    /// `station_x` does not decrease strictly from nose to tail.
    #[error("dolphin `station_x` must decrease strictly from nose to tail, got {0:?}")]
    StationOrder([f64; 7]),
    /// `max_bend` negative, or so large that a fully active muscle spring's rest length
    /// would not stay positive.
    #[error("dolphin `max_bend` must be non-negative and keep muscle rest lengths positive, got {0} rad")]
    Bend(f64),
}

/// What a spring is part of.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum SpringKind {
    /// An edge around a ring.
    Ring,
    /// A diameter across a ring (top–bottom or left–right).
    Cross,
    /// Nose to ring 1, ring to ring along the same slot, or ring 5 to a fluke tip.
    Longitudinal,
    /// A diagonal of a side quad between two rings (shear resistance).
    Diagonal,
    /// Between the two fluke tips.
    Fluke,
}

/// Which side of a segment a muscle spring lies on.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Side {
    /// The top (+z) line, contracted by positive activation.
    Dorsal,
    /// The bottom (−z) line, contracted by negative activation.
    Ventral,
}

/// One spring-damper between masses `a` and `b`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Spring {
    /// First mass.
    pub a: usize,
    /// Second mass.
    pub b: usize,
    /// Relaxed rest length, the distance in the rest shape (m).
    pub rest_length: f64,
    /// Stiffness (N/m).
    pub stiffness: f64,
    /// What it is part of.
    pub kind: SpringKind,
    /// The muscle that changes its rest length, if any.
    pub muscle: Option<Muscle>,
}

/// How a muscle acts on one of its springs.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Muscle {
    /// The segment (0..6), i.e. muscle `segment + 1`.
    pub segment: usize,
    /// The side of the segment the spring lies on.
    pub side: Side,
    /// |∂L/∂θ|: the spring's first-order length change per radian of segment bend (m/rad).
    pub arm: f64,
}

/// A surface face: a triangle (`n == 3`) or quad (`n == 4`), corners ordered so that the
/// vector area points outwards.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Face {
    /// Corner masses; only the first `n` are used.
    pub corners: [usize; 4],
    /// Number of corners, 3 or 4.
    pub n: usize,
}

impl Face {
    /// Vector area A n of the face for positions `q` (m²): ½ (b − a) × (c − a) for a
    /// triangle, ½ (c − a) × (d − b) for a (possibly non-planar) quad.
    pub fn vector_area(&self, q: &[f64]) -> Vector3<f64> {
        let p = |k: usize| point(q, self.corners[k]);
        if self.n == 3 {
            0.5 * (p(1) - p(0)).cross(&(p(2) - p(0)))
        } else {
            0.5 * (p(2) - p(0)).cross(&(p(3) - p(1)))
        }
    }

    /// Mean of the face's corner values in `q` (positions or velocities).
    pub fn mean(&self, q: &[f64]) -> Vector3<f64> {
        let mut s = Vector3::zeros();
        for &c in &self.corners[..self.n] {
            s += point(q, c);
        }
        s / self.n as f64
    }
}

/// The dolphin: validated parameters with the springs, faces and rest shape built from them.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "DolphinParams", into = "DolphinParams")]
pub struct Dolphin {
    params: DolphinParams,
    masses: [f64; N_MASSES],
    rest: [f64; N_POS],
    springs: Vec<Spring>,
    faces: Vec<Face>,
}

impl Default for Dolphin {
    fn default() -> Self {
        Self::new(DolphinParams::default()).expect("default dolphin parameters are valid")
    }
}

impl TryFrom<DolphinParams> for Dolphin {
    type Error = DolphinError;
    fn try_from(p: DolphinParams) -> Result<Self, DolphinError> {
        Self::new(p)
    }
}

impl From<Dolphin> for DolphinParams {
    fn from(d: Dolphin) -> Self {
        d.params
    }
}

fn point(q: &[f64], i: usize) -> Vector3<f64> {
    Vector3::new(q[3 * i], q[3 * i + 1], q[3 * i + 2])
}

fn add(f: &mut [f64], i: usize, v: &Vector3<f64>) {
    f[3 * i] += v.x;
    f[3 * i + 1] += v.y;
    f[3 * i + 2] += v.z;
}

impl Dolphin {
    /// The parameters it was built from.
    pub fn params(&self) -> &DolphinParams {
        &self.params
    }

    /// Mass of each point mass (kg).
    pub fn masses(&self) -> &[f64; N_MASSES] {
        &self.masses
    }

    /// Total mass (kg).
    pub fn total_mass(&self) -> f64 {
        self.masses.iter().sum()
    }

    /// The springs (91).
    pub fn springs(&self) -> &[Spring] {
        &self.springs
    }

    /// The surface faces (26), outward-oriented.
    pub fn faces(&self) -> &[Face] {
        &self.faces
    }

    /// Rest-shape positions (69): nose at `station_x[0]` on the +x axis, body along −x.
    pub fn rest_positions(&self) -> &[f64; N_POS] {
        &self.rest
    }

    /// The rest shape at rest: `[rest positions, zero velocities]` (138).
    pub fn rest_state(&self) -> Vec<f64> {
        let mut x = vec![0.0; 2 * N_POS];
        x[..N_POS].copy_from_slice(&self.rest);
        x
    }

    /// The modes of the motion linearized about the rest shape at rest with the muscles relaxed,
    /// slowest first: one per complex-conjugate pair of eigenvalues of the first-order system
    /// and one per real eigenvalue (the six rigid-body motions among them, at zero). The drag
    /// is quadratic in the velocity, so it adds no damping at rest; the Jacobian is by central
    /// differences.
    pub fn modes(&self) -> Vec<Mode> {
        let x = self.rest_state();
        let u = [0.0; N_SEGMENTS];
        let n = x.len();
        let mut a = nalgebra::DMatrix::zeros(n, n);
        let mut b = nalgebra::DMatrix::zeros(n, N_SEGMENTS);
        finite_difference_jacobians(self, &x, &u, DEFAULT_FD_STEP, &mut a, &mut b);
        // Central differences leave the rigid motions' zero eigenvalues slightly off zero.
        Mode::of_eigenvalues(a.complex_eigenvalues().iter(), 1e-9)
    }

    /// Rest length of spring `s` under muscle activations `act` (already clamped to [−1, 1]).
    pub fn active_rest_length(&self, s: &Spring, act: &[f64; N_SEGMENTS]) -> f64 {
        match s.muscle {
            Some(m) => {
                let change = self.params.max_bend * act[m.segment] * m.arm;
                match m.side {
                    Side::Dorsal => s.rest_length - change,
                    Side::Ventral => s.rest_length + change,
                }
            }
            None => s.rest_length,
        }
    }
}

impl Model for Dolphin {
    fn name(&self) -> &str {
        "dolphin"
    }
    fn state_names(&self) -> Vec<String> {
        let mut names = Vec::with_capacity(2 * N_POS);
        for prefix in ["", "v"] {
            for i in 0..N_MASSES {
                let m = mass_name(i);
                for axis in ["x", "y", "z"] {
                    names.push(format!("{m}.{prefix}{axis}"));
                }
            }
        }
        names
    }
    fn control_names(&self) -> Vec<String> {
        (1..=N_SEGMENTS).map(|i| format!("muscle{i}")).collect()
    }
    fn parameters(&self) -> Vec<Parameter> {
        let p = &self.params;
        let stations = ["nose", "ring1", "ring2", "ring3", "ring4", "ring5", "fluke"];
        let mut out = Vec::new();
        for (s, x) in stations.iter().zip(p.station_x) {
            out.push(Parameter::new(
                format!("station_x.{s}"),
                x,
                "m",
                "position of the station along the body axis",
            ));
        }
        for (r, (h, w)) in p.ring_half_height.iter().zip(p.ring_half_width).enumerate() {
            out.push(Parameter::new(
                format!("ring_half_height.ring{}", r + 1),
                *h,
                "m",
                "z of the top and bottom masses",
            ));
            out.push(Parameter::new(
                format!("ring_half_width.ring{}", r + 1),
                w,
                "m",
                "y of the left and right masses",
            ));
        }
        out.push(Parameter::new(
            "fluke_half_span",
            p.fluke_half_span,
            "m",
            "y of the fluke tips",
        ));
        for (s, m) in stations.iter().zip(p.station_mass) {
            out.push(Parameter::new(
                format!("station_mass.{s}"),
                m,
                "kg",
                "mass of each point mass at the station",
            ));
        }
        out.extend([
            Parameter::new(
                "total_mass",
                self.total_mass(),
                "kg",
                "sum of the 23 masses",
            ),
            Parameter::new(
                "stiffness",
                p.stiffness,
                "N/m",
                "structural spring stiffness",
            ),
            Parameter::new(
                "muscle_stiffness",
                p.muscle_stiffness,
                "N/m",
                "stiffness of the dorsal and ventral longitudinal (muscle) springs",
            ),
            Parameter::new("damping", p.damping, "N*s/m", "spring damping on L-dot"),
            Parameter::new(
                "max_bend",
                p.max_bend,
                "rad",
                "segment bend commanded by a fully active muscle",
            ),
            Parameter::new(
                "drag",
                p.drag,
                "kg/m^3",
                "rho in f = -rho A |n.v| (n.v) n on each face",
            ),
            Parameter::new(
                "gravity",
                p.gravity,
                "m/s^2",
                "along -z; 0 = neutral buoyancy",
            ),
        ]);
        out
    }
    fn default_dt(&self) -> f64 {
        0.002
    }
}

impl Ode for Dolphin {
    fn derivative(&self, x: &[f64], u: &[f64], dx: &mut [f64]) {
        let (q, v) = x.split_at(N_POS);
        let (dq, dv) = dx.split_at_mut(N_POS);
        dq.copy_from_slice(v);
        dv.fill(0.0);
        let mut act = [0.0; N_SEGMENTS];
        for (a, ui) in act.iter_mut().zip(u) {
            *a = ui.clamp(-1.0, 1.0);
        }
        let damping = self.params.damping;
        for s in &self.springs {
            let d = point(q, s.b) - point(q, s.a);
            let len = d.norm();
            if len == 0.0 {
                continue;
            }
            let e = d / len;
            let ldot = (point(v, s.b) - point(v, s.a)).dot(&e);
            let f = e * (s.stiffness * (len - self.active_rest_length(s, &act)) + damping * ldot);
            add(dv, s.a, &f);
            add(dv, s.b, &-f);
        }
        let rho = self.params.drag;
        if rho > 0.0 {
            for face in &self.faces {
                let a = face.vector_area(q);
                let area = a.norm();
                if area == 0.0 {
                    continue;
                }
                let n = a / area;
                let vn = n.dot(&face.mean(v));
                let f = n * (-rho * area * vn.abs() * vn / face.n as f64);
                for &c in &face.corners[..face.n] {
                    add(dv, c, &f);
                }
            }
        }
        for (i, m) in self.masses.iter().enumerate() {
            for k in 0..3 {
                dv[3 * i + k] /= m;
            }
            dv[3 * i + 2] -= self.params.gravity;
        }
    }

    fn position_dim(&self) -> Option<usize> {
        Some(N_POS)
    }

    /// Kinetic plus relaxed-spring plus gravitational energy (J).
    fn energy(&self, x: &[f64]) -> Option<f64> {
        let pot: f64 = (0..N_MASSES)
            .map(|i| self.masses[i] * self.params.gravity * x[3 * i + 2])
            .sum();
        Some(self.kinetic_energy(x) + self.spring_energy(x) + pot)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::physics::{Dynamics, IntegratorKind, Simulator};
    use nalgebra::DMatrix;
    use std::f64::consts::TAU;

    /// Travelling wave u_s = sin(2π f t − s·lag): head to tail for lag > 0.
    fn wave(t: f64, freq: f64, lag_deg: f64, u: &mut [f64; N_SEGMENTS]) {
        for (s, us) in u.iter_mut().enumerate() {
            *us = (TAU * freq * t - lag_deg.to_radians() * s as f64).sin();
        }
    }

    /// Swims `secs` seconds from rest at the default dt; returns the final state, the largest
    /// shape error and the smallest volume seen.
    fn swim(d: &Dolphin, freq: f64, lag_deg: f64, secs: f64) -> (Vec<f64>, f64, f64) {
        let dt = d.default_dt();
        let mut sim = Simulator::new(d.clone(), IntegratorKind::SemiImplicitEuler);
        let mut x = d.rest_state();
        let mut u = [0.0; N_SEGMENTS];
        let (mut max_err, mut min_vol) = (0.0_f64, f64::INFINITY);
        for k in 0..(secs / dt).round() as usize {
            wave(k as f64 * dt, freq, lag_deg, &mut u);
            sim.step(&mut x, &u, dt);
            max_err = max_err.max(d.shape_error(&x));
            min_vol = min_vol.min(d.volume(&x));
        }
        (x, max_err, min_vol)
    }

    /// Distance the centre of mass moved along the rest shape's forward axis (m).
    fn forward_distance(d: &Dolphin, x: &[f64]) -> f64 {
        let x0 = d.rest_state();
        (d.centre_of_mass(x) - d.centre_of_mass(&x0)).dot(&d.forward_axis(&x0))
    }

    /// A deformed, moving, spinning state (deterministic pseudo-random perturbation).
    pub(super) fn perturbed(d: &Dolphin, scale: f64) -> Vec<f64> {
        let mut x = d.rest_state();
        let spin = Vector3::new(0.3, -0.8, 0.5);
        for i in 0..N_MASSES {
            let p = point(&x, i);
            let v = Vector3::new(0.2, -0.1, 0.3) + spin.cross(&p);
            for k in 0..3 {
                let r = ((i * 3 + k) as f64 * 12.9898).sin() * 43758.5453;
                x[3 * i + k] += scale * (r - r.floor() - 0.5);
                x[N_POS + 3 * i + k] = v[k] + 10.0 * scale * ((i + 7 * k) as f64).cos();
            }
        }
        x
    }

    fn quiet(d: &Dolphin, damping: f64) -> Dolphin {
        Dolphin::new(DolphinParams {
            drag: 0.0,
            damping,
            ..d.params().clone()
        })
        .unwrap()
    }

    fn stiffness_matrix(d: &Dolphin) -> DMatrix<f64> {
        let q = d.rest_positions();
        let mut k = DMatrix::zeros(N_POS, N_POS);
        for s in d.springs() {
            let e = (point(q, s.b) - point(q, s.a)).normalize();
            let block = s.stiffness * e * e.transpose();
            for (i, j, sign) in [
                (s.a, s.a, 1.0),
                (s.b, s.b, 1.0),
                (s.a, s.b, -1.0),
                (s.b, s.a, -1.0),
            ] {
                for r in 0..3 {
                    for c in 0..3 {
                        k[(3 * i + r, 3 * j + c)] += sign * block[(r, c)];
                    }
                }
            }
        }
        k
    }

    #[test]
    fn rest_shape_is_a_rigid_equilibrium() {
        let d = Dolphin::default();
        let mut dx = vec![1.0; 2 * N_POS];
        d.derivative(&d.rest_state(), &[0.0; N_SEGMENTS], &mut dx);
        assert!(dx.iter().all(|a| a.abs() < 1e-9), "{dx:?}");
        // Exactly six zero modes (rigid motions): the springs brace every deformation.
        let mut k = stiffness_matrix(&d);
        for i in 0..N_POS {
            for j in 0..N_POS {
                k[(i, j)] /= (d.masses()[i / 3] * d.masses()[j / 3]).sqrt();
            }
        }
        let mut w2: Vec<f64> = k.symmetric_eigen().eigenvalues.iter().copied().collect();
        w2.sort_by(f64::total_cmp);
        assert!(w2[5].abs() < 1e-6 && w2[6] > 25.0, "{:?}", &w2[..8]);
        // Stable at the default step: ω_max δt < 2 for symplectic Euler.
        assert!(w2[N_POS - 1].sqrt() * d.default_dt() < 1.0);
        // An active muscle is not an equilibrium: it bends the segment.
        let mut u = [0.0; N_SEGMENTS];
        u[2] = 1.0;
        d.derivative(&d.rest_state(), &u, &mut dx);
        assert!(dx[N_POS..].iter().any(|a| a.abs() > 1.0));
    }

    #[test]
    fn springs_conserve_momentum_and_energy() {
        let d = Dolphin::default();
        // Momenta: exact for central internal forces under symplectic Euler, damping included.
        let damped = quiet(&d, d.params().damping);
        let x0 = perturbed(&d, 0.03);
        let (p0, l0) = (damped.momentum(&x0), damped.angular_momentum(&x0));
        let mut sim = Simulator::new(damped.clone(), IntegratorKind::SemiImplicitEuler);
        let mut x = x0.clone();
        for _ in 0..1000 {
            sim.step(&mut x, &[0.0; N_SEGMENTS], 1e-3);
        }
        assert!((damped.momentum(&x) - p0).norm() < 1e-10 * p0.norm());
        assert!((damped.angular_momentum(&x) - l0).norm() < 1e-10 * l0.norm());
        assert!(damped.energy(&x).unwrap() < 0.9 * damped.energy(&x0).unwrap());
        // Energy: conserved without damping, up to RK4's error, which shrinks at its order.
        let free = quiet(&d, 0.0);
        let e0 = free.energy(&x0).unwrap();
        let drift = |h: f64| {
            let mut sim = Simulator::new(free.clone(), IntegratorKind::Rk4);
            let mut x = x0.clone();
            let (mut max_dev, mut min_spring) = (0.0_f64, f64::INFINITY);
            for _ in 0..(0.5 / h).round() as usize {
                sim.step(&mut x, &[0.0; N_SEGMENTS], h);
                max_dev = max_dev.max((free.energy(&x).unwrap() - e0).abs());
                min_spring = min_spring.min(free.spring_energy(&x));
            }
            (max_dev, min_spring, x)
        };
        let (coarse, _, _) = drift(5e-4);
        let (fine, min_spring, x) = drift(2.5e-4);
        eprintln!("RK4 energy drift over 0.5 s: {coarse:.3e} J (h = 5e-4), {fine:.3e} J (h = 2.5e-4) of {e0:.1} J");
        assert!(
            fine < 2e-6 * e0 && fine < coarse / 10.0,
            "{coarse} {fine} of {e0}"
        );
        // ... while elastic and kinetic energy really are exchanged.
        assert!(min_spring < 0.5 * free.spring_energy(&x0));
        assert!((free.momentum(&x) - free.momentum(&x0)).norm() < 1e-10 * p0.norm());
    }

    #[test]
    fn invariant_to_rotating_and_translating_the_world() {
        let d = Dolphin::default();
        let x = perturbed(&d, 0.03);
        let u = [0.7, -0.3, 1.0, -1.0, 0.2, 0.5];
        let r = Rotation3::from_euler_angles(0.4, -1.1, 2.5);
        let t = Vector3::new(3.0, -7.0, 1.5);
        let mut y = x.clone();
        for i in 0..N_MASSES {
            let p = r * point(&x, i) + t;
            let v = r * point(&x[N_POS..], i);
            y[3 * i..3 * i + 3].copy_from_slice(p.as_slice());
            y[N_POS + 3 * i..N_POS + 3 * i + 3].copy_from_slice(v.as_slice());
        }
        let (mut dx, mut dy) = (vec![0.0; 2 * N_POS], vec![0.0; 2 * N_POS]);
        d.derivative(&x, &u, &mut dx);
        d.derivative(&y, &u, &mut dy);
        let scale = dx.iter().fold(0.0_f64, |m, a| m.max(a.abs()));
        for half in [0, N_POS] {
            for i in 0..N_MASSES {
                let expect = r * point(&dx[half..], i);
                let got = point(&dy[half..], i);
                assert!((expect - got).norm() < 1e-10 * scale, "{half} {i}");
            }
        }
        assert!((d.shape_error(&x) - d.shape_error(&y)).abs() < 1e-12);
    }

    /// The rule the default damping was chosen by (`DolphinParams::default`): the largest of
    /// 20, 50, 100, 150, 200, 300 N·s/m at which every mode keeps |λ| δt ≤ 1.5 at δt = 0.002 s.
    /// It also checks what the rule trades: how many modes fail the pendulum's rule at N50's
    /// 0.1 s (neither lasting two super-steps nor decaying by e² within one), many at the old
    /// 20 N·s/m and few at 150.
    #[test]
    fn default_dolphin_damping_is_the_largest_its_step_keeps_stable() {
        let dt = Dolphin::default().default_dt();
        let with = |damping: f64| {
            Dolphin::new(DolphinParams {
                damping,
                ..DolphinParams::default()
            })
            .unwrap()
            .modes()
        };
        let stable = |modes: &[Mode]| modes.iter().all(|m| m.rate() * dt <= 1.5);
        let unfit = |modes: &[Mode]| {
            modes
                .iter()
                .filter(|m| m.period_s < 0.2 && m.decay_per_s * 0.1 < 2.0)
                .count()
        };
        let ladder = [20.0, 50.0, 100.0, 150.0, 200.0, 300.0];
        let chosen = ladder
            .iter()
            .copied()
            .filter(|&c| stable(&with(c)))
            .fold(f64::NAN, f64::max);
        assert_eq!(chosen, 150.0);
        assert_eq!(Dolphin::default().params().damping, chosen);
        let (old, new) = (with(20.0), Dolphin::default().modes());
        assert_eq!(unfit(&old), 47, "{old:?}");
        assert_eq!(unfit(&new), 6, "{new:?}");
        // The six rigid-body motions (twelve eigenvalues) sit at zero; every other mode is
        // slower than two super-steps or damped.
        assert!(new.iter().filter(|m| m.rate() < 1e-3).count() >= 6);
        assert!(new
            .iter()
            .filter(|m| m.rate() >= 1e-3)
            .all(|m| m.period_s > 0.2 || m.decay_per_s > 5.0));
        // The integrator is as stable as the rule says: a kick to every mass dies out.
        let d = Dolphin::default();
        let mut sim = Simulator::new(d.clone(), IntegratorKind::SemiImplicitEuler);
        let mut x = perturbed(&d, 0.02);
        let u = [0.0; N_SEGMENTS];
        for _ in 0..2000 {
            sim.step(&mut x, &u, dt);
        }
        assert!(x.iter().all(|v| v.is_finite()));
        assert!(d.shape_error(&x) < 1e-3, "{}", d.shape_error(&x));
    }

    #[test]
    fn travelling_wave_swims_forward_and_reversed_or_dragless_does_not() {
        let d = Dolphin::default();
        let secs = 5.0;
        let (x, _, _) = swim(&d, 1.0, 30.0, secs);
        let forward = forward_distance(&d, &x);
        let (xr, _, _) = swim(&d, 1.0, -30.0, secs);
        let reversed = forward_distance(&d, &xr);
        eprintln!(
            "1 Hz wave, 30 deg/segment, {secs} s: forward {forward:.3} m, reversed {reversed:.3} m"
        );
        assert!(forward > 0.5, "forward wave: {forward} m");
        assert!(
            reversed < 0.5 * forward,
            "reversed wave: {reversed} m vs {forward} m"
        );
        // Without water the same wave only wiggles in place: momentum stays zero.
        let (xd, _, _) = swim(&quiet(&d, d.params().damping), 1.0, 30.0, secs);
        let moved = d.centre_of_mass(&xd) - d.centre_of_mass(&d.rest_state());
        assert!(moved.norm() < 1e-9, "no drag: moved {moved}");
    }

    #[test]
    fn twenty_seconds_of_swimming_stay_finite_and_keep_shape() {
        let d = Dolphin::default();
        let (x, max_err, min_vol) = swim(&d, 1.0, 30.0, 20.0);
        let v0 = d.volume(&d.rest_state());
        eprintln!(
            "20 s: forward {:.3} m, max shape error {max_err:.4}, min volume {:.3} of rest",
            forward_distance(&d, &x),
            min_vol / v0
        );
        assert!(x.iter().all(|v| v.is_finite()));
        assert!(max_err < 0.1, "shape error {max_err}");
        assert!(min_vol > 0.8 * v0, "volume {min_vol} of {v0}");
        assert!(forward_distance(&d, &x) > 2.0);
    }

    #[test]
    fn parameters_are_validated_and_round_trip() {
        let bad = |f: fn(&mut DolphinParams)| {
            let mut p = DolphinParams::default();
            f(&mut p);
            Dolphin::new(p).unwrap_err()
        };
        assert_eq!(
            bad(|p| p.stiffness = -1.0),
            DolphinError::NotPositive {
                name: "stiffness",
                value: -1.0
            }
        );
        assert!(matches!(
            bad(|p| p.station_x[3] = 2.0),
            DolphinError::StationOrder(_)
        ));
        assert_eq!(bad(|p| p.max_bend = 10.0), DolphinError::Bend(10.0));
        assert!(matches!(
            bad(|p| p.drag = f64::NAN),
            DolphinError::Negative { .. }
        ));
        let d = Dolphin::default();
        let json = serde_json::to_string(&d).unwrap();
        let back: Dolphin = serde_json::from_str(&json).unwrap();
        assert_eq!(back, d);
        assert!(d
            .parameters()
            .iter()
            .any(|p| p.name == "max_bend" && p.unit == "rad"));
    }
}
