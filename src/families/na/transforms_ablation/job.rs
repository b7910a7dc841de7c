//! The job of `na_transforms_ablation`: every variant of every task's emulator trained,
//! its rollouts, drift and control measured, and the dolphin's hierarchy likewise.

use super::{Params, WITHIN_TOLERANCE};
use crate::emulator::cache::EmulatorCache;
use crate::emulator::catalog::{rollout_error, BuildSpec, NetModel, TransformSet};
use crate::emulator::hierarchy::{
    build_global, hierarchy_rollout_error, BuiltDolphin, HierarchySpec, NetReport, GLOBAL_DIM,
};
use crate::emulator::Emulator;
use crate::experiment::output::Tables;
use crate::experiment::rows::table_of;
use crate::experiment::rule::rule_table_of;
use crate::experiment::{other, Error, Job, RunContext};
use crate::families::na::fig13_control::{
    learn_and_replay, learn_swim, start_simulator_error, DolphinControl, Task,
};
use crate::families::na::table1_structure::{
    build_dolphin_emulator, build_emulator, build_spec, dolphin_drift, position_part,
};
use crate::physics::dolphin::N_SEGMENTS;

crate::result_rows! {
    /// One row of `nets.csv`: one variant's emulator of one task (the dolphin's: its global net).
    pub struct NetRow {
        /// The task (`dolphin` for the hierarchy).
        task: String = "task",
        /// The variant ([`TransformSet::name`]).
        variant: String = "variant",
        /// Net inputs.
        inputs: i64 = "inputs",
        /// Hidden units.
        hidden: i64 = "hidden",
        /// Net outputs.
        outputs: i64 = "outputs",
        /// Training examples.
        examples: i64 = "examples",
        /// Weights.
        weights: i64 = "weights",
        /// Training seconds (NaN when training failed).
        train_s: f64 = "train_s",
        /// Why training stopped (`failed: ...` with the error when it failed).
        stop: String = "stop",
        /// 1 when the net came from the cache.
        cached: i64 = "cached",
        /// 1 when training failed.
        failed: i64 = "failed",
    }
}

crate::result_rows! {
    /// One row of `errors.csv`: one trained variant's rollout errors and zero-control drift.
    pub struct ErrorsRow {
        /// The task.
        task: String = "task",
        /// The variant.
        variant: String = "variant",
        /// One-step error (units of each variable's spread²).
        rollout1_error: f64 = "rollout1_error",
        /// 40-step rollout error, mean over the steps.
        rollout40_error_mean: f64 = "rollout40_error_mean",
        /// 40-step rollout error at the last step.
        rollout40_error_final: f64 = "rollout40_error_final",
        /// The emulator's end position from the start (m).
        drift_emulator_m: f64 = "drift_emulator_m",
        /// The simulator's end position from the start (m).
        drift_simulator_m: f64 = "drift_simulator_m",
        /// The emulator's and the simulator's end positions apart (m).
        drift_gap_m: f64 = "drift_gap_m",
    }
}

crate::result_rows! {
    /// One row of `rollout.csv`: one trained variant's rollout error at one super-step.
    pub struct RolloutRow {
        /// The task.
        task: String = "task",
        /// The variant.
        variant: String = "variant",
        /// The super-step (from 1).
        step: i64 = "step",
        /// Mean squared error (units of each variable's spread²).
        error: f64 = "error",
    }
}

crate::result_rows! {
    /// One row of `control.csv`: Fig. 13's control learned through one variant, replayed on the
    /// simulator.
    pub struct ControlRow {
        /// The task.
        task: String = "task",
        /// The variant.
        variant: String = "variant",
        /// Descent iterations.
        iterations: i64 = "iterations",
        /// The descent's best iteration (0: never improved on its start, or nothing learned).
        best_iteration: i64 = "best_iteration",
        /// The objective at the start (NaN when nothing was learned).
        j_start: f64 = "j_start",
        /// The best objective.
        j_best: f64 = "j_best",
        /// Final error through the emulator (1 = tolerance).
        emulator_error: f64 = "emulator_error",
        /// Final error replayed on the simulator (1 = tolerance).
        simulator_error: f64 = "simulator_error",
        /// 1 when both final errors are within tolerance.
        at_goal: i64 = "at_goal",
        /// The start's controls replayed on the simulator: their final error.
        start_simulator_error: f64 = "start_simulator_error",
    }
}

crate::result_rows! {
    /// One row of `net_seeds.csv`: per net seed, task and variant, the measures the rule reads.
    pub struct SeedRow {
        /// The net seed.
        net_seed: i64 = "net_seed",
        /// The task.
        task: String = "task",
        /// The variant.
        variant: String = "variant",
        /// 40-step rollout error, mean (NaN when training failed).
        rollout40_error_mean: f64 = "rollout40_error_mean",
        /// The descent's best iteration.
        best_iteration: i64 = "best_iteration",
        /// The control's final error on the simulator (NaN when nothing was learned).
        simulator_error: f64 = "simulator_error",
        /// The start's controls replayed on the simulator: their final error.
        start_simulator_error: f64 = "start_simulator_error",
        /// 1 when training failed.
        failed: i64 = "failed",
    }
}

/// The `control` row of a variant through which nothing was learned (no finite step scale).
fn push_unlearned(
    control: &mut Vec<ControlRow>,
    task: &str,
    v: TransformSet,
    iterations: usize,
    start_error: f64,
) {
    control.push(ControlRow {
        task: task.to_string(),
        variant: v.name().to_string(),
        iterations: iterations as i64,
        best_iteration: 0,
        j_start: f64::NAN,
        j_best: f64::NAN,
        emulator_error: f64::NAN,
        simulator_error: f64::NAN,
        at_goal: 0,
        start_simulator_error: start_error,
    });
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

/// The rows of the tables the job writes.
#[derive(Default)]
struct Outputs {
    nets: Vec<NetRow>,
    errors: Vec<ErrorsRow>,
    rollout: Vec<RolloutRow>,
    control: Vec<ControlRow>,
    seeds: Vec<SeedRow>,
}

impl Job for Params {
    fn params_json(&self) -> serde_json::Value {
        serde_json::to_value(self).unwrap_or_default()
    }

    fn run(&self, ctx: &RunContext) -> Result<Tables, Error> {
        let mut out = Outputs::default();
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
            let mut other_seed = Outputs::default();
            for task in &self.tasks {
                self.run_task(ctx, task, s, &mut other_seed, &pb)?;
            }
            out.seeds.extend(other_seed.seeds);
        }
        pb.finish_and_clear();
        if let Some(d) = &self.dolphin {
            self.run_dolphin(ctx, d, &mut out)?;
        }
        Ok(Tables::from([
            ("nets", table_of(&out.nets)),
            ("errors", table_of(&out.errors)),
            ("rollout", table_of(&out.rollout)),
            ("control", table_of(&out.control)),
            ("net_seeds", table_of(&out.seeds)),
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
            out.nets.push(NetRow {
                task: name.to_string(),
                variant: v.name().to_string(),
                inputs: inputs as i64,
                hidden: hidden as i64,
                outputs: n as i64,
                examples: spec.net.examples as i64,
                weights: weights as i64,
                train_s,
                stop,
                cached,
                failed,
            });
            let Ok(trained) = b else {
                out.seeds.push(SeedRow {
                    net_seed: seed as i64,
                    task: name.to_string(),
                    variant: v.name().to_string(),
                    rollout40_error_mean: f64::NAN,
                    best_iteration: 0,
                    simulator_error: f64::NAN,
                    start_simulator_error: start_error,
                    failed: 1,
                });
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
                out.rollout.push(RolloutRow {
                    task: name.to_string(),
                    variant: v.name().to_string(),
                    step: (k + 1) as i64,
                    error: *x,
                });
            }
            let rollout40 = errs.iter().sum::<f64>() / errs.len() as f64;
            let [de, ds, gap] = drift(e, spec, &x0, &task.rest_control(), self.rollout_steps);
            out.errors.push(ErrorsRow {
                task: name.to_string(),
                variant: v.name().to_string(),
                rollout1_error: errs[0],
                rollout40_error_mean: rollout40,
                rollout40_error_final: errs[errs.len() - 1],
                drift_emulator_m: de,
                drift_simulator_m: ds,
                drift_gap_m: gap,
            });
            // Fig. 13's control through this variant, replayed on the simulator.
            let learned = ctx.stage(&format!("learn {at} {}", v.name()), || {
                learn_and_replay(&cal, e, self.steps, self.curvature_iterations)
            })?;
            let (best_iteration, simulator_error) = match learned {
                Some((run, r)) => {
                    out.control.push(ControlRow {
                        task: name.to_string(),
                        variant: v.name().to_string(),
                        iterations: task.task.iterations as i64,
                        best_iteration: run.best_iteration as i64,
                        j_start: r.trace.first().map_or(f64::NAN, |t| t.objective),
                        j_best: r.best_objective(),
                        emulator_error: run.emulator_error,
                        simulator_error: run.simulator_error,
                        at_goal: i64::from(run.at_goal()),
                        start_simulator_error: start_error,
                    });
                    (run.best_iteration as i64, run.simulator_error)
                }
                // No finite step scale through this net: nothing learned.
                None => {
                    push_unlearned(&mut out.control, name, v, task.task.iterations, start_error);
                    (0, f64::NAN)
                }
            };
            out.seeds.push(SeedRow {
                net_seed: seed as i64,
                task: name.to_string(),
                variant: v.name().to_string(),
                rollout40_error_mean: rollout40,
                best_iteration,
                simulator_error,
                start_simulator_error: start_error,
                failed: 0,
            });
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
        out: &mut Outputs,
    ) -> Result<(), Error> {
        let spec = d.nets.spec(ctx.seed, self.steps, self.example_scale);
        let built = ctx.stage("train dolphin hierarchy", || build_dolphin_emulator(&spec))?;
        let variants = self.dolphin_variants(ctx, &spec, &built);
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
                    out.nets.push(NetRow {
                        task: "dolphin".into(),
                        variant: v.name().to_string(),
                        inputs: inputs as i64,
                        hidden: d.nets.global.hidden as i64,
                        outputs: outputs as i64,
                        examples: spec.global.examples as i64,
                        weights: weights as i64,
                        train_s: f64::NAN,
                        stop: format!("failed: {e}"),
                        cached: 0,
                        failed: 1,
                    });
                    continue;
                }
            };
            out.nets.push(NetRow {
                task: "dolphin".into(),
                variant: v.name().to_string(),
                inputs: inputs as i64,
                hidden: rep.hidden as i64,
                outputs: outputs as i64,
                examples: rep.examples as i64,
                weights: weights as i64,
                train_s: rep.train_s,
                stop: rep.stop.clone(),
                cached: i64::from(rep.from_cache),
                failed: 0,
            });
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
                out.rollout.push(RolloutRow {
                    task: "dolphin".into(),
                    variant: v.name().to_string(),
                    step: (k + 1) as i64,
                    error: *x,
                });
            }
            let [emu, sim, start] =
                dolphin_drift(&composed, &spec, &[0.0; N_SEGMENTS], self.rollout_steps)?;
            out.errors.push(ErrorsRow {
                task: "dolphin".into(),
                variant: v.name().to_string(),
                rollout1_error: errs[0],
                rollout40_error_mean: errs.iter().sum::<f64>() / errs.len() as f64,
                rollout40_error_final: errs[errs.len() - 1],
                drift_emulator_m: apart(&emu, &start),
                drift_simulator_m: apart(&sim, &start),
                drift_gap_m: apart(&emu, &sim),
            });
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
                    out.control.push(ControlRow {
                        task: "dolphin".into(),
                        variant: v.name().to_string(),
                        iterations: d.iterations as i64,
                        best_iteration: r.best_iteration as i64,
                        j_start: r.trace.first().map_or(f64::NAN, |t| t.objective),
                        j_best: r.best_objective(),
                        emulator_error: e_emu,
                        simulator_error: e_sim,
                        at_goal: i64::from(e_emu <= WITHIN_TOLERANCE && e_sim <= WITHIN_TOLERANCE),
                        start_simulator_error: start_error,
                    });
                }
                Err(_) => push_unlearned(&mut out.control, "dolphin", v, d.iterations, start_error),
            }
        }
        Ok(())
    }

    /// Every variant's global net of the dolphin's hierarchy `built` (of `spec`), trained in
    /// parallel (the full variant is the hierarchy's own); a failed build is its error's text.
    fn dolphin_variants(
        &self,
        ctx: &RunContext,
        spec: &HierarchySpec,
        built: &BuiltDolphin,
    ) -> Vec<Result<(Emulator, NetReport), String>> {
        use rayon::prelude::*;
        let cache = EmulatorCache::from_env();
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
        })
    }
}
