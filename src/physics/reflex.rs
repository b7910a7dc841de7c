//! # The 12 canonical actuation reflexes (Christensen, Marks, Ngo 1995, §2.2, Fig. 3)
//!
//! A reflex is a global deformation of the lattice's rest shape: scale, shear, splay or twist,
//! about the rest shape's centre of mass c, along one of the three lattice-centric axes (the
//! axes of the frame the rest positions are written in). The rest lengths of the regime are the
//! spring lengths of the deformed rest shape, so a reflex number R ∈ 0..=11 and a coefficient
//! α ∈ [−1, 1] determine every rest length.
//!
//! Numbering: R = 3·kind + axis with kind 0 scale, 1 shear, 2 splay, 3 twist and axis 0 x,
//! 1 y, 2 z. For axis a let b = a+1, c = a+2 (mod 3), r = p − c the position relative to the
//! centre of mass, h_a = max |r_a| over the masses and ρ = r_a / h_a ∈ [−1, 1]:
//!
//! - **scale**: r_a ← (1 + κα) r_a (stretch or squash along a);
//! - **shear**: r_b ← r_b + γα r_a (layers across a slide along b);
//! - **splay**: r_b ← (1 + σαρ) r_b, r_c ← (1 + σαρ) r_c (the +a end widens, the −a end
//!   narrows, for α > 0);
//! - **twist**: (r_b, r_c) rotated about a by θ = τ α ρ (the two ends turn opposite ways).
//!
//! κ, γ, σ, τ are the [`ReflexGains`]. The paper gives no magnitudes; the defaults (0.5, 0.5,
//! 0.5, π/6) make α = ±1 an exaggerated but non-degenerate deformation.
//!
//! A reflex can be rigid for a particular lattice, and then changes no rest length: e.g. the
//! pyramid's `twist_z`, whose base is a single layer and whose apex lies on the axis.

use super::lattice::{lengths, Lattice, LatticeError};
use serde::{Deserialize, Serialize};

/// The kind of global deformation.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Hash)]
#[serde(rename_all = "snake_case")]
pub enum ReflexKind {
    /// Stretch or squash along the axis.
    Scale,
    /// Slide layers across the axis along the next axis.
    Shear,
    /// Widen one end and narrow the other.
    Splay,
    /// Turn the two ends opposite ways about the axis.
    Twist,
}

/// One of the 12 reflexes: a deformation kind along a lattice axis.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Hash)]
#[serde(deny_unknown_fields)]
pub struct Reflex {
    /// The deformation.
    pub kind: ReflexKind,
    /// The lattice-centric axis: 0 x, 1 y, 2 z.
    pub axis: usize,
}

impl Reflex {
    /// Number of reflexes.
    pub const COUNT: usize = 12;

    /// The reflex with number `r` = 3·kind + axis.
    pub fn from_number(r: usize) -> Result<Self, LatticeError> {
        let kind = match r / 3 {
            0 => ReflexKind::Scale,
            1 => ReflexKind::Shear,
            2 => ReflexKind::Splay,
            3 => ReflexKind::Twist,
            _ => return Err(LatticeError::InvalidReflex(r)),
        };
        Ok(Self { kind, axis: r % 3 })
    }

    /// Its number 0–11.
    pub fn number(self) -> usize {
        let k = match self.kind {
            ReflexKind::Scale => 0,
            ReflexKind::Shear => 1,
            ReflexKind::Splay => 2,
            ReflexKind::Twist => 3,
        };
        3 * k + self.axis
    }

    /// Short name, e.g. `twist_z`.
    pub fn name(self) -> String {
        let kind = match self.kind {
            ReflexKind::Scale => "scale",
            ReflexKind::Shear => "shear",
            ReflexKind::Splay => "splay",
            ReflexKind::Twist => "twist",
        };
        format!("{kind}_{}", ["x", "y", "z"][self.axis % 3])
    }
}

/// Magnitudes of the reflexes at |α| = 1.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ReflexGains {
    /// κ: relative stretch along the axis (dimensionless).
    pub scale: f64,
    /// γ: shear strain, displacement along b per unit of r_a (dimensionless).
    pub shear: f64,
    /// σ: relative widening of the +a end (dimensionless).
    pub splay: f64,
    /// τ: twist angle of the +a end (rad).
    pub twist: f64,
}

impl Default for ReflexGains {
    fn default() -> Self {
        Self {
            scale: 0.5,
            shear: 0.5,
            splay: 0.5,
            twist: std::f64::consts::FRAC_PI_6,
        }
    }
}

/// The deformed rest shape of a reflex and the rest lengths it implies.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Deformation {
    /// Deformed rest positions in the lattice frame (m), one per mass.
    pub positions: Vec<[f64; 3]>,
    /// Spring rest lengths of the regime (m), one per spring.
    pub rest_lengths: Vec<f64>,
}

/// Deforms `lattice`'s rest shape by reflex `number` (0–11) with coefficient `alpha`
/// ∈ [−1, 1]; returns the deformed positions and the resulting rest lengths.
pub fn deform(
    lattice: &Lattice,
    number: usize,
    alpha: f64,
    gains: &ReflexGains,
) -> Result<Deformation, LatticeError> {
    let reflex = Reflex::from_number(number)?;
    if !(alpha.is_finite() && (-1.0..=1.0).contains(&alpha)) {
        return Err(LatticeError::InvalidCoefficient(alpha));
    }
    lattice.validate()?;
    let rest = lattice.rest_positions();
    let c = lattice.center_of_mass(&rest);
    let (a, b, cc) = (reflex.axis, (reflex.axis + 1) % 3, (reflex.axis + 2) % 3);
    let half = rest.iter().map(|p| (p[a] - c[a]).abs()).fold(0.0, f64::max);
    let positions: Vec<[f64; 3]> = rest
        .iter()
        .map(|p| {
            let mut r = [p[0] - c[0], p[1] - c[1], p[2] - c[2]];
            let rho = if half > 0.0 { r[a] / half } else { 0.0 };
            match reflex.kind {
                ReflexKind::Scale => r[a] *= 1.0 + gains.scale * alpha,
                ReflexKind::Shear => r[b] += gains.shear * alpha * r[a],
                ReflexKind::Splay => {
                    let f = 1.0 + gains.splay * alpha * rho;
                    r[b] *= f;
                    r[cc] *= f;
                }
                ReflexKind::Twist => {
                    let (s, co) = crate::portable::sin_cos(gains.twist * alpha * rho);
                    let (rb, rc) = (r[b], r[cc]);
                    r[b] = co * rb - s * rc;
                    r[cc] = s * rb + co * rc;
                }
            }
            [r[0] + c[0], r[1] + c[1], r[2] + c[2]]
        })
        .collect();
    let rest_lengths = lengths(&positions, &lattice.springs);
    if let Some((j, &l)) = rest_lengths
        .iter()
        .enumerate()
        .find(|(_, l)| !(l.is_finite() && **l > 0.0))
    {
        return Err(LatticeError::InvalidRestLength(j, l));
    }
    Ok(Deformation {
        positions,
        rest_lengths,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    const GAINS: ReflexGains = ReflexGains {
        scale: 0.5,
        shear: 0.5,
        splay: 0.5,
        twist: std::f64::consts::FRAC_PI_6,
    };

    /// Index of the cube's spring between masses `a` and `b` (index = x + 2y + 4z).
    fn spring(cube: &Lattice, a: usize, b: usize) -> usize {
        cube.springs
            .iter()
            .position(|s| (s.a, s.b) == (a.min(b), a.max(b)))
            .expect("cube has all pairs")
    }

    fn assert_length(cube: &Lattice, d: &Deformation, a: usize, b: usize, want: f64) {
        let got = d.rest_lengths[spring(cube, a, b)];
        assert!((got - want).abs() < 1e-12, "{a}-{b}: {got} vs {want}");
    }

    #[test]
    fn numbers_round_trip_and_are_validated() {
        for r in 0..Reflex::COUNT {
            assert_eq!(Reflex::from_number(r).unwrap().number(), r);
        }
        assert_eq!(Reflex::from_number(11).unwrap().name(), "twist_z");
        assert_eq!(
            Reflex::from_number(12),
            Err(LatticeError::InvalidReflex(12))
        );
        let cube = Lattice::cube();
        assert_eq!(
            deform(&cube, 0, 1.5, &GAINS),
            Err(LatticeError::InvalidCoefficient(1.5))
        );
        assert!(deform(&cube, 0, f64::NAN, &GAINS).is_err());
    }

    #[test]
    fn zero_coefficient_leaves_rest_lengths_unchanged() {
        for lattice in [Lattice::cube(), Lattice::pyramid(), Lattice::chair()] {
            let rest = lattice.rest_lengths();
            for r in 0..Reflex::COUNT {
                let d = deform(&lattice, r, 0.0, &GAINS).unwrap();
                for (j, (a, b)) in d.rest_lengths.iter().zip(&rest).enumerate() {
                    assert!(
                        (a - b).abs() < 1e-12,
                        "{} reflex {r} spring {j}",
                        lattice.name
                    );
                }
                // A non-zero coefficient changes some of them, except the pyramid's twist
                // about its vertical axis: its base is one layer and its apex is on the axis,
                // so that twist is a rigid rotation.
                if lattice.name == "lattice_pyramid" && r == 11 {
                    continue;
                }
                let d = deform(&lattice, r, 0.7, &GAINS).unwrap();
                let change = d
                    .rest_lengths
                    .iter()
                    .zip(&rest)
                    .map(|(a, b)| (a - b).abs())
                    .fold(0.0, f64::max);
                assert!(change > 1e-3, "{} reflex {r} changes nothing", lattice.name);
            }
        }
    }

    #[test]
    fn scale_on_unit_cube() {
        let cube = Lattice::cube();
        let s: f64 = 1.0 + 0.5 * 0.6;
        let d = deform(&cube, 2, 0.6, &GAINS).unwrap(); // scale_z
        assert_length(&cube, &d, 0, 4, s); // vertical edge
        assert_length(&cube, &d, 0, 1, 1.0); // x edge
        assert_length(&cube, &d, 0, 3, 2f64.sqrt()); // bottom face diagonal
        assert_length(&cube, &d, 0, 5, (1.0 + s * s).sqrt()); // xz face diagonal
        assert_length(&cube, &d, 0, 7, (2.0 + s * s).sqrt()); // body diagonal
        let d = deform(&cube, 0, -1.0, &GAINS).unwrap(); // scale_x squash
        assert_length(&cube, &d, 0, 1, 0.5);
        assert_length(&cube, &d, 0, 4, 1.0);
        // The centre of mass does not move.
        let c = cube.center_of_mass(&d.positions);
        assert!(c.iter().all(|v| (v - 0.5).abs() < 1e-12), "{c:?}");
    }

    #[test]
    fn shear_on_unit_cube() {
        let cube = Lattice::cube();
        let g: f64 = 0.5 * 0.6; // top moves +g/2 along x, bottom −g/2
        let d = deform(&cube, 5, 0.6, &GAINS).unwrap(); // shear_z: x += γα r_z
        assert_length(&cube, &d, 0, 4, (1.0 + g * g).sqrt()); // tilted vertical edge
        assert_length(&cube, &d, 0, 5, (1.0 + (1.0 + g).powi(2)).sqrt()); // long diagonal
        assert_length(&cube, &d, 1, 4, (1.0 + (1.0 - g).powi(2)).sqrt()); // short diagonal
        assert_length(&cube, &d, 0, 1, 1.0); // horizontal edges unchanged
        assert_length(&cube, &d, 0, 2, 1.0);
        assert_length(&cube, &d, 0, 6, (2.0 + g * g).sqrt()); // yz face diagonal
        let top = d.positions[4];
        assert!((top[0] - g / 2.0).abs() < 1e-12 && (top[2] - 1.0).abs() < 1e-12);
    }

    #[test]
    fn twist_on_unit_cube() {
        let cube = Lattice::cube();
        let theta: f64 = 0.6 * std::f64::consts::FRAC_PI_6; // top +θ, bottom −θ about z
        let d = deform(&cube, 11, 0.6, &GAINS).unwrap(); // twist_z
        let s = theta.sin();
        let c = theta.cos();
        // A vertical edge spans a chord 2·(1/√2)·sin θ horizontally.
        assert_length(&cube, &d, 0, 4, (1.0 + 2.0 * s * s).sqrt());
        // Body diagonals span a chord 2·(1/√2)·cos θ.
        assert_length(&cube, &d, 0, 7, (1.0 + 2.0 * c * c).sqrt());
        // Top and bottom faces turn rigidly.
        assert_length(&cube, &d, 4, 5, 1.0);
        assert_length(&cube, &d, 4, 7, 2f64.sqrt());
        assert_length(&cube, &d, 0, 1, 1.0);
        // Heights are unchanged.
        for (p, q) in d.positions.iter().zip(cube.rest_positions()) {
            assert!((p[2] - q[2]).abs() < 1e-12);
        }
    }

    #[test]
    fn splay_on_unit_cube() {
        let cube = Lattice::cube();
        let d = deform(&cube, 8, 0.6, &GAINS).unwrap(); // splay_z: top ×1.3, bottom ×0.7
        assert_length(&cube, &d, 4, 5, 1.3);
        assert_length(&cube, &d, 0, 1, 0.7);
        assert_length(&cube, &d, 0, 4, (1.0 + 2.0 * 0.3f64.powi(2)).sqrt());
    }
}
