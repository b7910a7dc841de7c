//! # Time-varying LQR tracking and quadratic value functions
//!
//! Given a trajectory (x̄_k, ū_k) of the discrete problem of [`super`], linearize the dynamics
//! along it (A_k = F_x, B_k = F_u) and expand the cost to second order (l_x, l_u, l_xx, l_uu).
//! The backward Riccati recursion, from P_N = g_xx, p_N = g_x, v_N = g(x̄_N), is
//!
//! ```text
//! Q_x  = l_x + A_kᵀ p_{k+1}          Q_u  = l_u + B_kᵀ p_{k+1}
//! Q_xx = l_xx + A_kᵀ P_{k+1} A_k     Q_uu = l_uu + B_kᵀ P_{k+1} B_k     Q_ux = B_kᵀ P_{k+1} A_k
//! K_k  = −Q_uu⁻¹ Q_ux
//! p_k  = Q_x + K_kᵀ Q_u
//! P_k  = Q_xx + K_kᵀ Q_uu K_k + K_kᵀ Q_ux + Q_uxᵀ K_k
//! v_k  = l(x̄_k, ū_k) + v_{k+1}
//! ```
//!
//! and gives the tracking policy u = ū_k + K_k Δx with Δx = x − x̄_k, and the quadratic value
//! function of linear Bellman combination, eq. (12):
//! v̂(x, k) = v(x̄_k) + p_kᵀ Δx + ½ Δxᵀ P_k Δx, where v(x̄_k) is the cost remaining along the
//! trajectory. p and P are those of *this* policy (no feedforward correction), so that
//! v̂(x̄_k, k) is exactly the remaining cost; when the trajectory is optimal (Q_u = 0, e.g. after
//! [`super::ddp`] converges), they are the optimal value function's gradient and Hessian.
//! By default second-order dynamics terms are not included (the classical LQR approximation,
//! [`ValueModel::Lqr`]); [`ValueModel::Ddp`] adds them as the DDP backward pass does
//! (Q_xx += p'·F_xx, Q_ux += p'·F_ux, Q_uu += p'·F_uu, with F_zz by differences of the exact
//! Jacobians), giving DDP's gains and value function (LBC §5.2 uses DDP's).
//!
//! ## References
//! - D. H. Jacobson, D. Q. Mayne, *Differential Dynamic Programming*, Elsevier, 1970.
//! - M. da Silva, F. Durand, J. Popović, *Linear Bellman Combination for Control of Character
//!   Animation*, SIGGRAPH 2009, §5.2 (eq. 12).

use super::small::{copy_into, on_dims, SmallAlloc, Zeros};
use super::{cholesky_in_place, cholesky_solve_in_place, symmetrize};
use super::{ControlError, Knots, QuadraticCost, Rk4Map, StageDerivatives};
use crate::linalg;
use crate::physics::linearize::Linearize;
use nalgebra::{DMatrix, DVector, DefaultAllocator, Dim};

/// A time-varying LQR tracking controller with its quadratic value function (eq. 12). The
/// per-knot vectors and matrices are stored contiguously ([`Knots`]); knot k's are
/// `x_ref.vector(k)`, `gains.matrix(k)` and so on.
#[derive(Debug, Clone, PartialEq)]
pub struct TrackingController {
    /// Reference states x̄_0..x̄_N (n × 1 each).
    pub x_ref: Knots,
    /// Reference controls ū_0..ū_{N−1} (m × 1 each).
    pub u_ref: Knots,
    /// Feedback gains K_0..K_{N−1} (m × n).
    pub gains: Knots,
    /// Remaining cost along the reference, v(x̄_k) for k = 0..N.
    pub value_ref: Vec<f64>,
    /// Value gradients p_0..p_N (n × 1 each).
    pub value_gradient: Knots,
    /// Value Hessians P_0..P_N (n × n).
    pub value_hessian: Knots,
}

impl TrackingController {
    /// Horizon N (number of control steps).
    pub fn horizon(&self) -> usize {
        self.u_ref.len()
    }

    /// State dimension n.
    pub fn state_dim(&self) -> usize {
        self.x_ref.shape().0
    }

    /// Control dimension m.
    pub fn control_dim(&self) -> usize {
        self.u_ref.shape().0
    }

    /// u = ū_k + K_k (x − x̄_k) for k < N, written into `u`. Does not allocate.
    pub fn policy_into(&self, x: &[f64], k: usize, u: &mut [f64]) {
        assert!(
            k < self.horizon(),
            "policy step {k} beyond horizon {}",
            self.horizon()
        );
        let (xr, ur, gain) = (
            self.x_ref.slice(k),
            self.u_ref.slice(k),
            self.gains.slice(k),
        );
        let m = ur.len();
        for (i, ui) in u.iter_mut().enumerate() {
            let mut v = ur[i];
            for j in 0..x.len() {
                // K_k is column-major: K[(i, j)] is entry i + j m.
                v += gain[i + j * m] * (x[j] - xr[j]);
            }
            *ui = v;
        }
    }

    /// u = ū_k + K_k (x − x̄_k) for k < N.
    pub fn policy(&self, x: &[f64], k: usize) -> DVector<f64> {
        let mut u = DVector::zeros(self.control_dim());
        self.policy_into(x, k, u.as_mut_slice());
        u
    }

    /// v̂(x, k) = v(x̄_k) + p_kᵀ Δx + ½ Δxᵀ P_k Δx for k ≤ N. Does not allocate.
    pub fn value(&self, x: &[f64], k: usize) -> f64 {
        let (xr, p, hess) = (
            self.x_ref.slice(k),
            self.value_gradient.slice(k),
            self.value_hessian.slice(k),
        );
        let n = xr.len();
        let mut v = self.value_ref[k];
        for j in 0..x.len() {
            let dj = x[j] - xr[j];
            v += p[j] * dj;
            for i in 0..x.len() {
                // P_k is column-major: P[(i, j)] is entry i + j n.
                v += 0.5 * (x[i] - xr[i]) * hess[i + j * n] * dj;
            }
        }
        v
    }
}

/// Which backward recursion builds a tracker's gains and quadratic value function.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ValueModel {
    /// First-order dynamics (LQR / iLQR).
    Lqr,
    /// With the second-order dynamics terms of DDP; F_zz by central differences of the
    /// Jacobians with this relative step.
    Ddp {
        /// Relative difference step.
        fd_step: f64,
    },
}

/// Builds the LQR tracking controller of the trajectory (`xs`: N + 1 states, `us`: N controls)
/// for `cost` under the RK4 dynamics `map` (needs [`Linearize`]).
pub fn track<M: Linearize>(
    map: &Rk4Map<M>,
    cost: &QuadraticCost,
    xs: &[DVector<f64>],
    us: &[DVector<f64>],
) -> Result<TrackingController, ControlError> {
    track_with(map, cost, xs, us, ValueModel::Lqr)
}

/// [`track`] with the value model chosen: [`ValueModel::Ddp`] adds the second-order dynamics
/// terms of the DDP backward pass.
pub fn track_with<M: Linearize>(
    map: &Rk4Map<M>,
    cost: &QuadraticCost,
    xs: &[DVector<f64>],
    us: &[DVector<f64>],
    model: ValueModel,
) -> Result<TrackingController, ControlError> {
    let (n, m) = (map.state_dim(), map.control_dim());
    let mut ws = map.workspace();
    let mut second = |x: &DVector<f64>, u: &DVector<f64>, h: f64, fzz: &mut [DMatrix<f64>]| {
        map.second_derivatives(x, u, h, fzz, &mut ws)
    };
    let second: Option<&mut SecondDerivatives<'_>> = match model {
        ValueModel::Lqr => None,
        ValueModel::Ddp { .. } => Some(&mut second),
    };
    check_trajectory((n, m), cost, xs, us)?;
    // Every knot's (A_k, B_k) first: the knots are independent, and the map computes them
    // four at a time where the model allows (`Rk4Map::jacobians_each`, the same bits).
    let horizon = us.len();
    let (mut ak, mut bk) = (Knots::zeros(horizon, n, n), Knots::zeros(horizon, n, m));
    map.jacobians_each(xs, us, &mut map.workspace(), |k, a, b| {
        ak.matrix_mut(k).copy_from(a);
        bk.matrix_mut(k).copy_from(b);
    });
    riccati(
        (n, m),
        cost,
        xs,
        us,
        model,
        &mut |k, _, _, a, b| {
            a.copy_from(&ak.matrix(k));
            b.copy_from(&bk.matrix(k));
        },
        second,
    )
}

/// The step Jacobians (A_k, B_k) of step `k` at (x̄_k, ū_k), written into `a` (n × n) and `b`
/// (n × m): the source of the linearization the Riccati recursion follows.
pub type StepJacobians<'a> =
    dyn FnMut(usize, &DVector<f64>, &DVector<f64>, &mut DMatrix<f64>, &mut DMatrix<f64>) + 'a;

/// Second derivatives F_zz of each state component at (x, u), by differences with relative step
/// h, written into n matrices of size (n + m) × (n + m) (full DDP's value model only).
pub type SecondDerivatives<'a> =
    dyn FnMut(&DVector<f64>, &DVector<f64>, f64, &mut [DMatrix<f64>]) + 'a;

/// The LQR tracker ([`ValueModel::Lqr`]) of the trajectory (`xs`: N + 1 states, `us`: N
/// controls) of any discrete map of n states and m controls whose Jacobians (A_k, B_k) come
/// from `jacobians` (e.g. those of a learned emulator, [`super::step_tracker`]): the same
/// recursion as [`track`].
pub fn track_linearized(
    dims: (usize, usize),
    cost: &QuadraticCost,
    xs: &[DVector<f64>],
    us: &[DVector<f64>],
    jacobians: &mut StepJacobians<'_>,
) -> Result<TrackingController, ControlError> {
    riccati(dims, cost, xs, us, ValueModel::Lqr, jacobians, None)
}

/// The backward recursion of the module docs, for `dims` = (n, m).
fn riccati(
    (n, m): (usize, usize),
    cost: &QuadraticCost,
    xs: &[DVector<f64>],
    us: &[DVector<f64>],
    model: ValueModel,
    jacobians: &mut StepJacobians<'_>,
    second: Option<&mut SecondDerivatives<'_>>,
) -> Result<TrackingController, ControlError> {
    check_trajectory((n, m), cost, xs, us)?;
    on_dims!(n, m, |nd, md| riccati_on(
        nd, md, cost, xs, us, model, jacobians, second
    ))
}

/// The errors [`riccati`] reports before any work: an empty horizon, N + 1 states for N
/// controls, each of its size, and a cost for these sizes and this horizon.
fn check_trajectory(
    (n, m): (usize, usize),
    cost: &QuadraticCost,
    xs: &[DVector<f64>],
    us: &[DVector<f64>],
) -> Result<(), ControlError> {
    let horizon = us.len();
    if horizon == 0 {
        return Err(ControlError::EmptyHorizon);
    }
    if xs.len() != horizon + 1 {
        return Err(ControlError::DimensionMismatch {
            what: "reference states (N + 1)",
            expected: horizon + 1,
            found: xs.len(),
        });
    }
    for (what, v, d) in xs
        .iter()
        .map(|x| ("reference state", x, n))
        .chain(us.iter().map(|u| ("reference control", u, m)))
    {
        if v.len() != d {
            return Err(ControlError::DimensionMismatch {
                what,
                expected: d,
                found: v.len(),
            });
        }
    }
    cost.validate(n, m, horizon)?;
    Ok(())
}

/// [`riccati`] on matrices of dimensions `Nd` × `Md` (fixed-size where [`super::small`] has
/// the size): the inputs (A_k, B_k, the cost's derivatives) are copied in and the gains and
/// value derivatives copied out, every product on the fixed-size matrices.
#[allow(clippy::too_many_arguments)]
fn riccati_on<Nd: Dim, Md: Dim>(
    nd: Nd,
    md: Md,
    cost: &QuadraticCost,
    xs: &[DVector<f64>],
    us: &[DVector<f64>],
    model: ValueModel,
    jacobians: &mut StepJacobians<'_>,
    mut second: Option<&mut SecondDerivatives<'_>>,
) -> Result<TrackingController, ControlError>
where
    DefaultAllocator: SmallAlloc<Nd, Md>,
{
    let (n, m) = (nd.value(), md.value());
    let horizon = us.len();
    let z = Zeros { n: nd, m: md };
    // The sources write heap matrices; they are copied into the fixed-size ones.
    let (mut a_src, mut b_src) = (DMatrix::zeros(n, n), DMatrix::zeros(n, m));
    let mut l_src = StageDerivatives::new(n, m);
    let (mut a, mut b) = (z.nn(), z.nm());
    let (mut lx, mut lu, mut lxx, mut luu) = (z.vn(), z.vm(), z.nn(), z.mm());
    let mut fzz = match model {
        ValueModel::Lqr => Vec::new(),
        ValueModel::Ddp { .. } => vec![DMatrix::zeros(n + m, n + m); n],
    };
    let mut gains = Knots::zeros(horizon, m, n);
    let mut value_ref = vec![0.0; horizon + 1];
    let mut pv = Knots::zeros(horizon + 1, n, 1);
    let mut pm = Knots::zeros(horizon + 1, n, n);
    // p_{k+1} and P_{k+1}, then p_k and P_k.
    let (mut p1, mut hess1, mut p, mut hess) = (z.vn(), z.nn(), z.vn(), z.nn());
    {
        let (mut p_n, mut hess_n) = (DVector::zeros(n), DMatrix::zeros(n, n));
        cost.terminal_derivatives(&xs[horizon], &mut p_n, &mut hess_n);
        value_ref[horizon] = cost.terminal(&xs[horizon]);
        copy_into(&mut p1, &p_n);
        copy_into(&mut hess1, &hess_n);
        copy_into(&mut pv.matrix_mut(horizon), &p_n);
        copy_into(&mut pm.matrix_mut(horizon), &hess_n);
    }
    // Scratch for the step: every product is written in place (`mul_to`, `transpose_to`), the
    // same kernels and summation order as the operator forms, so the loop does not allocate.
    let (mut at, mut bt) = (z.nn(), z.mn());
    let (mut qx, mut qu) = (z.vn(), z.vm());
    let (mut tn, mut tm) = (z.vn(), z.vm());
    let (mut pa, mut qxx, mut tnn) = (z.nn(), z.nn(), z.nn());
    let (mut quu, mut tmm, mut chol) = (z.mm(), z.mm(), z.mm());
    let (mut qux, mut tmn) = (z.mn(), z.mn());
    let (mut gt, mut tnm) = (z.nm(), z.nm());
    let mut gain = z.mn();
    for k in (0..horizon).rev() {
        jacobians(k, &xs[k], &us[k], &mut a_src, &mut b_src);
        copy_into(&mut a, &a_src);
        copy_into(&mut b, &b_src);
        cost.running_derivatives(k, &xs[k], &us[k], &mut l_src);
        copy_into(&mut lx, &l_src.lx);
        copy_into(&mut lu, &l_src.lu);
        copy_into(&mut lxx, &l_src.lxx);
        copy_into(&mut luu, &l_src.luu);
        a.transpose_to(&mut at);
        b.transpose_to(&mut bt);
        // Q_x = l_x + Aᵀ p', Q_u = l_u + Bᵀ p'.
        linalg::mul_to(&at, &p1, &mut tn);
        qx.copy_from(&lx);
        qx += &tn;
        linalg::mul_to(&bt, &p1, &mut tm);
        qu.copy_from(&lu);
        qu += &tm;
        // Q_xx = l_xx + Aᵀ (P' A), Q_uu = l_uu + (Bᵀ P') B, Q_ux = Bᵀ (P' A).
        linalg::mul_to(&hess1, &a, &mut pa);
        linalg::mul_to(&at, &pa, &mut tnn);
        qxx.copy_from(&lxx);
        qxx += &tnn;
        linalg::mul_to(&bt, &hess1, &mut tmn);
        linalg::mul_to(&tmn, &b, &mut tmm);
        quu.copy_from(&luu);
        quu += &tmm;
        linalg::mul_to(&bt, &pa, &mut qux);
        if let (ValueModel::Ddp { fd_step }, Some(second)) = (model, second.as_mut()) {
            second(&xs[k], &us[k], fd_step, &mut fzz);
            for (c, h) in fzz.iter().enumerate() {
                let w = p1[c];
                for j in 0..n {
                    for i in 0..n {
                        qxx[(i, j)] += h[(i, j)] * w;
                    }
                    for i in 0..m {
                        qux[(i, j)] += h[(n + i, j)] * w;
                    }
                }
                for j in 0..m {
                    for i in 0..m {
                        quu[(i, j)] += h[(n + i, n + j)] * w;
                    }
                }
            }
        }
        chol.copy_from(&quu);
        if !cholesky_in_place(&mut chol, m) {
            return Err(ControlError::NotPositiveDefinite { step: k });
        }
        gain.copy_from(&qux);
        gain.neg_mut();
        // Column by column (column-major storage).
        for column in gain.as_mut_slice().chunks_exact_mut(m.max(1)) {
            cholesky_solve_in_place(&chol, m, column);
        }
        // p = Q_x + Kᵀ Q_u.
        gain.transpose_to(&mut gt);
        linalg::mul_to(&gt, &qu, &mut tn);
        p.copy_from(&qx);
        p += &tn;
        // P = Q_xx + (Kᵀ Q_uu) K + Kᵀ Q_ux + Q_uxᵀ K, summed in that order.
        linalg::mul_to(&gt, &quu, &mut tnm);
        linalg::mul_to(&tnm, &gain, &mut tnn);
        hess.copy_from(&qxx);
        hess += &tnn;
        linalg::mul_to(&gt, &qux, &mut tnn);
        hess += &tnn;
        qux.transpose_to(&mut tnm);
        linalg::mul_to(&tnm, &gain, &mut tnn);
        hess += &tnn;
        symmetrize(&mut hess);
        copy_into(&mut gains.matrix_mut(k), &gain);
        copy_into(&mut pv.matrix_mut(k), &p);
        copy_into(&mut pm.matrix_mut(k), &hess);
        std::mem::swap(&mut p1, &mut p);
        std::mem::swap(&mut hess1, &mut hess);
        value_ref[k] = cost.running(k, &xs[k], &us[k]) + value_ref[k + 1];
    }
    Ok(TrackingController {
        x_ref: Knots::from_vectors(xs),
        u_ref: Knots::from_vectors(us),
        gains,
        value_ref,
        value_gradient: pv,
        value_hessian: pm,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::control::test_models::LinearOde;
    use crate::control::StateCost;

    /// Scalar ẋ = a x + b u: RK4 of a linear ODE is exactly x' = φ x + γ u with the degree-4
    /// Taylor polynomials of e^{ah} and (e^{ah} − 1)/a · b.
    fn scalar_problem(
        a: f64,
        b: f64,
        h: f64,
        q: f64,
        r: f64,
        qf: f64,
    ) -> (Rk4Map<LinearOde>, QuadraticCost, f64, f64) {
        let map = Rk4Map::new(
            LinearOde {
                a: DMatrix::from_element(1, 1, a),
                b: DMatrix::from_element(1, 1, b),
            },
            h,
        )
        .unwrap();
        let ah = a * h;
        let phi = 1.0 + ah + ah * ah / 2.0 + ah.powi(3) / 6.0 + ah.powi(4) / 24.0;
        let gamma = h * b * (1.0 + ah / 2.0 + ah * ah / 6.0 + ah.powi(3) / 24.0);
        let cost = QuadraticCost {
            dt: h,
            r: DMatrix::from_element(1, 1, r),
            state: Some(StateCost {
                weight: DMatrix::from_element(1, 1, q),
                reference: vec![DVector::zeros(1)],
            }),
            q_final: DMatrix::from_element(1, 1, qf),
            x_final: DVector::zeros(1),
        };
        (map, cost, phi, gamma)
    }

    #[test]
    fn scalar_riccati_matches_the_hand_recursion_and_the_algebraic_riccati_root() {
        let (a, b, h, q, r, qf) = (0.7, 1.3, 0.05, 2.0, 0.5, 3.0);
        let (map, cost, phi, gamma) = scalar_problem(a, b, h, q, r, qf);
        let horizon = 400;
        // The zero trajectory is feasible for a linear system.
        let xs = vec![DVector::zeros(1); horizon + 1];
        let us = vec![DVector::zeros(1); horizon];
        let ctl = track(&map, &cost, &xs, &us).unwrap();
        // Hand recursion of the discrete scalar Riccati equation, V = ½ P x²:
        // P_N = 2 q_f; P = 2 q h + φ² P' − (φ γ P')² / (r h + γ² P'); K = −φ γ P' / (r h + γ² P').
        let (qd, rd) = (2.0 * q * h, r * h);
        let mut p = 2.0 * qf;
        assert!((ctl.value_hessian.matrix(horizon)[(0, 0)] - p).abs() < 1e-12);
        for k in (0..horizon).rev() {
            let s = rd + gamma * gamma * p;
            let gain = -phi * gamma * p / s;
            p = qd + phi * phi * p - (phi * gamma * p).powi(2) / s;
            assert!((ctl.gains.matrix(k)[(0, 0)] - gain).abs() < 1e-9 * gain.abs().max(1.0));
            assert!((ctl.value_hessian.matrix(k)[(0, 0)] - p).abs() < 1e-9 * p.max(1.0));
            assert_eq!(ctl.value_gradient.vector(k)[0], 0.0);
        }
        // Far from the end, P_k solves γ² P² + ((1 − φ²) r_d − q_d γ²) P − q_d r_d = 0.
        let bq = (1.0 - phi * phi) * rd - qd * gamma * gamma;
        let root = (-bq + (bq * bq + 4.0 * gamma * gamma * qd * rd).sqrt()) / (2.0 * gamma * gamma);
        assert!(
            (ctl.value_hessian.matrix(0)[(0, 0)] - root).abs() < 1e-8 * root,
            "{} vs {root}",
            ctl.value_hessian.matrix(0)[(0, 0)]
        );
        // The value at x is ½ P_0 x², and the policy is K_0 x.
        assert!((ctl.value(&[0.3], 0) - 0.5 * root * 0.09).abs() < 1e-8);
        assert!((ctl.policy(&[0.3], 0)[0] - 0.3 * ctl.gains.matrix(0)[(0, 0)]).abs() < 1e-15);
    }

    #[test]
    fn value_equals_the_cost_of_following_the_policy_on_a_linear_system() {
        // On a linear system with quadratic cost the quadratic value function of the tracking
        // policy is exact, also around a non-optimal reference trajectory.
        let (map, cost, _, _) = scalar_problem(-0.4, 1.0, 0.1, 1.0, 0.2, 5.0);
        let horizon = 30;
        let us: Vec<DVector<f64>> = (0..horizon)
            .map(|k| DVector::from_element(1, (k as f64 * 0.3).sin()))
            .collect();
        let xs = map.rollout(&DVector::from_element(1, 1.0), &us).unwrap();
        let ctl = track(&map, &cost, &xs, &us).unwrap();
        assert!((ctl.value_ref[0] - cost.total(&xs, &us)).abs() < 1e-12);
        for k0 in [0, 10, 29] {
            let start = xs[k0][0] + 0.37;
            let mut x = DVector::from_element(1, start);
            let mut total = 0.0;
            let mut ws = map.workspace();
            let mut next = DVector::zeros(1);
            for k in k0..horizon {
                let u = ctl.policy(x.as_slice(), k);
                total += cost.running(k, &x, &u);
                map.step(&x, &u, &mut next, &mut ws);
                std::mem::swap(&mut x, &mut next);
            }
            total += cost.terminal(&x);
            let v = ctl.value(&[start], k0);
            assert!(
                (v - total).abs() < 1e-10 * total.abs().max(1.0),
                "k0 = {k0}: {v} vs {total}"
            );
        }
    }

    #[test]
    fn fixed_size_recursion_is_the_dynamic_one_bit_for_bit() {
        // The acrobot (4 × 1) and a damped pendulum (2 × 1) run on fixed-size matrices
        // (`super::super::small`); the heap path must give the same gains and value functions,
        // bit for bit, for both value models and with a running state cost.
        use crate::control::test_models::DampedPendulum;
        use crate::physics::acrobot::Acrobot;
        let dt = 0.02;
        recursion_bits_agree(
            &Rk4Map::new(Acrobot::default(), dt).unwrap(),
            &[-1.2, 0.3, 0.5, -0.7],
        );
        recursion_bits_agree(&Rk4Map::new(DampedPendulum, dt).unwrap(), &[2.5, -0.4]);
    }

    /// Asserts that [`track_with`] (fixed-size matrices for `map`'s dimensions) and the heap
    /// recursion give the same bits along a driven rollout from `x0`.
    fn recursion_bits_agree<M: Linearize>(map: &Rk4Map<M>, x0: &[f64]) {
        use crate::control::StateCost;
        use nalgebra::Dyn;
        let (n, m, dt) = (map.state_dim(), map.control_dim(), map.dt);
        let us: Vec<DVector<f64>> = (0..60)
            .map(|k| DVector::from_element(m, 4.0 * (k as f64 * dt * 5.0).sin()))
            .collect();
        let xs = map.rollout(&DVector::from_column_slice(x0), &us).unwrap();
        let q = DMatrix::from_fn(n, n, |i, j| if i == j { 3.0 + i as f64 } else { 0.4 });
        let mut cost =
            QuadraticCost::effort(dt, m, DMatrix::identity(n, n) * 5.0, DVector::zeros(n));
        cost.r *= 100.0;
        cost.state = Some(StateCost {
            weight: q,
            reference: xs[..60].to_vec(),
        });
        let bits = |ctl: &TrackingController| -> Vec<u64> {
            let matrices = ctl
                .gains
                .as_slice()
                .iter()
                .chain(ctl.value_hessian.as_slice());
            matrices
                .chain(ctl.value_gradient.as_slice())
                .chain(&ctl.value_ref)
                .map(|v| v.to_bits())
                .collect()
        };
        for model in [ValueModel::Lqr, ValueModel::Ddp { fd_step: 1e-5 }] {
            let fixed = track_with(map, &cost, &xs, &us, model).unwrap();
            let mut ws = map.workspace();
            let mut ws2 = map.workspace();
            let mut second =
                |x: &DVector<f64>, u: &DVector<f64>, h: f64, f: &mut [DMatrix<f64>]| {
                    map.second_derivatives(x, u, h, f, &mut ws2)
                };
            let second: Option<&mut SecondDerivatives<'_>> = match model {
                ValueModel::Lqr => None,
                ValueModel::Ddp { .. } => Some(&mut second),
            };
            let mut jac =
                |_: usize,
                 x: &DVector<f64>,
                 u: &DVector<f64>,
                 a: &mut DMatrix<f64>,
                 b: &mut DMatrix<f64>| map.jacobians(x, u, a, b, &mut ws);
            let dynamic =
                riccati_on(Dyn(n), Dyn(m), &cost, &xs, &us, model, &mut jac, second).unwrap();
            assert_eq!(bits(&fixed), bits(&dynamic), "n = {n}, {model:?}");
        }
    }

    #[test]
    fn tracking_the_optimized_swing_up_rejects_a_perturbation() {
        use crate::control::ddp::{self, DdpOptions, DdpVariant};
        use crate::physics::acrobot::Acrobot;
        use std::f64::consts::FRAC_PI_2;
        let dt = 0.02;
        let map = Rk4Map::new(Acrobot::default(), dt).unwrap();
        let cost = QuadraticCost::effort(
            dt,
            1,
            DMatrix::from_diagonal(&DVector::from_vec(vec![100.0, 100.0, 10.0, 10.0])),
            DVector::from_vec(vec![FRAC_PI_2, 0.0, 0.0, 0.0]),
        );
        let x0 = DVector::from_vec(vec![-FRAC_PI_2, 0.0, 0.0, 0.0]);
        let u_init: Vec<DVector<f64>> = (0..150)
            .map(|k| DVector::from_element(1, (k as f64 * dt * 3.0).sin()))
            .collect();
        // Stopped by the gradient alone (tol_cost 0): the comparison below needs the optimum,
        // and a relative cost change below 1e-8 can come first (gradient norm 7e-6).
        let options = DdpOptions {
            variant: DdpVariant::Full,
            tol_cost: 0.0,
            ..DdpOptions::default()
        };
        let sol = ddp::solve(&map, &cost, &x0, &u_init, &options).unwrap();
        assert!(
            sol.gradient_norm < 1e-6,
            "DDP did not converge: {:?}, gradient norm {}",
            sol.termination,
            sol.gradient_norm
        );
        let ctl = track(&map, &cost, &sol.x, &sol.u).unwrap();
        // With the second-order terms the tracker is full DDP's last backward pass: at the
        // optimum (unregularized, feedforward ~ 0) its gains are the solver's.
        let ddp = track_with(
            &map,
            &cost,
            &sol.x,
            &sol.u,
            ValueModel::Ddp {
                fd_step: options.fd_step,
            },
        )
        .unwrap();
        assert_eq!(sol.regularization, 0.0);
        let (mut diff, mut scale, mut lqr_diff) = (0.0f64, 0.0f64, 0.0f64);
        for k in 0..150 {
            diff = diff.max((ddp.gains.matrix(k) - sol.gains.matrix(k)).abs().max());
            lqr_diff = lqr_diff.max((ctl.gains.matrix(k) - sol.gains.matrix(k)).abs().max());
            scale = scale.max(sol.gains.matrix(k).abs().max());
        }
        assert!(
            diff < 1e-6 * scale,
            "DDP tracker gains off by {diff} (scale {scale})"
        );
        // The first-order (LQR) gains differ: the second-order terms matter here.
        assert!(lqr_diff > 1e3 * diff, "LQR {lqr_diff} vs DDP {diff}");
        // eq. 12 along the trajectory: the remaining cost.
        assert!((ctl.value_ref[0] - sol.cost).abs() < 1e-9 * sol.cost);
        assert_eq!(ctl.value(sol.x[0].as_slice(), 0), ctl.value_ref[0]);
        // At an optimum p_k is the costate: p_0 = ∂J/∂x_0 = λ_0 of the adjoint recursion
        // λ_N = g_x, λ_k = F_xᵀ λ_{k+1} (no running state cost here).
        let mut lam = DVector::zeros(4);
        let mut s1 = DMatrix::zeros(4, 4);
        cost.terminal_derivatives(&sol.x[150], &mut lam, &mut s1);
        let mut ws = map.workspace();
        let (mut fx, mut fu) = (DMatrix::zeros(4, 4), DMatrix::zeros(4, 1));
        for k in (0..150).rev() {
            map.jacobians(&sol.x[k], &sol.u[k], &mut fx, &mut fu, &mut ws);
            lam = fx.transpose() * &lam;
        }
        // The open-loop cost is very curved in x_0 (∂²J/∂x² ~ 1e5 here), so the differences
        // need a tiny step; the adjoint λ_0 is the sharp check.
        let h = 1e-7;
        for i in 0..4 {
            let (mut xp, mut xm) = (x0.clone(), x0.clone());
            xp[i] += h;
            xm[i] -= h;
            let jp = cost.total(&map.rollout(&xp, &sol.u).unwrap(), &sol.u);
            let jm = cost.total(&map.rollout(&xm, &sol.u).unwrap(), &sol.u);
            let fd = (jp - jm) / (2.0 * h);
            let p = ctl.value_gradient.vector(0)[i];
            assert!(
                (lam[i] - p).abs() < 1e-6 * p.abs().max(1.0),
                "p_0[{i}] {p} vs λ {}",
                lam[i]
            );
            assert!(
                (fd - p).abs() < 1e-4 * fd.abs().max(1.0),
                "p_0[{i}] {p} vs {fd}"
            );
        }
        // From a start 3° off, feedback lands near the handstand; the open-loop tape does not.
        let start = &x0 + DVector::from_vec(vec![0.05, -0.05, 0.0, 0.0]);
        let closed = closed_loop(&map, &cost, &ctl, &start, true);
        let open = closed_loop(&map, &cost, &ctl, &start, false);
        let target = &sol.x[150];
        let (d_closed, d_open) = ((&closed.0 - target).norm(), (&open.0 - target).norm());
        assert!(
            d_closed < 0.2 * d_open,
            "closed loop {d_closed} vs open loop {d_open}"
        );
        // The quadratic value function predicts the closed-loop cost of nearby starts; the
        // first-order part is exact at an optimum, so the relative error of the predicted
        // increase shrinks linearly with the offset.
        let rel_err = |d: f64| {
            let start = &x0 + DVector::from_vec(vec![d, -d, 0.0, 0.0]);
            let actual = closed_loop(&map, &cost, &ctl, &start, true).1;
            let predicted = ctl.value(start.as_slice(), 0);
            ((predicted - actual) / (actual - sol.cost)).abs()
        };
        let (e1, e2) = (rel_err(0.01), rel_err(0.005));
        assert!(e1 < 0.05 && e2 < 0.65 * e1, "relative errors {e1}, {e2}");
    }

    /// Final state and cost of following the controller (or only its tape) from `start`.
    fn closed_loop<M: Linearize>(
        map: &Rk4Map<M>,
        cost: &QuadraticCost,
        ctl: &TrackingController,
        start: &DVector<f64>,
        feedback: bool,
    ) -> (DVector<f64>, f64) {
        let mut ws = map.workspace();
        let mut x = start.clone();
        let mut next = x.clone();
        let mut total = 0.0;
        for k in 0..ctl.horizon() {
            let u = if feedback {
                ctl.policy(x.as_slice(), k)
            } else {
                ctl.u_ref.vector(k).clone_owned()
            };
            total += cost.running(k, &x, &u);
            map.step(&x, &u, &mut next, &mut ws);
            std::mem::swap(&mut x, &mut next);
        }
        total += cost.terminal(&x);
        (x, total)
    }

    #[test]
    fn rejects_mismatched_trajectories() {
        let (map, cost, _, _) = scalar_problem(0.1, 1.0, 0.1, 1.0, 1.0, 1.0);
        let us = vec![DVector::zeros(1); 3];
        let xs = vec![DVector::zeros(1); 3];
        assert!(matches!(
            track(&map, &cost, &xs, &us),
            Err(ControlError::DimensionMismatch {
                expected: 4,
                found: 3,
                ..
            })
        ));
        assert_eq!(
            track(&map, &cost, &xs[..1], &[]),
            Err(ControlError::EmptyHorizon)
        );
    }
}
