//! # Observables of the dolphin: centre of mass, momenta, energies, shape and segment frames
//!
//! Quantities computed from a state x = [q, v] without integrating it:
//!
//! ```text
//! c = Σ mᵢ pᵢ / M,   P = Σ mᵢ vᵢ,   L = Σ mᵢ pᵢ × vᵢ,   T = ½ Σ mᵢ |vᵢ|²,
//! U_spring = ½ Σ k (L − L₀)²,        V = ⅓ Σ_faces (vector area · face mean) (closed surface),
//! ```
//!
//! the shape error against the rest shape after removing the best rigid motion, and the rigid
//! frame of each segment ([`SegmentFrame`]: mass-weighted centroid of its frame masses, an
//! orientation fitted to them, and their mean linear and angular velocity), which the
//! hierarchical emulator uses as its global state (NeuroAnimator §3.3, Fig. 7).
//!
//! ## References
//! - R. Grzeszczuk, D. Terzopoulos, G. Hinton, *NeuroAnimator*, SIGGRAPH 1998, §3.3.

use super::*;

/// The rigid frame of one body segment (NeuroAnimator's local centre of mass, Fig. 7).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SegmentFrame {
    /// Mass-weighted centroid of the segment's frame masses (m).
    pub centroid: Vector3<f64>,
    /// Best-fit rotation taking the segment's rest shape to its current shape (identity at rest).
    pub orientation: UnitQuaternion<f64>,
    /// Velocity of the centroid (m/s).
    pub velocity: Vector3<f64>,
    /// Angular velocity in the world frame, I⁻¹ Σ m r × v about the centroid (rad/s).
    pub angular_velocity: Vector3<f64>,
}

impl SegmentFrame {
    /// The 13 numbers `[centroid, quaternion (w, x, y, z) with w ≥ 0, velocity, angular
    /// velocity]`; six of them make the 78 state inputs of the paper's global net (Table 1).
    pub fn to_array(&self) -> [f64; 13] {
        let q = self.orientation.quaternion();
        let s = if q.w < 0.0 { -1.0 } else { 1.0 };
        let (c, v, w) = (self.centroid, self.velocity, self.angular_velocity);
        [
            c.x,
            c.y,
            c.z,
            s * q.w,
            s * q.i,
            s * q.j,
            s * q.k,
            v.x,
            v.y,
            v.z,
            w.x,
            w.y,
            w.z,
        ]
    }

    /// The 13 numbers of [`SegmentFrame::to_array`] with the quaternion's sign chosen so that
    /// its dot product with `reference` (`[w, x, y, z]`) is not negative, rather than w ≥ 0.
    ///
    /// A rotation has two quaternions, ±q. Forcing w ≥ 0 makes the representation jump from q
    /// to −q wherever a segment's rotation passes through a half turn (e.g. the heading passes
    /// ±π), so neighbouring segments and successive steps disagree in sign. Choosing the sign
    /// against a nearby rotation — the reference segment's, or the same segment's at the
    /// previous step — keeps the numbers continuous (NeuroAnimator §3.3's global net learns
    /// their changes).
    pub fn to_array_aligned(&self, reference: [f64; 4]) -> [f64; 13] {
        let mut a = self.to_array();
        let dot: f64 = (0..4).map(|k| a[3 + k] * reference[k]).sum();
        if dot < 0.0 {
            for v in &mut a[3..7] {
                *v = -*v;
            }
        }
        a
    }

    /// A world point expressed in the segment's frame.
    pub fn to_local(&self, p: &Vector3<f64>) -> Vector3<f64> {
        self.orientation
            .inverse_transform_vector(&(p - self.centroid))
    }

    /// A point given in the segment's frame, in world coordinates.
    pub fn to_world(&self, p: &Vector3<f64>) -> Vector3<f64> {
        self.centroid + self.orientation.transform_vector(p)
    }
}

impl Dolphin {
    /// Centre of mass of state (or positions) `x` (m).
    pub fn centre_of_mass(&self, x: &[f64]) -> Vector3<f64> {
        self.weighted_mean(&x[..N_POS])
    }

    /// Velocity of the centre of mass (m/s).
    pub fn centre_of_mass_velocity(&self, x: &[f64]) -> Vector3<f64> {
        self.weighted_mean(&x[N_POS..2 * N_POS])
    }

    fn weighted_mean(&self, q: &[f64]) -> Vector3<f64> {
        let mut s = Vector3::zeros();
        for (i, m) in self.masses.iter().enumerate() {
            s += *m * point(q, i);
        }
        s / self.total_mass()
    }

    /// Total linear momentum Σ m v (kg·m/s).
    pub fn momentum(&self, x: &[f64]) -> Vector3<f64> {
        self.centre_of_mass_velocity(x) * self.total_mass()
    }

    /// Total angular momentum Σ m p × v about the world origin (kg·m²/s).
    pub fn angular_momentum(&self, x: &[f64]) -> Vector3<f64> {
        let (q, v) = x.split_at(N_POS);
        (0..N_MASSES)
            .map(|i| self.masses[i] * point(q, i).cross(&point(v, i)))
            .sum()
    }

    /// Unit vector from the centre of mass to the nose: the body's forward axis (+x at rest).
    pub fn forward_axis(&self, x: &[f64]) -> Vector3<f64> {
        (point(x, NOSE) - self.centre_of_mass(x)).normalize()
    }

    /// Mean over the springs of |L − L₀| / L₀ with the relaxed rest lengths L₀: 0 in the rest
    /// shape, growing as the body deforms (NeuroAnimator §5.3's unnatural deformations).
    pub fn shape_error(&self, x: &[f64]) -> f64 {
        let q = &x[..N_POS];
        self.springs
            .iter()
            .map(|s| {
                let l = (point(q, s.b) - point(q, s.a)).norm();
                (l - s.rest_length).abs() / s.rest_length
            })
            .sum::<f64>()
            / self.springs.len() as f64
    }

    /// Volume enclosed by the surface faces (m³); a collapsing or inverting body loses it.
    pub fn volume(&self, x: &[f64]) -> f64 {
        let q = &x[..N_POS];
        self.faces
            .iter()
            .map(|f| f.vector_area(q).dot(&f.mean(q)))
            .sum::<f64>()
            / 3.0
    }

    /// Kinetic energy ½ Σ m |v|² (J).
    pub fn kinetic_energy(&self, x: &[f64]) -> f64 {
        let v = &x[N_POS..2 * N_POS];
        (0..N_MASSES)
            .map(|i| 0.5 * self.masses[i] * point(v, i).norm_squared())
            .sum()
    }

    /// Elastic energy ½ Σ k (L − L₀)² with relaxed muscles (J).
    pub fn spring_energy(&self, x: &[f64]) -> f64 {
        let q = &x[..N_POS];
        self.springs
            .iter()
            .map(|s| {
                let d = (point(q, s.b) - point(q, s.a)).norm() - s.rest_length;
                0.5 * s.stiffness * d * d
            })
            .sum()
    }

    /// Rigid frame of segment `s` (0..6) fitted to [`segment_frame_masses`]: mass-weighted
    /// centroid and velocity, the best-fit (Kabsch) rotation from the rest shape, and the
    /// angular velocity that best explains the masses' velocities about the centroid.
    pub fn segment_frame(&self, x: &[f64], s: usize) -> SegmentFrame {
        let (q, v) = x.split_at(N_POS);
        let idx = segment_frame_masses(s);
        let mut m_tot = 0.0;
        let (mut c, mut c0, mut vc) = (Vector3::zeros(), Vector3::zeros(), Vector3::zeros());
        for &i in idx {
            let m = self.masses[i];
            m_tot += m;
            c += m * point(q, i);
            c0 += m * point(&self.rest, i);
            vc += m * point(v, i);
        }
        c /= m_tot;
        c0 /= m_tot;
        vc /= m_tot;
        let mut h = Matrix3::zeros();
        let mut inertia = Matrix3::zeros();
        let mut ang = Vector3::zeros();
        for &i in idx {
            let m = self.masses[i];
            let r = point(q, i) - c;
            let r0 = point(&self.rest, i) - c0;
            h += m * r * r0.transpose();
            inertia += m * (Matrix3::identity() * r.norm_squared() - r * r.transpose());
            ang += m * r.cross(&(point(v, i) - vc));
        }
        // Kabsch: R maximising tr(Rᵀ H) is U diag(1, 1, det(U Vᵀ)) Vᵀ for H = U Σ Vᵀ.
        let svd = h.svd(true, true);
        let (u, vt) = (svd.u.unwrap(), svd.v_t.unwrap());
        let d = (u * vt).determinant().signum();
        let rot = u * Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, d)) * vt;
        let orientation =
            UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(rot));
        let angular_velocity = inertia
            .try_inverse()
            .map(|inv| inv * ang)
            .unwrap_or_else(Vector3::zeros);
        SegmentFrame {
            centroid: c,
            orientation,
            velocity: vc,
            angular_velocity,
        }
    }

    /// The frames of all six segments.
    pub fn segment_frames(&self, x: &[f64]) -> [SegmentFrame; N_SEGMENTS] {
        std::array::from_fn(|s| self.segment_frame(x, s))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn segment_frames_follow_rigid_motion() {
        let d = Dolphin::default();
        let rest = d.rest_state();
        let frames0 = d.segment_frames(&rest);
        let rot = UnitQuaternion::from_euler_angles(0.3, 0.9, -2.0);
        let (t, v0, w) = (
            Vector3::new(1.0, 2.0, -3.0),
            Vector3::new(0.5, 0.0, -0.2),
            Vector3::new(0.1, -0.4, 0.7),
        );
        let mut x = rest.clone();
        for i in 0..N_MASSES {
            let p = rot * point(&rest, i) + t;
            let v = v0 + w.cross(&p);
            x[3 * i..3 * i + 3].copy_from_slice(p.as_slice());
            x[N_POS + 3 * i..N_POS + 3 * i + 3].copy_from_slice(v.as_slice());
        }
        for (s, (f0, f)) in frames0.iter().zip(d.segment_frames(&x)).enumerate() {
            assert!(f0.orientation.angle() < 1e-12 && f0.angular_velocity.norm() < 1e-12);
            let c = rot * f0.centroid + t;
            assert!((f.centroid - c).norm() < 1e-12, "{s}");
            assert!(f.orientation.angle_to(&rot) < 1e-9, "{s}");
            assert!((f.velocity - (v0 + w.cross(&c))).norm() < 1e-12, "{s}");
            assert!((f.angular_velocity - w).norm() < 1e-10, "{s}");
            let p = point(&x, segment_frame_masses(s)[0]);
            assert!((f.to_world(&f.to_local(&p)) - p).norm() < 1e-12);
            assert!(f.to_array()[3] >= 0.0);
            // Aligned to a reference: the same rotation, the sign that agrees with it.
            let a = f.to_array();
            let neg = [-a[3], -a[4], -a[5], -a[6]];
            let b = f.to_array_aligned(neg);
            assert_eq!(b[3..7], neg[..]);
            assert_eq!(f.to_array_aligned([a[3], a[4], a[5], a[6]]), a);
        }
        assert!((d.forward_axis(&x) - rot * Vector3::x()).norm() < 1e-12);
        assert!(d.shape_error(&x) < 1e-14);
    }
}
