//! # Planar three-link pendulum (NeuroAnimator, Fig. 5a)
//!
//! Three rigid rods hang in gravity from a fixed pivot, joined by revolute joints with viscous
//! friction τ_f = −b_i q̇_i. The state is `[q1, q2, q3, q̇1, q̇2, q̇3]` with q1 measured from
//! straight down and q2, q3 relative to the previous link. The *active* variant has a motor
//! torque at each joint, the *ext. force* variant adds a force on each link, applied at the
//! link's centre of mass perpendicular to it (positive towards increasing absolute angle).
//!
//! Full articulated dynamics. With absolute angles φ = S q (S lower-triangular ones), link i's
//! mass beyond it μ_i = Σ_{k>i} m_k, and coefficients
//!
//! - D_i = I_i + m_i c_i² + μ_i l_i²,
//! - A_ij = l_i (m_j c_j + μ_j l_j) for i < j (symmetric),
//! - G_i = g (m_i c_i + μ_i l_i),
//!
//! the absolute-angle equations are M(φ) φ̈ + b(φ, φ̇) + G sin φ = Q_ext with
//! M_ij = A_ij cos(φ_i − φ_j), M_ii = D_i, b_i = Σ_j A_ij sin(φ_i − φ_j) φ̇_j². In joint
//! coordinates: Sᵀ M S q̈ = Sᵀ(Q_ext − b − G sin φ) + u − B q̇.

use super::{Model, Ode, Parameter};
use nalgebra::{Matrix3, Vector3};
use serde::{Deserialize, Serialize};

/// One rigid link.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Link {
    /// Mass (kg).
    pub mass: f64,
    /// Length from its joint to the next joint (m).
    pub length: f64,
    /// Distance of the centre of mass from its joint (m).
    pub com: f64,
    /// Moment of inertia about the centre of mass (kg·m²).
    pub inertia: f64,
    /// Viscous friction at the joint that drives this link (N·m·s/rad).
    pub damping: f64,
}

impl Link {
    /// A uniform rod of the given mass and length with joint damping `damping`.
    pub fn rod(mass: f64, length: f64, damping: f64) -> Self {
        Self {
            mass,
            length,
            com: 0.5 * length,
            inertia: mass * length * length / 12.0,
            damping,
        }
    }
}

/// A mode of a body's motion linearized about rest ([`Pendulum3::modes`],
/// [`super::dolphin::Dolphin::modes`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Mode {
    /// Period of the oscillation (s); infinite for an overdamped (real) mode.
    pub period_s: f64,
    /// Decay rate of its amplitude, −Re λ (1/s): it falls by e in 1/decay seconds.
    pub decay_per_s: f64,
}

impl Mode {
    /// The modes of a first-order linear system's eigenvalues λ, slowest first: one per
    /// complex-conjugate pair (the one with Im λ ≥ 0) and one per real eigenvalue, an
    /// eigenvalue whose imaginary part is at most `real_below` counting as real.
    pub fn of_eigenvalues<'a>(
        eigenvalues: impl Iterator<Item = &'a nalgebra::Complex<f64>>,
        real_below: f64,
    ) -> Vec<Mode> {
        let mut modes: Vec<Mode> = eigenvalues
            .filter(|l| l.im >= 0.0)
            .map(|l| Mode {
                period_s: if l.im > real_below {
                    std::f64::consts::TAU / l.im
                } else {
                    f64::INFINITY
                },
                decay_per_s: -l.re,
            })
            .collect();
        modes.sort_by(|x, y| x.rate().total_cmp(&y.rate()));
        modes
    }

    /// |λ| (1/s), the mode's overall rate: what orders modes slowest first.
    pub fn rate(&self) -> f64 {
        let w = std::f64::consts::TAU / self.period_s;
        crate::portable::hypot(self.decay_per_s, w)
    }

    /// Damping ratio ζ = decay / |λ| (1 for an overdamped mode).
    pub fn damping_ratio(&self) -> f64 {
        let w = std::f64::consts::TAU / self.period_s;
        self.decay_per_s / (self.decay_per_s * self.decay_per_s + w * w).sqrt()
    }
}

/// Which inputs the pendulum takes (Table 1 of NeuroAnimator).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PendulumVariant {
    /// No inputs.
    Passive,
    /// A motor torque at each joint (3 controls).
    Active,
    /// Motor torques and a perpendicular force on each link (6 controls).
    ExtForce,
}

/// The planar three-link pendulum.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Pendulum3 {
    /// The links, from the pivot outwards.
    pub links: [Link; 3],
    /// Gravitational acceleration (m/s²).
    pub gravity: f64,
    /// Which inputs it takes.
    pub variant: PendulumVariant,
}

impl Pendulum3 {
    /// Default pendulum: three uniform 1 kg, 0.5 m rods; joint friction 0.2 N·m·s/rad at the
    /// pivot and 1 N·m·s/rad at the two elbows.
    ///
    /// Why the elbows are stiff with friction: the undamped chain's modes have periods of 2.04,
    /// 0.82 and 0.44 s, and NeuroAnimator's emulators step 0.5 s (N50) or 1 s (N100) at
    /// δt = 0.01 s; a mode faster than two super-steps that is not damped out within one is
    /// something a 20-unit net cannot follow. Elbow friction damps the two elbow modes (one
    /// overdamped, one at 1.13 s decaying at 6.2/s) while the pendulum's swing, the slowest mode
    /// (2.03 s), stays lightly damped (ζ ≈ 0.017), so a weak motor must still swing to build
    /// momentum.
    ///
    /// Why the pivot has more friction than a bearing would: an emulator run open loop carries
    /// each super-step's error along the swing for as long as the swing remembers, and a swing
    /// that decays by e only after longer than the paper's controllers last (20 s) delivers
    /// every step's error to the final state undiminished. At 0.2 N·m·s/rad the swing decays by
    /// e in 18.8 s (at 0.05, 34.5 s). [`Self::modes`] gives the modes;
    /// `experiments/na_table1_structure.toml` states the rule the frictions were chosen by.
    pub fn new(variant: PendulumVariant) -> Self {
        let pivot = Link::rod(1.0, 0.5, 0.2);
        let elbow = Link::rod(1.0, 0.5, 1.0);
        Self {
            links: [pivot, elbow, elbow],
            gravity: 9.81,
            variant,
        }
    }

    /// The swing: the oscillating mode of longest period ([`Self::modes`]), the whole chain
    /// swinging about the pivot; `None` when no mode oscillates.
    pub fn swing(&self) -> Option<Mode> {
        self.modes()
            .into_iter()
            .filter(|m| m.period_s.is_finite())
            .max_by(|a, b| a.period_s.total_cmp(&b.period_s))
    }

    /// The modes of the motion linearized about hanging at rest (M q̈ + B q̇ + K q = 0, K =
    /// Sᵀ diag(G) S), slowest first: one per complex-conjugate pair of eigenvalues of the
    /// first-order system and one per real eigenvalue.
    pub fn modes(&self) -> Vec<Mode> {
        let (_, _, g) = self.coefficients();
        let s = Matrix3::new(1.0, 0.0, 0.0, 1.0, 1.0, 0.0, 1.0, 1.0, 1.0);
        let m = self.mass_matrix(&[0.0; 3]);
        let k = s.transpose() * Matrix3::from_diagonal(&Vector3::from(g)) * s;
        let b = Matrix3::from_fn(|i, j| if i == j { self.links[i].damping } else { 0.0 });
        let m_inv = m
            .try_inverse()
            .expect("the mass matrix is positive definite");
        let mut a = nalgebra::Matrix6::<f64>::zeros();
        a.fixed_view_mut::<3, 3>(0, 3)
            .copy_from(&Matrix3::identity());
        a.fixed_view_mut::<3, 3>(3, 0).copy_from(&(-m_inv * k));
        a.fixed_view_mut::<3, 3>(3, 3).copy_from(&(-m_inv * b));
        Mode::of_eigenvalues(a.complex_eigenvalues().iter(), 1e-12)
    }

    /// The same pendulum without joint friction.
    pub fn frictionless(mut self) -> Self {
        for l in &mut self.links {
            l.damping = 0.0;
        }
        self
    }

    /// (D, A, G) coefficients of the absolute-angle equations.
    fn coefficients(&self) -> ([f64; 3], [[f64; 3]; 3], [f64; 3]) {
        let m = |i: usize| self.links[i].mass;
        let beyond = |i: usize| -> f64 { (i + 1..3).map(m).sum() };
        let mut d = [0.0; 3];
        let mut a = [[0.0; 3]; 3];
        let mut g = [0.0; 3];
        for i in 0..3 {
            let li = &self.links[i];
            d[i] = li.inertia + li.mass * li.com * li.com + beyond(i) * li.length * li.length;
            g[i] = self.gravity * (li.mass * li.com + beyond(i) * li.length);
            for j in i + 1..3 {
                let lj = &self.links[j];
                let v = li.length * (lj.mass * lj.com + beyond(j) * lj.length);
                a[i][j] = v;
                a[j][i] = v;
            }
        }
        (d, a, g)
    }

    fn absolute(q: &[f64]) -> [f64; 3] {
        [q[0], q[0] + q[1], q[0] + q[1] + q[2]]
    }

    fn absolute_mass_matrix(&self, phi: &[f64; 3]) -> Matrix3<f64> {
        let (d, a, _) = self.coefficients();
        Self::mass_of(&d, &a, |i, j| crate::portable::cos(phi[i] - phi[j]))
    }

    /// M(φ) from the coefficients and cos(φ_i − φ_j) (`cos_diff`, symmetric in i and j).
    fn mass_of(
        d: &[f64; 3],
        a: &[[f64; 3]; 3],
        cos_diff: impl Fn(usize, usize) -> f64,
    ) -> Matrix3<f64> {
        Matrix3::from_fn(|i, j| {
            if i == j {
                d[i]
            } else {
                a[i][j] * cos_diff(i, j)
            }
        })
    }

    /// Joint-space mass matrix Sᵀ M(φ) S at joint angles `q` (symmetric positive definite).
    pub fn mass_matrix(&self, q: &[f64]) -> Matrix3<f64> {
        let s = Matrix3::new(1.0, 0.0, 0.0, 1.0, 1.0, 0.0, 1.0, 1.0, 1.0);
        s.transpose() * self.absolute_mass_matrix(&Self::absolute(q)) * s
    }

    /// Planar positions of the joints and the tip: pivot, joint 2, joint 3, tip (m).
    pub fn joint_positions(&self, q: &[f64]) -> [[f64; 2]; 4] {
        let phi = Self::absolute(q);
        let mut p = [[0.0; 2]; 4];
        for i in 0..3 {
            p[i + 1] = [
                p[i][0] + self.links[i].length * crate::portable::sin(phi[i]),
                p[i][1] - self.links[i].length * crate::portable::cos(phi[i]),
            ];
        }
        p
    }

    /// Velocity of link `i`'s centre of mass along its perpendicular n_i (m/s).
    pub fn com_normal_velocity(&self, x: &[f64], i: usize) -> f64 {
        let phi = Self::absolute(x);
        let w = Self::absolute(&x[3..6]);
        let mut v = self.links[i].com * w[i];
        for k in 0..i {
            v += self.links[k].length * crate::portable::cos(phi[i] - phi[k]) * w[k];
        }
        v
    }
}

impl Model for Pendulum3 {
    fn name(&self) -> &str {
        match self.variant {
            PendulumVariant::Passive => "pendulum3_passive",
            PendulumVariant::Active => "pendulum3",
            PendulumVariant::ExtForce => "pendulum3_ext",
        }
    }
    fn state_names(&self) -> Vec<String> {
        ["q1", "q2", "q3", "q1_dot", "q2_dot", "q3_dot"]
            .map(String::from)
            .to_vec()
    }
    fn control_names(&self) -> Vec<String> {
        let torques = ["torque1", "torque2", "torque3"];
        let forces = ["force1", "force2", "force3"];
        match self.variant {
            PendulumVariant::Passive => vec![],
            PendulumVariant::Active => torques.map(String::from).to_vec(),
            PendulumVariant::ExtForce => torques
                .iter()
                .chain(&forces)
                .map(|s| s.to_string())
                .collect(),
        }
    }
    fn parameters(&self) -> Vec<Parameter> {
        let mut p = Vec::new();
        for (i, l) in self.links.iter().enumerate() {
            let link = format!("link{}", i + 1);
            let body = [l.mass, l.length, l.com, l.inertia];
            p.extend(Parameter::rigid_link(&link, body, "joint-to-joint length"));
            p.push(Parameter::joint_damping(&link, l.damping));
        }
        p.push(Parameter::gravity(
            self.gravity,
            "gravitational acceleration",
        ));
        p
    }
    fn default_dt(&self) -> f64 {
        0.01
    }
}

impl Ode for Pendulum3 {
    fn derivative(&self, x: &[f64], u: &[f64], dx: &mut [f64]) {
        let (d, a, g) = self.coefficients();
        let phi = Self::absolute(x);
        let w = Self::absolute(&x[3..6]);
        // sin and cos of each absolute angle once; those of the differences by the angle
        // identities sin(φ_i − φ_j) = s_i c_j − c_i s_j, cos(φ_i − φ_j) = c_i c_j + s_i s_j
        // (exactly odd and even in the swap of i and j).
        let sc = phi.map(crate::portable::sin_cos);
        let sin_diff = |i: usize, j: usize| sc[i].0 * sc[j].1 - sc[i].1 * sc[j].0;
        let cos_diff = |i: usize, j: usize| sc[i].1 * sc[j].1 + sc[i].0 * sc[j].0;
        let m = Self::mass_of(&d, &a, cos_diff);
        // Q_abs − b − G sin φ in absolute coordinates.
        let mut rhs = Vector3::zeros();
        for i in 0..3 {
            let mut b = 0.0;
            for j in 0..3 {
                if j != i {
                    b += a[i][j] * sin_diff(i, j) * w[j] * w[j];
                }
            }
            rhs[i] = -b - g[i] * sc[i].0;
        }
        if self.variant == PendulumVariant::ExtForce {
            for i in 0..3 {
                let f = u[3 + i];
                rhs[i] += f * self.links[i].com;
                for k in 0..i {
                    rhs[k] += f * self.links[k].length * cos_diff(i, k);
                }
            }
        }
        let s = Matrix3::new(1.0, 0.0, 0.0, 1.0, 1.0, 0.0, 1.0, 1.0, 1.0);
        let mut tau = s.transpose() * rhs;
        for j in 0..3 {
            tau[j] -= self.links[j].damping * x[3 + j];
            if self.variant != PendulumVariant::Passive {
                tau[j] += u[j];
            }
        }
        let mq = s.transpose() * m * s;
        // Positive definite for every finite state; a non-finite one (a blown-up coarse step)
        // gives NaN rates, which `check_finite` reports, rather than a panic.
        let qdd = ldl_solve3(&mq, &tau).unwrap_or(Vector3::repeat(f64::NAN));
        dx[..3].copy_from_slice(&x[3..6]);
        dx[3] = qdd[0];
        dx[4] = qdd[1];
        dx[5] = qdd[2];
    }

    fn position_dim(&self) -> Option<usize> {
        Some(3)
    }

    fn energy(&self, x: &[f64]) -> Option<f64> {
        let (_, _, g) = self.coefficients();
        let phi = Self::absolute(x);
        let w = Vector3::from(Self::absolute(&x[3..6]));
        let ke = 0.5 * (w.transpose() * self.absolute_mass_matrix(&phi) * w)[0];
        let pe: f64 = (0..3).map(|i| -g[i] * crate::portable::cos(phi[i])).sum();
        Some(ke + pe)
    }
}

/// x with M x = b for a symmetric positive definite 3 × 3 M (its lower triangle read), or
/// `None` where M is not positive definite (a pivot that is zero, negative or NaN): the
/// square-root-free factorization M = L D Lᵀ (L unit lower triangular), then L y = b,
/// D z = y, Lᵀ x = z, with the three pivots inverted once (3 divisions, no square roots,
/// where Cholesky takes 3 roots and 9 divisions). The pendulum solves one such system per
/// derivative evaluation.
fn ldl_solve3(m: &Matrix3<f64>, b: &Vector3<f64>) -> Option<Vector3<f64>> {
    let (m11, m21, m31) = (m[(0, 0)], m[(1, 0)], m[(2, 0)]);
    let (m22, m32, m33) = (m[(1, 1)], m[(2, 1)], m[(2, 2)]);
    let positive = |d: f64| d > 0.0; // false for zero, negative and NaN pivots
    if !positive(m11) {
        return None;
    }
    let i1 = 1.0 / m11;
    let (l21, l31) = (m21 * i1, m31 * i1);
    let d2 = m22 - l21 * m21;
    if !positive(d2) {
        return None;
    }
    let i2 = 1.0 / d2;
    let l32 = (m32 - l31 * m21) * i2;
    let d3 = m33 - l31 * m31 - l32 * l32 * d2;
    if !positive(d3) {
        return None;
    }
    let i3 = 1.0 / d3;
    let y2 = b[1] - l21 * b[0];
    let y3 = b[2] - l31 * b[0] - l32 * y2;
    let x3 = y3 * i3;
    let x2 = y2 * i2 - l32 * x3;
    let x1 = b[0] * i1 - l21 * x2 - l31 * x3;
    Some(Vector3::new(x1, x2, x3))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::physics::{IntegratorKind, Simulator};
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// The derivative as it was before the shared trigonometry and the hand-written solve
    /// (pairwise sin and cos, nalgebra's Cholesky), the reference the faster evaluation is
    /// checked against.
    fn reference_derivative(p: &Pendulum3, x: &[f64], u: &[f64], dx: &mut [f64]) {
        let (_, a, g) = p.coefficients();
        let phi = Pendulum3::absolute(x);
        let w = Pendulum3::absolute(&x[3..6]);
        let m = p.absolute_mass_matrix(&phi);
        // Q_abs − b − G sin φ in absolute coordinates.
        let mut rhs = Vector3::zeros();
        for i in 0..3 {
            let mut b = 0.0;
            for j in 0..3 {
                if j != i {
                    b += a[i][j] * (phi[i] - phi[j]).sin() * w[j] * w[j];
                }
            }
            rhs[i] = -b - g[i] * phi[i].sin();
        }
        if p.variant == PendulumVariant::ExtForce {
            for i in 0..3 {
                let f = u[3 + i];
                rhs[i] += f * p.links[i].com;
                for k in 0..i {
                    rhs[k] += f * p.links[k].length * (phi[i] - phi[k]).cos();
                }
            }
        }
        let s = Matrix3::new(1.0, 0.0, 0.0, 1.0, 1.0, 0.0, 1.0, 1.0, 1.0);
        let mut tau = s.transpose() * rhs;
        for j in 0..3 {
            tau[j] -= p.links[j].damping * x[3 + j];
            if p.variant != PendulumVariant::Passive {
                tau[j] += u[j];
            }
        }
        let mq = s.transpose() * m * s;
        // Positive definite for every finite state; a non-finite one (a blown-up coarse step)
        // gives NaN rates, which `check_finite` reports, rather than a panic.
        let qdd = mq
            .cholesky()
            .map_or(Vector3::repeat(f64::NAN), |c| c.solve(&tau));
        dx[..3].copy_from_slice(&x[3..6]);
        dx[3] = qdd[0];
        dx[4] = qdd[1];
        dx[5] = qdd[2];
    }
    /// The derivative agrees with the pairwise evaluation (every variant, many random states
    /// and controls, far outside the training ranges too) to rounding: the angle identities
    /// and the L D Lᵀ solve change only the last digits.
    #[test]
    fn derivative_agrees_with_the_pairwise_reference() {
        let mut rng = ChaCha8Rng::seed_from_u64(2);
        let mut draw = || rng.random_range(-0.5..0.5);
        let mut worst = 0.0f64;
        for variant in [
            PendulumVariant::Passive,
            PendulumVariant::Active,
            PendulumVariant::ExtForce,
        ] {
            let p = Pendulum3::new(variant);
            let m = p.control_dim();
            for i in 0..20_000 {
                let scale = if i % 4 == 0 { 200.0 } else { 4.0 };
                let x: Vec<f64> = (0..6).map(|_| draw() * scale).collect();
                let u: Vec<f64> = (0..m).map(|_| draw() * 10.0).collect();
                let (mut a, mut b) = ([0.0; 6], [0.0; 6]);
                p.derivative(&x, &u, &mut a);
                reference_derivative(&p, &x, &u, &mut b);
                let size = b.iter().fold(1.0f64, |s, v| s.max(v.abs()));
                for (a, b) in a.iter().zip(&b) {
                    worst = worst.max((a - b).abs() / size);
                }
            }
        }
        assert!(
            worst < 1e-11,
            "largest difference {worst:e} of the largest rate"
        );
        assert!(
            worst > 0.0,
            "the two evaluations differ in the last digits at all"
        );
    }

    /// The L D Lᵀ solve is backward stable and refuses what nalgebra's Cholesky refuses: on the
    /// pendulum's own joint-space mass matrices at random states and on random SPD matrices
    /// spanning many scales, ‖M x − b‖ ≤ 1e-13 (‖M‖ ‖x‖ + ‖b‖) (max norms) and x is within
    /// rounding of nalgebra's on the pendulum's well-conditioned matrices; on matrices with a
    /// zero, negative or NaN pivot both refuse.
    #[test]
    fn ldl_solve3_is_backward_stable_and_refuses_as_nalgebra() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let mut draw = || rng.random_range(-0.5..0.5);
        let p = Pendulum3::new(PendulumVariant::Active);
        let nalgebra = |m: &Matrix3<f64>, b: &Vector3<f64>| m.cholesky().map(|c| c.solve(b));
        let max = |v: &Vector3<f64>| v.amax();
        for i in 0..20_000 {
            let b = Vector3::new(draw() * 50.0, draw() * 50.0, draw() * 50.0);
            let pendulum = i % 2 == 0;
            let m = if pendulum {
                let q = [draw() * 20.0, draw() * 20.0, draw() * 20.0];
                p.mass_matrix(&q)
            } else {
                let a = Matrix3::from_fn(|_, _| draw() * 10f64.powi(i % 7 - 3));
                a * a.transpose() + Matrix3::identity() * (draw() + 0.5) * 1e-6
            };
            let x = ldl_solve3(&m, &b).expect("positive definite");
            let norm_m = m.abs().row_sum().max();
            let residual = max(&(m * x - b));
            assert!(
                residual <= 1e-13 * (norm_m * max(&x) + max(&b)),
                "{m} {b}: residual {residual:e}"
            );
            if pendulum {
                let r = nalgebra(&m, &b).expect("positive definite");
                assert!(max(&(x - r)) <= 1e-12 * max(&r), "{m} {b}");
            }
        }
        let b = Vector3::new(1.0, -2.0, 0.5);
        for m in [
            Matrix3::zeros(),
            Matrix3::new(1.0, 2.0, 0.0, 2.0, 1.0, 0.0, 0.0, 0.0, 1.0),
            Matrix3::from_diagonal(&Vector3::new(1.0, f64::NAN, 1.0)),
            Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, -0.0)),
            Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, -1.0)),
        ] {
            assert_eq!(ldl_solve3(&m, &b), None, "{m}");
            assert!(nalgebra(&m, &b).is_none(), "{m}");
        }
        let inf = Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, f64::INFINITY));
        assert_eq!(ldl_solve3(&inf, &b), nalgebra(&inf, &b));
    }

    #[test]
    fn mass_matrix_is_symmetric_positive_definite() {
        let p = Pendulum3::new(PendulumVariant::Active);
        for q in [[0.0, 0.0, 0.0], [1.0, -2.0, 0.5], [3.0, 3.0, -3.0]] {
            let m = p.mass_matrix(&q);
            assert!((m - m.transpose()).abs().max() < 1e-14);
            let eig = m.symmetric_eigenvalues();
            assert!(eig.iter().all(|&e| e > 0.0), "{eig:?}");
        }
    }

    /// The rule the default pendulum's friction was chosen by (stated in
    /// `experiments/na_table1_structure.toml`): at δt = 0.01 s every mode either lasts at least
    /// two super-steps of N50 (0.5 s) and of N100 (1 s), or decays by e² within one super-step;
    /// the swing (slowest mode) stays lightly damped, ζ ≤ 0.05, and decays by e within the
    /// paper's 20 s controllers; the stiffest decay keeps RK4 at 0.01 s well inside its
    /// stability limit (|λ| δt ≤ 1.5 against 2.78). The pivot's friction is the smallest of
    /// 0.05, 0.1, 0.2, 0.5, 1 N·m·s/rad that passes: the undamped-elbow pendulum (0.05
    /// everywhere) fails it, and so do the pivot's 0.05 and 0.1 with the elbows at 1.
    #[test]
    fn default_pendulum_modes_fit_the_super_steps() {
        let fits = |p: &Pendulum3| {
            let modes = p.modes();
            let steps_ok = [0.5, 1.0].iter().all(|&big| {
                modes
                    .iter()
                    .all(|m| m.period_s >= 2.0 * big || m.decay_per_s * big >= 2.0)
            });
            let stiff = modes.iter().all(|m| m.decay_per_s * 0.01 <= 1.5);
            let swing = p.swing().expect("the chain swings");
            let remembers = 1.0 / swing.decay_per_s;
            steps_ok && swing.damping_ratio() <= 0.05 && remembers <= 20.0 && stiff
        };
        let p = Pendulum3::new(PendulumVariant::Active);
        assert!(fits(&p), "{:?}", p.modes());
        let swing = p.swing().unwrap();
        assert!((swing.period_s - 2.03).abs() < 0.01, "{swing:?}");
        assert!((1.0 / swing.decay_per_s - 18.8).abs() < 0.1, "{swing:?}");
        for lighter in [0.05, 0.1] {
            let mut q = p.clone();
            q.links[0].damping = lighter;
            assert!(!fits(&q), "pivot {lighter}: {:?}", q.modes());
        }
        let mut old = p.clone();
        for l in &mut old.links {
            l.damping = 0.05;
        }
        assert!(!fits(&old), "{:?}", old.modes());
        let mut periods: Vec<f64> = old.modes().iter().map(|m| m.period_s).collect();
        periods.sort_by(|a, b| b.total_cmp(a));
        for (got, want) in periods.iter().zip([2.04, 0.82, 0.44]) {
            assert!((got - want).abs() < 0.01, "{periods:?}");
        }
        // Frictionless: no decay, three oscillations.
        assert!(p
            .clone()
            .frictionless()
            .modes()
            .iter()
            .all(|m| m.decay_per_s.abs() < 1e-9));
    }

    #[test]
    fn frictionless_pendulum_conserves_energy() {
        let p = Pendulum3::new(PendulumVariant::Passive).frictionless();
        let x0 = [1.2, -0.7, 0.9, 0.0, 1.0, -0.5];
        let e0 = p.energy(&x0).unwrap();
        let mut sim = Simulator::new(p.clone(), IntegratorKind::Rk4);
        let mut max_dev: f64 = 0.0;
        sim.rollout(
            &x0,
            0.001,
            5000,
            |_, _, _, _| {},
            |_, _, x| {
                max_dev = max_dev.max((p.energy(x).unwrap() - e0).abs());
            },
        )
        .unwrap();
        assert!(max_dev < 1e-8 * e0.abs().max(1.0), "energy drift {max_dev}");
    }

    #[test]
    fn power_balance_with_torques_friction_and_forces() {
        // dE/dt = Σ (u_j − b_j q̇_j) q̇_j + Σ f_i v⊥_i, checked by central differences.
        let p = Pendulum3::new(PendulumVariant::ExtForce);
        let x = [0.4, -0.3, 0.8, 0.7, -1.1, 0.5];
        let u = [0.3, -0.2, 0.5, 1.0, -0.7, 0.4];
        let mut dx = [0.0; 6];
        p.derivative(&x, &u, &mut dx);
        let h = 1e-6;
        let shifted = |s: f64| -> f64 {
            let y: Vec<f64> = x.iter().zip(&dx).map(|(a, b)| a + s * b).collect();
            p.energy(&y).unwrap()
        };
        let de = (shifted(h) - shifted(-h)) / (2.0 * h);
        let mut power = 0.0;
        for j in 0..3 {
            power += (u[j] - p.links[j].damping * x[3 + j]) * x[3 + j];
            power += u[3 + j] * p.com_normal_velocity(&x, j);
        }
        assert!((de - power).abs() < 1e-6, "dE/dt {de} vs power {power}");
    }

    #[test]
    fn hanging_at_rest_stays_at_rest() {
        let p = Pendulum3::new(PendulumVariant::Passive);
        let mut dx = [1.0; 6];
        p.derivative(&[0.0; 6], &[], &mut dx);
        assert!(dx.iter().all(|v| v.abs() < 1e-15));
    }

    #[test]
    fn mirror_symmetry() {
        // Reflecting the pendulum about the vertical negates every angle and rate.
        let p = Pendulum3::new(PendulumVariant::Active);
        let x = [0.3, -0.9, 1.4, 0.2, 0.6, -0.4];
        let u = [0.1, 0.2, -0.3];
        let (mut a, mut b) = ([0.0; 6], [0.0; 6]);
        p.derivative(&x, &u, &mut a);
        let xm: Vec<f64> = x.iter().map(|v| -v).collect();
        let um: Vec<f64> = u.iter().map(|v| -v).collect();
        p.derivative(&xm, &um, &mut b);
        for i in 0..6 {
            assert!((a[i] + b[i]).abs() < 1e-12);
        }
    }
}
