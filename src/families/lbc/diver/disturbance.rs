//! `lbc_dive_disturbance` (LBC §6.1): linear Bellman combination of the dive controllers against
//! a stiff proportional-derivative dive controller under random pushes.
//!
//! The paper: "An important aspect of linear Bellman combination is that it uses less control
//! than standard proportional derivative control … we added random forces to the diver. Using
//! linear Bellman combination, one can see the effects of this added force and watch how the
//! control compensates for it. With a standard proportional-derivative dive controller, the
//! effects of the applied disturbances are not immediately visible, although the final outcome
//! is altered. With PD control, disturbances are invisible even when the applied forces are
//! scaled by a factor of four."
//!
//! - **LBC**: the three vertical dives of `lbc_diver_coordination` (take-off rates `omegas`,
//!   torque-limited DDP, LQR trackers), combined with w = 1 at the noise model's λ.
//! - **PD** (Wooten-style, ours): every joint servoed to the reference dive's joint angle and
//!   rate at each instant (the `reference` component's DDP dive), no feedforward, gains
//!   kp_j = limit_j / `pd.angle_at_limit` (the full torque at that error) and
//!   kd_j = kp_j · `pd.damping_s`, torques clamped to the limits.
//! - **Pushes**: `pushes.count` forces on the torso's centre of mass per trial, each
//!   `pushes.duration` s long at a uniform time in `pushes.window`, of magnitude
//!   `pushes.force_n` × U(0.5, 1) in a uniform direction (stream 100 + trial), scaled by each
//!   of `force_scales`; the same pushes for both controllers.
//! - **Closed loop**: both controllers evaluated every `substeps`-th of the dive's step (the
//!   stiff PD needs it), RK4 on the diver with one force point.
//!
//! `disturbance.csv`: controller, force_scale, effort, deviation, final_error, trial,
//! entry_change, max_torque_fraction. Effort = ∫ ½ uᵀRu dt (R the dives' control weight);
//! deviation = RMS over the flight of the torso and joint angles' difference from the same
//! controller's unpushed dive (rad: how visibly the motion reacts); final_error = |entry angle|
//! from vertical (rad); entry_change = |entry angle − the unpushed dive's| (rad: whether the
//! outcome is altered). Force scale 0 is each controller's unpushed dive (trial 0).

use super::rows::{DisturbanceRow, FlightRow, PushRow};
use super::{DiveSettings, TORSO};
use crate::bellman::combine::{BlendMode, TrackerBlend};
use crate::experiment::output::Tables;
use crate::experiment::plot::{Figure, FigureSink, Legend, Mark, Panel, Series};
use crate::experiment::report::{sig, Findings, Verdict};
use crate::experiment::resolve::{ensure, positive, ParamError, Validate};
use crate::experiment::rows::{read_rows, table_of, TableRow};
use crate::experiment::rule::{Check, Cmp, Null, Partly, Rule};
use crate::experiment::stats::bootstrap_intervals;
use crate::experiment::{other, Error, Family, Job, RunContext};
use crate::families::lbc::{film, rule_settings, rule_table};
use crate::physics::diver::{diver, entry_angle};
use crate::physics::planar::ForcePoint;
use crate::physics::{Dynamics, IntegratorKind, Simulator};
use nalgebra::DVector;
use rand::Rng;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// The family.
pub struct LbcDiveDisturbance;

/// The PD controller's gains (ours).
#[derive(Debug, Clone, Copy, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PdGains {
    /// Joint error at which the PD reaches its torque limit (rad).
    pub angle_at_limit: f64,
    /// kd / kp (s).
    pub damping_s: f64,
}

/// The random pushes.
#[derive(Debug, Clone, Copy, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Pushes {
    /// Pushes per trial.
    pub count: usize,
    /// Seconds each lasts.
    pub duration: f64,
    /// Largest force (N) at scale 1.
    pub force_n: f64,
    /// Start times are uniform in [window[0], window[1]] s.
    pub window: [f64; 2],
}

/// The verdict's thresholds (ours).
#[derive(Debug, Clone, Copy, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DisturbanceRule {
    /// LBC's motion reacts visibly: its mean deviation at scale 1 at least this multiple of
    /// the PD's.
    pub visible_ratio: f64,
    /// The PD's outcome is altered: its mean entry change at the largest scale at least this
    /// (rad).
    pub outcome_change: f64,
    /// The pushes are felt (premise): LBC's mean deviation at scale 1 at least this (rad).
    pub felt: f64,
}

/// Parameters of `lbc_dive_disturbance`.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DisturbanceParams {
    /// Dive settings (`lbc_diver_coordination`'s).
    pub dive: DiveSettings,
    /// Take-off rates of the combined dives (rad/s).
    pub omegas: Vec<f64>,
    /// Which dive the PD tracks (0-based into `omegas`); every trial takes off at its rate.
    pub reference: usize,
    /// The PD's gains.
    pub pd: PdGains,
    /// The pushes.
    pub pushes: Pushes,
    /// Force scales (the paper's 1 and 4).
    pub force_scales: Vec<f64>,
    /// Trials (push sets) per scale.
    pub trials: usize,
    /// Closed-loop evaluations per dive step.
    pub substeps: usize,
    /// The verdict's thresholds.
    pub rule: DisturbanceRule,
}

impl Validate for DisturbanceParams {
    fn validate(&self) -> Result<(), ParamError> {
        self.dive
            .validate_with(&self.omegas, self.reference, "reference")?;
        positive("pd.angle_at_limit", self.pd.angle_at_limit)?;
        positive("pd.damping_s", self.pd.damping_s)?;
        let p = &self.pushes;
        ensure(
            (1..=100).contains(&p.count),
            "pushes.count",
            "must be 1 to 100",
        )?;
        positive("pushes.duration", p.duration)?;
        positive("pushes.force_n", p.force_n)?;
        ensure(
            p.window[0] >= 0.0 && p.window[1] > p.window[0] && p.window[1] <= self.dive.horizon,
            "pushes.window",
            "must be an interval within the flight",
        )?;
        ensure(
            !self.force_scales.is_empty()
                && self.force_scales.iter().all(|s| s.is_finite() && *s > 0.0),
            "force_scales",
            "positive scales",
        )?;
        ensure(
            (1..=1000).contains(&self.trials),
            "trials",
            "must be 1 to 1000",
        )?;
        ensure(
            (1..=1000).contains(&self.substeps),
            "substeps",
            "must be 1 to 1000",
        )?;
        positive("rule.visible_ratio", self.rule.visible_ratio)?;
        positive("rule.outcome_change", self.rule.outcome_change)?;
        positive("rule.felt", self.rule.felt)?;
        Ok(())
    }
}

/// One push: (start s, duration s, force x N, force y N).
type Push = (f64, f64, f64, f64);

/// The pushes of trial `trial` at scale 1 (stream 100 + trial).
fn pushes_of(ctx: &RunContext, p: &Pushes, trial: usize) -> Vec<Push> {
    let mut rng = ctx.rng(100 + trial as u64);
    (0..p.count)
        .map(|_| {
            let t = p.window[0] + (p.window[1] - p.window[0]) * rng.random::<f64>();
            let mag = p.force_n * (0.5 + 0.5 * rng.random::<f64>());
            let (s, c) = crate::portable::sin_cos(std::f64::consts::TAU * rng.random::<f64>());
            (t, p.duration, mag * c, mag * s)
        })
        .collect()
}

/// Who controls the dive.
enum Controller<'a> {
    Lbc(&'a TrackerBlend<'a>),
    /// Reference angles and rates per dive step, kp and kd per joint.
    Pd(&'a [DVector<f64>], [f64; 6], [f64; 6]),
}

/// A dive: the state at every dive step, ∫½uᵀRu dt and the largest torque fraction.
struct Flight {
    states: Vec<Vec<f64>>,
    effort: f64,
    max_torque_fraction: f64,
}

/// The closed-loop dive from `x0` under `ctl` with `pushes` scaled by `scale` (module docs).
fn fly(
    d: &DiveSettings,
    ctl: &Controller,
    x0: &DVector<f64>,
    pushes: &[Push],
    scale: f64,
    substeps: usize,
) -> Result<Flight, Error> {
    let mut tree = diver();
    tree.forces = vec![ForcePoint {
        link: 0,
        offset: tree.links[0].com,
    }];
    let mut sim = Simulator::new(tree, IntegratorKind::Rk4);
    let (steps, h) = (d.steps(), d.dt / substeps as f64);
    let mut x: Vec<f64> = x0.iter().copied().collect();
    let mut u = [0.0; 8];
    let components = match ctl {
        Controller::Lbc(b) => b.trackers.len(),
        Controller::Pd(..) => 0,
    };
    let (mut tq, mut alpha, mut ui) = ([0.0; 6], vec![0.0; components], [0.0; 6]);
    let mut out = Flight {
        states: vec![x.clone()],
        effort: 0.0,
        max_torque_fraction: 0.0,
    };
    for k in 0..steps {
        for s in 0..substeps {
            let t = (k as f64 + s as f64 / substeps as f64) * d.dt;
            match ctl {
                Controller::Lbc(b) => {
                    b.control(&x, k, &mut tq, &mut alpha, &mut ui)
                        .map_err(|e| other(format!("LBC at step {k}: {e:?}")))?;
                }
                Controller::Pd(r, kp, kd) => {
                    let f = s as f64 / substeps as f64;
                    let (a, b) = (&r[k], &r[(k + 1).min(r.len() - 1)]);
                    for j in 0..6 {
                        let (qi, vi) = (3 + j, 12 + j);
                        let q_ref = a[qi] + f * (b[qi] - a[qi]);
                        let v_ref = a[vi] + f * (b[vi] - a[vi]);
                        tq[j] = (kp[j] * (q_ref - x[qi]) - kd[j] * (x[vi] - v_ref))
                            .clamp(-d.torque_limits[j], d.torque_limits[j]);
                    }
                }
            }
            u[..6].copy_from_slice(&tq);
            let (mut fx, mut fy) = (0.0, 0.0);
            for &(t0, dur, px, py) in pushes {
                if t >= t0 && t < t0 + dur {
                    fx += scale * px;
                    fy += scale * py;
                }
            }
            u[6] = fx;
            u[7] = fy;
            for (j, v) in tq.iter().enumerate() {
                out.effort += h * 0.5 * d.control_weight * v * v;
                out.max_torque_fraction = out.max_torque_fraction.max(v.abs() / d.torque_limits[j]);
            }
            sim.step(&mut x, &u, h);
        }
        crate::physics::check_finite("diver", k + 1, (k + 1) as f64 * d.dt, &x).map_err(other)?;
        out.states.push(x.clone());
    }
    Ok(out)
}

/// RMS over the flight of the torso and joint angles of `a` minus `b` (rad).
fn deviation(a: &[Vec<f64>], b: &[Vec<f64>]) -> f64 {
    let (mut s, mut n) = (0.0, 0usize);
    for (x, y) in a.iter().zip(b) {
        for i in TORSO..9 {
            s += (x[i] - y[i]).powi(2);
            n += 1;
        }
    }
    (s / n.max(1) as f64).sqrt()
}

impl Job for DisturbanceParams {
    fn params_json(&self) -> serde_json::Value {
        serde_json::to_value(self).unwrap_or_default()
    }

    fn run(&self, ctx: &RunContext) -> Result<Tables, Error> {
        let d = &self.dive;
        let cases: Vec<(f64, f64)> = self.omegas.iter().map(|&w| (w, 0.0)).collect();
        let (sols, trackers, examples) = d.optimize_all(ctx, &cases)?;
        let limits = d.torque_limits;
        let blend = TrackerBlend {
            trackers: &trackers,
            weights: vec![1.0; trackers.len()],
            lambda: d.lambda(),
            limits: Some(&limits),
            mode: BlendMode::Lbc,
        };
        let reference = &sols[self.reference].x;
        let kp: [f64; 6] = std::array::from_fn(|j| limits[j] / self.pd.angle_at_limit);
        let kd: [f64; 6] = std::array::from_fn(|j| kp[j] * self.pd.damping_s);
        let x0 = d.takeoff(self.omegas[self.reference]);
        let lbc = Controller::Lbc(&blend);
        let pd = Controller::Pd(reference, kp, kd);
        let ctls: [(&str, &Controller); 2] = [("lbc", &lbc), ("pd", &pd)];
        let tree = diver();
        let entry = |f: &Flight| entry_angle(&tree, &f.states[f.states.len() - 1][..9]);
        let base: Vec<Flight> = ctls
            .iter()
            .map(|(_, c)| fly(d, c, &x0, &[], 0.0, self.substeps))
            .collect::<Result<_, _>>()?;
        let jobs: Vec<(usize, usize, usize)> = (0..ctls.len())
            .flat_map(|c| {
                (0..self.force_scales.len())
                    .flat_map(move |s| (0..self.trials).map(move |t| (c, s, t)))
            })
            .collect();
        let flights: Vec<Flight> = ctx.stage("pushed dives", || {
            jobs.par_iter()
                .map(|&(c, s, t)| {
                    let pushes = pushes_of(ctx, &self.pushes, t);
                    fly(
                        d,
                        ctls[c].1,
                        &x0,
                        &pushes,
                        self.force_scales[s],
                        self.substeps,
                    )
                })
                .collect::<Result<_, _>>()
        })?;
        let mut table: Vec<DisturbanceRow> = Vec::with_capacity(ctls.len() + jobs.len());
        for (c, (name, _)) in ctls.iter().enumerate() {
            let b = &base[c];
            table.push(DisturbanceRow {
                controller: name.to_string(),
                force_scale: 0.0,
                effort: b.effort,
                deviation: 0.0,
                final_error: entry(b).abs(),
                trial: 0,
                entry_change: 0.0,
                max_torque_fraction: b.max_torque_fraction,
            });
        }
        for (&(c, s, t), f) in jobs.iter().zip(&flights) {
            let b = &base[c];
            table.push(DisturbanceRow {
                controller: ctls[c].0.to_string(),
                force_scale: self.force_scales[s],
                effort: f.effort,
                deviation: deviation(&f.states, &b.states),
                final_error: entry(f).abs(),
                trial: t as i64,
                entry_change: (entry(f) - entry(b)).abs(),
                max_torque_fraction: f.max_torque_fraction,
            });
        }
        // Motion of both controllers, unpushed and under trial 0's pushes at every scale, for
        // the figure and the GIF.
        let mut motion: Vec<FlightRow> = Vec::new();
        for (c, (name, _)) in ctls.iter().enumerate() {
            let mut runs: Vec<(f64, &Flight)> = vec![(0.0, &base[c])];
            for (s, &scale) in self.force_scales.iter().enumerate() {
                let i = jobs.iter().position(|&j| j == (c, s, 0)).expect("trial 0");
                runs.push((scale, &flights[i]));
            }
            for (scale, f) in runs {
                for (k, x) in f.states.iter().enumerate() {
                    motion.push(FlightRow::at(name, scale, k as f64 * d.dt, x));
                }
            }
        }
        let mut pushes: Vec<PushRow> = Vec::new();
        for t in 0..self.trials {
            for (t0, dur, fx, fy) in pushes_of(ctx, &self.pushes, t) {
                pushes.push(PushRow {
                    trial: t as i64,
                    start_s: t0,
                    duration_s: dur,
                    force_x_n: fx,
                    force_y_n: fy,
                });
            }
        }
        let r = &self.rule;
        let rule = rule_table(&[
            ("visible_ratio", r.visible_ratio),
            ("outcome_change", r.outcome_change),
            ("felt", r.felt),
            ("lambda", d.lambda()),
            ("angle_at_limit", self.pd.angle_at_limit),
            (
                "largest_scale",
                self.force_scales.iter().cloned().fold(0.0, f64::max),
            ),
        ]);
        Ok(Tables::from([
            ("disturbance", table_of(&table)),
            ("dives", table_of(&examples)),
            ("motion", table_of(&motion)),
            ("pushes", table_of(&pushes)),
            ("rule", rule),
        ]))
    }
}

/// One row of `disturbance.csv`: a controller's dive at a force scale under one trial's pushes
/// (the unpushed dive has one trial), with its effort, deviation, final error and entry change.
struct TrialRow {
    controller: String,
    scale: f64,
    trial: usize,
    v: [f64; 4],
}

/// The rows of `disturbance.csv` in `dir`.
fn trial_rows(dir: &Path) -> Result<Vec<TrialRow>, Error> {
    let rows: Vec<DisturbanceRow> = read_rows(&dir.join("disturbance.csv"))?;
    Ok(rows
        .into_iter()
        .map(|r| TrialRow {
            v: [r.effort, r.deviation, r.final_error, r.entry_change],
            controller: r.controller,
            scale: r.force_scale,
            trial: r.trial as usize,
        })
        .collect())
}

/// The pushed trials' ids, ascending.
fn trial_ids(rows: &[TrialRow]) -> Vec<usize> {
    let mut ids: Vec<usize> = rows
        .iter()
        .filter(|r| r.scale != 0.0)
        .map(|r| r.trial)
        .collect();
    ids.sort_unstable();
    ids.dedup();
    ids
}

/// Per controller and force scale (first-seen order), the means of the four measures over the
/// pushed trials `pick` (indices into [`trial_ids`], repeats allowed, as a bootstrap resample
/// draws them; `None`: every trial once); the unpushed dive's single row as it is.
fn means_over(rows: &[TrialRow], pick: Option<&[usize]>) -> Vec<(String, f64, [f64; 4])> {
    let ids = trial_ids(rows);
    let all: Vec<usize> = (0..ids.len()).collect();
    let pick = pick.unwrap_or(&all);
    let mut out: Vec<(String, f64, [f64; 4])> = Vec::new();
    for r in rows {
        if !out.iter().any(|o| o.0 == r.controller && o.1 == r.scale) {
            out.push((r.controller.clone(), r.scale, [0.0; 4]));
        }
    }
    for o in &mut out {
        let of = |trial: usize| {
            rows.iter()
                .find(|r| r.controller == o.0 && r.scale == o.1 && r.trial == trial)
                .map_or([f64::NAN; 4], |r| r.v)
        };
        o.2 = if o.1 == 0.0 {
            rows.iter()
                .find(|r| r.controller == o.0 && r.scale == 0.0)
                .map_or([f64::NAN; 4], |r| r.v)
        } else {
            let mut sum = [0.0; 4];
            for &k in pick {
                let v = of(ids[k]);
                for j in 0..4 {
                    sum[j] += v[j];
                }
            }
            sum.map(|x| x / pick.len() as f64)
        };
    }
    out
}

/// Bootstrap seed of the intervals over trials (fixed, so a report is the same everywhere).
const BOOTSTRAP_SEED: u64 = 1;

/// `rule` with each check's 95% bootstrap interval over the pushed trials of `rows`: the
/// trials resampled with replacement, the rule rebuilt from each resample's means, and the
/// percentiles of each check's value (the premise first, then the held checks).
fn with_trial_intervals(
    mut rule: Rule,
    rows: &[TrialRow],
    build: impl Fn(&[(String, f64, [f64; 4])]) -> Option<Rule>,
) -> Rule {
    let n = trial_ids(rows).len();
    let k = rule.premise.len() + rule.held.len();
    // One rule built per resample gives every check's value.
    let intervals = bootstrap_intervals(n, BOOTSTRAP_SEED, k, |idx, out| {
        if let Some(r) = build(&means_over(rows, Some(idx))) {
            for (o, c) in out.iter_mut().zip(r.premise.iter().chain(&r.held)) {
                *o = c.value;
            }
        }
    });
    let checks = rule.premise.iter_mut().chain(rule.held.iter_mut());
    for (c, (lo, hi)) in checks.zip(intervals) {
        if lo.is_finite() && hi.is_finite() {
            *c = c.clone().with_interval(lo, hi);
        }
    }
    rule
}

/// The means of `controller` at force scale `scale`, if the run has them.
fn mean_of(m: &[(String, f64, [f64; 4])], controller: &str, scale: f64) -> Option<[f64; 4]> {
    m.iter()
        .find(|o| o.0 == controller && o.1 == scale)
        .map(|o| o.2)
}

/// The verdict's rule from the means (`None` without the unpushed, scale-1 or largest-scale
/// rows). Premise: the pushes are felt (LBC's deviation at scale 1 at least `felt`). (a) LBC
/// uses less control than PD, unpushed and at scale 1; (b) LBC's motion reacts visibly: its
/// deviation at scale 1 at least `visible_ratio` times PD's there; (c) PD's stays invisible at
/// the largest scale by the same ratio: LBC's deviation at scale 1 at least `visible_ratio`
/// times PD's at the largest scale; (d) PD's outcome is altered there: its entry moves at least
/// `outcome_change`. Held: all four; partly: (a) and (b).
pub fn disturbance_rule(
    m: &[(String, f64, [f64; 4])],
    largest: f64,
    visible_ratio: f64,
    outcome_change: f64,
    felt: f64,
) -> Option<Rule> {
    let get = |c: &str, s: f64| mean_of(m, c, s);
    let (l0, p0, l1, p1, pl) = (
        get("lbc", 0.0)?,
        get("pd", 0.0)?,
        get("lbc", 1.0)?,
        get("pd", 1.0)?,
        get("pd", largest)?,
    );
    let unpushed = |v| Null::new("the unpushed dive", v);
    let premise = Check::new(
        "the pushes are felt: LBC's deviation at x1 (rad)",
        l1[1],
        Cmp::AtLeast,
        felt,
        unpushed(0.0),
    )
    .ok()?;
    let held = vec![
        Check::new(
            "LBC's control effort over PD's, the larger of unpushed and x1",
            (l0[0] / p0[0]).max(l1[0] / p1[0]),
            Cmp::Below,
            1.0,
            Null::new("PD itself", 1.0),
        )
        .ok()?,
        Check::new(
            "LBC's motion reacts visibly: its deviation at x1 over PD's at x1",
            l1[1] / p1[1],
            Cmp::AtLeast,
            visible_ratio,
            Null::new("PD itself", 1.0),
        )
        .ok()?,
        Check::new(
            format!(
                "PD's motion stays invisible at x{}: LBC's deviation at x1 over PD's at x{}",
                sig(largest),
                sig(largest)
            ),
            l1[1] / pl[1],
            Cmp::AtLeast,
            visible_ratio,
            Null::new(format!("PD at x{} itself", sig(largest)), 1.0),
        )
        .ok()?,
        Check::new(
            format!(
                "PD's outcome is altered at x{}: its entry moves (rad)",
                sig(largest)
            ),
            pl[3],
            Cmp::AtLeast,
            outcome_change,
            unpushed(0.0),
        )
        .ok()?,
    ];
    Some(Rule {
        premise: vec![premise],
        held,
        partly: Partly::All(vec![0, 1]),
    })
}

impl Family for LbcDiveDisturbance {
    const KIND: &'static str = "lbc_dive_disturbance";
    type Params = DisturbanceParams;
    const CAPTIONS: &'static [(&'static str, &'static str)] = &[
        (
            "measures",
            "per controller and force scale (0: unpushed), the mean over trials of the control effort ∫½uᵀRu dt, the deviation of the torso and joint angles from the same controller's unpushed dive (RMS, rad) and the entry's change (rad).",
        ),
        (
            "torso",
            "the torso angle over the flight of each controller, unpushed and under trial 0's pushes at each scale; dashed: when each of trial 0's pushes starts.",
        ),
        (
            "dives",
            "from the left: LBC under trial 0's pushes at scale 1, LBC unpushed (grey), PD under the same pushes, PD unpushed (grey).",
        ),
    ];

    fn figures(&self, fig: &FigureSink, tables: &Tables) -> Result<Vec<PathBuf>, Error> {
        let t = DisturbanceRow::from_table(tables.require("disturbance")?);
        let mut files = fig.draw("measures", &measures_figure(&t))?;
        let m = FlightRow::from_table(tables.require("motion")?);
        // Trial 0's pushes, as vertical lines over the torso angles' range.
        let p = PushRow::from_table(tables.require("pushes")?);
        files.extend(fig.draw("torso", &torso_figure(&m, &p))?);
        // GIF: both controllers under scale 1, each beside its unpushed dive.
        let tree = diver();
        let rows = |name: &str, sc: f64| -> Vec<usize> {
            (0..m.len())
                .filter(|&i| m[i].controller == name && m[i].force_scale == sc)
                .collect()
        };
        let mut dives = Vec::new();
        let qs: Vec<[f64; film::DIVER_COORDS]> = m.iter().map(FlightRow::coords).collect();
        for (k, (name, label)) in [("lbc", "LBC, pushed ×1"), ("pd", "PD, pushed ×1")]
            .iter()
            .enumerate()
        {
            for (sc, lab, color) in [
                (1.0, label.to_string(), k),
                (0.0, format!("{} unpushed", name.to_uppercase()), 7),
            ] {
                let r = rows(name, sc);
                if r.is_empty() {
                    continue;
                }
                dives.push(film::Dive {
                    label: lab,
                    color,
                    t: r.iter().map(|&i| m[i].t_s).collect(),
                    q: r.iter().map(|&i| qs[i].as_slice()).collect(),
                });
            }
        }
        if !dives.is_empty() {
            let frames =
                film::diver_frames(&tree, &dives, 1.5, "Random pushes: LBC reacts, PD does not");
            files.push(fig.gif("dives", &frames, film::GIF_DELAY_CS)?);
        }
        Ok(files)
    }

    fn report(&self, dir: &Path) -> Result<Findings, Error> {
        let rule = rule_settings(dir)?;
        let rows = trial_rows(dir)?;
        let m = means_over(&rows, None);
        let largest = rule("largest_scale");
        let mut md = String::from("Means over the trials (force scale 0: the unpushed dive):\n\n| controller | force scale | effort ∫½uᵀRu dt | deviation (rad) | entry error (rad) | entry change (rad) |\n| --- | --- | --- | --- | --- | --- |\n");
        for (c, s, v) in &m {
            md.push_str(&format!(
                "| {c} | {} | {} | {} | {} | {} |\n",
                sig(*s),
                sig(v[0]),
                sig(v[1]),
                sig(v[2]),
                sig(v[3])
            ));
        }
        let build = |m: &[(String, f64, [f64; 4])]| {
            disturbance_rule(
                m,
                largest,
                rule("visible_ratio"),
                rule("outcome_change"),
                rule("felt"),
            )
        };
        let rule = build(&m).map(|r| with_trial_intervals(r, &rows, build));
        let Some(rule) = rule else {
            return Ok(Findings {
                ours: md,
                verdict: Verdict::NotAssessed,
                rule: None,
                why: "The run lacks the unpushed, scale-1 or largest-scale rows the rule reads, or its thresholds let a null pass.".into(),
            });
        };
        let get = |c: &str, s: f64| mean_of(&m, c, s).unwrap_or([f64::NAN; 4]);
        let (l0, p0, l1, p1, pl) = (
            get("lbc", 0.0),
            get("pd", 0.0),
            get("lbc", 1.0),
            get("pd", 1.0),
            get("pd", largest),
        );
        let verdict = rule.verdict();
        let why = format!(
            "LBC's control effort {le0} unpushed and {le1} under pushes against PD's {pe0} and {pe1}; its motion deviates {ld} rad (RMS) from its unpushed dive under pushes x1 against PD's {pd1} rad, and PD's at x{lg} {pdl} rad while its entry moves {pch} rad (means over the trials).{lines} Rule (ours, fixed in the spec; one ratio, visible_ratio, tells visible from invisible in (b) and (c)): {text} PD gains ours (full torque at {al} rad).",
            le0 = sig(l0[0]),
            le1 = sig(l1[0]),
            pe0 = sig(p0[0]),
            pe1 = sig(p1[0]),
            ld = sig(l1[1]),
            pd1 = sig(p1[1]),
            lg = sig(largest),
            pdl = sig(pl[1]),
            pch = sig(pl[3]),
            lines = rule.lines(),
            text = rule.text(),
            al = sig(rule_settings(dir)?("angle_at_limit")),
        );
        Ok(Findings {
            ours: md,
            verdict,
            rule: rule.clone().into(),
            why,
        })
    }
}

/// The measures per force scale (from `disturbance`): each controller's mean effort,
/// deviation and entry change.
fn measures_figure(t: &[DisturbanceRow]) -> Figure {
    let mut scales: Vec<f64> = t.iter().map(|r| r.force_scale).collect();
    scales.sort_by(f64::total_cmp);
    scales.dedup();
    let x_of = |v: f64| scales.iter().position(|&x| x == v).unwrap_or(0) as f64;
    let panel = |col: fn(&DisturbanceRow) -> f64, title: &str, y: &str| {
        let series = ["lbc", "pd"]
            .iter()
            .enumerate()
            .map(|(k, name)| {
                let pts: Vec<(f64, f64)> = scales
                    .iter()
                    .map(|&sc| {
                        let vals: Vec<f64> = t
                            .iter()
                            .filter(|r| r.controller == *name && r.force_scale == sc)
                            .map(col)
                            .collect();
                        (
                            x_of(sc),
                            vals.iter().sum::<f64>() / vals.len().max(1) as f64,
                        )
                    })
                    .collect();
                Series::line(name.to_uppercase(), pts, k).mark(Mark::LinePoints)
            })
            .collect();
        Panel {
            title: title.into(),
            x_label: "force scale (0: unpushed)".into(),
            y_label: y.into(),
            series,
            x_categories: scales.iter().map(|v| format!("{v}")).collect(),
            x_range: Some((-0.5, scales.len() as f64 - 0.5)),
            legend: Legend::UpperLeft,
            ..Panel::default()
        }
    };
    Figure::grid(
        vec![
            panel(|r| r.effort, "control effort", "∫½uᵀRu dt"),
            panel(
                |r| r.deviation,
                "motion's deviation from the unpushed dive",
                "RMS angle difference (rad)",
            ),
            panel(
                |r| r.entry_change,
                "change of the entry angle",
                "|Δ entry| (rad)",
            ),
        ],
        3,
    )
}

/// The torso angle over time per controller and force scale (from `motion`), trial 0's
/// pushes (from `pushes`) as vertical lines.
fn torso_figure(m: &[FlightRow], p: &[PushRow]) -> Figure {
    let mut mscales: Vec<f64> = m.iter().map(|r| r.force_scale).collect();
    mscales.sort_by(f64::total_cmp);
    mscales.dedup();
    let (lo, hi) = m
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), r| {
            (a.min(r.torso_rad), b.max(r.torso_rad))
        });
    let panels: Vec<Panel> = ["lbc", "pd"]
        .iter()
        .map(|name| {
            let mut series: Vec<Series> = mscales
                .iter()
                .enumerate()
                .map(|(k, &sc)| {
                    let pts = m
                        .iter()
                        .filter(|r| r.controller == *name && r.force_scale == sc)
                        .map(|r| (r.t_s, r.torso_rad))
                        .collect();
                    let label = if sc == 0.0 {
                        "unpushed".to_string()
                    } else {
                        format!("pushes ×{sc}")
                    };
                    Series::line(label, pts, k)
                })
                .collect();
            for (n, push) in p.iter().filter(|r| r.trial == 0).enumerate() {
                let label = if n == 0 { "a push starts" } else { "" };
                let at = push.start_s;
                series.push(Series::line(label, vec![(at, lo), (at, hi)], 7).mark(Mark::Dashed));
            }
            Panel {
                title: format!("{}: torso angle", name.to_uppercase()),
                x_label: "t (s)".into(),
                y_label: "torso angle (rad)".into(),
                series,
                legend: Legend::UpperLeft,
                ..Panel::default()
            }
        })
        .collect();
    Figure::grid(panels, 2)
}

#[cfg(test)]
mod tests {

    /// Resampling trials moves the pushed means and leaves the unpushed dive alone; the
    /// intervals bracket each check's value over every trial.
    #[test]
    fn the_trial_bootstrap_resamples_pushed_trials_only() {
        let row = |c: &str, scale: f64, trial: usize, dev: f64| TrialRow {
            controller: c.into(),
            scale,
            trial,
            v: [1.0, dev, 0.0, dev / 10.0],
        };
        let mut rows = vec![row("lbc", 0.0, 0, 0.0), row("pd", 0.0, 0, 0.0)];
        for t in 0..6 {
            let d = 0.1 + 0.02 * t as f64;
            rows.push(row("lbc", 1.0, t, d));
            rows.push(row("pd", 1.0, t, d / 5.0));
            rows.push(row("lbc", 4.0, t, 4.0 * d));
            rows.push(row("pd", 4.0, t, d / 1.5));
        }
        let all = means_over(&rows, None);
        let lbc1 = all.iter().find(|o| o.0 == "lbc" && o.1 == 1.0).unwrap().2[1];
        assert!((lbc1 - 0.15).abs() < 1e-12);
        let first = means_over(&rows, Some(&[0, 0, 0, 0, 0, 0]));
        let lbc1_first = first.iter().find(|o| o.0 == "lbc" && o.1 == 1.0).unwrap().2[1];
        assert!((lbc1_first - 0.1).abs() < 1e-12);
        assert_eq!(
            first.iter().find(|o| o.0 == "lbc" && o.1 == 0.0).unwrap().2,
            all[0].2
        );
        let build = |m: &[(String, f64, [f64; 4])]| disturbance_rule(m, 4.0, 2.0, 0.001, 0.01);
        let rule = with_trial_intervals(build(&all).unwrap(), &rows, build);
        for c in rule.premise.iter().chain(&rule.held) {
            let (lo, hi) = c.interval.expect("an interval");
            assert!(
                lo <= c.value + 1e-12 && c.value <= hi + 1e-12,
                "{}: {lo} {} {hi}",
                c.label,
                c.value
            );
        }
    }
    use super::*;
    use crate::experiment::rule::Outcome;

    fn m(rows: &[(&str, f64, [f64; 4])]) -> Vec<(String, f64, [f64; 4])> {
        rows.iter().map(|r| (r.0.to_string(), r.1, r.2)).collect()
    }

    #[test]
    fn the_rule_reads_effort_visibility_and_outcome_with_one_ratio() {
        // The paper's story: LBC cheaper and visibly pushed, PD stiff but its entry altered.
        let story = m(&[
            ("lbc", 0.0, [1.0, 0.0, 0.01, 0.0]),
            ("pd", 0.0, [5.0, 0.0, 0.02, 0.0]),
            ("lbc", 1.0, [1.2, 0.05, 0.02, 0.01]),
            ("pd", 1.0, [5.5, 0.005, 0.03, 0.01]),
            ("pd", 4.0, [6.0, 0.02, 0.06, 0.04]),
        ]);
        let rule = |m: &[(String, f64, [f64; 4])], felt: f64| {
            disturbance_rule(m, 4.0, 2.0, 0.01, felt).unwrap()
        };
        assert_eq!(rule(&story, 0.01).verdict(), Verdict::Held);
        // PD at x4 deviating nearly as much as LBC at x1 is not invisible by the ratio that
        // makes LBC's visible: (c) fails, partly held.
        let mut close = story.clone();
        close[4].2[1] = 0.045;
        let r = rule(&close, 0.01);
        assert_eq!(r.verdict(), Verdict::Partly);
        assert_eq!(r.held[2].outcome(), Outcome::Fail);
        // PD cheaper: (a) fails, and partly needs it.
        let mut other = story.clone();
        other[1].2[0] = 0.5;
        assert_eq!(rule(&other, 0.01).verdict(), Verdict::NotHeld);
        // Pushes too weak to be felt: the premise fails.
        assert_eq!(rule(&story, 0.1).verdict(), Verdict::PremiseNotReproduced);
        // Missing rows: nothing to judge; a ratio of 1 (PD itself passes) is refused.
        assert!(disturbance_rule(&story[..2], 4.0, 2.0, 0.01, 0.01).is_none());
        assert!(disturbance_rule(&story, 4.0, 1.0, 0.01, 0.01).is_none());
    }
}
