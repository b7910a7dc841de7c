//! `x_lbc_emulator` (beyond the papers): linear Bellman combination (da Silva et al. 2009) of
//! controllers learned by backpropagation through time through a NeuroAnimator emulator
//! (Grzeszczuk et al. 1998).
//!
//! The lunar lander (N50 catalog net, the one `na_fig13_control` uses) lands softly from the
//! Fig. 13 start at two targets that differ only along one axis (`axis`, x by default) at
//! `components[0]` and `components[1]`. Each is learned by BPTT with Levenberg–Marquardt
//! steps through the emulator (the Fig. 13 objective: μ_u/2 Σ |v|² + ½ Σ_k (s_M,k − s_d,k)²/σ_k²
//! in normalized controls v = (u − u_c)/c, |v| ≤ 1 the actuator box). Along each emulated tape
//! the emulator is linearized by its exact Jacobians and an LQR tracker with the eq. 12 value
//! function built for the same objective ([`crate::control::step_tracker`]): cost
//! dt·½ vᵀ(μ_u/Δt)v per super-step of Δt, terminal Σ_k (s_k − s_d,k)²/(2σ_k²).
//!
//! **Noise model and λ.** With control cost ½ vᵀRv, R = μ_u/Δt, the linear Bellman equation
//! holds for white noise on v of covariance λR⁻¹ (LBC eq. 8); the spec states its intensity σ_u
//! (half-widths·√s), so λ = σ_u² R. The weights w for a desired target d on the axis come from
//! projecting exp(−q (x − d)²) onto exp(−q (x − c_i)²) with q = Q_axis/λ (§4.1; the components'
//! other terminal terms are equal and drop out).
//!
//! **Compared on the physical simulator** (RK4, the control held over each super-step, the state
//! fed back once per super-step), per desired target: `lbc` (α_i ∝ w_i exp(−v̂_i/λ)), `naive`
//! (fixed w/Σw), `tracker1`, `tracker2` (each component alone, closed loop), `open_loop1`,
//! `open_loop2` (each component's tape replayed), `bptt` (BPTT re-optimized from scratch for the
//! desired target, its tape replayed: the ground truth of what the emulator can learn, with its
//! wall time) and `bptt_tracked` (that tape with its own emulator tracker, closed loop). The
//! same policies are also run on the emulator (`final_error_emulator`). Final error: RMS of
//! (s_M − s_d)/σ over the state (≤ 1: within tolerance), s_d the desired target.
//!
//! Tables: `targets` (desired_target, method, final_error_emulator, final_error_simulator,
//! effort, seconds, weight1, weight2, final_x, final_axis_offset), `components` (component,
//! target, learn_seconds, tracker_seconds, iterations, objective, emulator_error,
//! open_loop_simulator_error, tracked_simulator_error), `trajectory` (desired_target, method,
//! step, t, s0 … on the simulator), `goal` (desired_target, s0 …: the target state), `rule`. `effort` is ½ Σ_k |v_k|² over the super-steps,
//! `seconds` the wall time to obtain the controller for that target (BPTT: learning; LBC and
//! naive: projecting the weights; the components' own costs are in `components`),
//! `mean_entropy` the mean normalized entropy of the blend weights α over the super-steps on the
//! simulator (0: one component, 1: even; NaN for the open-loop replays and where extrapolation
//! makes a weight negative).

use crate::bellman::combine::{normalized_entropy, BlendMode, CombineError, TrackerBlend};
use crate::bellman::projection::{project, GaussianReward};
use crate::control::tracker::ValueTracker;
use crate::control::bptt::{learn_with, Bptt, Descent, Knots, Schedule, StepRule};
use crate::control::step_tracker::{AffineControls, StepTracker};
use crate::control::QuadraticCost;
use crate::emulator::catalog::{NetModel, NetSpec, TrainSettings};
use crate::emulator::Emulator;
use crate::experiment::output::{df_f64, df_str, read_csv, Table, Tables};
use crate::experiment::plot::{Figure, FigureSink, Mark, Panel, Series};
use crate::experiment::report::{sig, Findings, Verdict};
use crate::experiment::resolve::{ensure, positive, ParamError, Validate};
use crate::experiment::{other, Error, Family, Job, RunContext};
use crate::families::lbc::{rule_settings, rule_table};
use crate::families::na::fig13_control::anim::{write_animation, Scene, Track, SIMULATOR};
use crate::families::na::fig13_control::Task;
use crate::families::na::table1_structure::{
    build_emulator, build_spec, validate_nets, validate_training,
};
use crate::physics::lander::Lander;
use crate::physics::DifferentiableStep;
use crate::row;
use nalgebra::{DMatrix, DVector};
use plotters::style::RGBColor;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// The family.
pub struct XLbcEmulator;

/// Parameters of `x_lbc_emulator`.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Params {
    /// Physical steps per emulator step n (N50: 50).
    pub steps: usize,
    /// Multiplies the net's example count.
    pub example_scale: f64,
    /// The emulator net (lander or truck).
    pub net: NetSpec,
    /// Training settings (those of `na_table1_structure`, so the net comes from the cache).
    pub training: TrainSettings,
    /// Emulator steps M.
    pub horizon: usize,
    /// Knots per actuator K.
    pub knots: usize,
    /// BPTT iterations of each learning run.
    pub iterations: usize,
    /// BPTT step rule (e.g. Levenberg–Marquardt).
    pub step_rule: StepRule,
    /// Start state.
    pub start: Vec<f64>,
    /// Target final state (its `axis` component is replaced by each target's value).
    pub target: Vec<f64>,
    /// Tolerance σ_k per state variable (weight 1/σ²; 0 = ignore).
    pub final_tolerance: Vec<f64>,
    /// Effort weight μ_u.
    pub effort_mu: f64,
    /// Index of the state variable the targets differ in.
    pub axis: usize,
    /// The two components' targets on the axis.
    pub components: [f64; 2],
    /// Desired targets on the axis.
    pub desired: Vec<f64>,
    /// Intensity σ_u of white noise on the normalized controls (√s); λ = σ_u² μ_u/Δt.
    pub control_noise: f64,
    /// Ours: the fraction of strictly in-between targets on which LBC's simulator error must
    /// be ≤ 1.
    pub within_fraction: f64,
    /// Ours: LBC's mean simulator error over the in-between targets may exceed naive's by at
    /// most this (tolerance units).
    pub naive_margin: f64,
    /// Ours: LBC's mean distance of the final position on the axis from the desired target
    /// (simulator, in-between targets) may exceed naive's by at most this (m).
    pub axis_margin: f64,
}

impl Validate for Params {
    fn validate(&self) -> Result<(), ParamError> {
        ensure(self.steps >= 1, "steps", "must be >= 1")?;
        let model = self.net.model;
        ensure(
            matches!(model, NetModel::Lander | NetModel::Truck),
            "net.model",
            "must be lander or truck",
        )?;
        let n = model.state_dim();
        ensure(self.horizon >= 1, "horizon", "must be >= 1")?;
        ensure(
            self.knots >= 1 && self.knots <= self.horizon,
            "knots",
            "must be in [1, horizon]",
        )?;
        ensure(self.iterations >= 1, "iterations", "must be >= 1")?;
        self.step_rule.validate("step_rule")?;
        for (k, v) in [
            ("start", &self.start),
            ("target", &self.target),
            ("final_tolerance", &self.final_tolerance),
        ] {
            ensure(v.len() == n, k, format!("needs {n} values"))?;
            ensure(v.iter().all(|x| x.is_finite()), k, "must be finite")?;
        }
        ensure(
            self.final_tolerance.iter().all(|&x| x >= 0.0),
            "final_tolerance",
            "must be >= 0",
        )?;
        ensure(self.axis < n, "axis", format!("must be < {n}"))?;
        ensure(
            self.final_tolerance[self.axis] > 0.0,
            "final_tolerance",
            "the axis needs a tolerance > 0",
        )?;
        positive("effort_mu", self.effort_mu)?;
        ensure(
            self.components[0] < self.components[1],
            "components",
            "must be increasing",
        )?;
        ensure(!self.desired.is_empty(), "desired", "needs at least one")?;
        ensure(
            self.desired.iter().all(|d| d.is_finite()),
            "desired",
            "must be finite",
        )?;
        positive("control_noise", self.control_noise)?;
        ensure(
            (0.0..=1.0).contains(&self.within_fraction),
            "within_fraction",
            "must be in [0, 1]",
        )?;
        ensure(self.naive_margin >= 0.0, "naive_margin", "must be >= 0")?;
        ensure(self.axis_margin >= 0.0, "axis_margin", "must be >= 0")?;
        validate_nets(std::slice::from_ref(&self.net), self.example_scale)?;
        validate_training(&self.training)
    }
}

/// Names of the compared methods, in table order.
const METHODS: [&str; 8] = [
    "lbc",
    "naive",
    "tracker1",
    "tracker2",
    "open_loop1",
    "open_loop2",
    "bptt",
    "bptt_tracked",
];

/// A learned component: its tape (normalized controls) and emulated states, and its tracker.
struct Component {
    tape: Vec<DVector<f64>>,
    tracker: StepTracker,
    learn_seconds: f64,
    tracker_seconds: f64,
    iterations: usize,
    objective: f64,
    emulator_final: Vec<f64>,
}

/// Where a policy runs: the emulator (one step per super-step) or the simulator (`steps` RK4
/// steps of δt with the control held).
#[derive(Clone, Copy)]
enum Substrate {
    Emulator,
    Simulator,
}

/// A run's final state, effort ½ Σ |v|² and states per super-step.
struct Outcome {
    states: Vec<Vec<f64>>,
    effort: f64,
}

impl Params {
    fn super_dt(&self) -> f64 {
        self.net.physical_dt * self.steps as f64
    }

    /// The Fig. 13 task reaching `value` on the axis.
    fn task(&self, value: f64) -> Task {
        let mut target = self.target.clone();
        target[self.axis] = value;
        Task {
            name: format!("target {value}"),
            net: self.net.clone(),
            horizon: self.horizon,
            knots: self.knots,
            iterations: self.iterations,
            limit_fraction: 1.0,
            start: self.start.clone(),
            target,
            final_tolerance: self.final_tolerance.clone(),
            effort_mu: self.effort_mu,
            eta: 1.0,
            alpha: 0.0,
            step_rule: self.step_rule,
        }
    }

    fn start_state(&self) -> Vec<f64> {
        let mut x0 = self.start.clone();
        if self.net.model == NetModel::Lander {
            Lander::default().normalize_state(&mut x0);
        }
        x0
    }

    /// Centre and half-width of each actuator's box: u = centre + half-width ⊙ v.
    fn control_map<'a>(&self, emu: &'a Emulator) -> AffineControls<'a, Emulator> {
        let l = self.net.model.control_limits();
        AffineControls {
            inner: emu,
            offset: (0..l.low.len())
                .map(|j| 0.5 * (l.low[j] + l.high[j]))
                .collect(),
            scale: (0..l.low.len())
                .map(|j| 0.5 * (l.high[j] - l.low[j]))
                .collect(),
        }
    }

    /// R = μ_u/Δt in normalized controls.
    fn control_weight(&self) -> f64 {
        self.effort_mu / self.super_dt()
    }

    /// λ = σ_u² R (eq. 8).
    fn lambda(&self) -> f64 {
        self.control_noise * self.control_noise * self.control_weight()
    }

    /// Terminal weight Q_k = 1/(2σ_k²) of variable k (0 without a tolerance).
    fn terminal_weight(&self, k: usize) -> f64 {
        let s = self.final_tolerance[k];
        if s > 0.0 {
            0.5 / (s * s)
        } else {
            0.0
        }
    }

    /// The tracker cost for the target `value` (the BPTT objective per super-step).
    fn cost(&self, value: f64, m: usize) -> QuadraticCost {
        let n = self.target.len();
        let task = self.task(value);
        QuadraticCost {
            dt: self.super_dt(),
            r: DMatrix::identity(m, m) * self.control_weight(),
            state: None,
            q_final: DMatrix::from_fn(
                n,
                n,
                |i, j| {
                    if i == j {
                        self.terminal_weight(i)
                    } else {
                        0.0
                    }
                },
            ),
            x_final: DVector::from_column_slice(&task.target),
        }
    }

    /// Learns the tape for `value` by BPTT through `emu` and builds its tracker.
    fn learn(&self, emu: &Emulator, value: f64) -> Result<Component, Error> {
        let task = self.task(value);
        let (n, m) = (self.net.model.state_dim(), self.net.model.control_dim());
        let objective = task.objective();
        let knots = Knots {
            steps: self.horizon,
            per_actuator: self.knots,
            m,
        };
        let x0 = self.start_state();
        let t0 = Instant::now();
        let mut bptt = Bptt::new(emu, &objective, knots, task.bounds(), &x0).map_err(other)?;
        let rest = task.rest_control();
        let init: Vec<f64> = (0..knots.len()).map(|i| rest[i % m]).collect();
        let v0 = bptt.from_controls(&init);
        let schedule = Schedule {
            descent: Descent::Plain { eta: 1.0 },
            rule: self.step_rule,
            scale: 1.0,
            curvature_iterations: 1,
        };
        let run = learn_with(
            &mut bptt,
            &v0,
            &schedule,
            self.iterations,
            &mut |_, _, _| false,
        );
        bptt.rollout(&run.best_knots);
        let learn_seconds = t0.elapsed().as_secs_f64();
        let map = self.control_map(emu);
        let xs: Vec<DVector<f64>> = bptt
            .states()
            .chunks_exact(n)
            .map(DVector::from_column_slice)
            .collect();
        let tape: Vec<DVector<f64>> = bptt
            .controls()
            .chunks_exact(m)
            .map(|u| DVector::from_fn(m, |j, _| (u[j] - map.offset[j]) / map.scale[j]))
            .collect();
        let t1 = Instant::now();
        let tracker = StepTracker::build(&map, &self.cost(value, m), &xs, &tape, self.super_dt())
            .map_err(other)?;
        Ok(Component {
            tracker_seconds: t1.elapsed().as_secs_f64(),
            emulator_final: xs[self.horizon].as_slice().to_vec(),
            tape,
            tracker,
            learn_seconds,
            iterations: run.best_iteration,
            objective: run.best_objective(),
        })
    }

    /// Runs `policy` (normalized controls, clamped to |v| ≤ 1) from the start on `substrate`.
    fn execute(
        &self,
        emu: &Emulator,
        substrate: Substrate,
        policy: &mut dyn FnMut(&[f64], usize, &mut [f64]) -> Result<(), Error>,
    ) -> Result<Outcome, Error> {
        let (n, m) = (self.net.model.state_dim(), self.net.model.control_dim());
        let map = self.control_map(emu);
        let mut sim = self.net.model.simulator();
        let mut scratch = DifferentiableStep::scratch(&map);
        let mut x = self.start_state();
        let (mut v, mut u, mut next) = (vec![0.0; m], vec![0.0; m], vec![0.0; n]);
        let mut states = vec![x.clone()];
        let mut effort = 0.0;
        for k in 0..self.horizon {
            policy(&x, k, &mut v)?;
            for vj in v.iter_mut() {
                *vj = vj.clamp(-1.0, 1.0);
            }
            effort += 0.5 * v.iter().map(|a| a * a).sum::<f64>();
            match substrate {
                Substrate::Emulator => {
                    DifferentiableStep::step(&map, &x, &v, &mut scratch, &mut next);
                    x.copy_from_slice(&next);
                }
                Substrate::Simulator => {
                    map.to_controls(&v, &mut u);
                    for _ in 0..self.steps {
                        sim.step(&mut x, &u, self.net.physical_dt);
                    }
                }
            }
            if x.iter().any(|a| !a.is_finite()) {
                return Err(other(format!("non-finite state at super-step {k}")));
            }
            states.push(x.clone());
        }
        Ok(Outcome { states, effort })
    }
}

/// A blend of the component trackers as a policy.
///
/// Where LBC's combined reward Σ w_i z_i is not positive (extrapolating weights, one w_i < 0,
/// whose negative term dominates at the state reached) the blend is undefined there: `undefined`
/// is set and the run stops with an error, which the caller records as a failed run.
fn blend_policy<'a>(
    blend: &'a TrackerBlend<'a, StepTracker>,
    alpha_log: &'a mut Vec<f64>,
    undefined: &'a std::cell::Cell<bool>,
) -> impl FnMut(&[f64], usize, &mut [f64]) -> Result<(), Error> + 'a {
    let n = blend.trackers.len();
    let m = blend.trackers[0].control_dim();
    let (mut alpha, mut ui) = (vec![0.0; n], vec![0.0; m]);
    move |x, k, v| {
        blend.control(x, k, v, &mut alpha, &mut ui).map_err(|e| {
            if matches!(e, CombineError::NonPositiveReward(_)) {
                undefined.set(true);
            }
            other(format!("super-step {k}: {e}"))
        })?;
        // Entropy is defined for α ≥ 0; extrapolating weights (one w_i < 0) give NaN.
        alpha_log.push(if alpha.iter().all(|&a| a > -1e-12) {
            normalized_entropy(&alpha).max(0.0)
        } else {
            f64::NAN
        });
        Ok(())
    }
}

impl Job for Params {
    fn params_json(&self) -> serde_json::Value {
        serde_json::to_value(self).unwrap_or_default()
    }

    fn run(&self, ctx: &RunContext) -> Result<Tables, Error> {
        let model = self.net.model;
        let n = model.state_dim();
        let spec = build_spec(
            ctx.seed,
            &self.net,
            self.steps,
            self.example_scale,
            &self.training,
        );
        let trained = ctx.stage(&format!("train {} N{}", model.name(), self.steps), || {
            build_emulator(&spec)
        })?;
        let emu = &trained.emulator;
        let comps = ctx.stage("learn components", || {
            self.components
                .iter()
                .map(|&c| self.learn(emu, c))
                .collect::<Result<Vec<_>, Error>>()
        })?;
        let trackers: Vec<StepTracker> = comps.iter().map(|c| c.tracker.clone()).collect();
        let lambda = self.lambda();
        let q = self.terminal_weight(self.axis) / lambda;
        let spacing = self.components[1] - self.components[0];

        let mut components_t = Table::new(&[
            "component",
            "target",
            "learn_seconds",
            "tracker_seconds",
            "iterations",
            "objective",
            "emulator_error",
            "open_loop_simulator_error",
            "tracked_simulator_error",
        ]);
        let mut targets_t = Table::new(&[
            "desired_target",
            "method",
            "final_error_emulator",
            "final_error_simulator",
            "effort",
            "seconds",
            "weight1",
            "weight2",
            "final_axis_value",
            "mean_entropy",
        ]);
        let mut cols: Vec<String> = ["desired_target", "method", "step", "t"]
            .iter()
            .map(|s| s.to_string())
            .collect();
        // The state variables by their `describe` names.
        cols.extend(model.state_names());
        debug_assert_eq!(cols.len(), 4 + n);
        let col_refs: Vec<&str> = cols.iter().map(String::as_str).collect();
        let mut trajectory = Table::new(&col_refs);
        let mut goal_cols = vec!["desired_target"];
        goal_cols.extend_from_slice(&col_refs[4..]);
        let mut goal_t = Table::new(&goal_cols);

        let dt = self.super_dt();
        ctx.stage("compare", || -> Result<(), Error> {
            for (i, (c, &value)) in comps.iter().zip(&self.components).enumerate() {
                let task = self.task(value);
                let open = self.execute(emu, Substrate::Simulator, &mut |_, k, v| {
                    v.copy_from_slice(c.tape[k].as_slice());
                    Ok(())
                })?;
                let tracked = self.execute(emu, Substrate::Simulator, &mut |x, k, v| {
                    c.tracker.policy_into(x, k, v);
                    Ok(())
                })?;
                components_t.push(row![
                    format!("{}", i + 1),
                    value,
                    c.learn_seconds,
                    c.tracker_seconds,
                    c.iterations as i64,
                    c.objective,
                    task.final_error(&c.emulator_final),
                    task.final_error(&open.states[self.horizon]),
                    task.final_error(&tracked.states[self.horizon])
                ]);
            }
            for &d in &self.desired {
                let task = self.task(d);
                let mut r = row![d];
                r.extend(task.target.iter().map(|&v| v.into()));
                goal_t.push(r);
                let t0 = Instant::now();
                let comp_rewards: Vec<GaussianReward> = self
                    .components
                    .iter()
                    .map(|&c| GaussianReward::isotropic(&[c], q))
                    .collect();
                let mut w = project(&comp_rewards, &GaussianReward::isotropic(&[d], q))
                    .map_err(other)?
                    .weights;
                // Projection round-off: at a component's own target the other weight comes out
                // as ±1e-16, and a negative one makes Σ w_i z_i ≤ 0 wherever that component's
                // z dominates. A weight within 1e-12 of the largest's magnitude is zero.
                let largest = w.iter().fold(0.0f64, |a, b| a.max(b.abs()));
                for wi in &mut w {
                    if wi.abs() <= 1e-12 * largest {
                        *wi = 0.0;
                    }
                }
                let projection_seconds = t0.elapsed().as_secs_f64();
                let fresh = self.learn(emu, d)?;
                let limits = None;
                for method in METHODS {
                    let blend = |mode| TrackerBlend {
                        trackers: &trackers,
                        weights: w.clone(),
                        lambda,
                        mode,
                        limits,
                    };
                    let own = [fresh.tracker.clone()];
                    let (blend, seconds) = match method {
                        "lbc" => (Some(blend(BlendMode::Lbc)), projection_seconds),
                        "naive" => (Some(blend(BlendMode::Naive)), projection_seconds),
                        "tracker1" => (Some(blend(BlendMode::Single(0))), 0.0),
                        "tracker2" => (Some(blend(BlendMode::Single(1))), 0.0),
                        "bptt_tracked" => (
                            Some(TrackerBlend {
                                trackers: &own,
                                weights: vec![1.0],
                                lambda,
                                mode: BlendMode::Single(0),
                                limits,
                            }),
                            fresh.learn_seconds + fresh.tracker_seconds,
                        ),
                        "bptt" => (None, fresh.learn_seconds),
                        _ => (None, 0.0),
                    };
                    let tape = match method {
                        "open_loop1" => &comps[0].tape,
                        "open_loop2" => &comps[1].tape,
                        _ => &fresh.tape,
                    };
                    let mut entropy = Vec::new();
                    let undefined = std::cell::Cell::new(false);
                    let mut run = |substrate| -> Result<Outcome, Error> {
                        match &blend {
                            Some(b) => {
                                let mut log = Vec::new();
                                let r = self.execute(
                                    emu,
                                    substrate,
                                    &mut blend_policy(b, &mut log, &undefined),
                                );
                                if matches!(substrate, Substrate::Simulator) {
                                    entropy = log;
                                }
                                r
                            }
                            None => self.execute(emu, substrate, &mut |_, k, v| {
                                v.copy_from_slice(tape[k].as_slice());
                                Ok(())
                            }),
                        }
                    };
                    // A blend undefined along a run (above) is a failed run on that substrate:
                    // its row has NaN final errors, effort and axis value.
                    let mut outcome = |substrate| match run(substrate) {
                        Ok(o) => Ok(Some(o)),
                        Err(_) if undefined.replace(false) => Ok(None),
                        Err(e) => Err(e),
                    };
                    let on_emu = outcome(Substrate::Emulator)?;
                    let on_sim = outcome(Substrate::Simulator)?;
                    let (Some(on_emu), Some(on_sim)) = (&on_emu, on_sim) else {
                        let emu_error = on_emu
                            .as_ref()
                            .map_or(f64::NAN, |o| task.final_error(&o.states[self.horizon]));
                        targets_t.push(row![
                            d,
                            method,
                            emu_error,
                            f64::NAN,
                            f64::NAN,
                            seconds,
                            w[0],
                            w[1],
                            f64::NAN,
                            f64::NAN
                        ]);
                        continue;
                    };
                    let end = &on_sim.states[self.horizon];
                    let mean_entropy = if entropy.is_empty() {
                        f64::NAN
                    } else {
                        entropy.iter().sum::<f64>() / entropy.len() as f64
                    };
                    targets_t.push(row![
                        d,
                        method,
                        task.final_error(&on_emu.states[self.horizon]),
                        task.final_error(end),
                        on_sim.effort,
                        seconds,
                        w[0],
                        w[1],
                        end[self.axis],
                        mean_entropy
                    ]);
                    for (k, s) in on_sim.states.iter().enumerate() {
                        let mut r = row![d, method, k as i64, k as f64 * dt];
                        r.extend(s.iter().map(|&v| v.into()));
                        trajectory.push(r);
                    }
                }
            }
            Ok(())
        })?;
        let rule = rule_table(&[
            ("lambda", lambda),
            ("control_noise", self.control_noise),
            ("q_spacing2", q * spacing * spacing),
            ("component1", self.components[0]),
            ("component2", self.components[1]),
            ("within_fraction", self.within_fraction),
            ("naive_margin", self.naive_margin),
            ("axis_margin", self.axis_margin),
            ("super_step_s", dt),
        ]);
        Ok(Tables::from([
            ("targets", targets_t),
            ("components", components_t),
            ("trajectory", trajectory),
            ("goal", goal_t),
            ("rule", rule),
        ]))
    }
}

/// Colours of the methods in the figure (palette indices).
fn method_color(method: &str) -> usize {
    METHODS.iter().position(|m| *m == method).unwrap_or(0)
}

impl Family for XLbcEmulator {
    const KIND: &'static str = "x_lbc_emulator";
    type Params = Params;
    const BEYOND: bool = true;

    fn figures(&self, fig: &FigureSink, tables: &Tables) -> Result<Vec<PathBuf>, Error> {
        let t = tables.require("targets")?;
        let (d, meth, es, ee) = (
            t.f64s("desired_target"),
            t.strs("method"),
            t.f64s("final_error_simulator"),
            t.f64s("final_error_emulator"),
        );
        let (lo, hi) = d
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| {
                (a.min(x), b.max(x))
            });
        let panel = |title: &str, ys: &[f64]| {
            let mut series: Vec<Series> = METHODS
                .iter()
                .map(|&mm| {
                    let pts = (0..d.len())
                        .filter(|&r| meth[r] == mm)
                        .map(|r| (d[r], ys[r].max(1e-3)))
                        .collect();
                    let mark = if mm.starts_with("open_loop") || mm == "bptt" {
                        Mark::Dashed
                    } else {
                        Mark::LinePoints
                    };
                    Series::line(mm, pts, method_color(mm)).mark(mark)
                })
                .collect();
            series.push(
                Series::line("tolerance (error 1)", vec![(lo, 1.0), (hi, 1.0)], 9)
                    .mark(Mark::Dashed),
            );
            Panel {
                title: title.into(),
                x_label: "desired landing target x (m)".into(),
                y_label: "final error (RMS of (s - s_d)/tolerance)".into(),
                log_y: true,
                series,
                ..Panel::default()
            }
        };
        // Tall panels: the nine-entry legend then fits above the data (the plot raises the
        // top of the y range for it) instead of covering it.
        let mut files = fig.draw(
            "error",
            &Figure {
                panel_size: (640, 640),
                ..Figure::grid(
                    vec![
                        panel("on the physical simulator", &es),
                        panel("on the emulator", &ee),
                    ],
                    2,
                )
            },
        )?;
        files.extend(animation(fig, tables)?);
        Ok(files)
    }

    fn report(&self, dir: &Path) -> Result<Findings, Error> {
        let setting = rule_settings(dir)?;
        let (c1, c2, frac, margin, lambda, axis_margin) = (
            setting("component1"),
            setting("component2"),
            setting("within_fraction"),
            setting("naive_margin"),
            setting("lambda"),
            setting("axis_margin"),
        );
        let between = |x: f64| x > c1 && x < c2;
        let df = read_csv(&dir.join("targets.csv"))?;
        let (d, meth, es, ee, secs, reached) = (
            df_f64(&df, "desired_target")?,
            df_str(&df, "method")?,
            df_f64(&df, "final_error_simulator")?,
            df_f64(&df, "final_error_emulator")?,
            df_f64(&df, "seconds")?,
            df_f64(&df, "final_axis_value")?,
        );
        let miss = |mm: &str| -> Vec<f64> {
            (0..d.len())
                .filter(|&r| meth[r] == mm && between(d[r]))
                .map(|r| (reached[r] - d[r]).abs())
                .collect()
        };
        let errs = |mm: &str| -> Vec<f64> {
            (0..d.len())
                .filter(|&r| meth[r] == mm && between(d[r]))
                .map(|r| es[r])
                .collect()
        };
        let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len().max(1) as f64;
        let lbc = errs("lbc");
        let within = lbc.iter().filter(|&&e| e <= 1.0).count();
        let need = (frac * lbc.len() as f64).ceil() as usize;
        let (ml, mn) = (mean(&lbc), mean(&errs("naive")));
        let ok_within = !lbc.is_empty() && within >= need;
        let ok_naive = !lbc.is_empty() && ml <= mn + margin;
        let (xl, xn) = (mean(&miss("lbc")), mean(&miss("naive")));
        let ok_axis = !lbc.is_empty() && xl <= xn + axis_margin;
        let verdict = Verdict::graded(
            ok_within && ok_naive && ok_axis,
            ok_within || ok_naive || ok_axis,
        );
        let mut md = String::from(
            "Final error (RMS of (s − s_d)/tolerance, ≤ 1 within tolerance) on the simulator / emulator, per desired target and method:\n\n| desired x (m) |",
        );
        for mm in METHODS {
            md.push_str(&format!(" {mm} |"));
        }
        md.push_str("\n| --- |");
        md.push_str(&" --- |".repeat(METHODS.len()));
        md.push('\n');
        let mut targets: Vec<f64> = Vec::new();
        for &x in &d {
            if !targets.contains(&x) {
                targets.push(x);
            }
        }
        for &x in &targets {
            md.push_str(&format!("| {} |", sig(x)));
            for mm in METHODS {
                let r = (0..d.len()).find(|&r| d[r] == x && meth[r] == mm);
                match r {
                    Some(r) => md.push_str(&format!(" {} / {} |", sig(es[r]), sig(ee[r]))),
                    None => md.push_str(" – |"),
                }
            }
            md.push('\n');
        }
        let bptt_s: Vec<f64> = (0..d.len())
            .filter(|&r| meth[r] == "bptt")
            .map(|r| secs[r])
            .collect();
        let comps = read_csv(&dir.join("components.csv"))?;
        let (cl, co, ct) = (
            df_f64(&comps, "learn_seconds")?,
            df_f64(&comps, "open_loop_simulator_error")?,
            df_f64(&comps, "tracked_simulator_error")?,
        );
        md.push_str(&format!(
            "\nComponents (targets x = {} and {} m): open-loop replay error on the simulator {} and {}, with the emulator-derived tracker in closed loop {} and {}; learned in {} s and {} s. BPTT re-optimized per desired target: mean {} s. λ = {} (from the stated control noise). Mean simulator error over the in-between targets: LBC {}, naive {}, BPTT open loop {}, BPTT tracked {}.\n",
            sig(c1),
            sig(c2),
            sig(co[0]),
            sig(co[1]),
            sig(ct[0]),
            sig(ct[1]),
            sig(cl[0]),
            sig(cl[1]),
            sig(mean(&bptt_s)),
            sig(lambda),
            sig(ml),
            sig(mn),
            sig(mean(&errs("bptt"))),
            sig(mean(&errs("bptt_tracked"))),
        ));
        md.push_str(
            "\nThe error is an RMS over all 13 state variables, so it dilutes a miss along the axis (a landing 3 m off the desired x alone gives 0.83): the mean distance of the final x from the desired x (m) on the simulator over the in-between targets, per method:\n\n| method | mean distance to the desired x (m) | mean final error |\n| --- | --- | --- |\n",
        );
        for mm in METHODS {
            md.push_str(&format!(
                "| {mm} | {} | {} |\n",
                sig(mean(&miss(mm))),
                sig(mean(&errs(mm)))
            ));
        }
        Ok(Findings {
            ours: md,
            verdict,
            why: format!(
                "Rule (ours, fixed in the spec): held needs LBC's simulator error ≤ 1 on at least {} of the {} targets strictly between the components ({} were), LBC's mean simulator error there no worse than the naive blend's + {} ({} vs {}), and LBC's mean distance from the desired x no more than naive's + {} m ({} vs {} m; this third condition was added after the first full run showed that the RMS error dilutes a miss along x); partly needs one of the three.",
                sig(frac),
                lbc.len(),
                within,
                sig(margin),
                sig(ml),
                sig(mn),
                sig(axis_margin),
                sig(xl),
                sig(xn)
            ),
        })
    }
}

/// GIF of the LBC motion on the simulator at the in-between target nearest the middle, with
/// BPTT's re-optimized open-loop replay beside it.
fn animation(fig: &FigureSink, tables: &Tables) -> Result<Vec<PathBuf>, Error> {
    let (Some(tr), Some(rule)) = (tables.get("trajectory"), tables.get("rule")) else {
        return Ok(Vec::new());
    };
    let (rk, rv) = (rule.strs("setting"), rule.f64s("value"));
    let get = |k: &str| rk.iter().position(|s| s == k).map_or(f64::NAN, |i| rv[i]);
    let (c1, c2, dt) = (get("component1"), get("component2"), get("super_step_s"));
    let (d, meth) = (tr.f64s("desired_target"), tr.strs("method"));
    let mid = 0.5 * (c1 + c2);
    let Some(&pick) = d
        .iter()
        .filter(|&&x| x > c1 && x < c2)
        .min_by(|a, b| (*a - mid).abs().total_cmp(&(*b - mid).abs()))
    else {
        return Ok(Vec::new());
    };
    // The model whose state names the table has (results before the names: s0, s1, ...).
    let (model, names) = [NetModel::Lander, NetModel::Truck]
        .into_iter()
        .map(|m| (m, m.state_names()))
        .find(|(_, names)| names.iter().all(|c| tr.column(c).is_some()))
        .unwrap_or_else(|| {
            let width = (0..)
                .take_while(|k| tr.column(&format!("s{k}")).is_some())
                .count();
            let model = if width == NetModel::Lander.state_dim() {
                NetModel::Lander
            } else {
                NetModel::Truck
            };
            (model, (0..width).map(|k| format!("s{k}")).collect())
        });
    let cols: Vec<Vec<f64>> = names.iter().map(|c| tr.f64s(c)).collect();
    let track = |mm: &str| -> Vec<Vec<f64>> {
        (0..d.len())
            .filter(|&r| d[r] == pick && meth[r] == mm)
            .map(|r| cols.iter().map(|c| c[r]).collect())
            .collect()
    };
    let lbc = track("lbc");
    let g = tables.require("goal")?;
    let gd = g.f64s("desired_target");
    let Some(gr) = gd.iter().position(|&x| x == pick) else {
        return Ok(Vec::new());
    };
    let goal: Vec<f64> = names.iter().map(|c| g.f64s(c)[gr]).collect();
    let tracks = vec![
        Track {
            label: "LBC of the two emulator-derived trackers".into(),
            color: RGBColor(200, 60, 30),
            states: lbc,
        },
        Track {
            label: "BPTT re-optimized, open-loop replay".into(),
            color: SIMULATOR,
            states: track("bptt"),
        },
    ];
    let (p, _) = write_animation(
        &fig.dir,
        &format!("{}_lbc", fig.id),
        &Scene::for_model(model),
        &format!("lander: LBC to x = {} m on the simulator", sig(pick)),
        "simulator: LBC closed loop (red), re-optimized BPTT tape open loop (grey), goal (green)",
        dt,
        &goal,
        &tracks,
    )?;
    Ok(vec![p])
}
