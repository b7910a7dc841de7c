//! # Objective functions from sampled trajectories (Christensen, Marks, Ngo 1995, Table 1)
//!
//! An [`Objective`] is a weighted sum Σ w_k · term_k(trajectory) (larger is better; a
//! negative weight makes a term a penalty). The terms, computed from the samples of a
//! [`Trajectory`] (c(t) the centre of mass, t_0 = 0 … t_K = T the sample times):
//!
//! - `displacement`: final horizontal displacement (c(T) − c(0))·d along a unit direction d (m);
//! - `horizontal_distance`: net horizontal displacement |c_xy(T) − c_xy(0)| (m);
//! - `max_height`: max_k c_z(t_k) − c_z(0) (m);
//! - `min_contacts`: the minimum over samples of the number of masses in contact with the
//!   floor (height ≤ `contact_height`);
//! - `contact_time`: the time with at least one mass in contact, Σ_{k ≥ 1} Δt · [contact at
//!   t_k] (s);
//! - `rotation`: total rotation of the body frame of a triplet of masses about the centre of
//!   mass, signed about a world axis a: Σ_k a · log(R_k R_{k−1}ᵀ) (rad; `absolute` takes the
//!   magnitude of the sum);
//! - `orientation_loss`: a boolean (0 or 1): whether a body axis (facing x, left-right y, up z
//!   of the lattice-centric frame) ever (or, with `at_end_only`, at T) turns more than
//!   `max_angle_deg` from its initial world direction — loss of front-facing direction,
//!   left-right orientation or uprightness;
//! - `asymmetry`: the average over samples and masses of |q_i − S_a q_{m(i)}|, with q the
//!   positions in the body frame about the centre of mass, S_a the reflection across the
//!   plane normal to lattice axis a and m(i) the mirror partner of mass i in the rest shape (m);
//! - `hops`: how many times the lattice goes from touching the floor to fully airborne;
//! - `on_ground`: a boolean, 1 when some mass touches the floor at T.
//!
//! The body frame is the orthonormal frame of a triplet of masses (p_0, p_1, p_2):
//! e_1 ∥ p_1 − p_0, e_2 ∥ the part of p_2 − p_0 orthogonal to e_1, e_3 = e_1 × e_2;
//! R_k = F(t_k) F_restᵀ maps lattice-centric axes to world axes.

use super::controller::Trajectory;
use super::SynthesisError;
use nalgebra::{Matrix3, Vector3};
use serde::{Deserialize, Serialize};

/// Which body axis an orientation term watches.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Orientation {
    /// The lattice x axis (front-facing direction).
    Facing,
    /// The lattice y axis (left-right orientation).
    LeftRight,
    /// The lattice z axis (uprightness).
    Upright,
}

impl Orientation {
    fn axis(self) -> usize {
        match self {
            Orientation::Facing => 0,
            Orientation::LeftRight => 1,
            Orientation::Upright => 2,
        }
    }
}

/// One objective term (Table 1); see the module docs for the formulas.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum Term {
    /// Final horizontal displacement of the centre of mass along `direction` (m).
    Displacement {
        /// Horizontal direction (x, y), normalized on use.
        direction: [f64; 2],
    },
    /// Net horizontal displacement of the centre of mass, any direction (m).
    HorizontalDistance,
    /// Maximum rise of the centre of mass above its initial height (m).
    MaxHeight,
    /// Minimum number of masses in contact with the floor.
    MinContacts,
    /// Time with at least one mass on the floor (s).
    ContactTime,
    /// Total rotation of the triplet frame about a world axis (rad).
    Rotation {
        /// World axis (normalized on use); the sign of the rotation is about this axis.
        axis: [f64; 3],
        /// Take the magnitude of the net rotation.
        #[serde(default)]
        absolute: bool,
    },
    /// 1 when the body axis turned more than `max_angle_deg` from its start direction.
    OrientationLoss {
        /// Which axis.
        orientation: Orientation,
        /// Largest tolerated angle (degrees).
        max_angle_deg: f64,
        /// Check only the final sample (else every sample).
        #[serde(default)]
        at_end_only: bool,
    },
    /// Average asymmetry about lattice axis `axis` (0 x, 1 y, 2 z) (m).
    Asymmetry {
        /// The mirror axis.
        axis: usize,
    },
    /// Number of take-offs (contact → no contact).
    Hops,
    /// 1 when the lattice touches the floor at T.
    OnGround,
}

impl Term {
    /// Name of the term, for tables (`orientation_loss` terms name their axis).
    pub fn name(&self) -> String {
        match self {
            Term::Displacement { .. } => "displacement".into(),
            Term::HorizontalDistance => "horizontal_distance".into(),
            Term::MaxHeight => "max_height".into(),
            Term::MinContacts => "min_contacts".into(),
            Term::ContactTime => "contact_time".into(),
            Term::Rotation { .. } => "rotation".into(),
            Term::OrientationLoss { orientation, .. } => match orientation {
                Orientation::Facing => "facing_loss".into(),
                Orientation::LeftRight => "left_right_loss".into(),
                Orientation::Upright => "uprightness_loss".into(),
            },
            Term::Asymmetry { axis } => format!("asymmetry_{}", ["x", "y", "z"][axis % 3]),
            Term::Hops => "hops".into(),
            Term::OnGround => "on_ground".into(),
        }
    }
}

/// A term with its weight.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Weighted {
    /// Weight (negative for a penalty).
    pub weight: f64,
    /// The term.
    pub term: Term,
}

/// A weighted sum of terms, with the contact threshold and the triplet of the body frame.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Objective {
    /// The terms.
    pub terms: Vec<Weighted>,
    /// Height (m) at or below which a mass counts as touching the floor.
    pub contact_height: f64,
    /// Three non-collinear masses defining the body frame.
    pub frame_masses: [usize; 3],
}

fn norm(v: &[f64]) -> f64 {
    v.iter().map(|x| x * x).sum::<f64>().sqrt()
}

impl Objective {
    /// Checks weights, directions, axes and the triplet against a lattice of `n_masses`
    /// masses with rest positions `rest`.
    pub fn validate(&self, rest: &[[f64; 3]]) -> Result<(), SynthesisError> {
        let n = rest.len();
        if !(self.contact_height.is_finite() && self.contact_height >= 0.0) {
            return Err(SynthesisError::Invalid(
                "contact_height",
                self.contact_height,
            ));
        }
        let [a, b, c] = self.frame_masses;
        for i in [a, b, c] {
            if i >= n {
                return Err(SynthesisError::Invalid("frame mass", i as f64));
            }
        }
        if frame(&rest[a], &rest[b], &rest[c]).is_none() {
            return Err(SynthesisError::Invalid(
                "frame masses (collinear)",
                a as f64,
            ));
        }
        for w in &self.terms {
            if !w.weight.is_finite() {
                return Err(SynthesisError::Invalid("weight", w.weight));
            }
            match &w.term {
                Term::Displacement { direction } if !(norm(direction) > 0.0) => {
                    return Err(SynthesisError::Invalid("direction", norm(direction)))
                }
                Term::Rotation { axis, .. } if !(norm(axis) > 0.0) => {
                    return Err(SynthesisError::Invalid("rotation axis", norm(axis)))
                }
                Term::OrientationLoss { max_angle_deg, .. }
                    if !(max_angle_deg.is_finite() && *max_angle_deg >= 0.0) =>
                {
                    return Err(SynthesisError::Invalid("max_angle_deg", *max_angle_deg))
                }
                Term::Asymmetry { axis } if *axis > 2 => {
                    return Err(SynthesisError::Invalid("asymmetry axis", *axis as f64))
                }
                _ => {}
            }
        }
        Ok(())
    }

    /// The value of every term, in order (unweighted).
    pub fn values(&self, tr: &Trajectory) -> Vec<f64> {
        let ctx = Context::new(self, tr);
        self.terms.iter().map(|w| ctx.term(&w.term)).collect()
    }

    /// Σ weight · value.
    pub fn total(&self, tr: &Trajectory) -> f64 {
        self.values(tr)
            .iter()
            .zip(&self.terms)
            .map(|(v, w)| w.weight * v)
            .sum()
    }
}

/// Orthonormal frame (columns e1, e2, e3) of a triplet, or None when collinear.
fn frame(p0: &[f64; 3], p1: &[f64; 3], p2: &[f64; 3]) -> Option<Matrix3<f64>> {
    let (p0, p1, p2) = (Vector3::from(*p0), Vector3::from(*p1), Vector3::from(*p2));
    let e1 = (p1 - p0).try_normalize(1e-12)?;
    let u = p2 - p0;
    let e2 = (u - e1 * e1.dot(&u)).try_normalize(1e-12)?;
    let e3 = e1.cross(&e2);
    Some(Matrix3::from_columns(&[e1, e2, e3]))
}

/// Per-trajectory quantities shared by the terms.
struct Context<'a> {
    obj: &'a Objective,
    tr: &'a Trajectory,
    com: Vec<[f64; 3]>,
    /// Body rotation R_k (lattice axes → world) per sample.
    rot: Vec<Matrix3<f64>>,
    contacts: Vec<usize>,
}

impl<'a> Context<'a> {
    fn new(obj: &'a Objective, tr: &'a Trajectory) -> Self {
        let [a, b, c] = obj.frame_masses;
        let rest = frame(&tr.rest[a], &tr.rest[b], &tr.rest[c]).unwrap_or_else(Matrix3::identity);
        let rot = tr
            .frames
            .iter()
            .map(|f| {
                frame(&f.positions[a], &f.positions[b], &f.positions[c])
                    .map(|m| m * rest.transpose())
                    .unwrap_or_else(Matrix3::identity)
            })
            .collect();
        let contacts = tr
            .frames
            .iter()
            .map(|f| {
                f.positions
                    .iter()
                    .filter(|p| p[2] <= obj.contact_height)
                    .count()
            })
            .collect();
        Self {
            obj,
            tr,
            com: tr.coms(),
            rot,
            contacts,
        }
    }

    fn term(&self, term: &Term) -> f64 {
        let (c0, c1) = (self.com[0], self.com[self.com.len() - 1]);
        let k = self.contacts.len();
        match term {
            Term::Displacement { direction } => {
                let n = norm(direction);
                ((c1[0] - c0[0]) * direction[0] + (c1[1] - c0[1]) * direction[1]) / n
            }
            Term::HorizontalDistance => crate::portable::hypot(c1[0] - c0[0], c1[1] - c0[1]),
            Term::MaxHeight => {
                self.com
                    .iter()
                    .map(|c| c[2])
                    .fold(f64::NEG_INFINITY, f64::max)
                    - c0[2]
            }
            Term::MinContacts => self.contacts.iter().copied().min().unwrap_or(0) as f64,
            Term::ContactTime => (1..k)
                .filter(|&i| self.contacts[i] > 0)
                .map(|i| self.tr.frames[i].t - self.tr.frames[i - 1].t)
                .sum(),
            Term::Rotation { axis, absolute } => {
                let a = Vector3::from(*axis).normalize();
                let total: f64 = self
                    .rot
                    .windows(2)
                    .map(|w| scaled_axis(&(w[1] * w[0].transpose())).dot(&a))
                    .sum();
                if *absolute {
                    total.abs()
                } else {
                    total
                }
            }
            Term::OrientationLoss {
                orientation,
                max_angle_deg,
                at_end_only,
            } => {
                let i = orientation.axis();
                let start = self.rot[0].column(i).into_owned();
                let cos_max = crate::portable::cos(max_angle_deg.to_radians());
                let lost = |r: &Matrix3<f64>| r.column(i).dot(&start) < cos_max;
                let any = if *at_end_only {
                    lost(&self.rot[self.rot.len() - 1])
                } else {
                    self.rot.iter().any(lost)
                };
                if any {
                    1.0
                } else {
                    0.0
                }
            }
            Term::Asymmetry { axis } => self.asymmetry(*axis),
            Term::Hops => (1..k)
                .filter(|&i| self.contacts[i - 1] > 0 && self.contacts[i] == 0)
                .count() as f64,
            Term::OnGround => {
                if self.contacts[k - 1] > 0 {
                    1.0
                } else {
                    0.0
                }
            }
        }
    }

    fn asymmetry(&self, axis: usize) -> f64 {
        let tr = self.tr;
        let rc = tr.com(&tr.rest);
        let rel: Vec<Vector3<f64>> = tr
            .rest
            .iter()
            .map(|p| Vector3::from(*p) - Vector3::from(rc))
            .collect();
        let flip = |mut v: Vector3<f64>| {
            v[axis] = -v[axis];
            v
        };
        // Mirror partner of each mass in the rest shape.
        let partner: Vec<usize> = rel
            .iter()
            .map(|r| {
                let m = flip(*r);
                (0..rel.len())
                    .min_by(|&i, &j| (rel[i] - m).norm().total_cmp(&(rel[j] - m).norm()))
                    .unwrap_or(0)
            })
            .collect();
        let n = rel.len() as f64;
        let mut sum = 0.0;
        for (f, (r, c)) in tr.frames.iter().zip(self.rot.iter().zip(&self.com)) {
            let q: Vec<Vector3<f64>> = f
                .positions
                .iter()
                .map(|p| r.transpose() * (Vector3::from(*p) - Vector3::from(*c)))
                .collect();
            sum += (0..q.len())
                .map(|i| (q[i] - flip(q[partner[i]])).norm())
                .sum::<f64>()
                / n;
        }
        let _ = self.obj;
        sum / tr.frames.len() as f64
    }
}

/// The axis × angle vector of the rotation matrix `m`: θ = atan2(|v|, tr m − 1) with v the
/// skew part (m₃₂ − m₂₃, m₁₃ − m₃₁, m₂₁ − m₁₂) = 2 sin θ · axis, axis = v / |v| (zero below
/// nalgebra's ε). nalgebra's `scaled_axis` takes θ from libm's `acos` (processor-dependent
/// last bits, and inaccurate for the small angles between frames); this is
/// [`crate::portable::atan2`].
fn scaled_axis(m: &Matrix3<f64>) -> Vector3<f64> {
    let v = Vector3::new(
        m[(2, 1)] - m[(1, 2)],
        m[(0, 2)] - m[(2, 0)],
        m[(1, 0)] - m[(0, 1)],
    );
    let n = v.norm();
    if n <= f64::EPSILON {
        return Vector3::zeros();
    }
    let angle = crate::portable::atan2(n, m.trace() - 1.0);
    v * (angle / n)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scaled_axis_is_nalgebras() {
        for (k, rv) in [
            [0.3, -0.2, 0.1],
            [1e-4, 2e-5, -3e-5],
            [0.0, 2.5, 0.4],
            [0.0; 3],
        ]
        .iter()
        .enumerate()
        {
            let r = nalgebra::Rotation3::new(Vector3::from(*rv));
            let ours = scaled_axis(r.matrix());
            let tol = if k == 1 { 1e-12 } else { 1e-14 };
            assert!((ours - r.scaled_axis()).norm() <= tol, "{rv:?}: {ours}");
            assert!((ours - Vector3::from(*rv)).norm() <= 1e-14, "{rv:?}");
        }
    }
    use crate::physics::lattice::Lattice;
    use crate::synthesis::controller::Frame;

    /// A hand-made trajectory of the unit cube: `motion(t)` gives (translation, rotation
    /// vector about the centre of mass) at each of the sample times.
    fn traj(times: &[f64], motion: impl Fn(f64) -> ([f64; 3], [f64; 3])) -> Trajectory {
        let cube = Lattice::cube();
        let rest = cube.rest_positions();
        let c = Vector3::new(0.5, 0.5, 0.5);
        let frames = times
            .iter()
            .map(|&t| {
                let (dx, rv) = motion(t);
                let r = nalgebra::Rotation3::new(Vector3::from(rv));
                Frame {
                    t,
                    positions: rest
                        .iter()
                        .map(|p| (r * (Vector3::from(*p) - c) + c + Vector3::from(dx)).into())
                        .collect(),
                    regime: 0,
                }
            })
            .collect();
        Trajectory {
            masses: vec![1.0; 8],
            rest,
            frames,
        }
    }

    fn obj(term: Term) -> Objective {
        Objective {
            terms: vec![Weighted { weight: 2.0, term }],
            contact_height: 1e-3,
            frame_masses: [0, 1, 2],
        }
    }

    fn value(term: Term, tr: &Trajectory) -> f64 {
        let o = obj(term);
        o.validate(&tr.rest).unwrap();
        let v = o.values(tr)[0];
        assert!((o.total(tr) - 2.0 * v).abs() < 1e-12);
        v
    }

    fn times(n: usize, dt: f64) -> Vec<f64> {
        (0..=n).map(|k| k as f64 * dt).collect()
    }

    #[test]
    fn displacement_height_and_distance() {
        // Moves 3 m along x and 4 m along y, rising to 2 m at t = 0.5 and landing.
        let tr = traj(&times(10, 0.1), |t| {
            (
                [3.0 * t, 4.0 * t, 2.0 * (1.0 - (2.0 * t - 1.0).powi(2))],
                [0.0; 3],
            )
        });
        let d = |dir| value(Term::Displacement { direction: dir }, &tr);
        assert!((d([1.0, 0.0]) - 3.0).abs() < 1e-12);
        assert!((d([0.0, -2.0]) + 4.0).abs() < 1e-12);
        assert!((value(Term::HorizontalDistance, &tr) - 5.0).abs() < 1e-12);
        assert!((value(Term::MaxHeight, &tr) - 2.0).abs() < 1e-12);
    }

    #[test]
    fn contacts_contact_time_hops_and_on_ground() {
        // Two hops: airborne on (0.2, 0.4) and (0.6, 0.8] with samples every 0.1 s.
        let air = |t: f64| (t > 0.15 && t < 0.45) || t > 0.55;
        let tr = traj(&times(8, 0.1), |t| {
            ([0.0, 0.0, if air(t) { 0.3 } else { 0.0 }], [0.0; 3])
        });
        assert_eq!(value(Term::MinContacts, &tr), 0.0);
        assert_eq!(value(Term::Hops, &tr), 2.0);
        // In contact at t = 0.1, 0.5: 2 intervals of 0.1 s.
        assert!((value(Term::ContactTime, &tr) - 0.2).abs() < 1e-12);
        assert_eq!(value(Term::OnGround, &tr), 0.0);
        // Resting: four masses always in contact, on the ground at T, no hops.
        let rest = traj(&times(4, 0.1), |_| ([0.0; 3], [0.0; 3]));
        assert_eq!(value(Term::MinContacts, &rest), 4.0);
        assert_eq!(value(Term::OnGround, &rest), 1.0);
        assert_eq!(value(Term::Hops, &rest), 0.0);
        assert!((value(Term::ContactTime, &rest) - 0.4).abs() < 1e-12);
    }

    #[test]
    fn rotation_accumulates_a_full_backward_somersault() {
        // One full turn about −y (backward when moving +x), in 40 steps.
        let tr = traj(&times(40, 0.025), |t| {
            ([0.0, 0.0, 1.0], [0.0, -2.0 * std::f64::consts::PI * t, 0.0])
        });
        let two_pi = 2.0 * std::f64::consts::PI;
        let back = value(
            Term::Rotation {
                axis: [0.0, -1.0, 0.0],
                absolute: false,
            },
            &tr,
        );
        assert!((back - two_pi).abs() < 1e-9, "{back}");
        let fwd = value(
            Term::Rotation {
                axis: [0.0, 1.0, 0.0],
                absolute: true,
            },
            &tr,
        );
        assert!((fwd - two_pi).abs() < 1e-9, "{fwd}");
        let yaw = value(
            Term::Rotation {
                axis: [0.0, 0.0, 1.0],
                absolute: false,
            },
            &tr,
        );
        assert!(yaw.abs() < 1e-9);
        // The somersault loses uprightness and facing on the way, but not left-right, and
        // ends upright.
        let loss = |o, end| {
            value(
                Term::OrientationLoss {
                    orientation: o,
                    max_angle_deg: 45.0,
                    at_end_only: end,
                },
                &tr,
            )
        };
        assert_eq!(loss(Orientation::Upright, false), 1.0);
        assert_eq!(loss(Orientation::Facing, false), 1.0);
        assert_eq!(loss(Orientation::LeftRight, false), 0.0);
        assert_eq!(loss(Orientation::Upright, true), 0.0);
    }

    #[test]
    fn a_quarter_yaw_loses_facing_but_not_uprightness() {
        let tr = traj(&times(10, 0.1), |t| {
            ([0.0; 3], [0.0, 0.0, 0.5 * std::f64::consts::PI * t])
        });
        let loss = |o| {
            value(
                Term::OrientationLoss {
                    orientation: o,
                    max_angle_deg: 60.0,
                    at_end_only: false,
                },
                &tr,
            )
        };
        assert_eq!(loss(Orientation::Facing), 1.0);
        assert_eq!(loss(Orientation::LeftRight), 1.0);
        assert_eq!(loss(Orientation::Upright), 0.0);
        let yaw = value(
            Term::Rotation {
                axis: [0.0, 0.0, 2.0],
                absolute: false,
            },
            &tr,
        );
        assert!((yaw - 0.5 * std::f64::consts::PI).abs() < 1e-9);
    }

    #[test]
    fn asymmetry_is_zero_for_rigid_motion_and_measures_a_shear() {
        let tr = traj(&times(5, 0.1), |t| ([t, 0.0, 0.2], [0.1 * t, 0.2, 0.3 * t]));
        for axis in 0..3 {
            assert!(value(Term::Asymmetry { axis }, &tr) < 1e-9);
        }
        // Shift the top face (z = 1) by +s along x in every frame: asymmetric about x
        // (the mirror of a top mass at x is the top mass at 1 − x, shifted the same way).
        let s = 0.2;
        let mut sheared = traj(&times(2, 0.1), |_| ([0.0; 3], [0.0; 3]));
        for f in &mut sheared.frames {
            for p in &mut f.positions {
                if p[2] > 0.5 {
                    p[0] += s;
                }
            }
        }
        // Body frame from masses 0, 1, 2 (bottom face) is unchanged; com shifts by s/2 in x.
        // Top masses: q_x = x + s − 0.5 − s/2, mirror partner at 1 − x: |q + S q'| = s;
        // bottom masses: q_x = x − 0.5 − s/2, partner gives |2·(−s/2)| = s. Mean s.
        let a = value(Term::Asymmetry { axis: 0 }, &sheared);
        assert!((a - s).abs() < 1e-9, "{a}");
        assert!(value(Term::Asymmetry { axis: 1 }, &sheared) < 1e-9);
    }

    #[test]
    fn validation_and_toml_form() {
        let rest = Lattice::cube().rest_positions();
        let mut o = obj(Term::Displacement {
            direction: [0.0, 0.0],
        });
        assert!(o.validate(&rest).is_err());
        o.terms[0].term = Term::MaxHeight;
        o.frame_masses = [0, 1, 9];
        assert!(o.validate(&rest).is_err());
        o.frame_masses = [0, 1, 1];
        assert!(o.validate(&rest).is_err());
        let w: Weighted = toml::from_str(
            "weight = -1.0\nterm = { kind = \"orientation_loss\", orientation = \"upright\", max_angle_deg = 60.0 }",
        )
        .unwrap();
        assert_eq!(w.term.name(), "uprightness_loss");
        let w: Weighted = toml::from_str("weight = 1.0\nterm = { kind = \"hops\" }").unwrap();
        assert_eq!(w.term, Term::Hops);
        assert!(toml::from_str::<Weighted>(
            "weight = 1.0\nterm = { kind = \"displacement\", direction = [1.0, 0.0], extra = 1 }"
        )
        .is_err());
    }
}
