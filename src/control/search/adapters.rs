//! Control problems as search problems, on either substrate.
//!
//! Both adapters search the normalized knots v of a [`Bptt`] problem (its box: [−1, 1] for a
//! bounded actuator, its raw bounds otherwise) and score them with the same [`Objective`]:
//!
//! - [`BpttProblem`]: J(v) is the emulator rollout [`Bptt::rollout`]; the gradient is
//!   [`Bptt::gradient`]. [`bptt_search`] runs plain or momentum descent on it under a
//!   [`Budget`].
//! - [`ReplayProblem`]: the same knots expanded to per-step controls, each held for `substeps`
//!   physical steps of `physical_dt` on a simulator (as [`crate::control::bptt::replay`]); a
//!   state map takes every simulator state at an emulator step time to the objective's state
//!   space (identity when they agree; for the dolphin, the 138-dim mass state to the 78-dim
//!   segment frames), and J is the objective of that trajectory.
//!
//! Both keep a pool of per-thread workspaces (a `Bptt` with its scratch, or a simulator with
//! its buffers) behind a mutex, so `evaluate(&self)` runs in parallel without allocating once
//! the pool is warm.

use super::{
    start_point, Budget, SearchBox, SearchProblem, SearchResult, Spent, StopReason, TraceRow,
};
use crate::control::bptt::{
    learn_until, Bounds, Bptt, Descent, DifferentiableStep, IterationTrace, Knots, Learned,
};
use crate::control::objective::Objective;
use crate::control::ControlError;
use crate::physics::Dynamics;
use std::sync::Mutex;
use std::time::Instant;

/// The search box of normalized knots: [−1, 1] for a bounded actuator, its raw bounds for one
/// unbounded on a side (as [`Bounds::project`]).
fn knot_box(knots: Knots, bounds: &Bounds) -> SearchBox {
    let m = knots.m;
    // The box of each normalized knot value: [-1, 1] for a bounded actuator of unit gain,
    // scaled by its gain otherwise (the ends `Bounds::project` clamps to).
    let (low, high) = (0..knots.len())
        .map(|i| {
            let j = i % m;
            (
                bounds.project(j, f64::NEG_INFINITY),
                bounds.project(j, f64::INFINITY),
            )
        })
        .unzip();
    SearchBox { low, high }
}

/// Takes a workspace from a pool (or makes one), runs `f` on it and returns it to the pool.
fn with_pooled<W, R>(
    pool: &Mutex<Vec<W>>,
    make: impl FnOnce() -> W,
    f: impl FnOnce(&mut W) -> R,
) -> R {
    let taken = pool.lock().unwrap_or_else(|e| e.into_inner()).pop();
    let mut w = taken.unwrap_or_else(make);
    let r = f(&mut w);
    pool.lock().unwrap_or_else(|e| e.into_inner()).push(w);
    r
}

/// A [`Bptt`] problem (emulator rollout + objective over normalized knots) as a search
/// problem with a gradient.
pub struct BpttProblem<'a, D: DifferentiableStep> {
    dynamics: &'a D,
    objective: &'a Objective,
    knots: Knots,
    bounds: Bounds,
    x0: Vec<f64>,
    search_box: SearchBox,
    pool: Mutex<Vec<Bptt<'a, D>>>,
}

impl<'a, D> BpttProblem<'a, D>
where
    D: DifferentiableStep + Sync,
    D::Scratch: Send,
{
    /// The problem of `bptt` (same step, objective, knots, bounds and start state); it keeps
    /// its own workspaces.
    pub fn new(bptt: &Bptt<'a, D>) -> Self {
        Self {
            dynamics: bptt.dynamics(),
            objective: bptt.objective(),
            knots: bptt.knots(),
            bounds: bptt.bounds().clone(),
            x0: bptt.start_state().to_vec(),
            search_box: knot_box(bptt.knots(), bptt.bounds()),
            pool: Mutex::new(Vec::new()),
        }
    }

    /// Runs `f` on a workspace `Bptt` of this problem (taken from the pool).
    pub fn with_bptt<R>(&self, f: impl FnOnce(&mut Bptt<'a, D>) -> R) -> R {
        let make = || {
            Bptt::new(
                self.dynamics,
                self.objective,
                self.knots,
                self.bounds.clone(),
                &self.x0,
            )
            .expect("validated when the original Bptt was built")
        };
        with_pooled(&self.pool, make, f)
    }

    /// The BPTT step scale λ ([`Bptt::curvature`] at `v` with `iterations` power iterations)
    /// and what estimating it cost, to charge to [`bptt_search`].
    pub fn curvature(&self, v: &[f64], iterations: usize) -> (f64, Spent) {
        self.with_bptt(|b| {
            let (f0, b0, t0) = (b.forward_passes(), b.backward_passes(), Instant::now());
            let lambda = b.curvature(v, iterations);
            let spent = Spent {
                evaluations: b.forward_passes() - f0,
                gradients: b.backward_passes() - b0,
                seconds: t0.elapsed().as_secs_f64(),
            };
            (lambda, spent)
        })
    }
}

impl<D> SearchProblem for BpttProblem<'_, D>
where
    D: DifferentiableStep + Sync,
    D::Scratch: Send,
{
    fn search_box(&self) -> &SearchBox {
        &self.search_box
    }

    fn evaluate(&self, v: &[f64]) -> f64 {
        self.with_bptt(|b| b.rollout(v))
    }

    fn gradient(&self, v: &[f64], grad: &mut [f64]) -> Option<f64> {
        Some(self.with_bptt(|b| b.gradient(v, grad)))
    }
}

/// The trace row of BPTT iteration `e` (best so far `best`), after set-up costs `setup`:
/// iteration l has spent l + 1 gradients, each one evaluation and one backward pass.
fn bptt_row(e: &IterationTrace, best: f64, setup: Spent) -> TraceRow {
    TraceRow {
        iteration: e.iteration,
        evaluations: setup.evaluations + e.iteration + 1,
        gradients: setup.gradients + e.iteration + 1,
        seconds: setup.seconds + e.seconds,
        best,
        current: e.objective,
    }
}

/// The search trace of a [`learn`](crate::control::bptt::learn) trace, after set-up costs
/// `setup` (e.g. the step-scale estimate of [`BpttProblem::curvature`]). The final rollout
/// `learn` runs to return the states re-evaluates the last iterate and is not counted.
pub fn trace_from_bptt(trace: &[IterationTrace], setup: Spent) -> Vec<TraceRow> {
    let mut best = f64::INFINITY;
    trace
        .iter()
        .map(|e| {
            if e.objective < best {
                best = e.objective;
            }
            bptt_row(e, best, setup)
        })
        .collect()
}

/// BPTT descent ([`learn_until`]) from normalized knots `v0` with step scale λ = `scale`
/// within `budget`, the first row charged `setup`. Returns the search result (best iterate)
/// and what `learn` returns (final iterate, its controls and emulated states). Stops with
/// [`StopReason::NonFinite`] when J becomes non-finite.
pub fn bptt_search<D>(
    problem: &BpttProblem<'_, D>,
    v0: &[f64],
    descent: Descent,
    scale: f64,
    budget: &Budget,
    setup: Spent,
) -> Result<(SearchResult, Learned), ControlError>
where
    D: DifferentiableStep + Sync,
    D::Scratch: Send,
{
    budget.validate()?;
    let v = start_point(&problem.search_box, v0)?;
    let mut best = v.clone();
    let mut best_value = f64::INFINITY;
    let mut trace = Vec::new();
    let mut stop = None;
    let iterations = budget.max_iterations.unwrap_or(usize::MAX);
    let learned = problem.with_bptt(|b| {
        learn_until(b, &v, descent, scale, iterations, &mut |e, v| {
            if e.objective.is_finite() && e.objective < best_value {
                best_value = e.objective;
                best.copy_from_slice(v);
            }
            let row = bptt_row(e, best_value, setup);
            trace.push(row);
            stop = budget.exhausted(&row);
            stop.is_some()
        })
    });
    let stop = match stop {
        Some(reason) => reason,
        None if !learned.final_objective().is_finite() => StopReason::NonFinite,
        None => StopReason::Iterations,
    };
    let result = SearchResult {
        best,
        best_value,
        trace,
        evaluations: Vec::new(),
        stop,
    };
    Ok((result, learned))
}

/// Maps a simulator state to the objective's state space (writes the second argument).
pub type StateMap<'a> = Box<dyn Fn(&[f64], &mut [f64]) + Send + Sync + 'a>;

/// A workspace of [`ReplayProblem`]: a simulator and the trajectory buffers.
struct ReplayScratch {
    sim: Box<dyn Dynamics>,
    x: Vec<f64>,
    knot_u: Vec<f64>,
    controls: Vec<f64>,
    states: Vec<f64>,
}

/// A simulated rollout of [`ReplayProblem::rollout`].
#[derive(Debug, Clone, PartialEq)]
pub struct ReplayRollout {
    /// J of the trajectory.
    pub objective: f64,
    /// Mapped states at the emulator step times s_0 … s_M (objective state space, n each).
    pub states: Vec<f64>,
    /// Per-step controls u_0 … u_{M−1} (control units, m each).
    pub controls: Vec<f64>,
    /// The simulator's final state (its own state space).
    pub final_state: Vec<f64>,
}

/// The knots of a [`Bptt`] problem replayed on a physical simulator and scored with the same
/// objective; a search problem without a gradient.
pub struct ReplayProblem<'a> {
    simulator: Box<dyn Fn() -> Box<dyn Dynamics> + Send + Sync + 'a>,
    objective: &'a Objective,
    knots: Knots,
    bounds: Bounds,
    x0: Vec<f64>,
    physical_dt: f64,
    substeps: usize,
    n: usize,
    state_map: StateMap<'a>,
    search_box: SearchBox,
    pool: Mutex<Vec<ReplayScratch>>,
}

impl<'a> ReplayProblem<'a> {
    /// The objective, knots and bounds of `bptt` replayed on simulators made by `simulator`
    /// from its state `sim_x0`, each control held for `substeps` steps of `physical_dt` s;
    /// `state_map` takes a simulator state to the state space of `bptt`'s step.
    pub fn new<D: DifferentiableStep>(
        bptt: &Bptt<'a, D>,
        simulator: impl Fn() -> Box<dyn Dynamics> + Send + Sync + 'a,
        sim_x0: &[f64],
        physical_dt: f64,
        substeps: usize,
        state_map: StateMap<'a>,
    ) -> Result<Self, ControlError> {
        if !(physical_dt.is_finite() && physical_dt > 0.0) {
            return Err(ControlError::InvalidTimeStep(physical_dt));
        }
        if substeps == 0 {
            return Err(ControlError::InvalidSetting {
                what: "substeps",
                value: 0.0,
            });
        }
        let knots = bptt.knots();
        let sim = simulator();
        let dims = [
            ("simulator controls", sim.control_dim(), knots.m),
            ("simulator start state", sim_x0.len(), sim.state_dim()),
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
        let n = bptt.dynamics().state_dim();
        let problem = Self {
            simulator: Box::new(simulator),
            objective: bptt.objective(),
            knots,
            bounds: bptt.bounds().clone(),
            x0: sim_x0.to_vec(),
            physical_dt,
            substeps,
            n,
            state_map,
            search_box: knot_box(knots, bptt.bounds()),
            pool: Mutex::new(Vec::new()),
        };
        let first = problem.scratch_with(sim);
        problem
            .pool
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .push(first);
        Ok(problem)
    }

    fn scratch_with(&self, sim: Box<dyn Dynamics>) -> ReplayScratch {
        let (steps, m) = (self.knots.steps, self.knots.m);
        ReplayScratch {
            sim,
            x: self.x0.clone(),
            knot_u: vec![0.0; self.knots.len()],
            controls: vec![0.0; steps * m],
            states: vec![0.0; (steps + 1) * self.n],
        }
    }

    /// Simulates normalized knots `v` into `w`'s buffers and returns J.
    fn simulate(&self, v: &[f64], w: &mut ReplayScratch) -> f64 {
        let (n, m) = (self.n, self.knots.m);
        self.bounds.denormalize(v, &mut w.knot_u);
        self.knots.expand(&w.knot_u, &mut w.controls);
        w.x.copy_from_slice(&self.x0);
        (self.state_map)(&w.x, &mut w.states[..n]);
        for i in 0..self.knots.steps {
            let u = &w.controls[i * m..(i + 1) * m];
            for _ in 0..self.substeps {
                w.sim.step(&mut w.x, u, self.physical_dt);
            }
            (self.state_map)(&w.x, &mut w.states[(i + 1) * n..(i + 2) * n]);
        }
        self.objective.value(&w.states, &w.controls, n, m)
    }

    fn with_scratch<R>(&self, f: impl FnOnce(&mut ReplayScratch) -> R) -> R {
        with_pooled(&self.pool, || self.scratch_with((self.simulator)()), f)
    }

    /// The simulated trajectory of normalized knots `v` and its objective.
    pub fn rollout(&self, v: &[f64]) -> ReplayRollout {
        self.with_scratch(|w| {
            let objective = self.simulate(v, w);
            ReplayRollout {
                objective,
                states: w.states.clone(),
                controls: w.controls.clone(),
                final_state: w.x.clone(),
            }
        })
    }
}

impl SearchProblem for ReplayProblem<'_> {
    fn search_box(&self) -> &SearchBox {
        &self.search_box
    }

    fn evaluate(&self, v: &[f64]) -> f64 {
        self.with_scratch(|w| self.simulate(v, w))
    }
}

#[cfg(test)]
mod tests {
    use super::super::{anneal, hill_climb, time_to_target, AnnealingConfig, ClimbConfig};
    use super::*;
    use crate::control::bptt::fixtures::{lander_emulator, linear};
    use crate::control::bptt::{learn, replay};
    use crate::control::objective::{ControlEffort, FinalState};
    use crate::emulator::catalog::NetModel;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn objective() -> Objective {
        Objective::default()
            .with(ControlEffort::plain(0.05, 2))
            .with(FinalState {
                mu: 1.0,
                target: vec![1.0, -0.5, 0.5],
                weights: vec![1.0, 2.0, 1.0],
            })
    }

    fn knots() -> Knots {
        Knots {
            steps: 8,
            per_actuator: 4,
            m: 2,
        }
    }

    fn random_points(d: usize, k: usize, seed: u64) -> Vec<Vec<f64>> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        (0..k)
            .map(|_| (0..d).map(|_| rng.random_range(-1.5..1.5)).collect())
            .collect()
    }

    #[test]
    fn bptt_problem_is_the_bptt_rollout_and_gradient() {
        let (sys, obj) = (linear(), objective());
        // One bounded actuator, one unbounded: box [−1, 1] and (−∞, ∞).
        let bounds = Bounds::new(vec![-1.0, f64::NEG_INFINITY], vec![3.0, f64::INFINITY]);
        let mut b = Bptt::new(&sys, &obj, knots(), bounds, &[0.2, -0.1, 0.3]).unwrap();
        let p = BpttProblem::new(&b);
        assert_eq!(p.dim(), 8);
        assert_eq!(p.search_box().low[..2], [-1.0, f64::NEG_INFINITY]);
        let mut g = vec![0.0; 8];
        let mut h = vec![0.0; 8];
        for v in random_points(8, 5, 1) {
            let mut projected = v.clone();
            p.search_box().project(&mut projected);
            let mut by_bptt = v.clone();
            b.project(&mut by_bptt);
            assert_eq!(projected, by_bptt);
            assert_eq!(p.evaluate(&v).to_bits(), b.rollout(&v).to_bits());
            let j = p.gradient(&v, &mut g).unwrap();
            assert_eq!(j, b.gradient(&v, &mut h));
            assert_eq!(g, h);
        }
    }

    #[test]
    fn replay_problem_matches_the_bptt_rollout_on_the_same_system_and_maps_states() {
        let (sys, obj) = (linear(), objective());
        let bounds = Bounds::new(vec![-1.0, -2.0], vec![1.0, 0.5]);
        let x0 = [0.2, -0.1, 0.3];
        let mut b = Bptt::new(&sys, &obj, knots(), bounds, &x0).unwrap();
        let identity: StateMap = Box::new(|x, s| s.copy_from_slice(x));
        let same = ReplayProblem::new(&b, || Box::new(linear()), &x0, 0.1, 1, identity).unwrap();
        // Two physical steps per emulator step, and a state map s = 2 x.
        let doubled: StateMap = Box::new(|x, s| {
            for (s, x) in s.iter_mut().zip(x) {
                *s = 2.0 * x;
            }
        });
        let mapped = ReplayProblem::new(&b, || Box::new(linear()), &x0, 0.1, 2, doubled).unwrap();
        assert_eq!(same.search_box(), BpttProblem::new(&b).search_box());
        for v in random_points(8, 4, 2) {
            assert_eq!(same.evaluate(&v).to_bits(), b.rollout(&v).to_bits());
            let r = same.rollout(&v);
            assert_eq!(r.states, b.states());
            assert_eq!(r.controls, b.controls());
            // Reference: replay, then map and score.
            let rep = replay(&mut linear(), &x0, b.controls(), 0.1, 2, &[0.0; 3]);
            let states: Vec<f64> = rep.states.iter().map(|x| 2.0 * x).collect();
            let j = obj.value(&states, b.controls(), 3, 2);
            assert_eq!(mapped.evaluate(&v).to_bits(), j.to_bits());
            assert_eq!(mapped.rollout(&v).final_state, rep.states[24..]);
        }
        assert!(matches!(
            ReplayProblem::new(
                &b,
                || Box::new(linear()),
                &x0[..2],
                0.1,
                1,
                Box::new(|x, s| s.copy_from_slice(x))
            ),
            Err(ControlError::DimensionMismatch { .. })
        ));
        assert!(ReplayProblem::new(
            &b,
            || Box::new(linear()),
            &x0,
            0.0,
            1,
            Box::new(|x, s| s.copy_from_slice(x))
        )
        .is_err());
    }

    #[test]
    fn searches_run_on_an_emulator_problem_and_bptt_search_traces_learn() {
        let (e, obj, x0) = lander_emulator();
        let m = NetModel::Lander.control_dim();
        let knots = Knots {
            steps: 6,
            per_actuator: 3,
            m,
        };
        let bounds = Bounds::new(vec![-0.5; m], vec![0.5; m]);
        let mut b = Bptt::new(&e, &obj, knots, bounds, &x0).unwrap();
        let p = BpttProblem::new(&b);
        let v0 = vec![0.0; p.dim()];
        for v in random_points(p.dim(), 3, 4) {
            assert_eq!(p.evaluate(&v).to_bits(), b.rollout(&v).to_bits());
        }
        // BPTT under a budget is learn, traced.
        let (lambda, spent) = p.curvature(&v0, 5);
        assert!(lambda > 0.0);
        assert_eq!((spent.evaluations, spent.gradients), (11, 11));
        let descent = Descent::Momentum {
            eta: 1.0,
            alpha: 0.5,
        };
        let reference = learn(&mut b, &v0, descent, lambda, 20);
        let (r, learned) =
            bptt_search(&p, &v0, descent, lambda, &Budget::iterations(20), spent).unwrap();
        assert_eq!(learned.knots, reference.knots);
        assert_eq!(r.stop, StopReason::Iterations);
        let rows = trace_from_bptt(&reference.trace, spent);
        assert_eq!(r.trace.len(), 21);
        for (a, b) in r.trace.iter().zip(&rows) {
            assert_eq!(
                (a.iteration, a.evaluations, a.gradients),
                (b.iteration, b.evaluations, b.gradients)
            );
            assert_eq!((a.best, a.current), (b.best, b.current));
        }
        assert_eq!(r.trace[0].evaluations, 12);
        assert_eq!(r.trace[20].gradients, 11 + 21);
        assert_eq!(p.evaluate(&r.best), r.best_value);
        // It learns: the random-weight fixture's landscape is shallow, so only a decrease.
        assert!(
            r.best_value < r.trace[0].current,
            "{} vs {}",
            r.best_value,
            r.trace[0].current
        );
        // An evaluation budget stops BPTT as it does the others.
        let (short, _) =
            bptt_search(&p, &v0, descent, lambda, &Budget::evaluations(15), spent).unwrap();
        assert_eq!(short.stop, StopReason::Evaluations);
        assert_eq!(short.trace.last().unwrap().evaluations, 15);
        // Gradient-free searches on the same problem, in parallel: same on 1 and 2 threads.
        let climb = |threads| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap()
                .install(|| {
                    hill_climb(&p, &v0, &ClimbConfig::default(), 5, &Budget::iterations(30))
                        .unwrap()
                })
        };
        let (c1, c2) = (climb(1), climb(2));
        assert_eq!(c1.best, c2.best);
        assert!(c1.best_value < c1.trace[0].best);
        let sa = anneal(
            &p,
            &v0,
            &AnnealingConfig::default(),
            5,
            &Budget::evaluations(200),
        )
        .unwrap();
        assert!(sa.best_value < sa.trace[0].current);
        // Time to BPTT's final objective, for the gradient-free search.
        let target = r.best_value;
        let reached = time_to_target(&r.trace, target).unwrap();
        assert!(reached.iteration <= 20 && reached.evaluations == 12 + reached.iteration);
    }
}
