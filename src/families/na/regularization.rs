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
use crate::experiment::output::{df_f64, df_str, read_csv, unique, Table, Tables};
use crate::experiment::plot::{Figure, FigureSink, Mark, Panel, Series};
use crate::experiment::report::{sig, Findings};
use crate::experiment::resolve::{ensure, positive, ParamError, Validate};
use crate::experiment::rule::{
    rule_settings, rule_table_of, shown, Check, Cmp, Null, Partly, Rule,
};
use crate::experiment::{other, Error, Family, Job, RunContext};
use crate::physics::dolphin::{Dolphin, N_POS, N_SEGMENTS};
use crate::physics::{check_finite, Dynamics};
use crate::row;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use std::time::Instant;

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
        let mut shape = Table::new(&["schedule", "t", "shape_error"]);
        let mut cost = Table::new(&[
            "schedule",
            "reg_steps",
            "every",
            "seconds",
            "us_per_step",
            "mean_shape_error",
            "final_shape_error",
            "roughness",
        ]);
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
            push_curve(&mut shape, "simulator", &curve, big_dt);
            cost.push(row![
                "simulator",
                0i64,
                0i64,
                f64::NAN,
                f64::NAN,
                mean(&curve[1..]),
                curve[k_steps],
                rough
            ]);
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
            cost.push(row![
                s.name.as_str(),
                s.steps as i64,
                s.every as i64,
                seconds,
                1e6 * seconds / k_steps as f64,
                mean(&curve[1..]),
                curve[k_steps],
                rough
            ]);
            pb.inc(1);
        }
        pb.finish_and_clear();
        Ok(Tables::from([
            ("shape_error", shape),
            ("cost", cost),
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

fn push_curve(t: &mut Table, name: &str, curve: &[f64], big_dt: f64) {
    for (k, e) in curve.iter().enumerate() {
        t.push(row![name, k as f64 * big_dt, *e]);
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
        let t = tables.require("shape_error")?;
        let (name, time, err) = (t.strs("schedule"), t.f64s("t"), t.f64s("shape_error"));
        let names = unique(&name);
        // Each schedule in words, from the cost table's steps and spacing.
        let cost = tables.require("cost")?;
        let (cn, cs, ce) = (
            cost.strs("schedule"),
            cost.f64s("reg_steps"),
            cost.f64s("every"),
        );
        let words = |nm: &str| -> String {
            match cn.iter().position(|c| c == nm) {
                _ if nm == "simulator" => "physical simulator".into(),
                Some(r) if cs[r] == 0.0 => "emulator, no regularization".into(),
                Some(r) if ce[r] <= 1.0 => format!(
                    "emulator, {} regularization step{} after every step",
                    cs[r],
                    if cs[r] == 1.0 { "" } else { "s" }
                ),
                Some(r) => format!(
                    "emulator, {} regularization steps after every {}th step",
                    cs[r], ce[r]
                ),
                None => nm.to_string(),
            }
        };
        let series = names
            .iter()
            .enumerate()
            .map(|(i, nm)| {
                let pts = (0..name.len())
                    // t = 0 is the exact rest shape (error ~1e-15), off the log scale.
                    .filter(|&r| &name[r] == nm && time[r] > 0.0)
                    .map(|r| (time[r], err[r]))
                    .collect();
                let s = Series::line(words(nm), pts, i);
                if nm == "simulator" {
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
        let df = read_csv(&dir.join("cost.csv"))?;
        let name = df_str(&df, "schedule")?;
        let (steps, every, us, mean_e, final_e, rough) = (
            df_f64(&df, "reg_steps")?,
            df_f64(&df, "every")?,
            df_f64(&df, "us_per_step")?,
            df_f64(&df, "mean_shape_error")?,
            df_f64(&df, "final_shape_error")?,
            df_f64(&df, "roughness")?,
        );
        let mut md = String::from(
            "| schedule | steps | every | us per emulation step | mean shape error | final shape error | roughness (m) |\n| --- | --- | --- | --- | --- | --- | --- |\n",
        );
        for r in 0..name.len() {
            md.push_str(&format!(
                "| {} | {} | {} | {} | {} | {} | {} |\n",
                name[r],
                steps[r],
                every[r],
                sig(us[r]),
                sig(mean_e[r]),
                sig(final_e[r]),
                sig(rough[r])
            ));
        }
        let find = |pred: &dyn Fn(usize) -> bool| (0..name.len()).find(|&r| pred(r));
        let sim = find(&|r| name[r] == "simulator");
        let none = find(&|r| name[r] != "simulator" && steps[r] == 0.0);
        // "A few steps after each emulation step": the largest such schedule up to 5 steps.
        let few = (0..name.len())
            .filter(|&r| {
                name[r] != "simulator" && steps[r] > 0.0 && every[r] == 1.0 && steps[r] <= 5.0
            })
            .max_by(|&a, &b| steps[a].total_cmp(&steps[b]));
        let rare = find(&|r| every[r] > 1.0 && steps[r] > 0.0);
        let (verdict, why, rule) = match (sim, none, few, rare) {
            (Some(s), Some(z), Some(f), Some(r)) => {
                let settings = rule_settings(dir)?;
                let bars = RegularizationRule {
                    drift_ratio: settings("drift_ratio"),
                    fix_ratio: settings("fix_ratio"),
                };
                let rule = regularization_rule(
                    final_e[z] / final_e[s],
                    mean_e[f] / mean_e[z],
                    rough[f] / rough[r],
                    &bars,
                );
                let (verdict, lines, text) = shown(rule.as_ref(), " No rule: a bar its null meets.");
                (
                    verdict,
                    format!(
                        "Without regularization the final shape error is {} ({}x the simulator's {}); `{}` brings the mean shape error from {} to {}; its roughness {} vs {} for `{}` (same budget, rarely). Checks:{lines} Rule (thresholds ours, in the spec's [params.rule]): {text}",
                        sig(final_e[z]),
                        sig(final_e[z] / final_e[s]),
                        sig(final_e[s]),
                        name[f],
                        sig(mean_e[z]),
                        sig(mean_e[f]),
                        sig(rough[f]),
                        sig(rough[r]),
                        name[r]
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
