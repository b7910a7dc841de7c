//! # Lattice geometry: point masses, springs and the shipped shapes
//!
//! A [`Lattice`] is data: point masses at rest positions and springs between them, each with
//! stiffness k, damping D and rest length L (by default the rest distance |p_a − p_b|). Three
//! lattices ship (Christensen, Marks, Ngo 1995, Fig. 1): the cube (8 masses, all 28 pairs
//! joined), the pyramid or "spider" (5 masses, 10 springs) and the chair (10 masses, 35
//! springs). [`Lattice::placed_state`] rotates and lifts the rest shape into a start state.
//!
//! ## References
//! - J. Christensen, J. Marks, J. T. Ngo, *Automatic Motion Synthesis for 3D Mass-Spring
//!   Models*, The Visual Computer 13(1), 1997 (MERL TR95-01).

use super::LatticeError;
use nalgebra::{Matrix3, Vector3};
use serde::{Deserialize, Serialize};

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
        let rot = axis_angle_rotation(rotation);
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

/// The rotation by the axis × angle vector `v` (Rodrigues' formula as nalgebra's
/// `Rotation3::new` writes it, with [`crate::portable::sin_cos`]: the same bits everywhere).
fn axis_angle_rotation(v: [f64; 3]) -> Matrix3<f64> {
    let angle = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    if angle == 0.0 {
        return Matrix3::identity();
    }
    let (ux, uy, uz) = (v[0] / angle, v[1] / angle, v[2] / angle);
    let (sqx, sqy, sqz) = (ux * ux, uy * uy, uz * uz);
    let (sin, cos) = crate::portable::sin_cos(angle);
    let one_m_cos = 1.0 - cos;
    Matrix3::new(
        sqx + (1.0 - sqx) * cos,
        ux * uy * one_m_cos - uz * sin,
        ux * uz * one_m_cos + uy * sin,
        ux * uy * one_m_cos + uz * sin,
        sqy + (1.0 - sqy) * cos,
        uy * uz * one_m_cos - ux * sin,
        ux * uz * one_m_cos - uy * sin,
        uy * uz * one_m_cos + ux * sin,
        sqz + (1.0 - sqz) * cos,
    )
}

/// Distances |p_a − p_b| for each spring.
pub fn lengths(p: &[[f64; 3]], springs: &[Spring]) -> Vec<f64> {
    springs
        .iter()
        .map(|s| (Vector3::from(p[s.a]) - Vector3::from(p[s.b])).norm())
        .collect()
}
