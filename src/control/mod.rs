//! # Optimal control: trajectory optimization and LQR tracking
//!
//! Everything here works on one discrete-time problem built from a continuous model
//! ẋ = f(x, u) that implements [`Linearize`]:
//!
//! - dynamics x_{k+1} = F(x_k, u_k), one classic RK4 step of `dt` with u_k held constant
//!   ([`Rk4Map`]);
//! - cost J = g(x_N) + Σ_{k<N} dt·(q(x_k) + ½ u_kᵀ R u_k) ([`QuadraticCost`]), with the
//!   terminal cost g(x) = (x − x̄)ᵀ Q_f (x − x̄) of linear Bellman combination (§5.1) and an
//!   optional running state cost q(x) = (x − r_k)ᵀ Q (x − r_k).
//!
//! The derivatives of F are exact for the RK4 map: with stage states y_s = x + c_s k_{s−1}
//! (c = 0, h/2, h/2, h) and stage Jacobians A_s, B_s of f at (y_s, u),
//!
//! ```text
//! ∂k_s/∂x = A_s (I + c_s ∂k_{s−1}/∂x),   ∂k_s/∂u = A_s c_s ∂k_{s−1}/∂u + B_s,
//! F_x = I + h/6 (∂k_1 + 2∂k_2 + 2∂k_3 + ∂k_4)/∂x,   F_u likewise without the I.
//! ```
//!
//! Second derivatives (full DDP only) are central differences of (F_x, F_u).
//!
//! - [`ddp`]: differential dynamic programming, iLQR and full second-order, with
//!   Levenberg–Marquardt regularization, line search and box control bounds.
//! - [`lqr`]: time-varying LQR tracking of a given trajectory and its quadratic value function
//!   (linear Bellman combination, eq. 12).
//!
//! - [`objective`]: NeuroAnimator control-learning objectives (§4.2) as composable terms with
//!   gradients; [`bptt`]: backpropagation through time through any [`DifferentiableStep`] (an
//!   emulator, or [`Rk4Map`] of a physical model: its vector–Jacobian product is
//!   s̄ = F_xᵀ s̄', ū = F_uᵀ s̄' with the exact Jacobians above), plain and momentum descent on
//!   piecewise-constant controls (§4.3);
//!   [`search`]: box-bounded searches with one trace and budget — simulated annealing,
//!   Nelder–Mead, parallel hill climbing and BPTT — on emulator or simulator rollouts (§6).
//!
//! Solvers return data; they never print or write files.

pub mod bptt;
pub mod ddp;
pub mod lqr;
pub mod objective;
pub mod search;

use crate::physics::linearize::Linearize;
use crate::physics::DifferentiableStep;
use crate::physics::Ode;
use nalgebra::{DMatrix, DVector};

/// Errors of the control module; each carries the offending value.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum ControlError {
    /// The time step must be positive and finite.
    #[error("time step must be positive and finite, got {0}")]
    InvalidTimeStep(f64),
    /// The horizon must have at least one step.
    #[error("the horizon must have at least one step")]
    EmptyHorizon,
    /// A vector or matrix has the wrong size.
    #[error("{what}: expected size {expected}, got {found}")]
    DimensionMismatch {
        /// Which argument.
        what: &'static str,
        /// Size the problem needs.
        expected: usize,
        /// Size given.
        found: usize,
    },
    /// A control bound has lower > upper (or is NaN).
    #[error("control bound {index}: lower {lower} > upper {upper}")]
    InvalidBounds {
        /// Control index.
        index: usize,
        /// Lower bound.
        lower: f64,
        /// Upper bound.
        upper: f64,
    },
    /// A rollout produced NaN or infinity.
    #[error("rollout became non-finite at step {step}")]
    NonFinite {
        /// Step index whose result was not finite.
        step: usize,
    },
    /// A search budget sets no limit (iterations, evaluations or seconds).
    #[error("the search budget sets no limit")]
    UnboundedBudget,
    /// A search setting is out of its range.
    #[error("{what} out of range: {value}")]
    InvalidSetting {
        /// Which setting.
        what: &'static str,
        /// The value given.
        value: f64,
    },
    /// The control Hessian Q_uu of the LQR recursion is not positive definite.
    #[error("Q_uu is not positive definite at step {step}")]
    NotPositiveDefinite {
        /// Step index.
        step: usize,
    },
}

/// `Ok` when a size is as expected, else [`ControlError::DimensionMismatch`] naming `what`.
pub(crate) fn check_dim(
    what: &'static str,
    expected: usize,
    found: usize,
) -> Result<(), ControlError> {
    if expected == found {
        Ok(())
    } else {
        Err(ControlError::DimensionMismatch {
            what,
            expected,
            found,
        })
    }
}

/// Scratch buffers of [`Rk4Map`]; make one with [`Rk4Map::workspace`].
#[derive(Debug, Clone)]
pub struct Rk4Workspace {
    k: [DVector<f64>; 4],
    y: DVector<f64>,
    a: DMatrix<f64>,
    b: DMatrix<f64>,
    dkx: [DMatrix<f64>; 4],
    dku: [DMatrix<f64>; 4],
    tmp: DMatrix<f64>,
    xp: DVector<f64>,
    up: DVector<f64>,
    fxp: DMatrix<f64>,
    fup: DMatrix<f64>,
    fxm: DMatrix<f64>,
    fum: DMatrix<f64>,
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
            dkx: [nn(), nn(), nn(), nn()],
            dku: [nm(), nm(), nm(), nm()],
            tmp: nn(),
            xp: v(),
            up: DVector::zeros(m),
            fxp: nn(),
            fup: nm(),
            fxm: nn(),
            fum: nm(),
        }
    }

    /// Writes F(x, u) into `out`. Does not allocate.
    pub fn step(
        &self,
        x: &DVector<f64>,
        u: &DVector<f64>,
        out: &mut DVector<f64>,
        ws: &mut Rk4Workspace,
    ) {
        let h = self.dt;
        let c = [0.0, 0.5 * h, 0.5 * h, h];
        for s in 0..4 {
            self.stage(s, c[s], x, u, ws);
        }
        out.copy_from(x);
        let w = h / 6.0;
        out.axpy(w, &ws.k[0], 1.0);
        out.axpy(2.0 * w, &ws.k[1], 1.0);
        out.axpy(2.0 * w, &ws.k[2], 1.0);
        out.axpy(w, &ws.k[3], 1.0);
    }

    /// RK4 stage `s`: the stage state y_s = x + c k_{s−1} (y_0 = x) into `ws.y` and the stage
    /// slope k_s = f(y_s, u) into `ws.k[s]`.
    fn stage(&self, s: usize, c: f64, x: &DVector<f64>, u: &DVector<f64>, ws: &mut Rk4Workspace) {
        ws.y.copy_from(x);
        if s > 0 {
            ws.y.axpy(c, &ws.k[s - 1], 1.0);
        }
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
    /// chained through the stage Jacobians (see the module docs). Does not allocate.
    pub fn jacobians(
        &self,
        x: &DVector<f64>,
        u: &DVector<f64>,
        fx: &mut DMatrix<f64>,
        fu: &mut DMatrix<f64>,
        ws: &mut Rk4Workspace,
    ) {
        let h = self.dt;
        let c = [0.0, 0.5 * h, 0.5 * h, h];
        for s in 0..4 {
            self.stage(s, c[s], x, u, ws);
            self.model
                .jacobians(ws.y.as_slice(), u.as_slice(), &mut ws.a, &mut ws.b);
            if s == 0 {
                ws.dkx[0].copy_from(&ws.a);
                ws.dku[0].copy_from(&ws.b);
            } else {
                // ∂k_s/∂x = A (I + c ∂k_{s−1}/∂x)
                ws.tmp.copy_from(&ws.dkx[s - 1]);
                ws.tmp *= c[s];
                for i in 0..ws.tmp.nrows() {
                    ws.tmp[(i, i)] += 1.0;
                }
                ws.a.mul_to(&ws.tmp, &mut ws.dkx[s]);
                // ∂k_s/∂u = c A ∂k_{s−1}/∂u + B
                let (prev, cur) = ws.dku.split_at_mut(s);
                cur[0].copy_from(&ws.b);
                cur[0].gemm(c[s], &ws.a, &prev[s - 1], 1.0);
            }
        }
        let w = h / 6.0;
        fx.fill_with_identity();
        fu.fill(0.0);
        for (s, weight) in [w, 2.0 * w, 2.0 * w, w].into_iter().enumerate() {
            fx.zip_apply(&ws.dkx[s], |a, b| *a += weight * b);
            fu.zip_apply(&ws.dku[s], |a, b| *a += weight * b);
        }
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
/// time ([`bptt`]) runs through a simulator as it does through an emulator: the vector–Jacobian
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

/// Running state cost q(x) = (x − r_k)ᵀ Q (x − r_k) around a reference.
#[derive(Debug, Clone, PartialEq)]
pub struct StateCost {
    /// Weight Q (n × n, symmetric positive semidefinite).
    pub weight: DMatrix<f64>,
    /// Reference states: one (constant reference) or one per step k = 0..N−1.
    pub reference: Vec<DVector<f64>>,
}

impl StateCost {
    fn reference(&self, k: usize) -> &DVector<f64> {
        if self.reference.len() == 1 {
            &self.reference[0]
        } else {
            &self.reference[k]
        }
    }
}

/// First and second derivatives of one step's running cost l(x, u).
#[derive(Debug, Clone, PartialEq)]
pub struct StageDerivatives {
    /// ∂l/∂x (n).
    pub lx: DVector<f64>,
    /// ∂l/∂u (m).
    pub lu: DVector<f64>,
    /// ∂²l/∂x² (n × n).
    pub lxx: DMatrix<f64>,
    /// ∂²l/∂u² (m × m).
    pub luu: DMatrix<f64>,
}

impl StageDerivatives {
    /// Zeroed buffers for n states and m controls.
    pub fn new(n: usize, m: usize) -> Self {
        Self {
            lx: DVector::zeros(n),
            lu: DVector::zeros(m),
            lxx: DMatrix::zeros(n, n),
            luu: DMatrix::zeros(m, m),
        }
    }
}

/// The cost J = g(x_N) + Σ_k dt·(q(x_k) + ½ u_kᵀ R u_k) with g(x) = (x − x̄)ᵀ Q_f (x − x̄).
#[derive(Debug, Clone, PartialEq)]
pub struct QuadraticCost {
    /// Time step weighting the running cost (s); use the map's `dt`.
    pub dt: f64,
    /// Control weight R (m × m, symmetric positive definite).
    pub r: DMatrix<f64>,
    /// Optional running state cost q.
    pub state: Option<StateCost>,
    /// Terminal weight Q_f (n × n, symmetric positive semidefinite).
    pub q_final: DMatrix<f64>,
    /// Terminal target x̄.
    pub x_final: DVector<f64>,
}

impl QuadraticCost {
    /// ½∫uᵀu dt plus the terminal cost (x − x̄)ᵀ Q_f (x − x̄): the swing-up objective of linear
    /// Bellman combination §6.2.
    pub fn effort(
        dt: f64,
        control_dim: usize,
        q_final: DMatrix<f64>,
        x_final: DVector<f64>,
    ) -> Self {
        Self {
            dt,
            r: DMatrix::identity(control_dim, control_dim),
            state: None,
            q_final,
            x_final,
        }
    }

    /// Checks sizes against a problem with n states, m controls and horizon N.
    pub fn validate(&self, n: usize, m: usize, horizon: usize) -> Result<(), ControlError> {
        let dim = check_dim;
        if !(self.dt.is_finite() && self.dt > 0.0) {
            return Err(ControlError::InvalidTimeStep(self.dt));
        }
        dim("R rows", m, self.r.nrows())?;
        dim("R columns", m, self.r.ncols())?;
        dim("Q_f rows", n, self.q_final.nrows())?;
        dim("Q_f columns", n, self.q_final.ncols())?;
        dim("terminal target", n, self.x_final.len())?;
        if let Some(s) = &self.state {
            dim("Q rows", n, s.weight.nrows())?;
            dim("Q columns", n, s.weight.ncols())?;
            if s.reference.len() != 1 {
                dim("state references", horizon, s.reference.len())?;
            }
            for r in &s.reference {
                dim("state reference", n, r.len())?;
            }
        }
        Ok(())
    }

    /// Running cost of step k: dt·(q(x) + ½ uᵀ R u).
    pub fn running(&self, k: usize, x: &DVector<f64>, u: &DVector<f64>) -> f64 {
        let mut c = 0.5 * quad_form(&self.r, u.as_slice(), None);
        if let Some(s) = &self.state {
            c += quad_form(&s.weight, x.as_slice(), Some(s.reference(k).as_slice()));
        }
        self.dt * c
    }

    /// Terminal cost g(x) = (x − x̄)ᵀ Q_f (x − x̄).
    pub fn terminal(&self, x: &DVector<f64>) -> f64 {
        quad_form(&self.q_final, x.as_slice(), Some(self.x_final.as_slice()))
    }

    /// Total cost of a trajectory of N + 1 states and N controls.
    pub fn total(&self, xs: &[DVector<f64>], us: &[DVector<f64>]) -> f64 {
        let run: f64 = us
            .iter()
            .enumerate()
            .map(|(k, u)| self.running(k, &xs[k], u))
            .sum();
        run + self.terminal(&xs[us.len()])
    }

    /// Derivatives of the running cost of step k into `out` (l_ux = 0). Does not allocate.
    pub fn running_derivatives(
        &self,
        k: usize,
        x: &DVector<f64>,
        u: &DVector<f64>,
        out: &mut StageDerivatives,
    ) {
        let dt = self.dt;
        // ½ uᵀRu: gradient ½(R + Rᵀ)u, Hessian ½(R + Rᵀ).
        sym_grad_hess(
            &self.r,
            u.as_slice(),
            None,
            0.5 * dt,
            &mut out.lu,
            &mut out.luu,
        );
        match &self.state {
            Some(s) => sym_grad_hess(
                &s.weight,
                x.as_slice(),
                Some(s.reference(k).as_slice()),
                dt,
                &mut out.lx,
                &mut out.lxx,
            ),
            None => {
                out.lx.fill(0.0);
                out.lxx.fill(0.0);
            }
        }
    }

    /// Derivatives of the terminal cost: g_x = (Q_f + Q_fᵀ)(x − x̄), g_xx = Q_f + Q_fᵀ.
    pub fn terminal_derivatives(
        &self,
        x: &DVector<f64>,
        gx: &mut DVector<f64>,
        gxx: &mut DMatrix<f64>,
    ) {
        sym_grad_hess(
            &self.q_final,
            x.as_slice(),
            Some(self.x_final.as_slice()),
            1.0,
            gx,
            gxx,
        );
    }
}

/// (x − c)ᵀ W (x − c), with c = 0 when absent.
fn quad_form(w: &DMatrix<f64>, x: &[f64], c: Option<&[f64]>) -> f64 {
    let d = |i: usize| x[i] - c.map_or(0.0, |c| c[i]);
    let mut s = 0.0;
    for j in 0..x.len() {
        let dj = d(j);
        for i in 0..x.len() {
            s += d(i) * w[(i, j)] * dj;
        }
    }
    s
}

/// Gradient and Hessian of scale·(x − c)ᵀ W (x − c): scale·(W + Wᵀ)(x − c), scale·(W + Wᵀ).
fn sym_grad_hess(
    w: &DMatrix<f64>,
    x: &[f64],
    c: Option<&[f64]>,
    scale: f64,
    grad: &mut DVector<f64>,
    hess: &mut DMatrix<f64>,
) {
    let n = x.len();
    for j in 0..n {
        for i in 0..n {
            hess[(i, j)] = scale * (w[(i, j)] + w[(j, i)]);
        }
    }
    for i in 0..n {
        let mut g = 0.0;
        for j in 0..n {
            g += hess[(i, j)] * (x[j] - c.map_or(0.0, |c| c[j]));
        }
        grad[i] = g;
    }
}

/// Replaces a square matrix by ½(A + Aᵀ) in place.
pub(crate) fn symmetrize(a: &mut DMatrix<f64>) {
    let n = a.nrows();
    for j in 0..n {
        for i in 0..j {
            let v = 0.5 * (a[(i, j)] + a[(j, i)]);
            a[(i, j)] = v;
            a[(j, i)] = v;
        }
    }
}

/// In-place Cholesky factorization of the leading `dim` × `dim` block of `a` (its lower
/// triangle becomes L with A = L Lᵀ). Returns false when the block is not positive definite.
pub(crate) fn cholesky_in_place(a: &mut DMatrix<f64>, dim: usize) -> bool {
    for j in 0..dim {
        let mut d = a[(j, j)];
        for k in 0..j {
            d -= a[(j, k)] * a[(j, k)];
        }
        if !(d > 0.0 && d.is_finite()) {
            return false;
        }
        let d = d.sqrt();
        a[(j, j)] = d;
        for i in j + 1..dim {
            let mut s = a[(i, j)];
            for k in 0..j {
                s -= a[(i, k)] * a[(j, k)];
            }
            a[(i, j)] = s / d;
        }
    }
    true
}

/// Solves L Lᵀ y = b in place with the factor of [`cholesky_in_place`] (leading `dim` block).
pub(crate) fn cholesky_solve_in_place(l: &DMatrix<f64>, dim: usize, b: &mut [f64]) {
    for i in 0..dim {
        let mut s = b[i];
        for k in 0..i {
            s -= l[(i, k)] * b[k];
        }
        b[i] = s / l[(i, i)];
    }
    for i in (0..dim).rev() {
        let mut s = b[i];
        for k in i + 1..dim {
            s -= l[(k, i)] * b[k];
        }
        b[i] = s / l[(i, i)];
    }
}

#[cfg(test)]
pub(crate) mod test_models {
    //! Models used only by the control tests.
    use crate::physics::linearize::Linearize;
    use crate::physics::{Model, Ode, Parameter};
    use nalgebra::DMatrix;

    /// ẋ = A x + B u.
    #[derive(Debug, Clone)]
    pub struct LinearOde {
        pub a: DMatrix<f64>,
        pub b: DMatrix<f64>,
    }

    impl Model for LinearOde {
        fn name(&self) -> &str {
            "linear"
        }
        fn state_names(&self) -> Vec<String> {
            (0..self.a.nrows()).map(|i| format!("x{i}")).collect()
        }
        fn control_names(&self) -> Vec<String> {
            (0..self.b.ncols()).map(|i| format!("u{i}")).collect()
        }
        fn parameters(&self) -> Vec<Parameter> {
            vec![]
        }
        fn default_dt(&self) -> f64 {
            0.1
        }
    }

    impl Ode for LinearOde {
        fn derivative(&self, x: &[f64], u: &[f64], dx: &mut [f64]) {
            for (i, d) in dx.iter_mut().enumerate() {
                *d = (0..x.len()).map(|j| self.a[(i, j)] * x[j]).sum::<f64>()
                    + (0..u.len()).map(|j| self.b[(i, j)] * u[j]).sum::<f64>();
            }
        }
    }

    impl Linearize for LinearOde {
        fn jacobians(&self, _x: &[f64], _u: &[f64], a: &mut DMatrix<f64>, b: &mut DMatrix<f64>) {
            a.copy_from(&self.a);
            b.copy_from(&self.b);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::physics::acrobot::Acrobot;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn random_vec(rng: &mut ChaCha8Rng, n: usize, s: f64) -> DVector<f64> {
        DVector::from_fn(n, |_, _| rng.random_range(-s..s))
    }

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

    #[test]
    fn cost_derivatives_match_finite_differences() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let (n, m) = (3, 2);
        let sym = |rng: &mut ChaCha8Rng, d: usize| {
            let a = DMatrix::from_fn(d, d, |_, _| rng.random_range(-1.0..1.0));
            &a * a.transpose() + DMatrix::identity(d, d)
        };
        // A deliberately non-symmetric Q: the derivatives must use its symmetric part.
        let mut q = sym(&mut rng, n);
        q[(0, 1)] += 0.3;
        let cost = QuadraticCost {
            dt: 0.1,
            r: sym(&mut rng, m),
            state: Some(StateCost {
                weight: q,
                reference: vec![random_vec(&mut rng, n, 1.0), random_vec(&mut rng, n, 1.0)],
            }),
            q_final: sym(&mut rng, n),
            x_final: random_vec(&mut rng, n, 1.0),
        };
        cost.validate(n, m, 2).unwrap();
        let x = random_vec(&mut rng, n, 2.0);
        let u = random_vec(&mut rng, m, 2.0);
        let mut l = StageDerivatives::new(n, m);
        cost.running_derivatives(1, &x, &u, &mut l);
        let StageDerivatives { lx, lu, lxx, luu } = l;
        let (mut gx, mut gxx) = (DVector::zeros(n), DMatrix::zeros(n, n));
        cost.terminal_derivatives(&x, &mut gx, &mut gxx);
        let h = 1e-5;
        for i in 0..n {
            let (mut xp, mut xm) = (x.clone(), x.clone());
            xp[i] += h;
            xm[i] -= h;
            let d = (cost.running(1, &xp, &u) - cost.running(1, &xm, &u)) / (2.0 * h);
            assert!((d - lx[i]).abs() < 1e-8, "l_x[{i}] {d} vs {}", lx[i]);
            let d = (cost.terminal(&xp) - cost.terminal(&xm)) / (2.0 * h);
            assert!((d - gx[i]).abs() < 1e-8, "g_x[{i}] {d} vs {}", gx[i]);
            // Hessian columns from differences of the analytic gradient.
            let (mut gp, mut gm) = (DVector::zeros(n), DVector::zeros(n));
            let mut scratch = DMatrix::zeros(n, n);
            cost.terminal_derivatives(&xp, &mut gp, &mut scratch);
            cost.terminal_derivatives(&xm, &mut gm, &mut scratch);
            let col = (gp - gm) / (2.0 * h);
            assert!((col - gxx.column(i)).amax() < 1e-7);
            let (mut lp, mut lm) = (StageDerivatives::new(n, m), StageDerivatives::new(n, m));
            cost.running_derivatives(1, &xp, &u, &mut lp);
            cost.running_derivatives(1, &xm, &u, &mut lm);
            assert!(((lp.lx - lm.lx) / (2.0 * h) - lxx.column(i)).amax() < 1e-7);
        }
        for i in 0..m {
            let (mut up, mut um) = (u.clone(), u.clone());
            up[i] += h;
            um[i] -= h;
            let d = (cost.running(1, &x, &up) - cost.running(1, &x, &um)) / (2.0 * h);
            assert!((d - lu[i]).abs() < 1e-8, "l_u[{i}] {d} vs {}", lu[i]);
            let (mut lp, mut lm) = (StageDerivatives::new(n, m), StageDerivatives::new(n, m));
            cost.running_derivatives(1, &x, &up, &mut lp);
            cost.running_derivatives(1, &x, &um, &mut lm);
            assert!(((lp.lu - lm.lu) / (2.0 * h) - luu.column(i)).amax() < 1e-7);
        }
    }

    #[test]
    fn cholesky_helpers_solve_spd_systems_and_reject_indefinite_ones() {
        let a = DMatrix::from_row_slice(3, 3, &[4.0, 1.0, 0.5, 1.0, 3.0, 0.2, 0.5, 0.2, 2.0]);
        let mut l = a.clone();
        assert!(cholesky_in_place(&mut l, 3));
        let mut y = [1.0, -2.0, 0.5];
        cholesky_solve_in_place(&l, 3, &mut y);
        let r = &a * DVector::from_row_slice(&y) - DVector::from_row_slice(&[1.0, -2.0, 0.5]);
        assert!(r.amax() < 1e-12);
        let mut bad = DMatrix::from_row_slice(2, 2, &[1.0, 2.0, 2.0, 1.0]);
        assert!(!cholesky_in_place(&mut bad, 2));
    }

    #[test]
    fn invalid_inputs_are_reported_with_their_values() {
        assert_eq!(
            Rk4Map::new(Acrobot::default(), -0.1).unwrap_err(),
            ControlError::InvalidTimeStep(-0.1)
        );
        let cost = QuadraticCost::effort(0.01, 2, DMatrix::identity(4, 4), DVector::zeros(4));
        assert_eq!(
            cost.validate(4, 1, 10).unwrap_err(),
            ControlError::DimensionMismatch {
                what: "R rows",
                expected: 1,
                found: 2
            }
        );
    }
}
