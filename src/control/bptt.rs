//! # Control learning by backpropagation through time (NeuroAnimator §4.3)
//!
//! The controller is a set of piecewise-constant knots: K knots per actuator over M steps, knot
//! k held on the steps i with ⌊i K / M⌋ = k ([`Knots`]; the paper's lander: 20 per actuator × 4
//! actuators = 80 over 40 steps). Each actuator has a box [lo, hi] ([`Bounds`]); the optimizer
//! works on normalized knots v ∈ [−1, 1], u = (hi + lo)/2 + v (hi − lo)/2 (unbounded actuators:
//! u = v), and projects v back onto the box after every update.
//!
//! One iteration rolls the differentiable step forward, s_{i+1} = N(s_i, u_i) (eq. 10), then
//! runs the chain rule backwards through the cascade ([`Bptt::gradient`]):
//!
//! ```text
//! s̄_M = ∂J/∂s_M,   ū_i = ∂J/∂u_i + (∂N/∂u)ᵀ s̄_{i+1},   s̄_i = ∂J/∂s_i + (∂N/∂s)ᵀ s̄_{i+1},
//! ```
//!
//! each product being one vector–Jacobian product of the step ([`DifferentiableStep::vjp`],
//! defined next to [`crate::physics::Dynamics`]: for an emulator through its transforms and
//! network, for a physical model through the exact Jacobians of its RK4 step,
//! [`super::Rk4Map`]). The rollout records what each step's product needs on one contiguous
//! tape ([`DifferentiableStep::step_taped`]; for an emulator its network's input, hidden
//! activations and output), so the backward sweep does not repeat the forward passes and gives
//! bit for bit the same products. Knot gradients sum ū_i over the steps
//! a knot holds. The update ([`Descent`]) is plain descent (eq. 13) or descent with momentum
//! (eq. 14–15):
//!
//! ```text
//! v^{l+1} = Π(v^l − η/λ ∇J(v^l)),        δ^{l+1} = −η/λ ∇J(v^l) + α δ^l,  v^{l+1} = Π(v^l + δ^{l+1}),
//! ```
//!
//! with Π the projection onto the box and λ a fixed per-problem step scale: by default the
//! largest Hessian eigenvalue magnitude of J at the initial knots ([`Bptt::curvature`], power
//! iteration on finite-difference Hessian–vector products). In these units plain descent on a
//! quadratic is stable for η < 2 and heavy-ball momentum for η < 2(1 + α). The momentum state
//! carries the step actually taken (after projection).
//!
//! λ measured once is the paper's rule, and it is only right where the curvature does not
//! change along the way: far from the goal the residual term of the Hessian makes λ large, and
//! near it the fixed step is far too short (or, where the curvature grows, too long).
//! [`StepRule`] adds two options ([`learn_with`]): re-measuring λ every few iterations, and a
//! backtracking (Armijo) line search on the momentum step that grows the step after each
//! first-try acceptance.
//!
//! [`learn`] runs the loop and returns the trace (objective, gradient norm and wall seconds per
//! iteration; [`learn_until`] adds a stop rule, e.g. a [`super::search::Budget`]) and the
//! best-so-far iterate;
//! [`replay`] drives a physical simulator with the learned controls to measure the gap between
//! the emulated and the simulated final state. Nothing here writes files.
//!
//! ## References
//! - R. Grzeszczuk, D. Terzopoulos, G. Hinton, *NeuroAnimator*, SIGGRAPH 1998, §4.3, eq. 13–15.
//! - P. J. Werbos, *Backpropagation through time: what it does and how to do it*, Proc. IEEE
//!   78(10), 1990.
//! - L. Armijo, *Minimization of functions having Lipschitz continuous first partial
//!   derivatives*, Pacific J. Math. 16(1), 1966; J. Nocedal, S. Wright, *Numerical
//!   Optimization*, 2nd ed., §3.1 (backtracking), §16.7 (projected gradient).

use super::objective::{GaussNewton, Objective};
use super::ControlError;
pub use crate::physics::differentiable::{DifferentiableStep, LinearStep};
use crate::physics::Dynamics;
use serde::{Deserialize, Serialize};

/// Piecewise-constant controls: `per_actuator` knots per actuator over `steps` steps; knot k
/// (of actuator j, stored at `k * m + j`) holds on the steps i with ⌊i K / M⌋ = k.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Knots {
    /// Steps M.
    pub steps: usize,
    /// Knots per actuator K (1 ≤ K ≤ M).
    pub per_actuator: usize,
    /// Actuators m.
    pub m: usize,
}

impl Knots {
    /// Total number of knot values K m.
    pub fn len(&self) -> usize {
        self.per_actuator * self.m
    }
    /// Whether there are none.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// The knot that step `i` uses.
    pub fn knot_of(&self, i: usize) -> usize {
        i * self.per_actuator / self.steps
    }
    /// Per-step controls (M m) from knot values (K m).
    pub fn expand(&self, knots: &[f64], controls: &mut [f64]) {
        let m = self.m;
        for i in 0..self.steps {
            let k = self.knot_of(i);
            controls[i * m..(i + 1) * m].copy_from_slice(&knots[k * m..(k + 1) * m]);
        }
    }
    /// Knot gradients: sums the per-step gradients over the steps each knot holds.
    pub fn reduce(&self, u_bar: &[f64], knot_bar: &mut [f64]) {
        let m = self.m;
        knot_bar.fill(0.0);
        for i in 0..self.steps {
            let k = self.knot_of(i);
            for j in 0..m {
                knot_bar[k * m + j] += u_bar[i * m + j];
            }
        }
    }
}

/// Box bounds on each actuator.
#[derive(Debug, Clone, PartialEq)]
pub struct Bounds {
    /// Lower bounds (may be −∞).
    pub low: Vec<f64>,
    /// Upper bounds (may be +∞).
    pub high: Vec<f64>,
}

impl Bounds {
    /// No bounds on `m` actuators.
    pub fn unbounded(m: usize) -> Self {
        Self {
            low: vec![f64::NEG_INFINITY; m],
            high: vec![f64::INFINITY; m],
        }
    }
    /// Centre and half-width of actuator j's box ((0, 1) when it is unbounded on a side).
    pub fn affine(&self, j: usize) -> (f64, f64) {
        let (lo, hi) = (self.low[j], self.high[j]);
        if lo.is_finite() && hi.is_finite() {
            (0.5 * (lo + hi), 0.5 * (hi - lo))
        } else {
            (0.0, 1.0)
        }
    }
    /// Control values from normalized values `v` of consecutive actuators (value i belongs to
    /// actuator i mod m): u_i = c_j + h_j v_i with [`Bounds::affine`] of j.
    pub fn denormalize(&self, v: &[f64], u: &mut [f64]) {
        // Actuator by actuator down the knots: the same c_j + h_j v_i as value by value, without
        // an integer division and the bounds' tests per value.
        let m = self.low.len();
        let n = u.len().min(v.len());
        for j in 0..m {
            let (c, h) = self.affine(j);
            for i in (j..n).step_by(m) {
                u[i] = c + h * v[i];
            }
        }
    }
    /// Projects a normalized value of actuator j onto its box.
    pub fn project(&self, j: usize, v: f64) -> f64 {
        let (lo, hi) = (self.low[j], self.high[j]);
        if lo.is_finite() && hi.is_finite() {
            v.clamp(-1.0, 1.0)
        } else {
            v.clamp(lo, hi)
        }
    }
}

/// Forward emulation and backpropagation through time for one control problem.
pub struct Bptt<'a, D: DifferentiableStep> {
    dynamics: &'a D,
    objective: &'a Objective,
    knots: Knots,
    bounds: Bounds,
    x0: Vec<f64>,
    scratch: D::Scratch,
    knot_u: Vec<f64>,
    states: Vec<f64>,
    controls: Vec<f64>,
    /// Per-step records of the last rollout for the backward sweep
    /// ([`DifferentiableStep::step_taped`]), `tape_len` values per step.
    tape: Vec<f64>,
    tape_len: usize,
    s_bar: Vec<f64>,
    u_bar: Vec<f64>,
    sb: Vec<f64>,
    ub: Vec<f64>,
    forward_passes: usize,
    backward_passes: usize,
}

impl<'a, D: DifferentiableStep> Bptt<'a, D> {
    /// A problem: start state `x0`, `knots`, `bounds`, `objective`.
    pub fn new(
        dynamics: &'a D,
        objective: &'a Objective,
        knots: Knots,
        bounds: Bounds,
        x0: &[f64],
    ) -> Result<Self, ControlError> {
        let (n, m) = (dynamics.state_dim(), dynamics.control_dim());
        let dims = [
            ("start state", x0.len(), n),
            ("knot actuators", knots.m, m),
            ("lower bounds", bounds.low.len(), m),
            ("upper bounds", bounds.high.len(), m),
        ];
        for (what, found, expected) in dims {
            if found != expected {
                return Err(ControlError::DimensionMismatch {
                    what,
                    expected,
                    found,
                });
            }
        }
        if knots.steps == 0 || knots.per_actuator == 0 || knots.per_actuator > knots.steps {
            return Err(ControlError::EmptyHorizon);
        }
        for j in 0..m {
            let (lower, upper) = (bounds.low[j], bounds.high[j]);
            if lower.is_nan() || upper.is_nan() || lower > upper {
                return Err(ControlError::InvalidBounds {
                    index: j,
                    lower,
                    upper,
                });
            }
        }
        let big_m = knots.steps;
        let tape_len = dynamics.tape_len();
        Ok(Self {
            dynamics,
            objective,
            knots,
            bounds,
            x0: x0.to_vec(),
            scratch: dynamics.scratch(),
            knot_u: vec![0.0; knots.len()],
            states: vec![0.0; (big_m + 1) * n],
            controls: vec![0.0; big_m * m],
            tape: vec![0.0; big_m * tape_len],
            tape_len,
            s_bar: vec![0.0; (big_m + 1) * n],
            u_bar: vec![0.0; big_m * m],
            sb: vec![0.0; n],
            ub: vec![0.0; m],
            forward_passes: 0,
            backward_passes: 0,
        })
    }

    /// The differentiable step it rolls out.
    pub fn dynamics(&self) -> &'a D {
        self.dynamics
    }

    /// The objective J.
    pub fn objective(&self) -> &'a Objective {
        self.objective
    }

    /// The actuator boxes.
    pub fn bounds(&self) -> &Bounds {
        &self.bounds
    }

    /// The start state s_0.
    pub fn start_state(&self) -> &[f64] {
        &self.x0
    }

    /// Forward rollouts run so far (each [`Bptt::rollout`], including those inside
    /// [`Bptt::gradient`] and [`Bptt::curvature`]): the objective-evaluation count.
    pub fn forward_passes(&self) -> usize {
        self.forward_passes
    }

    /// Backward passes run so far (each [`Bptt::gradient`], including those inside
    /// [`Bptt::curvature`]).
    pub fn backward_passes(&self) -> usize {
        self.backward_passes
    }

    /// Number of optimization variables (knot values).
    pub fn dim(&self) -> usize {
        self.knots.len()
    }

    /// The knot layout.
    pub fn knots(&self) -> Knots {
        self.knots
    }

    /// Knot values in control units from normalized ones.
    pub fn to_controls(&self, v: &[f64], u: &mut [f64]) {
        self.bounds.denormalize(v, u);
    }

    /// Normalized knot values from knot values in control units (projected onto the box).
    pub fn from_controls(&self, u: &[f64]) -> Vec<f64> {
        let m = self.knots.m;
        u.iter()
            .enumerate()
            .map(|(i, u)| {
                let (c, h) = self.bounds.affine(i % m);
                self.bounds.project(i % m, (u - c) / h)
            })
            .collect()
    }

    /// Projects normalized knots onto the box, in place.
    pub fn project(&self, v: &mut [f64]) {
        let m = self.knots.m;
        for (i, v) in v.iter_mut().enumerate() {
            *v = self.bounds.project(i % m, *v);
        }
    }

    /// Emulates the motion under normalized knots `v` and returns J.
    pub fn rollout(&mut self, v: &[f64]) -> f64 {
        self.simulate(v);
        let (n, m) = (self.dynamics.state_dim(), self.knots.m);
        self.objective.value(&self.states, &self.controls, n, m)
    }

    /// Emulates the motion under normalized knots `v` (the states, controls and tape of
    /// [`Bptt::rollout`], without J).
    fn simulate(&mut self, v: &[f64]) {
        let (n, m) = (self.dynamics.state_dim(), self.knots.m);
        let mut ku = std::mem::take(&mut self.knot_u);
        self.to_controls(v, &mut ku);
        self.knots.expand(&ku, &mut self.controls);
        self.knot_u = ku;
        self.forward_passes += 1;
        self.states[..n].copy_from_slice(&self.x0);
        let tl = self.tape_len;
        for i in 0..self.knots.steps {
            let (head, tail) = self.states.split_at_mut((i + 1) * n);
            self.dynamics.step_taped(
                &head[i * n..],
                &self.controls[i * m..(i + 1) * m],
                &mut self.scratch,
                &mut tail[..n],
                &mut self.tape[i * tl..(i + 1) * tl],
            );
        }
    }

    /// J and its gradient with respect to the normalized knots (written to `grad`).
    pub fn gradient(&mut self, v: &[f64], grad: &mut [f64]) -> f64 {
        // J comes with its partial derivatives below.
        self.simulate(v);
        let (n, m) = (self.dynamics.state_dim(), self.knots.m);
        let j = self.objective.gradient(
            &self.states,
            &self.controls,
            n,
            m,
            &mut self.s_bar,
            &mut self.u_bar,
        );
        self.backpropagate(self.knots.steps, grad);
        j
    }

    /// Runs the chain rule backwards from state s_`top` to s_0 over the adjoints seeded in
    /// `s_bar` and `u_bar` (about the last rollout), and writes the knot gradient (normalized
    /// knots) to `grad`.
    fn backpropagate(&mut self, top: usize, grad: &mut [f64]) {
        self.backward_passes += 1;
        let (n, m, tl) = (self.dynamics.state_dim(), self.knots.m, self.tape_len);
        for i in (0..top).rev() {
            // The tape is the last rollout's, at these same states and controls.
            self.dynamics.vjp_taped(
                &self.states[i * n..(i + 1) * n],
                &self.controls[i * m..(i + 1) * m],
                &self.tape[i * tl..(i + 1) * tl],
                &self.s_bar[(i + 1) * n..(i + 2) * n],
                &mut self.scratch,
                &mut self.sb,
                &mut self.ub,
            );
            for k in 0..n {
                self.s_bar[i * n + k] += self.sb[k];
            }
            for k in 0..m {
                self.u_bar[i * m + k] += self.ub[k];
            }
        }
        self.knots.reduce(&self.u_bar, grad);
        for j in 0..m {
            let h = self.bounds.affine(j).1;
            for g in grad.iter_mut().skip(j).step_by(m) {
                *g *= h;
            }
        }
    }

    /// J, its gradient (to `grad`) and its Gauss–Newton matrix over the normalized knots (to
    /// `h`, row-major d × d) at `v`, from the terms' curvatures `curvature`
    /// ([`Objective::gauss_newton`]): Σ_terms Σ_{i,k} h_k r_ik r_ikᵀ with r_ik = ∂s_ik/∂v (one
    /// backward pass from s_i per weighted state variable k), plus the exact control-effort
    /// Hessian. Exact for a linear step.
    pub fn gauss_newton(
        &mut self,
        v: &[f64],
        curvature: &[GaussNewton],
        grad: &mut [f64],
        h: &mut [f64],
    ) -> f64 {
        let j = self.gradient(v, grad);
        let (m, d) = (self.knots.m, self.dim());
        let last = self.knots.steps;
        h.fill(0.0);
        let mut row = vec![0.0; d];
        for c in curvature {
            match c {
                GaussNewton::Zero => {}
                GaussNewton::Controls { diagonal } => {
                    for i in 0..last {
                        let k = self.knots.knot_of(i);
                        for (a, hd) in diagonal.iter().enumerate() {
                            let s = self.bounds.affine(a).1;
                            let q = k * m + a;
                            h[q * d + q] += hd * s * s;
                        }
                    }
                }
                GaussNewton::States { from, to, diagonal } => {
                    // The start state does not depend on the knots.
                    for i in (*from).min(last).max(1)..=(*to).min(last) {
                        for (k, &hk) in diagonal.iter().enumerate() {
                            if hk == 0.0 {
                                continue;
                            }
                            self.state_row(i, k, &mut row);
                            for (p, rp) in row.iter().enumerate() {
                                if *rp != 0.0 {
                                    for (q, rq) in row.iter().enumerate() {
                                        h[p * d + q] += hk * rp * rq;
                                    }
                                }
                            }
                        }
                    }
                }
            }
        }
        j
    }

    /// ∂s_ik/∂v over the normalized knots (to `row`) at the last rollout's knots: one
    /// backward pass from s_i.
    fn state_row(&mut self, i: usize, k: usize, row: &mut [f64]) {
        let n = self.dynamics.state_dim();
        self.s_bar.fill(0.0);
        self.u_bar.fill(0.0);
        self.s_bar[i * n + k] = 1.0;
        self.backpropagate(i, row);
    }

    /// Rows ∂s_{step,k}/∂v over the normalized knots at `v`, one per variable k of `vars`
    /// (a rollout, then one backward pass each; `step` is clamped to the horizon).
    pub fn state_jacobian(&mut self, v: &[f64], step: usize, vars: &[usize]) -> Vec<Vec<f64>> {
        self.rollout(v);
        let i = step.min(self.knots.steps);
        vars.iter()
            .map(|&k| {
                let mut row = vec![0.0; self.dim()];
                self.state_row(i, k, &mut row);
                row
            })
            .collect()
    }

    /// States s_0 … s_M of the last rollout (n each).
    pub fn states(&self) -> &[f64] {
        &self.states
    }

    /// Per-step controls u_0 … u_{M−1} of the last rollout (m each, control units).
    pub fn controls(&self) -> &[f64] {
        &self.controls
    }

    /// Largest Hessian eigenvalue magnitude of J at normalized knots `v`: `iterations` steps of
    /// power iteration on central-difference Hessian–vector products (step 1e-4), started from
    /// the gradient direction.
    pub fn curvature(&mut self, v: &[f64], iterations: usize) -> f64 {
        let d = self.dim();
        let mut g = vec![0.0; d];
        self.gradient(v, &mut g);
        let mut dir = g.clone();
        if norm(&dir) == 0.0 {
            dir.fill(1.0);
        }
        let (mut gp, mut gm, mut vp) = (vec![0.0; d], vec![0.0; d], vec![0.0; d]);
        let eps = 1e-4;
        let mut lambda = 0.0;
        for _ in 0..iterations {
            let nd = norm(&dir);
            dir.iter_mut().for_each(|x| *x /= nd);
            for i in 0..d {
                vp[i] = v[i] + eps * dir[i];
            }
            self.gradient(&vp, &mut gp);
            for i in 0..d {
                vp[i] = v[i] - eps * dir[i];
            }
            self.gradient(&vp, &mut gm);
            let hv: Vec<f64> = (0..d).map(|i| (gp[i] - gm[i]) / (2.0 * eps)).collect();
            lambda = dot(&dir, &hv).abs();
            if norm(&hv) == 0.0 {
                break;
            }
            dir = hv;
        }
        lambda
    }
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// Euclidean norm.
pub fn norm(a: &[f64]) -> f64 {
    dot(a, a).sqrt()
}

/// The update rule: plain descent (eq. 13) or descent with momentum (eq. 14–15).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Descent {
    /// δ = −η/λ ∇J.
    Plain {
        /// Learning rate η (in units of 1/λ).
        eta: f64,
    },
    /// δ^{l+1} = −η/λ ∇J + α δ^l.
    Momentum {
        /// Learning rate η (in units of 1/λ).
        eta: f64,
        /// Momentum α ∈ [0, 1).
        alpha: f64,
    },
}

/// Optimizer state: the previous step δ^l (empty before the first).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct DescentState {
    /// The previous step.
    pub delta: Vec<f64>,
}

impl Descent {
    /// η.
    pub fn eta(&self) -> f64 {
        match *self {
            Self::Plain { eta } | Self::Momentum { eta, .. } => eta,
        }
    }
    /// α (0 for plain descent).
    pub fn alpha(&self) -> f64 {
        match *self {
            Self::Plain { .. } => 0.0,
            Self::Momentum { alpha, .. } => alpha,
        }
    }
    /// The step for gradient `grad` with step scale λ = `scale`, and the next state.
    pub fn update(
        &self,
        grad: &[f64],
        scale: f64,
        state: DescentState,
    ) -> (Vec<f64>, DescentState) {
        let (eta, alpha) = (self.eta(), self.alpha());
        let step: Vec<f64> = grad
            .iter()
            .enumerate()
            .map(|(i, g)| -eta / scale * g + alpha * state.delta.get(i).copied().unwrap_or(0.0))
            .collect();
        let next = DescentState {
            delta: step.clone(),
        };
        (step, next)
    }
}

/// `substeps` steps of an inner differentiable step as one step (e.g. 50 RK4 steps of a
/// physical model as one N50 emulator step), so BPTT runs through the physics on the
/// emulator's knots and horizon. The vector–Jacobian product replays the inner steps to store
/// their states, then chains the inner products backwards.
pub struct Substepped<D> {
    /// The inner step.
    pub inner: D,
    /// Inner steps per step (≥ 1).
    pub substeps: usize,
}

/// Scratch of [`Substepped`]: the inner scratch, the inner states and two adjoint buffers.
pub struct SubsteppedScratch<S> {
    inner: S,
    states: Vec<f64>,
    sb: Vec<f64>,
    ub: Vec<f64>,
    acc: Vec<f64>,
}

impl<D: DifferentiableStep> DifferentiableStep for Substepped<D> {
    type Scratch = SubsteppedScratch<D::Scratch>;
    fn state_dim(&self) -> usize {
        self.inner.state_dim()
    }
    fn control_dim(&self) -> usize {
        self.inner.control_dim()
    }
    fn scratch(&self) -> Self::Scratch {
        let (n, m) = (self.state_dim(), self.control_dim());
        SubsteppedScratch {
            inner: self.inner.scratch(),
            states: vec![0.0; (self.substeps + 1) * n],
            sb: vec![0.0; n],
            ub: vec![0.0; m],
            acc: vec![0.0; n],
        }
    }
    fn step(&self, s: &[f64], u: &[f64], scratch: &mut Self::Scratch, s_next: &mut [f64]) {
        self.fill(s, u, scratch);
        let n = self.state_dim();
        s_next.copy_from_slice(&scratch.states[self.substeps * n..]);
    }
    fn vjp(
        &self,
        s: &[f64],
        u: &[f64],
        s_next_bar: &[f64],
        scratch: &mut Self::Scratch,
        s_bar: &mut [f64],
        u_bar: &mut [f64],
    ) {
        self.fill(s, u, scratch);
        let n = self.state_dim();
        scratch.acc.copy_from_slice(s_next_bar);
        u_bar.fill(0.0);
        for k in (0..self.substeps).rev() {
            self.inner.vjp(
                &scratch.states[k * n..(k + 1) * n],
                u,
                &scratch.acc,
                &mut scratch.inner,
                &mut scratch.sb,
                &mut scratch.ub,
            );
            scratch.acc.copy_from_slice(&scratch.sb);
            for (a, b) in u_bar.iter_mut().zip(&scratch.ub) {
                *a += b;
            }
        }
        s_bar.copy_from_slice(&scratch.acc);
    }
}

impl<D: DifferentiableStep> Substepped<D> {
    /// Runs the inner steps from `s` under `u`, storing the states in the scratch.
    fn fill(&self, s: &[f64], u: &[f64], scratch: &mut SubsteppedScratch<D::Scratch>) {
        let n = self.state_dim();
        scratch.states[..n].copy_from_slice(s);
        for k in 0..self.substeps {
            let (head, tail) = scratch.states.split_at_mut((k + 1) * n);
            self.inner
                .step(&head[k * n..], u, &mut scratch.inner, &mut tail[..n]);
        }
    }
}

/// How the step size evolves during learning (the paper: fixed).
///
/// - `Fixed`: λ measured once at the initial knots (the paper's η in units of 1/λ);
/// - `Reestimate`: λ re-measured ([`Bptt::curvature`], as many power iterations as the
///   first estimate) at the current iterate every `every` iterations, so η keeps its meaning
///   where the curvature grows or shrinks along the way;
/// - `Armijo`: a backtracking line search on the step η t/λ (t = 1 at the start): the step
///   p = −(η t/λ) ∇J + α δ (momentum dropped when p is not a descent direction) is tried at
///   σ = 1, `shrink`, `shrink`², … until the projected point v' = Π(v + σ p) satisfies the
///   sufficient-decrease test J(v') ≤ J(v) + c ∇J·(v' − v); then t ← σ t, and t ← `grow` t when
///   the first try passed. After `max_backtracks` failures the iterate stays put and the
///   momentum is reset.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum StepRule {
    /// λ fixed at the initial knots.
    #[default]
    Fixed,
    /// λ re-measured every `every` iterations.
    Reestimate {
        /// Iterations between estimates (≥ 1).
        every: usize,
    },
    /// Backtracking (Armijo) line search with step growth.
    Armijo {
        /// Sufficient-decrease constant c ∈ (0, 1).
        c: f64,
        /// Backtracking factor ∈ (0, 1).
        shrink: f64,
        /// Growth after a first-try acceptance (≥ 1).
        grow: f64,
        /// Backtracks per iteration before giving up (≥ 1).
        max_backtracks: usize,
    },
    /// Levenberg–Marquardt on the Gauss–Newton matrix of the objective ([`Bptt::gauss_newton`];
    /// ours, not the paper's: η and α are not used).
    LevenbergMarquardt {
        /// Initial damping μ relative to the diagonal of the Gauss–Newton matrix (> 0).
        damping: f64,
        /// Trials per iteration, each with more damping, before giving up (≥ 1).
        max_tries: usize,
    },
}

impl StepRule {
    /// Its name in tables: `fixed`, `reestimate`, `armijo` or `levenberg_marquardt`.
    pub fn name(&self) -> &'static str {
        match self {
            Self::Fixed => "fixed",
            Self::Reestimate { .. } => "reestimate",
            Self::Armijo { .. } => "armijo",
            Self::LevenbergMarquardt { .. } => "levenberg_marquardt",
        }
    }

    /// Checks the settings; `key` names the spec key in messages.
    pub fn validate(&self, key: &str) -> Result<(), crate::params::ParamError> {
        use crate::params::ensure;
        match *self {
            Self::Fixed => Ok(()),
            Self::Reestimate { every } => {
                ensure(every >= 1, &format!("{key}.every"), "must be >= 1")
            }
            Self::Armijo {
                c,
                shrink,
                grow,
                max_backtracks,
            } => {
                ensure(c > 0.0 && c < 1.0, &format!("{key}.c"), "must be in (0, 1)")?;
                ensure(
                    shrink > 0.0 && shrink < 1.0,
                    &format!("{key}.shrink"),
                    "must be in (0, 1)",
                )?;
                ensure(
                    grow >= 1.0 && grow.is_finite(),
                    &format!("{key}.grow"),
                    "must be >= 1",
                )?;
                ensure(
                    max_backtracks >= 1,
                    &format!("{key}.max_backtracks"),
                    "must be >= 1",
                )
            }
            Self::LevenbergMarquardt { damping, max_tries } => {
                ensure(
                    damping > 0.0 && damping.is_finite(),
                    &format!("{key}.damping"),
                    "must be > 0",
                )?;
                ensure(max_tries >= 1, &format!("{key}.max_tries"), "must be >= 1")
            }
        }
    }
}

/// One traced iteration: J and |∇J| at the iterate v^l (iteration 0 = the initial knots).
/// Under [`StepRule::Fixed`] iteration l has cost l + 1 gradient evaluations (one forward
/// rollout and one backward pass each); `evaluations` counts every forward rollout, line-search
/// trials and curvature re-estimates included.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct IterationTrace {
    /// Iteration l.
    pub iteration: usize,
    /// J(v^l).
    pub objective: f64,
    /// |∇_v J(v^l)| (normalized knots).
    pub grad_norm: f64,
    /// Wall-clock seconds from the start of [`learn`] to the end of this iteration's gradient
    /// (timing only: not deterministic, never used by the loop unless a stop rule reads it).
    pub seconds: f64,
    /// Forward rollouts from the start of the loop to this iterate's gradient, inclusive.
    pub evaluations: usize,
    /// The effective step scale λ/t of the step that produced this iterate (iteration 0: the
    /// initial λ; under [`StepRule::LevenbergMarquardt`], the damping μ after the step; ∞ after
    /// a step that found no decrease).
    pub scale: f64,
}

/// What [`learn`] returns.
#[derive(Debug, Clone, PartialEq)]
pub struct Learned {
    /// Final normalized knots.
    pub knots: Vec<f64>,
    /// Per-step controls of the final knots (control units, M m).
    pub controls: Vec<f64>,
    /// Emulated states s_0 … s_M under the final knots (n each).
    pub states: Vec<f64>,
    /// One entry per iteration, 0 ..= iterations (fewer when J became non-finite).
    pub trace: Vec<IterationTrace>,
    /// The iterate with the lowest finite J (best so far; the first on ties).
    pub best_iteration: usize,
    /// Its normalized knots.
    pub best_knots: Vec<f64>,
}

impl Learned {
    /// J at the final knots.
    pub fn final_objective(&self) -> f64 {
        self.trace.last().map_or(f64::NAN, |t| t.objective)
    }
    /// J at the best iterate.
    pub fn best_objective(&self) -> f64 {
        self.trace
            .get(self.best_iteration)
            .map_or(f64::NAN, |t| t.objective)
    }
}

/// Runs `iterations` updates of `descent` with step scale λ = `scale` from normalized knots
/// `v0`, projecting onto the box after each; stops early if J becomes non-finite.
pub fn learn<D: DifferentiableStep>(
    bptt: &mut Bptt<'_, D>,
    v0: &[f64],
    descent: Descent,
    scale: f64,
    iterations: usize,
) -> Learned {
    learn_until(bptt, v0, descent, scale, iterations, &mut |_, _| false)
}

/// [`learn`] with a stop rule: each iteration's trace entry is passed, with the normalized
/// knots v^l it was computed at, to `stop`, which ends the loop there by returning true (as
/// reaching `iterations` or a non-finite J would). The updates are those of [`learn`], so a
/// rule that never fires gives exactly its result.
pub fn learn_until<D: DifferentiableStep>(
    bptt: &mut Bptt<'_, D>,
    v0: &[f64],
    descent: Descent,
    scale: f64,
    iterations: usize,
    stop: &mut dyn FnMut(&IterationTrace, &[f64]) -> bool,
) -> Learned {
    let schedule = Schedule {
        descent,
        rule: StepRule::Fixed,
        scale,
        curvature_iterations: 0,
    };
    learn_with(bptt, v0, &schedule, iterations, &mut |e, v, _| stop(e, v))
}

/// The update rule, its step rule, the initial step scale λ and the power iterations of each
/// re-estimate ([`StepRule::Reestimate`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Schedule {
    /// Plain descent or momentum, η in units of 1/λ.
    pub descent: Descent,
    /// How λ evolves.
    pub rule: StepRule,
    /// The initial λ.
    pub scale: f64,
    /// Power iterations per re-estimate.
    pub curvature_iterations: usize,
}

/// [`learn_until`] under any [`Schedule`]; `stop` also sees the states s_0 … s_M of the
/// iterate's rollout. Under [`StepRule::Fixed`] the iterates are exactly those of [`learn`].
pub fn learn_with<D: DifferentiableStep>(
    bptt: &mut Bptt<'_, D>,
    v0: &[f64],
    schedule: &Schedule,
    iterations: usize,
    stop: &mut dyn FnMut(&IterationTrace, &[f64], &[f64]) -> bool,
) -> Learned {
    let start = std::time::Instant::now();
    let passes0 = bptt.forward_passes();
    let descent = schedule.descent;
    let (eta, alpha) = (descent.eta(), descent.alpha());
    let mut lambda = schedule.scale;
    let mut t = 1.0;
    let mut v = v0.to_vec();
    bptt.project(&mut v);
    let d = v.len();
    let mut g = vec![0.0; d];
    let (mut p, mut trial) = (vec![0.0; d], vec![0.0; d]);
    let mut state = DescentState::default();
    let mut trace = Vec::with_capacity(iterations.min(4096) + 1);
    let (mut best_iteration, mut best_value, mut best_knots) = (0, f64::INFINITY, v.clone());
    let mut taken_scale = lambda;
    // Levenberg–Marquardt: the terms' curvatures (an objective without one gets none, and the
    // damping alone scales the step), the Gauss–Newton matrix, the damping μ and its growth ν.
    let lm = matches!(schedule.rule, StepRule::LevenbergMarquardt { .. });
    let curvature = if lm {
        bptt.objective().gauss_newton().unwrap_or_default()
    } else {
        Vec::new()
    };
    let mut hmat = vec![0.0; if lm { d * d } else { 0 }];
    let (mut mu, mut nu) = match schedule.rule {
        StepRule::LevenbergMarquardt { damping, .. } => (damping, 2.0),
        _ => (0.0, 2.0),
    };
    if lm {
        taken_scale = mu;
    }
    for l in 0..=iterations {
        if let StepRule::Reestimate { every } = schedule.rule {
            if l > 0 && l % every == 0 {
                let est = bptt.curvature(&v, schedule.curvature_iterations.max(1));
                if est.is_finite() && est > 0.0 {
                    lambda = est;
                }
            }
        }
        let j = if lm {
            bptt.gauss_newton(&v, &curvature, &mut g, &mut hmat)
        } else {
            bptt.gradient(&v, &mut g)
        };
        let entry = IterationTrace {
            iteration: l,
            objective: j,
            grad_norm: norm(&g),
            seconds: start.elapsed().as_secs_f64(),
            evaluations: bptt.forward_passes() - passes0,
            scale: taken_scale,
        };
        trace.push(entry);
        if j.is_finite() && j < best_value {
            (best_iteration, best_value) = (l, j);
            best_knots.copy_from_slice(&v);
        }
        if stop(&entry, &v, bptt.states()) || !j.is_finite() || l == iterations {
            break;
        }
        match schedule.rule {
            StepRule::Fixed | StepRule::Reestimate { .. } => {
                let (step, next) = descent.update(&g, lambda, std::mem::take(&mut state));
                state = next;
                for ((x, s), o) in v.iter_mut().zip(&step).zip(trial.iter_mut()) {
                    *o = *x;
                    *x += s;
                }
                taken_scale = lambda;
            }
            StepRule::Armijo {
                c,
                shrink,
                grow,
                max_backtracks,
            } => {
                for i in 0..d {
                    p[i] = -eta * t / lambda * g[i]
                        + alpha * state.delta.get(i).copied().unwrap_or(0.0);
                }
                if dot(&p, &g) >= 0.0 {
                    for i in 0..d {
                        p[i] = -eta * t / lambda * g[i];
                    }
                }
                let (mut sigma, t_used) = (1.0, t);
                let mut accepted = false;
                for _ in 0..=max_backtracks {
                    for i in 0..d {
                        trial[i] = v[i] + sigma * p[i];
                    }
                    bptt.project(&mut trial);
                    let decrease: f64 = (0..d).map(|i| g[i] * (trial[i] - v[i])).sum();
                    if decrease < 0.0 && bptt.rollout(&trial) <= j + c * decrease {
                        accepted = true;
                        break;
                    }
                    sigma *= shrink;
                }
                taken_scale = lambda / (t_used * sigma);
                if accepted {
                    t = (t_used * if sigma == 1.0 { grow } else { sigma }).min(1e12);
                    std::mem::swap(&mut v, &mut trial);
                } else {
                    t = (t_used * sigma).max(1e-12);
                    taken_scale = f64::INFINITY;
                    trial.copy_from_slice(&v);
                }
            }
            StepRule::LevenbergMarquardt { max_tries, .. } => {
                let mut accepted = false;
                for _ in 0..max_tries {
                    if !lm_trial(bptt, &v, &g, &hmat, mu, &mut trial) {
                        (mu, nu) = (mu * nu, nu * 2.0);
                        continue;
                    }
                    // Predicted decrease of the quadratic model along the projected step.
                    let dv: Vec<f64> = (0..d).map(|i| trial[i] - v[i]).collect();
                    let curv: f64 = (0..d)
                        .map(|p| dv[p] * dot(&hmat[p * d..(p + 1) * d], &dv))
                        .sum();
                    let predicted = -(dot(&g, &dv) + 0.5 * curv);
                    let actual = j - bptt.rollout(&trial);
                    let rho = actual / predicted;
                    if predicted > 0.0 && rho.is_finite() && rho > 1e-4 {
                        mu *= (1.0 - (2.0 * rho - 1.0).powi(3)).max(1.0 / 3.0);
                        nu = 2.0;
                        accepted = true;
                        break;
                    }
                    (mu, nu) = (mu * nu, nu * 2.0);
                }
                mu = mu.clamp(1e-12, 1e12);
                if accepted {
                    taken_scale = mu;
                    std::mem::swap(&mut v, &mut trial);
                } else {
                    taken_scale = f64::INFINITY;
                    trial.copy_from_slice(&v);
                }
            }
        }
        bptt.project(&mut v);
        // The momentum state carries the step actually taken (after projection); `trial`
        // holds the previous iterate.
        state.delta.resize(d, 0.0);
        for (dl, (a, b)) in state.delta.iter_mut().zip(v.iter().zip(&trial)) {
            *dl = a - b;
        }
    }
    bptt.rollout(&v);
    Learned {
        knots: v,
        controls: bptt.controls().to_vec(),
        states: bptt.states().to_vec(),
        trace,
        best_iteration,
        best_knots,
    }
}

/// One Levenberg–Marquardt trial point: solves (H_FF + μ diag(H)_FF) δ_F = −g_F over the free
/// knots F (those not held at a bound by the gradient) and writes Π(v + δ) to `trial`; false
/// when the damped matrix is not positive definite.
fn lm_trial<D: DifferentiableStep>(
    bptt: &Bptt<'_, D>,
    v: &[f64],
    g: &[f64],
    h: &[f64],
    mu: f64,
    trial: &mut [f64],
) -> bool {
    let (d, m) = (v.len(), bptt.knots().m);
    let free: Vec<usize> = (0..d)
        .filter(|&i| bptt.bounds().project(i % m, v[i] - 1e-9 * g[i].signum()) != v[i])
        .collect();
    trial.copy_from_slice(v);
    if free.is_empty() {
        return true;
    }
    let max_diag = (0..d).map(|i| h[i * d + i]).fold(0.0, f64::max);
    let floor = if max_diag > 0.0 { 1e-9 * max_diag } else { 1.0 };
    let f = free.len();
    let a = nalgebra::DMatrix::from_fn(f, f, |r, c| {
        let (p, q) = (free[r], free[c]);
        h[p * d + q]
            + if r == c {
                mu * h[p * d + p].max(floor)
            } else {
                0.0
            }
    });
    let Some(chol) = a.cholesky() else {
        return false;
    };
    let step = chol.solve(&nalgebra::DVector::from_fn(f, |r, _| -g[free[r]]));
    for (r, &p) in free.iter().enumerate() {
        trial[p] = bptt.bounds().project(p % m, v[p] + step[r]);
    }
    true
}

/// The learned controls replayed on a physical simulator.
#[derive(Debug, Clone, PartialEq)]
pub struct Replay {
    /// Simulated states at the emulator step times (M + 1, n each).
    pub states: Vec<f64>,
    /// |s_M^emulated − s_M^simulated| (Euclidean, state units).
    pub final_gap: f64,
}

/// Drives `sim` from `x0` with per-step `controls` (m each), each held for `substeps` physical
/// steps of `physical_dt`; compares the final state with `emulated_final`.
pub fn replay(
    sim: &mut dyn Dynamics,
    x0: &[f64],
    controls: &[f64],
    physical_dt: f64,
    substeps: usize,
    emulated_final: &[f64],
) -> Replay {
    let m = sim.control_dim();
    let mut x = x0.to_vec();
    let mut states = x.clone();
    for u in controls.chunks_exact(m.max(1)) {
        for _ in 0..substeps {
            sim.step(&mut x, &u[..m], physical_dt);
        }
        states.extend_from_slice(&x);
    }
    let gap = x
        .iter()
        .zip(emulated_final)
        .map(|(a, b)| (a - b) * (a - b))
        .sum::<f64>()
        .sqrt();
    Replay {
        states,
        final_gap: gap,
    }
}

/// Test fixtures shared by the BPTT tests and the search adapters' tests.
#[cfg(test)]
pub(crate) mod fixtures {
    use super::super::objective::{ControlEffort, FinalState, Objective};
    use super::LinearStep;
    use crate::emulator::catalog::NetModel;
    use crate::emulator::mlp::{Mlp, WeightInit};
    use crate::emulator::{Emulator, Transforms};
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    /// A lander-shaped emulator with random weights (seed 3, 12 hidden units, Δt = 0.5 s), a
    /// soft-landing-like objective (reach the start state moved by (+3, ·, −5), small effort)
    /// and the start state.
    pub(crate) fn lander_emulator() -> (Emulator, Objective, Vec<f64>) {
        let model = NetModel::Lander;
        let (n, m) = (model.state_dim(), model.control_dim());
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let mlp = Mlp::new(n + m, 12, n, WeightInit::FanIn, &mut rng);
        let t = Transforms::unfitted(&model.transform_config(), n, m).unwrap();
        let e = Emulator::new(t, mlp, 0.5).unwrap();
        let x0 = model.start_state(&mut rng);
        let mut target = x0.clone();
        target[0] += 3.0;
        target[2] -= 5.0;
        let obj = Objective::default()
            .with(FinalState {
                mu: 1.0,
                target,
                weights: vec![1.0; n],
            })
            .with(ControlEffort::plain(0.01, m));
        (e, obj, x0)
    }

    /// A stable 3-state, 2-control linear map.
    pub(crate) fn linear() -> LinearStep {
        LinearStep {
            a: vec![1.0, 0.1, 0.0, -0.2, 0.95, 0.1, 0.0, 0.05, 0.9],
            b: vec![0.0, 0.1, 0.3, 0.0, 0.0, 0.2],
            n: 3,
            m: 2,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::objective::{ControlEffort, FinalState, StateWindow};
    use super::fixtures::linear;
    use super::*;
    use crate::emulator::catalog::NetModel;
    use crate::emulator::mlp::{Mlp, WeightInit};
    use crate::emulator::{Emulator, Transforms};
    use rand::SeedableRng;

    fn fd_check<D: DifferentiableStep>(bptt: &mut Bptt<'_, D>, v: &[f64], tol: f64) {
        let mut g = vec![0.0; v.len()];
        bptt.gradient(v, &mut g);
        let h = 1e-6;
        let scale = norm(&g).max(1.0);
        for i in 0..v.len() {
            let (mut p, mut q) = (v.to_vec(), v.to_vec());
            p[i] += h;
            q[i] -= h;
            let fd = (bptt.rollout(&p) - bptt.rollout(&q)) / (2.0 * h);
            assert!(
                (fd - g[i]).abs() <= tol * scale,
                "knot {i}: fd {fd} vs bptt {}",
                g[i]
            );
        }
    }

    /// [`Bounds::denormalize`] (actuator by actuator) is c_j + h_j v_i value by value, every
    /// bit, for bounded and unbounded actuators and a length that is not a whole number of
    /// knots.
    #[test]
    fn denormalize_is_the_affine_map_value_by_value() {
        let bounds = Bounds {
            low: vec![-2.0, f64::NEG_INFINITY, 0.3],
            high: vec![5.0, 1.0, 0.7],
        };
        let v: Vec<f64> = (0..17).map(|i| (i as f64 * 0.37).sin() * 1.3).collect();
        let mut u = vec![f64::NAN; v.len()];
        bounds.denormalize(&v, &mut u);
        for (i, (u, v)) in u.iter().zip(&v).enumerate() {
            let (c, h) = bounds.affine(i % 3);
            assert_eq!(u.to_bits(), (c + h * v).to_bits(), "value {i}");
        }
    }

    #[test]
    fn bptt_gradient_matches_finite_differences_on_a_linear_system() {
        let sys = linear();
        let obj = Objective::default()
            .with(ControlEffort {
                mu: 0.1,
                offset: vec![0.5, 0.0],
                scale: vec![2.0, 1.0],
            })
            .with(FinalState {
                mu: 1.0,
                target: vec![1.0, -1.0, 0.5],
                weights: vec![1.0, 2.0, 0.5],
            })
            .with(StateWindow {
                mu: 0.3,
                from: 6,
                to: 10,
                reference: vec![0.0, 0.0, 0.0],
                weights: vec![0.0, 1.0, 1.0],
            });
        let knots = Knots {
            steps: 10,
            per_actuator: 4,
            m: 2,
        };
        let bounds = Bounds {
            low: vec![-1.0, f64::NEG_INFINITY],
            high: vec![3.0, f64::INFINITY],
        };
        let mut b = Bptt::new(&sys, &obj, knots, bounds, &[0.2, -0.1, 0.3]).unwrap();
        let v: Vec<f64> = (0..b.dim()).map(|i| (i as f64 * 0.3).sin() * 0.5).collect();
        fd_check(&mut b, &v, 1e-6);
    }

    /// The J that `gradient` returns (from the objective's gradient pass) is the J of
    /// `rollout` bit for bit, and the gradient the same whether a rollout came before.
    #[test]
    fn gradient_returns_the_rollout_objective_bit_for_bit() {
        let (e, obj, x0) = fixtures::lander_emulator();
        let (knots, bounds) = lander_layout(8, 4);
        let mut b = Bptt::new(&e, &obj, knots, bounds, &x0).unwrap();
        for k in 0..5 {
            let v: Vec<f64> = (0..b.dim())
                .map(|i| (i as f64 * 0.7 + k as f64).cos())
                .collect();
            let (mut g1, mut g2) = (vec![0.0; v.len()], vec![0.0; v.len()]);
            let j1 = b.gradient(&v, &mut g1);
            let j0 = b.rollout(&v);
            let j2 = b.gradient(&v, &mut g2);
            assert_eq!(j1.to_bits(), j0.to_bits(), "J at knots {k}");
            assert_eq!(j2.to_bits(), j0.to_bits());
            assert!(g1.iter().zip(&g2).all(|(a, b)| a.to_bits() == b.to_bits()));
        }
    }

    /// The lander's knots over `steps` steps, `per_actuator` each, in small boxes (which keep
    /// the fixture's random net in its responsive range).
    fn lander_layout(steps: usize, per_actuator: usize) -> (Knots, Bounds) {
        let m = NetModel::Lander.control_dim();
        let knots = Knots {
            steps,
            per_actuator,
            m,
        };
        let bounds = Bounds {
            low: vec![-0.5; m],
            high: vec![0.5; m],
        };
        (knots, bounds)
    }

    #[test]
    fn bptt_gradient_matches_finite_differences_through_an_emulator_with_transforms() {
        let (e, obj, x0) = fixtures::lander_emulator();
        let (knots, bounds) = lander_layout(6, 3);
        let mut b = Bptt::new(&e, &obj, knots, bounds, &x0).unwrap();
        let v: Vec<f64> = (0..b.dim()).map(|i| (i as f64 * 0.7).cos() * 0.6).collect();
        fd_check(&mut b, &v, 1e-5);
    }

    /// Through the dolphin's global net: 6 segment frames expressed in one segment's frame
    /// (six points, twelve vectors, six quaternions), with the swim's progress term.
    #[test]
    fn bptt_gradient_matches_finite_differences_through_the_dolphin_global_net() {
        use crate::control::objective::Progress;
        use crate::emulator::hierarchy::{global_state, global_transforms, GLOBAL_DIM};
        use crate::physics::dolphin::Dolphin;
        let (n, m) = (GLOBAL_DIM, 6);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(4);
        let mlp = Mlp::new(n + m, 10, n, WeightInit::FanIn, &mut rng);
        let t = Transforms::unfitted(&global_transforms(), n, m).unwrap();
        let e = Emulator::new(t, mlp, 0.1).unwrap();
        let d = Dolphin::default();
        let mut x = d.rest_state();
        for (i, q) in x.iter_mut().enumerate() {
            *q += 0.02 * (i as f64 * 0.37).sin();
        }
        let mut g0 = vec![0.0; n];
        global_state(&d, &x, &mut g0);
        let obj = Objective::default()
            .with(ControlEffort::plain(0.01, m))
            .with(Progress {
                mu: 1.0,
                direction: [1.0, 0.0, 0.0],
                points: (0..6).map(|s| 13 * s).collect(),
            });
        let knots = Knots {
            steps: 4,
            per_actuator: 2,
            m,
        };
        let bounds = Bounds {
            low: vec![-1.0; m],
            high: vec![1.0; m],
        };
        let mut b = Bptt::new(&e, &obj, knots, bounds, &g0).unwrap();
        let v: Vec<f64> = (0..b.dim()).map(|i| (i as f64 * 0.9).sin() * 0.5).collect();
        fd_check(&mut b, &v, 1e-5);
    }

    /// Through a physical simulator: the RK4 step of the acrobot, with its analytic Jacobians.
    #[test]
    fn bptt_gradient_matches_finite_differences_through_the_rk4_acrobot() {
        use crate::control::Rk4Map;
        use crate::physics::acrobot::Acrobot;
        let map = Rk4Map::new(Acrobot::default(), 0.02).unwrap();
        let x0 = [-1.2, 0.4, 0.3, -0.5];
        let obj = Objective::default()
            .with(ControlEffort::plain(0.05, 1))
            .with(FinalState {
                mu: 1.0,
                target: vec![-0.9, 0.1, 0.0, 0.0],
                weights: vec![1.0, 1.0, 0.1, 0.1],
            })
            .with(StateWindow {
                mu: 0.2,
                from: 3,
                to: 6,
                reference: vec![-1.0, 0.2, 0.0, 0.0],
                weights: vec![1.0, 0.5, 0.0, 0.1],
            });
        let knots = Knots {
            steps: 6,
            per_actuator: 3,
            m: 1,
        };
        let bounds = Bounds {
            low: vec![-4.0],
            high: vec![4.0],
        };
        let mut b = Bptt::new(&map, &obj, knots, bounds, &x0).unwrap();
        let v: Vec<f64> = (0..b.dim()).map(|i| (i as f64 * 0.8).sin() * 0.6).collect();
        fd_check(&mut b, &v, 1e-6);
    }

    /// Through the RK4 step of the active 3-link pendulum, linearized by central differences.
    #[test]
    fn bptt_gradient_matches_finite_differences_through_the_rk4_pendulum() {
        use crate::control::Rk4Map;
        use crate::physics::linearize::FiniteDifference;
        use crate::physics::pendulum::{Pendulum3, PendulumVariant};
        let model = FiniteDifference::new(Pendulum3::new(PendulumVariant::Active));
        let map = Rk4Map::new(model, 0.01).unwrap();
        let x0 = [0.3, -0.2, 0.1, 0.5, 0.0, -0.4];
        let obj = Objective::default()
            .with(ControlEffort::plain(0.01, 3))
            .with(FinalState {
                mu: 1.0,
                target: vec![0.5, 0.0, 0.0, 0.0, 0.0, 0.0],
                weights: vec![1.0, 1.0, 1.0, 0.1, 0.1, 0.1],
            });
        let knots = Knots {
            steps: 4,
            per_actuator: 2,
            m: 3,
        };
        let bounds = Bounds {
            low: vec![-2.0; 3],
            high: vec![2.0; 3],
        };
        let mut b = Bptt::new(&map, &obj, knots, bounds, &x0).unwrap();
        let v: Vec<f64> = (0..b.dim()).map(|i| (i as f64 * 0.6).cos() * 0.5).collect();
        fd_check(&mut b, &v, 1e-5);
    }

    /// Substeps: five inner steps of the linear map are A⁵ s + Σ Aᵏ B u, and BPTT through the
    /// composition matches finite differences (through the RK4 truck too).
    #[test]
    fn substepped_steps_compose_and_their_gradients_match_finite_differences() {
        use crate::control::Rk4Map;
        use crate::physics::linearize::FiniteDifference;
        use crate::physics::truck::Truck;
        let sub = Substepped {
            inner: linear(),
            substeps: 5,
        };
        let (s, u) = ([0.3, -0.2, 0.5], [0.7, -0.4]);
        let mut y = [0.0; 3];
        sub.step(&s, &u, &mut sub.scratch(), &mut y);
        let mut x = s.to_vec();
        for _ in 0..5 {
            let mut z = [0.0; 3];
            linear().step(&x, &u, &mut (), &mut z);
            x = z.to_vec();
        }
        assert!(y.iter().zip(&x).all(|(a, b)| (a - b).abs() < 1e-14));
        let obj = Objective::default()
            .with(ControlEffort::plain(0.01, 2))
            .with(FinalState {
                mu: 1.0,
                target: vec![1.0, -1.0, 0.5],
                weights: vec![1.0, 2.0, 0.5],
            });
        let knots = Knots {
            steps: 4,
            per_actuator: 2,
            m: 2,
        };
        let mut b = Bptt::new(&sub, &obj, knots, Bounds::unbounded(2), &s).unwrap();
        let v: Vec<f64> = (0..b.dim()).map(|i| (i as f64 * 0.4).sin()).collect();
        fd_check(&mut b, &v, 1e-6);
        let truck = Substepped {
            inner: Rk4Map::new(FiniteDifference::new(Truck::default()), 0.01).unwrap(),
            substeps: 10,
        };
        let obj = Objective::default().with(FinalState {
            mu: 1.0,
            target: vec![0.0; 6],
            weights: vec![1.0, 1.0, 10.0, 1.0, 1.0, 1.0],
        });
        let bounds = Bounds {
            low: vec![-3.0, -0.5],
            high: vec![3.0, 0.5],
        };
        let x0 = [-2.0, 1.0, 0.3, 1.0, 0.0, 0.0];
        let mut b = Bptt::new(&truck, &obj, knots, bounds, &x0).unwrap();
        let v: Vec<f64> = (0..b.dim()).map(|i| 0.5 * (i as f64 * 0.7).cos()).collect();
        fd_check(&mut b, &v, 1e-5);
    }

    #[test]
    fn knots_expand_and_reduce_are_adjoint() {
        let k = Knots {
            steps: 40,
            per_actuator: 20,
            m: 4,
        };
        assert_eq!(k.len(), 80);
        assert_eq!(
            (k.knot_of(0), k.knot_of(1), k.knot_of(2), k.knot_of(39)),
            (0, 0, 1, 19)
        );
        let knots: Vec<f64> = (0..80).map(|i| i as f64).collect();
        let ub: Vec<f64> = (0..160).map(|i| (i as f64).sin()).collect();
        let mut u = vec![0.0; 160];
        k.expand(&knots, &mut u);
        let mut kb = vec![0.0; 80];
        k.reduce(&ub, &mut kb);
        assert!((dot(&u, &ub) - dot(&knots, &kb)).abs() < 1e-9);
    }

    /// J = ½ Σ_k λ_k (x_k(M) − 1)² on a one-step identity system with eigenvalues 1 … 100.
    fn ill_conditioned() -> (LinearStep, Objective) {
        let n = 4;
        let mut b = vec![0.0; n * n];
        for k in 0..n {
            b[k * n + k] = 1.0;
        }
        let sys = LinearStep {
            a: vec![0.0; n * n],
            b,
            n,
            m: n,
        };
        let obj = Objective::default().with(FinalState {
            mu: 1.0,
            target: vec![1.0; n],
            weights: vec![1.0, 10.0, 30.0, 100.0],
        });
        (sys, obj)
    }

    #[test]
    fn momentum_beats_plain_descent_on_an_ill_conditioned_quadratic() {
        let (sys, obj) = ill_conditioned();
        let knots = Knots {
            steps: 1,
            per_actuator: 1,
            m: 4,
        };
        let mut b = Bptt::new(&sys, &obj, knots, Bounds::unbounded(4), &[0.0; 4]).unwrap();
        let v0 = vec![0.0; 4];
        let lambda = b.curvature(&v0, 50);
        assert!((lambda - 100.0).abs() < 1e-3, "{lambda}");
        let plain = learn(&mut b, &v0, Descent::Plain { eta: 1.0 }, lambda, 100);
        let mom = learn(
            &mut b,
            &v0,
            Descent::Momentum {
                eta: 1.5,
                alpha: 0.5,
            },
            lambda,
            100,
        );
        assert_eq!(plain.trace.len(), 101);
        let (p, q) = (plain.final_objective(), mom.final_objective());
        assert!(q < 0.1 * p, "momentum {q} vs plain {p}");
        // Plain descent above η = 2 (in units of 1/λ_max) diverges on a quadratic.
        let wild = learn(&mut b, &v0, Descent::Plain { eta: 2.2 }, lambda, 60);
        assert!(wild.final_objective() > wild.trace[0].objective);
    }

    /// s'_k = exp(u_k) (the state is ignored): J = ½ Σ (e^{u_k} − 1)² is steep far out
    /// (J'' ≈ 2e^{2u}, about 790 at u = 3) and flat at the optimum u = 0 (J'' = 1), so a step
    /// scale measured at the start is hundreds of times too small near the goal.
    struct ExpStep;

    impl DifferentiableStep for ExpStep {
        type Scratch = ();
        fn state_dim(&self) -> usize {
            3
        }
        fn control_dim(&self) -> usize {
            3
        }
        fn scratch(&self) {}
        fn step(&self, _s: &[f64], u: &[f64], _: &mut (), s_next: &mut [f64]) {
            for (y, u) in s_next.iter_mut().zip(u) {
                *y = u.exp();
            }
        }
        fn vjp(
            &self,
            _s: &[f64],
            u: &[f64],
            sb1: &[f64],
            _: &mut (),
            sb: &mut [f64],
            ub: &mut [f64],
        ) {
            sb.fill(0.0);
            for k in 0..3 {
                ub[k] = u[k].exp() * sb1[k];
            }
        }
    }

    fn exp_problem() -> Objective {
        Objective::default().with(FinalState {
            mu: 1.0,
            target: vec![1.0; 3],
            weights: vec![1.0; 3],
        })
    }

    fn schedule(descent: Descent, rule: StepRule, scale: f64) -> Schedule {
        Schedule {
            descent,
            rule,
            scale,
            curvature_iterations: 30,
        }
    }

    const MOMENTUM: Descent = Descent::Momentum {
        eta: 1.5,
        alpha: 0.5,
    };
    const ARMIJO: StepRule = StepRule::Armijo {
        c: 1e-4,
        shrink: 0.5,
        grow: 2.0,
        max_backtracks: 30,
    };

    /// Iterations until J ≤ `goal` (None: never within the run).
    fn iterations_to(r: &Learned, goal: f64) -> Option<usize> {
        r.trace
            .iter()
            .find(|e| e.objective <= goal)
            .map(|e| e.iteration)
    }

    #[test]
    fn reestimated_and_line_searched_steps_converge_where_the_fixed_scale_crawls() {
        let obj = exp_problem();
        let knots = Knots {
            steps: 1,
            per_actuator: 1,
            m: 3,
        };
        let mut b = Bptt::new(&ExpStep, &obj, knots, Bounds::unbounded(3), &[0.0; 3]).unwrap();
        let v0 = vec![3.0, 2.5, 2.0];
        let lambda = b.curvature(&v0, 50);
        assert!(lambda > 500.0, "{lambda}");
        let goal = 1e-8;
        let run = |b: &mut Bptt<'_, ExpStep>, rule| {
            learn_with(
                b,
                &v0,
                &schedule(MOMENTUM, rule, lambda),
                300,
                &mut |_, _, _| false,
            )
        };
        let fixed = run(&mut b, StepRule::Fixed);
        let re = run(&mut b, StepRule::Reestimate { every: 5 });
        let ls = run(&mut b, ARMIJO);
        // The paper's fixed step: still far from the goal after 300 iterations.
        assert_eq!(
            iterations_to(&fixed, goal),
            None,
            "{}",
            fixed.final_objective()
        );
        for (name, r) in [("reestimate", &re), ("armijo", &ls)] {
            let k =
                iterations_to(r, goal).unwrap_or_else(|| panic!("{name}: {}", r.final_objective()));
            assert!(k <= 60, "{name}: {k} iterations");
            assert!(r.best_objective() <= goal);
            assert!(
                r.knots.iter().all(|u| u.abs() < 1e-3),
                "{name}: {:?}",
                r.knots
            );
        }
        // The line search never raises J; its extra rollouts are counted.
        assert!(ls
            .trace
            .windows(2)
            .all(|w| w[1].objective <= w[0].objective));
        let last = ls.trace.last().unwrap();
        assert!(last.evaluations > last.iteration + 1);
        // Re-estimates are counted too: 61 rollouts each (a gradient and 2 × 30 for the
        // Hessian–vector products).
        let r_last = re.trace.last().unwrap();
        assert!(r_last.evaluations >= r_last.iteration + 1 + 61 * (r_last.iteration / 5));
        assert!(
            r_last.scale < 10.0,
            "re-estimated λ near the optimum: {}",
            r_last.scale
        );
    }

    #[test]
    fn line_search_converges_on_the_ill_conditioned_quadratic_and_the_linear_fixture() {
        let (sys, obj) = ill_conditioned();
        let knots = Knots {
            steps: 1,
            per_actuator: 1,
            m: 4,
        };
        let mut b = Bptt::new(&sys, &obj, knots, Bounds::unbounded(4), &[0.0; 4]).unwrap();
        let v0 = vec![0.0; 4];
        let lambda = b.curvature(&v0, 50);
        let s = schedule(MOMENTUM, ARMIJO, lambda);
        let ls = learn_with(&mut b, &v0, &s, 200, &mut |_, _, _| false);
        let fx = learn(&mut b, &v0, MOMENTUM, lambda, 200);
        // On a quadratic λ_max is the right scale everywhere: the line search converges
        // (J from 70.5 to below 1e-4) about as fast as the fixed step, no faster.
        let (a, f) = (ls.final_objective(), fx.final_objective());
        assert!(a < 1e-4 && a < 10.0 * f, "armijo {a} vs fixed {f}");
        // A re-estimate on a quadratic measures the same λ: exactly the fixed run.
        let fixed = learn(&mut b, &v0, MOMENTUM, lambda, 40);
        let re = learn_with(
            &mut b,
            &v0,
            &schedule(MOMENTUM, StepRule::Reestimate { every: 1000 }, lambda),
            40,
            &mut |_, _, _| false,
        );
        assert_eq!(fixed.knots, re.knots);
        // The linear fixture within bounds: the line search stays in the box and ends at
        // least as low as the paper's fixed step.
        let sys = linear();
        let obj = Objective::default()
            .with(ControlEffort::plain(0.01, 2))
            .with(FinalState {
                mu: 1.0,
                target: vec![2.0, -1.0, 1.0],
                weights: vec![1.0, 10.0, 100.0],
            });
        let knots = Knots {
            steps: 8,
            per_actuator: 4,
            m: 2,
        };
        let bounds = Bounds {
            low: vec![-3.0, -3.0],
            high: vec![3.0, 3.0],
        };
        let mut b = Bptt::new(&sys, &obj, knots, bounds, &[0.0; 3]).unwrap();
        let v0 = vec![0.0; b.dim()];
        let lambda = b.curvature(&v0, 50);
        let fixed = learn(&mut b, &v0, MOMENTUM, lambda, 100);
        let ls = learn_with(
            &mut b,
            &v0,
            &schedule(MOMENTUM, ARMIJO, lambda),
            100,
            &mut |_, _, _| false,
        );
        assert!(ls.knots.iter().all(|v| v.abs() <= 1.0));
        assert!(
            ls.final_objective() <= fixed.final_objective() + 1e-12,
            "armijo {} vs fixed {}",
            ls.final_objective(),
            fixed.final_objective()
        );
    }

    const LM: StepRule = StepRule::LevenbergMarquardt {
        damping: 1e-3,
        max_tries: 30,
    };

    /// The linear fixture with effort, a final-state term and a trajectory window.
    fn linear_problem() -> Objective {
        Objective::default()
            .with(ControlEffort {
                mu: 0.05,
                offset: vec![0.1, -0.2],
                scale: vec![2.0, 0.5],
            })
            .with(FinalState {
                mu: 1.0,
                target: vec![2.0, -1.0, 1.0],
                weights: vec![1.0, 10.0, 100.0],
            })
            .with(StateWindow {
                mu: 0.3,
                from: 3,
                to: 5,
                reference: vec![0.5, 0.0, 0.0],
                weights: vec![1.0, 0.0, 2.0],
            })
    }

    #[test]
    fn gauss_newton_matrix_is_the_exact_hessian_for_a_linear_step() {
        let sys = linear();
        let obj = linear_problem();
        let knots = Knots {
            steps: 8,
            per_actuator: 4,
            m: 2,
        };
        let bounds = Bounds {
            low: vec![-3.0, -1.0],
            high: vec![3.0, 2.0],
        };
        let mut b = Bptt::new(&sys, &obj, knots, bounds, &[0.2, 0.0, -0.1]).unwrap();
        let d = b.dim();
        let v: Vec<f64> = (0..d).map(|i| 0.4 * (i as f64 * 0.9).sin()).collect();
        let curvature = obj.gauss_newton().unwrap();
        let (mut g, mut h) = (vec![0.0; d], vec![0.0; d * d]);
        let j = b.gauss_newton(&v, &curvature, &mut g, &mut h);
        let mut g0 = vec![0.0; d];
        assert_eq!(j, b.gradient(&v, &mut g0));
        assert_eq!(g, g0);
        // J is quadratic in the knots: central differences of the gradient are exact.
        let eps = 1e-3;
        let (mut gp, mut gm) = (vec![0.0; d], vec![0.0; d]);
        let scale = h.iter().fold(0.0f64, |a, x| a.max(x.abs()));
        assert!(scale > 1.0);
        for q in 0..d {
            let (mut p, mut m) = (v.clone(), v.clone());
            p[q] += eps;
            m[q] -= eps;
            b.gradient(&p, &mut gp);
            b.gradient(&m, &mut gm);
            for r in 0..d {
                let fd = (gp[r] - gm[r]) / (2.0 * eps);
                assert!(
                    (fd - h[r * d + q]).abs() <= 1e-8 * scale,
                    "H[{r},{q}]: fd {fd} vs {}",
                    h[r * d + q]
                );
            }
        }
        // A term without a curvature rules Gauss–Newton out.
        #[derive(Debug)]
        struct Opaque;
        impl crate::control::objective::Term for Opaque {
            fn value(&self, _: crate::control::objective::Trajectory<'_>) -> f64 {
                0.0
            }
            fn add_gradient(
                &self,
                _: crate::control::objective::Trajectory<'_>,
                _: &mut [f64],
                _: &mut [f64],
            ) {
            }
        }
        assert!(linear_problem().with(Opaque).gauss_newton().is_none());
    }

    #[test]
    fn levenberg_marquardt_solves_the_linear_problem_in_a_few_iterations_and_stays_in_the_box() {
        let sys = linear();
        let obj = linear_problem();
        let knots = Knots {
            steps: 8,
            per_actuator: 4,
            m: 2,
        };
        // Wide bounds: the unconstrained optimum is inside, so LM reaches a zero gradient.
        let wide = Bounds {
            low: vec![-50.0, -50.0],
            high: vec![50.0, 50.0],
        };
        let mut b = Bptt::new(&sys, &obj, knots, wide, &[0.0; 3]).unwrap();
        let v0 = vec![0.0; b.dim()];
        let lm = learn_with(
            &mut b,
            &v0,
            &schedule(MOMENTUM, LM, 1.0),
            5,
            &mut |_, _, _| false,
        );
        let start = &lm.trace[0];
        let last = lm.trace.last().unwrap();
        assert!(
            last.grad_norm < 1e-6 * start.grad_norm,
            "|g| {} -> {}",
            start.grad_norm,
            last.grad_norm
        );
        // The paper's momentum descent after 100 iterations ends no lower.
        let lambda = b.curvature(&v0, 50);
        let fixed = learn(&mut b, &v0, MOMENTUM, lambda, 100);
        assert!(lm.final_objective() <= fixed.final_objective() + 1e-9);
        // Tight bounds: the iterates stay in the box and J never rises.
        let tight = Bounds {
            low: vec![-0.5, -0.3],
            high: vec![0.5, 0.3],
        };
        let mut b = Bptt::new(&sys, &obj, knots, tight, &[0.0; 3]).unwrap();
        let r = learn_with(
            &mut b,
            &v0,
            &schedule(MOMENTUM, LM, 1.0),
            30,
            &mut |_, _, _| false,
        );
        assert!(r.knots.iter().all(|v| v.abs() <= 1.0));
        assert!(r.knots.iter().any(|v| v.abs() == 1.0), "{:?}", r.knots);
        assert!(r.trace.windows(2).all(|w| w[1].objective <= w[0].objective));
        // Projected-gradient optimality: zero gradient on the free knots, and on each knot held
        // at a bound the gradient pushes outwards.
        let mut g = vec![0.0; r.knots.len()];
        b.gradient(&r.knots, &mut g);
        for (v, g) in r.knots.iter().zip(&g) {
            if v.abs() < 1.0 {
                assert!(g.abs() < 1e-6, "free knot {v}: gradient {g}");
            } else {
                assert!(g * v <= 1e-9, "knot at {v}: gradient {g}");
            }
        }
    }

    #[test]
    fn levenberg_marquardt_converges_where_momentum_crawls_on_the_nonlinear_problem() {
        let obj = exp_problem();
        let knots = Knots {
            steps: 1,
            per_actuator: 1,
            m: 3,
        };
        let mut b = Bptt::new(&ExpStep, &obj, knots, Bounds::unbounded(3), &[0.0; 3]).unwrap();
        let v0 = vec![3.0, 2.5, 2.0];
        let r = learn_with(
            &mut b,
            &v0,
            &schedule(MOMENTUM, LM, 1.0),
            40,
            &mut |_, _, _| false,
        );
        let k = iterations_to(&r, 1e-8).unwrap_or_else(|| panic!("{}", r.final_objective()));
        assert!(k <= 30, "{k} iterations");
        assert!(r.trace.windows(2).all(|w| w[1].objective <= w[0].objective));
    }

    #[test]
    fn bounds_are_respected_and_replay_on_the_same_system_has_no_gap() {
        let sys = linear();
        let obj = Objective::default().with(FinalState {
            mu: 1.0,
            target: vec![50.0, 50.0, 50.0],
            weights: vec![1.0; 3],
        });
        let knots = Knots {
            steps: 8,
            per_actuator: 2,
            m: 2,
        };
        let bounds = Bounds {
            low: vec![-1.0, -2.0],
            high: vec![1.0, 0.5],
        };
        let mut b = Bptt::new(&sys, &obj, knots, bounds.clone(), &[0.0; 3]).unwrap();
        let v0 = vec![0.0; b.dim()];
        let lambda = b.curvature(&v0, 30);
        let r = learn(&mut b, &v0, Descent::Plain { eta: 1.0 }, lambda, 30);
        for u in r.controls.chunks(2) {
            assert!(u[0] >= -1.0 - 1e-12 && u[0] <= 1.0 + 1e-12);
            assert!(u[1] >= -2.0 - 1e-12 && u[1] <= 0.5 + 1e-12);
        }
        assert!(r.final_objective() < r.trace[0].objective);
        // The same linear map as Dynamics: replay reproduces the final state.
        let last = &r.states[r.states.len() - 3..];
        let rep = replay(&mut linear(), &[0.0; 3], &r.controls, 0.1, 1, last);
        assert!(rep.final_gap < 1e-12);
        assert_eq!(rep.states.len(), 9 * 3);
    }
}
