//! The job: train (or load) each emulator, time it against its physical simulator over the
//! same simulated time, at the training step and at equal accuracy, and tabulate the speedups
//! with their breakdown.

use super::timing::{hold, time_dolphin, time_emulator, time_physical};
use super::{Params, TimedDolphin, TimedNet, DOLPHIN_EXPLICIT, DOLPHIN_IMPLICIT};
use crate::emulator::catalog::{NetModel, RolloutReference};
use crate::emulator::dataset::ControlSignal;
use crate::emulator::hierarchy;
use crate::experiment::output::Tables;
use crate::experiment::rows::table_of;
use crate::experiment::rule::rule_table_of;
use crate::experiment::{other, Error, Job, RunContext};
use crate::families::na::equal_accuracy::match_substeps;
use crate::families::na::table1_structure::{
    build_dolphin_emulator, build_emulator, build_spec, ROLLOUT_EPISODES, ROLLOUT_STEPS,
};
use crate::physics::dolphin::ImplicitDolphin;
use crate::physics::Dynamics;

crate::result_rows! {
    /// One row of `speedup.csv`: one emulator timed against one physical simulator over the
    /// same simulated time.
    pub struct SpeedupRow {
        /// The model's name (`pendulum_passive`, ..., `dolphin`).
        model: String = "model",
        /// The emulator's label (`N25`, `N50`, `N100`, `N50_reg`).
        emulator: String = "emulator",
        /// The physical simulator's seconds over the horizon.
        physical_s: f64 = "physical_s",
        /// The emulator's seconds over the same simulated time.
        emulator_s: f64 = "emulator_s",
        /// physical_s / emulator_s.
        speedup: f64 = "speedup",
        /// Physical steps timed.
        physical_steps: i64 = "physical_steps",
        /// Emulator (super-)steps timed.
        emulator_steps: i64 = "emulator_steps",
        /// Seconds per physical step.
        physical_step_s: f64 = "physical_step_s",
        /// Seconds per emulator step.
        emulator_step_s: f64 = "emulator_step_s",
        /// Physical steps per emulator step.
        n: i64 = "n",
        /// Physical step cost / emulator step cost.
        step_cost_ratio: f64 = "step_cost_ratio",
        /// The physical integrator (`RK4`, or the dolphin's explicit or implicit one).
        physical_integrator: String = "physical_integrator",
        /// The physical step (s).
        physical_dt: f64 = "physical_dt",
    }
}

crate::result_rows! {
    /// One row of `equal_accuracy.csv`: an emulator against the largest physical step as
    /// accurate as it.
    pub struct EqualAccuracyRow {
        /// The model's name.
        model: String = "model",
        /// The emulator's label.
        emulator: String = "emulator",
        /// The emulator's rollout error (Table 1's `rollout40_error_mean`).
        emulator_error: f64 = "emulator_error",
        /// j: physical steps per super-step at the matched step Δt/j.
        substeps: i64 = "substeps",
        /// The matched physical step Δt/j (s).
        matched_dt: f64 = "matched_dt",
        /// The physical error at the matched step.
        matched_error: f64 = "matched_error",
        /// The physical error at Δt/(j−1) (NaN when j = 1).
        coarser_error: f64 = "coarser_error",
        /// Physical steps timed at the matched step.
        physical_steps: i64 = "physical_steps",
        /// Emulator steps timed.
        emulator_steps: i64 = "emulator_steps",
        /// The physical simulator's seconds at the matched step.
        physical_s: f64 = "physical_s",
        /// The emulator's seconds.
        emulator_s: f64 = "emulator_s",
        /// physical_s / emulator_s.
        speedup: f64 = "speedup",
    }
}

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

/// One `speedup` row (the timings with their breakdown).
#[allow(clippy::too_many_arguments)]
fn push_speedup(
    rows: &mut Vec<SpeedupRow>,
    model: &str,
    emulator: &str,
    integrator: &str,
    dt: f64,
    (physical_s, physical_steps): (f64, usize),
    (emulator_s, emulator_steps): (f64, usize),
) {
    let b = breakdown(physical_s, physical_steps, emulator_s, emulator_steps);
    rows.push(SpeedupRow {
        model: model.to_string(),
        emulator: emulator.to_string(),
        physical_s,
        emulator_s,
        speedup: physical_s / emulator_s,
        physical_steps: physical_steps as i64,
        emulator_steps: emulator_steps as i64,
        physical_step_s: b.physical_step_s,
        emulator_step_s: b.emulator_step_s,
        n: b.n,
        step_cost_ratio: b.ratio,
        physical_integrator: integrator.to_string(),
        physical_dt: dt,
    });
}

impl Job for Params {
    fn params_json(&self) -> serde_json::Value {
        serde_json::to_value(self).unwrap_or_default()
    }

    fn run(&self, ctx: &RunContext) -> Result<Tables, Error> {
        let mut t = SpeedupTables::default();
        for (i, tm) in self.models.iter().enumerate() {
            self.time_model(ctx, i, tm, &mut t)?;
        }
        if let Some(d) = &self.dolphin {
            self.time_dolphin_nets(ctx, d, &mut t.speedup)?;
        }
        Ok(Tables::from([
            ("speedup", table_of(&t.speedup)),
            ("equal_accuracy", table_of(&t.equal)),
            ("rule", rule_table_of(&self.rule)?),
        ]))
    }
}

/// The `speedup` and `equal_accuracy` rows.
#[derive(Default)]
struct SpeedupTables {
    speedup: Vec<SpeedupRow>,
    equal: Vec<EqualAccuracyRow>,
}

/// A model's timed horizon: its start, the sampled per-step controls and the physical
/// simulator's seconds over them.
struct PhysicalRun {
    x0: Vec<f64>,
    u: Vec<f64>,
    physical_s: f64,
}

impl Params {
    /// One model: its controls sampled from stream `100 + i`, the physical simulator timed
    /// over them, then every emulator of `tm` ([`Params::time_net`]).
    fn time_model(
        &self,
        ctx: &RunContext,
        i: usize,
        tm: &TimedNet,
        t: &mut SpeedupTables,
    ) -> Result<(), Error> {
        let steps = self.physical_steps;
        let model: NetModel = tm.net.model;
        let dt = tm.net.physical_dt;
        let mut rng = ctx.rng(100 + i as u64);
        let x0 = model.start_state_in(tm.net.data, &mut rng);
        let m = model.control_dim();
        let signal = ControlSignal::sample(
            model.control_process_in(tm.net.data),
            &model.sampling_limits(tm.net.data),
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
        let run = PhysicalRun { x0, u, physical_s };
        for &n in &tm.emulators {
            self.time_net(ctx, tm, n, &run, sim.as_mut(), t)?;
        }
        Ok(())
    }

    /// The N`n` emulator of `tm`: trained, timed on the held controls beside the physical
    /// run (`speedup` row), and against the largest physical step as accurate as it
    /// (`equal_accuracy` row, that step's run timed on `sim`).
    fn time_net(
        &self,
        ctx: &RunContext,
        tm: &TimedNet,
        n: usize,
        run: &PhysicalRun,
        sim: &mut dyn Dynamics,
        t: &mut SpeedupTables,
    ) -> Result<(), Error> {
        let steps = self.physical_steps;
        let model: NetModel = tm.net.model;
        let dt = tm.net.physical_dt;
        let m = model.control_dim();
        let (x0, u, physical_s) = (&run.x0, &run.u, run.physical_s);
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
            time_emulator(&trained.emulator, x0, &ue, k_steps, self.repeats)
        });
        let label = format!("N{n}");
        push_speedup(
            &mut t.speedup,
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
        let matched_s = ctx.stage(&format!("time {} at {matched_dt} s", model.name()), || {
            time_physical(sim, x0, &uj, matched_dt, k_steps * j, self.repeats)
        });
        t.equal.push(EqualAccuracyRow {
            model: model.name().to_string(),
            emulator: label,
            emulator_error,
            substeps: j as i64,
            matched_dt,
            matched_error: matched.error,
            coarser_error: matched.coarser_error,
            physical_steps: (k_steps * j) as i64,
            emulator_steps: k_steps as i64,
            physical_s: matched_s,
            emulator_s,
            speedup: matched_s / emulator_s,
        });
        Ok(())
    }

    /// The dolphin: its controls sampled from stream 200, the explicit simulator timed over
    /// them, and the plain and regularized hierarchy (the plain one also against the implicit
    /// integrator at the paper's step), one `speedup` row each.
    fn time_dolphin_nets(
        &self,
        ctx: &RunContext,
        d: &TimedDolphin,
        table: &mut Vec<SpeedupRow>,
    ) -> Result<(), Error> {
        let steps = self.physical_steps;
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
                table,
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
                table,
                "dolphin",
                &label,
                DOLPHIN_IMPLICIT,
                h,
                (implicit_s, implicit_steps),
                (emulator_s, k_steps),
            );
        }
        Ok(())
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
}
