//! # The DDP backward pass and the adjoint gradient
//!
//! Along the current trajectory (x̄, ū), from V_x = g_x, V_xx = g_xx at the last state, each
//! step k = N−1 … 0 builds the local quadratic model of the cost-to-go
//!
//! ```text
//! Q_x  = l_x + F_xᵀ V_x'                  Q_u  = l_u + F_uᵀ V_x'
//! Q_xx = l_xx + F_xᵀ V_xx' F_x (+ V_x'·F_xx)    Q_ux = F_uᵀ V_xx' F_x (+ V_x'·F_ux)
//! Q_uu = l_uu + F_uᵀ V_xx' F_u (+ V_x'·F_uu)
//! ```
//!
//! and the affine control law δu = k + K δx minimizing it, k = −(Q_uu + μI)⁻¹ Q_u,
//! K = −(Q_uu + μI)⁻¹ Q_ux (with bounds: k from [`super::box_qp`], rows of K zero for clamped
//! controls), then propagates
//!
//! ```text
//! V_x  = Q_x + Kᵀ Q_uu k + Kᵀ Q_u + Q_uxᵀ k
//! V_xx = Q_xx + Kᵀ Q_uu K + Kᵀ Q_ux + Q_uxᵀ K.
//! ```
//!
//! The terms in parentheses make full DDP; iLQR drops them. Alongside, the adjoint recursion
//! λ_N = g_x, λ_k = l_x + F_xᵀ λ_{k+1} gives the exact gradient ∂J/∂u_k = l_u + F_uᵀ λ_{k+1}
//! ([`cost_gradient`]), which the stopping test uses (projected on the bounds).
//!
//! ## References
//! - D. H. Jacobson, D. Q. Mayne, *Differential Dynamic Programming*, Elsevier, 1970.
//! - Y. Tassa, T. Erez, E. Todorov, *Synthesis and stabilization of complex behaviors through
//!   online trajectory optimization*, IROS 2012.

use super::{box_qp, Buffers, DdpOptions, DdpVariant};
use crate::control::small::{copy_into, on_dims, SmallAlloc, Zeros};
use crate::control::{
    cholesky_in_place, cholesky_solve_in_place, symmetrize, ControlError, QuadraticCost, Rk4Map,
    StageDerivatives,
};
use crate::linalg;
use crate::physics::linearize::Linearize;
use nalgebra::{DMatrix, DVector, DefaultAllocator, Dim, Matrix, RawStorage, RawStorageMut, U1};

/// Exact gradient ∂J/∂u_k of the total cost for the controls `us` from `x0` (adjoint method).
pub fn cost_gradient<M: Linearize>(
    map: &Rk4Map<M>,
    cost: &QuadraticCost,
    x0: &DVector<f64>,
    us: &[DVector<f64>],
) -> Result<Vec<DVector<f64>>, ControlError> {
    let (n, m) = (map.state_dim(), map.control_dim());
    let xs = map.rollout(x0, us)?;
    let mut ws = map.workspace();
    let (mut fx, mut fu) = (DMatrix::zeros(n, n), DMatrix::zeros(n, m));
    let mut l = StageDerivatives::new(n, m);
    let mut lam = DVector::zeros(n);
    let mut gxx = DMatrix::zeros(n, n);
    cost.terminal_derivatives(&xs[us.len()], &mut lam, &mut gxx);
    let mut grads = vec![DVector::zeros(m); us.len()];
    for k in (0..us.len()).rev() {
        map.jacobians(&xs[k], &us[k], &mut fx, &mut fu, &mut ws);
        cost.running_derivatives(k, &xs[k], &us[k], &mut l);
        grads[k] = &l.lu + fu.transpose() * &lam;
        lam = &l.lx + fx.transpose() * &lam;
    }
    Ok(grads)
}

/// Result of a successful backward pass: Σ kᵀQ_u, Σ ½ kᵀQ_uu k, projected gradient norm.
pub(super) struct BackwardResult {
    pub(super) dv1: f64,
    pub(super) dv2: f64,
    pub(super) gradient_norm: f64,
}

/// Backward pass at (xs, us) with regularization μ; `None` when Q_uu + μI is not positive
/// definite at some step. On fixed-size matrices where [`crate::control::small`] has the size
/// (without heap allocation), else on heap matrices allocated once per pass.
pub(super) fn backward(
    cost: &QuadraticCost,
    xs: &[DVector<f64>],
    us: &[DVector<f64>],
    mu: f64,
    options: &DdpOptions,
    b: &mut Buffers,
) -> Option<BackwardResult> {
    on_dims!(xs[0].len(), us[0].len(), |nd, md| backward_on(
        nd, md, cost, xs, us, mu, options, b
    ))
}

/// nalgebra's dot product of two dynamic-size vectors, in its summation order (eight partial
/// sums over blocks of eight, then the rest in turn from the first), for any storage: the
/// products Aᵀx of [`backward_on`] keep the bits of the heap matrices' `gemv_tr`, whose
/// fixed-size dot products of 2 to 4 values add in another order.
fn dot<D: Dim, S1, S2>(a: &Matrix<f64, D, U1, S1>, b: &Matrix<f64, D, U1, S2>) -> f64
where
    S1: RawStorage<f64, D>,
    S2: RawStorage<f64, D>,
{
    let n = a.nrows();
    let mut res = 0.0;
    let mut acc = [0.0; 8];
    let mut i = 0;
    while n - i >= 8 {
        for (l, acc) in acc.iter_mut().enumerate() {
            *acc += a[i + l] * b[i + l];
        }
        i += 8;
    }
    for l in 0..4 {
        res += acc[l] + acc[l + 4];
    }
    for k in i..n {
        res += a[k] * b[k];
    }
    res
}

/// y ← α Aᵀx + βy with [`dot`] (β = 0: y is not read), as nalgebra's `gemv_tr`.
fn gemv_tr<R: Dim, C: Dim, SY, SA, SX>(
    y: &mut Matrix<f64, C, U1, SY>,
    alpha: f64,
    a: &Matrix<f64, R, C, SA>,
    x: &Matrix<f64, R, U1, SX>,
    beta: f64,
) where
    SY: RawStorageMut<f64, C>,
    SA: RawStorage<f64, R, C>,
    SX: RawStorage<f64, R>,
{
    for j in 0..a.ncols() {
        let d = alpha * dot(&a.column(j), x);
        y[j] = if beta == 0.0 { d } else { d + beta * y[j] };
    }
}

/// C ← α AᵀB + βC column by column with [`gemv_tr`], as nalgebra's `gemm_tr`.
fn gemm_tr<R: Dim, C1: Dim, C2: Dim, SC, SA, SB>(
    c: &mut Matrix<f64, C1, C2, SC>,
    alpha: f64,
    a: &Matrix<f64, R, C1, SA>,
    b: &Matrix<f64, R, C2, SB>,
    beta: f64,
) where
    SC: RawStorageMut<f64, C1, C2>,
    SA: RawStorage<f64, R, C1>,
    SB: RawStorage<f64, R, C2>,
{
    for j in 0..c.ncols() {
        gemv_tr(&mut c.column_mut(j), alpha, a, &b.column(j), beta);
    }
}

/// [`backward`] on matrices of dimensions `Nd` × `Md`: the step's Jacobians and the cost's
/// derivatives are copied in and the gains copied out; the bounded case's QP works on the heap
/// buffers of `b`.
#[allow(clippy::too_many_arguments)]
pub(super) fn backward_on<Nd: Dim, Md: Dim>(
    nd: Nd,
    md: Md,
    cost: &QuadraticCost,
    xs: &[DVector<f64>],
    us: &[DVector<f64>],
    mu: f64,
    options: &DdpOptions,
    b: &mut Buffers,
) -> Option<BackwardResult>
where
    DefaultAllocator: SmallAlloc<Nd, Md>,
{
    let horizon = us.len();
    let (n, m) = (nd.value(), md.value());
    let full = options.variant == DdpVariant::Full;
    let z = Zeros { n: nd, m: md };
    let (mut fx, mut fu) = (z.nn(), z.nm());
    let (mut lx, mut lu, mut lxx, mut luu) = (z.vn(), z.vm(), z.nn(), z.mm());
    let (mut vx, mut vxx, mut lam, mut lam_tmp) = (z.vn(), z.nn(), z.vn(), z.vn());
    let (mut qx, mut qu, mut qxx, mut quu, mut qux, mut quu_reg) =
        (z.vn(), z.vm(), z.nn(), z.mm(), z.mn(), z.mm());
    let (mut vxx_fx, mut vxx_fu, mut gu, mut tm, mut tmn) =
        (z.nn(), z.nm(), z.vm(), z.vm(), z.mn());
    let (mut kff, mut gain) = (z.vm(), z.mn());
    cost.terminal_derivatives(&xs[horizon], &mut b.vx, &mut b.vxx);
    copy_into(&mut vx, &b.vx);
    copy_into(&mut vxx, &b.vxx);
    lam.copy_from(&vx);
    let (mut dv1, mut dv2, mut g2) = (0.0, 0.0, 0.0);
    for k in (0..horizon).rev() {
        copy_into(&mut fx, &b.fx.matrix(k));
        copy_into(&mut fu, &b.fu.matrix(k));
        cost.running_derivatives(k, &xs[k], &us[k], &mut b.l);
        copy_into(&mut lx, &b.l.lx);
        copy_into(&mut lu, &b.l.lu);
        copy_into(&mut lxx, &b.l.lxx);
        copy_into(&mut luu, &b.l.luu);
        // Exact (adjoint) gradient, projected on the bounds.
        gu.copy_from(&lu);
        gemv_tr(&mut gu, 1.0, &fu, &lam, 1.0);
        if let Some(bounds) = &options.bounds {
            for (i, g) in gu.iter_mut().enumerate() {
                let u = us[k][i];
                if (u <= bounds.lower[i] && *g > 0.0) || (u >= bounds.upper[i] && *g < 0.0) {
                    *g = 0.0;
                }
            }
        }
        // ‖g‖² as nalgebra's `norm_squared`: 0 + g·g.
        g2 += 0.0 + dot(&gu, &gu);
        lam_tmp.copy_from(&lx);
        gemv_tr(&mut lam_tmp, 1.0, &fx, &lam, 1.0);
        std::mem::swap(&mut lam, &mut lam_tmp);

        // Q function.
        qx.copy_from(&lx);
        gemv_tr(&mut qx, 1.0, &fx, &vx, 1.0);
        qu.copy_from(&lu);
        gemv_tr(&mut qu, 1.0, &fu, &vx, 1.0);
        linalg::mul_to(&vxx, &fx, &mut vxx_fx);
        linalg::mul_to(&vxx, &fu, &mut vxx_fu);
        qxx.copy_from(&lxx);
        gemm_tr(&mut qxx, 1.0, &fx, &vxx_fx, 1.0);
        quu.copy_from(&luu);
        gemm_tr(&mut quu, 1.0, &fu, &vxx_fu, 1.0);
        gemm_tr(&mut qux, 1.0, &fu, &vxx_fx, 0.0);
        if full {
            for (a, hess) in b.fzz[k].iter().enumerate() {
                let w = vx[a];
                for j in 0..n {
                    for i in 0..n {
                        qxx[(i, j)] += w * hess[(i, j)];
                    }
                    for i in 0..m {
                        qux[(i, j)] += w * hess[(n + i, j)];
                    }
                }
                for j in 0..m {
                    for i in 0..m {
                        quu[(i, j)] += w * hess[(n + i, n + j)];
                    }
                }
            }
        }
        quu_reg.copy_from(&quu);
        for i in 0..m {
            quu_reg[(i, i)] += mu;
        }

        // Gains.
        match &options.bounds {
            None => {
                if !cholesky_in_place(&mut quu_reg, m) {
                    return None;
                }
                for i in 0..m {
                    kff[i] = -qu[i];
                }
                cholesky_solve_in_place(&quu_reg, m, kff.as_mut_slice());
                gain.copy_from(&qux);
                gain.neg_mut();
                // Column by column (column-major storage).
                for column in gain.as_mut_slice().chunks_exact_mut(m.max(1)) {
                    cholesky_solve_in_place(&quu_reg, m, column);
                }
            }
            Some(bounds) => {
                copy_into(&mut b.quu_reg, &quu_reg);
                copy_into(&mut b.qu, &qu);
                b.lo.copy_from(&bounds.lower);
                b.lo -= &us[k];
                b.hi.copy_from(&bounds.upper);
                b.hi -= &us[k];
                // Warm start from the previous iteration's feedforward step.
                b.warm.copy_from_slice(b.kff.slice(k));
                if !box_qp(&b.quu_reg, &b.qu, &b.lo, &b.hi, &b.warm, &mut b.qp) {
                    return None;
                }
                copy_into(&mut kff, &b.qp.x);
                gain.fill(0.0);
                let nf = b.qp.free_index.len();
                for j in 0..n {
                    b.qp.rhs.clear();
                    for &i in &b.qp.free_index {
                        b.qp.rhs.push(-qux[(i, j)]);
                    }
                    cholesky_solve_in_place(&b.qp.factor, nf, &mut b.qp.rhs);
                    for (a, &i) in b.qp.free_index.iter().enumerate() {
                        gain[(i, j)] = b.qp.rhs[a];
                    }
                }
            }
        }
        copy_into(&mut b.kff.matrix_mut(k), &kff);
        copy_into(&mut b.gains.matrix_mut(k), &gain);

        // Expected reduction and value update.
        tm.gemv(1.0, &quu, &kff, 0.0);
        dv1 += dot(&kff, &qu);
        dv2 += 0.5 * dot(&kff, &tm);
        vx.copy_from(&qx);
        gemv_tr(&mut vx, 1.0, &gain, &tm, 1.0);
        gemv_tr(&mut vx, 1.0, &gain, &qu, 1.0);
        gemv_tr(&mut vx, 1.0, &qux, &kff, 1.0);
        linalg::gemm(&mut tmn, 1.0, &quu, &gain, 0.0);
        vxx.copy_from(&qxx);
        gemm_tr(&mut vxx, 1.0, &gain, &tmn, 1.0);
        gemm_tr(&mut vxx, 1.0, &gain, &qux, 1.0);
        gemm_tr(&mut vxx, 1.0, &qux, &gain, 1.0);
        symmetrize(&mut vxx);
    }
    Some(BackwardResult {
        dv1,
        dv2,
        gradient_norm: g2.sqrt(),
    })
}
