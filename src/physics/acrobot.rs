//! # Acrobot: the two-link gymnast (linear Bellman combination, Fig. 7)
//!
//! Point masses m1, m2 at the ends of massless links of lengths l1, l2; the shoulder is a
//! passive pivot, the hip (joint 2) has a torque τ. State `[θ1, θ2, ω1, ω2]` in radians:
//! θ1 is link 1's angle from the +x axis, counter-clockwise (−π/2 hangs straight down, +π/2 is
//! the handstand), θ2 is link 2's angle relative to link 1.
//!
//! With h = m2 l1 l2 sin θ2, the equations are M(θ) θ̈ + c(θ, ω) + G(θ) = [0, τ] with
//!
//! - M11 = (m1 + m2) l1² + m2 l2² + 2 m2 l1 l2 cos θ2, M12 = m2 l2² + m2 l1 l2 cos θ2,
//!   M22 = m2 l2²;
//! - c1 = −h (2 ω1 ω2 + ω2²), c2 = h ω1²;
//! - G1 = (m1 + m2) g l1 cos θ1 + m2 g l2 cos(θ1 + θ2), G2 = m2 g l2 cos(θ1 + θ2).
//!
//! Analytic Jacobians ([`Linearize`]): writing r = [0, τ] − c − G so that θ̈ = M⁻¹ r, each
//! column of ∂θ̈/∂z is M⁻¹ (∂r/∂z − (∂M/∂z) θ̈); only M11 and M12 depend on θ2.

use super::linearize::Linearize;
use super::{Model, Ode, Parameter};
use crate::fastmath::sin_cos_x4;
use crate::lanes::{Real, X4};
use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};

/// The acrobot with the paper's unit masses and lengths by default.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Acrobot {
    /// Mass at the end of link 1 (kg).
    pub m1: f64,
    /// Mass at the end of link 2 (kg).
    pub m2: f64,
    /// Length of link 1 (m).
    pub l1: f64,
    /// Length of link 2 (m).
    pub l2: f64,
    /// Gravitational acceleration (m/s²).
    pub gravity: f64,
}

impl Default for Acrobot {
    fn default() -> Self {
        Self {
            m1: 1.0,
            m2: 1.0,
            l1: 1.0,
            l2: 1.0,
            gravity: 9.81,
        }
    }
}

/// Sines and cosines of the joint angles and their sum ([`Acrobot::trig`]), of one state or
/// of four in lanes.
#[derive(Debug, Clone, Copy)]
struct Trig<T = f64> {
    s1: T,
    c1: T,
    s2: T,
    c2: T,
    s12: T,
    c12: T,
}

impl<T: Real> Trig<T> {
    /// The pairs of both angles, the sum's by the angle-sum identities.
    #[inline(always)]
    fn of(s1: T, c1: T, s2: T, c2: T) -> Self {
        Trig {
            s1,
            c1,
            s2,
            c2,
            s12: s1 * c2 + c1 * s2,
            c12: c1 * c2 - s1 * s2,
        }
    }
}

impl Acrobot {
    /// Joint-space mass matrix as `[[M11, M12], [M12, M22]]`.
    pub fn mass_matrix(&self, theta2: f64) -> [[f64; 2]; 2] {
        self.mass_of(crate::portable::cos(theta2))
    }

    /// [`Acrobot::mass_matrix`] given cos θ2 (of one state, or of four in lanes). The products
    /// of parameters are formed first, left to right, as the written-out formula evaluates.
    #[inline(always)]
    fn mass_of<T: Real>(&self, c2: T) -> [[T; 2]; 2] {
        let Self { m1, m2, l1, l2, .. } = *self;
        let c = T::splat;
        let m11 = c((m1 + m2) * l1 * l1 + m2 * l2 * l2) + c(2.0 * m2 * l1 * l2) * c2;
        let m12 = c(m2 * l2 * l2) + c(m2 * l1 * l2) * c2;
        let m22 = c(m2 * l2 * l2);
        [[m11, m12], [m12, m22]]
    }

    /// sin and cos of θ1, θ2 and θ1 + θ2: both joint angles' pairs at once
    /// ([`crate::fastmath::sin_cos2`]), the sum's by the angle-sum identities (shared by
    /// [`Ode::derivative`] and the linearization, so their θ̈ agree bit for bit).
    #[inline(always)]
    fn trig(t1: f64, t2: f64) -> Trig {
        let ((s1, c1), (s2, c2)) = crate::fastmath::sin_cos2(t1, t2);
        Trig::of(s1, c1, s2, c2)
    }

    /// Positions of the two masses (m).
    pub fn positions(&self, x: &[f64]) -> [[f64; 2]; 2] {
        let p1 = [
            self.l1 * crate::portable::cos(x[0]),
            self.l1 * crate::portable::sin(x[0]),
        ];
        let a = x[0] + x[1];
        [
            p1,
            [
                p1[0] + self.l2 * crate::portable::cos(a),
                p1[1] + self.l2 * crate::portable::sin(a),
            ],
        ]
    }
}

impl Model for Acrobot {
    fn name(&self) -> &str {
        "acrobot"
    }
    fn state_names(&self) -> Vec<String> {
        ["theta1", "theta2", "omega1", "omega2"]
            .map(String::from)
            .to_vec()
    }
    fn control_names(&self) -> Vec<String> {
        vec!["tau".into()]
    }
    fn parameters(&self) -> Vec<Parameter> {
        vec![
            Parameter::new("m1", self.m1, "kg", "point mass at the end of link 1"),
            Parameter::new("m2", self.m2, "kg", "point mass at the end of link 2"),
            Parameter::new("l1", self.l1, "m", "length of link 1 (massless)"),
            Parameter::new("l2", self.l2, "m", "length of link 2 (massless)"),
            Parameter::gravity(self.gravity, "gravitational acceleration"),
        ]
    }
    fn default_dt(&self) -> f64 {
        0.01
    }
}

impl Ode for Acrobot {
    fn derivative(&self, x: &[f64], u: &[f64], dx: &mut [f64]) {
        let Self {
            m1,
            m2,
            l1,
            l2,
            gravity: g,
        } = *self;
        let (t1, t2, w1, w2) = (x[0], x[1], x[2], x[3]);
        let Trig {
            c1, s2, c2, c12, ..
        } = Self::trig(t1, t2);
        let [[a, b], [_, d]] = self.mass_of(c2);
        let h = m2 * l1 * l2 * s2;
        let g1 = (m1 + m2) * g * l1 * c1 + m2 * g * l2 * c12;
        let g2 = m2 * g * l2 * c12;
        let r1 = h * (2.0 * w1 * w2 + w2 * w2) - g1;
        let r2 = -h * w1 * w1 - g2 + u[0];
        let det = a * d - b * b;
        dx[0] = w1;
        dx[1] = w2;
        dx[2] = (d * r1 - b * r2) / det;
        dx[3] = (a * r2 - b * r1) / det;
    }

    fn position_dim(&self) -> Option<usize> {
        Some(2)
    }

    fn energy(&self, x: &[f64]) -> Option<f64> {
        let [[a, b], [_, d]] = self.mass_matrix(x[1]);
        let (w1, w2) = (x[2], x[3]);
        let ke = 0.5 * (a * w1 * w1 + 2.0 * b * w1 * w2 + d * w2 * w2);
        let [p1, p2] = self.positions(x);
        let pe = self.gravity * (self.m1 * p1[1] + self.m2 * p2[1]);
        Some(ke + pe)
    }
}

impl Linearize for Acrobot {
    fn jacobians(&self, x: &[f64], u: &[f64], a: &mut DMatrix<f64>, b: &mut DMatrix<f64>) {
        self.linearize(x, u, None, a, b);
    }

    fn derivative_and_jacobians(
        &self,
        x: &[f64],
        u: &[f64],
        dx: &mut [f64],
        a: &mut DMatrix<f64>,
        b: &mut DMatrix<f64>,
    ) {
        self.linearize(x, u, Some(dx), a, b);
    }

    #[inline(always)]
    fn derivative_and_jacobians_x4(
        &self,
        x: &[X4],
        u: &[X4],
        dx: &mut [X4],
        a: &mut [X4],
        b: &mut [X4],
    ) -> bool {
        let ((s1, c1), (s2, c2)) = (sin_cos_x4(x[0]), sin_cos_x4(x[1]));
        let (f, fa, fb) =
            self.linearize_at([x[0], x[1], x[2], x[3]], u[0], Trig::of(s1, c1, s2, c2));
        dx.copy_from_slice(&f);
        a.copy_from_slice(&fa);
        b.copy_from_slice(&fb);
        true
    }
}

impl Acrobot {
    /// The Jacobians at (x, u), and f(x, u) into `dx` when given: θ̈ = M⁻¹ r is computed on
    /// the way with the operations of [`Ode::derivative`], so it is bit-identical to it.
    fn linearize(
        &self,
        x: &[f64],
        u: &[f64],
        dx: Option<&mut [f64]>,
        a: &mut DMatrix<f64>,
        b: &mut DMatrix<f64>,
    ) {
        let trig = Self::trig(x[0], x[1]);
        let (f, fa, fb) = self.linearize_at([x[0], x[1], x[2], x[3]], u[0], trig);
        if let Some(dx) = dx {
            dx.copy_from_slice(&f);
        }
        let a: &mut [f64; 16] = a.as_mut_slice().try_into().expect("A is 4 × 4");
        *a = fa;
        let b: &mut [f64; 4] = b.as_mut_slice().try_into().expect("B is 4 × 1");
        *b = fb;
    }

    /// f(x, u), A (4 × 4, column-major) and B (4 × 1) at x = (θ1, θ2, ω1, ω2), u = τ, given
    /// the angles' sines and cosines: the one body of the scalar linearization and of four
    /// points in lanes ([`Real`]), so lane i of the latter is bit for bit the former at point i.
    #[inline(always)]
    fn linearize_at<T: Real>(&self, x: [T; 4], tau: T, trig: Trig<T>) -> ([T; 4], [T; 16], [T; 4]) {
        let Self {
            m1,
            m2,
            l1,
            l2,
            gravity: g,
        } = *self;
        let c = T::splat;
        let [_, _, w1, w2] = x;
        let Trig {
            s1,
            c1,
            s2,
            c2,
            s12,
            c12,
        } = trig;
        let [[m11, m12], [_, m22]] = self.mass_of(c2);
        let h = c(m2 * l1 * l2) * s2;
        let dh = c(m2 * l1 * l2) * c2; // ∂h/∂θ2
        let g1 = c((m1 + m2) * g * l1) * c1 + c(m2 * g * l2) * c12;
        let g2 = c(m2 * g * l2) * c12;
        let r1 = h * (c(2.0) * w1 * w2 + w2 * w2) - g1;
        let r2 = -h * w1 * w1 - g2 + tau;
        let det = m11 * m22 - m12 * m12;
        // θ̈ = M⁻¹ r with M⁻¹ = [[m22, −m12], [−m12, m11]] / det.
        let solve = |v1: T, v2: T| ((m22 * v1 - m12 * v2) / det, (m11 * v2 - m12 * v1) / det);
        let (a1, a2) = solve(r1, r2);
        // ∂r/∂z for z = θ1, θ2, ω1, ω2.
        let gs12 = c(m2 * g * l2) * s12;
        let dr_t1 = (c((m1 + m2) * g * l1) * s1 + gs12, gs12);
        let dr_t2 = (
            dh * (c(2.0) * w1 * w2 + w2 * w2) + gs12,
            -dh * w1 * w1 + gs12,
        );
        let dr_w1 = (c(2.0) * h * w2, -c(2.0) * h * w1);
        let dr_w2 = (c(2.0) * h * (w1 + w2), c(0.0));
        // ∂M/∂θ2 θ̈ with ∂M11/∂θ2 = −2 m2 l1 l2 sin θ2 = −2h, ∂M12/∂θ2 = −h, ∂M22/∂θ2 = 0.
        let dm_a = (-c(2.0) * h * a1 - h * a2, -h * a1);
        let cols = [dr_t1, (dr_t2.0 - dm_a.0, dr_t2.1 - dm_a.1), dr_w1, dr_w2];
        // Rows 2 and 3 of A, column by column, and of B.
        let (p0, q0) = solve(cols[0].0, cols[0].1);
        let (p1, q1) = solve(cols[1].0, cols[1].1);
        let (p2, q2) = solve(cols[2].0, cols[2].1);
        let (p3, q3) = solve(cols[3].0, cols[3].1);
        let (pu, qu) = solve(c(0.0), c(1.0));
        let (zero, one) = (c(0.0), c(1.0));
        (
            [w1, w2, a1, a2],
            [
                zero, zero, p0, q0, //
                zero, zero, p1, q1, //
                one, zero, p2, q2, //
                zero, one, p3, q3,
            ],
            [zero, zero, pu, qu],
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::physics::{IntegratorKind, Simulator};
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;
    use std::f64::consts::FRAC_PI_2;

    #[test]
    fn hanging_down_at_rest_stays_there() {
        let a = Acrobot::default();
        let mut sim = Simulator::new(a, IntegratorKind::Rk4);
        let x = sim
            .rollout(
                &[-FRAC_PI_2, 0.0, 0.0, 0.0],
                0.01,
                1000,
                |_, _, _, _| {},
                |_, _, _| {},
            )
            .unwrap();
        assert!((x[0] + FRAC_PI_2).abs() < 1e-12 && x[1].abs() < 1e-12);
        assert!(x[2].abs() < 1e-12 && x[3].abs() < 1e-12);
    }

    #[test]
    fn conserves_energy_without_torque() {
        let a = Acrobot::default();
        let x0 = [-1.0, 0.8, 0.5, -1.0];
        let e0 = a.energy(&x0).unwrap();
        let mut sim = Simulator::new(a.clone(), IntegratorKind::Rk4);
        let mut dev: f64 = 0.0;
        sim.rollout(
            &x0,
            0.001,
            5000,
            |_, _, _, _| {},
            |_, _, x| {
                dev = dev.max((a.energy(x).unwrap() - e0).abs());
            },
        )
        .unwrap();
        assert!(dev < 1e-8, "energy drift {dev}");
    }

    #[test]
    fn hip_torque_power_balance() {
        let a = Acrobot::default();
        let x = [0.3, -0.4, 1.2, -0.8];
        let u = [2.5];
        let mut dx = [0.0; 4];
        a.derivative(&x, &u, &mut dx);
        let h = 1e-6;
        let e = |s: f64| {
            let y: Vec<f64> = x.iter().zip(&dx).map(|(p, q)| p + s * q).collect();
            a.energy(&y).unwrap()
        };
        let de = (e(h) - e(-h)) / (2.0 * h);
        assert!((de - u[0] * x[3]).abs() < 1e-6, "{de} vs {}", u[0] * x[3]);
    }

    /// The shared evaluation is exactly the two separate ones (bit for bit), so the RK4 map's
    /// Jacobians, and everything built on them, do not depend on which path ran.
    #[test]
    fn derivative_and_jacobians_are_bit_identical_to_the_separate_calls() {
        let model = Acrobot::default();
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let mut draw = |scale: f64| scale * rng.random_range(-0.5..0.5);
        let (mut a1, mut b1) = (DMatrix::zeros(4, 4), DMatrix::zeros(4, 1));
        let (mut a2, mut b2) = (DMatrix::zeros(4, 4), DMatrix::zeros(4, 1));
        for _ in 0..1000 {
            let x = [draw(20.0), draw(20.0), draw(40.0), draw(40.0)];
            let u = [draw(100.0)];
            let (mut d1, mut d2) = ([0.0; 4], [0.0; 4]);
            model.derivative(&x, &u, &mut d1);
            model.jacobians(&x, &u, &mut a1, &mut b1);
            model.derivative_and_jacobians(&x, &u, &mut d2, &mut a2, &mut b2);
            let bits = |v: &[f64]| v.iter().map(|f| f.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(&d1), bits(&d2), "f at {x:?}");
            assert_eq!(bits(a1.as_slice()), bits(a2.as_slice()), "A at {x:?}");
            assert_eq!(bits(b1.as_slice()), bits(b2.as_slice()), "B at {x:?}");
        }
    }

    #[test]
    fn mass_matrix_is_symmetric_positive_definite() {
        let a = Acrobot::default();
        for t2 in [-3.0, -1.0, 0.0, 0.5, 3.1] {
            let [[m11, m12], [m21, m22]] = a.mass_matrix(t2);
            assert_eq!(m12, m21);
            assert!(m11 > 0.0 && m11 * m22 - m12 * m12 > 0.0);
        }
    }
}
