//! # Grid dynamic programming for low-dimensional systems (LBC §5.2)
//!
//! A regular 2-D grid over state space with barycentric interpolation on the Kuhn
//! triangulation (each cell split into two triangles; a point is the convex combination of the
//! three vertices of its triangle).
//!
//! **Linearly-solvable backup** (Todorov 2006, 2009). The passive dynamics p(x′|x) are one
//! explicit-Euler step of the uncontrolled drift plus Gaussian noise in the controlled (velocity)
//! coordinate, discretized with the 3-point Gauss–Hermite rule and spread onto the grid
//! barycentrically. With per-step cost ℓ = q(x)·dt + λ·KL(π(·|x) ‖ p(·|x)), the finite-horizon
//! Bellman equation is linear in the reward z = exp(−v/λ):
//!
//! z_t(x) = exp(−q(x)·dt/λ) · Σ_{x′} p(x′|x) z_{t+1}(x′),  z_T = exp(−g/λ),
//!
//! and the optimal policy is π*(x′|x) = p(x′|x) z_{t+1}(x′) / Σ p z_{t+1}. Hence the solution
//! for terminal reward Σ w_i h_i is exactly Σ w_i z_i: linear Bellman combination.
//!
//! **Ordinary (nonlinear) backup** for comparison: deterministic dynamics, a discrete control
//! set, v_t(x) = min_u [(q(x) + ½u²)·dt + v_{t+1}(x + dt·f(x, u))] with v_{t+1} interpolated
//! barycentrically. Its value functions do not superpose.
//!
//! ## References
//! - E. Todorov, *Efficient computation of optimal actions*, PNAS 106 (2009).
//! - R. Munos, A. Moore, *Barycentric interpolators for continuous space and time
//!   reinforcement learning*, NIPS 1998.
//! - M. da Silva, F. Durand, J. Popović, *Linear Bellman Combination*, SIGGRAPH 2009, §5.2.

/// A regular grid over a box in 2-D state space; the first axis may be periodic (an angle).
#[derive(Debug, Clone, PartialEq)]
pub struct Grid2 {
    /// Lower corner.
    pub lo: [f64; 2],
    /// Upper corner (for a periodic axis, lo + period).
    pub hi: [f64; 2],
    /// Points per axis (periodic axis: the point at `hi` is the one at `lo`).
    pub n: [usize; 2],
    /// Whether axis 0 wraps around.
    pub periodic0: bool,
}

impl Grid2 {
    /// Number of grid points.
    pub fn len(&self) -> usize {
        self.n[0] * self.n[1]
    }

    /// Whether the grid has no points.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Spacing along each axis.
    pub fn step(&self) -> [f64; 2] {
        let d0 = if self.periodic0 {
            (self.hi[0] - self.lo[0]) / self.n[0] as f64
        } else {
            (self.hi[0] - self.lo[0]) / (self.n[0] - 1) as f64
        };
        [d0, (self.hi[1] - self.lo[1]) / (self.n[1] - 1) as f64]
    }

    /// Flat index of grid point (i, j) (axis 0 fastest).
    pub fn index(&self, i: usize, j: usize) -> usize {
        j * self.n[0] + i
    }

    /// Coordinates of a grid point.
    pub fn point(&self, idx: usize) -> [f64; 2] {
        let (i, j) = (idx % self.n[0], idx / self.n[0]);
        let h = self.step();
        [self.lo[0] + i as f64 * h[0], self.lo[1] + j as f64 * h[1]]
    }

    /// Barycentric interpolation weights of `p`: up to 3 `(index, weight)` pairs summing to 1.
    /// Points outside a non-periodic axis are clamped to the boundary.
    pub fn interpolate(&self, p: [f64; 2]) -> [(usize, f64); 3] {
        let h = self.step();
        let mut f = [(p[0] - self.lo[0]) / h[0], (p[1] - self.lo[1]) / h[1]];
        let mut base = [0usize; 2];
        for a in 0..2 {
            if a == 0 && self.periodic0 {
                let n = self.n[0] as f64;
                f[0] = f[0].rem_euclid(n);
                let b = f[0].floor().min(n - 1.0);
                base[0] = b as usize;
                f[0] -= b;
            } else {
                let max = (self.n[a] - 1) as f64;
                let c = f[a].clamp(0.0, max);
                let b = c.floor().min(max - 1.0).max(0.0);
                base[a] = b as usize;
                f[a] = c - b;
            }
        }
        let i1 = if self.periodic0 {
            (base[0] + 1) % self.n[0]
        } else {
            base[0] + 1
        };
        let (i0, j0, j1) = (base[0], base[1], base[1] + 1);
        let (fx, fy) = (f[0], f[1]);
        if fx >= fy {
            [
                (self.index(i0, j0), 1.0 - fx),
                (self.index(i1, j0), fx - fy),
                (self.index(i1, j1), fy),
            ]
        } else {
            [
                (self.index(i0, j0), 1.0 - fy),
                (self.index(i0, j1), fy - fx),
                (self.index(i1, j1), fx),
            ]
        }
    }

    /// Barycentric interpolation of grid values at `p`.
    pub fn sample(&self, values: &[f64], p: [f64; 2]) -> f64 {
        self.interpolate(p)
            .iter()
            .map(|&(i, w)| w * values[i])
            .sum()
    }
}

/// A sparse row-stochastic transition matrix (compressed rows).
#[derive(Debug, Clone, PartialEq)]
pub struct Transitions {
    /// Row start offsets (len = states + 1).
    pub offsets: Vec<usize>,
    /// Column indices.
    pub cols: Vec<usize>,
    /// Probabilities.
    pub probs: Vec<f64>,
}

impl Transitions {
    /// (P z)(x) for every x.
    pub fn apply(&self, z: &[f64], out: &mut [f64]) {
        for (s, o) in out.iter_mut().enumerate() {
            let r = self.offsets[s]..self.offsets[s + 1];
            *o = self.cols[r.clone()]
                .iter()
                .zip(&self.probs[r])
                .map(|(&c, &p)| p * z[c])
                .sum();
        }
    }

    /// The entries of row `s`.
    pub fn row(&self, s: usize) -> impl Iterator<Item = (usize, f64)> + '_ {
        let r = self.offsets[s]..self.offsets[s + 1];
        self.cols[r.clone()]
            .iter()
            .copied()
            .zip(self.probs[r].iter().copied())
    }
}

/// A 2-state second-order system ẋ0 = x1, ẋ1 = a(x) + u for the grid problems.
pub trait GridSystem: Sync {
    /// Passive acceleration a(x).
    fn accel(&self, x: [f64; 2]) -> f64;
    /// State cost rate q(x).
    fn state_cost(&self, _x: [f64; 2]) -> f64 {
        0.0
    }
}

/// Passive transitions: Euler step of the drift, then velocity noise σ√dt·ξ by 3-point
/// Gauss–Hermite (nodes 0, ±√3, weights 2/3, 1/6, 1/6), spread barycentrically.
pub fn passive_transitions(grid: &Grid2, sys: &dyn GridSystem, dt: f64, sigma: f64) -> Transitions {
    let nodes = [
        (0.0, 2.0 / 3.0),
        (3f64.sqrt(), 1.0 / 6.0),
        (-(3f64.sqrt()), 1.0 / 6.0),
    ];
    let mut offsets = Vec::with_capacity(grid.len() + 1);
    let mut cols = Vec::new();
    let mut probs = Vec::new();
    offsets.push(0);
    let mut row: Vec<(usize, f64)> = Vec::with_capacity(9);
    for s in 0..grid.len() {
        let x = grid.point(s);
        let mean = [x[0] + dt * x[1], x[1] + dt * sys.accel(x)];
        row.clear();
        for &(k, w) in &nodes {
            let p = [mean[0], mean[1] + k * sigma * dt.sqrt()];
            for (c, b) in grid.interpolate(p) {
                if b > 0.0 {
                    match row.iter_mut().find(|(cc, _)| *cc == c) {
                        Some(e) => e.1 += w * b,
                        None => row.push((c, w * b)),
                    }
                }
            }
        }
        row.sort_by_key(|e| e.0);
        for &(c, p) in &row {
            cols.push(c);
            probs.push(p);
        }
        offsets.push(cols.len());
    }
    Transitions {
        offsets,
        cols,
        probs,
    }
}

/// Rewards z_t for t = 0..=steps (`z[steps]` = terminal) of the linearly-solvable problem.
pub fn solve_linear(
    p: &Transitions,
    state_cost: &[f64],
    terminal_reward: &[f64],
    dt: f64,
    lambda: f64,
    steps: usize,
) -> Vec<Vec<f64>> {
    let n = terminal_reward.len();
    let decay: Vec<f64> = state_cost
        .iter()
        .map(|q| crate::portable::exp(-q * dt / lambda))
        .collect();
    let mut z = vec![vec![0.0; n]; steps + 1];
    z[steps].copy_from_slice(terminal_reward);
    for t in (0..steps).rev() {
        let (head, tail) = z.split_at_mut(t + 1);
        p.apply(&tail[0], &mut head[t]);
        for (zi, d) in head[t].iter_mut().zip(&decay) {
            *zi *= d;
        }
    }
    z
}

/// Expected velocity change per second under π(x′|x) ∝ p(x′|x) z(x′), minus that of the
/// passive dynamics: the mean control u(x) the policy applies.
pub fn mean_control(grid: &Grid2, p: &Transitions, z_next: &[f64], dt: f64, s: usize) -> f64 {
    let (mut num, mut den, mut passive) = (0.0, 0.0, 0.0);
    for (c, pr) in p.row(s) {
        let v = grid.point(c)[1];
        num += pr * z_next[c] * v;
        den += pr * z_next[c];
        passive += pr * v;
    }
    (num / den - passive) / dt
}

/// Value of a stochastic policy given as a mixture Σ_i β_i π_i with π_i(x′|x) ∝ p(x′|x)
/// z_i(x′) (fixed β: the naive blend), by backward policy evaluation with cost
/// q·dt + λ·KL(π ‖ p); `terminal` is the terminal cost.
// The arguments are the problem's named quantities (p, q, λ, z_i, β, …), as the paper writes them.
#[allow(clippy::too_many_arguments)]
pub fn evaluate_mixture(
    p: &Transitions,
    state_cost: &[f64],
    terminal: &[f64],
    components: &[&[Vec<f64>]],
    beta: &[f64],
    dt: f64,
    lambda: f64,
    steps: usize,
) -> Vec<Vec<f64>> {
    let n = terminal.len();
    let mut v = vec![vec![0.0; n]; steps + 1];
    v[steps].copy_from_slice(terminal);
    let mut probs: Vec<(usize, f64)> = Vec::with_capacity(16);
    for t in (0..steps).rev() {
        let (head, tail) = v.split_at_mut(t + 1);
        let next = &tail[0];
        for s in 0..n {
            probs.clear();
            for (c, pr) in p.row(s) {
                probs.push((c, pr));
            }
            // Mixture probabilities π(x′|x) = Σ β_i p z_i(x′) / (P z_i)(x).
            let mut pi = [0.0f64; 64];
            assert!(probs.len() <= 64, "transition rows are short");
            for (i, zi) in components.iter().enumerate() {
                let zn = &zi[t + 1];
                let norm: f64 = probs.iter().map(|&(c, pr)| pr * zn[c]).sum();
                for (k, &(c, pr)) in probs.iter().enumerate() {
                    pi[k] += beta[i] * pr * zn[c] / norm;
                }
            }
            let mut cost = state_cost[s] * dt;
            for (k, &(c, pr)) in probs.iter().enumerate() {
                if pi[k] > 0.0 {
                    cost += lambda * pi[k] * crate::portable::ln(pi[k] / pr) + pi[k] * next[c];
                }
            }
            head[t][s] = cost;
        }
    }
    v
}

/// Values v_t for t = 0..=steps of the deterministic problem with control set `controls`,
/// by the ordinary Bellman backup; returns (values, greedy controls per step).
pub fn solve_nonlinear(
    grid: &Grid2,
    sys: &dyn GridSystem,
    terminal: &[f64],
    controls: &[f64],
    dt: f64,
    steps: usize,
) -> (Vec<Vec<f64>>, Vec<Vec<f64>>) {
    use rayon::prelude::*;
    let n = grid.len();
    let mut v = vec![vec![0.0; n]; steps + 1];
    let mut policy = vec![vec![0.0; n]; steps];
    v[steps].copy_from_slice(terminal);
    for t in (0..steps).rev() {
        let (head, tail) = v.split_at_mut(t + 1);
        let next = &tail[0];
        head[t]
            .par_iter_mut()
            .zip(policy[t].par_iter_mut())
            .enumerate()
            .for_each(|(s, (vo, uo))| {
                let x = grid.point(s);
                let a = sys.accel(x);
                let q = sys.state_cost(x);
                let mut best = (f64::INFINITY, 0.0);
                for &u in controls {
                    let xn = [x[0] + dt * x[1], x[1] + dt * (a + u)];
                    let c = (q + 0.5 * u * u) * dt + grid.sample(next, xn);
                    if c < best.0 {
                        best = (c, u);
                    }
                }
                *vo = best.0;
                *uo = best.1;
            });
    }
    (v, policy)
}

#[cfg(test)]
mod tests {
    use super::*;

    struct Pendulum;
    impl GridSystem for Pendulum {
        fn accel(&self, x: [f64; 2]) -> f64 {
            -9.81 * x[0].sin() - 0.1 * x[1]
        }
    }

    fn grid() -> Grid2 {
        Grid2 {
            lo: [-std::f64::consts::PI, -6.0],
            hi: [std::f64::consts::PI, 6.0],
            n: [40, 41],
            periodic0: true,
        }
    }

    #[test]
    fn barycentric_weights_reproduce_linear_functions() {
        let g = Grid2 {
            lo: [0.0, 0.0],
            hi: [1.0, 2.0],
            n: [5, 9],
            periodic0: false,
        };
        let vals: Vec<f64> = (0..g.len())
            .map(|s| {
                let p = g.point(s);
                2.0 * p[0] - 3.0 * p[1] + 1.0
            })
            .collect();
        for p in [[0.13, 0.77], [0.9, 1.99], [0.5, 0.5], [0.0, 2.0]] {
            let w = g.interpolate(p);
            assert!((w.iter().map(|e| e.1).sum::<f64>() - 1.0).abs() < 1e-14);
            assert!(w.iter().all(|e| e.1 >= -1e-15));
            assert!((g.sample(&vals, p) - (2.0 * p[0] - 3.0 * p[1] + 1.0)).abs() < 1e-12);
        }
    }

    #[test]
    fn transitions_are_stochastic() {
        let g = grid();
        let p = passive_transitions(&g, &Pendulum, 0.02, 1.0);
        for s in 0..g.len() {
            let sum: f64 = p.row(s).map(|e| e.1).sum();
            assert!((sum - 1.0).abs() < 1e-12);
            assert!(p.row(s).all(|e| e.1 > 0.0));
        }
    }

    #[test]
    fn z_superposition_holds_to_precision() {
        let g = grid();
        let p = passive_transitions(&g, &Pendulum, 0.02, 1.0);
        let q = vec![0.0; g.len()];
        let h = |c: f64| -> Vec<f64> {
            (0..g.len())
                .map(|s| {
                    let x = g.point(s);
                    let d = (x[0] - c + std::f64::consts::PI)
                        .rem_euclid(2.0 * std::f64::consts::PI)
                        - std::f64::consts::PI;
                    (-(2.0 * d * d + 0.2 * x[1] * x[1])).exp()
                })
                .collect()
        };
        let (h1, h2) = (h(-1.0), h(1.0));
        let w = [0.7, 1.3];
        let hc: Vec<f64> = h1
            .iter()
            .zip(&h2)
            .map(|(a, b)| w[0] * a + w[1] * b)
            .collect();
        let z1 = solve_linear(&p, &q, &h1, 0.02, 1.0, 50);
        let z2 = solve_linear(&p, &q, &h2, 0.02, 1.0, 50);
        let zc = solve_linear(&p, &q, &hc, 0.02, 1.0, 50);
        let mut worst: f64 = 0.0;
        for s in 0..g.len() {
            let comb = w[0] * z1[0][s] + w[1] * z2[0][s];
            worst = worst.max(((-comb.ln()) - (-zc[0][s].ln())).abs());
        }
        assert!(worst < 1e-10, "{worst}");
    }

    #[test]
    fn evaluating_the_optimal_policy_gives_the_optimal_value() {
        let g = grid();
        let p = passive_transitions(&g, &Pendulum, 0.02, 1.0);
        let q: Vec<f64> = (0..g.len()).map(|s| 0.1 * g.point(s)[1].powi(2)).collect();
        let term: Vec<f64> = (0..g.len())
            .map(|s| (g.point(s)[0] - 0.5).powi(2))
            .collect();
        let h: Vec<f64> = term.iter().map(|v| (-v).exp()).collect();
        let z = solve_linear(&p, &q, &h, 0.02, 1.0, 30);
        let v = evaluate_mixture(&p, &q, &term, &[z.as_slice()], &[1.0], 0.02, 1.0, 30);
        for s in 0..g.len() {
            assert!(
                (v[0][s] + z[0][s].ln()).abs() < 1e-9,
                "{} vs {}",
                v[0][s],
                -z[0][s].ln()
            );
        }
    }

    #[test]
    fn nonlinear_backup_prefers_cheap_controls() {
        let g = grid();
        let term: Vec<f64> = (0..g.len())
            .map(|s| {
                let x = g.point(s);
                x[0] * x[0] + x[1] * x[1]
            })
            .collect();
        let (v, pol) = solve_nonlinear(&g, &Pendulum, &term, &[-2.0, 0.0, 2.0], 0.02, 5);
        // Hanging at rest at the target costs nothing and needs no control.
        let s = g.index(20, 20);
        assert!(v[0][s].abs() < 1e-9 && pol[0][s] == 0.0);
        assert!(v[0].iter().all(|x| x.is_finite()));
    }
}
