//! # Control-learning objectives (NeuroAnimator §4.2)
//!
//! A controller u = [u_1 … u_M] drives an emulator through the motion s = [s_1 … s_{M+1}]
//! (eq. 10). The objective (eq. 11) is a weighted sum of a controller term and trajectory terms;
//! the typical one (eq. 12) is
//!
//! ```text
//! J(u) = μ_u/2 Σ_i |u_i|² + μ_s/2 (s_{M+1} − s_d)²
//! ```
//!
//! Here every term is a [`Term`] that returns its value and adds its gradient with respect to
//! every state and every control of the trajectory; an [`Objective`] sums terms. Terms:
//!
//! - [`ControlEffort`]: μ_u/2 Σ_i Σ_j ((u_ij − o_j)/c_j)², effort about an offset o (e.g. the
//!   hover thrust) in units c per actuator;
//! - [`FinalState`]: μ_s/2 Σ_k w_k (s_{M+1,k} − s_{d,k})², the final-state term with a weight
//!   per state variable;
//! - [`StateWindow`]: μ/2 Σ_{i ∈ window} Σ_k w_k (s_{i,k} − r_k)², a trajectory term over a
//!   range of states (e.g. the descent velocity in the last seconds before touchdown);
//! - [`Progress`]: −μ d·(p̄_M − p̄_0), distance travelled along a direction (swimming forward).
//!
//! Layout ([`Trajectory`]): `states` holds the M + 1 states s_0 … s_M row after row (n each;
//! s_0 is the given start state, the paper's s_1), `controls` the M per-step controls (m each).
//!
//! Objectives are minimized here (the paper writes J as a cost but the update with a plus sign).
//!
//! ## References
//! - R. Grzeszczuk, D. Terzopoulos, G. Hinton, *NeuroAnimator: Fast neural network emulation
//!   and control of physics-based models*, SIGGRAPH 1998, §4.2.

use std::fmt::Debug;

/// A trajectory as the terms see it: the states s_0 … s_M (n each) and the controls
/// u_0 … u_{M−1} (m each), row after row.
#[derive(Debug, Clone, Copy)]
pub struct Trajectory<'a> {
    /// The M + 1 states.
    pub states: &'a [f64],
    /// The M controls.
    pub controls: &'a [f64],
    /// State dimension n.
    pub n: usize,
    /// Control dimension m.
    pub m: usize,
}

impl Trajectory<'_> {
    /// The final state s_M.
    pub fn last(&self) -> &[f64] {
        &self.states[self.states.len() - self.n..]
    }

    /// State s_i.
    pub fn state(&self, i: usize) -> &[f64] {
        &self.states[i * self.n..(i + 1) * self.n]
    }
}

/// One term of an objective over a trajectory of `steps` emulator steps.
pub trait Term: Debug + Send + Sync {
    /// Its value on trajectory `t`.
    fn value(&self, t: Trajectory<'_>) -> f64;
    /// Adds ∂term/∂states to `s_bar` and ∂term/∂controls to `u_bar` (the layouts of `t`).
    fn add_gradient(&self, t: Trajectory<'_>, s_bar: &mut [f64], u_bar: &mut [f64]);
    /// [`Term::add_gradient`], then returns the value.
    fn gradient(&self, t: Trajectory<'_>, s_bar: &mut [f64], u_bar: &mut [f64]) -> f64 {
        self.add_gradient(t, s_bar, u_bar);
        self.value(t)
    }
    /// Its Gauss–Newton curvature, for terms that are weighted sums of squares of states or
    /// controls (or linear); `None` (the default) for any other term, which rules out
    /// [`crate::control::bptt::StepRule::LevenbergMarquardt`].
    fn gauss_newton(&self) -> Option<GaussNewton> {
        None
    }
}

/// The Gauss–Newton curvature of a [`Term`]: its exact Hessian with respect to the states and
/// controls it reads (constant for these forms), which the chain rule through the dynamics'
/// Jacobians turns into the Gauss–Newton matrix over the knots.
#[derive(Debug, Clone, PartialEq)]
pub enum GaussNewton {
    /// Linear in the trajectory: no curvature.
    Zero,
    /// μ/2 Σ_i Σ_j h_j (u_ij − o_j)² over every control: Hessian diag(h) per step.
    Controls {
        /// h_j per actuator.
        diagonal: Vec<f64>,
    },
    /// μ/2 Σ_{i ∈ from..=to} Σ_k h_k (s_ik − r_k)²: Hessian diag(h) on each state in the
    /// window (indices clamped to the trajectory like [`StateWindow`]).
    States {
        /// First state index.
        from: usize,
        /// Last state index.
        to: usize,
        /// h_k per state variable.
        diagonal: Vec<f64>,
    },
}

/// Controller efficiency: μ/2 Σ_i Σ_j ((u_ij − offset_j)/scale_j)².
#[derive(Debug, Clone, PartialEq)]
pub struct ControlEffort {
    /// Weight μ_u.
    pub mu: f64,
    /// Control about which effort is measured, per actuator (e.g. zero torque, hover thrust).
    pub offset: Vec<f64>,
    /// Unit of each actuator (e.g. its limit), so actuators of different units compare.
    pub scale: Vec<f64>,
}

impl ControlEffort {
    /// μ/2 Σ |u_i|²: the plain effort term of eq. 12 for `m` actuators.
    pub fn plain(mu: f64, m: usize) -> Self {
        Self {
            mu,
            offset: vec![0.0; m],
            scale: vec![1.0; m],
        }
    }
}

impl Term for ControlEffort {
    fn value(&self, t: Trajectory<'_>) -> f64 {
        let m = t.m;
        let mut sum = 0.0;
        for u in t.controls.chunks_exact(m) {
            for j in 0..m {
                let d = (u[j] - self.offset[j]) / self.scale[j];
                sum += d * d;
            }
        }
        0.5 * self.mu * sum
    }

    fn add_gradient(&self, t: Trajectory<'_>, _s_bar: &mut [f64], u_bar: &mut [f64]) {
        let m = t.m;
        for (u, g) in t.controls.chunks_exact(m).zip(u_bar.chunks_exact_mut(m)) {
            for j in 0..m {
                let c = self.scale[j];
                g[j] += self.mu * (u[j] - self.offset[j]) / (c * c);
            }
        }
    }

    fn gauss_newton(&self) -> Option<GaussNewton> {
        let diagonal = self.scale.iter().map(|c| self.mu / (c * c)).collect();
        Some(GaussNewton::Controls { diagonal })
    }
}

/// Weighted squared distance of a state to a reference: Σ_k w_k (s_k − r_k)².
fn weighted_sq(s: &[f64], r: &[f64], w: &[f64]) -> f64 {
    s.iter()
        .zip(r)
        .zip(w)
        .map(|((a, b), w)| w * (a - b) * (a - b))
        .sum()
}

/// Adds the gradient of μ/2 Σ_k w_k (s_k − r_k)² to `s_bar`: s̄_k += μ w_k (s_k − r_k).
fn add_weighted_sq_gradient(mu: f64, s: &[f64], r: &[f64], w: &[f64], s_bar: &mut [f64]) {
    for (((g, a), b), w) in s_bar.iter_mut().zip(s).zip(r).zip(w) {
        *g += mu * w * (a - b);
    }
}

/// The final-state term: μ/2 Σ_k w_k (s_{M,k} − target_k)².
#[derive(Debug, Clone, PartialEq)]
pub struct FinalState {
    /// Weight μ_s.
    pub mu: f64,
    /// Desired final state s_d.
    pub target: Vec<f64>,
    /// Weight per state variable (0 ignores it).
    pub weights: Vec<f64>,
}

impl Term for FinalState {
    fn value(&self, t: Trajectory<'_>) -> f64 {
        0.5 * self.mu * weighted_sq(t.last(), &self.target, &self.weights)
    }

    fn add_gradient(&self, t: Trajectory<'_>, s_bar: &mut [f64], _u_bar: &mut [f64]) {
        let k0 = t.states.len() - t.n;
        let (target, weights) = (&self.target, &self.weights);
        add_weighted_sq_gradient(self.mu, t.last(), target, weights, &mut s_bar[k0..]);
    }

    fn gauss_newton(&self) -> Option<GaussNewton> {
        Some(GaussNewton::States {
            from: usize::MAX,
            to: usize::MAX,
            diagonal: self.weights.iter().map(|w| self.mu * w).collect(),
        })
    }
}

/// A trajectory term over the states s_i with `from <= i <= to` (clamped to the trajectory):
/// μ/2 Σ_i Σ_k w_k (s_{i,k} − reference_k)².
#[derive(Debug, Clone, PartialEq)]
pub struct StateWindow {
    /// Weight μ.
    pub mu: f64,
    /// First state index in the window (0 = the start state).
    pub from: usize,
    /// Last state index in the window (M = the final state).
    pub to: usize,
    /// Reference state.
    pub reference: Vec<f64>,
    /// Weight per state variable (0 ignores it).
    pub weights: Vec<f64>,
}

impl StateWindow {
    fn range(&self, states: &[f64], n: usize) -> std::ops::RangeInclusive<usize> {
        let last = states.len() / n - 1;
        self.from.min(last)..=self.to.min(last)
    }
}

impl Term for StateWindow {
    fn value(&self, t: Trajectory<'_>) -> f64 {
        let sum: f64 = self
            .range(t.states, t.n)
            .map(|i| weighted_sq(t.state(i), &self.reference, &self.weights))
            .sum();
        0.5 * self.mu * sum
    }

    fn add_gradient(&self, t: Trajectory<'_>, s_bar: &mut [f64], _u_bar: &mut [f64]) {
        let n = t.n;
        let (reference, weights) = (&self.reference, &self.weights);
        for i in self.range(t.states, n) {
            let bar = &mut s_bar[i * n..(i + 1) * n];
            add_weighted_sq_gradient(self.mu, t.state(i), reference, weights, bar);
        }
    }

    fn gauss_newton(&self) -> Option<GaussNewton> {
        Some(GaussNewton::States {
            from: self.from,
            to: self.to,
            diagonal: self.weights.iter().map(|w| self.mu * w).collect(),
        })
    }
}

/// Progress along a direction (e.g. distance swum forward, to be maximized, so it enters the
/// objective with a minus sign): −μ d · (p̄_M − p̄_0), where p̄ is the mean of the points whose
/// x, y, z sit at state indices `points[j]`, `points[j] + 1`, `points[j] + 2`.
#[derive(Debug, Clone, PartialEq)]
pub struct Progress {
    /// Weight μ (per metre).
    pub mu: f64,
    /// Direction d (the objective rewards motion along it; normally a unit vector).
    pub direction: [f64; 3],
    /// State index of the x coordinate of each point averaged.
    pub points: Vec<usize>,
}

impl Progress {
    fn along(&self, s: &[f64]) -> f64 {
        let k = self.points.len().max(1) as f64;
        self.points
            .iter()
            .map(|&i| (0..3).map(|a| self.direction[a] * s[i + a]).sum::<f64>())
            .sum::<f64>()
            / k
    }
}

impl Term for Progress {
    fn value(&self, t: Trajectory<'_>) -> f64 {
        -self.mu * (self.along(t.last()) - self.along(t.state(0)))
    }

    fn add_gradient(&self, t: Trajectory<'_>, s_bar: &mut [f64], _u_bar: &mut [f64]) {
        let k0 = t.states.len() - t.n;
        let c = self.mu / self.points.len().max(1) as f64;
        for &i in &self.points {
            for a in 0..3 {
                s_bar[k0 + i + a] -= c * self.direction[a];
                s_bar[i + a] += c * self.direction[a];
            }
        }
    }

    fn gauss_newton(&self) -> Option<GaussNewton> {
        Some(GaussNewton::Zero)
    }
}

/// A sum of terms.
#[derive(Debug, Default)]
pub struct Objective {
    /// The terms.
    pub terms: Vec<Box<dyn Term>>,
}

impl Objective {
    /// An objective of the given terms.
    pub fn new(terms: Vec<Box<dyn Term>>) -> Self {
        Self { terms }
    }

    /// Adds a term.
    pub fn with(mut self, term: impl Term + 'static) -> Self {
        self.terms.push(Box::new(term));
        self
    }

    /// J for a trajectory.
    pub fn value(&self, states: &[f64], controls: &[f64], n: usize, m: usize) -> f64 {
        let t = Trajectory {
            states,
            controls,
            n,
            m,
        };
        self.terms.iter().map(|term| term.value(t)).sum()
    }

    /// The Gauss–Newton curvature of every term, or `None` if a term has none.
    pub fn gauss_newton(&self) -> Option<Vec<GaussNewton>> {
        self.terms.iter().map(|t| t.gauss_newton()).collect()
    }

    /// J and its partial derivatives with respect to every state and control (`s_bar` and
    /// `u_bar` are overwritten).
    pub fn gradient(
        &self,
        states: &[f64],
        controls: &[f64],
        n: usize,
        m: usize,
        s_bar: &mut [f64],
        u_bar: &mut [f64],
    ) -> f64 {
        let t = Trajectory {
            states,
            controls,
            n,
            m,
        };
        s_bar.fill(0.0);
        u_bar.fill(0.0);
        self.terms
            .iter()
            .map(|term| term.gradient(t, s_bar, u_bar))
            .sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn traj<'a>(states: &'a [f64], controls: &'a [f64], n: usize, m: usize) -> Trajectory<'a> {
        Trajectory {
            states,
            controls,
            n,
            m,
        }
    }

    fn check_fd(term: &dyn Term) {
        let (n, m, steps) = (3, 2, 5);
        let states: Vec<f64> = (0..(steps + 1) * n)
            .map(|i| (i as f64 * 0.37).sin())
            .collect();
        let controls: Vec<f64> = (0..steps * m).map(|i| (i as f64 * 0.71).cos()).collect();
        let mut sb = vec![0.0; states.len()];
        let mut ub = vec![0.0; controls.len()];
        let v = term.gradient(traj(&states, &controls, n, m), &mut sb, &mut ub);
        assert!((v - term.value(traj(&states, &controls, n, m))).abs() < 1e-12);
        let h = 1e-6;
        for i in 0..states.len() {
            let (mut p, mut q) = (states.clone(), states.clone());
            p[i] += h;
            q[i] -= h;
            let fd = (term.value(traj(&p, &controls, n, m))
                - term.value(traj(&q, &controls, n, m)))
                / (2.0 * h);
            assert!((fd - sb[i]).abs() < 1e-6, "state {i}: {fd} vs {}", sb[i]);
        }
        for i in 0..controls.len() {
            let (mut p, mut q) = (controls.clone(), controls.clone());
            p[i] += h;
            q[i] -= h;
            let fd = (term.value(traj(&states, &p, n, m)) - term.value(traj(&states, &q, n, m)))
                / (2.0 * h);
            assert!((fd - ub[i]).abs() < 1e-6, "control {i}: {fd} vs {}", ub[i]);
        }
    }

    #[test]
    fn every_term_gradient_matches_finite_differences() {
        check_fd(&ControlEffort {
            mu: 0.7,
            offset: vec![0.2, -0.1],
            scale: vec![2.0, 0.5],
        });
        check_fd(&FinalState {
            mu: 1.3,
            target: vec![0.1, 0.2, -0.3],
            weights: vec![1.0, 0.0, 4.0],
        });
        check_fd(&StateWindow {
            mu: 0.9,
            from: 3,
            to: 99,
            reference: vec![0.0, 1.0, 0.0],
            weights: vec![0.5, 2.0, 1.0],
        });
        check_fd(&Progress {
            mu: 2.5,
            direction: [0.6, 0.0, -0.8],
            points: vec![0],
        });
        let all = Objective::default()
            .with(ControlEffort::plain(0.1, 2))
            .with(FinalState {
                mu: 1.0,
                target: vec![0.0; 3],
                weights: vec![1.0; 3],
            });
        let (n, m) = (3, 2);
        let states = vec![0.5; 4 * n];
        let controls = vec![1.0; 3 * m];
        let mut sb = vec![9.0; states.len()];
        let mut ub = vec![9.0; controls.len()];
        let v = all.gradient(&states, &controls, n, m, &mut sb, &mut ub);
        assert!((v - (0.05 * 6.0 + 0.5 * 0.75)).abs() < 1e-12);
        assert!(sb[..9].iter().all(|&g| g == 0.0));
        assert!(ub.iter().all(|&g| (g - 0.1).abs() < 1e-12));
    }
}
