//! `na_baselines_swim` (NeuroAnimator §6): learning the dolphin's swim controller by
//! backpropagation through time against gradient-free searches.
//!
//! The paper: simulated annealing and the simplex method need 500–3,500 iterations (over an
//! hour) to learn a controller; backpropagation through time through the emulator needs about
//! 20 (under 10 s). Here every method searches the same 120 normalized knots (20 per muscle,
//! 6 muscles, [−1, 1]) of the swim task of [`super::swim`] from the same random start
//! (half-width `init_spread`, the full range in the spec; the first start of
//! `na_fig13_control`'s dolphin) and minimizes the same objective J = effort − distance swum;
//! every run is scored at its best-so-far iterate (lowest J on its substrate), as
//! `na_fig13_control` scores its runs:
//!
//! - `bptt_momentum`, `bptt_plain`: descent through the hierarchy's global net
//!   ([`crate::control::search::bptt_search`]), η in units of 1/λ (λ: the largest Hessian
//!   eigenvalue magnitude of J at the start, whose power-iteration cost is charged to both);
//! - `annealing`, `simplex`, `hill_climbing` ([`crate::control::search`]): on the emulator
//!   (the same global net rollout) **and** on the physical simulator (the knots replayed on
//!   the mass-spring dolphin, 50 physical steps per emulator step, mass states mapped to the
//!   six segment frames at the emulator step times).
//!
//! Every method's objective is J on its own substrate. Counting follows
//! [`crate::control::search`]: an iteration is one annealing proposal, one simplex step, one
//! hill-climbing batch or one BPTT gradient step; a gradient counts one evaluation.
//!
//! Tables:
//! - `baselines` (method, substrate, iteration, evaluations, seconds, objective, gradients,
//!   current): one row per iteration; `objective` is the best J so far, `current` J at the
//!   method's current point. `seconds` (wall clock from the start of the method, the BPTT
//!   step-scale estimate included for BPTT) is the only non-deterministic column.
//! - `final` (method, substrate, iterations, evaluations, seconds, objective_substrate,
//!   objective_emulator, objective_simulator, distance_emulator_m, distance_simulator_m,
//!   target, iterations_to_bptt, evaluations_to_bptt, seconds_to_bptt, best_iteration): the
//!   best knots of each run evaluated on both substrates and the forward distance (m) they
//!   swim; `target` is BPTT-momentum's best J on the row's substrate (on the simulator: its
//!   learned knots replayed there) and the `*_to_bptt` columns are where the run's best J
//!   first reached it (NaN: never); `best_iteration` is where it reached its own best.

use super::swim::SwimTask;
use super::table1_structure::{build_dolphin_emulator, DolphinNets};
use crate::control::bptt::{Bptt, Descent};
use crate::control::search::{
    anneal, bptt_search, hill_climb, nelder_mead, time_to_target, AnnealingConfig, BpttProblem,
    Budget, ClimbConfig, Geometric, ReplayProblem, SearchProblem, SearchResult, SimplexConfig,
};
use crate::emulator::hierarchy::{self, global_state};
use crate::experiment::output::{df_f64, df_str, read_csv, Table, Tables};
use crate::experiment::plot::{Figure, FigureSink, Mark, Panel, Series};
use crate::experiment::report::{sig, Findings, Verdict};
use crate::experiment::resolve::{ensure, positive, ParamError, Validate};
use crate::experiment::{Error, Family, Job, RunContext};
use crate::row;
use crate::seed::mix_seed;
use rand::Rng;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// The family.
pub struct NaBaselines;

/// The BPTT runs.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BpttSettings {
    /// Gradient steps per run (the paper: about 20).
    pub iterations: usize,
    /// Momentum learning rate η (units of 1/λ).
    pub eta: f64,
    /// Momentum α.
    pub alpha: f64,
    /// Plain-descent learning rate η (units of 1/λ).
    pub plain_eta: f64,
}

/// The budget of every gradient-free search on one substrate.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SearchBudget {
    /// Objective evaluations (rollouts), the initialization's included.
    pub evaluations: usize,
    /// Optional wall-clock limit per search (s); makes the traces timing-dependent.
    #[serde(default)]
    pub seconds: Option<f64>,
}

impl SearchBudget {
    fn budget(&self) -> Budget {
        let b = Budget::evaluations(self.evaluations);
        match self.seconds {
            Some(s) => b.with_seconds(s),
            None => b,
        }
    }

    fn validate(&self, key: &str) -> Result<(), ParamError> {
        ensure(
            self.evaluations >= 2,
            &format!("{key}.evaluations"),
            "must be >= 2",
        )?;
        if let Some(s) = self.seconds {
            positive(&format!("{key}.seconds"), s)?;
        }
        Ok(())
    }
}

/// Budgets per substrate.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Budgets {
    /// Searches on the global net.
    pub emulator: SearchBudget,
    /// Searches on the physical simulator.
    pub simulator: SearchBudget,
}

/// Simulated annealing ([`AnnealingConfig`]); temperature and step cool geometrically from
/// their start to their end values over the substrate's evaluation budget.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AnnealingSettings {
    /// Perturbed copies of the start evaluated first (they set the temperature scale).
    pub initial_samples: usize,
    /// Initial temperature, in units of the spread of those samples' J.
    pub start_temperature: f64,
    /// Final temperature (same units).
    pub end_temperature: f64,
    /// Initial proposal standard deviation, in half-widths of the box.
    pub step: f64,
    /// Final proposal standard deviation.
    pub end_step: f64,
}

impl AnnealingSettings {
    fn config(&self, evaluations: usize) -> AnnealingConfig {
        let planned = evaluations.saturating_sub(self.initial_samples + 1).max(2);
        AnnealingConfig {
            initial_samples: self.initial_samples,
            temperature: Geometric::over(self.start_temperature, self.end_temperature, planned),
            step: Geometric::over(self.step, self.end_step, planned),
        }
    }
}

/// Nelder–Mead ([`SimplexConfig`]).
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SimplexSettings {
    /// Edge of the initial simplex, in half-widths.
    pub step: f64,
    /// Convergence tolerance on the vertex values' standard deviation.
    pub sd_tolerance: f64,
    /// Weight of the squared distance outside the box.
    pub penalty: f64,
    /// Restarts after a convergence that improved the best point.
    pub restarts: usize,
}

/// Parallel hill climbing ([`ClimbConfig`]).
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ClimbSettings {
    /// Proposals per iteration.
    pub batch: usize,
    /// Initial and largest step, in half-widths.
    pub step: f64,
    /// Step factor after a batch without improvement.
    pub shrink: f64,
    /// Step factor after an improvement.
    pub grow: f64,
}

/// Parameters of `na_baselines_swim`.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Params {
    /// Physical steps per emulator step n (N50).
    pub steps: usize,
    /// Multiplies the nets' example counts.
    pub example_scale: f64,
    /// Power iterations for the BPTT step scale λ.
    pub curvature_iterations: usize,
    /// Half-width of the uniform random initial knots (normalized units).
    pub init_spread: f64,
    /// The swim task.
    pub swim: SwimTask,
    /// The dolphin hierarchy (only its global net is used).
    pub nets: DolphinNets,
    /// The BPTT runs.
    pub bptt: BpttSettings,
    /// Gradient-free budgets per substrate.
    pub budget: Budgets,
    /// Simulated annealing.
    pub annealing: AnnealingSettings,
    /// Nelder–Mead simplex.
    pub simplex: SimplexSettings,
    /// Parallel hill climbing.
    pub hill_climbing: ClimbSettings,
    /// The same runs again on the dolphin's last-round DAgger global net of
    /// `na_fig13_control` (ours), if run.
    #[serde(default)]
    pub dagger: Option<SwimDagger>,
}

/// `[params.dagger]`: what, besides this file's task, nets and BPTT settings, determines
/// `na_fig13_control`'s dolphin DAgger chain (its `[params.dolphin]` restarts and
/// `[params.dolphin.dagger]`), so its cached nets are the ones searched on.
#[derive(Debug, Clone, Copy, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SwimDagger {
    /// Seeded restarts of the chain's learner.
    pub restarts: usize,
    /// Rounds, perturbations, fine-tuning budget.
    pub settings: crate::emulator::dagger::DaggerSettings,
    /// Super-steps of the fine-tuning's rollout windows.
    pub rollout_k: usize,
    /// Weight of the rollout loss.
    pub rollout_weight: f64,
}

/// The substrate name of runs on the DAgger net.
pub const DAGGER_SUBSTRATE: &str = "dagger_emulator";

impl Params {
    /// `na_fig13_control`'s parameters with the dolphin task alone and its DAgger chain, as
    /// this file states them: what keys and builds the DAgger nets.
    pub fn fig13(&self, d: &SwimDagger) -> super::fig13_control::Params {
        use super::fig13_control::dolphin_dagger::DolphinDagger;
        use super::fig13_control::DolphinControl;
        super::fig13_control::Params {
            steps: self.steps,
            curvature_iterations: self.curvature_iterations,
            example_scale: self.example_scale,
            tasks: vec![],
            training: self.nets.training,
            dolphin: Some(DolphinControl {
                nets: self.nets.clone(),
                swim: self.swim.clone(),
                iterations: self.bptt.iterations,
                eta: self.bptt.eta,
                alpha: self.bptt.alpha,
                init_spread: self.init_spread,
                restarts: d.restarts,
                step_rule: crate::control::bptt::StepRule::Fixed,
                dagger: Some(DolphinDagger {
                    settings: d.settings,
                    rollout_k: d.rollout_k,
                    rollout_weight: d.rollout_weight,
                }),
            }),
            sweep: None,
            physics_sweep: None,
            dagger: None,
        }
    }
}

impl Validate for Params {
    fn validate(&self) -> Result<(), ParamError> {
        ensure(self.steps >= 1, "steps", "must be >= 1")?;
        positive("example_scale", self.example_scale)?;
        ensure(
            self.curvature_iterations >= 1,
            "curvature_iterations",
            "must be >= 1",
        )?;
        ensure(
            self.init_spread >= 0.0 && self.init_spread <= 1.0,
            "init_spread",
            "must be in [0, 1]",
        )?;
        self.swim.validate("swim")?;
        self.nets.validate("nets", self.example_scale)?;
        if let Some(d) = &self.dagger {
            ensure(d.restarts >= 1, "dagger.restarts", "must be >= 1")?;
            super::fig13_control::dolphin_dagger::DolphinDagger {
                settings: d.settings,
                rollout_k: d.rollout_k,
                rollout_weight: d.rollout_weight,
            }
            .validate("dagger")?;
        }
        let b = &self.bptt;
        ensure(b.iterations >= 1, "bptt.iterations", "must be >= 1")?;
        positive("bptt.eta", b.eta)?;
        positive("bptt.plain_eta", b.plain_eta)?;
        ensure(
            (0.0..1.0).contains(&b.alpha),
            "bptt.alpha",
            "must be in [0, 1)",
        )?;
        self.budget.emulator.validate("budget.emulator")?;
        self.budget.simulator.validate("budget.simulator")?;
        let a = &self.annealing;
        positive("annealing.start_temperature", a.start_temperature)?;
        positive("annealing.end_temperature", a.end_temperature)?;
        ensure(
            a.end_temperature <= a.start_temperature,
            "annealing.end_temperature",
            "must be <= start_temperature",
        )?;
        positive("annealing.step", a.step)?;
        positive("annealing.end_step", a.end_step)?;
        ensure(
            a.end_step <= a.step,
            "annealing.end_step",
            "must be <= step",
        )?;
        let s = &self.simplex;
        positive("simplex.step", s.step)?;
        ensure(
            s.sd_tolerance >= 0.0 && s.sd_tolerance.is_finite(),
            "simplex.sd_tolerance",
            "must be >= 0",
        )?;
        ensure(
            s.penalty >= 0.0 && s.penalty.is_finite(),
            "simplex.penalty",
            "must be >= 0",
        )?;
        let h = &self.hill_climbing;
        ensure(h.batch >= 1, "hill_climbing.batch", "must be >= 1")?;
        positive("hill_climbing.step", h.step)?;
        ensure(
            h.shrink > 0.0 && h.shrink <= 1.0,
            "hill_climbing.shrink",
            "must be in (0, 1]",
        )?;
        ensure(
            h.grow >= 1.0 && h.grow.is_finite(),
            "hill_climbing.grow",
            "must be >= 1",
        )
    }
}

/// The gradient-free methods, in table order.
pub const SEARCHES: [&str; 3] = ["annealing", "simplex", "hill_climbing"];
/// Every method, in table order.
pub const METHODS: [&str; 5] = [
    "bptt_momentum",
    "bptt_plain",
    "annealing",
    "simplex",
    "hill_climbing",
];

/// One finished run.
struct Run {
    method: &'static str,
    substrate: &'static str,
    result: SearchResult,
}

impl Params {
    /// A gradient-free search on one problem.
    fn search<P: SearchProblem>(
        &self,
        method: &str,
        problem: &P,
        v0: &[f64],
        budget: &SearchBudget,
        seed: u64,
    ) -> Result<SearchResult, Error> {
        let b = budget.budget();
        let r = match method {
            "annealing" => anneal(
                problem,
                v0,
                &self.annealing.config(budget.evaluations),
                seed,
                &b,
            ),
            "simplex" => {
                let s = &self.simplex;
                let cfg = SimplexConfig {
                    step: s.step,
                    sd_tolerance: s.sd_tolerance,
                    penalty: s.penalty,
                    restarts: s.restarts,
                };
                nelder_mead(problem, v0, &cfg, &b)
            }
            _ => {
                let h = &self.hill_climbing;
                let cfg = ClimbConfig {
                    batch: h.batch,
                    step: h.step,
                    shrink: h.shrink,
                    grow: h.grow,
                };
                hill_climb(problem, v0, &cfg, seed, &b)
            }
        };
        r.map_err(super::other)
    }
}

impl Params {
    /// The two BPTT runs (momentum, plain) through `problem`'s net from `v0`, with the step
    /// scale λ measured there first (its cost charged to both); `substrate` names the net
    /// (`emulator`: the Table 1 net, whose stages keep their plain names).
    fn bptt_runs(
        &self,
        ctx: &RunContext,
        problem: &BpttProblem<'_, crate::emulator::Emulator>,
        v0: &[f64],
        substrate: &'static str,
    ) -> Result<Vec<Run>, Error> {
        let label = |name: &str| {
            if substrate == "emulator" {
                name.to_string()
            } else {
                format!("{name} ({substrate})")
            }
        };
        let (lambda, spent) = ctx.stage(&label("curvature"), || {
            problem.curvature(v0, self.curvature_iterations)
        });
        if !(lambda.is_finite() && lambda > 0.0) {
            return Err(super::other(format!(
                "dolphin ({substrate}): step scale λ = {lambda}"
            )));
        }
        let b = &self.bptt;
        let mut runs = vec![];
        for (method, descent) in [
            (
                "bptt_momentum",
                Descent::Momentum {
                    eta: b.eta,
                    alpha: b.alpha,
                },
            ),
            ("bptt_plain", Descent::Plain { eta: b.plain_eta }),
        ] {
            let (result, _) = ctx
                .stage(&label(method), || {
                    bptt_search(
                        problem,
                        v0,
                        descent,
                        lambda,
                        &Budget::iterations(b.iterations),
                        spent,
                    )
                })
                .map_err(super::other)?;
            runs.push(Run {
                method,
                substrate,
                result,
            });
        }
        Ok(runs)
    }
}

fn opt(v: Option<f64>) -> f64 {
    v.unwrap_or(f64::NAN)
}

impl Job for Params {
    fn params_json(&self) -> serde_json::Value {
        serde_json::to_value(self).unwrap_or_default()
    }

    fn run(&self, ctx: &RunContext) -> Result<Tables, Error> {
        let spec = self.nets.spec(ctx.seed, self.steps, self.example_scale);
        let built = ctx.stage("train dolphin hierarchy", || build_dolphin_emulator(&spec))?;
        let body = built.emulator.dolphin().clone();
        let global = built.emulator.global();
        let swim = &self.swim;
        let objective = swim.objective();
        let knots = swim.knot_layout();
        let (x0, g0) = swim.start(&body);
        let bptt =
            Bptt::new(global, &objective, knots, swim.bounds(), &g0).map_err(super::other)?;
        // The initial knots of na_fig13_control's dolphin.
        let mut rng = ctx.rng(400);
        let v0: Vec<f64> = (0..knots.len())
            .map(|_| self.init_spread * (2.0 * rng.random::<f64>() - 1.0))
            .collect();
        let emulator = BpttProblem::new(&bptt);
        let simulator = ReplayProblem::new(
            &bptt,
            || Box::new(hierarchy::simulator(&body)) as Box<dyn crate::physics::Dynamics>,
            &x0,
            self.nets.physical_dt,
            self.steps,
            Box::new(|x: &[f64], out: &mut [f64]| global_state(&body, x, out)),
        )
        .map_err(super::other)?;

        let mut runs: Vec<Run> = vec![];
        runs.extend(self.bptt_runs(ctx, &emulator, &v0, "emulator")?);
        let pb = ctx.progress(2 * SEARCHES.len() as u64, "gradient-free searches");
        for (k, method) in SEARCHES.into_iter().enumerate() {
            let seed = mix_seed(ctx.seed, 410 + k as u64);
            let result = ctx.stage(&format!("{method} emulator"), || {
                self.search(method, &emulator, &v0, &self.budget.emulator, seed)
            })?;
            runs.push(Run {
                method,
                substrate: "emulator",
                result,
            });
            pb.inc(1);
            let result = ctx.stage(&format!("{method} simulator"), || {
                self.search(method, &simulator, &v0, &self.budget.simulator, seed)
            })?;
            runs.push(Run {
                method,
                substrate: "simulator",
                result,
            });
            pb.inc(1);
        }
        pb.finish_and_clear();

        // The same runs on the dolphin's last-round DAgger net (ours), from the same start.
        let dagger_net = match &self.dagger {
            Some(d) => Some(self.fig13(d).dolphin_dagger_net(ctx)?),
            None => None,
        };
        let dagger_bptt = match &dagger_net {
            Some(net) => {
                Some(Bptt::new(net, &objective, knots, swim.bounds(), &g0).map_err(super::other)?)
            }
            None => None,
        };
        if let Some(b) = &dagger_bptt {
            let problem = BpttProblem::new(b);
            runs.extend(self.bptt_runs(ctx, &problem, &v0, DAGGER_SUBSTRATE)?);
            for (k, method) in SEARCHES.into_iter().enumerate() {
                let seed = mix_seed(ctx.seed, 410 + k as u64);
                let result = ctx.stage(&format!("{method} ({DAGGER_SUBSTRATE})"), || {
                    self.search(method, &problem, &v0, &self.budget.emulator, seed)
                })?;
                runs.push(Run {
                    method,
                    substrate: DAGGER_SUBSTRATE,
                    result,
                });
            }
        }

        let mut baselines = Table::new(&[
            "method",
            "substrate",
            "iteration",
            "evaluations",
            "seconds",
            "objective",
            "gradients",
            "current",
        ]);
        for r in &runs {
            for t in &r.result.trace {
                baselines.push(row![
                    r.method,
                    r.substrate,
                    t.iteration,
                    t.evaluations,
                    t.seconds,
                    t.best,
                    t.gradients,
                    t.current
                ]);
            }
        }
        // Every run's best knots on both substrates.
        let on_both = |v: &[f64]| -> (f64, f64, f64, f64) {
            if v.iter().any(|x| !x.is_finite()) {
                return (f64::NAN, f64::NAN, f64::NAN, f64::NAN);
            }
            let (je, de) = emulator.with_bptt(|b| {
                let j = b.rollout(v);
                (j, swim.distance(b.states()))
            });
            let sim = simulator.rollout(v);
            (je, sim.objective, de, swim.distance(&sim.states))
        };
        let evaluated: Vec<(f64, f64, f64, f64)> =
            runs.iter().map(|r| on_both(&r.result.best)).collect();
        let momentum = runs
            .iter()
            .position(|r| r.method == "bptt_momentum")
            .expect("the momentum run is first");
        let targets = (evaluated[momentum].0, evaluated[momentum].1);
        // On the DAgger net: its own momentum run's best J there.
        let dagger_target = runs
            .iter()
            .find(|r| r.method == "bptt_momentum" && r.substrate == DAGGER_SUBSTRATE)
            .map_or(f64::NAN, |r| r.result.best_value);
        let mut final_t = Table::new(&[
            "method",
            "substrate",
            "iterations",
            "evaluations",
            "seconds",
            "objective_substrate",
            "objective_emulator",
            "objective_simulator",
            "distance_emulator_m",
            "distance_simulator_m",
            "target",
            "iterations_to_bptt",
            "evaluations_to_bptt",
            "seconds_to_bptt",
            "best_iteration",
        ]);
        for (r, &(je, js, de, ds)) in runs.iter().zip(&evaluated) {
            let target = match r.substrate {
                "emulator" => targets.0,
                DAGGER_SUBSTRATE => dagger_target,
                _ => targets.1,
            };
            let trace = &r.result.trace;
            let last = trace.last().expect("a search has iteration 0");
            let reached = time_to_target(trace, target);
            let own = time_to_target(trace, r.result.best_value);
            final_t.push(row![
                r.method,
                r.substrate,
                last.iteration,
                last.evaluations,
                last.seconds,
                r.result.best_value,
                je,
                js,
                de,
                ds,
                target,
                opt(reached.map(|x| x.iteration as f64)),
                opt(reached.map(|x| x.evaluations as f64)),
                opt(reached.map(|x| x.seconds)),
                opt(own.map(|x| x.iteration as f64))
            ]);
        }
        Ok(Tables::from([("baselines", baselines), ("final", final_t)]))
    }
}

/// (method, substrate) pairs in first-seen order.
fn curves(method: &[String], substrate: &[String]) -> Vec<(String, String)> {
    let mut out: Vec<(String, String)> = vec![];
    for (m, s) in method.iter().zip(substrate) {
        if !out.iter().any(|(a, b)| a == m && b == s) {
            out.push((m.clone(), s.clone()));
        }
    }
    out
}

impl Family for NaBaselines {
    const KIND: &'static str = "na_baselines_swim";
    type Params = Params;

    fn figures(&self, fig: &FigureSink, tables: &Tables) -> Result<Vec<PathBuf>, Error> {
        let t = tables.require("baselines")?;
        let (meth, sub, it, secs, obj) = (
            t.strs("method"),
            t.strs("substrate"),
            t.f64s("iteration"),
            t.f64s("seconds"),
            t.f64s("objective"),
        );
        // `dagger`: the runs on the DAgger net alone, else the others.
        let series = |x: &dyn Fn(usize) -> f64, dagger: bool| -> Vec<Series> {
            curves(&meth, &sub)
                .iter()
                .filter(|(_, s)| (s == DAGGER_SUBSTRATE) == dagger)
                .map(|(m, s)| {
                    let pts = (0..meth.len())
                        .filter(|&r| &meth[r] == m && &sub[r] == s && obj[r].is_finite())
                        .map(|r| (x(r), obj[r]))
                        .filter(|p| p.0 > 0.0)
                        .collect();
                    let color = METHODS.iter().position(|x| x == m).unwrap_or(0);
                    let line = Series::line(format!("{m} ({s})"), pts, color);
                    if s == "simulator" {
                        line.mark(Mark::Dashed)
                    } else {
                        line
                    }
                })
                .collect()
        };
        // The first two panels draw the same series in the same colours, so the key is drawn
        // once, in the wall-clock panel: in the iteration panel every corner's key box hid part
        // of a curve (hill_climbing (simulator) around iterations 10-40).
        let mut by_iteration = series(&|r| it[r] + 1.0, false);
        by_iteration.iter_mut().for_each(|s| s.label.clear());
        let mut panels = vec![
            Panel {
                title: "dolphin swim: objective vs iterations (key: next panel)".into(),
                x_label: "iteration + 1 (log)".into(),
                y_label: "best objective J (effort - distance in m)".into(),
                log_x: true,
                series: by_iteration,
                ..Panel::default()
            },
            Panel {
                title: "dolphin swim: objective vs wall-clock time".into(),
                x_label: "wall-clock seconds (log)".into(),
                y_label: "best objective J (effort - distance in m)".into(),
                log_x: true,
                series: series(&|r| secs[r], false),
                ..Panel::default()
            },
        ];
        let on_dagger = series(&|r| it[r] + 1.0, true);
        if !on_dagger.is_empty() {
            panels.push(Panel {
                title: "the same on the DAgger global net (ours)".into(),
                x_label: "iteration + 1 (log)".into(),
                y_label: "best objective J on the DAgger net".into(),
                log_x: true,
                series: on_dagger,
                ..Panel::default()
            });
        }
        let cols = panels.len();
        fig.draw("objective", &Figure::grid(panels, cols))
    }

    fn report(&self, dir: &Path) -> Result<Findings, Error> {
        let f = read_csv(&dir.join("final.csv"))?;
        let (meth, sub) = (df_str(&f, "method")?, df_str(&f, "substrate")?);
        let col = |name: &str| df_f64(&f, name);
        let (iters, evals, secs) = (col("iterations")?, col("evaluations")?, col("seconds")?);
        let (j_sub, j_emu, j_sim) = (
            col("objective_substrate")?,
            col("objective_emulator")?,
            col("objective_simulator")?,
        );
        let (d_emu, d_sim) = (col("distance_emulator_m")?, col("distance_simulator_m")?);
        let (target, k_to, e_to, s_to) = (
            col("target")?,
            col("iterations_to_bptt")?,
            col("evaluations_to_bptt")?,
            col("seconds_to_bptt")?,
        );
        let row_of = |m: &str, s: &str| (0..meth.len()).find(|&r| meth[r] == m && sub[r] == s);
        let mom = row_of("bptt_momentum", "emulator")
            .ok_or_else(|| super::other("no bptt_momentum run"))?;
        let reach = |r: usize| -> String {
            if k_to[r].is_finite() {
                format!("{} / {} / {}", k_to[r], e_to[r], sig(s_to[r]))
            } else {
                "never".into()
            }
        };
        let mut md = String::from(
            "| method | substrate | iterations / evaluations / s run | to BPTT's J: iterations / evaluations / s | J on substrate | J emulator | J simulator | distance emulator (m) | distance simulator (m) |\n| --- | --- | --- | --- | --- | --- | --- | --- | --- |\n",
        );
        for r in 0..meth.len() {
            md.push_str(&format!(
                "| {} | {} | {} / {} / {} | {} | {} | {} | {} | {} | {} |\n",
                meth[r],
                sub[r],
                iters[r],
                evals[r],
                sig(secs[r]),
                reach(r),
                sig(j_sub[r]),
                sig(j_emu[r]),
                sig(j_sim[r]),
                sig(d_emu[r]),
                sig(d_sim[r])
            ));
        }
        // The rule on one emulator substrate: BPTT-momentum's row there, whether it is fast
        // (its result within 30 iterations), the gradient-free methods that need >= 10x its
        // iterations there (or never get there within their budget) and those that do not,
        // a note per method, the farthest the methods' knots learned there swim on the
        // simulator, and the verdict (held: fast, every method slow, BPTT's knots swim at
        // least as far; partly: fast and some method slow).
        let judge = |substrate: &str| -> Option<Judged> {
            let mom = row_of("bptt_momentum", substrate)?;
            let k_bptt = k_to[mom];
            let bptt_fast = k_bptt.is_finite() && k_bptt <= 30.0;
            let (mut slow, mut fast, mut notes) = (vec![], vec![], vec![]);
            for m in SEARCHES {
                let Some(r) = row_of(m, substrate) else {
                    continue;
                };
                let ok = !k_to[r].is_finite() || k_to[r] >= 10.0 * k_bptt.max(1.0);
                if ok {
                    slow.push(m);
                } else {
                    fast.push(m);
                }
                notes.push(if k_to[r].is_finite() {
                    format!(
                        "{m} reached it after {} iterations ({}x, {} s vs {} s)",
                        k_to[r],
                        sig(k_to[r] / k_bptt.max(1.0)),
                        sig(s_to[r]),
                        sig(s_to[mom])
                    )
                } else {
                    format!(
                        "{m} never did in {} iterations / {} evaluations (best J {})",
                        iters[r],
                        evals[r],
                        sig(j_sub[r])
                    )
                });
            }
            let rival_sim = SEARCHES
                .iter()
                .filter_map(|m| row_of(m, substrate))
                .map(|r| d_sim[r])
                .fold(f64::NEG_INFINITY, f64::max);
            let verdict = Verdict::graded(
                bptt_fast && fast.is_empty() && !slow.is_empty() && d_sim[mom] >= rival_sim,
                bptt_fast && !slow.is_empty(),
            );
            Some(Judged {
                mom,
                k_bptt,
                notes,
                rival_sim,
                verdict,
            })
        };
        let main = judge("emulator").ok_or_else(|| super::other("no bptt_momentum run"))?;
        let (k_bptt, notes, rival_sim, verdict) =
            (main.k_bptt, &main.notes, main.rival_sim, main.verdict);
        let sim_notes: Vec<String> = SEARCHES
            .iter()
            .filter_map(|m| row_of(m, "simulator"))
            .map(|r| {
                if k_to[r].is_finite() {
                    format!(
                        "{} reached it after {} iterations ({} s)",
                        meth[r],
                        k_to[r],
                        sig(s_to[r])
                    )
                } else {
                    format!(
                        "{} never did in {} iterations / {} evaluations / {} s (best J {})",
                        meth[r],
                        iters[r],
                        evals[r],
                        sig(secs[r]),
                        sig(j_sub[r])
                    )
                }
            })
            .collect();
        // How the momentum iterate's J moved (a monotone descent never rises).
        let b = read_csv(&dir.join("baselines.csv"))?;
        let (bm, bs, cur) = (
            df_str(&b, "method")?,
            df_str(&b, "substrate")?,
            df_f64(&b, "current")?,
        );
        let mom_j: Vec<f64> = (0..bm.len())
            .filter(|&r| bm[r] == "bptt_momentum" && bs[r] == "emulator")
            .map(|r| cur[r])
            .collect();
        let rises = mom_j.windows(2).filter(|w| w[1] > w[0]).count();
        let sim_target = (0..meth.len())
            .find(|&r| sub[r] == "simulator")
            .map_or(f64::NAN, |r| target[r]);
        // The same rule on the DAgger net (ours; a line beside the headline, rule in the spec).
        let dagger_line = match judge(DAGGER_SUBSTRATE) {
            Some(g) => format!(
                " On the dolphin's last-round DAgger global net (ours, substrate `{DAGGER_SUBSTRATE}`, the same start and budgets): BPTT with momentum reaches its best J = {} at iteration {}; {}. Replayed on the simulator, BPTT's knots learned there swim {} m, the gradient-free methods' at most {} m. The same rule on the DAgger net: {}.",
                sig(j_sub[g.mom]),
                g.k_bptt,
                g.notes.join("; "),
                sig(d_sim[g.mom]),
                sig(g.rival_sim),
                g.verdict.label()
            ),
            None => String::new(),
        };
        Ok(Findings {
            ours: md,
            verdict,
            why: format!(
                "BPTT with momentum reaches its best emulator J = {} at iteration {} ({} s, the step-scale estimate included; its iterate's J rose in {rises} of {} steps; its knots swim {} m on the simulator vs {} m on the emulator). On the emulator, {}. On the physical simulator (target: BPTT's knots replayed there, J = {}), {}. Replayed on the simulator, BPTT's knots swim {} m, the gradient-free methods' emulator-learned knots at most {} m. Held needs BPTT to reach its result within 30 iterations, every gradient-free method on the emulator to need at least 10x as many iterations or never reach it, and BPTT's knots to swim on the simulator at least as far as every gradient-free method's emulator-learned knots (the emulator's ranking holds on the physical model); partly: BPTT fast and at least one method slow. An iteration is one annealing proposal, one simplex step, one hill-climbing batch (several evaluations) or one gradient step; budgets are far below the paper's hour, so 'never' means 'not within the budget'. Seconds are this machine's wall clock.",
                sig(j_sub[mom]),
                k_bptt,
                sig(s_to[mom]),
                mom_j.len().saturating_sub(1),
                sig(d_sim[mom]),
                sig(d_emu[mom]),
                notes.join("; "),
                sig(sim_target),
                sim_notes.join("; "),
                sig(d_sim[mom]),
                sig(rival_sim)
            ) + &dagger_line,
        })
    }
}

/// The verdict rule's parts on one emulator substrate (see `report`).
struct Judged {
    mom: usize,
    k_bptt: f64,
    notes: Vec<String>,
    rival_sim: f64,
    verdict: Verdict,
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The DAgger net searched on is `na_fig13_control`'s: this file's task, nets, BPTT
    /// settings and `[params.dagger]` rebuild exactly its dolphin task and chain (and its
    /// steps, step-scale iterations and example scale), so the chain's cache keys agree.
    #[test]
    fn the_dagger_net_is_fig13s_dolphin_chain() {
        use crate::experiment::spec::SpecFile;
        let params = |file: &str| -> toml::Table {
            let f = SpecFile::load(std::path::Path::new(file)).unwrap();
            f.raw.params
        };
        let ours: Params = toml::Value::Table(params("experiments/na_baselines_swim.toml"))
            .try_into()
            .unwrap();
        let theirs: crate::families::na::fig13_control::Params =
            toml::Value::Table(params("experiments/na_fig13_control.toml"))
                .try_into()
                .unwrap();
        let built = ours.fig13(&ours.dagger.expect("the spec runs the DAgger net"));
        assert_eq!(
            serde_json::to_value(&built.dolphin).unwrap(),
            serde_json::to_value(&theirs.dolphin).unwrap(),
            "dolphin task and chain"
        );
        assert_eq!(
            (built.steps, built.curvature_iterations, built.example_scale),
            (
                theirs.steps,
                theirs.curvature_iterations,
                theirs.example_scale
            )
        );
    }

    #[test]
    fn annealing_cools_from_start_to_end_over_the_budget() {
        let a = AnnealingSettings {
            initial_samples: 8,
            start_temperature: 0.5,
            end_temperature: 0.005,
            step: 0.1,
            end_step: 0.01,
        };
        let c = a.config(1009);
        assert_eq!(c.temperature.at(1.0, 1), 0.5);
        assert!((c.temperature.at(1.0, 1000) - 0.005).abs() < 1e-9);
        assert!((c.step.at(1.0, 1000) - 0.01).abs() < 1e-9);
    }

    #[test]
    fn curves_keep_first_seen_order() {
        let m: Vec<String> = ["a", "a", "b", "a"].map(String::from).to_vec();
        let s: Vec<String> = ["e", "e", "e", "s"].map(String::from).to_vec();
        assert_eq!(
            curves(&m, &s),
            vec![
                ("a".into(), "e".into()),
                ("b".into(), "e".into()),
                ("a".into(), "s".into())
            ]
        );
    }
}
