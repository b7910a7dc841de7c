//! # Spatial (6-D) vector algebra
//!
//! Featherstone's notation (*Rigid Body Dynamics Algorithms*, 2008, ch. 2): a motion vector
//! (spatial velocity, acceleration, a joint axis) is `[ω; v]`, angular part first, v the
//! velocity of the body-fixed point at the frame's origin; a force vector is `[n; f]`, the
//! moment n about the frame's origin first. Both are [`Vector6`] here; which one a vector is
//! follows from its name and use.
//!
//! A Plücker transform ᴮX_A maps motion vectors from A coordinates to B coordinates. With E
//! the rotation taking A coordinates to B coordinates and r the position of B's origin in A
//! coordinates,
//!
//! ᴮX_A = [E, 0; −E r×, E],  ᴮX_A [ω; v] = [E ω; E (v − r × ω)],
//!
//! and a force f given in B coordinates is ᴮX_Aᵀ f = [Eᵀ n + r × Eᵀ f; Eᵀ f] in A coordinates
//! ([`Xform::force_to_parent`]), so that power f · m is the same in either frame.
//!
//! The spatial inertia of a body of mass m with centre of mass c and rotational inertia Ī_c
//! about it (both in the body's coordinates) is I = [Ī_c + m c× c×ᵀ, m c×; m c×ᵀ, m 1]
//! ([`inertia`]); its momentum is h = I v.
//!
//! Cross products: v ×ₘ m = [ω × m_ω; ω × m_v + v × m_ω] for motion vectors and
//! v ×* f = [ω × n + v × f; ω × f] for forces (Featherstone eq. 2.31–2.32).

use nalgebra::{Matrix3, Matrix6, Vector3, Vector6};

/// A motion vector `[ω; v]` or a force vector `[n; f]`.
pub type Spatial = Vector6<f64>;

/// The angular (first) half of a spatial vector.
#[inline]
pub fn top(s: &Spatial) -> Vector3<f64> {
    Vector3::new(s[0], s[1], s[2])
}

/// The linear (second) half of a spatial vector.
#[inline]
pub fn bottom(s: &Spatial) -> Vector3<f64> {
    Vector3::new(s[3], s[4], s[5])
}

/// Joins an angular and a linear half.
#[inline]
pub fn join(a: Vector3<f64>, b: Vector3<f64>) -> Spatial {
    Spatial::new(a.x, a.y, a.z, b.x, b.y, b.z)
}

/// The skew matrix a× with (a×) b = a × b.
#[inline]
pub fn skew(a: &Vector3<f64>) -> Matrix3<f64> {
    Matrix3::new(0.0, -a.z, a.y, a.z, 0.0, -a.x, -a.y, a.x, 0.0)
}

/// v ×ₘ m: the rate of change of motion vector m carried by a frame moving with velocity v.
#[inline]
pub fn cross_motion(v: &Spatial, m: &Spatial) -> Spatial {
    let (w, vl) = (top(v), bottom(v));
    join(w.cross(&top(m)), w.cross(&bottom(m)) + vl.cross(&top(m)))
}

/// v ×* f: the rate of change of force vector f carried by a frame moving with velocity v.
#[inline]
pub fn cross_force(v: &Spatial, f: &Spatial) -> Spatial {
    let (w, vl) = (top(v), bottom(v));
    join(w.cross(&top(f)) + vl.cross(&bottom(f)), w.cross(&bottom(f)))
}

/// Spatial inertia of a body of `mass` (kg) with centre of mass `com` (m) and rotational
/// inertia `icom` about it (kg·m²), all in the body's coordinates.
pub fn inertia(mass: f64, com: &Vector3<f64>, icom: &Matrix3<f64>) -> Matrix6<f64> {
    let cx = skew(com);
    let mut out = Matrix6::zeros();
    out.fixed_view_mut::<3, 3>(0, 0)
        .copy_from(&(icom + cx * cx.transpose() * mass));
    out.fixed_view_mut::<3, 3>(0, 3).copy_from(&(cx * mass));
    out.fixed_view_mut::<3, 3>(3, 0)
        .copy_from(&(cx.transpose() * mass));
    out.fixed_view_mut::<3, 3>(3, 3)
        .copy_from(&(Matrix3::identity() * mass));
    out
}

/// A Plücker transform ᴮX_A from a parent frame A to a child frame B.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Xform {
    /// Rotation taking A coordinates to B coordinates.
    pub e: Matrix3<f64>,
    /// Position of B's origin in A coordinates (m).
    pub r: Vector3<f64>,
}

impl Xform {
    /// The identity transform.
    pub fn identity() -> Self {
        Self {
            e: Matrix3::identity(),
            r: Vector3::zeros(),
        }
    }

    /// Motion vector m (A coordinates) in B coordinates: ᴮX_A m.
    #[inline]
    pub fn motion(&self, m: &Spatial) -> Spatial {
        let w = top(m);
        join(self.e * w, self.e * (bottom(m) - self.r.cross(&w)))
    }

    /// Force vector f (B coordinates) in A coordinates: ᴮX_Aᵀ f.
    #[inline]
    pub fn force_to_parent(&self, f: &Spatial) -> Spatial {
        let lin = self.e.transpose() * bottom(f);
        join(self.e.transpose() * top(f) + self.r.cross(&lin), lin)
    }

    /// The 6 × 6 matrix ᴮX_A.
    pub fn matrix(&self) -> Matrix6<f64> {
        let mut out = Matrix6::zeros();
        out.fixed_view_mut::<3, 3>(0, 0).copy_from(&self.e);
        out.fixed_view_mut::<3, 3>(3, 3).copy_from(&self.e);
        out.fixed_view_mut::<3, 3>(3, 0)
            .copy_from(&(-self.e * skew(&self.r)));
        out
    }

    /// Spatial inertia `i` (B coordinates) in A coordinates: ᴮX_Aᵀ I ᴮX_A.
    pub fn inertia_to_parent(&self, i: &Matrix6<f64>) -> Matrix6<f64> {
        let x = self.matrix();
        x.transpose() * i * x
    }
}

// Rotations and quaternions.

/// Rotation matrix of quaternion q = (w, x, y, z) divided by its norm; the identity for a
/// zero quaternion (so that an all-zero state stays finite).
pub fn quat_to_matrix(q: [f64; 4]) -> Matrix3<f64> {
    let [w, x, y, z] = q;
    let n2 = w * w + x * x + y * y + z * z;
    if n2 == 0.0 {
        return Matrix3::identity();
    }
    let s = 2.0 / n2;
    Matrix3::new(
        1.0 - s * (y * y + z * z),
        s * (x * y - w * z),
        s * (x * z + w * y),
        s * (x * y + w * z),
        1.0 - s * (x * x + z * z),
        s * (y * z - w * x),
        s * (x * z - w * y),
        s * (y * z + w * x),
        1.0 - s * (x * x + y * y),
    )
}

/// ½ q ⊗ (0, ω): the time derivative of quaternion q under angular velocity ω in the rotated
/// (body) frame.
pub fn quat_rate(q: [f64; 4], w: [f64; 3]) -> [f64; 4] {
    let [s, x, y, z] = q;
    let [a, b, c] = w;
    [
        0.5 * (-x * a - y * b - z * c),
        0.5 * (s * a + y * c - z * b),
        0.5 * (s * b + z * a - x * c),
        0.5 * (s * c + x * b - y * a),
    ]
}

/// Angle (rad) of the rotation a⁻¹ ⊗ b between quaternions a and b (each normalized first):
/// 2 atan2(|vec|, |w|), which keeps full precision for tiny angles and reads q and −q as the
/// same rotation.
pub fn quat_angle(a: &[f64], b: &[f64]) -> f64 {
    let (na, nb) = (
        a.iter().map(|c| c * c).sum::<f64>().sqrt(),
        b.iter().map(|c| c * c).sum::<f64>().sqrt(),
    );
    let (aw, av) = (a[0], Vector3::new(-a[1], -a[2], -a[3]));
    let (bw, bv) = (b[0], Vector3::new(b[1], b[2], b[3]));
    let w = (aw * bw - av.dot(&bv)) / (na * nb);
    let v = (bv * aw + av * bw + av.cross(&bv)) / (na * nb);
    2.0 * crate::portable::atan2(v.norm(), w.abs())
}

/// Rotation by `angle` (rad) about the unit `axis` (Rodrigues' formula, portable sine and
/// cosine).
pub fn axis_angle(axis: &Vector3<f64>, angle: f64) -> Matrix3<f64> {
    let (s, c) = crate::portable::sin_cos(angle);
    let k = skew(axis);
    Matrix3::identity() + k * s + k * k * (1.0 - c)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rot(a: f64, b: f64) -> Matrix3<f64> {
        let (sa, ca) = (a.sin(), a.cos());
        let (sb, cb) = (b.sin(), b.cos());
        Matrix3::new(ca, -sa, 0.0, sa, ca, 0.0, 0.0, 0.0, 1.0)
            * Matrix3::new(1.0, 0.0, 0.0, 0.0, cb, -sb, 0.0, sb, cb)
    }

    #[test]
    fn power_is_invariant_and_cross_products_are_dual() {
        let x = Xform {
            e: rot(0.4, -1.1),
            r: Vector3::new(0.3, -0.2, 0.7),
        };
        let m = Spatial::new(0.1, -0.5, 0.3, 1.2, 0.4, -0.8);
        let f = Spatial::new(-0.7, 0.2, 0.9, 0.5, -1.5, 0.25);
        // f_B · (X m_A) = (Xᵀ f_B) · m_A
        let p1 = f.dot(&x.motion(&m));
        let p2 = x.force_to_parent(&f).dot(&m);
        assert!((p1 - p2).abs() < 1e-14);
        assert!((x.matrix() * m - x.motion(&m)).norm() < 1e-14);
        // (v ×* f) · m = −f · (v ×ₘ m)
        let v = Spatial::new(0.3, 0.6, -0.2, -0.4, 0.1, 0.9);
        let a = cross_force(&v, &f).dot(&m);
        let b = -f.dot(&cross_motion(&v, &m));
        assert!((a - b).abs() < 1e-14);
    }

    #[test]
    fn inertia_gives_the_kinetic_energy_of_a_rigid_body() {
        let (m, c) = (2.0, Vector3::new(0.1, -0.3, 0.2));
        let ic = Matrix3::new(0.5, 0.02, -0.01, 0.02, 0.4, 0.03, -0.01, 0.03, 0.3);
        let v = Spatial::new(0.3, 0.6, -0.2, -0.4, 0.1, 0.9);
        let (w, vo) = (top(&v), bottom(&v));
        let vc = vo + w.cross(&c);
        let want = 0.5 * m * vc.norm_squared() + 0.5 * w.dot(&(ic * w));
        let got = 0.5 * v.dot(&(inertia(m, &c, &ic) * v));
        assert!((want - got).abs() < 1e-14);
    }
}
