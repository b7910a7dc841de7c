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
//! The knots and boxes are in `layout`, the problem with its rollout, tape and backward sweep in
//! `sweep`, the update and step rules with their settings in `rules`, the loop in `optimize`,
//! composed steps in `substepped` and the replay on a simulator in `simulator`.
//!
//! ## References
//! - R. Grzeszczuk, D. Terzopoulos, G. Hinton, *NeuroAnimator*, SIGGRAPH 1998, §4.3, eq. 13–15.
//! - P. J. Werbos, *Backpropagation through time: what it does and how to do it*, Proc. IEEE
//!   78(10), 1990.
//! - L. Armijo, *Minimization of functions having Lipschitz continuous first partial
//!   derivatives*, Pacific J. Math. 16(1), 1966; J. Nocedal, S. Wright, *Numerical
//!   Optimization*, 2nd ed., §3.1 (backtracking), §16.7 (projected gradient).

mod layout;
mod optimize;
mod rules;
mod simulator;
mod substepped;
mod sweep;

pub use crate::physics::differentiable::{DifferentiableStep, LinearStep};
pub use layout::{Bounds, Knots};
pub use optimize::{learn, learn_until, learn_with, IterationTrace, Learned};
pub use rules::{Descent, DescentState, Schedule, StepRule};
pub use simulator::{replay, Replay};
pub use substepped::{Substepped, SubsteppedScratch};
use sweep::dot;
pub use sweep::{norm, Bptt};

/// Test fixtures shared by the BPTT tests and the search adapters' tests.
#[cfg(test)]
pub(crate) mod fixtures {
    use super::super::objective::{ControlEffort, FinalState, Objective, StateWindow};
    use super::{norm, Bptt, DifferentiableStep, LinearStep};
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

    /// Checks `bptt`'s gradient at `v` against central differences of its rollout.
    pub(crate) fn fd_check<D: DifferentiableStep>(bptt: &mut Bptt<'_, D>, v: &[f64], tol: f64) {
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

    /// The linear fixture with effort, a final-state term and a trajectory window.
    pub(crate) fn linear_problem() -> Objective {
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
}
