//! # `na_transforms_ablation` (NeuroAnimator §3.2, Fig. 6): the emulator's transforms, one at a time
//!
//! The paper wraps each emulator net in fixed transforms (Fig. 6): the net predicts the state
//! change (T^Δ) in the model's local frame (T'), on normalized inputs and outputs (T^σ,
//! Appendix A's groups), and says each operator makes the net easier to train and that the
//! invariant emulator was crucial. This experiment builds the emulator of each Fig. 13 task
//! four ways on the same data, net size, training and budget ([`TransformSet`]: `plain`, the
//! bare net predicting the next state; `delta`; `delta_frame`; `full`, the Fig. 13 net itself,
//! so a warm run loads it from the cache) and measures, for each:
//!
//! - the one-step and 40-step rollout error against the simulator, in units of each state
//!   variable's spread ([`rollout_error`], Table 1's measure);
//! - the zero-control drift from the task's start: 40 super-steps under the rest control, the
//!   emulator's and the simulator's end positions apart (m);
//! - Fig. 13's control learned through it (the task's momentum, η, α and iteration count;
//!   actuator gains and final-state weights calibrated once through the `full` net and then
//!   fixed for every variant, so all learn the same objective), replayed on the simulator.
//!
//! Tables: `nets` (task, variant, inputs, hidden, outputs, examples, weights, train_s, stop,
//! cached, failed), `errors` (task, variant, rollout1_error, rollout40_error_mean,
//! rollout40_error_final, drift_emulator_m, drift_simulator_m, drift_gap_m), `rollout` (task,
//! variant, step, error), `control` (task, variant, iterations, best_iteration, j_start, j_best,
//! emulator_error, simulator_error, at_goal, start_simulator_error: the start's controls
//! replayed, the same on every row of a task), `rule` (setting, value). Figures: `<id>_rollout` (rollout error against the
//! super-step, one line per variant, a panel per task) and `<id>_summary` (each measure against
//! the variant, one line per task). A variant whose training fails (non-finite) is a row with
//! `failed = 1` and empty measures: it counts as an infinite error in the rule.
//!
//! Verdict ([`ablation_rule`], thresholds ours in the spec's `[params.rule]`): per task, (a)
//! the full chain's 40-step error at most `full_over_plain` of the plain net's; (b) every added
//! operator lowers the 40-step error below `operator_ratio` of the previous variant's (an
//! operator that changes nothing scores 1 and fails); (c) the control learned through the full
//! chain ends within tolerance on the simulator (its null: the start's controls replayed);
//! (d) that control's simulator error below `control_over_plain` of the plain net's control's.
//! Held: every check; partly: (a) for every task (the training half of the claim).

use crate::emulator::cache::EmulatorCache;
use crate::emulator::catalog::{rollout_error, BuildSpec, NetModel, TrainSettings, TransformSet};
use crate::emulator::hierarchy::{
    build_global, hierarchy_rollout_error, HierarchySpec, NetReport, GLOBAL_DIM,
};
use crate::emulator::Emulator;
use crate::experiment::output::{df_f64, df_str, read_csv, Table, Tables};
use crate::experiment::plot::{Figure, FigureSink, Mark, Panel, Series};
use crate::experiment::report::{sig, Findings};
use crate::experiment::resolve::{each_bar, ensure, ParamError, Validate};
use crate::experiment::rule::{
    rule_settings, rule_table_of, shown, Check, Cmp, Null, Partly, Rule,
};
use crate::experiment::stats::{bootstrap_intervals, median_with_infinities};
use crate::experiment::{other, Error, Family, Job, RunContext};
use crate::families::na::fig13_control::{
    learn_and_replay, learn_swim, start_simulator_error, DolphinControl, Formulation, Task,
};
use crate::families::na::table1_structure::{
    build_dolphin_emulator, build_emulator, build_spec, dolphin_drift, position_part,
    validate_nets, validate_training,
};
use crate::physics::dolphin::N_SEGMENTS;
use crate::row;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// The family.
pub struct NaTransforms;

/// Parameters of `na_transforms_ablation`.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Params {
    /// Physical steps per emulator step (Fig. 13: N50).
    pub steps: usize,
    /// Scale of every net's training examples (1 = Table 1's).
    pub example_scale: f64,
    /// Power iterations of the step scale λ (as Fig. 13).
    pub curvature_iterations: usize,
    /// The variants, operators added in order; must include `full` (it calibrates the tasks).
    pub variants: Vec<TransformSet>,
    /// Rollout episodes of the rollout error.
    pub rollout_episodes: usize,
    /// Super-steps of the rollouts and of the drift.
    pub rollout_steps: usize,
    /// The Fig. 13 tasks (paper formulation), their nets as Fig. 13's.
    pub tasks: Vec<Task>,
    /// Training settings (Fig. 13's, so the `full` nets are the cached Fig. 13 nets).
    pub training: TrainSettings,
    /// The dolphin's global net (Fig. 13's hierarchy and swim), its variants composed with the
    /// whole chain's local nets, if run.
    #[serde(default)]
    pub dolphin: Option<DolphinControl>,
    /// The verdict's thresholds (ours).
    pub rule: AblationRule,
    /// Further seeds of the tasks' nets (beside the run's own): every variant of every task
    /// (not the dolphin) is built and measured again through each (`net_seeds.csv`), and the
    /// tasks' checks read the median over the seeds. At most [`MAX_NET_SEEDS`].
    #[serde(default)]
    pub net_seeds: Vec<u64>,
}

/// The most net seeds a run may name (each is a set of variant nets to train when not cached).
pub const MAX_NET_SEEDS: usize = 16;

/// The verdict's thresholds ([`ablation_rule`]; ours).
#[derive(Debug, Clone, Copy, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AblationRule {
    /// An added operator helps when it lowers the 40-step error below this fraction of the
    /// previous variant's (an operator that changes nothing scores 1, so it must be below 1).
    pub operator_ratio: f64,
    /// The full chain's 40-step error must be at most this fraction of the plain net's.
    pub full_over_plain: f64,
    /// The control learned through the full chain must end on the simulator below this
    /// fraction of the plain net's control's final error.
    pub control_over_plain: f64,
}

impl AblationRule {
    /// Every ratio in (0, 1): 1 is what a variant that changes nothing scores.
    fn validate(&self) -> Result<(), ParamError> {
        each_bar(
            self,
            |v| v > 0.0 && v < 1.0,
            "must be in (0, 1): a ratio of 1 is what a variant that changes nothing scores",
        )
    }
}

/// A final error of at most 1 is within the task's tolerance (the unit of the final error).
const WITHIN_TOLERANCE: f64 = 1.0;

impl Validate for Params {
    fn validate(&self) -> Result<(), ParamError> {
        ensure(self.steps >= 1, "steps", "must be >= 1")?;
        ensure(
            self.curvature_iterations >= 1,
            "curvature_iterations",
            "must be >= 1",
        )?;
        ensure(
            self.variants.contains(&TransformSet::Full),
            "variants",
            "must include `full` (the tasks are calibrated through it)",
        )?;
        for (i, v) in self.variants.iter().enumerate() {
            ensure(
                !self.variants[..i].contains(v),
                &format!("variants[{i}]"),
                format!("`{}` is listed twice", v.name()),
            )?;
        }
        ensure(
            self.rollout_episodes >= 1 && self.rollout_steps >= 1,
            "rollout_episodes",
            "rollout_episodes and rollout_steps must be >= 1",
        )?;
        ensure(!self.tasks.is_empty(), "tasks", "need at least one task")?;
        for (i, t) in self.tasks.iter().enumerate() {
            t.validate_at(i)?;
            ensure(
                t.net.transforms == TransformSet::Full,
                &format!("tasks[{i}].net.transforms"),
                "leave it out: the experiment builds every variant of `variants`",
            )?;
            ensure(
                t.formulation == Formulation::Paper,
                &format!("tasks[{i}].formulation"),
                "the ablation runs the paper's formulation",
            )?;
        }
        let nets: Vec<_> = self.tasks.iter().map(|t| t.net.clone()).collect();
        validate_nets(&nets, self.example_scale)?;
        if let Some(d) = &self.dolphin {
            d.validate("dolphin", self.example_scale)?;
            ensure(
                d.dagger.is_none() && d.ours_swim.is_none(),
                "dolphin",
                "leave out `dagger` and `ours_swim`: the ablation learns the paper's swim only",
            )?;
        }
        self.rule.validate()?;
        ensure(
            self.net_seeds.len() <= MAX_NET_SEEDS,
            "net_seeds",
            format!("at most {MAX_NET_SEEDS}"),
        )?;
        validate_training(&self.training)
    }
}

/// The `control` row of a variant through which nothing was learned (no finite step scale).
fn push_unlearned(
    control: &mut Table,
    task: &str,
    v: TransformSet,
    iterations: usize,
    start_error: f64,
) {
    control.push(row![
        task,
        v.name(),
        iterations,
        0_i64,
        f64::NAN,
        f64::NAN,
        f64::NAN,
        f64::NAN,
        0_i64,
        start_error
    ]);
}

/// One variant's emulator of one task: built, or why not.
type Built = Result<crate::emulator::catalog::Trained, String>;

/// The emulator's and the simulator's positions apart after `steps` super-steps from `x0` under
/// the constant control `u`: (emulator drift, simulator drift, gap), each in metres of the
/// model's position part.
fn drift(e: &Emulator, spec: &BuildSpec, x0: &[f64], u: &[f64], steps: usize) -> [f64; 3] {
    let m = spec.net.model;
    let (mut xe, mut xs, mut next) = (x0.to_vec(), x0.to_vec(), x0.to_vec());
    let mut sc = e.scratch();
    let mut sim = m.simulator();
    for _ in 0..steps {
        e.predict(&xe, u, &mut sc, &mut next);
        xe.copy_from_slice(&next);
        for _ in 0..spec.steps {
            sim.step(&mut xs, u, spec.net.physical_dt);
        }
    }
    let p = position_part(m);
    let d = |a: &[f64], b: &[f64]| {
        a[p.clone()]
            .iter()
            .zip(&b[p.clone()])
            .map(|(x, y)| (x - y).powi(2))
            .sum::<f64>()
            .sqrt()
    };
    [d(&xe, x0), d(&xs, x0), d(&xe, &xs)]
}

/// The tables the job writes.
struct Outputs {
    nets: Table,
    errors: Table,
    rollout: Table,
    control: Table,
    seeds: Table,
}

/// Columns of `net_seeds.csv`: per net seed, task and variant, the measures the rule reads.
const SEED_COLUMNS: [&str; 8] = [
    "net_seed",
    "task",
    "variant",
    "rollout40_error_mean",
    "best_iteration",
    "simulator_error",
    "start_simulator_error",
    "failed",
];

impl Outputs {
    fn new() -> Self {
        Self {
            nets: Table::new(&[
                "task", "variant", "inputs", "hidden", "outputs", "examples", "weights", "train_s",
                "stop", "cached", "failed",
            ]),
            errors: Table::new(&[
                "task",
                "variant",
                "rollout1_error",
                "rollout40_error_mean",
                "rollout40_error_final",
                "drift_emulator_m",
                "drift_simulator_m",
                "drift_gap_m",
            ]),
            rollout: Table::new(&["task", "variant", "step", "error"]),
            control: Table::new(&[
                "task",
                "variant",
                "iterations",
                "best_iteration",
                "j_start",
                "j_best",
                "emulator_error",
                "simulator_error",
                "at_goal",
                "start_simulator_error",
            ]),
            seeds: Table::new(&SEED_COLUMNS),
        }
    }
}

impl Job for Params {
    fn params_json(&self) -> serde_json::Value {
        serde_json::to_value(self).unwrap_or_default()
    }

    fn run(&self, ctx: &RunContext) -> Result<Tables, Error> {
        let mut out = Outputs::new();
        let further = crate::experiment::seeds::further_seeds(&self.net_seeds, ctx.seed);
        let pb = ctx.progress(
            (self.tasks.len() * self.variants.len() * (1 + further.len())) as u64,
            "emulator variants",
        );
        for task in &self.tasks {
            self.run_task(ctx, task, ctx.seed, &mut out, &pb)?;
        }
        // The same through the nets of each further seed: only `net_seeds.csv` keeps them.
        for &s in &further {
            let mut other_seed = Outputs::new();
            for task in &self.tasks {
                self.run_task(ctx, task, s, &mut other_seed, &pb)?;
            }
            out.seeds.append(&other_seed.seeds).map_err(other)?;
        }
        pb.finish_and_clear();
        if let Some(d) = &self.dolphin {
            self.run_dolphin(
                ctx,
                d,
                &mut out.nets,
                &mut out.errors,
                &mut out.rollout,
                &mut out.control,
            )?;
        }
        Ok(Tables::from([
            ("nets", out.nets),
            ("errors", out.errors),
            ("rollout", out.rollout),
            ("control", out.control),
            ("net_seeds", out.seeds),
            ("rule", rule_table_of(&self.rule)?),
        ]))
    }
}

impl Params {
    /// Every variant of `task` built with the nets of `seed` (side by side; from the cache
    /// where there), its rollout error, drift and Fig. 13 control replayed on the simulator,
    /// into `out`.
    fn run_task(
        &self,
        ctx: &RunContext,
        task: &Task,
        seed: u64,
        out: &mut Outputs,
        pb: &indicatif::ProgressBar,
    ) -> Result<(), Error> {
        let model: NetModel = task.net.model;
        let (n, m) = (model.state_dim(), model.control_dim());
        let at = if seed == ctx.seed {
            task.name.clone()
        } else {
            format!("{}, net seed {seed}", task.name)
        };
        let specs: Vec<BuildSpec> = self
            .variants
            .iter()
            .map(|&v| {
                let mut net = task.net.clone();
                net.transforms = v;
                build_spec(seed, &net, self.steps, self.example_scale, &self.training)
            })
            .collect();
        // Side by side; a variant that cannot be trained is a result, not an error.
        let built: Vec<Built> = ctx.stage(&format!("train {at} variants"), || {
            use rayon::prelude::*;
            specs
                .par_iter()
                .map(|s| build_emulator(s).map_err(|e| e.to_string()))
                .collect()
        });
        let x0 = task.start_state();
        let full = self
            .variants
            .iter()
            .position(|&v| v == TransformSet::Full)
            .expect("validated");
        let full_net = built[full]
            .as_ref()
            .map_err(|e| other(format!("{at}: the full emulator failed: {e}")))?;
        // One objective for every variant: gains and weights measured through `full`.
        let cal = task
            .calibrated(&full_net.emulator, &x0)
            .map_err(|e| other(format!("{at}: {e}")))?;
        // The null of the control checks: the start's controls replayed (no net involved
        // but to expand the knots).
        let start_error = start_simulator_error(&cal, &full_net.emulator, self.steps)?;
        let name = task.name.as_str();
        for ((&v, spec), b) in self.variants.iter().zip(&specs).zip(&built) {
            let (inputs, hidden) = (n + m, spec.net.hidden);
            let weights = crate::emulator::mlp::Mlp::weight_count(inputs, hidden, n);
            // (train_s, stop, cached, failed) of the net's row.
            let (train_s, stop, cached, failed) = match b {
                Ok(t) => (t.train_s, t.stop.clone(), i64::from(t.from_cache), 0_i64),
                Err(e) => (f64::NAN, format!("failed: {e}"), 0, 1),
            };
            out.nets.push(row![
                name,
                v.name(),
                inputs,
                hidden,
                n,
                spec.net.examples,
                weights,
                train_s,
                stop.as_str(),
                cached,
                failed
            ]);
            let Ok(trained) = b else {
                out.seeds.push(row![
                    seed as i64,
                    name,
                    v.name(),
                    f64::NAN,
                    0_i64,
                    f64::NAN,
                    start_error,
                    1_i64
                ]);
                pb.inc(1);
                continue;
            };
            let e = &trained.emulator;
            let errs = ctx
                .stage(&format!("rollouts {at} {}", v.name()), || {
                    rollout_error(e, spec, self.rollout_episodes, self.rollout_steps)
                })
                .map_err(other)?;
            for (k, x) in errs.iter().enumerate() {
                out.rollout.push(row![name, v.name(), k + 1, *x]);
            }
            let rollout40 = errs.iter().sum::<f64>() / errs.len() as f64;
            let [de, ds, gap] = drift(e, spec, &x0, &task.rest_control(), self.rollout_steps);
            out.errors.push(row![
                name,
                v.name(),
                errs[0],
                rollout40,
                errs[errs.len() - 1],
                de,
                ds,
                gap
            ]);
            // Fig. 13's control through this variant, replayed on the simulator.
            let learned = ctx.stage(&format!("learn {at} {}", v.name()), || {
                learn_and_replay(&cal, e, self.steps, self.curvature_iterations)
            })?;
            let (best_iteration, simulator_error) = match learned {
                Some((run, r)) => {
                    out.control.push(row![
                        name,
                        v.name(),
                        task.task.iterations,
                        run.best_iteration,
                        r.trace.first().map_or(f64::NAN, |t| t.objective),
                        r.best_objective(),
                        run.emulator_error,
                        run.simulator_error,
                        i64::from(run.at_goal()),
                        start_error
                    ]);
                    (run.best_iteration as i64, run.simulator_error)
                }
                // No finite step scale through this net: nothing learned.
                None => {
                    push_unlearned(&mut out.control, name, v, task.task.iterations, start_error);
                    (0, f64::NAN)
                }
            };
            out.seeds.push(row![
                seed as i64,
                name,
                v.name(),
                rollout40,
                best_iteration,
                simulator_error,
                start_error,
                0_i64
            ]);
            pb.inc(1);
        }
        Ok(())
    }
}

impl Params {
    /// The dolphin's rows: each variant of its global net (the whole chain's is Fig. 13's,
    /// from the cache; the others trained on the same examples and budget), composed with the
    /// whole chain's local nets for the rollouts; the global net's own rollout error, its
    /// zero-control drift from the rest pose, and Fig. 13's swim learned through it and
    /// replayed on the simulator. The swim's final error is its distance short of the
    /// hand-made wave's on the simulator, in units of half the wave's distance (1 = the swim
    /// goal's bar, half the wave's distance; 0 = at least as far as the wave).
    fn run_dolphin(
        &self,
        ctx: &RunContext,
        d: &DolphinControl,
        nets: &mut Table,
        errors: &mut Table,
        rollout: &mut Table,
        control: &mut Table,
    ) -> Result<(), Error> {
        use rayon::prelude::*;
        let spec = d.nets.spec(ctx.seed, self.steps, self.example_scale);
        let built = ctx.stage("train dolphin hierarchy", || build_dolphin_emulator(&spec))?;
        let cache = EmulatorCache::from_env();
        let variants: Vec<Result<(Emulator, NetReport), String>> =
            ctx.stage("train dolphin global-net variants", || {
                self.variants
                    .par_iter()
                    .map(|&v| {
                        if v == TransformSet::Full {
                            return Ok((built.emulator.global().clone(), built.nets[0].clone()));
                        }
                        let s = HierarchySpec {
                            global_transforms: v,
                            ..spec.clone()
                        };
                        build_global(&s, &cache).map_err(|e| e.to_string())
                    })
                    .collect()
            });
        let body = built.emulator.dolphin().clone();
        let swim = &d.swim;
        let (x0, _) = swim.start(&body);
        let (dt, n) = (d.nets.physical_dt, self.steps);
        let knots = swim.knot_layout();
        let mut wave_u = vec![0.0; knots.steps * knots.m];
        knots.expand(&swim.reference_knots(dt * n as f64), &mut wave_u);
        let (_, wave_g) = swim.simulate(&body, &x0, &wave_u, dt, n).map_err(other)?;
        let wave = swim.distance(&wave_g);
        let short = |dist: f64| (wave - dist).max(0.0) / (0.5 * wave);
        // The null of the control checks: the dolphin at rest (zero controls) over the swim.
        let rest_u = vec![0.0; knots.steps * knots.m];
        let (_, rest_g) = swim.simulate(&body, &x0, &rest_u, dt, n).map_err(other)?;
        let start_error = short(swim.distance(&rest_g));
        let apart = |a: &[f64], b: &[f64]| {
            a.iter()
                .zip(b)
                .map(|(x, y)| (x - y).powi(2))
                .sum::<f64>()
                .sqrt()
        };
        let (inputs, outputs) = (GLOBAL_DIM + N_SEGMENTS, GLOBAL_DIM);
        let weights =
            crate::emulator::mlp::Mlp::weight_count(inputs, d.nets.global.hidden, outputs);
        for (&v, b) in self.variants.iter().zip(variants) {
            let (global, rep) = match b {
                Ok(x) => x,
                Err(e) => {
                    nets.push(row![
                        "dolphin",
                        v.name(),
                        inputs,
                        d.nets.global.hidden,
                        outputs,
                        spec.global.examples,
                        weights,
                        f64::NAN,
                        format!("failed: {e}").as_str(),
                        0_i64,
                        1_i64
                    ]);
                    continue;
                }
            };
            nets.push(row![
                "dolphin",
                v.name(),
                inputs,
                rep.hidden,
                outputs,
                rep.examples,
                weights,
                rep.train_s,
                rep.stop.as_str(),
                i64::from(rep.from_cache),
                0_i64
            ]);
            let composed = built.emulator.with_global(global.clone());
            let (errs, _) = ctx
                .stage(&format!("rollouts dolphin {}", v.name()), || {
                    hierarchy_rollout_error(
                        &composed,
                        &spec,
                        self.rollout_episodes,
                        self.rollout_steps,
                    )
                })
                .map_err(other)?;
            for (k, x) in errs.iter().enumerate() {
                rollout.push(row!["dolphin", v.name(), k + 1, *x]);
            }
            let [emu, sim, start] =
                dolphin_drift(&composed, &spec, &[0.0; N_SEGMENTS], self.rollout_steps)?;
            errors.push(row![
                "dolphin",
                v.name(),
                errs[0],
                errs.iter().sum::<f64>() / errs.len() as f64,
                errs[errs.len() - 1],
                apart(&emu, &start),
                apart(&sim, &start),
                apart(&emu, &sim)
            ]);
            // Fig. 13's swim through this variant; a net without a finite step scale learns
            // nothing (a result, as for the other tasks: without a table of starts to fill,
            // `learn_swim` fails only there or building the net's BPTT).
            let label = format!(" {}", v.name());
            match learn_swim(
                ctx,
                d,
                &global,
                &body,
                n,
                self.curvature_iterations,
                &label,
                None,
            ) {
                Ok((r, best)) => {
                    let (_, sim_g) = swim
                        .simulate(&body, &x0, &best.controls, dt, n)
                        .map_err(other)?;
                    let (e_emu, e_sim) = (
                        short(swim.distance(&best.states)),
                        short(swim.distance(&sim_g)),
                    );
                    control.push(row![
                        "dolphin",
                        v.name(),
                        d.iterations,
                        r.best_iteration,
                        r.trace.first().map_or(f64::NAN, |t| t.objective),
                        r.best_objective(),
                        e_emu,
                        e_sim,
                        i64::from(e_emu <= WITHIN_TOLERANCE && e_sim <= WITHIN_TOLERANCE),
                        start_error
                    ]);
                }
                Err(_) => push_unlearned(control, "dolphin", v, d.iterations, start_error),
            }
        }
        Ok(())
    }
}

/// One variant's measures: its name, 40-step mean rollout error, the simulator final error of
/// the control learned through it and that descent's best iteration (0: it never improved on
/// its start).
#[derive(Debug, Clone, PartialEq)]
pub struct VariantRow {
    /// The variant's name.
    pub variant: String,
    /// 40-step mean rollout error (infinite when training failed).
    pub rollout40: f64,
    /// Simulator final error of its control (infinite when nothing was learned).
    pub simulator: f64,
    /// The descent's best iteration.
    pub best_iteration: usize,
}

/// One task's measures per variant, in the spec's variant order, and the simulator final
/// error of the start's controls (the control checks' null).
#[derive(Debug, Clone, PartialEq)]
pub struct TaskRows {
    /// The task.
    pub task: String,
    /// Each variant's measures.
    pub rows: Vec<VariantRow>,
    /// The start's controls replayed on the simulator: their final error.
    pub start: f64,
}

impl TaskRows {
    fn get(&self, v: TransformSet) -> Option<&VariantRow> {
        self.rows.iter().find(|r| r.variant == v.name())
    }

    /// The 40-step errors along plain → delta → delta_frame → full (infinite where missing).
    fn chain(&self) -> Vec<f64> {
        TransformSet::ALL
            .iter()
            .map(|&v| self.get(v).map_or(f64::INFINITY, |r| finite(r.rollout40)))
            .collect()
    }

    /// The largest ratio of an added operator's 40-step error to the previous variant's.
    pub fn worst_operator_ratio(&self) -> f64 {
        self.chain()
            .windows(2)
            .map(|w| ratio(w[1], w[0]))
            .fold(f64::NEG_INFINITY, f64::max)
    }

    /// The simulator final error of the control learned through `v` (infinite where missing).
    fn simulator(&self, v: TransformSet) -> f64 {
        self.get(v).map_or(f64::INFINITY, |r| finite(r.simulator))
    }

    /// The variants whose descent never improved on its start (best iteration 0).
    pub fn stuck(&self) -> Vec<&str> {
        self.rows
            .iter()
            .filter(|r| r.best_iteration == 0 && r.simulator.is_finite())
            .map(|r| r.variant.as_str())
            .collect()
    }
}

/// NaN (a failed measure) as infinite.
fn finite(x: f64) -> f64 {
    if x.is_nan() {
        f64::INFINITY
    } else {
        x
    }
}

/// a / b, infinite over infinite is NaN (fails every check), finite over infinite 0.
fn ratio(a: f64, b: f64) -> f64 {
    if b.is_infinite() && a.is_finite() {
        0.0
    } else {
        a / b
    }
}

/// Bootstrap seed of the intervals over net seeds (fixed, so a report is the same everywhere).
const BOOTSTRAP_SEED: u64 = 1;

/// One task's values of checks (a)-(d) at one net seed, and each check's null there.
fn task_values(t: &TaskRows) -> ([f64; 4], [f64; 4]) {
    let e = t.chain();
    let (plain, full) = (e[0], e[e.len() - 1]);
    let (sf, sp) = (
        t.simulator(TransformSet::Full),
        t.simulator(TransformSet::Plain),
    );
    (
        [
            ratio(full, plain),
            t.worst_operator_ratio(),
            sf,
            ratio(sf, sp),
        ],
        [1.0, 1.0, t.start, 1.0],
    )
}

/// The verdict's rule (module docs): per task, (a) the full chain's 40-step error over the
/// plain net's, (b) the largest added operator's ratio, (c) the full chain's control within
/// tolerance on the simulator, (d) that control's error over the plain net's control's; held
/// needs every check, partly every task's (a). `tasks` holds each task's rows per net seed:
/// with more than one, each check reads the median over the seeds (a failed measure, +∞,
/// counted as the worst) with its 95% bootstrap interval over them, and its null the median
/// of the nulls. `None` when a check's null passes (a start already within tolerance).
pub fn ablation_rule(tasks: &[Vec<TaskRows>], r: &AblationRule) -> Option<Rule> {
    let mut held = Vec::new();
    let mut training = Vec::new();
    for seeds in tasks {
        let Some(first) = seeds.first() else {
            continue;
        };
        let k = seeds.len();
        let values: Vec<([f64; 4], [f64; 4])> = seeds.iter().map(task_values).collect();
        let median_of = |j: usize, idx: &mut dyn Iterator<Item = usize>, null: bool| {
            let v: Vec<f64> = idx
                .map(|i| if null { values[i].1[j] } else { values[i].0[j] })
                .collect();
            median_with_infinities(&v)
        };
        let value = [0, 1, 2, 3].map(|j| median_of(j, &mut (0..k), false));
        let null = [0, 1, 2, 3].map(|j| median_of(j, &mut (0..k), true));
        let intervals = (k > 1).then(|| {
            bootstrap_intervals(k, BOOTSTRAP_SEED, 4, |idx, out| {
                for (j, o) in out.iter_mut().enumerate() {
                    *o = median_of(j, &mut idx.iter().copied(), false);
                }
            })
        });
        let over = if k > 1 {
            format!(", median over {k} net seeds")
        } else {
            String::new()
        };
        let t = &first.task;
        let checks = [
            (
                format!("{t}: the full chain's 40-step error over the plain net's{over}"),
                Cmp::AtMost,
                r.full_over_plain,
                "the plain net itself",
            ),
            (
                format!(
                    "{t}: the largest ratio of an added operator's 40-step error to the previous variant's{over}"
                ),
                Cmp::Below,
                r.operator_ratio,
                "an operator that changes nothing",
            ),
            (
                format!(
                    "{t}: the control learned through the full chain, final error on the simulator{over}"
                ),
                Cmp::AtMost,
                WITHIN_TOLERANCE,
                "the start's controls",
            ),
            (
                format!("{t}: that control's simulator error over the plain net's control's{over}"),
                Cmp::Below,
                r.control_over_plain,
                "the plain net's control itself",
            ),
        ];
        training.push(held.len());
        for (j, (label, cmp, bar, null_label)) in checks.into_iter().enumerate() {
            let c = Check::new(label, value[j], cmp, bar, Null::new(null_label, null[j]));
            held.push(match &intervals {
                Some(iv) if !iv[j].0.is_nan() && !iv[j].1.is_nan() => {
                    c.map(|c| c.with_interval(iv[j].0, iv[j].1))
                }
                _ => c,
            });
        }
    }
    if held.is_empty() {
        return None;
    }
    Rule::gated(vec![], held, Partly::All(training))
}

/// Each task's rows per net seed: the tasks in `net_seeds.csv` from it (every seed, the run's
/// own first), the others (the dolphin) from the run's own tables ([`task_rows`]), one seed. A
/// task whose seeds have different variants (a truncated or edited table) is an error naming
/// the file.
fn seeded_rows(dir: &Path) -> Result<Vec<Vec<TaskRows>>, Error> {
    let own = task_rows(dir)?;
    let path = dir.join("net_seeds.csv");
    let df = read_csv(&path)?;
    let (seed, task, variant) = (
        df_f64(&df, "net_seed")?,
        df_str(&df, "task")?,
        df_str(&df, "variant")?,
    );
    let (e40, best, sim, start, failed) = (
        df_f64(&df, "rollout40_error_mean")?,
        df_f64(&df, "best_iteration")?,
        df_f64(&df, "simulator_error")?,
        df_f64(&df, "start_simulator_error")?,
        df_f64(&df, "failed")?,
    );
    let mut out = Vec::new();
    for t in own {
        let rows: Vec<usize> = (0..task.len()).filter(|&i| task[i] == t.task).collect();
        if rows.is_empty() {
            out.push(vec![t]);
            continue;
        }
        let mut seeds: Vec<f64> = Vec::new();
        for &i in &rows {
            if !seeds.contains(&seed[i]) {
                seeds.push(seed[i]);
            }
        }
        let mut per_seed = Vec::new();
        for s in seeds {
            let mine: Vec<usize> = rows.iter().copied().filter(|&i| seed[i] == s).collect();
            let rows_here: Vec<VariantRow> = mine
                .iter()
                .map(|&i| {
                    let measure = |x: f64| if failed[i] != 0.0 { f64::INFINITY } else { x };
                    VariantRow {
                        variant: variant[i].clone(),
                        rollout40: measure(e40[i]),
                        simulator: measure(sim[i]),
                        best_iteration: best[i] as usize,
                    }
                })
                .collect();
            if rows_here.len() != t.rows.len() {
                return Err(other(format!(
                    "{}: net seed {s} of {} has {} variants, the run's own {} (a truncated or edited table)",
                    path.display(),
                    t.task,
                    rows_here.len(),
                    t.rows.len()
                )));
            }
            per_seed.push(TaskRows {
                task: t.task.clone(),
                rows: rows_here,
                start: start[mine[0]],
            });
        }
        out.push(per_seed);
    }
    Ok(out)
}

/// The rule's rows from the `errors` and `control` tables of a run folder, one per task of
/// `nets`; a variant missing from a table (its training failed) has infinite errors.
fn task_rows(dir: &Path) -> Result<Vec<TaskRows>, Error> {
    let nets = read_csv(&dir.join("nets.csv"))?;
    let (nt, nv) = (df_str(&nets, "task")?, df_str(&nets, "variant")?);
    let errors = read_csv(&dir.join("errors.csv"))?;
    let (et, ev, e40) = (
        df_str(&errors, "task")?,
        df_str(&errors, "variant")?,
        df_f64(&errors, "rollout40_error_mean")?,
    );
    let control = read_csv(&dir.join("control.csv"))?;
    let (ct, cv, cs, cb, c0) = (
        df_str(&control, "task")?,
        df_str(&control, "variant")?,
        df_f64(&control, "simulator_error")?,
        df_f64(&control, "best_iteration")?,
        df_f64(&control, "start_simulator_error")?,
    );
    let mut out: Vec<TaskRows> = Vec::new();
    for (t, v) in nt.iter().zip(&nv) {
        let at = |ts: &[String], vs: &[String]| (0..ts.len()).find(|&i| &ts[i] == t && &vs[i] == v);
        let (ei, ci) = (at(&et, &ev), at(&ct, &cv));
        let start = (0..ct.len())
            .find(|&i| &ct[i] == t)
            .map_or(f64::NAN, |i| c0[i]);
        let r = VariantRow {
            variant: v.clone(),
            rollout40: ei.map_or(f64::INFINITY, |i| e40[i]),
            simulator: ci.map_or(f64::INFINITY, |i| cs[i]),
            best_iteration: ci.map_or(0, |i| cb[i] as usize),
        };
        match out.iter_mut().find(|x| &x.task == t) {
            Some(x) => x.rows.push(r),
            None => out.push(TaskRows {
                task: t.clone(),
                rows: vec![r],
                start,
            }),
        }
    }
    Ok(out)
}

fn words(v: &str) -> &str {
    match v {
        "plain" => "plain net (next state)",
        "delta" => "+ state change",
        "delta_frame" => "+ local frame",
        "full" => "+ normalization (full)",
        other => other,
    }
}

impl Family for NaTransforms {
    const KIND: &'static str = "na_transforms_ablation";
    type Params = Params;
    const CAPTIONS: &'static [(&'static str, &'static str)] = &[
        (
            "rollout",
            "each emulator variant's rollout error against the simulator (mean over episodes and state variables of the squared error in units of each variable's spread) against the emulator step, one panel per task; the operators are added left to right in the legend.",
        ),
        (
            "summary",
            "per variant (operators added left to right): one-step and 40-step rollout error, the zero-control drift gap from the Fig. 13 start, and the simulator final error of the Fig. 13 control learned through it (1 = tolerance, dashed; for the dolphin, the swim's distance short of the hand-made wave's in units of half of it); one line per task.",
        ),
    ];

    fn figures(&self, fig: &FigureSink, tables: &Tables) -> Result<Vec<PathBuf>, Error> {
        let r = tables.require("rollout")?;
        let (rt, rv, rk, re) = (
            r.strs("task"),
            r.strs("variant"),
            r.f64s("step"),
            r.f64s("error"),
        );
        let mut tasks: Vec<String> = Vec::new();
        let mut variants: Vec<String> = Vec::new();
        let n = tables.require("nets")?;
        for (t, v) in n.strs("task").iter().zip(n.strs("variant")) {
            if !tasks.contains(t) {
                tasks.push(t.clone());
            }
            if !variants.contains(&v) {
                variants.push(v);
            }
        }
        let panels: Vec<Panel> = tasks
            .iter()
            .map(|t| Panel {
                title: format!("{t}: rollout error of each variant"),
                x_label: "emulator step (super-step)".into(),
                y_label: "mean squared error (units of each variable's spread²)".into(),
                log_y: true,
                series: variants
                    .iter()
                    .enumerate()
                    .map(|(k, v)| {
                        let pts = (0..rt.len())
                            .filter(|&i| &rt[i] == t && &rv[i] == v)
                            .map(|i| (rk[i], re[i]))
                            .filter(|p| p.1 > 0.0)
                            .collect();
                        Series::line(words(v), pts, k)
                    })
                    .collect(),
                ..Panel::default()
            })
            .collect();
        let mut files = fig.draw("rollout", &Figure::grid(panels, 2))?;
        let e = tables.require("errors")?;
        let c = tables.require("control")?;
        let (et, ev) = (e.strs("task"), e.strs("variant"));
        let (ct, cv) = (c.strs("task"), c.strs("variant"));
        let x_of = |v: &str| variants.iter().position(|x| x == v).unwrap_or(0) as f64;
        let metric = |title: &str,
                      y: &str,
                      ts: &[String],
                      vs: &[String],
                      col: Vec<f64>,
                      tol: bool,
                      floor: f64| {
            let mut series: Vec<Series> = tasks
                .iter()
                .enumerate()
                .map(|(k, t)| {
                    let pts = (0..ts.len())
                        .filter(|&i| &ts[i] == t)
                        .map(|i| (x_of(&vs[i]), col[i].max(floor)))
                        .filter(|p| p.1 > 0.0 && p.1.is_finite())
                        .collect();
                    Series::line(t.clone(), pts, k)
                })
                .collect();
            if tol {
                series.push(
                    Series::line(
                        "tolerance (1)",
                        vec![(-0.2, 1.0), (variants.len() as f64 - 0.8, 1.0)],
                        tasks.len(),
                    )
                    .mark(Mark::Dashed),
                );
            }
            Panel {
                title: title.into(),
                x_label: "transforms (operators added left to right)".into(),
                y_label: y.into(),
                log_y: true,
                series,
                x_categories: variants.iter().map(|v| words(v).to_string()).collect(),
                x_range: Some((-0.5, variants.len() as f64 - 0.5)),
                ..Panel::default()
            }
        };
        let panels = vec![
            metric(
                "one-step error",
                "squared error (spread² units)",
                &et,
                &ev,
                e.f64s("rollout1_error"),
                false,
                0.0,
            ),
            metric(
                "40-step rollout error (mean)",
                "squared error (spread² units)",
                &et,
                &ev,
                e.f64s("rollout40_error_mean"),
                false,
                0.0,
            ),
            metric(
                "zero-control drift from the Fig. 13 start",
                "emulator - simulator end position (m; below 1 mm drawn at 1 mm)",
                &et,
                &ev,
                e.f64s("drift_gap_m"),
                false,
                1e-3,
            ),
            metric(
                "Fig. 13 control replayed on the simulator",
                "final error (1 = tolerance; dolphin: half the wave's distance)",
                &ct,
                &cv,
                c.f64s("simulator_error"),
                true,
                0.0,
            ),
        ];
        let mut f = Figure::grid(panels, 2);
        f.panel_size.0 = 720;
        files.extend(fig.draw("summary", &f)?);
        Ok(files)
    }

    fn report(&self, dir: &Path) -> Result<Findings, Error> {
        let e = read_csv(&dir.join("errors.csv"))?;
        let c = read_csv(&dir.join("control.csv"))?;
        let nets = read_csv(&dir.join("nets.csv"))?;
        let (nt, nv, nf) = (
            df_str(&nets, "task")?,
            df_str(&nets, "variant")?,
            df_f64(&nets, "failed")?,
        );
        let (et, ev) = (df_str(&e, "task")?, df_str(&e, "variant")?);
        let (e1, e40, gap) = (
            df_f64(&e, "rollout1_error")?,
            df_f64(&e, "rollout40_error_mean")?,
            df_f64(&e, "drift_gap_m")?,
        );
        let (ct, cv) = (df_str(&c, "task")?, df_str(&c, "variant")?);
        let (ce, cs) = (
            df_f64(&c, "emulator_error")?,
            df_f64(&c, "simulator_error")?,
        );
        let mut md = String::from(
            "| task | transforms | one-step error | 40-step error (mean) | zero-control drift gap (m) | Fig. 13 control: final error, emulator | final error, simulator |\n| --- | --- | --- | --- | --- | --- | --- |\n",
        );
        for i in 0..nt.len() {
            let (t, v) = (&nt[i], &nv[i]);
            if nf[i] != 0.0 {
                md.push_str(&format!(
                    "| {t} | {} | training failed | | | | |\n",
                    words(v)
                ));
                continue;
            }
            let ei = (0..et.len()).find(|&j| &et[j] == t && &ev[j] == v);
            let ci = (0..ct.len()).find(|&j| &ct[j] == t && &cv[j] == v);
            let g = |o: Option<usize>, x: &[f64]| o.map_or("–".into(), |j| sig(x[j]));
            md.push_str(&format!(
                "| {t} | {} | {} | {} | {} | {} | {} |\n",
                words(v),
                g(ei, &e1),
                g(ei, &e40),
                g(ei, &gap),
                g(ci, &ce),
                g(ci, &cs)
            ));
        }
        let seeded = seeded_rows(dir)?;
        let rows: Vec<TaskRows> = seeded.iter().filter_map(|s| s.first().cloned()).collect();
        if seeded.iter().any(|s| s.len() > 1) {
            md.push_str("\nPer net seed (`net_seeds.csv`; every variant built and measured again through the nets of each seed, the run's own first), the values the checks take the median of:\n\n| task | net seed | full chain's 40-step error / plain's | worst operator ratio | full chain's control, simulator final error | / plain net's control's |\n| --- | --- | --- | --- | --- | --- |\n");
            let ids = read_csv(&dir.join("net_seeds.csv"))?;
            let (it, is) = (df_str(&ids, "task")?, df_f64(&ids, "net_seed")?);
            for per_seed in seeded.iter().filter(|s| s.len() > 1) {
                let mut seen: Vec<f64> = Vec::new();
                for i in (0..it.len()).filter(|&i| it[i] == per_seed[0].task) {
                    if !seen.contains(&is[i]) {
                        seen.push(is[i]);
                    }
                }
                for (t, s) in per_seed.iter().zip(seen) {
                    let (v, _) = task_values(t);
                    md.push_str(&format!(
                        "| {} | {} | {} | {} | {} | {} |\n",
                        t.task,
                        s as u64,
                        sig(v[0]),
                        sig(v[1]),
                        sig(v[2]),
                        sig(v[3])
                    ));
                }
            }
        }
        let settings = rule_settings(dir)?;
        let thresholds = AblationRule {
            operator_ratio: settings("operator_ratio"),
            full_over_plain: settings("full_over_plain"),
            control_over_plain: settings("control_over_plain"),
        };
        let rule = ablation_rule(&seeded, &thresholds);
        let (verdict, lines, text) = shown(
            rule.as_ref(),
            " No rule: a check's null passes (a start already within tolerance).",
        );
        let mut parts = Vec::new();
        let mut stuck = Vec::new();
        for t in &rows {
            let e = t.chain();
            parts.push(format!(
                "{}: 40-step error plain {} → full {}, control on the simulator through the full chain {} (plain net's {}, the start's {})",
                t.task,
                sig(e[0]),
                sig(e[e.len() - 1]),
                sig(t.simulator(TransformSet::Full)),
                sig(t.simulator(TransformSet::Plain)),
                sig(t.start)
            ));
            let s = t.stuck();
            if !s.is_empty() {
                stuck.push(format!("{} ({})", t.task, s.join(", ")));
            }
        }
        let stuck = if stuck.is_empty() {
            String::new()
        } else {
            format!(
                " The descent through these variants never improved on its start (best iteration 0), so their control is the start's: {}.",
                stuck.join("; ")
            )
        };
        Ok(Findings {
            ours: md,
            verdict,
            rule: rule.clone(),
            why: format!(
                "{}. Checks:{lines}{stuck} Rule (thresholds ours, in the spec; the spec's history gives the rule before): {text} Same data, net size, training and budget for every variant; the full chain is Fig. 13's net. The dolphin's rows are its global net's (composed with the whole chain's local nets for the rollouts); its control is the 20 s swim, whose final error is the distance it falls short of the hand-made wave's on the simulator in units of half that distance (1 = Fig. 13's bar), its start the dolphin at rest.",
                parts.join("; ")
            ),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::experiment::report::Verdict;

    const RULE: AblationRule = AblationRule {
        operator_ratio: 0.95,
        full_over_plain: 0.5,
        control_over_plain: 0.5,
    };

    /// A task of (variant, 40-step error, simulator error) rows from a start scoring 40.
    fn task(rows: &[(&str, f64, f64)]) -> TaskRows {
        TaskRows {
            task: "t".into(),
            rows: rows
                .iter()
                .map(|r| VariantRow {
                    variant: r.0.to_string(),
                    rollout40: r.1,
                    simulator: r.2,
                    best_iteration: 15,
                })
                .collect(),
            start: 40.0,
        }
    }

    /// Each task at one net seed.
    fn one_seed(tasks: &[TaskRows]) -> Vec<Vec<TaskRows>> {
        tasks.iter().map(|t| vec![t.clone()]).collect()
    }

    fn verdict(tasks: &[TaskRows]) -> Verdict {
        ablation_rule(&one_seed(tasks), &RULE)
            .expect("nulls fail")
            .verdict()
    }

    #[test]
    fn the_rule_needs_every_operator_to_help_and_contradicting_rows_fail() {
        let good = task(&[
            ("plain", 1.0, 10.0),
            ("delta", 0.5, 5.0),
            ("delta_frame", 0.3, 3.0),
            ("full", 0.1, 0.5),
        ]);
        assert_eq!(verdict(&[good.clone()]), Verdict::Held);
        // An operator that changes nothing (the null of check (b)) fails it: only partly.
        let no_op = task(&[
            ("plain", 1.0, 10.0),
            ("delta", 0.5, 5.0),
            ("delta_frame", 0.5, 3.0),
            ("full", 0.1, 0.5),
        ]);
        assert!((no_op.worst_operator_ratio() - 1.0).abs() < 1e-12);
        assert_eq!(verdict(&[no_op]), Verdict::Partly);
        // The full chain's control beats the plain net's but misses the tolerance: partly.
        let misses = task(&[
            ("plain", 1.0, 100.0),
            ("delta", 0.5, 5.0),
            ("delta_frame", 0.3, 3.0),
            ("full", 0.1, 3.0),
        ]);
        assert_eq!(verdict(&[good.clone(), misses]), Verdict::Partly);
        // The full chain no better than plain (the contradicting data): not held.
        let flat = task(&[
            ("plain", 0.2, 1.5),
            ("delta", 0.2, 1.5),
            ("delta_frame", 0.2, 1.5),
            ("full", 0.2, 1.5),
        ]);
        assert_eq!(verdict(&[flat.clone()]), Verdict::NotHeld);
        // Partly needs the training half in every task.
        assert_eq!(verdict(&[good.clone(), flat]), Verdict::NotHeld);
        // A plain net whose training failed counts as an infinite error.
        let failed = task(&[
            ("plain", f64::NAN, f64::NAN),
            ("delta", 0.5, 5.0),
            ("delta_frame", 0.3, 3.0),
            ("full", 0.1, 0.5),
        ]);
        assert_eq!(verdict(&[failed]), Verdict::Held);
    }

    #[test]
    fn a_start_already_within_tolerance_leaves_no_rule_and_stuck_descents_are_named() {
        let mut t = task(&[
            ("plain", 1.0, 10.0),
            ("delta", 0.5, 5.0),
            ("delta_frame", 0.3, 3.0),
            ("full", 0.1, 0.5),
        ]);
        t.rows[0].best_iteration = 0;
        assert_eq!(t.stuck(), vec!["plain"]);
        t.start = 0.9;
        assert!(ablation_rule(&one_seed(&[t]), &RULE).is_none());
    }

    #[test]
    fn a_ratio_of_one_is_refused_as_a_threshold() {
        assert!(RULE.validate().is_ok());
        for bad in [1.0, 1.1, 0.0] {
            let r = AblationRule {
                operator_ratio: bad,
                ..RULE
            };
            assert!(r.validate().is_err(), "{bad}");
        }
    }

    #[test]
    fn over_net_seeds_each_check_reads_the_median_and_its_interval() {
        let good = task(&[
            ("plain", 1.0, 10.0),
            ("delta", 0.5, 5.0),
            ("delta_frame", 0.3, 3.0),
            ("full", 0.1, 0.5),
        ]);
        // One seed of five whose full-chain control misses by far: the median is within
        // tolerance, but resamples that draw it three times or more are not.
        let mut miss = good.clone();
        miss.rows[3].simulator = 6.0;
        let seeds = vec![vec![
            good.clone(),
            miss,
            good.clone(),
            good.clone(),
            good.clone(),
        ]];
        let rule = ablation_rule(&seeds, &RULE).unwrap();
        let c = &rule.held[2];
        assert_eq!(c.value, 0.5);
        assert!(c.label.ends_with("median over 5 net seeds"), "{}", c.label);
        assert_eq!(c.interval, Some((0.5, 6.0)));
        assert_eq!(rule.verdict(), Verdict::Inconclusive);
        // Five alike seeds: intervals collapse and the verdict is the one seed's.
        let alike = vec![vec![good.clone(); 5]];
        assert_eq!(
            ablation_rule(&alike, &RULE).unwrap().verdict(),
            Verdict::Held
        );
    }

    #[test]
    fn a_truncated_seed_table_is_an_error_not_a_verdict_on_fewer_variants() {
        let dir = tempfile::tempdir().unwrap();
        let w = |name: &str, text: &str| std::fs::write(dir.path().join(name), text).unwrap();
        let variants = ["plain", "delta", "delta_frame", "full"];
        let mut nets = String::from("task,variant,failed\n");
        let mut errors = String::from("task,variant,rollout40_error_mean\n");
        let mut control =
            String::from("task,variant,simulator_error,best_iteration,start_simulator_error\n");
        let mut seeds = SEED_COLUMNS.join(",") + "\n";
        for (k, v) in variants.iter().enumerate() {
            let e = 1.0 / (k + 1) as f64;
            nets.push_str(&format!("truck,{v},0\n"));
            errors.push_str(&format!("truck,{v},{e}\n"));
            control.push_str(&format!("truck,{v},{},15,40\n", 10.0 * e));
            for s in [1, 2] {
                seeds.push_str(&format!("{s},truck,{v},{e},15,{},40,0\n", 10.0 * e));
            }
        }
        w("nets.csv", &nets);
        w("errors.csv", &errors);
        w("control.csv", &control);
        w("net_seeds.csv", &seeds);
        let rows = seeded_rows(dir.path()).unwrap();
        assert_eq!(rows.len(), 1);
        assert_eq!(rows[0].len(), 2);
        assert_eq!(rows[0][1].rows[3].rollout40, 0.25);
        // Seed 2's last variant cut off.
        let cut: String = seeds.lines().take(8).map(|l| format!("{l}\n")).collect();
        w("net_seeds.csv", &cut);
        let err = seeded_rows(dir.path()).unwrap_err().to_string();
        assert!(
            err.contains("net_seeds.csv") && err.contains("net seed 2"),
            "{err}"
        );
    }
}
