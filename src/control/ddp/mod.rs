//! # Differential dynamic programming (DDP) and iLQR
//!
//! Minimizes J = g(x_N) + Σ_k l(x_k, u_k) subject to x_{k+1} = F(x_k, u_k) (the problem of
//! [`super`]) by alternating a backward pass that builds a local quadratic model of the
//! cost-to-go along the current trajectory (x̄, ū) and a forward pass that rolls out an improved
//! one. Backward, from V_x = g_x, V_xx = g_xx:
//!
//! ```text
//! Q_x  = l_x + F_xᵀ V_x'                  Q_u  = l_u + F_uᵀ V_x'
//! Q_xx = l_xx + F_xᵀ V_xx' F_x (+ V_x'·F_xx)    Q_ux = F_uᵀ V_xx' F_x (+ V_x'·F_ux)
//! Q_uu = l_uu + F_uᵀ V_xx' F_u (+ V_x'·F_uu)
//! k = −(Q_uu + μI)⁻¹ Q_u,  K = −(Q_uu + μI)⁻¹ Q_ux
//! V_x  = Q_x + Kᵀ Q_uu k + Kᵀ Q_u + Q_uxᵀ k
//! V_xx = Q_xx + Kᵀ Q_uu K + Kᵀ Q_ux + Q_uxᵀ K
//! ```
//!
//! The terms in parentheses (second derivatives of the dynamics contracted with V_x') make
//! full second-order DDP ([`DdpVariant::Full`]); dropping them gives iLQR, a Gauss–Newton
//! method ([`DdpVariant::Ilqr`]). Forward, with step α:
//! u_k = ū_k + α k_k + K_k (x_k − x̄_k), x_{k+1} = F(x_k, u_k); the step is accepted when the
//! actual reduction is a fraction of the expected one, ΔJ(α) = −(α Σ kᵀQ_u + ½ α² Σ kᵀQ_uu k);
//! otherwise α shrinks (backtracking).
//!
//! μ is a Levenberg–Marquardt regularization of Q_uu with the adaptive schedule of Tassa et al.:
//! it grows (μ ← max(μ_min, μ·Δ), Δ ← max(Δ_0, Δ·Δ_0)) when Q_uu + μI is not positive definite
//! or the line search fails, and shrinks (Δ ← min(1/Δ_0, Δ/Δ_0), μ ← μ·Δ, or 0 below μ_min)
//! after an accepted step. With box bounds on u, k solves the box QP
//! min_δu ½ δuᵀ(Q_uu + μI)δu + Q_uᵀ δu, ū + δu ∈ [lower, upper] by projected Newton
//! ([`box_qp`]), and the rows of K for clamped controls are zero.
//!
//! Iterations stop when the relative cost reduction of an accepted step falls below
//! `tol_cost`, when the (projected) gradient ‖∂J/∂u‖ — computed exactly by the adjoint
//! recursion λ_N = g_x, λ_k = l_x + F_xᵀ λ_{k+1}, ∂J/∂u_k = l_u + F_uᵀ λ_{k+1} — falls below
//! `tol_grad`, after `max_iterations` forward passes, or when μ exceeds `mu_max`.
//! The returned gains always come from a backward pass at the returned trajectory.
//!
//! The backward pass and the adjoint gradient are in `backward`, the projected-Newton box QP
//! in `box_qp`; this module holds the options, the forward pass with its line search, the
//! regularization schedule and the solver loop ([`solve`]).
//!
//! ## References
//! - D. H. Jacobson, D. Q. Mayne, *Differential Dynamic Programming*, Elsevier, 1970.
//! - W. Li, E. Todorov, *Iterative linear quadratic regulator design for nonlinear biological
//!   movement systems*, ICINCO 2004 (iLQR).
//! - Y. Tassa, T. Erez, E. Todorov, *Synthesis and stabilization of complex behaviors through
//!   online trajectory optimization*, IROS 2012 (regularization schedule, line search).
//! - Y. Tassa, N. Mansard, E. Todorov, *Control-limited differential dynamic programming*,
//!   ICRA 2014 (projected-Newton box QP).

mod backward;
mod box_qp;

pub use backward::cost_gradient;
pub use box_qp::{box_qp, BoxQpWorkspace};

use super::{ControlError, Knots, QuadraticCost, Rk4Map, Rk4Workspace, StageDerivatives};
use crate::physics::linearize::Linearize;
use backward::backward;
#[cfg(test)]
use backward::backward_on;
use nalgebra::{DMatrix, DVector};

/// Which DDP variant to run.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DdpVariant {
    /// iLQR: first-order dynamics (Gauss–Newton Hessian).
    Ilqr,
    /// Full second-order DDP: adds V_x·F_zz, with F_zz by differences of the exact Jacobians.
    Full,
}

/// Box bounds lower ≤ u ≤ upper on every control.
#[derive(Debug, Clone, PartialEq)]
pub struct ControlBounds {
    /// Lower bounds (m).
    pub lower: DVector<f64>,
    /// Upper bounds (m).
    pub upper: DVector<f64>,
}

/// Settings of [`solve`].
#[derive(Debug, Clone, PartialEq)]
pub struct DdpOptions {
    /// iLQR or full DDP.
    pub variant: DdpVariant,
    /// Maximum number of forward passes.
    pub max_iterations: usize,
    /// Stop when an accepted step reduces the cost by less than `tol_cost`·|J|.
    pub tol_cost: f64,
    /// Stop when the projected gradient norm ‖∂J/∂u‖₂ is below this.
    pub tol_grad: f64,
    /// Initial regularization μ (0: start with pure Newton steps).
    pub mu_init: f64,
    /// Smallest nonzero μ; smaller values snap to 0.
    pub mu_min: f64,
    /// Give up when μ exceeds this.
    pub mu_max: f64,
    /// Base factor Δ_0 > 1 of the regularization schedule.
    pub mu_factor: f64,
    /// Backtracking factor for α, in (0, 1).
    pub backtrack: f64,
    /// Smallest α tried before the line search counts as failed.
    pub min_step: f64,
    /// Accept a step when actual reduction ≥ `armijo` × expected reduction.
    pub armijo: f64,
    /// Optional box bounds on u.
    pub bounds: Option<ControlBounds>,
    /// Relative difference step for the second derivatives of full DDP.
    pub fd_step: f64,
}

impl Default for DdpOptions {
    fn default() -> Self {
        Self {
            variant: DdpVariant::Ilqr,
            max_iterations: 200,
            tol_cost: 1e-8,
            tol_grad: 1e-7,
            mu_init: 0.0,
            mu_min: 1e-6,
            mu_max: 1e10,
            mu_factor: 1.6,
            backtrack: 0.5,
            min_step: 1e-4,
            armijo: 1e-4,
            bounds: None,
            fd_step: 1e-5,
        }
    }
}

/// One forward pass of [`solve`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct IterationRecord {
    /// Iteration number, from 1.
    pub iteration: usize,
    /// Cost after this iteration (unchanged when the step was rejected).
    pub cost: f64,
    /// Regularization μ used by this iteration's backward pass.
    pub regularization: f64,
    /// Accepted step size α, or 0 when the line search failed.
    pub step: f64,
    /// Projected gradient norm ‖∂J/∂u‖₂ at the start of the iteration.
    pub gradient_norm: f64,
    /// Reduction the quadratic model predicted for the accepted α (for α = 1 when rejected).
    pub expected_reduction: f64,
    /// Backward passes that failed (Q_uu + μI not positive definite) before this one worked.
    pub backward_failures: usize,
    /// Whether the step was accepted.
    pub accepted: bool,
}

/// Why [`solve`] stopped.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Termination {
    /// Relative cost reduction below `tol_cost`.
    CostChange,
    /// Projected gradient norm below `tol_grad`.
    Gradient,
    /// `max_iterations` forward passes done.
    MaxIterations,
    /// μ exceeded `mu_max` (no descent found; the gains may be stale).
    RegularizationLimit,
}

/// The result of [`solve`].
#[derive(Debug, Clone, PartialEq)]
pub struct DdpSolution {
    /// Optimized states x̄_0..x̄_N.
    pub x: Vec<DVector<f64>>,
    /// Optimized controls ū_0..ū_{N−1}.
    pub u: Vec<DVector<f64>>,
    /// Feedback gains K_0..K_{N−1} (m × n) of the last backward pass, at (x̄, ū).
    pub gains: Knots,
    /// Feedforward steps k_0..k_{N−1} (m × 1 each) of the last backward pass (≈ 0 at
    /// convergence).
    pub feedforward: Knots,
    /// Final cost J(x̄, ū).
    pub cost: f64,
    /// Projected gradient norm at the returned trajectory.
    pub gradient_norm: f64,
    /// Regularization μ at the end.
    pub regularization: f64,
    /// One record per forward pass.
    pub trace: Vec<IterationRecord>,
    /// Why the solver stopped.
    pub termination: Termination,
}

impl DdpSolution {
    /// Number of accepted steps.
    pub fn accepted_steps(&self) -> usize {
        self.trace.iter().filter(|r| r.accepted).count()
    }
}

/// Per-trajectory buffers of the solver, allocated once per [`solve`] call.
struct Buffers {
    fx: Knots,
    fu: Knots,
    fzz: Vec<Vec<DMatrix<f64>>>,
    kff: Knots,
    /// Knot k's previous feedforward step, the bounded QP's warm start.
    warm: DVector<f64>,
    gains: Knots,
    x_new: Vec<DVector<f64>>,
    u_new: Vec<DVector<f64>>,
    vx: DVector<f64>,
    vxx: DMatrix<f64>,
    l: StageDerivatives,
    qu: DVector<f64>,
    quu_reg: DMatrix<f64>,
    dx: DVector<f64>,
    lo: DVector<f64>,
    hi: DVector<f64>,
    qp: BoxQpWorkspace,
    rk4: Rk4Workspace,
}

impl Buffers {
    fn new(n: usize, m: usize, horizon: usize, full: bool, rk4: Rk4Workspace) -> Self {
        let vn = || DVector::zeros(n);
        let vm = || DVector::zeros(m);
        Self {
            fx: Knots::zeros(horizon, n, n),
            fu: Knots::zeros(horizon, n, m),
            fzz: if full {
                vec![vec![DMatrix::zeros(n + m, n + m); n]; horizon]
            } else {
                Vec::new()
            },
            kff: Knots::zeros(horizon, m, 1),
            warm: vm(),
            gains: Knots::zeros(horizon, m, n),
            x_new: vec![vn(); horizon + 1],
            u_new: vec![vm(); horizon],
            vx: vn(),
            vxx: DMatrix::zeros(n, n),
            l: StageDerivatives::new(n, m),
            qu: vm(),
            quu_reg: DMatrix::zeros(m, m),
            dx: vn(),
            lo: vm(),
            hi: vm(),
            qp: BoxQpWorkspace::new(m),
            rk4,
        }
    }
}

/// Forward pass with step α into `b.x_new`, `b.u_new`; returns the new cost, or `None` when
/// the rollout is not finite. Does not allocate.
fn forward<M: Linearize>(
    map: &Rk4Map<M>,
    cost: &QuadraticCost,
    xs: &[DVector<f64>],
    us: &[DVector<f64>],
    alpha: f64,
    options: &DdpOptions,
    b: &mut Buffers,
) -> Option<f64> {
    let horizon = us.len();
    b.x_new[0].copy_from(&xs[0]);
    let mut total = 0.0;
    for k in 0..horizon {
        b.dx.copy_from(&b.x_new[k]);
        b.dx -= &xs[k];
        let u = &mut b.u_new[k];
        u.copy_from(&us[k]);
        u.axpy(alpha, &b.kff.vector(k), 1.0);
        u.gemv(1.0, &b.gains.matrix(k), &b.dx, 1.0);
        if let Some(bounds) = &options.bounds {
            for i in 0..u.len() {
                u[i] = u[i].clamp(bounds.lower[i], bounds.upper[i]);
            }
        }
        total += cost.running(k, &b.x_new[k], u);
        let (done, rest) = b.x_new.split_at_mut(k + 1);
        map.step(&done[k], u, &mut rest[0], &mut b.rk4);
        if !rest[0].iter().all(|v| v.is_finite()) {
            return None;
        }
    }
    total += cost.terminal(&b.x_new[horizon]);
    total.is_finite().then_some(total)
}

fn compute_derivatives<M: Linearize>(
    map: &Rk4Map<M>,
    xs: &[DVector<f64>],
    us: &[DVector<f64>],
    options: &DdpOptions,
    b: &mut Buffers,
) {
    let (fxs, fus) = (&mut b.fx, &mut b.fu);
    map.jacobians_each(xs, us, &mut b.rk4, |k, fx, fu| {
        fxs.matrix_mut(k).copy_from(fx);
        fus.matrix_mut(k).copy_from(fu);
    });
    if options.variant == DdpVariant::Full {
        for k in 0..us.len() {
            map.second_derivatives(&xs[k], &us[k], options.fd_step, &mut b.fzz[k], &mut b.rk4);
        }
    }
}

fn validate<M: Linearize>(
    map: &Rk4Map<M>,
    cost: &QuadraticCost,
    x0: &DVector<f64>,
    u_init: &[DVector<f64>],
    options: &DdpOptions,
) -> Result<(), ControlError> {
    let (n, m) = (map.state_dim(), map.control_dim());
    if u_init.is_empty() {
        return Err(ControlError::EmptyHorizon);
    }
    let dim = super::check_dim;
    dim("initial state", n, x0.len())?;
    for u in u_init {
        dim("initial control", m, u.len())?;
    }
    if let Some(bounds) = &options.bounds {
        dim("lower bounds", m, bounds.lower.len())?;
        dim("upper bounds", m, bounds.upper.len())?;
        for i in 0..m {
            let (lower, upper) = (bounds.lower[i], bounds.upper[i]);
            if lower.is_nan() || upper.is_nan() || lower > upper {
                return Err(ControlError::InvalidBounds {
                    index: i,
                    lower,
                    upper,
                });
            }
        }
    }
    cost.validate(n, m, u_init.len())
}

/// Optimizes the controls from `x0`, starting from `u_init` (N controls; clamped to the bounds),
/// for `cost` under the RK4 dynamics `map` (needs [`Linearize`]). Returns the trajectory, the
/// feedback gains and the per-iteration trace.
pub fn solve<M: Linearize>(
    map: &Rk4Map<M>,
    cost: &QuadraticCost,
    x0: &DVector<f64>,
    u_init: &[DVector<f64>],
    options: &DdpOptions,
) -> Result<DdpSolution, ControlError> {
    validate(map, cost, x0, u_init, options)?;
    let (n, m, horizon) = (map.state_dim(), map.control_dim(), u_init.len());
    let mut us = u_init.to_vec();
    if let Some(bounds) = &options.bounds {
        for u in &mut us {
            for i in 0..m {
                u[i] = u[i].clamp(bounds.lower[i], bounds.upper[i]);
            }
        }
    }
    let mut xs = map.rollout(x0, &us)?;
    let mut j = cost.total(&xs, &us);
    let full = options.variant == DdpVariant::Full;
    let mut b = Buffers::new(n, m, horizon, full, map.workspace());
    let mut mu = options.mu_init;
    let mut delta = 1.0_f64;
    let increase = |mu: &mut f64, delta: &mut f64| {
        *delta = options.mu_factor.max(*delta * options.mu_factor);
        *mu = options.mu_min.max(*mu * *delta);
    };
    let mut trace = Vec::new();
    let mut pending: Option<Termination> = None;
    let mut need_derivatives = true;
    let mut iteration = 0;
    let (termination, gradient_norm) = loop {
        if need_derivatives {
            compute_derivatives(map, &xs, &us, options, &mut b);
            need_derivatives = false;
        }
        let mut failures = 0;
        let result = loop {
            match backward(cost, &xs, &us, mu, options, &mut b) {
                Some(r) => break Some(r),
                None => {
                    failures += 1;
                    increase(&mut mu, &mut delta);
                    if mu > options.mu_max {
                        break None;
                    }
                }
            }
        };
        let Some(result) = result else {
            break (Termination::RegularizationLimit, f64::NAN);
        };
        if let Some(t) = pending {
            break (t, result.gradient_norm);
        }
        if result.gradient_norm < options.tol_grad {
            break (Termination::Gradient, result.gradient_norm);
        }
        if iteration >= options.max_iterations {
            break (Termination::MaxIterations, result.gradient_norm);
        }
        iteration += 1;
        // Backtracking line search.
        let mut alpha = 1.0;
        let mut accepted = None;
        while alpha >= options.min_step {
            let expected = -(alpha * result.dv1 + alpha * alpha * result.dv2);
            if let Some(j_new) = forward(map, cost, &xs, &us, alpha, options, &mut b) {
                let actual = j - j_new;
                let ok = if expected > 0.0 {
                    actual >= options.armijo * expected
                } else {
                    actual > 0.0
                };
                if ok {
                    accepted = Some((alpha, j_new, expected));
                    break;
                }
            }
            alpha *= options.backtrack;
        }
        let mu_used = mu;
        match accepted {
            Some((alpha, j_new, expected)) => {
                std::mem::swap(&mut xs, &mut b.x_new);
                std::mem::swap(&mut us, &mut b.u_new);
                let reduction = j - j_new;
                if reduction < options.tol_cost * j.abs() {
                    pending = Some(Termination::CostChange);
                }
                j = j_new;
                need_derivatives = true;
                delta = (1.0 / options.mu_factor).min(delta / options.mu_factor);
                mu = if mu * delta > options.mu_min {
                    mu * delta
                } else {
                    0.0
                };
                trace.push(IterationRecord {
                    iteration,
                    cost: j,
                    regularization: mu_used,
                    step: alpha,
                    gradient_norm: result.gradient_norm,
                    expected_reduction: expected,
                    backward_failures: failures,
                    accepted: true,
                });
            }
            None => {
                trace.push(IterationRecord {
                    iteration,
                    cost: j,
                    regularization: mu_used,
                    step: 0.0,
                    gradient_norm: result.gradient_norm,
                    expected_reduction: -(result.dv1 + result.dv2),
                    backward_failures: failures,
                    accepted: false,
                });
                increase(&mut mu, &mut delta);
                if mu > options.mu_max {
                    break (Termination::RegularizationLimit, result.gradient_norm);
                }
            }
        }
    };
    Ok(DdpSolution {
        x: xs,
        u: us,
        gains: b.gains,
        feedforward: b.kff,
        cost: j,
        gradient_norm,
        regularization: mu,
        trace,
        termination,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::control::lqr;
    use crate::control::test_models::LinearOde;
    use crate::control::StateCost;
    use crate::physics::acrobot::Acrobot;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;
    use std::f64::consts::FRAC_PI_2;

    fn linear_problem() -> (Rk4Map<LinearOde>, QuadraticCost) {
        // A damped oscillator and an unstable mode, two inputs.
        let a = DMatrix::from_row_slice(3, 3, &[0.0, 1.0, 0.0, -2.0, -0.3, 0.5, 0.0, 0.2, 0.4]);
        let b = DMatrix::from_row_slice(3, 2, &[0.0, 0.0, 1.0, 0.0, 0.3, 1.0]);
        let map = Rk4Map::new(LinearOde { a, b }, 0.05).unwrap();
        let cost = QuadraticCost {
            dt: 0.05,
            r: DMatrix::from_row_slice(2, 2, &[1.0, 0.2, 0.2, 0.5]),
            state: Some(StateCost {
                weight: DMatrix::from_diagonal(&DVector::from_vec(vec![1.0, 0.1, 2.0])),
                reference: vec![DVector::zeros(3)],
            }),
            q_final: DMatrix::from_diagonal(&DVector::from_vec(vec![50.0, 5.0, 20.0])),
            x_final: DVector::zeros(3),
        };
        (map, cost)
    }

    #[test]
    fn linear_quadratic_problem_is_solved_in_one_step_and_equals_lqr() {
        let (map, cost) = linear_problem();
        let horizon = 60;
        let x0 = DVector::from_vec(vec![1.0, -0.5, 0.8]);
        // Independent reference: LQR around the zero trajectory (feasible for a linear system),
        // rolled out in closed loop from x0.
        let zeros_x = vec![DVector::zeros(3); horizon + 1];
        let zeros_u = vec![DVector::zeros(2); horizon];
        let ctl = lqr::track(&map, &cost, &zeros_x, &zeros_u).unwrap();
        let mut x_lqr = vec![x0.clone()];
        let mut u_lqr = Vec::new();
        let mut ws = map.workspace();
        for k in 0..horizon {
            let u = ctl.policy(x_lqr[k].as_slice(), k);
            let mut next = DVector::zeros(3);
            map.step(&x_lqr[k], &u, &mut next, &mut ws);
            u_lqr.push(u);
            x_lqr.push(next);
        }
        let j_lqr = cost.total(&x_lqr, &u_lqr);
        assert!((ctl.value(x0.as_slice(), 0) - j_lqr).abs() < 1e-9 * j_lqr);
        for variant in [DdpVariant::Ilqr, DdpVariant::Full] {
            let options = DdpOptions {
                variant,
                ..DdpOptions::default()
            };
            let sol = solve(&map, &cost, &x0, &zeros_u, &options).unwrap();
            assert_eq!(sol.accepted_steps(), 1, "{variant:?}: {:?}", sol.trace);
            assert_eq!(sol.trace[0].step, 1.0);
            assert_eq!(sol.termination, Termination::Gradient);
            assert!((sol.cost - j_lqr).abs() < 1e-9 * j_lqr);
            // The model's predicted reduction was exact.
            let first = &sol.trace[0];
            let initial = cost.total(&map.rollout(&x0, &zeros_u).unwrap(), &zeros_u);
            assert!((initial - first.cost - first.expected_reduction).abs() < 1e-9 * initial);
            for k in 0..horizon {
                assert!((&sol.u[k] - &u_lqr[k]).amax() < 1e-9, "u[{k}]");
                assert!((&sol.x[k + 1] - &x_lqr[k + 1]).amax() < 1e-9, "x[{k}]");
                assert!(
                    (sol.gains.matrix(k) - ctl.gains.matrix(k)).amax() < 1e-9,
                    "K[{k}]"
                );
                assert!(sol.feedforward.matrix(k).amax() < 1e-9);
            }
        }
    }

    #[test]
    fn adjoint_gradient_matches_finite_differences_of_the_cost() {
        let map = Rk4Map::new(Acrobot::default(), 0.02).unwrap();
        let mut cost = swing_up_cost(0.02);
        cost.state = Some(StateCost {
            weight: DMatrix::identity(4, 4) * 0.5,
            reference: vec![DVector::from_vec(vec![0.0, 0.5, 0.0, 0.0])],
        });
        let mut rng = ChaCha8Rng::seed_from_u64(9);
        let us: Vec<DVector<f64>> = (0..40)
            .map(|_| DVector::from_element(1, rng.random_range(-3.0..3.0)))
            .collect();
        let x0 = DVector::from_vec(vec![-FRAC_PI_2 + 0.2, 0.1, 0.0, 0.3]);
        let grads = cost_gradient(&map, &cost, &x0, &us).unwrap();
        let total = |us: &[DVector<f64>]| cost.total(&map.rollout(&x0, us).unwrap(), us);
        let h = 1e-6;
        for k in [0, 7, 20, 39] {
            let (mut up, mut um) = (us.clone(), us.clone());
            up[k][0] += h;
            um[k][0] -= h;
            let fd = (total(&up) - total(&um)) / (2.0 * h);
            assert!(
                (fd - grads[k][0]).abs() < 1e-6 * fd.abs().max(1.0),
                "k = {k}: {fd} vs {}",
                grads[k][0]
            );
        }
    }

    /// |J(α) − J(0) + expected(α)| / α² for the step α of one backward pass at μ = 0.
    fn model_error_ratios(variant: DdpVariant) -> Vec<f64> {
        let dt = 0.02;
        let map = Rk4Map::new(Acrobot::default(), dt).unwrap();
        // A heavier control weight keeps Q_uu positive definite at μ = 0 for full DDP too.
        let mut cost = swing_up_cost(dt);
        cost.r *= 20.0;
        let mut rng = ChaCha8Rng::seed_from_u64(4);
        let us: Vec<DVector<f64>> = (0..60)
            .map(|_| DVector::from_element(1, rng.random_range(-2.0..2.0)))
            .collect();
        let xs = map
            .rollout(&DVector::from_vec(vec![-1.2, 0.3, 0.5, -0.4]), &us)
            .unwrap();
        let j0 = cost.total(&xs, &us);
        let options = DdpOptions {
            variant,
            ..DdpOptions::default()
        };
        let mut b = Buffers::new(4, 1, us.len(), variant == DdpVariant::Full, map.workspace());
        compute_derivatives(&map, &xs, &us, &options, &mut b);
        let r = backward(&cost, &xs, &us, 0.0, &options, &mut b).expect("Q_uu positive definite");
        [0.02, 0.01, 0.005]
            .into_iter()
            .map(|alpha| {
                let j = forward(&map, &cost, &xs, &us, alpha, &options, &mut b).unwrap();
                let expected = -(alpha * r.dv1 + alpha * alpha * r.dv2);
                ((j0 - j) - expected).abs() / (alpha * alpha)
            })
            .collect()
    }

    #[test]
    fn fixed_size_backward_pass_is_the_dynamic_one_bit_for_bit() {
        // The acrobot (4 × 1) and a damped pendulum (2 × 1) run on fixed-size matrices
        // (`crate::control::small`) with products in the heap path's summation order; gains,
        // feedforward steps and the expected reductions must agree bit for bit, for both
        // variants, with and without bounds (some controls clamped), regularized or not.
        use crate::control::test_models::DampedPendulum;
        let dt = 0.02;
        let mut cost = swing_up_cost(dt);
        cost.r *= 20.0;
        let acrobot = Rk4Map::new(Acrobot::default(), dt).unwrap();
        backward_bits_agree(&acrobot, &cost, &[-1.2, 0.3, 0.5, -0.4]);
        let pendulum = Rk4Map::new(DampedPendulum, dt).unwrap();
        let mut cost = QuadraticCost::effort(
            dt,
            1,
            DMatrix::from_diagonal(&DVector::from_vec(vec![100.0, 10.0])),
            DVector::from_vec(vec![std::f64::consts::PI, 0.0]),
        );
        cost.r *= 20.0;
        backward_bits_agree(&pendulum, &cost, &[0.3, -0.4]);
    }

    /// Asserts that [`backward`] (fixed-size matrices for `map`'s dimensions) and the heap
    /// pass give the same bits along a random-control rollout from `x0`.
    fn backward_bits_agree<M: Linearize>(map: &Rk4Map<M>, cost: &QuadraticCost, x0: &[f64]) {
        use nalgebra::Dyn;
        let (n, m) = (map.state_dim(), map.control_dim());
        let mut rng = ChaCha8Rng::seed_from_u64(9);
        let us: Vec<DVector<f64>> = (0..60)
            .map(|_| DVector::from_fn(m, |_, _| rng.random_range(-3.0..3.0)))
            .collect();
        let xs = map.rollout(&DVector::from_column_slice(x0), &us).unwrap();
        let bits = |b: &Buffers, r: &backward::BackwardResult| -> Vec<u64> {
            let gains = b.gains.as_slice().iter();
            let kff = b.kff.as_slice().iter();
            gains
                .chain(kff)
                .chain([&r.dv1, &r.dv2, &r.gradient_norm])
                .map(|v| v.to_bits())
                .collect()
        };
        for variant in [DdpVariant::Ilqr, DdpVariant::Full] {
            for bound in [None, Some(2.0)] {
                for mu in [0.0, 0.3] {
                    let options = DdpOptions {
                        variant,
                        bounds: bound.map(|b| ControlBounds {
                            lower: DVector::from_element(m, -b),
                            upper: DVector::from_element(m, b),
                        }),
                        ..DdpOptions::default()
                    };
                    let full = variant == DdpVariant::Full;
                    let run = |fixed: bool| {
                        let mut b = Buffers::new(n, m, us.len(), full, map.workspace());
                        compute_derivatives(map, &xs, &us, &options, &mut b);
                        let r = if fixed {
                            backward(cost, &xs, &us, mu, &options, &mut b)
                        } else {
                            backward_on(Dyn(n), Dyn(m), cost, &xs, &us, mu, &options, &mut b)
                        };
                        bits(&b, &r.expect("Q_uu positive definite"))
                    };
                    assert_eq!(
                        run(true),
                        run(false),
                        "n = {n}, {variant:?}, bound {bound:?}, μ {mu}"
                    );
                }
            }
        }
    }

    #[test]
    fn full_ddp_predicts_the_cost_change_to_second_order_and_ilqr_does_not() {
        // Full DDP's second-order dynamics terms make its quadratic model the exact Taylor
        // expansion of J along the step, so error/α² → 0 linearly in α; iLQR's stays O(1).
        let full = model_error_ratios(DdpVariant::Full);
        let ilqr = model_error_ratios(DdpVariant::Ilqr);
        for w in full.windows(2) {
            assert!((w[1] / w[0] - 0.5).abs() < 0.1, "full DDP: {full:?}");
        }
        for w in ilqr.windows(2) {
            assert!((w[1] / w[0] - 1.0).abs() < 0.1, "iLQR: {ilqr:?}");
        }
        assert!(full[2] < 0.1 * ilqr[2], "full {full:?} vs iLQR {ilqr:?}");
    }

    /// ½∫u² + (x − handstand)ᵀ Q_f (x − handstand).
    fn swing_up_cost(dt: f64) -> QuadraticCost {
        QuadraticCost::effort(
            dt,
            1,
            DMatrix::from_diagonal(&DVector::from_vec(vec![100.0, 100.0, 10.0, 10.0])),
            DVector::from_vec(vec![FRAC_PI_2, 0.0, 0.0, 0.0]),
        )
    }

    /// Swing-up from hanging down, (−90°, 0, 0, 0), over `seconds` at step `dt`.
    fn swing_up(
        variant: DdpVariant,
        bounds: Option<f64>,
        seconds: f64,
        dt: f64,
        max_iterations: usize,
    ) -> (Rk4Map<Acrobot>, QuadraticCost, f64, DdpSolution) {
        swing_up_weighted(variant, bounds, seconds, dt, max_iterations, 1.0)
    }

    /// [`swing_up`] with the terminal weight scaled by `qf_scale`.
    fn swing_up_weighted(
        variant: DdpVariant,
        bounds: Option<f64>,
        seconds: f64,
        dt: f64,
        max_iterations: usize,
        qf_scale: f64,
    ) -> (Rk4Map<Acrobot>, QuadraticCost, f64, DdpSolution) {
        let map = Rk4Map::new(Acrobot::default(), dt).unwrap();
        let mut cost = swing_up_cost(dt);
        cost.q_final *= qf_scale;
        let horizon = (seconds / dt).round() as usize;
        let x0 = DVector::from_vec(vec![-FRAC_PI_2, 0.0, 0.0, 0.0]);
        // A small hip pumping at the hanging pendulum's frequency breaks the symmetry.
        let u_init: Vec<DVector<f64>> = (0..horizon)
            .map(|k| DVector::from_element(1, (k as f64 * dt * 3.0).sin()))
            .collect();
        let initial = cost.total(&map.rollout(&x0, &u_init).unwrap(), &u_init);
        let options = DdpOptions {
            variant,
            max_iterations,
            bounds: bounds.map(|b| ControlBounds {
                lower: DVector::from_element(1, -b),
                upper: DVector::from_element(1, b),
            }),
            ..DdpOptions::default()
        };
        let sol = solve(&map, &cost, &x0, &u_init, &options).unwrap();
        (map, cost, initial, sol)
    }

    fn check_swing_up(
        map: &Rk4Map<Acrobot>,
        cost: &QuadraticCost,
        initial: f64,
        sol: &DdpSolution,
    ) {
        // Monotone decrease, and the trace's costs are the costs of true rollouts.
        let mut previous = initial;
        for r in &sol.trace {
            assert!(
                r.cost <= previous,
                "cost rose at iteration {}: {:?}",
                r.iteration,
                sol.trace
            );
            assert_eq!(r.cost < previous, r.accepted);
            previous = r.cost;
        }
        let xs = map.rollout(&sol.x[0], &sol.u).unwrap();
        for (a, b) in xs.iter().zip(&sol.x) {
            assert!((a - b).amax() < 1e-12);
        }
        assert!((cost.total(&xs, &sol.u) - sol.cost).abs() < 1e-9 * sol.cost);
        assert!(
            sol.cost < 0.2 * initial,
            "{} vs initial {initial}",
            sol.cost
        );
    }

    #[test]
    fn ilqr_and_full_ddp_swing_the_acrobot_up_with_monotone_cost() {
        for variant in [DdpVariant::Ilqr, DdpVariant::Full] {
            let (map, cost, initial, sol) = swing_up(variant, None, 3.0, 0.02, 100);
            check_swing_up(&map, &cost, initial, &sol);
            let dist = (&sol.x[sol.u.len()] - &cost.x_final).norm();
            assert!(
                dist < 0.3,
                "{variant:?}: final distance to the handstand {dist}"
            );
        }
    }

    #[test]
    fn box_bounds_are_respected_and_active() {
        let bound = 6.0;
        for variant in [DdpVariant::Ilqr, DdpVariant::Full] {
            let (map, cost, initial, sol) = swing_up(variant, Some(bound), 3.0, 0.02, 100);
            check_swing_up(&map, &cost, initial, &sol);
            assert!(sol.u.iter().all(|u| u[0].abs() <= bound));
            // The unbounded optimum needs |u| ≈ 12.7, so the bound must bind somewhere, and
            // where the box QP clamps the control its feedback row is zero.
            let at_bound: Vec<usize> = (0..sol.u.len())
                .filter(|&k| sol.u[k][0].abs() == bound)
                .collect();
            assert!(!at_bound.is_empty(), "{variant:?}: the bound should bind");
            assert!(at_bound.iter().any(|&k| sol.gains.matrix(k).amax() == 0.0));
            for k in 0..sol.u.len() {
                if sol.u[k][0].abs() < bound {
                    assert!(
                        sol.gains.matrix(k).amax() > 0.0,
                        "{variant:?}: free step {k} has no feedback"
                    );
                }
            }
        }
    }

    /// Prints the swing-up numbers quoted in reports:
    /// `cargo test --lib control::ddp::tests::swing_up_report -- --ignored --nocapture`.
    #[test]
    #[ignore]
    fn swing_up_report() {
        for (variant, bounds, seconds, dt, qf_scale) in [
            (DdpVariant::Ilqr, None, 3.0, 0.02, 1.0),
            (DdpVariant::Full, None, 3.0, 0.02, 1.0),
            (DdpVariant::Ilqr, Some(6.0), 3.0, 0.02, 1.0),
            (DdpVariant::Full, Some(6.0), 3.0, 0.02, 1.0),
            (DdpVariant::Ilqr, None, 4.0, 0.01, 1.0),
            (DdpVariant::Full, None, 4.0, 0.01, 1.0),
            (DdpVariant::Ilqr, None, 4.0, 0.01, 100.0),
            (DdpVariant::Full, None, 4.0, 0.01, 100.0),
        ] {
            let (_, cost, initial, sol) =
                swing_up_weighted(variant, bounds, seconds, dt, 500, qf_scale);
            let x_n = &sol.x[sol.u.len()];
            println!(
                "{variant:?} T={seconds} dt={dt} Qf x{qf_scale} bounds {bounds:?}: {} iterations ({} accepted), {:?}, cost {initial:.4} -> {:.6}, |grad| {:.2e}, final state {:.4?}, distance to handstand {:.2e}, max |u| {:.3}",
                sol.trace.len(),
                sol.accepted_steps(),
                sol.termination,
                sol.cost,
                sol.gradient_norm,
                x_n.as_slice(),
                (x_n - &cost.x_final).norm(),
                sol.u.iter().map(|u| u[0].abs()).fold(0.0, f64::max),
            );
        }
    }
}
