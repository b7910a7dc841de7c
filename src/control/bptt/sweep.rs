//! One control problem ([`Bptt`]): the forward rollout on its tape and the backward sweep that
//! gives J's gradient over the normalized knots, its Gauss–Newton matrix and its curvature.

use super::{Bounds, Knots};
use crate::control::objective::{GaussNewton, Objective};
use crate::control::ControlError;
use crate::physics::differentiable::DifferentiableStep;

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

/// Dot product.
pub(super) fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// Euclidean norm.
pub fn norm(a: &[f64]) -> f64 {
    dot(a, a).sqrt()
}

#[cfg(test)]
mod tests {
    use super::super::fixtures::{self, fd_check, linear, linear_problem};
    use super::*;
    use crate::control::objective::{ControlEffort, FinalState, StateWindow};
    use crate::emulator::catalog::NetModel;
    use crate::emulator::mlp::{Mlp, WeightInit};
    use crate::emulator::{Emulator, Transforms};
    use rand::SeedableRng;

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
        let bounds = Bounds::new(vec![-1.0, f64::NEG_INFINITY], vec![3.0, f64::INFINITY]);
        let mut b = Bptt::new(&sys, &obj, knots, bounds.clone(), &[0.2, -0.1, 0.3]).unwrap();
        let v: Vec<f64> = (0..b.dim()).map(|i| (i as f64 * 0.3).sin() * 0.5).collect();
        fd_check(&mut b, &v, 1e-6);
        // Gains on the actuators (equal-sensitivity control units): the gradient is still J's over
        // the gained variables, and equals the unit-gain gradient times each actuator's gain
        // at the same controls.
        let gained = bounds.with_gain(vec![7.0, 0.25]);
        let mut g = Bptt::new(&sys, &obj, knots, gained, &[0.2, -0.1, 0.3]).unwrap();
        let w: Vec<f64> = v
            .iter()
            .enumerate()
            .map(|(i, x)| x / [7.0, 0.25][i % 2])
            .collect();
        fd_check(&mut g, &w, 1e-6);
        let (mut g0, mut g1) = (vec![0.0; v.len()], vec![0.0; v.len()]);
        let j0 = b.gradient(&v, &mut g0);
        let j1 = g.gradient(&w, &mut g1);
        assert!((j0 - j1).abs() <= 1e-12 * j0.abs().max(1.0), "{j0} vs {j1}");
        for (i, (a, c)) in g0.iter().zip(&g1).enumerate() {
            let want = a * [7.0, 0.25][i % 2];
            assert!(
                (c - want).abs() <= 1e-9 * want.abs().max(1e-9),
                "{i}: {c} vs {want}"
            );
        }
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
        let bounds = Bounds::new(vec![-0.5; m], vec![0.5; m]);
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
        let bounds = Bounds::new(vec![-1.0; m], vec![1.0; m]);
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
        let bounds = Bounds::new(vec![-4.0], vec![4.0]);
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
        let bounds = Bounds::new(vec![-2.0; 3], vec![2.0; 3]);
        let mut b = Bptt::new(&map, &obj, knots, bounds, &x0).unwrap();
        let v: Vec<f64> = (0..b.dim()).map(|i| (i as f64 * 0.6).cos() * 0.5).collect();
        fd_check(&mut b, &v, 1e-5);
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
        let bounds = Bounds::new(vec![-3.0, -1.0], vec![3.0, 2.0]);
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
}
