//! `na_table2_speedup` (NeuroAnimator §5.1, Table 2): wall time of 20,000 physical simulation
//! steps against the emulators that cover the same simulated time, N25, N50, N100 for the
//! passive and active pendulum, N50 for the truck and the lander, and N50 with and without 5
//! regularization steps per emulation step for the hierarchical dolphin (§5.3).
//!
//! Both competitors run here, in one process, on one thread, one after the other: the physical
//! simulator is the same RK4 at δt that generated the training data (the lander's quaternion
//! renormalized after each step), stepping in place without allocation; an emulator takes
//! 20,000 / n steps of [`crate::emulator::Emulator::predict`] (transforms + network, no
//! allocation). Controls (typical random controls of the model, [`ControlSignal`]) are
//! precomputed for both, the physical one per step and the emulator one per super step. Each
//! loop is timed `repeats` times and the fastest is kept. Emulators come from the cache when
//! `na_table1_structure` (same seed and settings) trained them already.
//!
//! Speedup = n × (physical step cost / emulator step cost), with n the physical steps one
//! emulator step covers, so a cheap simulator makes a small speedup whatever the net costs
//! (issue 11, defect 8): every row carries that breakdown. Two comparisons the paper made
//! besides: the dolphin against an implicit mass-spring integrator like its \[18\]
//! ([`crate::physics::dolphin::ImplicitDolphin`], linearized backward Euler) at the paper's
//! δt = 0.01 s (§6: 20 s are 2,000 physical steps), covering the emulator's simulated time; and
//! every rigid model at equal accuracy ([`super::equal_accuracy`]): the largest physical step
//! Δt / j whose 40-super-step rollout error (Table 1's `rollout40_error_mean` measure) is at
//! most the emulator's, timed over the emulator's simulated time.
//!
//! Tables: `speedup` (model, emulator, physical_s, emulator_s, speedup, physical_steps,
//! emulator_steps, physical_step_s, emulator_step_s, n, step_cost_ratio, physical_integrator,
//! physical_dt) and `equal_accuracy` (model, emulator, emulator_error, substeps, matched_dt,
//! matched_error, coarser_error, physical_steps, emulator_steps, physical_s, emulator_s,
//! speedup). Timings (`physical_s`, `emulator_s`, `speedup`, `*_step_s`, `step_cost_ratio`)
//! vary run to run; every other column is bit-reproducible.

use super::equal_accuracy::match_substeps;
use super::table1_structure::{
    build_dolphin_emulator, build_emulator, build_spec, validate_nets, validate_training,
    DolphinNets, ROLLOUT_EPISODES, ROLLOUT_STEPS,
};
use crate::emulator::catalog::RolloutReference;
use crate::emulator::catalog::{NetModel, NetSpec, TrainSettings};
use crate::emulator::dataset::ControlSignal;
use crate::emulator::hierarchy::{self, BoundRegularizer, DolphinEmulator, Regularizer, Schedule};
use crate::emulator::Emulator;
use crate::experiment::output::{df_f64, df_str, read_csv, unique, Table, Tables};
use crate::experiment::plot::{Figure, FigureSink, Mark, Panel, Series};
use crate::experiment::report::{sig, Findings, Verdict};
use crate::experiment::resolve::{ensure, positive, ParamError, Validate};
use crate::experiment::{other, Error, Family, Job, RunContext};
use crate::physics::dolphin::ImplicitDolphin;
use crate::physics::Dynamics;
use crate::row;
use serde::{Deserialize, Serialize};
use std::hint::black_box;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// The family.
pub struct NaSpeedup;

/// One model to time and the emulators (n values) to time it against.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TimedNet {
    /// The network (model, size, data, training method).
    pub net: NetSpec,
    /// Physical steps per emulator step, one emulator each (e.g. [25, 50, 100]).
    pub emulators: Vec<usize>,
}

/// Parameters of `na_table2_speedup`.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Params {
    /// Physical steps per timing run (the paper: 20,000).
    pub physical_steps: usize,
    /// Timing repetitions; the fastest is kept.
    pub repeats: usize,
    /// Multiplies every net's example count.
    pub example_scale: f64,
    /// Models and their emulators.
    pub models: Vec<TimedNet>,
    /// Training settings.
    pub training: TrainSettings,
    /// The dolphin rows: N50 and N50 with regularization steps after each emulation step.
    #[serde(default)]
    pub dolphin: Option<TimedDolphin>,
}

/// The dolphin rows of Table 2.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TimedDolphin {
    /// The hierarchy (as in `na_table1_structure`).
    pub nets: DolphinNets,
    /// Physical steps per emulator step n.
    pub steps: usize,
    /// The regularization step (§5.3).
    pub regularization: Regularizer,
    /// Regularization steps after each emulation step (the paper: 5).
    pub regularization_steps: usize,
    /// Step of the implicit (backward Euler) physical dolphin timed against N`steps` over the
    /// same simulated time (the paper's δt: 0.01 s); absent: no such row.
    #[serde(default)]
    pub implicit_dt: Option<f64>,
}

impl Validate for Params {
    fn validate(&self) -> Result<(), ParamError> {
        ensure(self.physical_steps >= 1, "physical_steps", "must be >= 1")?;
        ensure(self.repeats >= 1, "repeats", "must be >= 1")?;
        let nets: Vec<NetSpec> = self.models.iter().map(|m| m.net.clone()).collect();
        validate_nets(&nets, self.example_scale)?;
        for (i, m) in self.models.iter().enumerate() {
            ensure(
                !m.emulators.is_empty() && m.emulators.iter().all(|&n| n >= 1),
                &format!("models[{i}].emulators"),
                "need at least one n >= 1",
            )?;
            for &n in &m.emulators {
                ensure(
                    self.physical_steps % n == 0,
                    &format!("models[{i}].emulators"),
                    format!("n = {n} must divide physical_steps"),
                )?;
            }
        }
        if let Some(d) = &self.dolphin {
            d.nets.validate("dolphin.nets", self.example_scale)?;
            ensure(
                d.steps >= 1 && self.physical_steps.is_multiple_of(d.steps),
                "dolphin.steps",
                "must be >= 1 and divide physical_steps",
            )?;
            validate_regularizer("dolphin.regularization", &d.regularization)?;
            if let Some(h) = d.implicit_dt {
                positive("dolphin.implicit_dt", h)?;
                let per_super = d.steps as f64 * d.nets.physical_dt / h;
                ensure(
                    (per_super - per_super.round()).abs() < 1e-9 && per_super.round() >= 1.0,
                    "dolphin.implicit_dt",
                    format!(
                        "must divide the emulator's super-step {} s",
                        d.steps as f64 * d.nets.physical_dt
                    ),
                )?;
            }
        }
        validate_training(&self.training)
    }
}

/// The explicit integrator of the dolphin's training data.
const DOLPHIN_EXPLICIT: &str = "semi-implicit Euler";
/// The implicit integrator of the dolphin's extra row.
const DOLPHIN_IMPLICIT: &str = "backward Euler";

/// A row's cost breakdown: speedup = physical_s / emulator_s = n × ratio.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Breakdown {
    /// Seconds per physical step.
    pub physical_step_s: f64,
    /// Seconds per emulator (super-)step.
    pub emulator_step_s: f64,
    /// Physical steps per emulator step.
    pub n: i64,
    /// Physical step cost / emulator step cost.
    pub ratio: f64,
}

/// The breakdown of `physical_s` for `physical_steps` steps against `emulator_s` for
/// `emulator_steps` steps covering the same simulated time.
pub fn breakdown(
    physical_s: f64,
    physical_steps: usize,
    emulator_s: f64,
    emulator_steps: usize,
) -> Breakdown {
    let physical_step_s = physical_s / physical_steps as f64;
    let emulator_step_s = emulator_s / emulator_steps as f64;
    Breakdown {
        physical_step_s,
        emulator_step_s,
        n: (physical_steps / emulator_steps) as i64,
        ratio: physical_step_s / emulator_step_s,
    }
}

/// The paper's step cost ratio for a Table 2 cell: (physical s / 20,000) / (emulator s / (20,000 / n)).
fn paper_ratio(model: &str, emulator: &str) -> Option<f64> {
    let (physical, emulator_s, n) = match (model, emulator) {
        ("pendulum_passive", "N25") => (4.70, 0.10, 25.0),
        ("pendulum_passive", "N50") => (4.70, 0.05, 50.0),
        ("pendulum_passive", "N100") => (4.70, 0.02, 100.0),
        ("pendulum_active", "N25") => (4.52, 0.12, 25.0),
        ("pendulum_active", "N50") => (4.52, 0.06, 50.0),
        ("pendulum_active", "N100") => (4.52, 0.03, 100.0),
        ("truck", "N50") => (4.88, 0.07, 50.0),
        ("lander", "N50") => (6.44, 0.12, 50.0),
        ("dolphin", "N50") => (63.0, 0.95, 50.0),
        ("dolphin", "N50_reg") => (63.0, 2.48, 50.0),
        _ => return None,
    };
    Some(physical / (emulator_s * n))
}

/// One `speedup` row (the timings with their breakdown).
#[allow(clippy::too_many_arguments)]
fn push_speedup(
    table: &mut Table,
    model: &str,
    emulator: &str,
    integrator: &str,
    dt: f64,
    (physical_s, physical_steps): (f64, usize),
    (emulator_s, emulator_steps): (f64, usize),
) {
    let b = breakdown(physical_s, physical_steps, emulator_s, emulator_steps);
    table.push(row![
        model,
        emulator,
        physical_s,
        emulator_s,
        physical_s / emulator_s,
        physical_steps as i64,
        emulator_steps as i64,
        b.physical_step_s,
        b.emulator_step_s,
        b.n,
        b.ratio,
        integrator,
        dt
    ]);
}

/// `u` (rows of `m` controls) with each row repeated `times` times.
fn hold(u: &[f64], m: usize, times: usize) -> Vec<f64> {
    u.chunks(m.max(1))
        .flat_map(|r| std::iter::repeat_n(r, times).flatten().copied())
        .collect()
}

/// Fastest of `repeats` runs of `f`, in seconds.
fn best_time(repeats: usize, mut f: impl FnMut()) -> f64 {
    (0..repeats)
        .map(|_| {
            let t0 = Instant::now();
            f();
            t0.elapsed().as_secs_f64()
        })
        .fold(f64::INFINITY, f64::min)
}

/// Seconds for `steps` physical steps of `sim` from `x0` under per-step controls `u` (row-major).
fn time_physical(
    sim: &mut dyn Dynamics,
    x0: &[f64],
    u: &[f64],
    dt: f64,
    steps: usize,
    repeats: usize,
) -> f64 {
    let m = sim.control_dim();
    let mut x = x0.to_vec();
    best_time(repeats, || {
        x.copy_from_slice(x0);
        for k in 0..steps {
            sim.step(&mut x, &u[k * m..(k + 1) * m], dt);
        }
        black_box(&x);
    })
}

/// Seconds for `steps` emulator steps from `x0` under per-step controls `u` (row-major).
fn time_emulator(e: &Emulator, x0: &[f64], u: &[f64], steps: usize, repeats: usize) -> f64 {
    let m = e.control_dim();
    let mut scratch = e.scratch();
    let mut x = x0.to_vec();
    let mut y = x0.to_vec();
    best_time(repeats, || {
        x.copy_from_slice(x0);
        for k in 0..steps {
            e.predict(&x, &u[k * m..(k + 1) * m], &mut scratch, &mut y);
            std::mem::swap(&mut x, &mut y);
        }
        black_box(&x);
    })
}

/// Checks a regularizer: positive step and scales, and a step the explicit scheme survives
/// (the softened body's fastest spring mode ω = 330 √scale rad/s must keep ω δt < 1).
pub fn validate_regularizer(key: &str, r: &Regularizer) -> Result<(), ParamError> {
    positive(&format!("{key}.dt"), r.dt)?;
    positive(&format!("{key}.stiffness_scale"), r.stiffness_scale)?;
    positive(&format!("{key}.damping_scale"), r.damping_scale)?;
    ensure(
        330.0 * r.stiffness_scale.sqrt() * r.dt < 1.0,
        &format!("{key}.dt"),
        format!(
            "explicit regularization steps are unstable: 330 rad/s x sqrt(stiffness_scale) x dt = {:.2} must be < 1",
            330.0 * r.stiffness_scale.sqrt() * r.dt
        ),
    )?;
    ensure(
        r.dt * r.damping_scale * 20.0 <= 0.5,
        &format!("{key}.damping_scale"),
        "explicit regularization steps are unstable: dt x 20 N s/m x damping_scale must be <= 0.5",
    )
}

/// Seconds for the dolphin emulator to take one step per control in `u`, each followed by
/// `reg_steps` regularization steps (fastest of `repeats`).
fn time_dolphin(
    e: &DolphinEmulator,
    reg: &mut BoundRegularizer,
    reg_steps: usize,
    x0: &[f64],
    u: &[f64],
    repeats: usize,
) -> f64 {
    let mut scratch = e.scratch();
    let schedule = Schedule {
        steps: reg_steps,
        every: 1,
    };
    best_time(repeats, || {
        let x = e.emulate(reg, schedule, x0, u, &mut scratch, |_, _| {});
        black_box(&x);
    })
}

impl Job for Params {
    fn params_json(&self) -> serde_json::Value {
        serde_json::to_value(self).unwrap_or_default()
    }

    fn run(&self, ctx: &RunContext) -> Result<Tables, Error> {
        let mut table = Table::new(&[
            "model",
            "emulator",
            "physical_s",
            "emulator_s",
            "speedup",
            "physical_steps",
            "emulator_steps",
            "physical_step_s",
            "emulator_step_s",
            "n",
            "step_cost_ratio",
            "physical_integrator",
            "physical_dt",
        ]);
        let mut equal = Table::new(&[
            "model",
            "emulator",
            "emulator_error",
            "substeps",
            "matched_dt",
            "matched_error",
            "coarser_error",
            "physical_steps",
            "emulator_steps",
            "physical_s",
            "emulator_s",
            "speedup",
        ]);
        let steps = self.physical_steps;
        for (i, tm) in self.models.iter().enumerate() {
            let model: NetModel = tm.net.model;
            let dt = tm.net.physical_dt;
            let mut rng = ctx.rng(100 + i as u64);
            let x0 = model.start_state(&mut rng);
            let m = model.control_dim();
            let signal = ControlSignal::sample(
                model.control_process(),
                &model.control_limits(),
                steps as f64 * dt,
                &mut rng,
            );
            let mut u = vec![0.0; steps * m];
            for k in 0..steps {
                signal.at(k as f64 * dt, &mut u[k * m..(k + 1) * m]);
            }
            let mut sim = model.simulator();
            let physical_s = ctx.stage(&format!("time {} physical", model.name()), || {
                time_physical(sim.as_mut(), &x0, &u, dt, steps, self.repeats)
            });
            for &n in &tm.emulators {
                let spec = build_spec(ctx.seed, &tm.net, n, self.example_scale, &self.training);
                let trained = ctx.stage(&format!("train {} N{n}", model.name()), || {
                    build_emulator(&spec)
                })?;
                let k_steps = steps / n;
                let mut ue = vec![0.0; k_steps * m];
                for k in 0..k_steps {
                    ue[k * m..(k + 1) * m].copy_from_slice(&u[k * n * m..(k * n + 1) * m]);
                }
                let emulator_s = ctx.stage(&format!("time {} N{n}", model.name()), || {
                    time_emulator(&trained.emulator, &x0, &ue, k_steps, self.repeats)
                });
                let label = format!("N{n}");
                push_speedup(
                    &mut table,
                    model.name(),
                    &label,
                    "RK4",
                    dt,
                    (physical_s, steps),
                    (emulator_s, k_steps),
                );
                // Equal accuracy: the largest step Δt / j as accurate as the emulator.
                let reference = ctx
                    .stage(&format!("reference rollouts {} N{n}", model.name()), || {
                        RolloutReference::sample(&spec, ROLLOUT_EPISODES, ROLLOUT_STEPS)
                    })
                    .map_err(other)?;
                let emulator_error = reference.emulator_error(&trained.emulator);
                let matched = ctx.stage(&format!("match {} N{n}", model.name()), || {
                    match_substeps(emulator_error, n, |j| reference.physical_error(j))
                });
                let Some(matched) = matched else {
                    return Err(other(format!(
                        "{} N{n}: no physical step matches the emulator's error {emulator_error}",
                        model.name()
                    )));
                };
                let j = matched.substeps;
                let matched_dt = spec.super_dt() / j as f64;
                let uj = hold(&ue, m, j);
                let matched_s =
                    ctx.stage(&format!("time {} at {matched_dt} s", model.name()), || {
                        time_physical(
                            sim.as_mut(),
                            &x0,
                            &uj,
                            matched_dt,
                            k_steps * j,
                            self.repeats,
                        )
                    });
                equal.push(row![
                    model.name(),
                    label.as_str(),
                    emulator_error,
                    j as i64,
                    matched_dt,
                    matched.error,
                    matched.coarser_error,
                    (k_steps * j) as i64,
                    k_steps as i64,
                    matched_s,
                    emulator_s,
                    matched_s / emulator_s
                ]);
            }
        }
        if let Some(d) = &self.dolphin {
            let spec = d.nets.spec(ctx.seed, d.steps, self.example_scale);
            let built = ctx.stage("train dolphin hierarchy", || build_dolphin_emulator(&spec))?;
            let dolphin = built.emulator.dolphin().clone();
            let dt = d.nets.physical_dt;
            let mut rng = ctx.rng(200);
            let x0 = hierarchy::start_state(&dolphin, &mut rng);
            let m = Dynamics::control_dim(&built.emulator);
            let signal = ControlSignal::sample(
                hierarchy::control_process(),
                &hierarchy::control_limits(),
                steps as f64 * dt,
                &mut rng,
            );
            let mut u = vec![0.0; steps * m];
            for k in 0..steps {
                signal.at(k as f64 * dt, &mut u[k * m..(k + 1) * m]);
            }
            let mut sim = hierarchy::simulator(&dolphin);
            let physical_s = ctx.stage("time dolphin physical", || {
                time_physical(&mut sim, &x0, &u, dt, steps, self.repeats)
            });
            let n = d.steps;
            let k_steps = steps / n;
            let mut ue = vec![0.0; k_steps * m];
            for k in 0..k_steps {
                ue[k * m..(k + 1) * m].copy_from_slice(&u[k * n * m..(k * n + 1) * m]);
            }
            let mut reg = d.regularization.bind(&dolphin).map_err(other)?;
            for (label, reg_steps) in [
                (format!("N{n}"), 0),
                (format!("N{n}_reg"), d.regularization_steps),
            ] {
                let emulator_s = ctx.stage(&format!("time dolphin {label}"), || {
                    time_dolphin(&built.emulator, &mut reg, reg_steps, &x0, &ue, self.repeats)
                });
                push_speedup(
                    &mut table,
                    "dolphin",
                    &label,
                    DOLPHIN_EXPLICIT,
                    dt,
                    (physical_s, steps),
                    (emulator_s, k_steps),
                );
                if reg_steps > 0 {
                    continue;
                }
                // The implicit integrator at the paper's step over the same simulated time,
                // against the plain N50 (controls held over each implicit step as sampled).
                let Some(h) = d.implicit_dt else { continue };
                let per_super = (n as f64 * dt / h).round() as usize;
                let implicit_steps = k_steps * per_super;
                let mut ui = vec![0.0; implicit_steps * m];
                for k in 0..implicit_steps {
                    signal.at(k as f64 * h, &mut ui[k * m..(k + 1) * m]);
                }
                let mut imp = ImplicitDolphin::new(dolphin.clone());
                let implicit_s = ctx.stage("time dolphin implicit", || {
                    time_physical(&mut imp, &x0, &ui, h, implicit_steps, self.repeats)
                });
                push_speedup(
                    &mut table,
                    "dolphin",
                    &label,
                    DOLPHIN_IMPLICIT,
                    h,
                    (implicit_s, implicit_steps),
                    (emulator_s, k_steps),
                );
            }
        }
        Ok(Tables::from([
            ("speedup", table),
            ("equal_accuracy", equal),
        ]))
    }
}

impl Family for NaSpeedup {
    const KIND: &'static str = "na_table2_speedup";
    type Params = Params;

    fn figures(&self, fig: &FigureSink, tables: &Tables) -> Result<Vec<PathBuf>, Error> {
        let t = tables.require("speedup")?;
        let (model, emu, phys, es, integ) = (
            t.strs("model"),
            t.strs("emulator"),
            t.f64s("physical_s"),
            t.f64s("emulator_s"),
            t.strs("physical_integrator"),
        );
        // One group of bars per physical simulator: model and integrator.
        let group: Vec<String> = (0..model.len())
            .map(|r| format!("{} ({})", model[r], integ[r]))
            .collect();
        let groups = unique(&group);
        let kinds = unique(&emu);
        // Groups of bars per model: physical, then each emulator kind.
        let slots = kinds.len() + 1;
        let w = 0.8 / slots as f64;
        let pos = |mi: usize, slot: usize| mi as f64 + (slot as f64 + 0.5) * w - 0.4;
        // Physical bars carry their seconds, emulator bars their speedup (physical / emulator).
        let phys_rows: Vec<(f64, f64)> = groups
            .iter()
            .enumerate()
            .filter_map(|(mi, g)| {
                let r = group.iter().position(|x| x == g)?;
                Some((pos(mi, 0), phys[r]))
            })
            .collect();
        let phys_text = phys_rows
            .iter()
            .map(|q| format!("{} s", sig(q.1)))
            .collect();
        let mut series = vec![Series::line("physical simulator", phys_rows, 0)
            .mark(Mark::Bars {
                half_width: 0.45 * w,
            })
            .labelled(phys_text)];
        for (ki, k) in kinds.iter().enumerate() {
            let rows: Vec<usize> = groups
                .iter()
                .filter_map(|g| (0..model.len()).find(|&r| &group[r] == g && &emu[r] == k))
                .collect();
            let pts = rows
                .iter()
                .map(|&r| {
                    let mi = groups.iter().position(|g| *g == group[r]).unwrap_or(0);
                    (pos(mi, ki + 1), es[r])
                })
                .collect();
            let text = rows
                .iter()
                .map(|&r| format!("{:.0}×", phys[r] / es[r]))
                .collect();
            series.push(
                Series::line(format!("{k} (×: speedup)"), pts, ki + 1)
                    .mark(Mark::Bars {
                        half_width: 0.45 * w,
                    })
                    .labelled(text),
            );
        }
        let panel = Panel {
            title: format!(
                "Seconds for the simulated time of {} physical steps (log scale)",
                t.f64s("physical_steps").first().copied().unwrap_or(0.0)
            ),
            x_label: "physical simulator".into(),
            x_categories: groups,
            y_label: "wall time (s)".into(),
            log_y: true,
            series,
            ..Panel::default()
        };
        let mut panels = vec![panel];
        // Speedup at the training step against speedup at equal accuracy, per emulator.
        if let Ok(eq) = tables.require("equal_accuracy") {
            let (em, ee, esp, ej) = (
                eq.strs("model"),
                eq.strs("emulator"),
                eq.f64s("speedup"),
                eq.f64s("substeps"),
            );
            let cats: Vec<String> = (0..em.len())
                .map(|r| format!("{} {}", em[r].trim_start_matches("pendulum_"), ee[r]))
                .collect();
            let at_dt: Vec<(f64, f64)> = (0..em.len())
                .filter_map(|r| {
                    let s = (0..model.len()).find(|&q| {
                        model[q] == em[r] && emu[q] == ee[r] && integ[q] != DOLPHIN_IMPLICIT
                    })?;
                    Some((r as f64 - 0.2, phys[s] / es[s]))
                })
                .collect();
            let at_dt_text = at_dt.iter().map(|p| format!("{:.0}×", p.1)).collect();
            let eq_pts: Vec<(f64, f64)> = (0..em.len()).map(|r| (r as f64 + 0.2, esp[r])).collect();
            let eq_text = (0..em.len())
                .map(|r| format!("{}× (j={})", sig(esp[r]), ej[r]))
                .collect();
            panels.push(Panel {
                title: "Speedup over the physical simulator at the training δt and at the largest step Δt/j as accurate as the emulator (log scale)".into(),
                x_label: "emulator".into(),
                x_categories: cats,
                y_label: "speedup (physical s / emulator s)".into(),
                log_y: true,
                series: vec![
                    Series::line("at the training δt", at_dt, 0)
                        .mark(Mark::Bars { half_width: 0.18 })
                        .labelled(at_dt_text),
                    Series::line("at equal accuracy", eq_pts, 3)
                        .mark(Mark::Bars { half_width: 0.18 })
                        .labelled(eq_text),
                ],
                ..Panel::default()
            });
        }
        let mut fig_ = Figure::grid(panels, 1);
        fig_.panel_size = (1100, 560);
        fig.draw("speedup", &fig_)
    }

    fn report(&self, dir: &Path) -> Result<Findings, Error> {
        let df = read_csv(&dir.join("speedup.csv"))?;
        let (model, emu, integ) = (
            df_str(&df, "model")?,
            df_str(&df, "emulator")?,
            df_str(&df, "physical_integrator")?,
        );
        let (phys, es, sp) = (
            df_f64(&df, "physical_s")?,
            df_f64(&df, "emulator_s")?,
            df_f64(&df, "speedup")?,
        );
        let (ps, esr, n, ratio, pdt) = (
            df_f64(&df, "physical_step_s")?,
            df_f64(&df, "emulator_step_s")?,
            df_f64(&df, "n")?,
            df_f64(&df, "step_cost_ratio")?,
            df_f64(&df, "physical_dt")?,
        );
        let mut md = String::from(
            "| model | physical integrator, δt (s) | emulator | physical s | emulator s | speedup | = n | × step cost ratio | paper's ratio | physical step s | emulator step s |\n| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |\n",
        );
        for r in 0..model.len() {
            let paper = paper_ratio(&model[r], &emu[r]).map_or("—".to_string(), sig);
            md.push_str(&format!(
                "| {} | {}, {} | {} | {} | {} | {} | {} | {} | {} | {} | {} |\n",
                model[r],
                integ[r],
                pdt[r],
                emu[r],
                sig(phys[r]),
                sig(es[r]),
                sig(sp[r]),
                n[r],
                sig(ratio[r]),
                paper,
                sig(ps[r]),
                sig(esr[r])
            ));
        }
        let explicit = |r: usize| integ[r] != DOLPHIN_IMPLICIT;
        let n100: Vec<f64> = (0..model.len())
            .filter(|&r| emu[r] == "N100")
            .map(|r| sp[r])
            .collect();
        let n50_min = (0..model.len())
            .filter(|&r| emu[r] == "N50" && model[r] != "dolphin")
            .map(|r| sp[r])
            .fold(f64::INFINITY, f64::min);
        // Paper: N100 50-100x "and more"; every emulator an order of magnitude or more.
        let n100_ok = !n100.is_empty() && n100.iter().all(|&s| s >= 50.0);
        let n50_ok = n50_min >= 10.0;
        let dolphin = |e: &str, implicit: bool| {
            (0..model.len())
                .find(|&r| model[r] == "dolphin" && emu[r] == e && explicit(r) != implicit)
        };
        let dolphin_text = match (dolphin("N50", false), dolphin("N50_reg", false)) {
            (Some(a), Some(b)) => format!(
                " Dolphin: N50 {}x, N50 with regularization {}x over our semi-implicit Euler at δt = {} s (paper: 66x and 25x over its [18]).",
                sig(sp[a]),
                sig(sp[b]),
                pdt[a]
            ),
            _ => " Dolphin rows not built.".into(),
        };
        let implicit_text = match dolphin("N50", true) {
            Some(r) => format!(
                " Against the implicit (backward Euler) integrator at the paper's δt = {} s, one step costs {} s ({}x an N50 step), n = {}, so N50 is {}x faster (paper: 63.0 s / 0.95 s = 66x).",
                pdt[r],
                sig(ps[r]),
                sig(ratio[r]),
                n[r],
                sig(sp[r])
            ),
            None => String::new(),
        };
        let mut equal_text = String::new();
        let eq_path = dir.join("equal_accuracy.csv");
        if eq_path.exists() {
            let eq = read_csv(&eq_path)?;
            let (em, ee) = (df_str(&eq, "model")?, df_str(&eq, "emulator")?);
            let (err, j, mdt, merr, cerr, eps, ees, esp) = (
                df_f64(&eq, "emulator_error")?,
                df_f64(&eq, "substeps")?,
                df_f64(&eq, "matched_dt")?,
                df_f64(&eq, "matched_error")?,
                df_f64(&eq, "coarser_error")?,
                df_f64(&eq, "physical_s")?,
                df_f64(&eq, "emulator_s")?,
                df_f64(&eq, "speedup")?,
            );
            md.push_str("\n**Equal accuracy** (data, not part of the verdict): error = mean over 40 super-steps of the per-step mean squared state error in units of each variable's spread (Table 1's `rollout40_error_mean`), against the simulator at the training δt; the physical step is the largest Δt/j (j = 1 … n) whose error is at most the emulator's.\n\n| model | emulator | emulator error | j | matched δt (s) | its error | error at Δt/(j−1) | physical s | emulator s | speedup |\n| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |\n");
            for r in 0..em.len() {
                md.push_str(&format!(
                    "| {} | {} | {} | {} | {} | {} | {} | {} | {} | {} |\n",
                    em[r],
                    ee[r],
                    sig(err[r]),
                    j[r],
                    sig(mdt[r]),
                    sig(merr[r]),
                    if cerr[r].is_nan() {
                        "— (j = 1)".to_string()
                    } else {
                        sig(cerr[r])
                    },
                    sig(eps[r]),
                    sig(ees[r]),
                    sig(esp[r])
                ));
            }
            let at_one = (0..em.len()).filter(|&r| j[r] == 1.0).count();
            equal_text = format!(
                " At equal accuracy the speedups are {} ({} of {} emulators are matched by one physical step per super-step, so their equal-accuracy speedup is only the step cost ratio, an upper bound on the emulator's advantage).",
                esp.iter().map(|s| sig(*s)).collect::<Vec<_>>().join(", "),
                at_one,
                em.len()
            );
        }
        let pend: Vec<f64> = (0..model.len())
            .filter(|&r| model[r].starts_with("pendulum"))
            .map(|r| ratio[r])
            .collect();
        let pend_lo = sig(pend.iter().copied().fold(f64::INFINITY, f64::min));
        let pend_hi = sig(pend.iter().copied().fold(f64::NEG_INFINITY, f64::max));
        let ratio_of = |m: &str| {
            (0..model.len())
                .find(|&r| model[r] == m)
                .map_or("—".to_string(), |r| sig(ratio[r]))
        };
        let (truck_ratio, lander_ratio) = (ratio_of("truck"), ratio_of("lander"));
        let verdict = Verdict::from_checks(&[n100_ok, n50_ok]);
        Ok(Findings {
            ours: md,
            verdict,
            why: format!(
                "N100 speedups {} (paper: 50-100x and more); the slowest rigid-body N50 speedup is {} (paper: one to two orders of magnitude); speedup = n x step cost ratio (physical step s / emulator step s); the paper's ratios, from its Table 2, are 1.1-2.4 (0.5 with regularization), ours {pend_lo}-{pend_hi} for the pendulums, {truck_ratio} for the truck, {lander_ratio} for the lander (a 13-variable rigid body: one RK4 step costs less than a 17-50-13 net).{dolphin_text}{implicit_text}{equal_text}",
                n100.iter().map(|s| sig(*s)).collect::<Vec<_>>().join(", "),
                sig(n50_min)
            ),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn speedup_is_n_times_the_step_cost_ratio() {
        for (ps, pn, es, en) in [
            (0.0134, 20000, 1.21e-4, 400),
            (0.0027, 20000, 5.9e-4, 400),
            (0.21, 4000, 0.0118, 400),
            (3.3e-3, 77, 1.7e-2, 7),
        ] {
            let b = breakdown(ps, pn, es, en);
            let speedup = ps / es;
            assert_eq!(b.n, (pn / en) as i64);
            assert!(
                (b.n as f64 * b.ratio - speedup).abs() <= 1e-12 * speedup,
                "{b:?} vs {speedup}"
            );
            assert!((b.physical_step_s * pn as f64 - ps).abs() <= 1e-15 * ps);
        }
    }

    #[test]
    fn held_controls_repeat_each_row() {
        let u = [1.0, 2.0, 3.0, 4.0];
        assert_eq!(
            hold(&u, 2, 3),
            [1.0, 2.0, 1.0, 2.0, 1.0, 2.0, 3.0, 4.0, 3.0, 4.0, 3.0, 4.0]
        );
        assert_eq!(hold(&u, 2, 1), u);
    }
}
