//! `na_regularization` (NeuroAnimator §5.3, Table 2's last column): a mass-spring emulator's
//! small errors accumulate over hundreds of emulation steps into unnatural deformation; a few
//! cheap explicit-Euler regularization steps of the true spring dynamics (softer springs, more
//! damping) after every emulation step remove it, and do so more smoothly than more steps done
//! less often.
//!
//! The hierarchical dolphin emulator of `na_table1_structure` (from the cache) runs for
//! `duration_s` seconds from `trials` start states under travelling-wave muscle controls held
//! per super step, once per [`Schedule`] (e.g. none, 1 and 5 steps after every emulation step,
//! 25 steps after every fifth: the same budget as 5 per step, spent rarely); the physical
//! simulator runs the same controls as the reference. After every emulation step we record the
//! shape error — the RMS relative deviation of the spring lengths from their rest lengths
//! ([`crate::physics::dolphin::Dolphin::shape_error`]) — and the roughness of the motion, the
//! RMS second difference of the mass positions relative to the centre of mass between
//! consecutive super steps (a regularization burst that snaps the body shows up there).
//!
//! Tables: `shape_error` (schedule, t, shape_error; mean over trials; the simulator's rows are
//! schedule `simulator`) and `cost` (schedule, reg_steps, every, seconds, us_per_step,
//! mean_shape_error, final_shape_error, roughness). Seconds are wall time of the emulation loop
//! (fastest of `repeats`) and the one column that is not bit-reproducible.

use super::table1_structure::{build_dolphin_emulator, DolphinNets};
use super::table2_speedup::validate_regularizer;
use crate::emulator::dataset::ControlSignal;
use crate::emulator::hierarchy::{self, Regularizer, Schedule};
use crate::experiment::output::{unique, Tables};
use crate::experiment::plot::{Figure, FigureSink, Mark, Panel, Series};
use crate::experiment::report::{sig, Findings};
use crate::experiment::resolve::{ensure, positive, ParamError, Validate};
use crate::experiment::rows::{read_rows, table_of, TableRow};
use crate::experiment::rule::{
    rule_settings, rule_table_of, shown, Check, Cmp, Null, Partly, Rule,
};
use crate::experiment::{other, Error, Family, Job, RunContext};
use crate::physics::dolphin::{Dolphin, N_POS, N_SEGMENTS};
use crate::physics::{check_finite, Dynamics};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// The schedule name of the physical simulator's rows.
const SIMULATOR: &str = "simulator";

crate::result_rows! {
    /// One row of `shape_error.csv`: a schedule's mean shape error over the trials at one time.
    pub struct ShapeErrorRow {
        /// The schedule's name ([`SIMULATOR`] for the physical reference).
        schedule: String = "schedule",
        /// Animation time (s).
        t: f64 = "t",
        /// RMS relative spring-length deviation, mean over trials (inf once an emulation diverged).
        shape_error: f64 = "shape_error",
    }
}

crate::result_rows! {
    /// One row of `cost.csv`: a schedule's cost and its shape error over the whole run.
    pub struct CostRow {
        /// The schedule's name ([`SIMULATOR`] for the physical reference).
        schedule: String = "schedule",
        /// Regularization steps per burst (0: none).
        reg_steps: i64 = "reg_steps",
        /// Emulation steps between bursts (0 for the simulator).
        every: i64 = "every",
        /// Wall time of the emulation loop (s; fastest of the repeats; NaN for the simulator).
        seconds: f64 = "seconds",
        /// Microseconds per emulation step (NaN for the simulator).
        us_per_step: f64 = "us_per_step",
        /// Shape error averaged over the steps after the start.
        mean_shape_error: f64 = "mean_shape_error",
        /// Shape error at the last step.
        final_shape_error: f64 = "final_shape_error",
        /// Mean RMS second difference of the mass positions about the centre of mass (m).
        roughness: f64 = "roughness",
    }
}

/// The family.
pub struct NaRegularization;

/// A named regularization schedule.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NamedSchedule {
    /// Name in the tables.
    pub name: String,
    /// Regularization steps each time.
    pub steps: usize,
    /// Emulation steps between regularizations.
    pub every: usize,
}

/// Parameters of `na_regularization`.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Params {
    /// The hierarchy (as in `na_table1_structure`, so it comes from the cache).
    pub nets: DolphinNets,
    /// Physical steps per emulator step n.
    pub steps: usize,
    /// Multiplies the nets' example counts.
    pub example_scale: f64,
    /// Animation length per trial (s).
    pub duration_s: f64,
    /// Start states (trials).
    pub trials: usize,
    /// Timing repetitions (fastest kept).
    pub repeats: usize,
    /// The regularization step.
    pub regularization: Regularizer,
    /// The schedules compared.
    pub schedules: Vec<NamedSchedule>,
    /// The verdict's thresholds (ours).
    pub rule: RegularizationRule,
}

/// The verdict's thresholds ([`regularization_rule`]; ours, the paper states no number).
#[derive(Debug, Clone, Copy, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RegularizationRule {
    /// The emulation drifts: its final shape error without regularization is at least this
    /// many times the simulator's.
    pub drift_ratio: f64,
    /// A few steps after each emulation step fix it: their mean shape error is below this
    /// fraction of the unregularized one.
    pub fix_ratio: f64,
}

impl RegularizationRule {
    fn validate(&self) -> Result<(), ParamError> {
        ensure(
            self.drift_ratio > 1.0,
            "rule.drift_ratio",
            "must be above 1: the simulator itself scores 1",
        )?;
        ensure(
            self.fix_ratio > 0.0 && self.fix_ratio < 1.0,
            "rule.fix_ratio",
            "must be in (0, 1): no regularization scores 1",
        )
    }
}

/// The verdict's rule on the final shape error without regularization over the simulator's
/// (`drift`), the few-steps schedule's mean shape error over the unregularized one (`fix`) and
/// its roughness over the same budget spent rarely (`rough`): (a) drift above `r.drift_ratio`
/// (null: the simulator itself, 1), (b) fix below `r.fix_ratio` (null: no
/// regularization, 1), (c) smoother than the rare bursts (null: the rare schedule itself, 1).
/// Held when all pass; partly when (a) and (b) do, or (c).
pub fn regularization_rule(
    drift: f64,
    fix: f64,
    rough: f64,
    r: &RegularizationRule,
) -> Option<Rule> {
    let held = vec![
        Check::new(
            "final shape error without regularization over the simulator's",
            drift,
            Cmp::Above,
            r.drift_ratio,
            Null::new("the simulator itself", 1.0),
        ),
        Check::new(
            "mean shape error with a few steps after each emulation step over none",
            fix,
            Cmp::Below,
            r.fix_ratio,
            Null::new("no regularization", 1.0),
        ),
        Check::new(
            "roughness of those steps over the same budget spent rarely",
            rough,
            Cmp::Below,
            1.0,
            Null::new("the rare schedule itself", 1.0),
        ),
    ];
    Rule::gated(vec![], held, Partly::AnyOf(vec![vec![0, 1], vec![2]]))
}

impl Validate for Params {
    fn validate(&self) -> Result<(), ParamError> {
        self.nets.validate("nets", self.example_scale)?;
        self.rule.validate()?;
        ensure(self.steps >= 1, "steps", "must be >= 1")?;
        positive("example_scale", self.example_scale)?;
        positive("duration_s", self.duration_s)?;
        ensure(
            self.duration_s >= 2.0 * self.steps as f64 * self.nets.physical_dt,
            "duration_s",
            "must cover at least two emulation steps",
        )?;
        ensure(self.trials >= 1, "trials", "must be >= 1")?;
        ensure(self.repeats >= 1, "repeats", "must be >= 1")?;
        validate_regularizer("regularization", &self.regularization)?;
        ensure(!self.schedules.is_empty(), "schedules", "need at least one")?;
        for (i, s) in self.schedules.iter().enumerate() {
            ensure(
                s.every >= 1,
                &format!("schedules[{i}].every"),
                "must be >= 1",
            )?;
            ensure(
                !s.name.is_empty() && s.name != "simulator",
                &format!("schedules[{i}].name"),
                "must be non-empty and not `simulator` (the reference's name)",
            )?;
        }
        Ok(())
    }
}

/// RMS over masses of the second difference of positions relative to the centre of mass.
fn roughness(d: &Dolphin, a: &[f64], b: &[f64], c: &[f64]) -> f64 {
    let (ca, cb, cc) = (
        d.centre_of_mass(a),
        d.centre_of_mass(b),
        d.centre_of_mass(c),
    );
    let mut sum = 0.0;
    for i in 0..N_POS {
        let k = i % 3;
        let dd = (a[i] - ca[k]) - 2.0 * (b[i] - cb[k]) + (c[i] - cc[k]);
        sum += dd * dd;
    }
    (sum / (N_POS / 3) as f64).sqrt()
}

impl Job for Params {
    fn params_json(&self) -> serde_json::Value {
        serde_json::to_value(self).unwrap_or_default()
    }

    fn run(&self, ctx: &RunContext) -> Result<Tables, Error> {
        let spec = self.nets.spec(ctx.seed, self.steps, self.example_scale);
        let built = ctx.stage("train dolphin hierarchy", || build_dolphin_emulator(&spec))?;
        let emu = &built.emulator;
        let d = emu.dolphin().clone();
        let (n, dt) = (self.steps, self.nets.physical_dt);
        let big_dt = n as f64 * dt;
        let k_steps = (self.duration_s / big_dt).round() as usize;
        let m = N_SEGMENTS;
        // Per trial: start state and per-super-step controls.
        let cases: Vec<(Vec<f64>, Vec<f64>)> = (0..self.trials)
            .map(|t| {
                let mut rng = ctx.rng(300 + t as u64);
                let x0 = hierarchy::start_state(&d, &mut rng);
                let signal = ControlSignal::sample(
                    hierarchy::control_process(),
                    &hierarchy::control_limits(),
                    self.duration_s,
                    &mut rng,
                );
                let mut u = vec![0.0; k_steps * m];
                for k in 0..k_steps {
                    signal.at(k as f64 * big_dt, &mut u[k * m..(k + 1) * m]);
                }
                (x0, u)
            })
            .collect();
        let (mut shape, mut cost) = (Vec::new(), Vec::new());
        // The physical reference.
        {
            let mut sim = hierarchy::simulator(&d);
            let mut curve = vec![0.0; k_steps + 1];
            let mut rough = 0.0;
            for (x0, u) in &cases {
                let mut traj = vec![x0.clone()];
                let mut x = x0.clone();
                curve[0] += d.shape_error(&x) / self.trials as f64;
                for k in 0..k_steps {
                    for j in 0..n {
                        sim.step(&mut x, &u[k * m..(k + 1) * m], dt);
                        check_finite("dolphin", k * n + j + 1, (k * n + j + 1) as f64 * dt, &x)
                            .map_err(other)?;
                    }
                    curve[k + 1] += d.shape_error(&x) / self.trials as f64;
                    traj.push(x.clone());
                }
                rough += mean_roughness(&d, &traj) / self.trials as f64;
            }
            push_curve(&mut shape, SIMULATOR, &curve, big_dt);
            cost.push(CostRow {
                schedule: SIMULATOR.into(),
                reg_steps: 0,
                every: 0,
                seconds: f64::NAN,
                us_per_step: f64::NAN,
                mean_shape_error: mean(&curve[1..]),
                final_shape_error: curve[k_steps],
                roughness: rough,
            });
        }
        let pb = ctx.progress(self.schedules.len() as u64, "regularization schedules");
        for s in &self.schedules {
            let sched = Schedule {
                steps: s.steps,
                every: s.every,
            };
            let mut reg = self.regularization.bind(&d).map_err(other)?;
            let mut scratch = emu.scratch();
            let mut curve = vec![0.0; k_steps + 1];
            let mut rough = 0.0;
            for (x0, u) in &cases {
                let mut traj = vec![x0.clone()];
                curve[0] += d.shape_error(x0) / self.trials as f64;
                emu.emulate(&mut reg, sched, x0, u, &mut scratch, |k, x| {
                    // An emulator may diverge: record it (as inf) rather than abort the run.
                    let e = d.shape_error(x);
                    curve[k] += if e.is_finite() { e } else { f64::INFINITY } / self.trials as f64;
                    traj.push(x.to_vec());
                });
                rough += mean_roughness(&d, &traj) / self.trials as f64;
            }
            // Timing: the first trial's loop, fastest of `repeats`.
            let (x0, u) = &cases[0];
            let seconds = (0..self.repeats)
                .map(|_| {
                    let t0 = Instant::now();
                    let x = emu.emulate(&mut reg, sched, x0, u, &mut scratch, |_, _| {});
                    std::hint::black_box(&x);
                    t0.elapsed().as_secs_f64()
                })
                .fold(f64::INFINITY, f64::min);
            push_curve(&mut shape, &s.name, &curve, big_dt);
            cost.push(CostRow {
                schedule: s.name.clone(),
                reg_steps: s.steps as i64,
                every: s.every as i64,
                seconds,
                us_per_step: 1e6 * seconds / k_steps as f64,
                mean_shape_error: mean(&curve[1..]),
                final_shape_error: curve[k_steps],
                roughness: rough,
            });
            pb.inc(1);
        }
        pb.finish_and_clear();
        Ok(Tables::from([
            ("shape_error", table_of(&shape)),
            ("cost", table_of(&cost)),
            ("rule", rule_table_of(&self.rule)?),
        ]))
    }
}

fn mean(v: &[f64]) -> f64 {
    v.iter().sum::<f64>() / v.len().max(1) as f64
}

fn mean_roughness(d: &Dolphin, traj: &[Vec<f64>]) -> f64 {
    let r: Vec<f64> = traj
        .windows(3)
        .map(|w| roughness(d, &w[0], &w[1], &w[2]))
        .collect();
    let m = mean(&r);
    if m.is_finite() {
        m
    } else {
        f64::INFINITY
    }
}

fn push_curve(rows: &mut Vec<ShapeErrorRow>, name: &str, curve: &[f64], big_dt: f64) {
    for (k, e) in curve.iter().enumerate() {
        rows.push(ShapeErrorRow {
            schedule: name.to_string(),
            t: k as f64 * big_dt,
            shape_error: *e,
        });
    }
}

impl Family for NaRegularization {
    const CAPTIONS: &'static [(&'static str, &'static str)] = &[
        (
            "shape_error",
            "the dolphin hierarchy's shape error (RMS spring-length deviation) over 60 s beside the simulator's, with 0, 1 and 5 regularization steps per emulation step and 25 every fifth step.",
        ),
    ];
    const KIND: &'static str = "na_regularization";
    type Params = Params;

    fn figures(&self, fig: &FigureSink, tables: &Tables) -> Result<Vec<PathBuf>, Error> {
        let shape = ShapeErrorRow::from_table(tables.require("shape_error")?);
        let names = unique(&shape.iter().map(|r| r.schedule.clone()).collect::<Vec<_>>());
        // Each schedule in words, from the cost table's steps and spacing.
        let cost = CostRow::from_table(tables.require("cost")?);
        let words = |nm: &str| -> String {
            match cost.iter().find(|c| c.schedule == nm) {
                _ if nm == SIMULATOR => "physical simulator".into(),
                Some(c) if c.reg_steps == 0 => "emulator, no regularization".into(),
                Some(c) if c.every <= 1 => format!(
                    "emulator, {} regularization step{} after every step",
                    c.reg_steps,
                    if c.reg_steps == 1 { "" } else { "s" }
                ),
                Some(c) => format!(
                    "emulator, {} regularization steps after every {}th step",
                    c.reg_steps, c.every
                ),
                None => nm.to_string(),
            }
        };
        let series = names
            .iter()
            .enumerate()
            .map(|(i, nm)| {
                let pts = shape
                    .iter()
                    // t = 0 is the exact rest shape (error ~1e-15), off the log scale.
                    .filter(|r| r.schedule == *nm && r.t > 0.0)
                    .map(|r| (r.t, r.shape_error))
                    .collect();
                let s = Series::line(words(nm), pts, i);
                if nm == SIMULATOR {
                    s.mark(Mark::Dashed)
                } else {
                    s
                }
            })
            .collect();
        let panel = Panel {
            title: "Dolphin emulation: shape error vs time".into(),
            x_label: "animation time (s)".into(),
            y_label: "RMS relative spring-length deviation".into(),
            log_y: true,
            series,
            ..Panel::default()
        };
        let mut f = Figure::grid(vec![panel], 1);
        f.panel_size = (900, 520);
        fig.draw("shape_error", &f)
    }

    fn report(&self, dir: &Path) -> Result<Findings, Error> {
        let cost: Vec<CostRow> = read_rows(&dir.join("cost.csv"))?;
        let mut md = String::from(
            "| schedule | steps | every | us per emulation step | mean shape error | final shape error | roughness (m) |\n| --- | --- | --- | --- | --- | --- | --- |\n",
        );
        for r in &cost {
            md.push_str(&format!(
                "| {} | {} | {} | {} | {} | {} | {} |\n",
                r.schedule,
                r.reg_steps,
                r.every,
                sig(r.us_per_step),
                sig(r.mean_shape_error),
                sig(r.final_shape_error),
                sig(r.roughness)
            ));
        }
        let emulated = || cost.iter().filter(|r| r.schedule != SIMULATOR);
        let sim = cost.iter().find(|r| r.schedule == SIMULATOR);
        let none = emulated().find(|r| r.reg_steps == 0);
        // "A few steps after each emulation step": the largest such schedule up to 5 steps.
        let few = emulated()
            .filter(|r| r.reg_steps > 0 && r.every == 1 && r.reg_steps <= 5)
            .max_by_key(|r| r.reg_steps);
        let rare = cost.iter().find(|r| r.every > 1 && r.reg_steps > 0);
        let (verdict, why, rule) = match (sim, none, few, rare) {
            (Some(s), Some(z), Some(f), Some(r)) => {
                let settings = rule_settings(dir)?;
                let bars = RegularizationRule {
                    drift_ratio: settings("drift_ratio"),
                    fix_ratio: settings("fix_ratio"),
                };
                let rule = regularization_rule(
                    z.final_shape_error / s.final_shape_error,
                    f.mean_shape_error / z.mean_shape_error,
                    f.roughness / r.roughness,
                    &bars,
                );
                let (verdict, lines, text) = shown(rule.as_ref(), " No rule: a bar its null meets.");
                (
                    verdict,
                    format!(
                        "Without regularization the final shape error is {} ({}x the simulator's {}); `{}` brings the mean shape error from {} to {}; its roughness {} vs {} for `{}` (same budget, rarely). Checks:{lines} Rule (thresholds ours, in the spec's [params.rule]): {text}",
                        sig(z.final_shape_error),
                        sig(z.final_shape_error / s.final_shape_error),
                        sig(s.final_shape_error),
                        f.schedule,
                        sig(z.mean_shape_error),
                        sig(f.mean_shape_error),
                        sig(f.roughness),
                        sig(r.roughness),
                        r.schedule
                    ),
                    rule,
                )
            }
            _ => (
                crate::experiment::report::Verdict::NotAssessed,
                "needs a simulator row, a schedule without regularization, one with a few steps after every emulation step and one with steps done rarely".into(),
                None,
            ),
        };
        Ok(Findings {
            ours: md,
            verdict,
            rule,
            why,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::experiment::report::Verdict;

    const BARS: RegularizationRule = RegularizationRule {
        drift_ratio: 2.0,
        fix_ratio: 0.7,
    };

    #[test]
    fn drift_fixed_and_smoother_is_held_and_each_half_is_partly() {
        let verdict = |d, f, r| regularization_rule(d, f, r, &BARS).map(|x| x.verdict());
        assert_eq!(verdict(734.0, 0.19, 0.54), Some(Verdict::Held));
        // Fixed drift but rougher than rare bursts, or smoother without drift to fix.
        assert_eq!(verdict(734.0, 0.19, 1.2), Some(Verdict::Partly));
        assert_eq!(verdict(1.5, 0.19, 0.54), Some(Verdict::Partly));
        assert_eq!(verdict(1.5, 0.9, 1.2), Some(Verdict::NotHeld));
        // A drift bar the simulator itself passes is refused.
        let low = RegularizationRule {
            drift_ratio: 0.5,
            fix_ratio: 0.7,
        };
        assert!(regularization_rule(734.0, 0.19, 0.54, &low).is_none());
    }
}
