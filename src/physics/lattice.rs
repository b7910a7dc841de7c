//! # 3D mass-spring lattices on a floor (Christensen, Marks, Ngo 1995, §2.1)
//!
//! A lattice is a set of point masses joined by damped linear springs. With ℓ the current
//! length of a spring, ℓ̇ its rate and L its rest length, the spring pulls its two masses
//! together with the tension
//!
//! T = k (ℓ − L) + D ℓ̇,
//!
//! i.e. the force on mass a is −T·(p_a − p_b)/ℓ, equal and opposite on b. (The paper prints
//! the magnitude as f = −k(L − x) − D ẋ; read with one sign convention for both terms, that is
//! either anti-restoring or anti-damping, so we use the dissipative law above.) Gravity g acts
//! along −z and the floor is the plane z = 0:
//!
//! - **impact** (inelastic collision): a mass reaching the floor with v_z < 0 loses its normal
//!   velocity; its tangential velocity is reduced by at most μ·|v_z| (Coulomb's law for the
//!   impulse). Impacts are events handled by [`LatticeSim`], not by the force law.
//! - **resting contact**: a mass on the floor (z ≤ ε_z, |v_z| ≤ ε_v) receives the normal force
//!   N = max(0, −F_z) that cancels the downward part of the other forces F on it. Each
//!   contact involves one point mass and the mass matrix is diagonal, so this is the exact
//!   unilateral constraint force: no complementarity problem is needed.
//! - **friction** (regularized Coulomb): the friction force is the force that would stop the
//!   tangential motion within the time constant τ, f* = −F_t − m v_t/τ, clipped to the
//!   Coulomb limit μ_eff N. A mass at rest with |F_t| ≤ μN stays exactly at rest (static
//!   friction); a sliding mass feels |f| = μN opposing its motion (exactly opposite when F_t
//!   is parallel to v_t). The right-hand side stays bounded and Lipschitz (constant m/τ).
//! - **directional friction**: with preferred horizontal direction d, the coefficient is
//!   μ_eff = μ + (μ_d − μ)·max(0, ŝ·d) where ŝ is the direction of the (attempted) sliding,
//!   so sliding along +d is resisted by μ_d and sliding against it or across it by μ.
//!
//! The state is `[p_0, …, p_{n−1}, v_0, …, v_{n−1}]` (3 coordinates each, world frame, z up);
//! the controls are the springs' rest lengths ([`LatticeModel`] keeps the active ones when the
//! control slice is empty). The equations are integrated by adaptive Dormand–Prince RK45
//! (§2.1 of the paper) inside [`LatticeSim`], which ends a step at each impact.
//!
//! Three lattices ship as data: [`Lattice::cube`] (8 masses, 28 springs), [`Lattice::pyramid`]
//! (the "spider", 5 masses, 10 springs) and [`Lattice::chair`] (10 masses, 35 springs).
//! Actuation reflexes that produce rest lengths are in [`super::reflex`].
//!
//! ## References
//! - J. Christensen, J. Marks, J. T. Ngo, *Automatic Motion Synthesis for 3D Mass-Spring
//!   Models*, The Visual Computer 13(1), 1997 (MERL TR95-01).

use super::integrate::{Integrator, IntegratorKind, Rk45Stats};
use super::reflex::{self, ReflexGains};
use super::{Dynamics, Model, Ode, Parameter};
use nalgebra::{Rotation3, Vector3};
use serde::{Deserialize, Serialize};

/// Earth's gravitational acceleration (m/s²).
pub const EARTH_GRAVITY: f64 = 9.81;
/// The "low gravity" of the paper's somersault and pirouette examples: the Moon's (m/s²).
pub const LOW_GRAVITY: f64 = 1.62;

/// Errors of lattice construction and actuation.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum LatticeError {
    /// A lattice needs at least one mass.
    #[error("lattice has no masses")]
    Empty,
    /// A mass value that is not positive and finite (index, value in kg).
    #[error("mass {0} has invalid mass {1} kg (must be positive and finite)")]
    InvalidMass(usize, f64),
    /// A mass position that is not finite (index).
    #[error("mass {0} has a non-finite position")]
    InvalidPosition(usize),
    /// A spring whose end indices are out of range or equal (spring, a, b).
    #[error("spring {0} joins masses {1} and {2}: indices must differ and be in range")]
    InvalidEnds(usize, usize, usize),
    /// A spring whose ends coincide in the rest shape (spring index).
    #[error("spring {0} has zero rest length")]
    ZeroRestLength(usize),
    /// A negative or non-finite stiffness or damping (spring, value).
    #[error("spring {0} has invalid stiffness or damping {1} (must be finite and >= 0)")]
    InvalidSpring(usize, f64),
    /// A rest-length vector of the wrong length (got, expected).
    #[error("{0} rest lengths given, lattice has {1} springs")]
    RestLengthCount(usize, usize),
    /// A rest length that is not positive and finite (spring, value in m).
    #[error("spring {0}: invalid rest length {1} m")]
    InvalidRestLength(usize, f64),
    /// A reflex number outside 0–11.
    #[error("reflex number {0} is not in 0..=11")]
    InvalidReflex(usize),
    /// A floor parameter out of range (name, value).
    #[error("floor parameter `{0}` has invalid value {1}")]
    InvalidFloor(&'static str, f64),
    /// A reflex coefficient outside [−1, 1] or not finite.
    #[error("reflex coefficient {0} is not in [-1, 1]")]
    InvalidCoefficient(f64),
}

/// A point mass of a lattice.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PointMass {
    /// Position in the rest shape, lattice frame (m); z is the lattice's "up".
    pub position: [f64; 3],
    /// Mass (kg).
    pub mass: f64,
}

/// A damped linear spring between two masses of a lattice.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Spring {
    /// Index of the first mass.
    pub a: usize,
    /// Index of the second mass.
    pub b: usize,
    /// Spring constant k (N/m).
    pub stiffness: f64,
    /// Damping constant D on the rate of change of length (N·s/m).
    pub damping: f64,
}

/// A mass-spring lattice as data: its rest shape, masses and springs.
///
/// Rest lengths are the distances between the masses in the rest shape
/// ([`Lattice::rest_lengths`]); the lattice-centric axes of the reflexes are the axes of the
/// frame the rest positions are written in.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Lattice {
    /// Name, used as the model name (e.g. `lattice_cube`).
    pub name: String,
    /// The point masses with their rest positions.
    pub masses: Vec<PointMass>,
    /// The springs.
    pub springs: Vec<Spring>,
}

/// Default spring constant of the shipped lattices (N/m).
pub const DEFAULT_STIFFNESS: f64 = 500.0;
/// Default spring damping of the shipped lattices (N·s/m).
pub const DEFAULT_DAMPING: f64 = 10.0;

impl Lattice {
    /// Builds a lattice from rest positions, masses (kg) and index pairs, all springs sharing
    /// `stiffness` (N/m) and `damping` (N·s/m).
    pub fn from_parts(
        name: impl Into<String>,
        positions: &[[f64; 3]],
        masses: &[f64],
        pairs: &[(usize, usize)],
        stiffness: f64,
        damping: f64,
    ) -> Self {
        Self {
            name: name.into(),
            masses: positions
                .iter()
                .zip(masses)
                .map(|(&position, &mass)| PointMass { position, mass })
                .collect(),
            springs: pairs
                .iter()
                .map(|&(a, b)| Spring {
                    a,
                    b,
                    stiffness,
                    damping,
                })
                .collect(),
        }
    }

    /// The unit cube of Fig. 1: 1 kg masses at the corners of [0, 1]³ and 28 springs
    /// (12 edges, 12 face diagonals, 4 body diagonals). Mass index = x + 2y + 4z.
    pub fn cube() -> Self {
        let positions: Vec<[f64; 3]> = (0..8)
            .map(|i| [(i & 1) as f64, ((i >> 1) & 1) as f64, ((i >> 2) & 1) as f64])
            .collect();
        // Every pair of corners is an edge (1 differing bit), a face diagonal (2) or a body
        // diagonal (3): all 28 pairs.
        let mut pairs = Vec::new();
        for a in 0..8 {
            for b in a + 1..8 {
                pairs.push((a, b));
            }
        }
        Self::from_parts(
            "lattice_cube",
            &positions,
            &[1.0; 8],
            &pairs,
            DEFAULT_STIFFNESS,
            DEFAULT_DAMPING,
        )
    }

    /// The pyramid ("spider"): a 1 m square base and an apex 0.8 m above its centre, 1 kg
    /// masses, 10 springs (4 base edges, 2 base diagonals, 4 legs).
    pub fn pyramid() -> Self {
        let positions = [
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [1.0, 1.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.5, 0.5, 0.8],
        ];
        let pairs = [
            (0, 1),
            (1, 2),
            (2, 3),
            (3, 0),
            (0, 2),
            (1, 3),
            (0, 4),
            (1, 4),
            (2, 4),
            (3, 4),
        ];
        Self::from_parts(
            "lattice_pyramid",
            &positions,
            &[1.0; 5],
            &pairs,
            DEFAULT_STIFFNESS,
            DEFAULT_DAMPING,
        )
    }

    /// A chair: a 0.6 m × 0.6 m leg box 0.5 m high (4 feet, 4 seat corners) and a back of
    /// two masses 0.6 m above the rear seat corners; 10 masses of 1 kg and 35 springs of
    /// twice the default stiffness and damping (its back sways otherwise). Front is −x, the
    /// back stands at x = 0.6.
    pub fn chair() -> Self {
        let (w, h, hb) = (0.6, 0.5, 0.6);
        let mut positions = Vec::new();
        // Feet 0..4 and seat corners 4..8, index = x + 2y (+4 for the seat).
        for z in [0.0, h] {
            for j in 0..4 {
                positions.push([w * (j & 1) as f64, w * ((j >> 1) & 1) as f64, z]);
            }
        }
        // Back: 8 above seat corner 5 (x = w, y = 0), 9 above seat corner 7 (x = w, y = w).
        positions.push([w, 0.0, h + hb]);
        positions.push([w, w, h + hb]);
        // The leg box: all 28 pairs of its 8 corners (edges, face and body diagonals).
        let mut pairs = Vec::new();
        for a in 0..8 {
            for b in a + 1..8 {
                pairs.push((a, b));
            }
        }
        // The back: top bar, uprights, crossed diagonals, and braces to the front seat corners.
        pairs.extend([(8, 9), (5, 8), (7, 9), (5, 9), (7, 8), (4, 8), (6, 9)]);
        Self::from_parts(
            "lattice_chair",
            &positions,
            &[1.0; 10],
            &pairs,
            2.0 * DEFAULT_STIFFNESS,
            2.0 * DEFAULT_DAMPING,
        )
    }

    /// Number of point masses.
    pub fn n_masses(&self) -> usize {
        self.masses.len()
    }

    /// Checks masses, positions, spring ends and constants.
    pub fn validate(&self) -> Result<(), LatticeError> {
        if self.masses.is_empty() {
            return Err(LatticeError::Empty);
        }
        for (i, m) in self.masses.iter().enumerate() {
            if !(m.mass.is_finite() && m.mass > 0.0) {
                return Err(LatticeError::InvalidMass(i, m.mass));
            }
            if !m.position.iter().all(|v| v.is_finite()) {
                return Err(LatticeError::InvalidPosition(i));
            }
        }
        let n = self.masses.len();
        for (j, s) in self.springs.iter().enumerate() {
            if s.a >= n || s.b >= n || s.a == s.b {
                return Err(LatticeError::InvalidEnds(j, s.a, s.b));
            }
            for v in [s.stiffness, s.damping] {
                if !(v.is_finite() && v >= 0.0) {
                    return Err(LatticeError::InvalidSpring(j, v));
                }
            }
        }
        for (j, &l) in self.rest_lengths().iter().enumerate() {
            if l <= 0.0 {
                return Err(LatticeError::ZeroRestLength(j));
            }
        }
        Ok(())
    }

    /// Rest positions of the masses (m).
    pub fn rest_positions(&self) -> Vec<[f64; 3]> {
        self.masses.iter().map(|m| m.position).collect()
    }

    /// Rest lengths of the springs in the rest shape (m).
    pub fn rest_lengths(&self) -> Vec<f64> {
        lengths(&self.rest_positions(), &self.springs)
    }

    /// Total mass (kg).
    pub fn total_mass(&self) -> f64 {
        self.masses.iter().map(|m| m.mass).sum()
    }

    /// Centre of mass of positions `p` (one per mass).
    pub fn center_of_mass(&self, p: &[[f64; 3]]) -> [f64; 3] {
        let mut c = [0.0; 3];
        for (m, q) in self.masses.iter().zip(p) {
            for k in 0..3 {
                c[k] += m.mass * q[k];
            }
        }
        let total = self.total_mass();
        c.map(|v| v / total)
    }

    /// A state `[positions, velocities]` with the rest shape rotated about its centre of mass
    /// by `rotation` (axis × angle, rad), moved so that its centre of mass is horizontally at
    /// the origin and its lowest mass at height `height` (m), and every mass moving with
    /// `velocity` (m/s).
    pub fn placed_state(&self, rotation: [f64; 3], height: f64, velocity: [f64; 3]) -> Vec<f64> {
        let n = self.n_masses();
        let rot = Rotation3::new(Vector3::from(rotation));
        let c = Vector3::from(self.center_of_mass(&self.rest_positions()));
        let rotated: Vec<Vector3<f64>> = self
            .masses
            .iter()
            .map(|m| rot * (Vector3::from(m.position) - c))
            .collect();
        let low = rotated.iter().map(|p| p.z).fold(f64::INFINITY, f64::min);
        let mut x = vec![0.0; 6 * n];
        for (i, p) in rotated.iter().enumerate() {
            x[3 * i] = p.x;
            x[3 * i + 1] = p.y;
            x[3 * i + 2] = p.z - low + height;
            x[3 * n + 3 * i..3 * n + 3 * i + 3].copy_from_slice(&velocity);
        }
        x
    }

    /// The rest shape standing on the floor at rest, centre of mass above the origin.
    pub fn resting_state(&self) -> Vec<f64> {
        self.placed_state([0.0; 3], 0.0, [0.0; 3])
    }
}

/// Distances |p_a − p_b| for each spring.
pub fn lengths(p: &[[f64; 3]], springs: &[Spring]) -> Vec<f64> {
    springs
        .iter()
        .map(|s| (Vector3::from(p[s.a]) - Vector3::from(p[s.b])).norm())
        .collect()
}

/// The floor z = 0 and its friction.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Floor {
    /// Coulomb friction coefficient μ for sliding against or across the preferred direction.
    pub friction: f64,
    /// Coulomb friction coefficient μ_d for sliding along the preferred direction (equal to
    /// `friction` for isotropic friction).
    pub preferred_friction: f64,
    /// Preferred horizontal direction d = (x, y) in the world frame (normalized on use).
    pub preferred_direction: [f64; 2],
    /// Time constant τ of the regularized static friction (s): below the Coulomb limit,
    /// friction stops tangential motion within about τ.
    pub stick_time: f64,
    /// Height below which a mass with small normal velocity is in contact (m); also the
    /// penetration tolerated before an impact event is localized.
    pub contact_tolerance: f64,
    /// Normal speed below which a mass near the floor is in resting contact (m/s).
    pub velocity_tolerance: f64,
}

impl Default for Floor {
    fn default() -> Self {
        Self {
            friction: 1.0,
            preferred_friction: 1.0,
            preferred_direction: [1.0, 0.0],
            stick_time: 0.01,
            contact_tolerance: 1e-6,
            velocity_tolerance: 1e-6,
        }
    }
}

impl Floor {
    /// Checks that coefficients are ≥ 0, the direction is non-zero and the time constant and
    /// tolerances are positive.
    pub fn validate(&self) -> Result<(), LatticeError> {
        let [dx, dy] = self.preferred_direction;
        for (name, value, ok) in [
            ("friction", self.friction, self.friction >= 0.0),
            (
                "preferred_friction",
                self.preferred_friction,
                self.preferred_friction >= 0.0,
            ),
            ("preferred_direction", dx.hypot(dy), dx.hypot(dy) > 0.0),
            ("stick_time", self.stick_time, self.stick_time > 0.0),
            (
                "contact_tolerance",
                self.contact_tolerance,
                self.contact_tolerance > 0.0,
            ),
            (
                "velocity_tolerance",
                self.velocity_tolerance,
                self.velocity_tolerance > 0.0,
            ),
        ] {
            if !(ok && value.is_finite()) {
                return Err(LatticeError::InvalidFloor(name, value));
            }
        }
        Ok(())
    }

    /// Friction coefficient for sliding in horizontal direction `s` (any length).
    pub fn coefficient(&self, s: [f64; 2]) -> f64 {
        let [dx, dy] = self.preferred_direction;
        let dn = (dx * dx + dy * dy).sqrt();
        let sn = (s[0] * s[0] + s[1] * s[1]).sqrt();
        if dn == 0.0 || sn == 0.0 {
            return self.friction;
        }
        let cos = (s[0] * dx + s[1] * dy) / (sn * dn);
        self.friction + (self.preferred_friction - self.friction) * cos.max(0.0)
    }
}

/// A lattice with gravity, a floor and active rest lengths: an [`Ode`].
///
/// Controls are the springs' rest lengths (m); an empty control slice means "use
/// [`LatticeModel::rest_lengths`]". The floor's impacts are not part of the right-hand side:
/// integrate with [`LatticeSim`], which handles them as events.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LatticeModel {
    /// The lattice.
    pub lattice: Lattice,
    /// Gravitational acceleration along −z (m/s²); see [`EARTH_GRAVITY`], [`LOW_GRAVITY`].
    pub gravity: f64,
    /// The floor.
    pub floor: Floor,
    /// Gains of the actuation reflexes.
    pub reflex_gains: ReflexGains,
    /// Active rest lengths (m), one per spring.
    pub rest_lengths: Vec<f64>,
}

impl LatticeModel {
    /// A validated model of `lattice` with Earth gravity, the default floor and the rest
    /// shape's rest lengths.
    pub fn new(lattice: Lattice) -> Result<Self, LatticeError> {
        lattice.validate()?;
        let rest_lengths = lattice.rest_lengths();
        Ok(Self {
            lattice,
            gravity: EARTH_GRAVITY,
            floor: Floor::default(),
            reflex_gains: ReflexGains::default(),
            rest_lengths,
        })
    }

    /// The same model with gravity `g` (m/s²).
    pub fn with_gravity(mut self, g: f64) -> Self {
        self.gravity = g;
        self
    }

    /// The same model with floor `floor`, validated.
    pub fn with_floor(mut self, floor: Floor) -> Result<Self, LatticeError> {
        floor.validate()?;
        self.floor = floor;
        Ok(self)
    }

    /// Sets the active rest lengths (m), validated.
    pub fn set_rest_lengths(&mut self, rest: &[f64]) -> Result<(), LatticeError> {
        let ns = self.lattice.springs.len();
        if rest.len() != ns {
            return Err(LatticeError::RestLengthCount(rest.len(), ns));
        }
        if let Some((j, &l)) = rest
            .iter()
            .enumerate()
            .find(|(_, l)| !(l.is_finite() && **l > 0.0))
        {
            return Err(LatticeError::InvalidRestLength(j, l));
        }
        self.rest_lengths.copy_from_slice(rest);
        Ok(())
    }

    /// Activates reflex `number` (0–11) with coefficient `alpha` ∈ [−1, 1]: the active rest
    /// lengths become those of the deformed rest shape (§2.2).
    pub fn apply_reflex(&mut self, number: usize, alpha: f64) -> Result<(), LatticeError> {
        let d = reflex::deform(&self.lattice, number, alpha, &self.reflex_gains)?;
        self.set_rest_lengths(&d.rest_lengths)
    }

    /// Positions (m) of the masses in state `x`.
    pub fn positions(&self, x: &[f64]) -> Vec<[f64; 3]> {
        let n = self.lattice.n_masses();
        (0..n)
            .map(|i| [x[3 * i], x[3 * i + 1], x[3 * i + 2]])
            .collect()
    }

    /// Centre of mass (m) of state `x`.
    pub fn center_of_mass(&self, x: &[f64]) -> [f64; 3] {
        self.lattice.center_of_mass(&self.positions(x))
    }

    /// Kinetic energy (J) of state `x`.
    pub fn kinetic_energy(&self, x: &[f64]) -> f64 {
        let n = self.lattice.n_masses();
        let v = &x[3 * n..];
        self.lattice
            .masses
            .iter()
            .enumerate()
            .map(|(i, m)| 0.5 * m.mass * (0..3).map(|k| v[3 * i + k].powi(2)).sum::<f64>())
            .sum()
    }

    /// Number of masses in contact with the floor in state `x`.
    pub fn contacts(&self, x: &[f64]) -> usize {
        let n = self.lattice.n_masses();
        (0..n)
            .filter(|&i| self.in_contact(x[3 * i + 2], x[3 * n + 3 * i + 2]))
            .count()
    }

    fn in_contact(&self, z: f64, vz: f64) -> bool {
        z <= self.floor.contact_tolerance && vz.abs() <= self.floor.velocity_tolerance
    }

    /// Adds the spring forces (N) of state `x` with rest lengths `rest` to `f` (3 per mass).
    pub fn add_spring_forces(&self, x: &[f64], rest: &[f64], f: &mut [f64]) {
        let n = self.lattice.n_masses();
        let (p, v) = x.split_at(3 * n);
        for (s, &l0) in self.lattice.springs.iter().zip(rest) {
            let (a, b) = (3 * s.a, 3 * s.b);
            let d = [p[a] - p[b], p[a + 1] - p[b + 1], p[a + 2] - p[b + 2]];
            let dv = [v[a] - v[b], v[a + 1] - v[b + 1], v[a + 2] - v[b + 2]];
            let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
            if len == 0.0 {
                continue;
            }
            let rate = (d[0] * dv[0] + d[1] * dv[1] + d[2] * dv[2]) / len;
            let tension = s.stiffness * (len - l0) + s.damping * rate;
            for k in 0..3 {
                let fk = tension * d[k] / len;
                f[a + k] -= fk;
                f[b + k] += fk;
            }
        }
    }
}

impl Model for LatticeModel {
    fn name(&self) -> &str {
        &self.lattice.name
    }
    fn state_names(&self) -> Vec<String> {
        let n = self.lattice.n_masses();
        let mut names = Vec::with_capacity(6 * n);
        for prefix in ["", "v"] {
            for i in 0..n {
                for c in ["x", "y", "z"] {
                    names.push(format!("mass{i}.{prefix}{c}"));
                }
            }
        }
        names
    }
    fn control_names(&self) -> Vec<String> {
        (0..self.lattice.springs.len())
            .map(|j| format!("spring{j}.rest_length"))
            .collect()
    }
    fn parameters(&self) -> Vec<Parameter> {
        let f = &self.floor;
        let mut p = vec![
            Parameter::new("gravity", self.gravity, "m/s^2", "gravity along -z"),
            Parameter::new("floor.friction", f.friction, "1", "Coulomb coefficient"),
            Parameter::new(
                "floor.preferred_friction",
                f.preferred_friction,
                "1",
                "Coulomb coefficient sliding along the preferred direction",
            ),
            Parameter::new(
                "floor.preferred_direction.x",
                f.preferred_direction[0],
                "1",
                "preferred sliding direction, x component (world)",
            ),
            Parameter::new(
                "floor.preferred_direction.y",
                f.preferred_direction[1],
                "1",
                "preferred sliding direction, y component (world)",
            ),
            Parameter::new(
                "floor.stick_time",
                f.stick_time,
                "s",
                "time constant of regularized static friction",
            ),
            Parameter::new(
                "floor.contact_tolerance",
                f.contact_tolerance,
                "m",
                "contact height and tolerated penetration",
            ),
            Parameter::new(
                "floor.velocity_tolerance",
                f.velocity_tolerance,
                "m/s",
                "normal speed of resting contact",
            ),
        ];
        for (name, value, unit, description) in [
            (
                "reflex.scale",
                self.reflex_gains.scale,
                "1",
                "relative stretch at alpha = 1",
            ),
            (
                "reflex.shear",
                self.reflex_gains.shear,
                "1",
                "shear strain at alpha = 1",
            ),
            (
                "reflex.splay",
                self.reflex_gains.splay,
                "1",
                "relative widening at the extremes",
            ),
            (
                "reflex.twist",
                self.reflex_gains.twist,
                "rad",
                "twist angle at the extremes",
            ),
        ] {
            p.push(Parameter::new(name, value, unit, description));
        }
        for (i, m) in self.lattice.masses.iter().enumerate() {
            p.push(Parameter::new(
                format!("mass{i}.mass"),
                m.mass,
                "kg",
                "point mass",
            ));
        }
        for (j, s) in self.lattice.springs.iter().enumerate() {
            p.push(Parameter::new(
                format!("spring{j}.stiffness"),
                s.stiffness,
                "N/m",
                "spring constant k",
            ));
            p.push(Parameter::new(
                format!("spring{j}.damping"),
                s.damping,
                "N*s/m",
                "damping constant D",
            ));
            p.push(Parameter::new(
                format!("spring{j}.rest_length"),
                self.rest_lengths[j],
                "m",
                "active rest length L",
            ));
        }
        p
    }
    fn default_dt(&self) -> f64 {
        0.01
    }
}

impl Ode for LatticeModel {
    fn derivative(&self, x: &[f64], u: &[f64], dx: &mut [f64]) {
        let n = self.lattice.n_masses();
        let rest = if u.len() == self.lattice.springs.len() {
            u
        } else {
            &self.rest_lengths[..]
        };
        let (dp, dv) = dx.split_at_mut(3 * n);
        dp.copy_from_slice(&x[3 * n..]);
        dv.fill(0.0);
        self.add_spring_forces(x, rest, dv);
        let fl = &self.floor;
        for (i, m) in self.lattice.masses.iter().enumerate() {
            let f = &mut dv[3 * i..3 * i + 3];
            f[2] -= m.mass * self.gravity;
            let (z, v) = (x[3 * i + 2], &x[3 * n + 3 * i..3 * n + 3 * i + 3]);
            if self.in_contact(z, v[2]) {
                let normal = (-f[2]).max(0.0);
                f[2] += normal;
                // Force that would stop the tangential motion within τ, clipped to Coulomb.
                let want = [
                    -f[0] - m.mass * v[0] / fl.stick_time,
                    -f[1] - m.mass * v[1] / fl.stick_time,
                ];
                let size = (want[0] * want[0] + want[1] * want[1]).sqrt();
                let limit = fl.coefficient([-want[0], -want[1]]) * normal;
                let scale = if size > limit { limit / size } else { 1.0 };
                f[0] += want[0] * scale;
                f[1] += want[1] * scale;
            }
            for fk in f.iter_mut() {
                *fk /= m.mass;
            }
        }
    }

    fn position_dim(&self) -> Option<usize> {
        Some(3 * self.lattice.n_masses())
    }

    fn energy(&self, x: &[f64]) -> Option<f64> {
        let n = self.lattice.n_masses();
        let p = self.positions(x);
        let gravity: f64 = (0..n)
            .map(|i| self.lattice.masses[i].mass * self.gravity * x[3 * i + 2])
            .sum();
        let elastic: f64 = lengths(&p, &self.lattice.springs)
            .iter()
            .zip(&self.lattice.springs)
            .zip(&self.rest_lengths)
            .map(|((l, s), l0)| 0.5 * s.stiffness * (l - l0).powi(2))
            .sum();
        Some(self.kinetic_energy(x) + gravity + elastic)
    }
}

/// Counters of the contact events of a [`LatticeSim`].
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct ContactStats {
    /// Masses whose normal velocity was removed by an impact.
    pub impacts: u64,
    /// Integration intervals cut short at an impact time.
    pub events: u64,
    /// Re-integrations while localizing impact times.
    pub retries: u64,
    /// Deepest penetration below the floor at the end of an integration interval, before the
    /// impact projection (m, ≥ 0).
    pub deepest: f64,
}

/// Adaptive RK45 integration of a [`LatticeModel`] with impacts handled as events.
///
/// `step(x, u, dt)` integrates with the crate's adaptive Dormand–Prince integrator (step size
/// carried over between calls). When a mass ends an interval more than
/// [`Floor::contact_tolerance`] below the floor, the interval is redone up to the first
/// crossing time, estimated from the cubic Hermite interpolant of each mass's height
/// (z, v_z at both ends); repeated until no mass is below the tolerance. Then the impact
/// impulses are applied (normal velocity removed, tangential velocity reduced by at most
/// μ_eff·|v_z|, height set to 0) and integration continues from there. Between impacts the
/// right-hand side is smooth apart from contact making and breaking, so the step-size control
/// never has to resolve a collision by shrinking its steps.
#[derive(Debug, Clone)]
pub struct LatticeSim {
    /// The model.
    pub model: LatticeModel,
    integrator: Integrator,
    start: Vec<f64>,
    stats: ContactStats,
}

/// Largest number of re-integrations spent localizing one impact.
const MAX_LOCALIZE: usize = 40;

impl LatticeSim {
    /// A simulator with relative tolerance 1e−6 and absolute tolerance 1e−8.
    pub fn new(model: LatticeModel) -> Self {
        let n = model.state_dim();
        Self {
            model,
            integrator: Integrator::new(IntegratorKind::Rk45, n).with_tolerances(1e-6, 1e-8),
            start: vec![0.0; n],
            stats: ContactStats::default(),
        }
    }

    /// Sets the integrator's relative and absolute tolerances.
    pub fn with_tolerances(mut self, rtol: f64, atol: f64) -> Self {
        self.integrator = self.integrator.with_tolerances(rtol, atol);
        self
    }

    /// Sets the smallest internal RK45 step (s), below which a step is accepted whatever its
    /// error estimate: bounds the work when contact making and breaking chatters.
    pub fn with_min_step(mut self, min_step: f64) -> Self {
        self.integrator.min_step = min_step;
        self
    }

    /// The integrator's counters (accepted and rejected RK45 steps, evaluations).
    pub fn integrator_stats(&self) -> Rk45Stats {
        self.integrator.stats()
    }

    /// The contact counters.
    pub fn contact_stats(&self) -> ContactStats {
        self.stats
    }

    /// Lowest height (m) of any mass in `x`.
    fn lowest(&self, x: &[f64]) -> f64 {
        let n = self.model.lattice.n_masses();
        (0..n).map(|i| x[3 * i + 2]).fold(f64::INFINITY, f64::min)
    }

    /// Earliest time in (0, h] at which a mass that ends below the tolerance crosses z = 0,
    /// from the cubic Hermite interpolant between `self.start` and `x`.
    fn first_crossing(&self, x: &[f64], h: f64) -> f64 {
        let n = self.model.lattice.n_masses();
        let tol = self.model.floor.contact_tolerance;
        let mut first = h;
        for i in 0..n {
            let (z1, v1) = (x[3 * i + 2], x[3 * n + 3 * i + 2]);
            if z1 >= -tol {
                continue;
            }
            let (z0, v0) = (self.start[3 * i + 2], self.start[3 * n + 3 * i + 2]);
            let z = |s: f64| {
                let (s2, s3) = (s * s, s * s * s);
                (2.0 * s3 - 3.0 * s2 + 1.0) * z0
                    + (s3 - 2.0 * s2 + s) * h * v0
                    + (-2.0 * s3 + 3.0 * s2) * z1
                    + (s3 - s2) * h * v1
            };
            // First sample below the floor, then bisection.
            const SAMPLES: usize = 32;
            let mut lo = 0.0;
            let mut hi = 1.0;
            for k in 1..=SAMPLES {
                let s = k as f64 / SAMPLES as f64;
                if z(s) < 0.0 {
                    hi = s;
                    break;
                }
                lo = s;
            }
            for _ in 0..60 {
                let mid = 0.5 * (lo + hi);
                if z(mid) < 0.0 {
                    hi = mid;
                } else {
                    lo = mid;
                }
            }
            first = first.min(hi * h);
        }
        first
    }

    /// Applies impacts to the masses on or below the floor; returns how many were moving
    /// down faster than the velocity tolerance.
    fn impacts(&mut self, x: &mut [f64]) -> u64 {
        let n = self.model.lattice.n_masses();
        let floor = self.model.floor;
        let mut count = 0;
        for i in 0..n {
            let (iz, iv) = (3 * i + 2, 3 * n + 3 * i);
            let (z, vz) = (x[iz], x[iv + 2]);
            if z < 0.0 {
                x[iz] = 0.0;
            }
            if z <= floor.contact_tolerance && vz < 0.0 {
                x[iz] = 0.0;
                x[iv + 2] = 0.0;
                if vz < -floor.velocity_tolerance {
                    count += 1;
                }
                // Coulomb impulse: the tangential velocity loses at most μ·|Δv_n|.
                let vt = [x[iv], x[iv + 1]];
                let speed = (vt[0] * vt[0] + vt[1] * vt[1]).sqrt();
                if speed > 0.0 {
                    let cut = (floor.coefficient(vt) * -vz).min(speed);
                    x[iv] -= vt[0] / speed * cut;
                    x[iv + 1] -= vt[1] / speed * cut;
                }
            }
        }
        count
    }
}

impl Dynamics for LatticeSim {
    fn state_dim(&self) -> usize {
        self.model.state_dim()
    }
    fn control_dim(&self) -> usize {
        self.model.control_dim()
    }
    fn step(&mut self, x: &mut [f64], u: &[f64], dt: f64) {
        let tol = self.model.floor.contact_tolerance;
        self.stats.impacts += self.impacts(x);
        let mut left = dt;
        while left > 0.0 {
            self.start.copy_from_slice(x);
            let mut h = left;
            self.integrator.step(&self.model, x, u, h);
            let mut tries = 0;
            while self.lowest(x) < -tol && tries < MAX_LOCALIZE {
                let s = self.first_crossing(x, h);
                // Always shrink, so the loop makes progress even on a poor estimate, but never
                // below the integrator's smallest step: a step of f64::MIN_POSITIVE would leave
                // `left` unchanged and loop forever (seen when contact chatters).
                h = s.min(0.9 * h).max(self.integrator.min_step.min(left));
                x.copy_from_slice(&self.start);
                self.integrator.step(&self.model, x, u, h);
                self.stats.retries += 1;
                tries += 1;
            }
            if h < left {
                self.stats.events += 1;
            }
            self.stats.deepest = self.stats.deepest.max(-self.lowest(x));
            self.stats.impacts += self.impacts(x);
            left = if h < left { left - h } else { 0.0 };
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn free_cube(damping: bool) -> LatticeModel {
        let mut lattice = Lattice::cube();
        if !damping {
            for s in &mut lattice.springs {
                s.damping = 0.0;
            }
        }
        LatticeModel::new(lattice).unwrap().with_gravity(0.0)
    }

    /// A perturbed cube far above the floor with random velocities.
    fn tumbling_state(model: &LatticeModel, seed: u64) -> Vec<f64> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut x = model.lattice.placed_state([0.3, -0.2, 0.5], 5.0, [0.0; 3]);
        for v in x.iter_mut() {
            *v += rng.random_range(-0.1..0.1);
        }
        x
    }

    fn max_speed(model: &LatticeModel, x: &[f64]) -> f64 {
        let n = model.lattice.n_masses();
        x[3 * n..]
            .chunks(3)
            .map(|v| (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt())
            .fold(0.0, f64::max)
    }

    #[test]
    fn shipped_lattices_are_valid_and_round_trip() {
        for (lattice, n, ns) in [
            (Lattice::cube(), 8, 28),
            (Lattice::pyramid(), 5, 10),
            (Lattice::chair(), 10, 35),
        ] {
            lattice.validate().unwrap();
            assert_eq!((lattice.n_masses(), lattice.springs.len()), (n, ns));
            let json = serde_json::to_string(&lattice).unwrap();
            let back: Lattice = serde_json::from_str(&json).unwrap();
            assert_eq!(back, lattice);
            let model = LatticeModel::new(lattice).unwrap();
            assert_eq!(model.state_dim(), 6 * n);
            assert_eq!(model.control_dim(), ns);
            assert!(model.parameters().iter().all(|p| !p.unit.is_empty()));
        }
        // The cube: 12 edges, 12 face diagonals, 4 body diagonals.
        let rest = Lattice::cube().rest_lengths();
        for (len, count) in [(1.0, 12), (2f64.sqrt(), 12), (3f64.sqrt(), 4)] {
            let c = rest.iter().filter(|l| (*l - len).abs() < 1e-12).count();
            assert_eq!(c, count, "springs of length {len}");
        }
        let mut bad = Lattice::cube();
        bad.springs[3].b = 8;
        assert_eq!(bad.validate(), Err(LatticeError::InvalidEnds(3, 0, 8)));
        let mut model = LatticeModel::new(Lattice::pyramid()).unwrap();
        assert_eq!(
            model.set_rest_lengths(&[1.0; 3]),
            Err(LatticeError::RestLengthCount(3, 10))
        );
    }

    #[test]
    fn spring_forces_conserve_momentum() {
        // Damped springs, no gravity, no floor contact: Σ m a = 0 and Σ r × m a = 0.
        let model = free_cube(true);
        let n = model.lattice.n_masses();
        for seed in 0..5 {
            let x = tumbling_state(&model, seed);
            let u: Vec<f64> = model.rest_lengths.iter().map(|l| 0.9 * l).collect();
            let mut dx = vec![0.0; 6 * n];
            model.derivative(&x, &u, &mut dx);
            let (mut p, mut l) = (Vector3::zeros(), Vector3::zeros());
            let mut scale: f64 = 0.0;
            for (i, m) in model.lattice.masses.iter().enumerate() {
                let f = m.mass * Vector3::from_column_slice(&dx[3 * n + 3 * i..3 * n + 3 * i + 3]);
                let r = Vector3::from_column_slice(&x[3 * i..3 * i + 3]);
                p += f;
                l += r.cross(&f);
                scale = scale.max(f.norm());
            }
            assert!(scale > 1.0, "forces should be non-trivial: {scale}");
            assert!(p.norm() < 1e-12 * scale, "net force {p}");
            assert!(l.norm() < 1e-11 * scale, "net torque {l}");
        }
    }

    #[test]
    fn power_balance_of_damped_springs_and_gravity() {
        // Away from the floor, dE/dt = −Σ D ℓ̇² (springs' damping only), checked by central
        // differences along the flow.
        let model = LatticeModel::new(Lattice::chair()).unwrap();
        let x = tumbling_state(&model, 3);
        let mut dx = vec![0.0; x.len()];
        model.derivative(&x, &[], &mut dx);
        let h = 1e-6;
        let energy_at = |s: f64| {
            let y: Vec<f64> = x.iter().zip(&dx).map(|(a, b)| a + s * b).collect();
            model.energy(&y).unwrap()
        };
        let de = (energy_at(h) - energy_at(-h)) / (2.0 * h);
        let n = model.lattice.n_masses();
        let power: f64 = model
            .lattice
            .springs
            .iter()
            .map(|s| {
                let d = Vector3::from_column_slice(&x[3 * s.a..3 * s.a + 3])
                    - Vector3::from_column_slice(&x[3 * s.b..3 * s.b + 3]);
                let dv = Vector3::from_column_slice(&x[3 * n + 3 * s.a..3 * n + 3 * s.a + 3])
                    - Vector3::from_column_slice(&x[3 * n + 3 * s.b..3 * n + 3 * s.b + 3]);
                let rate = d.dot(&dv) / d.norm();
                -s.damping * rate * rate
            })
            .sum();
        assert!(power < -1e-3, "{power}");
        assert!(
            (de - power).abs() < 1e-6 * power.abs().max(1.0),
            "{de} vs {power}"
        );
    }

    #[test]
    fn undamped_free_lattice_conserves_energy() {
        let model = free_cube(false);
        let x0 = tumbling_state(&model, 7);
        let e0 = model.energy(&x0).unwrap();
        let mut sim = LatticeSim::new(model.clone()).with_tolerances(1e-10, 1e-12);
        let mut x = x0.clone();
        let mut worst: f64 = 0.0;
        for _ in 0..100 {
            sim.step(&mut x, &[], 0.02);
            worst = worst.max((model.energy(&x).unwrap() - e0).abs());
        }
        assert!(e0 > 0.01, "{e0}");
        assert!(worst < 1e-7 * e0, "energy drift {worst} of {e0}");
        // And damping dissipates it.
        let damped = free_cube(true);
        let mut sim = LatticeSim::new(damped.clone());
        let mut y = x0.clone();
        for _ in 0..100 {
            sim.step(&mut y, &[], 0.02);
        }
        assert!(damped.energy(&y).unwrap() < 0.5 * damped.energy(&x0).unwrap());
    }

    /// Settles `lattice` from its rest shape standing on the floor for `settle` seconds, then
    /// returns the largest displacement and speed seen over the next `watch` seconds.
    fn rest_drift(lattice: Lattice, settle: f64, watch: f64) -> (f64, f64, LatticeSim) {
        let model = LatticeModel::new(lattice).unwrap();
        let mut sim = LatticeSim::new(model.clone());
        let mut x = model.lattice.resting_state();
        let dt = 0.01;
        for _ in 0..(settle / dt) as usize {
            sim.step(&mut x, &[], dt);
        }
        let x1 = x.clone();
        let n = model.lattice.n_masses();
        let (mut drift, mut speed): (f64, f64) = (0.0, 0.0);
        for _ in 0..(watch / dt) as usize {
            sim.step(&mut x, &[], dt);
            for k in 0..3 * n {
                drift = drift.max((x[k] - x1[k]).abs());
            }
            speed = speed.max(max_speed(&model, &x));
            let low = (0..n).map(|i| x[3 * i + 2]).fold(f64::INFINITY, f64::min);
            assert!(low >= -model.floor.contact_tolerance, "penetration {low}");
        }
        (drift, speed, sim)
    }

    #[test]
    fn lattices_at_rest_on_the_floor_stay_at_rest() {
        for lattice in [Lattice::cube(), Lattice::pyramid(), Lattice::chair()] {
            let name = lattice.name.clone();
            // Standing up from the undeformed rest shape, the lattice sags under gravity and
            // its slowest modes take a few seconds to die out; then it must stay put.
            let (drift, speed, sim) = rest_drift(lattice, 10.0, 5.0);
            eprintln!(
                "{name}: drift {drift:.3e} m, speed {speed:.3e} m/s, {:?}, {:?}",
                sim.integrator_stats(),
                sim.contact_stats()
            );
            assert!(drift < 1e-6, "{name}: drift {drift} m");
            assert!(speed < 1e-5, "{name}: speed {speed} m/s");
        }
    }

    #[test]
    fn dropped_cube_comes_to_rest_on_the_floor() {
        let model = LatticeModel::new(Lattice::cube()).unwrap();
        let mut sim = LatticeSim::new(model.clone());
        // Tilted, 0.5 m up, moving sideways: corners land one after another.
        let mut x = model
            .lattice
            .placed_state([0.3, 0.2, 0.1], 0.5, [0.5, 0.0, 0.0]);
        let n = model.lattice.n_masses();
        let mut lowest = f64::INFINITY;
        for _ in 0..600 {
            sim.step(&mut x, &[], 0.01);
            lowest = (0..n).map(|i| x[3 * i + 2]).fold(lowest, f64::min);
            check_all_finite(&x);
        }
        let stats = sim.integrator_stats();
        let contact = sim.contact_stats();
        eprintln!("dropped cube: {stats:?}, {contact:?}, lowest {lowest:e}");
        assert!(
            lowest >= -model.floor.contact_tolerance,
            "penetration {lowest}"
        );
        assert!(
            contact.deepest <= model.floor.contact_tolerance,
            "{contact:?}"
        );
        assert!(contact.impacts >= 4, "{contact:?}");
        assert!(model.contacts(&x) >= 4, "ends standing on a face");
        assert!(
            max_speed(&model, &x) < 1e-4,
            "speed {}",
            max_speed(&model, &x)
        );
        // No stall: a bounded number of RK45 steps for 6 s.
        assert!(stats.accepted + stats.rejected < 20_000, "{stats:?}");
    }

    #[test]
    fn hopping_cube_in_low_gravity_does_not_stall() {
        // Alternating squash and stretch along z every 0.4 s: repeated take-offs and landings.
        let model = LatticeModel::new(Lattice::cube())
            .unwrap()
            .with_gravity(LOW_GRAVITY);
        let squash = reflex::deform(&model.lattice, 2, -0.3, &model.reflex_gains).unwrap();
        let stretch = reflex::deform(&model.lattice, 2, 0.3, &model.reflex_gains).unwrap();
        let mut sim = LatticeSim::new(model.clone());
        let mut x = model.lattice.resting_state();
        let (mut top, mut airborne) = (0.0f64, 0);
        for k in 0..800 {
            let u = if (k / 40) % 2 == 0 {
                &squash.rest_lengths
            } else {
                &stretch.rest_lengths
            };
            sim.step(&mut x, u, 0.01);
            check_all_finite(&x);
            top = top.max(model.center_of_mass(&x)[2]);
            if model.contacts(&x) == 0 {
                airborne += 1;
            }
        }
        let (stats, contact) = (sim.integrator_stats(), sim.contact_stats());
        eprintln!("hopping cube: {stats:?}, {contact:?}, top {top:.3} m, airborne {airborne}");
        assert!(airborne > 20, "it should leave the floor: {airborne}");
        assert!(contact.impacts >= 8, "{contact:?}");
        assert!(
            contact.deepest <= model.floor.contact_tolerance,
            "{contact:?}"
        );
        assert!(stats.accepted + stats.rejected < 50_000, "{stats:?}");
    }

    fn check_all_finite(x: &[f64]) {
        assert!(x.iter().all(|v| v.is_finite()));
    }

    /// Distance the cube's centre of mass slides along `dir` (±x) from rest on the floor when
    /// launched with 1 m/s along it, with preferred direction +x.
    fn slide(dir: f64) -> f64 {
        let floor = Floor {
            friction: 0.2,
            preferred_friction: 0.6,
            preferred_direction: [1.0, 0.0],
            ..Floor::default()
        };
        let model = LatticeModel::new(Lattice::cube())
            .unwrap()
            .with_floor(floor)
            .unwrap();
        let mut sim = LatticeSim::new(model.clone());
        let mut x = model.lattice.resting_state();
        for _ in 0..100 {
            sim.step(&mut x, &[], 0.01);
        }
        let n = model.lattice.n_masses();
        for i in 0..n {
            x[3 * n + 3 * i] += dir;
        }
        let c0 = model.center_of_mass(&x);
        for _ in 0..300 {
            sim.step(&mut x, &[], 0.01);
        }
        assert!(max_speed(&model, &x) < 1e-3, "still moving");
        (model.center_of_mass(&x)[0] - c0[0]) * dir
    }

    #[test]
    fn directional_friction_resists_the_preferred_direction() {
        let along = slide(1.0);
        let against = slide(-1.0);
        eprintln!("slide along {along:.4} m, against {against:.4} m");
        // Coulomb: d = v²/(2 μ g) = 0.255 m for μ = 0.2 and 0.085 m for μ = 0.6 when all the
        // kinetic energy goes into sliding friction; rocking and spring damping take a bit more.
        assert!(along > 0.0 && against > 0.0);
        assert!(along < 0.5 * against, "along {along}, against {against}");
        assert!(
            against < 0.255 * 1.02 && against > 0.255 * 0.85,
            "against {against}"
        );
        assert!(along < 0.085 * 1.02 && along > 0.085 * 0.5, "along {along}");
    }

    #[test]
    fn reflex_rest_lengths_are_reached_in_free_space() {
        // Zero gravity, no floor contact: the lattice relaxes to the deformed rest shape.
        let mut model = LatticeModel::new(Lattice::cube())
            .unwrap()
            .with_gravity(0.0);
        model.apply_reflex(11, 0.8).unwrap(); // twist_z
        let target = model.rest_lengths.clone();
        let mut sim = LatticeSim::new(model.clone());
        let mut x = model.lattice.placed_state([0.0; 3], 3.0, [0.0; 3]);
        for _ in 0..300 {
            sim.step(&mut x, &[], 0.01);
        }
        let now = lengths(&model.positions(&x), &model.lattice.springs);
        for (a, b) in now.iter().zip(&target) {
            assert!((a - b).abs() < 1e-5, "{a} vs {b}");
        }
        // Explicit controls override the active rest lengths.
        let mut dx = vec![0.0; x.len()];
        let mut dy = vec![0.0; x.len()];
        model.derivative(&x, &[], &mut dx);
        model.derivative(&x, &Lattice::cube().rest_lengths(), &mut dy);
        assert!(dx.iter().zip(&dy).any(|(a, b)| (a - b).abs() > 1e-3));
    }

    #[test]
    fn resting_contact_cancels_gravity_and_friction_holds() {
        // A single mass on the floor: the normal force cancels gravity exactly; a sliding
        // mass decelerates by μ g.
        let lattice = Lattice {
            name: "one".into(),
            masses: vec![PointMass {
                position: [0.0; 3],
                mass: 2.0,
            }],
            springs: vec![],
        };
        let model = LatticeModel::new(lattice).unwrap();
        let mut dx = [0.0; 6];
        model.derivative(&[0.0; 6], &[], &mut dx);
        assert_eq!(dx, [0.0; 6]);
        model.derivative(&[0.0, 0.0, 0.0, 3.0, 0.0, 0.0], &[], &mut dx);
        assert!((dx[3] + model.floor.friction * EARTH_GRAVITY).abs() < 1e-12);
        // Sliding along / against the preferred direction stops after v²/(2 μ g).
        let floor = Floor {
            friction: 0.2,
            preferred_friction: 0.6,
            preferred_direction: [0.0, 1.0],
            ..Floor::default()
        };
        let model = model.with_floor(floor).unwrap();
        let bad = Floor {
            stick_time: 0.0,
            ..floor
        };
        assert_eq!(
            bad.validate(),
            Err(LatticeError::InvalidFloor("stick_time", 0.0))
        );
        for (dir, mu) in [(1.0, 0.6), (-1.0, 0.2)] {
            let mut sim = LatticeSim::new(model.clone());
            let mut x = [0.0, 0.0, 0.0, 0.0, 2.0 * dir, 0.0];
            for _ in 0..300 {
                sim.step(&mut x, &[], 0.01);
            }
            let want = 4.0 / (2.0 * mu * EARTH_GRAVITY);
            assert!(x[4].abs() < 1e-9, "still sliding at {}", x[4]);
            assert!(
                (x[1] * dir - want).abs() < 1e-3 * want,
                "{} vs {want}",
                x[1]
            );
            assert_eq!((x[0], x[2]), (0.0, 0.0));
        }
        // In flight, gravity only.
        model.derivative(&[0.0, 0.0, 1.0, 3.0, 0.0, 0.0], &[], &mut dx);
        assert_eq!(&dx[3..], &[0.0, 0.0, -EARTH_GRAVITY]);
    }
}
