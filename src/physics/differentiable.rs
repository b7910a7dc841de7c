//! # Differentiable discrete steps: what backpropagation through time needs of a model
//!
//! A [`DifferentiableStep`] is a discrete-time map s' = N(s, u) together with its
//! vector–Jacobian product: given an adjoint s̄' of the next state it returns
//!
//! ```text
//! s̄ = (∂N/∂s)ᵀ s̄',      ū = (∂N/∂u)ᵀ s̄',
//! ```
//!
//! the one product that reverse-mode differentiation through a rollout (BPTT, Werbos 1990)
//! chains step by step. It sits next to [`super::Dynamics`] because it is a property of a
//! discrete model, not of a solver: a learned emulator implements it by backpropagating
//! through its transforms and network (NeuroAnimator §4.3, eq. 10), a physical model by the
//! exact Jacobians of its RK4 discretization (`control::Rk4Map` over any
//! [`super::linearize::Linearize`] model), and [`LinearStep`] as a reference. Solvers that
//! need gradients through time (`control::bptt`) ask only for this trait and never name a
//! concrete network or simulator.
//!
//! ## References
//! - P. J. Werbos, *Backpropagation through time: what it does and how to do it*, Proc. IEEE
//!   78(10), 1990.
//! - R. Grzeszczuk, D. Terzopoulos, G. Hinton, *NeuroAnimator*, SIGGRAPH 1998, §4.3.

use super::Dynamics;

/// A discrete-time step with a vector–Jacobian product: what BPTT needs of a model.
pub trait DifferentiableStep {
    /// Per-thread scratch.
    type Scratch;
    /// Number of state variables.
    fn state_dim(&self) -> usize;
    /// Number of control variables.
    fn control_dim(&self) -> usize;
    /// Fresh scratch.
    fn scratch(&self) -> Self::Scratch;
    /// Writes s' = N(s, u) into `s_next`.
    fn step(&self, s: &[f64], u: &[f64], scratch: &mut Self::Scratch, s_next: &mut [f64]);
    /// Writes `s_bar` = (∂N/∂s)ᵀ s̄' and `u_bar` = (∂N/∂u)ᵀ s̄' (overwritten).
    fn vjp(
        &self,
        s: &[f64],
        u: &[f64],
        s_next_bar: &[f64],
        scratch: &mut Self::Scratch,
        s_bar: &mut [f64],
        u_bar: &mut [f64],
    );

    /// How many values one step records for its VJP in [`DifferentiableStep::step_taped`]
    /// (0, the default: nothing, the VJP recomputes what it needs).
    fn tape_len(&self) -> usize {
        0
    }

    /// [`DifferentiableStep::step`] that also records, in `tape` ([`DifferentiableStep::tape_len`]
    /// values), what [`DifferentiableStep::vjp_taped`] at the same (s, u) needs (e.g. an
    /// emulator's network activations), so that the backward sweep of BPTT does not repeat the
    /// forward pass. The default records nothing.
    fn step_taped(
        &self,
        s: &[f64],
        u: &[f64],
        scratch: &mut Self::Scratch,
        s_next: &mut [f64],
        tape: &mut [f64],
    ) {
        let _ = tape;
        self.step(s, u, scratch, s_next);
    }

    /// [`DifferentiableStep::vjp`] from the `tape` that [`DifferentiableStep::step_taped`]
    /// recorded at the same (s, u); the result is bit for bit that of `vjp`. The default
    /// ignores the tape.
    #[allow(clippy::too_many_arguments)]
    fn vjp_taped(
        &self,
        s: &[f64],
        u: &[f64],
        tape: &[f64],
        s_next_bar: &[f64],
        scratch: &mut Self::Scratch,
        s_bar: &mut [f64],
        u_bar: &mut [f64],
    ) {
        let _ = tape;
        self.vjp(s, u, s_next_bar, scratch, s_bar, u_bar);
    }
}

/// A linear step s' = A s + B u (row-major A: n × n, B: n × m), for tests and references.
#[derive(Debug, Clone, PartialEq)]
pub struct LinearStep {
    /// A, row-major n × n.
    pub a: Vec<f64>,
    /// B, row-major n × m.
    pub b: Vec<f64>,
    /// State dimension n.
    pub n: usize,
    /// Control dimension m.
    pub m: usize,
}

impl DifferentiableStep for LinearStep {
    type Scratch = ();
    fn state_dim(&self) -> usize {
        self.n
    }
    fn control_dim(&self) -> usize {
        self.m
    }
    fn scratch(&self) {}
    fn step(&self, s: &[f64], u: &[f64], _: &mut (), s_next: &mut [f64]) {
        for r in 0..self.n {
            let a = &self.a[r * self.n..(r + 1) * self.n];
            let b = &self.b[r * self.m..(r + 1) * self.m];
            s_next[r] = a.iter().zip(s).map(|(x, y)| x * y).sum::<f64>()
                + b.iter().zip(u).map(|(x, y)| x * y).sum::<f64>();
        }
    }
    fn vjp(
        &self,
        _s: &[f64],
        _u: &[f64],
        sb1: &[f64],
        _: &mut (),
        s_bar: &mut [f64],
        u_bar: &mut [f64],
    ) {
        s_bar.fill(0.0);
        u_bar.fill(0.0);
        for r in 0..self.n {
            for c in 0..self.n {
                s_bar[c] += self.a[r * self.n + c] * sb1[r];
            }
            for c in 0..self.m {
                u_bar[c] += self.b[r * self.m + c] * sb1[r];
            }
        }
    }
}

/// The map as discrete dynamics: each `step` applies s' = A s + B u once, whatever `dt` (a
/// reference simulator for [`LinearStep`] rollouts, e.g. to replay learned controls).
impl Dynamics for LinearStep {
    fn state_dim(&self) -> usize {
        self.n
    }
    fn control_dim(&self) -> usize {
        self.m
    }
    fn step(&mut self, x: &mut [f64], u: &[f64], _dt: f64) {
        let mut y = vec![0.0; self.n];
        DifferentiableStep::step(self, x, u, &mut (), &mut y);
        x.copy_from_slice(&y);
    }
}

/// The full Jacobians A = ∂N/∂s (n × n) and B = ∂N/∂u (n × m) of a step at (s, u), row by
/// row from n vector–Jacobian products with the unit adjoints e_r: row r of [A B] is
/// e_rᵀ [∂N/∂s ∂N/∂u]. Exact wherever the step's VJP is (an emulator's passes through its
/// transforms and network). `adjoint`, `s_bar` and `u_bar` are scratch of sizes n, n, m.
#[allow(clippy::too_many_arguments)]
pub fn jacobians<D: DifferentiableStep + ?Sized>(
    step: &D,
    s: &[f64],
    u: &[f64],
    scratch: &mut D::Scratch,
    a: &mut nalgebra::DMatrix<f64>,
    b: &mut nalgebra::DMatrix<f64>,
    adjoint: &mut [f64],
    (s_bar, u_bar): (&mut [f64], &mut [f64]),
) {
    adjoint.fill(0.0);
    for r in 0..step.state_dim() {
        adjoint[r] = 1.0;
        step.vjp(s, u, adjoint, scratch, s_bar, u_bar);
        adjoint[r] = 0.0;
        for (c, v) in s_bar.iter().enumerate() {
            a[(r, c)] = *v;
        }
        for (c, v) in u_bar.iter().enumerate() {
            b[(r, c)] = *v;
        }
    }
}
