//! Several steps of an inner differentiable step as one ([`Substepped`]), e.g. RK4 steps of a
//! physical model on an emulator's step.

use crate::physics::differentiable::DifferentiableStep;

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

#[cfg(test)]
mod tests {
    use super::super::fixtures::{fd_check, linear};
    use super::*;
    use crate::control::bptt::{Bounds, Bptt, Knots};
    use crate::control::objective::{ControlEffort, FinalState, Objective};

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
        let bounds = Bounds::new(vec![-3.0, -0.5], vec![3.0, 0.5]);
        let x0 = [-2.0, 1.0, 0.3, 1.0, 0.0, 0.0];
        let mut b = Bptt::new(&truck, &obj, knots, bounds, &x0).unwrap();
        let v: Vec<f64> = (0..b.dim()).map(|i| 0.5 * (i as f64 * 0.7).cos()).collect();
        fd_check(&mut b, &v, 1e-5);
    }
}
