//! `lbc_acrobot_swingup` (LBC §6.2, Fig. 7): DDP swing-ups of the acrobot to the handstand from
//! two start states, minimizing ½∫uᵀu plus a quadratic terminal cost; LQR trackers with the
//! quadratic value functions of eq. 12; from a third start, compare tracker 1, tracker 2, a
//! naive fixed-weight blend and linear Bellman combination (w = 1); then a sweep over a grid of
//! start states showing where each policy succeeds.
//!
//! Tables: `final` (policy, final_distance, control_cost, final_theta1, final_theta2) with rows
//! `tracker1`, `tracker2`, `naive`, `lbc`; `trajectories` (policy, t, theta1, theta2, omega1,
//! omega2, u, alpha1); `swingups` (one row per optimized swing-up); `ddp_trace`; `sweep`
//! (theta1_deg, theta2_deg, policy, final_distance, control_cost, success).

use crate::bellman::combine::{BlendMode, TrackerBlend};
use crate::control::ddp::{solve, DdpOptions, DdpSolution, DdpVariant};
use crate::control::lqr::{track, TrackingController};
use crate::control::{QuadraticCost, Rk4Map};
use crate::experiment::output::{df_f64, df_str, read_csv, Table, Tables};
use crate::experiment::plot::{Figure, FigureSink, Heatmap, Legend, Mark, Panel, Series};
use crate::experiment::report::{sig, Findings, Verdict};
use crate::experiment::resolve::{ensure, positive, ParamError, Validate};
use crate::experiment::{other, Error, Family, Job, RunContext};
use crate::physics::acrobot::Acrobot;
use crate::row;
use nalgebra::{DMatrix, DVector};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::f64::consts::{FRAC_PI_2, PI};
use std::path::{Path, PathBuf};

/// The family.
pub struct LbcAcrobot;

/// Parameters of `lbc_acrobot_swingup`.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Params {
    /// Duration of each swing-up (s).
    pub horizon: f64,
    /// Time step of the RK4 discretization (s).
    pub dt: f64,
    /// Start states of the optimized swing-ups (θ1, θ2 in degrees, ω1, ω2 in deg/s).
    pub starts: Vec<[f64; 4]>,
    /// The test start state (degrees, deg/s).
    pub test_start: [f64; 4],
    /// Diagonal of the terminal weight Q_f about the handstand (π/2, 0, 0, 0).
    pub terminal_weights: [f64; 4],
    /// `ilqr` or `full` (second-order DDP).
    pub variant: String,
    /// DDP iteration limit.
    pub max_iterations: usize,
    /// Amplitude of the initial guess u(t) = a sin(ω t) (N·m).
    pub init_amplitude: f64,
    /// Frequency ω of the initial guess (rad/s).
    pub init_frequency: f64,
    /// Fixed weights w of the combination (1 = coordination).
    pub weights: Vec<f64>,
    /// Temperature λ of z = exp(−v̂/λ).
    pub lambda: f64,
    /// A policy succeeds when it ends closer than this to the handstand (state-space norm).
    pub success_distance: f64,
    /// Range of θ1 (degrees) of the start-state sweep.
    pub sweep_theta1: [f64; 2],
    /// Range of θ2 (degrees) of the start-state sweep.
    pub sweep_theta2: [f64; 2],
    /// Grid points per axis of the sweep.
    pub sweep_points: usize,
}

impl Validate for Params {
    fn validate(&self) -> Result<(), ParamError> {
        positive("horizon", self.horizon)?;
        positive("dt", self.dt)?;
        ensure(
            self.horizon >= 2.0 * self.dt,
            "horizon",
            "must cover at least two steps",
        )?;
        ensure(
            self.starts.len() >= 2,
            "starts",
            "need at least two swing-ups",
        )?;
        ensure(
            self.weights.len() == self.starts.len(),
            "weights",
            format!("need one weight per start ({})", self.starts.len()),
        )?;
        for (i, w) in self.weights.iter().enumerate() {
            positive(&format!("weights[{i}]"), *w)?;
        }
        for (i, w) in self.terminal_weights.iter().enumerate() {
            positive(&format!("terminal_weights[{i}]"), *w)?;
        }
        ensure(
            self.variant == "ilqr" || self.variant == "full",
            "variant",
            format!("unknown DDP variant `{}` (ilqr, full)", self.variant),
        )?;
        ensure(
            self.max_iterations >= 1,
            "max_iterations",
            "must be at least 1",
        )?;
        positive("lambda", self.lambda)?;
        positive("success_distance", self.success_distance)?;
        ensure(self.sweep_points >= 1, "sweep_points", "must be at least 1")?;
        for v in self.starts.iter().flatten().chain(&self.test_start) {
            ensure(v.is_finite(), "starts", "must be finite")?;
        }
        Ok(())
    }
}

/// The handstand.
fn handstand() -> DVector<f64> {
    DVector::from_vec(vec![FRAC_PI_2, 0.0, 0.0, 0.0])
}

fn radians(s: &[f64; 4]) -> DVector<f64> {
    DVector::from_iterator(4, s.iter().map(|v| v.to_radians()))
}

fn wrap(a: f64) -> f64 {
    (a + PI).rem_euclid(2.0 * PI) - PI
}

/// State-space distance to the handstand with angles wrapped.
pub fn distance_to_handstand(x: &[f64]) -> f64 {
    let d = [wrap(x[0] - FRAC_PI_2), wrap(x[1]), x[2], x[3]];
    d.iter().map(|v| v * v).sum::<f64>().sqrt()
}

/// Result of running one policy from one start (stops where the closed loop diverges).
struct Rollout {
    xs: Vec<DVector<f64>>,
    us: Vec<f64>,
    alpha1: Vec<f64>,
    control_cost: f64,
    /// Step at which the closed loop diverged (non-finite state), if it did.
    diverged: Option<usize>,
}

impl Rollout {
    /// Distance of the final state to the handstand; infinite when the closed loop diverged.
    fn final_distance(&self) -> f64 {
        match self.diverged {
            Some(_) => f64::INFINITY,
            None => distance_to_handstand(self.xs[self.xs.len() - 1].as_slice()),
        }
    }
}

impl Params {
    fn steps(&self) -> usize {
        (self.horizon / self.dt).round() as usize
    }

    fn cost(&self) -> QuadraticCost {
        QuadraticCost::effort(
            self.dt,
            1,
            DMatrix::from_diagonal(&DVector::from_row_slice(&self.terminal_weights)),
            handstand(),
        )
    }

    fn options(&self) -> DdpOptions {
        DdpOptions {
            variant: if self.variant == "full" {
                DdpVariant::Full
            } else {
                DdpVariant::Ilqr
            },
            max_iterations: self.max_iterations,
            ..DdpOptions::default()
        }
    }

    fn swing_up(&self, map: &Rk4Map<Acrobot>, start: &[f64; 4]) -> Result<DdpSolution, Error> {
        let u0: Vec<DVector<f64>> = (0..self.steps())
            .map(|k| {
                DVector::from_element(
                    1,
                    self.init_amplitude * (k as f64 * self.dt * self.init_frequency).sin(),
                )
            })
            .collect();
        solve(map, &self.cost(), &radians(start), &u0, &self.options()).map_err(other)
    }

    fn run_policy(
        &self,
        map: &Rk4Map<Acrobot>,
        blend: &TrackerBlend,
        x0: &DVector<f64>,
    ) -> Result<Rollout, Error> {
        let steps = self.steps();
        let mut ws = map.workspace();
        let mut x = x0.clone();
        let mut next = x0.clone();
        let (mut u, mut ui, mut alpha) = ([0.0], [0.0], vec![0.0; blend.trackers.len()]);
        let mut out = Rollout {
            xs: vec![x.clone()],
            us: Vec::with_capacity(steps),
            alpha1: Vec::with_capacity(steps),
            control_cost: 0.0,
            diverged: None,
        };
        for k in 0..steps {
            if blend
                .control(x.as_slice(), k, &mut u, &mut alpha, &mut ui)
                .is_err()
            {
                out.diverged = Some(k);
                break;
            }
            let uu = DVector::from_row_slice(&u);
            map.step(&x, &uu, &mut next, &mut ws);
            if !u[0].is_finite() || next.iter().any(|v| !(v.abs() < DIVERGED)) {
                // A policy that drives the closed loop unstable fails; that is a result here.
                out.diverged = Some(k);
                break;
            }
            std::mem::swap(&mut x, &mut next);
            out.control_cost += 0.5 * u[0] * u[0] * self.dt;
            out.us.push(u[0]);
            out.alpha1.push(alpha[0]);
            out.xs.push(x.clone());
        }
        Ok(out)
    }
}

/// A state component beyond this magnitude (rad or rad/s) counts as a diverged closed loop.
const DIVERGED: f64 = 1e4;

const POLICIES: [&str; 4] = ["tracker1", "tracker2", "naive", "lbc"];

fn mode(i: usize) -> BlendMode {
    match i {
        0 => BlendMode::Single(0),
        1 => BlendMode::Single(1),
        2 => BlendMode::Naive,
        _ => BlendMode::Lbc,
    }
}

impl Job for Params {
    fn params_json(&self) -> serde_json::Value {
        serde_json::to_value(self).unwrap_or_default()
    }

    fn run(&self, ctx: &RunContext) -> Result<Tables, Error> {
        let map = Rk4Map::new(Acrobot::default(), self.dt).map_err(other)?;
        let cost = self.cost();
        let pb = ctx.progress(self.starts.len() as u64, "DDP swing-ups");
        let sols: Vec<Result<DdpSolution, Error>> = ctx.stage("ddp", || {
            self.starts
                .par_iter()
                .map(|s| {
                    let r = self.swing_up(&map, s);
                    pb.inc(1);
                    r
                })
                .collect()
        });
        pb.finish_and_clear();
        let sols: Vec<DdpSolution> = sols.into_iter().collect::<Result<_, _>>()?;
        let trackers: Vec<TrackingController> = ctx.stage("lqr", || {
            sols.iter()
                .map(|s| track(&map, &cost, &s.x, &s.u).map_err(other))
                .collect::<Result<_, _>>()
        })?;
        let mut swingups = Table::new(&[
            "start",
            "theta1_deg",
            "theta2_deg",
            "iterations",
            "cost",
            "final_distance",
            "termination",
        ]);
        let mut trace = Table::new(&[
            "start",
            "iteration",
            "cost",
            "regularization",
            "step",
            "gradient_norm",
            "accepted",
        ]);
        for (i, (s, sol)) in self.starts.iter().zip(&sols).enumerate() {
            swingups.push(row![
                i + 1,
                s[0],
                s[1],
                sol.trace.len(),
                sol.cost,
                distance_to_handstand(sol.x[sol.u.len()].as_slice()),
                format!("{:?}", sol.termination)
            ]);
            for r in &sol.trace {
                trace.push(row![
                    i + 1,
                    r.iteration,
                    r.cost,
                    r.regularization,
                    r.step,
                    r.gradient_norm,
                    r.accepted as i64
                ]);
            }
        }
        let blend = |m: BlendMode| TrackerBlend {
            trackers: &trackers,
            weights: self.weights.clone(),
            lambda: self.lambda,
            mode: m,
        };
        // The test start.
        let x0 = radians(&self.test_start);
        let mut fin = Table::new(&[
            "policy",
            "final_distance",
            "control_cost",
            "final_theta1",
            "final_theta2",
        ]);
        let mut traj = Table::new(&[
            "policy", "t", "theta1", "theta2", "omega1", "omega2", "u", "alpha1",
        ]);
        ctx.stage("test start", || -> Result<(), Error> {
            for (i, name) in POLICIES.iter().enumerate() {
                let r = self.run_policy(&map, &blend(mode(i)), &x0)?;
                let xn = &r.xs[r.xs.len() - 1];
                fin.push(row![
                    *name,
                    r.final_distance(),
                    r.control_cost,
                    xn[0],
                    xn[1]
                ]);
                for (k, x) in r.xs.iter().enumerate() {
                    let (u, a) = if k < r.us.len() {
                        (r.us[k], r.alpha1[k])
                    } else {
                        (f64::NAN, f64::NAN)
                    };
                    traj.push(row![
                        *name,
                        k as f64 * self.dt,
                        x[0],
                        x[1],
                        x[2],
                        x[3],
                        u,
                        a
                    ]);
                }
            }
            Ok(())
        })?;
        // Sweep over start states.
        let n = self.sweep_points;
        let lin = |r: [f64; 2], i: usize| {
            if n == 1 {
                0.5 * (r[0] + r[1])
            } else {
                r[0] + (r[1] - r[0]) * i as f64 / (n - 1) as f64
            }
        };
        let grid: Vec<(f64, f64)> = (0..n)
            .flat_map(|j| {
                (0..n).map(move |i| (lin(self.sweep_theta1, i), lin(self.sweep_theta2, j)))
            })
            .collect();
        let pb = ctx.progress(grid.len() as u64, "start-state sweep");
        let rows: Vec<Result<Vec<(f64, f64)>, Error>> = ctx.stage("sweep", || {
            grid.par_iter()
                .map(|&(a, b)| {
                    let x0 = radians(&[a, b, 0.0, 0.0]);
                    let out = (0..POLICIES.len())
                        .map(|i| {
                            let r = self.run_policy(&map, &blend(mode(i)), &x0)?;
                            Ok((r.final_distance(), r.control_cost))
                        })
                        .collect();
                    pb.inc(1);
                    out
                })
                .collect()
        });
        pb.finish_and_clear();
        let mut sweep = Table::new(&[
            "theta1_deg",
            "theta2_deg",
            "policy",
            "final_distance",
            "control_cost",
            "success",
        ]);
        for (&(a, b), r) in grid.iter().zip(rows) {
            for (name, (d, c)) in POLICIES.iter().zip(r?) {
                sweep.push(row![a, b, *name, d, c, (d < self.success_distance) as i64]);
            }
        }
        Ok(Tables::from([
            ("final", fin),
            ("trajectories", traj),
            ("swingups", swingups),
            ("ddp_trace", trace),
            ("sweep", sweep),
        ]))
    }
}

impl Family for LbcAcrobot {
    const KIND: &'static str = "lbc_acrobot_swingup";
    type Params = Params;

    fn figures(&self, fig: &FigureSink, tables: &Tables) -> Result<Vec<PathBuf>, Error> {
        let traj = tables.require("trajectories")?;
        let (p, t, a1, a2, al) = (
            traj.strs("policy"),
            traj.f64s("t"),
            traj.f64s("theta1"),
            traj.f64s("theta2"),
            traj.f64s("alpha1"),
        );
        let acro = Acrobot::default();
        // Final poses.
        let mut series =
            vec![
                Series::line("handstand", vec![(0.0, 0.0), (0.0, 1.0), (0.0, 2.0)], 7)
                    .mark(Mark::Dashed),
            ];
        let mut angle_series = Vec::new();
        for (c, name) in POLICIES.iter().enumerate() {
            let rows: Vec<usize> = (0..p.len()).filter(|&r| p[r] == *name).collect();
            let Some(&last) = rows.last() else { continue };
            let [p1, p2] = acro.positions(&[a1[last], a2[last], 0.0, 0.0]);
            series.push(
                Series::line(*name, vec![(0.0, 0.0), (p1[0], p1[1]), (p2[0], p2[1])], c)
                    .mark(Mark::LinePoints),
            );
            angle_series.push(Series::line(
                *name,
                rows.iter().map(|&r| (t[r], a1[r])).collect(),
                c,
            ));
        }
        let pose = Panel {
            title: "final poses from (-105, -15, 0, 0) deg".into(),
            x_label: "x (m)".into(),
            y_label: "height above the bar (m)".into(),
            series,
            x_range: Some((-2.2, 2.2)),
            y_range: Some((-2.2, 2.2)),
            legend: Legend::LowerRight,
            ..Default::default()
        };
        let lbc_rows: Vec<usize> = (0..p.len())
            .filter(|&r| p[r] == "lbc" && al[r].is_finite())
            .collect();
        let angles = Panel {
            title: "shoulder angle theta1 (handstand: pi/2)".into(),
            x_label: "time (s)".into(),
            y_label: "theta1 (rad)".into(),
            series: angle_series,
            legend: Legend::LowerRight,
            ..Default::default()
        };
        let weights = Panel {
            title: "LBC blend weight of tracker 1".into(),
            x_label: "time (s)".into(),
            y_label: "alpha_1".into(),
            series: vec![Series::line(
                "alpha_1",
                lbc_rows.iter().map(|&r| (t[r], al[r])).collect(),
                3,
            )],
            y_range: Some((-0.05, 1.05)),
            ..Default::default()
        };
        let mut files = fig.draw("final_pose", &Figure::grid(vec![pose, angles, weights], 3))?;
        // Sweep heat maps.
        const CLAMP: f64 = 3.0;
        let sw = tables.require("sweep")?;
        let (s1, s2, sp, sd) = (
            sw.f64s("theta1_deg"),
            sw.f64s("theta2_deg"),
            sw.strs("policy"),
            sw.f64s("final_distance"),
        );
        let mut maps = Vec::new();
        for name in POLICIES {
            let rows: Vec<usize> = (0..sp.len()).filter(|&r| sp[r] == name).collect();
            if rows.is_empty() {
                continue;
            }
            let nx = rows
                .iter()
                .take_while(|&&r| s2[r] == s2[rows[0]])
                .count()
                .max(1);
            let ny = rows.len() / nx;
            maps.push(Heatmap {
                title: format!("{name}: final distance to handstand (capped at {CLAMP})"),
                x_label: "start theta1 (deg)".into(),
                y_label: "start theta2 (deg)".into(),
                x_range: (s1[rows[0]], s1[rows[nx - 1]]),
                y_range: (s2[rows[0]], s2[rows[rows.len() - 1]]),
                nx,
                ny,
                values: rows.iter().map(|&r| sd[r].min(CLAMP)).collect(),
                value_label: "distance".into(),
                diverging: false,
                range: Some((0.0, CLAMP)),
            });
        }
        files.extend(fig.draw("sweep", &Figure::heatmaps(maps, 2))?);
        Ok(files)
    }

    fn report(&self, dir: &Path) -> Result<Findings, Error> {
        use polars::prelude::*;
        let df = read_csv(&dir.join("final.csv"))?;
        let (p, d, c) = (
            df_str(&df, "policy")?,
            df_f64(&df, "final_distance")?,
            df_f64(&df, "control_cost")?,
        );
        let mut md = String::from("From (-105, -15, 0, 0) degrees:\n\n| policy | final distance to handstand | control cost ½∫u² |\n| --- | --- | --- |\n");
        let mut dist = std::collections::BTreeMap::new();
        for i in 0..p.len() {
            md.push_str(&format!("| {} | {} | {} |\n", p[i], sig(d[i]), sig(c[i])));
            dist.insert(p[i].clone(), d[i]);
        }
        let sweep = read_csv(&dir.join("sweep.csv"))?
            .lazy()
            .group_by([col("policy")])
            .agg([
                col("success").sum().alias("successes"),
                col("success").count().alias("starts"),
                col("final_distance").median().alias("median_distance"),
            ])
            .sort(["policy"], Default::default())
            .collect()
            .map_err(|e| Error::Polars(e.to_string()))?;
        let (sp, ss, sn, sm) = (
            df_str(&sweep, "policy")?,
            df_f64(&sweep, "successes")?,
            df_f64(&sweep, "starts")?,
            df_f64(&sweep, "median_distance")?,
        );
        md.push_str("\nStart-state sweep:\n\n| policy | successes | median final distance |\n| --- | --- | --- |\n");
        for i in 0..sp.len() {
            md.push_str(&format!(
                "| {} | {} of {} | {} |\n",
                sp[i],
                ss[i],
                sn[i],
                sig(sm[i])
            ));
        }
        let g = |k: &str| dist.get(k).copied().unwrap_or(f64::NAN);
        let (t1, t2, nv, lbc) = (g("tracker1"), g("tracker2"), g("naive"), g("lbc"));
        let lbc_best = lbc < nv && lbc < t1 && lbc < t2;
        let naive_mid = nv < t1.min(t2);
        let verdict = Verdict::graded(lbc_best && naive_mid, lbc < nv && lbc < t1.max(t2));
        Ok(Findings {
            ours: md,
            verdict,
            why: format!(
                "paper: the trackers fail to come near upright, the naive blend does better, LBC comes closest. Ours: LBC {} the closest ({}), naive {} better than both trackers ({} vs {} and {}).",
                if lbc_best { "is" } else { "is not" },
                sig(lbc),
                if naive_mid { "is" } else { "is not" },
                sig(nv),
                sig(t1),
                sig(t2)
            ),
        })
    }
}
