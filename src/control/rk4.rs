//! # The RK4 map of a continuous model and its exact derivatives
//!
//! F(x, u) is one classic RK4 step of `dt` with u held constant: with h = dt, stage states
//! y_s = x + c_s k_{s−1} (c = 0, h/2, h/2, h) and slopes k_s = f(y_s, u),
//!
//! ```text
//! F(x, u) = x + h/6 (k_1 + 2 k_2 + 2 k_3 + k_4).
//! ```
//!
//! Its Jacobians are exact, chained through the stage Jacobians A_s, B_s of f at (y_s, u):
//!
//! ```text
//! ∂k_s/∂x = A_s (I + c_s ∂k_{s−1}/∂x),   ∂k_s/∂u = A_s c_s ∂k_{s−1}/∂u + B_s,
//! F_x = I + h/6 (∂k_1 + 2∂k_2 + 2∂k_3 + ∂k_4)/∂x,   F_u likewise without the I;
//! ```
//!
//! second derivatives (full DDP) are central differences of (F_x, F_u). As a
//! [`DifferentiableStep`] its vector–Jacobian product is s̄ = F_xᵀ s̄', ū = F_uᵀ s̄', so BPTT
//! runs through a physical model exactly as through an emulator.
//!
//! ## References
//! - E. Hairer, S. P. Nørsett, G. Wanner, *Solving Ordinary Differential Equations I*,
//!   Springer 1993, §II.1 (the classic Runge–Kutta method).

use super::small::{copy_into, on_dims, SmallAlloc, Zeros};
use super::{symmetrize, ControlError};
use crate::lanes::X4;
use crate::linalg;
use crate::physics::linearize::Linearize;
use crate::physics::{DifferentiableStep, Ode};
use nalgebra::{DMatrix, DVector, DefaultAllocator, Dim, Dyn, Matrix, OMatrix, RawStorageMut};

/// What [`Rk4Map::jacobians_each`] hands each knot's (F_x, F_u) to, with the knot's index.
pub type KnotJacobians<'a> = dyn FnMut(usize, &DMatrix<f64>, &DMatrix<f64>) + 'a;

/// Scratch buffers of [`Rk4Map`]; make one with [`Rk4Map::workspace`].
#[derive(Debug, Clone)]
pub struct Rk4Workspace {
    k: [DVector<f64>; 4],
    y: DVector<f64>,
    a: DMatrix<f64>,
    b: DMatrix<f64>,
    /// The Jacobian chain for sizes without fixed-size matrices (`super::small`).
    chain: Chain<Dyn, Dyn>,
    xp: DVector<f64>,
    up: DVector<f64>,
    fxp: DMatrix<f64>,
    fup: DMatrix<f64>,
    fxm: DMatrix<f64>,
    fum: DMatrix<f64>,
}

/// The matrices of [`Rk4Map::jacobians`]' chain for n states and m controls: a stage's
/// Jacobians (A, B), ∂k_s/∂x and ∂k_s/∂u of the four stages, a product's scratch and the
/// sums F_x, F_u. On the stack for fixed sizes.
#[derive(Debug, Clone)]
struct Chain<N: Dim, M: Dim>
where
    DefaultAllocator: SmallAlloc<N, M>,
{
    a: OMatrix<f64, N, N>,
    b: OMatrix<f64, N, M>,
    dkx: [OMatrix<f64, N, N>; 4],
    dku: [OMatrix<f64, N, M>; 4],
    tmp: OMatrix<f64, N, N>,
    fx: OMatrix<f64, N, N>,
    fu: OMatrix<f64, N, M>,
}

impl<N: Dim, M: Dim> Chain<N, M>
where
    DefaultAllocator: SmallAlloc<N, M>,
{
    fn new(n: N, m: M) -> Self {
        let z = Zeros { n, m };
        Self {
            a: z.nn(),
            b: z.nm(),
            dkx: [z.nn(), z.nn(), z.nn(), z.nn()],
            dku: [z.nm(), z.nm(), z.nm(), z.nm()],
            tmp: z.nn(),
            fx: z.nn(),
            fu: z.nm(),
        }
    }
}

/// The discrete-time map F(x, u): one classic RK4 step of `dt` of a continuous model, with the
/// control held constant, and its exact first derivatives.
#[derive(Debug, Clone, PartialEq)]
pub struct Rk4Map<M> {
    /// The continuous-time model.
    pub model: M,
    /// Step length (s).
    pub dt: f64,
}

impl<M: Ode> Rk4Map<M> {
    /// Discretizes `model` with step `dt` (s).
    pub fn new(model: M, dt: f64) -> Result<Self, ControlError> {
        if !(dt.is_finite() && dt > 0.0) {
            return Err(ControlError::InvalidTimeStep(dt));
        }
        Ok(Self { model, dt })
    }

    /// State dimension n.
    pub fn state_dim(&self) -> usize {
        self.model.state_dim()
    }

    /// Control dimension m.
    pub fn control_dim(&self) -> usize {
        self.model.control_dim()
    }

    /// Scratch buffers sized for this model.
    pub fn workspace(&self) -> Rk4Workspace {
        let (n, m) = (self.state_dim(), self.control_dim());
        let v = || DVector::zeros(n);
        let nn = || DMatrix::zeros(n, n);
        let nm = || DMatrix::zeros(n, m);
        Rk4Workspace {
            k: [v(), v(), v(), v()],
            y: v(),
            a: nn(),
            b: nm(),
            chain: Chain::new(Dyn(n), Dyn(m)),
            xp: v(),
            up: DVector::zeros(m),
            fxp: nn(),
            fup: nm(),
            fxm: nn(),
            fum: nm(),
        }
    }

    /// Writes F(x, u) into `out`. Does not allocate. For the state sizes of
    /// `super::small` (4 and 2) the stages live in fixed-size arrays on the stack; the sums
    /// are the same (`step_on_heap` is the same step on the workspace's vectors, tested).
    pub fn step(
        &self,
        x: &DVector<f64>,
        u: &DVector<f64>,
        out: &mut DVector<f64>,
        ws: &mut Rk4Workspace,
    ) {
        match x.len() {
            4 => self.step_fixed::<4>(x.as_slice(), u.as_slice(), out.as_mut_slice()),
            2 => self.step_fixed::<2>(x.as_slice(), u.as_slice(), out.as_mut_slice()),
            _ => self.step_on_heap(x, u, out, ws),
        }
    }

    /// [`Rk4Map::step`] on stack arrays of N states: y_s = x + c_s k_{s−1} and
    /// F = x + w k_0 + 2w k_1 + 2w k_2 + w k_3, summed in [`Rk4Map::step_on_heap`]'s order
    /// (nalgebra's `axpy` with β = 1 computes a·x + y, one product and one sum per entry).
    fn step_fixed<const N: usize>(&self, x: &[f64], u: &[f64], out: &mut [f64]) {
        let x: [f64; N] = x.try_into().expect("state of N values");
        let h = self.dt;
        let c = [0.0, 0.5 * h, 0.5 * h, h];
        let mut k = [[0.0; N]; 4];
        for s in 0..4 {
            let mut y = x;
            if s > 0 {
                for i in 0..N {
                    y[i] += c[s] * k[s - 1][i];
                }
            }
            self.model.derivative(&y, u, &mut k[s]);
        }
        let w = h / 6.0;
        let mut f = x;
        for (weight, ks) in [w, 2.0 * w, 2.0 * w, w].into_iter().zip(&k) {
            for i in 0..N {
                f[i] += weight * ks[i];
            }
        }
        out.copy_from_slice(&f);
    }

    /// [`Rk4Map::step`] on the workspace's heap vectors (any state size).
    fn step_on_heap(
        &self,
        x: &DVector<f64>,
        u: &DVector<f64>,
        out: &mut DVector<f64>,
        ws: &mut Rk4Workspace,
    ) {
        let h = self.dt;
        let c = [0.0, 0.5 * h, 0.5 * h, h];
        for (s, &cs) in c.iter().enumerate() {
            self.stage(s, cs, x, u, ws);
        }
        out.copy_from(x);
        let w = h / 6.0;
        out.axpy(w, &ws.k[0], 1.0);
        out.axpy(2.0 * w, &ws.k[1], 1.0);
        out.axpy(2.0 * w, &ws.k[2], 1.0);
        out.axpy(w, &ws.k[3], 1.0);
    }

    /// The stage state y_s = x + c k_{s−1} (y_0 = x) of RK4 stage `s` into `ws.y`.
    fn stage_point(s: usize, c: f64, x: &DVector<f64>, ws: &mut Rk4Workspace) {
        ws.y.copy_from(x);
        if s > 0 {
            ws.y.axpy(c, &ws.k[s - 1], 1.0);
        }
    }

    /// RK4 stage `s`: the stage state y_s into `ws.y` ([`Rk4Map::stage_point`]) and the stage
    /// slope k_s = f(y_s, u) into `ws.k[s]`.
    fn stage(&self, s: usize, c: f64, x: &DVector<f64>, u: &DVector<f64>, ws: &mut Rk4Workspace) {
        Self::stage_point(s, c, x, ws);
        self.model
            .derivative(ws.y.as_slice(), u.as_slice(), ws.k[s].as_mut_slice());
    }

    /// Rolls out `us` from `x0`: returns the N + 1 states, or the first non-finite step.
    pub fn rollout(
        &self,
        x0: &DVector<f64>,
        us: &[DVector<f64>],
    ) -> Result<Vec<DVector<f64>>, ControlError> {
        let mut ws = self.workspace();
        let mut xs = Vec::with_capacity(us.len() + 1);
        xs.push(x0.clone());
        for (k, u) in us.iter().enumerate() {
            let mut next = DVector::zeros(x0.len());
            self.step(&xs[k], u, &mut next, &mut ws);
            if !next.iter().all(|v| v.is_finite()) {
                return Err(ControlError::NonFinite { step: k });
            }
            xs.push(next);
        }
        Ok(xs)
    }
}

impl<M: Linearize> Rk4Map<M> {
    /// Writes the exact Jacobians F_x (n × n) and F_u (n × m) of the RK4 map at (x, u),
    /// chained through the stage Jacobians (see the module docs). Does not allocate; on
    /// fixed-size matrices where `super::small` has the size.
    pub fn jacobians<Sx, Su>(
        &self,
        x: &DVector<f64>,
        u: &DVector<f64>,
        fx: &mut Matrix<f64, Dyn, Dyn, Sx>,
        fu: &mut Matrix<f64, Dyn, Dyn, Su>,
        ws: &mut Rk4Workspace,
    ) where
        Sx: RawStorageMut<f64, Dyn, Dyn>,
        Su: RawStorageMut<f64, Dyn, Dyn>,
    {
        on_dims!(
            x.len(),
            u.len(),
            |n, m| self.chain(x, u, &mut Chain::new(n, m), ws, fx, fu),
            |_n, _m| {
                // The heap chain lives in the workspace; lent out for the call.
                let mut chain = std::mem::replace(&mut ws.chain, Chain::new(Dyn(0), Dyn(0)));
                self.chain(x, u, &mut chain, ws, fx, fu);
                ws.chain = chain;
            }
        )
    }

    /// F_x and F_u at every knot (`xs[k]`, `us[k]`), k = 0 … N − 1 (N = `us.len()`), handed to
    /// `out(k, F_x, F_u)` in order: bit for bit the values of [`Rk4Map::jacobians`] at each
    /// knot. The knots are independent: where the model has a lane form
    /// ([`Linearize::derivative_and_jacobians_x4`]), the sizes are fixed ones of
    /// `super::small` and the processor has AVX2 and FMA, four knots run at once in the
    /// lanes of [`X4`], each lane repeating the scalar chain's operations in its order (the
    /// acrobot's: 0.12–0.16 µs a knot, from 0.37–0.43 one at a time; PERFORMANCE.md). The
    /// rest go one at a time.
    pub fn jacobians_each(
        &self,
        xs: &[DVector<f64>],
        us: &[DVector<f64>],
        ws: &mut Rk4Workspace,
        mut out: impl FnMut(usize, &DMatrix<f64>, &DMatrix<f64>),
    ) {
        let (n, m) = (self.state_dim(), self.control_dim());
        assert!(xs.len() >= us.len(), "a state for every knot");
        let (mut fx, mut fu) = (DMatrix::zeros(n, n), DMatrix::zeros(n, m));
        let done = match (n, m) {
            (4, 1) => self.jacobians_x4_dispatch::<4, 1>(xs, us, &mut fx, &mut fu, &mut out),
            (2, 1) => self.jacobians_x4_dispatch::<2, 1>(xs, us, &mut fx, &mut fu, &mut out),
            _ => 0,
        };
        for k in done..us.len() {
            self.jacobians(&xs[k], &us[k], &mut fx, &mut fu, ws);
            out(k, &fx, &fu);
        }
    }

    /// [`Rk4Map::jacobians_x4`] compiled for AVX2 and FMA where the processor has them
    /// ([`crate::fastmath::has_avx2_fma`]; the same bits), and none elsewhere: without FMA
    /// each lane's multiply–add would be a call to libm's `fma`, slower than the scalar chain.
    fn jacobians_x4_dispatch<const N: usize, const C: usize>(
        &self,
        xs: &[DVector<f64>],
        us: &[DVector<f64>],
        fx: &mut DMatrix<f64>,
        fu: &mut DMatrix<f64>,
        out: &mut KnotJacobians<'_>,
    ) -> usize {
        #[cfg(target_arch = "x86_64")]
        {
            #[target_feature(enable = "avx2,fma")]
            fn avx2<M: Linearize, const N: usize, const C: usize>(
                map: &Rk4Map<M>,
                (xs, us): (&[DVector<f64>], &[DVector<f64>]),
                fx: &mut DMatrix<f64>,
                fu: &mut DMatrix<f64>,
                out: &mut KnotJacobians<'_>,
            ) -> usize {
                map.jacobians_x4::<N, C>(xs, us, fx, fu, out)
            }
            if crate::fastmath::has_avx2_fma() {
                // SAFETY: the processor supports AVX2 and FMA (checked just above).
                return unsafe { avx2::<M, N, C>(self, (xs, us), fx, fu, out) };
            }
        }
        let _ = (xs, us, fx, fu, out);
        0
    }

    /// [`Rk4Map::jacobians_each`]'s knots in blocks of four ([`Rk4Map::chain_x4`]) for N
    /// states and C controls; returns how many knots it handed to `out` (none if the model
    /// has no lane form).
    #[inline(always)]
    fn jacobians_x4<const N: usize, const C: usize>(
        &self,
        xs: &[DVector<f64>],
        us: &[DVector<f64>],
        fx: &mut DMatrix<f64>,
        fu: &mut DMatrix<f64>,
        out: &mut KnotJacobians<'_>,
    ) -> usize {
        let mut k = 0;
        while k + 4 <= us.len() {
            let (mut x, mut u) = ([X4::splat(0.0); N], [X4::splat(0.0); C]);
            for l in 0..4 {
                let (xl, ul) = (xs[k + l].as_slice(), us[k + l].as_slice());
                for i in 0..N {
                    x[i].0[l] = xl[i];
                }
                for i in 0..C {
                    u[i].0[l] = ul[i];
                }
            }
            let Some((cx, cu)) = self.chain_x4::<N, C>(x, u) else {
                return k;
            };
            for l in 0..4 {
                for (j, col) in cx.iter().enumerate() {
                    for (i, v) in col.iter().enumerate() {
                        fx[(i, j)] = v.lane(l);
                    }
                }
                for (j, col) in cu.iter().enumerate() {
                    for (i, v) in col.iter().enumerate() {
                        fu[(i, j)] = v.lane(l);
                    }
                }
                out(k + l, fx, fu);
            }
            k += 4;
        }
        k
    }

    /// [`Rk4Map::chain`] at four points in lanes, on arrays of columns (`[j][i]` is entry
    /// (i, j)): every sum is nalgebra's, term for term — a product C = A·B sums column j as
    /// A₀ B₀ⱼ, then adds Aₖ Bₖⱼ for k = 1, 2, …; the gemm C ← αA·B + C adds (α Aₖ) Bₖⱼ to
    /// C from k = 0; a scaled sum adds w·b to the entry. Returns (F_x, F_u), or `None` if the
    /// model has no lane form.
    #[inline(always)]
    #[allow(clippy::type_complexity)]
    fn chain_x4<const N: usize, const C: usize>(
        &self,
        x: [X4; N],
        u: [X4; C],
    ) -> Option<([[X4; N]; N], [[X4; N]; C])> {
        let zero = X4::splat(0.0);
        let h = self.dt;
        let c = [0.0, 0.5 * h, 0.5 * h, h];
        let mut k = [[zero; N]; 4];
        let mut dkx = [[[zero; N]; N]; 4];
        let mut dku = [[[zero; N]; C]; 4];
        let (mut a, mut b) = ([[zero; N]; N], [[zero; N]; C]);
        for s in 0..4 {
            // y_s = x + c_s k_{s−1}: `axpy` forms c·k and adds it to the entry.
            let mut y = x;
            if s > 0 {
                let cs = X4::splat(c[s]);
                for i in 0..N {
                    y[i] = cs * k[s - 1][i] + y[i];
                }
            }
            if !self.model.derivative_and_jacobians_x4(
                &y,
                &u,
                &mut k[s],
                a.as_flattened_mut(),
                b.as_flattened_mut(),
            ) {
                return None;
            }
            if s == 0 {
                dkx[0] = a;
                dku[0] = b;
                continue;
            }
            let cs = X4::splat(c[s]);
            // ∂k_s/∂x = A (I + c ∂k_{s−1}/∂x)
            let mut t = dkx[s - 1];
            for col in &mut t {
                for v in col.iter_mut() {
                    *v = *v * cs;
                }
            }
            for (i, col) in t.iter_mut().enumerate() {
                col[i] = col[i] + X4::splat(1.0);
            }
            for (j, tj) in t.iter().enumerate() {
                for i in 0..N {
                    let mut acc = a[0][i] * tj[0];
                    for kk in 1..N {
                        acc = a[kk][i] * tj[kk] + acc;
                    }
                    dkx[s][j][i] = acc;
                }
            }
            // ∂k_s/∂u = c A ∂k_{s−1}/∂u + B
            for j in 0..C {
                for i in 0..N {
                    let mut acc = b[j][i];
                    for kk in 0..N {
                        acc = cs * a[kk][i] * dku[s - 1][j][kk] + acc;
                    }
                    dku[s][j][i] = acc;
                }
            }
        }
        let w = h / 6.0;
        let mut fx = [[zero; N]; N];
        for (i, col) in fx.iter_mut().enumerate() {
            col[i] = X4::splat(1.0);
        }
        let mut fu = [[zero; N]; C];
        for (s, weight) in [w, 2.0 * w, 2.0 * w, w].into_iter().enumerate() {
            let weight = X4::splat(weight);
            for (f, d) in fx.iter_mut().zip(&dkx[s]) {
                for (f, d) in f.iter_mut().zip(d) {
                    *f = *f + weight * *d;
                }
            }
            for (f, d) in fu.iter_mut().zip(&dku[s]) {
                for (f, d) in f.iter_mut().zip(d) {
                    *f = *f + weight * *d;
                }
            }
        }
        Some((fx, fu))
    }

    /// The Jacobian chain of the module docs on `ch`'s matrices, written to `fx`, `fu`; the
    /// model's stage Jacobians go through `ws.a`, `ws.b`.
    fn chain<Nd: Dim, Md: Dim, Sx, Su>(
        &self,
        x: &DVector<f64>,
        u: &DVector<f64>,
        ch: &mut Chain<Nd, Md>,
        ws: &mut Rk4Workspace,
        fx: &mut Matrix<f64, Dyn, Dyn, Sx>,
        fu: &mut Matrix<f64, Dyn, Dyn, Su>,
    ) where
        DefaultAllocator: SmallAlloc<Nd, Md>,
        Sx: RawStorageMut<f64, Dyn, Dyn>,
        Su: RawStorageMut<f64, Dyn, Dyn>,
    {
        let h = self.dt;
        let c = [0.0, 0.5 * h, 0.5 * h, h];
        for s in 0..4 {
            // The stage of [`Rk4Map::stage`], its slope and Jacobians in one evaluation.
            Self::stage_point(s, c[s], x, ws);
            self.model.derivative_and_jacobians(
                ws.y.as_slice(),
                u.as_slice(),
                ws.k[s].as_mut_slice(),
                &mut ws.a,
                &mut ws.b,
            );
            copy_into(&mut ch.a, &ws.a);
            copy_into(&mut ch.b, &ws.b);
            if s == 0 {
                ch.dkx[0].copy_from(&ch.a);
                ch.dku[0].copy_from(&ch.b);
            } else {
                // ∂k_s/∂x = A (I + c ∂k_{s−1}/∂x)
                ch.tmp.copy_from(&ch.dkx[s - 1]);
                ch.tmp *= c[s];
                for i in 0..ch.tmp.nrows() {
                    ch.tmp[(i, i)] += 1.0;
                }
                linalg::mul_to(&ch.a, &ch.tmp, &mut ch.dkx[s]);
                // ∂k_s/∂u = c A ∂k_{s−1}/∂u + B
                let (prev, cur) = ch.dku.split_at_mut(s);
                cur[0].copy_from(&ch.b);
                linalg::gemm(&mut cur[0], c[s], &ch.a, &prev[s - 1], 1.0);
            }
        }
        let w = h / 6.0;
        ch.fx.fill_with_identity();
        ch.fu.fill(0.0);
        for (s, weight) in [w, 2.0 * w, 2.0 * w, w].into_iter().enumerate() {
            ch.fx.zip_apply(&ch.dkx[s], |a, b| *a += weight * b);
            ch.fu.zip_apply(&ch.dku[s], |a, b| *a += weight * b);
        }
        copy_into(fx, &ch.fx);
        copy_into(fu, &ch.fu);
    }

    /// Second derivatives of the map: `out[a]` (length n, each (n + m) × (n + m)) receives the
    /// Hessian of component F_a with respect to z = (x, u), by central differences of the exact
    /// Jacobians with step `step`·max(1, |z_i|), symmetrized. Does not allocate.
    pub fn second_derivatives(
        &self,
        x: &DVector<f64>,
        u: &DVector<f64>,
        step: f64,
        out: &mut [DMatrix<f64>],
        ws: &mut Rk4Workspace,
    ) {
        let (n, m) = (x.len(), u.len());
        assert_eq!(out.len(), n, "one Hessian per state component");
        // Temporarily move the perturbation buffers out so that `ws` can be lent to jacobians.
        let mut xp = std::mem::replace(&mut ws.xp, DVector::zeros(0));
        let mut up = std::mem::replace(&mut ws.up, DVector::zeros(0));
        let mut fxp = std::mem::replace(&mut ws.fxp, DMatrix::zeros(0, 0));
        let mut fup = std::mem::replace(&mut ws.fup, DMatrix::zeros(0, 0));
        let mut fxm = std::mem::replace(&mut ws.fxm, DMatrix::zeros(0, 0));
        let mut fum = std::mem::replace(&mut ws.fum, DMatrix::zeros(0, 0));
        xp.copy_from(x);
        up.copy_from(u);
        for i in 0..n + m {
            let zi = if i < n { x[i] } else { u[i - n] };
            let hi = step * zi.abs().max(1.0);
            for (sign, (fx, fu)) in [(1.0, (&mut fxp, &mut fup)), (-1.0, (&mut fxm, &mut fum))] {
                if i < n {
                    xp[i] = zi + sign * hi;
                } else {
                    up[i - n] = zi + sign * hi;
                }
                self.jacobians(&xp, &up, fx, fu, ws);
            }
            if i < n {
                xp[i] = zi;
            } else {
                up[i - n] = zi;
            }
            // Column i of each Hessian: ∂(row a of [F_x F_u])/∂z_i.
            for (a, hess) in out.iter_mut().enumerate() {
                for j in 0..n {
                    hess[(j, i)] = (fxp[(a, j)] - fxm[(a, j)]) / (2.0 * hi);
                }
                for j in 0..m {
                    hess[(n + j, i)] = (fup[(a, j)] - fum[(a, j)]) / (2.0 * hi);
                }
            }
        }
        for hess in out.iter_mut() {
            symmetrize(hess);
        }
        ws.xp = xp;
        ws.up = up;
        ws.fxp = fxp;
        ws.fup = fup;
        ws.fxm = fxm;
        ws.fum = fum;
    }
}

/// Scratch of [`Rk4Map`] as a [`DifferentiableStep`]: the RK4 workspace, the state and control
/// as vectors, and the step's Jacobians F_x, F_u.
#[derive(Debug, Clone)]
pub struct Rk4StepScratch {
    ws: Rk4Workspace,
    x: DVector<f64>,
    u: DVector<f64>,
    out: DVector<f64>,
    fx: DMatrix<f64>,
    fu: DMatrix<f64>,
}

/// The RK4 step of a physical model as a differentiable step, so that backpropagation through
/// time ([`super::bptt`]) runs through a simulator as it does through an emulator: the vector–Jacobian
/// product is s̄ = F_xᵀ s̄', ū = F_uᵀ s̄' with the exact Jacobians of [`Rk4Map::jacobians`].
impl<M: Linearize> DifferentiableStep for Rk4Map<M> {
    type Scratch = Rk4StepScratch;
    fn state_dim(&self) -> usize {
        self.model.state_dim()
    }
    fn control_dim(&self) -> usize {
        self.model.control_dim()
    }
    fn scratch(&self) -> Rk4StepScratch {
        let (n, m) = (self.model.state_dim(), self.model.control_dim());
        Rk4StepScratch {
            ws: self.workspace(),
            x: DVector::zeros(n),
            u: DVector::zeros(m),
            out: DVector::zeros(n),
            fx: DMatrix::zeros(n, n),
            fu: DMatrix::zeros(n, m),
        }
    }
    fn step(&self, s: &[f64], u: &[f64], sc: &mut Rk4StepScratch, s_next: &mut [f64]) {
        sc.x.copy_from_slice(s);
        sc.u.copy_from_slice(u);
        Rk4Map::step(self, &sc.x, &sc.u, &mut sc.out, &mut sc.ws);
        s_next.copy_from_slice(sc.out.as_slice());
    }
    fn vjp(
        &self,
        s: &[f64],
        u: &[f64],
        s_next_bar: &[f64],
        sc: &mut Rk4StepScratch,
        s_bar: &mut [f64],
        u_bar: &mut [f64],
    ) {
        sc.x.copy_from_slice(s);
        sc.u.copy_from_slice(u);
        self.jacobians(&sc.x, &sc.u, &mut sc.fx, &mut sc.fu, &mut sc.ws);
        let transpose_times = |f: &DMatrix<f64>, out: &mut [f64]| {
            for (j, o) in out.iter_mut().enumerate() {
                *o = f.column(j).iter().zip(s_next_bar).map(|(a, b)| a * b).sum();
            }
        };
        transpose_times(&sc.fx, s_bar);
        transpose_times(&sc.fu, u_bar);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::control::test_models::{random_vec, DampedPendulum};
    use crate::physics::acrobot::Acrobot;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn rk4_step_matches_the_simulator() {
        use crate::physics::{Dynamics, IntegratorKind, Simulator};
        let map = Rk4Map::new(Acrobot::default(), 0.02).unwrap();
        let mut sim = Simulator::new(Acrobot::default(), IntegratorKind::Rk4);
        let x = DVector::from_vec(vec![0.3, -0.7, 1.1, 2.0]);
        let u = DVector::from_vec(vec![1.5]);
        let mut out = DVector::zeros(4);
        map.step(&x, &u, &mut out, &mut map.workspace());
        let mut y = x.as_slice().to_vec();
        sim.step(&mut y, u.as_slice(), 0.02);
        // Same scheme; only the summation order (one rounding) may differ.
        for (a, b) in out.iter().zip(&y) {
            assert!((a - b).abs() < 1e-14, "{out} vs {y:?}");
        }
    }

    /// Bit patterns of a matrix's entries.
    fn bits<R: Dim, C: Dim, S: nalgebra::RawStorage<f64, R, C>>(
        a: &nalgebra::Matrix<f64, R, C, S>,
    ) -> Vec<u64> {
        a.iter().map(|v| v.to_bits()).collect()
    }

    #[test]
    fn fixed_size_jacobian_chain_is_the_dynamic_one_bit_for_bit() {
        // The acrobot (4 × 1) and a damped pendulum (2 × 1) run on fixed-size matrices; the
        // heap path must give the same bits (`super::super::small`), including at large states
        // and controls.
        chain_bits_agree(&Rk4Map::new(Acrobot::default(), 0.05).unwrap(), 5);
        chain_bits_agree(&Rk4Map::new(DampedPendulum, 0.05).unwrap(), 6);
    }

    /// Asserts that `map`'s Jacobians (on fixed-size matrices for its dimensions) equal the
    /// heap chain's bit for bit at 600 random states.
    fn chain_bits_agree<M: Linearize>(map: &Rk4Map<M>, seed: u64) {
        let (n, m) = (map.state_dim(), map.control_dim());
        let mut ws = map.workspace();
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let (mut fx, mut fu) = (DMatrix::zeros(n, n), DMatrix::zeros(n, m));
        let (mut dfx, mut dfu) = (DMatrix::zeros(n, n), DMatrix::zeros(n, m));
        let mut dynamic = Chain::new(Dyn(n), Dyn(m));
        for scale in [0.1, 3.0, 300.0] {
            for _ in 0..200 {
                let x = random_vec(&mut rng, n, scale);
                let u = random_vec(&mut rng, m, 5.0 * scale);
                map.jacobians(&x, &u, &mut fx, &mut fu, &mut ws);
                map.chain(&x, &u, &mut dynamic, &mut ws, &mut dfx, &mut dfu);
                assert_eq!(bits(&fx), bits(&dfx), "F_x at {x}");
                assert_eq!(bits(&fu), bits(&dfu), "F_u at {x}");
            }
        }
    }

    #[test]
    fn jacobians_in_lanes_are_the_scalar_chain_bit_for_bit() {
        // The acrobot has a lane form: 4 knots at a time, then the remainder one by one (203
        // knots); the damped pendulum has none and goes knot by knot. Every knot's F_x, F_u
        // must be `jacobians`' bits, at small and large states and angles past the fast
        // sine's range (libm's, lane by lane).
        // Also the lane body compiled without AVX2 (`jacobians_x4` called directly), which
        // the dispatch does not use but which must be the same arithmetic.
        fn agree<M: Linearize>(map: &Rk4Map<M>, seed: u64, lanes: bool) {
            let (n, m) = (map.state_dim(), map.control_dim());
            let mut ws = map.workspace();
            let mut rng = ChaCha8Rng::seed_from_u64(seed);
            let (mut fx, mut fu) = (DMatrix::zeros(n, n), DMatrix::zeros(n, m));
            for scale in [0.1, 3.0, 300.0, 3e5] {
                let xs: Vec<_> = (0..204).map(|_| random_vec(&mut rng, n, scale)).collect();
                let us: Vec<_> = (0..203).map(|_| random_vec(&mut rng, m, scale)).collect();
                let seen = std::cell::Cell::new(0);
                let mut check = |k: usize, lx: &DMatrix<f64>, lu: &DMatrix<f64>| {
                    assert_eq!(k, seen.get(), "knots in order");
                    seen.set(k + 1);
                    map.jacobians(&xs[k], &us[k], &mut fx, &mut fu, &mut ws);
                    assert_eq!(bits(lx), bits(&fx), "F_x at {}", xs[k]);
                    assert_eq!(bits(lu), bits(&fu), "F_u at {}", xs[k]);
                };
                map.jacobians_each(&xs, &us, &mut map.workspace(), &mut check);
                assert_eq!(seen.get(), us.len());
                if (n, m) == (4, 1) {
                    seen.set(0);
                    let (mut lx, mut lu) = (DMatrix::zeros(n, n), DMatrix::zeros(n, m));
                    let done = map.jacobians_x4::<4, 1>(&xs, &us, &mut lx, &mut lu, &mut check);
                    assert_eq!(done, if lanes { 200 } else { 0 });
                }
            }
        }
        let zero = [X4::splat(0.0)];
        let mut out = [X4::splat(0.0); 24];
        let (dx, rest) = out.split_at_mut(4);
        let (a, b) = rest.split_at_mut(16);
        let acrobot = Acrobot::default();
        let x4 = [X4::splat(0.1); 4];
        assert!(acrobot.derivative_and_jacobians_x4(&x4, &zero, dx, a, b));
        agree(&Rk4Map::new(acrobot, 0.05).unwrap(), 14, true);
        agree(&Rk4Map::new(Acrobot::default(), 0.01).unwrap(), 15, true);
        assert!(!DampedPendulum.derivative_and_jacobians_x4(&x4[..2], &zero, dx, a, b));
        agree(&Rk4Map::new(DampedPendulum, 0.05).unwrap(), 16, false);
    }

    #[test]
    fn fixed_size_step_is_the_heap_one_bit_for_bit() {
        // The acrobot (4 states) and a damped pendulum (2) step on stack arrays; the heap
        // vectors' step must give the same bits, at small and large states.
        fn agree<M: Linearize>(map: &Rk4Map<M>, seed: u64) {
            let (n, m) = (map.state_dim(), map.control_dim());
            let mut ws = map.workspace();
            let mut rng = ChaCha8Rng::seed_from_u64(seed);
            let (mut fixed, mut heap) = (DVector::zeros(n), DVector::zeros(n));
            for scale in [0.1, 3.0, 300.0] {
                for _ in 0..500 {
                    let x = random_vec(&mut rng, n, scale);
                    let u = random_vec(&mut rng, m, 5.0 * scale);
                    map.step(&x, &u, &mut fixed, &mut ws);
                    map.step_on_heap(&x, &u, &mut heap, &mut ws);
                    assert_eq!(bits(&fixed), bits(&heap), "F at {x}");
                }
            }
        }
        agree(&Rk4Map::new(Acrobot::default(), 0.05).unwrap(), 12);
        agree(&Rk4Map::new(DampedPendulum, 0.05).unwrap(), 13);
    }

    #[test]
    fn rk4_jacobians_match_finite_differences_of_the_map() {
        let map = Rk4Map::new(Acrobot::default(), 0.05).unwrap();
        let mut ws = map.workspace();
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let (mut fx, mut fu) = (DMatrix::zeros(4, 4), DMatrix::zeros(4, 1));
        let (mut fp, mut fm) = (DVector::zeros(4), DVector::zeros(4));
        for _ in 0..10 {
            let x = random_vec(&mut rng, 4, 3.0);
            let u = random_vec(&mut rng, 1, 5.0);
            map.jacobians(&x, &u, &mut fx, &mut fu, &mut ws);
            let h = 1e-6;
            for j in 0..5 {
                let (mut xp, mut xm, mut up, mut um) = (x.clone(), x.clone(), u.clone(), u.clone());
                if j < 4 {
                    xp[j] += h;
                    xm[j] -= h;
                } else {
                    up[0] += h;
                    um[0] -= h;
                }
                map.step(&xp, &up, &mut fp, &mut ws);
                map.step(&xm, &um, &mut fm, &mut ws);
                let col = (&fp - &fm) / (2.0 * h);
                let exact = if j < 4 {
                    fx.column(j).into_owned()
                } else {
                    fu.column(0).into_owned()
                };
                let err = (&col - &exact).amax() / exact.amax().max(1.0);
                assert!(err < 1e-7, "column {j}: {col} vs {exact}");
            }
        }
    }

    #[test]
    fn rk4_second_derivatives_match_second_differences_of_the_map() {
        let map = Rk4Map::new(Acrobot::default(), 0.05).unwrap();
        let mut ws = map.workspace();
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let mut hess = vec![DMatrix::zeros(5, 5); 4];
        let mut f = [
            DVector::zeros(4),
            DVector::zeros(4),
            DVector::zeros(4),
            DVector::zeros(4),
        ];
        for _ in 0..4 {
            let x = random_vec(&mut rng, 4, 2.0);
            let u = random_vec(&mut rng, 1, 3.0);
            map.second_derivatives(&x, &u, 1e-5, &mut hess, &mut ws);
            let z = DVector::from_iterator(5, x.iter().chain(u.iter()).copied());
            let h = 1e-4;
            let mut worst: f64 = 0.0;
            for i in 0..5 {
                for j in 0..5 {
                    for (q, (si, sj)) in [(1.0, 1.0), (1.0, -1.0), (-1.0, 1.0), (-1.0, -1.0)]
                        .into_iter()
                        .enumerate()
                    {
                        let mut zp = z.clone();
                        zp[i] += si * h;
                        zp[j] += sj * h;
                        let xp = zp.rows(0, 4).into_owned();
                        let up = zp.rows(4, 1).into_owned();
                        map.step(&xp, &up, &mut f[q], &mut ws);
                    }
                    let d2 = (&f[0] - &f[1] - &f[2] + &f[3]) / (4.0 * h * h);
                    for a in 0..4 {
                        let scale = hess[a].amax().max(1.0);
                        worst = worst.max((d2[a] - hess[a][(i, j)]).abs() / scale);
                    }
                }
            }
            assert!(worst < 1e-5, "second derivatives off by {worst}");
        }
    }
}
