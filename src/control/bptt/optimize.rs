//! The descent loop ([`learn`], [`learn_until`], [`learn_with`]): fixed, re-estimated,
//! line-searched or Levenberg–Marquardt steps on the normalized knots, with the trace and the
//! best-so-far iterate ([`Learned`]).

use super::{dot, norm, Bptt, Descent, DescentState, Schedule, StepRule};
use crate::control::objective::GaussNewton;
use crate::physics::differentiable::DifferentiableStep;

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
    let Damping {
        lm,
        curvature,
        mut hmat,
        mut mu,
        mut nu,
    } = damping(bptt, schedule, d);
    if lm {
        taken_scale = mu;
    }
    for l in 0..=iterations {
        lambda = reestimated(bptt, &v, schedule, l, lambda);
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
        carry_step(&mut state, &v, &trial, d);
    }
    finish(bptt, v, trace, best_iteration, best_knots)
}

/// Levenberg–Marquardt's state: whether the schedule uses it, the terms' curvatures, the
/// Gauss–Newton matrix (d × d), the damping μ and its growth ν.
struct Damping {
    lm: bool,
    curvature: Vec<GaussNewton>,
    hmat: Vec<f64>,
    mu: f64,
    nu: f64,
}

/// Levenberg–Marquardt's setup for `d` knots: the terms' curvatures (an objective without one
/// gets none, and the damping alone scales the step), the Gauss–Newton matrix, the damping μ
/// and its growth ν; empty, with μ = 0, under other step rules.
fn damping<D: DifferentiableStep>(bptt: &Bptt<'_, D>, schedule: &Schedule, d: usize) -> Damping {
    let lm = matches!(schedule.rule, StepRule::LevenbergMarquardt { .. });
    let curvature = if lm {
        bptt.objective().gauss_newton().unwrap_or_default()
    } else {
        Vec::new()
    };
    let hmat = vec![0.0; if lm { d * d } else { 0 }];
    let (mu, nu) = match schedule.rule {
        StepRule::LevenbergMarquardt { damping, .. } => (damping, 2.0),
        _ => (0.0, 2.0),
    };
    Damping {
        lm,
        curvature,
        hmat,
        mu,
        nu,
    }
}

/// The step scale of iteration `l`: re-estimated from the curvature at `v` every `every`
/// iterations under [`StepRule::Reestimate`] (where the estimate is finite and positive),
/// else `lambda`.
// `%` as the loop had it (`is_multiple_of` would differ for `every` = 0).
#[allow(clippy::manual_is_multiple_of)]
#[inline]
fn reestimated<D: DifferentiableStep>(
    bptt: &mut Bptt<'_, D>,
    v: &[f64],
    schedule: &Schedule,
    l: usize,
    lambda: f64,
) -> f64 {
    if let StepRule::Reestimate { every } = schedule.rule {
        if l > 0 && l % every == 0 {
            let est = bptt.curvature(v, schedule.curvature_iterations.max(1));
            if est.is_finite() && est > 0.0 {
                return est;
            }
        }
    }
    lambda
}

/// The momentum state carries the step actually taken (after projection) to `v` from
/// `trial`, the previous iterate; in place, no allocation after the first iteration.
#[inline]
fn carry_step(state: &mut DescentState, v: &[f64], trial: &[f64], d: usize) {
    state.delta.resize(d, 0.0);
    for (dl, (a, b)) in state.delta.iter_mut().zip(v.iter().zip(trial)) {
        *dl = a - b;
    }
}

/// The last iterate `v` rolled out once more, so the controls and states are its own.
fn finish<D: DifferentiableStep>(
    bptt: &mut Bptt<'_, D>,
    v: Vec<f64>,
    trace: Vec<IterationTrace>,
    best_iteration: usize,
    best_knots: Vec<f64>,
) -> Learned {
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

#[cfg(test)]
mod tests {
    use super::super::fixtures::{linear, linear_problem};
    use super::*;
    use crate::control::bptt::{Bounds, Knots, LinearStep};
    use crate::control::objective::{ControlEffort, FinalState, Objective};

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
        let bounds = Bounds::new(vec![-3.0, -3.0], vec![3.0, 3.0]);
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
        let wide = Bounds::new(vec![-50.0, -50.0], vec![50.0, 50.0]);
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
        let tight = Bounds::new(vec![-0.5, -0.3], vec![0.5, 0.3]);
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
}
