//! `lbc_jumping`'s job: the PD take-off and landing, the DDP take-off examples and their
//! trackers, each desired jump's landing tracker, and every controller run on the simulator.

use super::rows::{JumpComponentRow, JumpRow, MotionRow, WeightRow};
use super::Params;
use crate::bellman::combine::normalized_entropy;
use crate::bellman::combine::{BlendMode, TrackerBlend};
use crate::control::ddp::DdpSolution;
use crate::control::lqr::{track, TrackingController};
use crate::control::{QuadraticCost, Rk4Map, StateCost};
use crate::experiment::output::{Table, Tables};
use crate::experiment::resolve::{ensure, positive, ParamError};
use crate::experiment::rows::table_of;
use crate::experiment::{other, Error, Job, RunContext};
use crate::families::lbc::{
    alpha_deviation, optimized_tracker, projected_weights, push_entropy, rule_table, scale_lambda,
    ENTROPY_COLUMNS,
};
use crate::physics::jumper::{Jumper, DOF, TORQUES};
use crate::physics::linearize::FiniteDifference;
use crate::physics::{check_finite, Dynamics, IntegratorKind, Simulator};
use crate::portable::hypot;
use crate::row;
use nalgebra::{DMatrix, DVector};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::f64::consts::{FRAC_PI_2, PI};
use std::time::Instant;

/// DDP's discrete dynamics: one RK4 step of the jumper per knot, Jacobians by differences.
type Map = Rk4Map<FiniteDifference<Jumper>>;

/// A Wooten-style PD take-off (Wooten and Hodgins 2000, the paper's initialization for jumps):
/// every joint driven toward an extended pose (head and elbows straight, hip and knee
/// straight, the ankle plantarflexed, the arms swung forward-up) at stiffness `strength`, the
/// torso held at its world angle by the hip.
#[derive(Debug, Clone, Copy, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Push {
    /// Damping as a fraction of the stiffness (s).
    pub kd_ratio: f64,
    /// Torque limit of every joint (N m), also DDP's and the trackers'.
    pub torque_limit: f64,
    /// Plantarflexion of the extended pose's ankle (rad).
    pub ankle_extension: f64,
    /// The shoulder's target (rad; π hangs the arms, 3π/2 points them forward).
    pub shoulder: f64,
    /// The torso's world angle target, back from upright (rad).
    pub torso: f64,
}

impl Push {
    pub(super) fn validate(&self) -> Result<(), ParamError> {
        ensure(
            self.kd_ratio >= 0.0 && self.kd_ratio < 1.0,
            "push.kd_ratio",
            "must be in [0, 1) s",
        )?;
        positive("push.torque_limit", self.torque_limit)?;
        ensure(
            self.ankle_extension.abs() < 1.5 && self.torso.abs() < 1.0,
            "push",
            "|ankle_extension| below 1.5 rad and |torso| below 1 rad",
        )?;
        ensure(
            (0.0..2.0 * PI).contains(&self.shoulder),
            "push.shoulder",
            "must be in [0, 2π) rad",
        )
    }

    /// The push's torques at state `x` with stiffness `strength` (N m/rad).
    pub fn control(&self, x: &[f64], strength: f64, u: &mut [f64]) {
        let (kp, kd) = (strength, self.kd_ratio * strength);
        let target = [
            0.0,
            self.shoulder,
            0.0,
            PI,
            0.0,
            FRAC_PI_2 - self.ankle_extension,
        ];
        let lim = self.torque_limit;
        for i in 0..TORQUES {
            u[i] = (kp * (target[i] - x[3 + i]) - kd * x[DOF + 3 + i]).clamp(-lim, lim);
        }
        // The torso in the world frame: the hip's reaction turns it.
        let e = x[2] - (FRAC_PI_2 + self.torso);
        u[3] = (kp * e + kd * x[DOF + 2]).clamp(-lim, lim);
    }
}

/// A PD landing: in the air the legs are set (knee bent by `knee_bend`, the thigh placing the
/// shank about vertical under a torso leaning `torso_lean` forward) and the foot is flattened
/// in the world; once heel or toe touches, the hip holds the torso's world angle and the ankle
/// balances the centre of mass over the middle of the sole. The arms are damped only.
#[derive(Debug, Clone, Copy, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Landing {
    /// Stiffness of the hip, knee, neck and elbow (N m/rad).
    pub kp: f64,
    /// Damping as a fraction of the stiffness (s).
    pub kd_ratio: f64,
    /// Torque limit of the hip, knee, neck, shoulder and elbow (N m).
    pub torque_limit: f64,
    /// The torso's forward lean (rad).
    pub torso_lean: f64,
    /// The knee's bend (rad).
    pub knee_bend: f64,
    /// Stiffness and damping flattening the foot in the air (N m/rad, N m s/rad).
    pub foot_kp: f64,
    /// (see `foot_kp`)
    pub foot_kd: f64,
    /// Ankle torque per metre of the centre of mass ahead of the middle of the sole (N m/m).
    pub balance_kp: f64,
    /// Ankle torque per m/s of the centre of mass's forward speed (N m s/m).
    pub balance_kd: f64,
    /// The ankle's torque limit (N m).
    pub ankle_limit: f64,
    /// Heel or toe within this of the ground counts as touching (m).
    pub contact_m: f64,
}

impl Landing {
    pub(super) fn validate(&self) -> Result<(), ParamError> {
        for (k, v) in [
            ("landing.kp", self.kp),
            ("landing.torque_limit", self.torque_limit),
            ("landing.foot_kp", self.foot_kp),
            ("landing.ankle_limit", self.ankle_limit),
            ("landing.contact_m", self.contact_m),
        ] {
            positive(k, v)?;
        }
        ensure(
            self.kd_ratio >= 0.0
                && self.kd_ratio < 1.0
                && self.foot_kd >= 0.0
                && self.balance_kp >= 0.0
                && self.balance_kd >= 0.0,
            "landing",
            "kd_ratio in [0, 1), foot_kd, balance_kp and balance_kd non-negative",
        )?;
        ensure(
            self.torso_lean.abs() < 1.0 && (0.0..2.0).contains(&self.knee_bend),
            "landing",
            "|torso_lean| below 1 rad, knee_bend in [0, 2) rad",
        )
    }

    /// The landing's torques at state `x`.
    pub fn control(&self, j: &Jumper, x: &[f64], u: &mut [f64]) {
        let (kp, kd, lim) = (self.kp, self.kd_ratio * self.kp, self.torque_limit);
        let pd = |target: f64, i: usize| {
            (kp * (target - x[3 + i]) - kd * x[DOF + 3 + i]).clamp(-lim, lim)
        };
        let torso = FRAC_PI_2 - self.torso_lean;
        let knee = -self.knee_bend;
        let hip = 1.5 * PI - torso - knee / 2.0;
        u[0] = pd(0.0, 0);
        u[1] = (-kd * x[DOF + 4]).clamp(-lim, lim);
        u[2] = pd(0.0, 2);
        u[4] = pd(knee, 4);
        let [heel, toe] = j.contact_points(&x[..DOF]);
        let touching = |p: [f64; 2]| p[1] - j.terrain.height_slope(p[0]).0 < self.contact_m;
        let al = self.ankle_limit;
        // The foot flattened in the world, always; on the ground the balance term too.
        let foot = x[2] + x[6] + x[7] + x[8];
        let rate = x[DOF + 2] + x[DOF + 6] + x[DOF + 7] + x[DOF + 8];
        let flat = self.foot_kp * (2.0 * PI - foot) - self.foot_kd * rate;
        if touching(heel) || touching(toe) {
            u[3] = (kp * (x[2] - torso) + kd * x[DOF + 2]).clamp(-lim, lim);
            let c = j.tree.center_of_mass(&x[..DOF])[0];
            let v = j.com_velocity(x)[0];
            let ahead = c - 0.5 * (heel[0] + toe[0]);
            u[5] = (flat - (self.balance_kp * ahead + self.balance_kd * v)).clamp(-al, al);
        } else {
            u[3] = pd(hip, 3);
            u[5] = flat.clamp(-al, al);
        }
    }
}

/// The jump's height from state `x`: the centre of mass's ballistic apex above `base` (m),
/// its height now plus v_y²/2g when rising.
pub fn jump_height(j: &Jumper, x: &[f64], base: f64) -> f64 {
    let vy = j.com_velocity(x)[1].max(0.0);
    j.tree.center_of_mass(&x[..DOF])[1] + vy * vy / (2.0 * j.tree.gravity) - base
}

/// A motion sampled at knots: states x_0..x_N and the mean torque over each knot.
struct Motion {
    xs: Vec<DVector<f64>>,
    us: Vec<DVector<f64>>,
}

/// Runs the continuous controller `ctl` on the simulator from `x0` for `knots` knots of
/// `knot_dt` (RK4 at knot_dt / substeps, the control updated every simulator step).
fn simulate(
    j: &Jumper,
    x0: &[f64],
    knots: usize,
    knot_dt: f64,
    substeps: usize,
    mut ctl: impl FnMut(&[f64], &mut [f64]),
) -> Result<Motion, Error> {
    let dt = knot_dt / substeps as f64;
    let mut sim = Simulator::new(j.clone(), IntegratorKind::Rk4);
    let mut x = x0.to_vec();
    let mut u = vec![0.0; TORQUES];
    let mut m = Motion {
        xs: vec![DVector::from_row_slice(&x)],
        us: Vec::with_capacity(knots),
    };
    for k in 0..knots {
        let mut mean = DVector::zeros(TORQUES);
        for s in 0..substeps {
            ctl(&x, &mut u);
            for i in 0..TORQUES {
                mean[i] += u[i] / substeps as f64;
            }
            sim.step(&mut x, &u, dt);
            let step = k * substeps + s;
            check_finite("jumper", step, step as f64 * dt, &x).map_err(other)?;
        }
        m.xs.push(DVector::from_row_slice(&x));
        m.us.push(mean);
    }
    Ok(m)
}

/// What one controller's jump did on the simulator.
#[derive(Debug, Clone, Default)]
pub(super) struct JumpRun {
    /// The state at take-off.
    pub takeoff: Vec<f64>,
    /// Whether the body fell ([`crate::physics::jumper::DiverBody`]'s fall limits) at any time.
    pub fell: bool,
    /// Whether it ended standing: not fallen, heel and toe on the ground, the centre of mass
    /// over the sole.
    pub landed: bool,
    /// ½∫uᵀRu dt over the take-off.
    pub effort: f64,
    /// The state at every knot and α_low over the take-off (when kept).
    pub states: Vec<Vec<f64>>,
    /// (see `states`)
    pub alpha_low: Vec<f64>,
}

/// Whether `x` stands balanced on its foot: not fallen, heel or toe within 1 cm of the
/// ground, the centre of mass above the sole (between heel and toe) and moving slower than
/// 0.5 m/s (the PD landing's balance rocks the body between heel and toe, so either may be up).
pub fn standing(j: &Jumper, x: &[f64]) -> bool {
    let [heel, toe] = j.contact_points(&x[..DOF]);
    let low = |p: [f64; 2]| (p[1] - j.terrain.height_slope(p[0]).0).abs() < 0.01;
    let c = j.tree.center_of_mass(&x[..DOF])[0];
    let v = j.com_velocity(x);
    !j.fallen(x)
        && (low(heel) || low(toe))
        && c >= heel[0].min(toe[0])
        && c <= heel[0].max(toe[0])
        && hypot(v[0], v[1]) < 0.5
}

/// What the run builds once.
struct Setup {
    body: Jumper,
    map: Map,
    x0: Vec<f64>,
    /// The crouch's centre-of-mass height (the jump heights' base).
    base: f64,
    /// The take-off's knots and the landing's.
    n_off: usize,
    n_land: usize,
    /// Q_T = Fᵀ W F: W = diag(1/scale²) over the centre of mass's position, the torso's and
    /// joints' angles, the centre of mass's velocity and the angular rates; F the Jacobian of
    /// those features at the average trajectory's take-off state ([`Setup::set_metric`]).
    q_final: DMatrix<f64>,
    /// W's diagonal.
    feature_weights: Vec<f64>,
    /// Q_T's angle entries (the running weight before its scale and horizon).
    q_angles: DMatrix<f64>,
    r: DMatrix<f64>,
}

impl Params {
    fn setup(&self) -> Result<Setup, Error> {
        let body = Jumper::default();
        let map = Rk4Map::new(FiniteDifference::new(body.clone()), self.knot_dt).map_err(other)?;
        let c = &self.crouch;
        let x0 = body.crouch(0.0, c.lean, c.shin, c.arm);
        let base = body.tree.center_of_mass(&x0[..DOF])[1];
        // W's diagonal (Q_T before [`Setup::set_metric`] maps it onto the state).
        let d = self.cost.terminal_diagonal(DOF);
        let mut a = vec![0.0; 2 * DOF];
        a[2..DOF].copy_from_slice(&d[2..DOF]);
        Ok(Setup {
            body,
            map,
            x0,
            base,
            n_off: (self.takeoff_s / self.knot_dt).round() as usize,
            n_land: (self.landing_s / self.knot_dt).round() as usize,
            q_final: DMatrix::from_diagonal(&DVector::from_vec(d.clone())),
            feature_weights: d,
            q_angles: DMatrix::from_diagonal(&DVector::from_vec(a)),
            r: self.cost.control_weight(TORQUES),
        })
    }
}

/// The take-off's features at state `x`: the centre of mass's position, the torso's and
/// joints' angles, the centre of mass's velocity and the angular rates (the hip's position and
/// velocity replaced by the centre of mass's: in the air no torque changes the latter, so a
/// terminal cost on it asks nothing the limbs could do by flailing).
pub fn features(j: &Jumper, x: &[f64]) -> Vec<f64> {
    let mut f = x.to_vec();
    let c = j.tree.center_of_mass(&x[..DOF]);
    let v = j.com_velocity(x);
    f[..2].copy_from_slice(&c);
    f[DOF..DOF + 2].copy_from_slice(&v);
    f
}

impl Setup {
    /// Sets Q_T = Fᵀ W F with F the features' Jacobian at `x` (central differences).
    fn set_metric(&mut self, x: &[f64]) {
        let n = 2 * DOF;
        let mut f = DMatrix::zeros(n, n);
        let h = 1e-6;
        for c in 0..n {
            let (mut a, mut b) = (x.to_vec(), x.to_vec());
            a[c] += h;
            b[c] -= h;
            let (fa, fb) = (features(&self.body, &a), features(&self.body, &b));
            for r in 0..n {
                f[(r, c)] = (fa[r] - fb[r]) / (2.0 * h);
            }
        }
        let w = DMatrix::from_diagonal(&DVector::from_row_slice(&self.feature_weights));
        let q = f.transpose() * w * &f;
        self.q_final = (&q + q.transpose()) * 0.5;
    }

    /// The PD push of `strength` from the crouch over the take-off.
    fn push(&self, p: &Params, strength: f64) -> Result<Motion, Error> {
        simulate(
            &self.body,
            &self.x0,
            self.n_off,
            p.knot_dt,
            p.substeps,
            |x, u| p.push.control(x, strength, u),
        )
    }

    /// The take-off error: the Q_T norm of `x − target`.
    fn error(&self, x: &[f64], target: &DVector<f64>) -> f64 {
        let d = DVector::from_row_slice(x) - target;
        (d.transpose() * &self.q_final * &d)[0].max(0.0).sqrt()
    }

    /// §6.1's objective toward `target` with `average` (its first `n` states) as the average
    /// trajectory over a horizon of `n` knots.
    fn cost(&self, p: &Params, target: DVector<f64>, average: &[DVector<f64>]) -> QuadraticCost {
        let n = average.len() - 1;
        let horizon = n as f64 * p.knot_dt;
        QuadraticCost {
            dt: p.knot_dt,
            r: self.r.clone(),
            state: Some(StateCost {
                weight: &self.q_angles * (p.cost.average_scale / horizon),
                reference: average[..n].to_vec(),
            }),
            q_final: self.q_final.clone(),
            x_final: target,
        }
    }

    /// A take-off example: DDP from the crouch to `own`'s take-off state with `average` as the
    /// average trajectory, initialized with `own`'s torques; its tracker and the seconds.
    fn example(
        &self,
        p: &Params,
        own: &Motion,
        average: &Motion,
    ) -> Result<(DdpSolution, TrackingController, f64), Error> {
        let cost = self.cost(p, own.xs[self.n_off].clone(), &average.xs);
        optimized_tracker(
            &self.map,
            &cost,
            &self.x0,
            &own.us,
            p.push.torque_limit,
            p.takeoff_iterations,
            p.tol_cost,
        )
    }

    /// The landing tracker of take-off state `x_d`: the PD landing's motion from it, tracked by
    /// TV-LQR with §6.1's objective (terminal: the landing's last state at rest; average: the
    /// landing itself).
    fn landing(&self, p: &Params, x_d: &DVector<f64>) -> Result<(TrackingController, f64), Error> {
        let t0 = Instant::now();
        let j = &self.body;
        let m = simulate(
            j,
            x_d.as_slice(),
            self.n_land,
            p.knot_dt,
            p.substeps,
            |x, u| p.landing.control(j, x, u),
        )?;
        let mut rest = m.xs[self.n_land].clone();
        rest.rows_mut(DOF, DOF).fill(0.0);
        let cost = self.cost(p, rest, &m.xs);
        let tracker = track(&self.map, &cost, &m.xs, &m.us).map_err(other)?;
        Ok((tracker, t0.elapsed().as_secs_f64()))
    }

    /// Runs a jump on the simulator: `takeoff` (a blend, or `None` for the PD push of
    /// `strength`) over the take-off, then `landing` over the landing, then the PD landing for
    /// `hold_s`.
    fn jump(
        &self,
        p: &Params,
        takeoff: Option<&TrackerBlend>,
        strength: f64,
        landing: &TrackingController,
        keep: bool,
    ) -> Result<JumpRun, Error> {
        let j = &self.body;
        let sim_dt = p.knot_dt / p.substeps as f64;
        let mut sim = Simulator::new(j.clone(), IntegratorKind::Rk4);
        let mut x = self.x0.clone();
        let (mut u, mut ui) = (vec![0.0; TORQUES], vec![0.0; TORQUES]);
        let mut alpha = vec![0.0; 2];
        let mut run = JumpRun::default();
        let limits = vec![p.push.torque_limit; TORQUES];
        let land = TrackerBlend {
            trackers: std::slice::from_ref(landing),
            weights: vec![1.0],
            lambda: 1.0,
            mode: BlendMode::Single(0),
            limits: Some(&limits),
        };
        let hold = (p.hold_s / p.knot_dt).round() as usize;
        let mut step = 0usize;
        for k in 0..self.n_off + self.n_land + hold {
            if keep {
                run.states.push(x.clone());
            }
            let phase_off = k < self.n_off;
            let knot_control = if phase_off {
                match takeoff {
                    Some(b) => {
                        b.control(&x, k, &mut u, &mut alpha, &mut ui)
                            .map_err(other)?;
                        true
                    }
                    None => false,
                }
            } else if k < self.n_off + self.n_land {
                land.control(&x, k - self.n_off, &mut u, &mut alpha[..1], &mut ui)
                    .map_err(other)?;
                true
            } else {
                false
            };
            if phase_off {
                run.alpha_low.push(if takeoff.is_some() {
                    alpha[0]
                } else {
                    f64::NAN
                });
            }
            let mut knot_effort = 0.0;
            for _ in 0..p.substeps {
                if !knot_control {
                    if phase_off {
                        p.push.control(&x, strength, &mut u);
                    } else {
                        p.landing.control(j, &x, &mut u);
                    }
                }
                if phase_off {
                    let ru: f64 = (0..TORQUES).map(|i| u[i] * u[i] * self.r[(i, i)]).sum();
                    knot_effort += 0.5 * ru * sim_dt;
                }
                sim.step(&mut x, &u, sim_dt);
                check_finite("jumper", step, step as f64 * sim_dt, &x).map_err(other)?;
                step += 1;
            }
            run.effort += knot_effort;
            if k + 1 == self.n_off {
                run.takeoff = x.clone();
            }
            if j.fallen(&x) {
                run.fell = true;
                break;
            }
        }
        if keep {
            run.states.push(x.clone());
        }
        if run.takeoff.is_empty() {
            run.takeoff = x.clone();
        }
        run.landed = !run.fell && standing(j, &x);
        Ok(run)
    }
}

/// Where each PD push sits in the job's list of pushes (and of their targets): the low and the
/// high example, their average (the metric's scale), then one per desired jump.
mod push {
    pub const LOW: usize = 0;
    pub const HIGH: usize = 1;
    pub const MEAN: usize = 2;
    pub const FIRST_DESIRED: usize = 3;
}

/// A compared take-off controller.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Takeoff {
    /// Linear Bellman combination of the two examples' trackers.
    Lbc,
    /// The examples' torques averaged with the projected weights.
    Naive,
    /// The low example's tracker alone.
    Low,
    /// The high example's tracker alone.
    High,
    /// The desired jump's own PD push (no blend).
    Reference,
}

impl Takeoff {
    /// Every controller, in `jumps.csv`'s order.
    const ALL: [Takeoff; 5] = [
        Takeoff::Lbc,
        Takeoff::Naive,
        Takeoff::Low,
        Takeoff::High,
        Takeoff::Reference,
    ];

    /// Its name in the tables.
    fn name(self) -> &'static str {
        METHODS[self as usize]
    }

    /// How its blend mixes the examples' trackers; `None`: it does not use them.
    fn mode(self) -> Option<BlendMode> {
        match self {
            Takeoff::Lbc => Some(BlendMode::Lbc),
            Takeoff::Naive => Some(BlendMode::Naive),
            Takeoff::Low => Some(BlendMode::Single(0)),
            Takeoff::High => Some(BlendMode::Single(1)),
            Takeoff::Reference => None,
        }
    }

    /// Whether its take-off is a blend whose α the tables record (LBC's and the naive one's).
    fn blends(self) -> bool {
        matches!(self, Takeoff::Lbc | Takeoff::Naive)
    }
}

/// The compared take-off controllers' names, in [`Takeoff::ALL`]'s order (`reference`: the
/// desired jump's own PD push).
pub(super) const METHODS: [&str; 5] = ["lbc", "naive", "low", "high", "reference"];

/// The tables made from the runs on the simulator ([`Params::run_tables`]).
struct RunTables {
    jumps: Vec<JumpRow>,
    weights: Vec<WeightRow>,
    entropy: Table,
    motion: Vec<MotionRow>,
}

/// A take-off example by DDP or a desired jump's landing tracker, built in one parallel stage.
enum Built {
    Example(Box<(DdpSolution, TrackingController, f64)>),
    Landing(Box<TrackingController>, f64),
}

/// The controllers a run compares: the two examples' DDP solutions with their seconds, their
/// trackers, and each desired jump's landing tracker with its seconds.
struct Controllers {
    examples: Vec<(DdpSolution, f64)>,
    trackers: Vec<TrackingController>,
    landings: Vec<(TrackingController, f64)>,
}

impl Params {
    /// Step 2: the two take-off examples by DDP and each desired jump's landing tracker, in
    /// parallel.
    fn controllers(
        &self,
        ctx: &RunContext,
        s: &Setup,
        pushes: &[Motion],
        targets: &[DVector<f64>],
    ) -> Result<Controllers, Error> {
        let nd = self.desired.len();
        let pb = ctx.progress((2 + nd) as u64, "take-off examples and landings");
        let built: Vec<Result<Built, Error>> = ctx.stage("controllers", || {
            (0..2 + nd)
                .into_par_iter()
                .map(|i| {
                    let r = if i < 2 {
                        s.example(self, &pushes[i], &pushes[push::MEAN])
                            .map(|e| Built::Example(Box::new(e)))
                    } else {
                        s.landing(self, &targets[push::FIRST_DESIRED + (i - 2)])
                            .map(|(t, secs)| Built::Landing(Box::new(t), secs))
                    };
                    pb.inc(1);
                    r
                })
                .collect()
        });
        pb.finish_and_clear();
        let (mut examples, mut trackers, mut landings) = (Vec::new(), Vec::new(), Vec::new());
        for b in built {
            match b? {
                Built::Example(e) => {
                    let (sol, tracker, secs) = *e;
                    examples.push((sol, secs));
                    trackers.push(tracker);
                }
                Built::Landing(t, secs) => landings.push((*t, secs)),
            }
        }
        Ok(Controllers {
            examples,
            trackers,
            landings,
        })
    }

    /// `jumps.csv`'s rows, LBC's α over each take-off (`weights.csv`), LBC's and the naive
    /// blend's α entropy (`entropy.csv`) and the kept runs' motion, from the runs of `cases`.
    fn run_tables(
        &self,
        s: &Setup,
        cases: &[(usize, Takeoff)],
        runs: &[(JumpRun, f64)],
        targets: &[DVector<f64>],
        heights: &[f64],
        projected: &[Vec<f64>],
    ) -> RunTables {
        let j = &s.body;
        let mut jumps: Vec<JumpRow> = Vec::with_capacity(runs.len());
        let mut weights = Vec::new();
        // α's entropy over the take-off (entropy.csv), LBC's and the naive blend's.
        let mut entropy = Table::new(&ENTROPY_COLUMNS);
        let mut motion = Vec::new();
        let frame = ((self.gif_frame_s / self.knot_dt).round() as usize).max(1);
        for (&(d, m), (r, secs)) in cases.iter().zip(runs) {
            let x_d = &targets[push::FIRST_DESIRED + d];
            let v = j.com_velocity(&r.takeoff);
            let vd = j.com_velocity(x_d.as_slice());
            jumps.push(JumpRow {
                desired_height_m: heights[push::FIRST_DESIRED + d],
                method: m.name().to_string(),
                takeoff_error: s.error(&r.takeoff, x_d),
                landed: r.landed as u8 as f64,
                desired_strength: self.desired[d],
                height_m: jump_height(j, &r.takeoff, s.base),
                fell: r.fell as u8 as f64,
                effort: r.effort,
                weight_low: projected[d][0],
                weight_high: projected[d][1],
                speed_error_m_s: hypot(v[0] - vd[0], v[1] - vd[1]),
                seconds: *secs,
            });
            if m.blends() {
                let pair = |a: f64| [a, 1.0 - a];
                let h: Vec<f64> = r
                    .alpha_low
                    .iter()
                    .map(|&a| normalized_entropy(&pair(a)))
                    .collect();
                let dev: Vec<f64> = r
                    .alpha_low
                    .iter()
                    .map(|&a| alpha_deviation(&pair(a), &projected[d]))
                    .collect();
                let run = format!(
                    "{} m",
                    crate::experiment::report::sig(heights[push::FIRST_DESIRED + d])
                );
                push_entropy(&mut entropy, &run, m.name(), self.knot_dt, &h, &dev);
            }
            if m == Takeoff::Lbc {
                // Every 5 ms (the take-off is short).
                let every = ((0.005 / self.knot_dt).round() as usize).max(1);
                for (i, a) in r.alpha_low.iter().enumerate().step_by(every) {
                    weights.push(WeightRow {
                        desired_height_m: heights[push::FIRST_DESIRED + d],
                        t_s: i as f64 * self.knot_dt,
                        alpha_low: *a,
                    });
                }
            }
            for (i, x) in r.states.iter().enumerate().step_by(frame) {
                let a = r.alpha_low.get(i).copied().unwrap_or(f64::NAN);
                motion.push(MotionRow::at(
                    m.name(),
                    i as f64 * self.knot_dt,
                    a,
                    &x[..DOF],
                ));
            }
        }
        RunTables {
            jumps,
            weights,
            entropy,
            motion,
        }
    }

    /// The rule's settings table; `heights` are the pushes' jump heights in [`push`]'s order.
    fn rule_settings(&self, lambda: f64, heights: &[f64], middle: usize) -> Table {
        rule_table(&[
            ("takeoff_tolerance", self.rule.takeoff_tolerance),
            ("lambda", lambda),
            ("low_height_m", heights[push::LOW]),
            ("high_height_m", heights[push::HIGH]),
            ("takeoff_s", self.takeoff_s),
            ("landing_s", self.landing_s),
            ("hold_s", self.hold_s),
            ("knot_dt", self.knot_dt),
            ("middle_desired", heights[push::FIRST_DESIRED + middle]),
        ])
    }
}

impl Job for Params {
    fn params_json(&self) -> serde_json::Value {
        serde_json::to_value(self).expect("params serialize")
    }

    fn run(&self, ctx: &RunContext) -> Result<Tables, Error> {
        let mut s = ctx.stage("setup", || self.setup())?;
        // 1. The PD pushes: the examples', the average's and each desired jump's.
        let mean = 0.5 * (self.low + self.high);
        let mut strengths = vec![self.low, self.high, mean];
        strengths.extend(&self.desired);
        let pushes: Vec<Motion> = ctx.stage("pushes", || {
            strengths
                .par_iter()
                .map(|&k| s.push(self, k))
                .collect::<Result<Vec<_>, _>>()
        })?;
        let targets: Vec<DVector<f64>> = pushes.iter().map(|m| m.xs[s.n_off].clone()).collect();
        s.set_metric(targets[push::MEAN].as_slice());
        let s = s;
        let j = &s.body;
        // 2. The two take-off examples by DDP and each desired jump's landing tracker, in
        //    parallel.
        let nd = self.desired.len();
        let Controllers {
            examples,
            trackers,
            landings,
        } = self.controllers(ctx, &s, &pushes, &targets)?;
        let centers = [targets[push::LOW].clone(), targets[push::HIGH].clone()];
        let lambda = scale_lambda(&s.q_final, &centers[0], &centers[1]);
        let limits = vec![self.push.torque_limit; TORQUES];
        let projected = (0..nd)
            .map(|d| {
                let what = format!("desired strength {}", self.desired[d]);
                projected_weights(
                    &s.q_final,
                    lambda,
                    &centers,
                    &targets[push::FIRST_DESIRED + d],
                    &what,
                )
            })
            .collect::<Result<Vec<_>, _>>()?;
        // 3. Every take-off with every desired jump's landing, on the simulator.
        let middle = nd / 2;
        let mut cases: Vec<(usize, Takeoff)> = Vec::new();
        for d in 0..nd {
            for m in Takeoff::ALL {
                cases.push((d, m));
            }
        }
        let pb = ctx.progress(cases.len() as u64, "jumps on the simulator");
        let runs: Vec<Result<(JumpRun, f64), Error>> = ctx.stage("jumps", || {
            cases
                .par_iter()
                .map(|&(d, m)| {
                    let t0 = Instant::now();
                    let w = &projected[d];
                    let blend = m.mode().map(|mode| TrackerBlend {
                        trackers: &trackers,
                        weights: w.clone(),
                        lambda,
                        mode,
                        limits: Some(&limits),
                    });
                    let keep = d == middle && m.blends();
                    let r = s.jump(self, blend.as_ref(), self.desired[d], &landings[d].0, keep)?;
                    pb.inc(1);
                    Ok((r, t0.elapsed().as_secs_f64()))
                })
                .collect()
        });
        pb.finish_and_clear();
        let runs = runs.into_iter().collect::<Result<Vec<_>, _>>()?;
        let heights: Vec<f64> = targets
            .iter()
            .map(|t| jump_height(j, t.as_slice(), s.base))
            .collect();
        let RunTables {
            jumps,
            weights,
            entropy,
            motion,
        } = self.run_tables(&s, &cases, &runs, &targets, &heights, &projected);
        // The examples alone against their own targets (the premise), on the simulator.
        let mut components = Vec::new();
        for (i, example) in [Takeoff::Low, Takeoff::High].into_iter().enumerate() {
            let (sol, secs) = &examples[i];
            let name = example.name();
            // Each example's tracker alone against its own target (the premise): its take-off
            // is the same at every desired jump (only the landing that follows differs).
            let r = cases
                .iter()
                .position(|c| c.1 == example)
                .map(|k| &runs[k].0)
                .ok_or_else(|| other(format!("no {name} run")))?;
            components.push(JumpComponentRow {
                component: name.to_string(),
                strength: strengths[i],
                height_m: heights[i],
                takeoff_error: s.error(&r.takeoff, &targets[i]),
                iterations: sol.trace.len() as i64,
                cost: sol.cost,
                termination: format!("{:?}", sol.termination),
                seconds: *secs,
            });
        }
        let mut landing = Table::new(&["desired", "desired_strength", "seconds"]);
        for d in 0..nd {
            landing.push(row![
                heights[push::FIRST_DESIRED + d],
                self.desired[d],
                landings[d].1
            ]);
        }
        let rule = self.rule_settings(lambda, &heights, middle);
        Ok(Tables::from([
            ("jumps", table_of(&jumps)),
            ("components", table_of(&components)),
            ("landing", landing),
            ("weights", table_of(&weights)),
            ("entropy", entropy),
            ("motion", table_of(&motion)),
            ("rule", rule),
        ]))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_jump_height_is_the_ballistic_apex() {
        let j = Jumper::default();
        let mut x = j.crouch(0.0, 0.3, 0.3, 0.0);
        let base = j.tree.center_of_mass(&x[..DOF])[1];
        assert!(jump_height(&j, &x, base).abs() < 1e-12);
        // Every link moving up at 2 m/s: 2²/2g above.
        x[DOF + 1] = 2.0;
        let h = jump_height(&j, &x, base);
        assert!((h - 4.0 / (2.0 * 9.81)).abs() < 1e-9, "{h}");
        // Falling: no rise.
        x[DOF + 1] = -2.0;
        assert!(jump_height(&j, &x, base).abs() < 1e-12);
    }

    /// The spec's PD push and landing (experiments/lbc_jumping.toml).
    fn spec() -> (Push, Landing) {
        (
            Push {
                kd_ratio: 0.1,
                torque_limit: 500.0,
                ankle_extension: 0.3,
                shoulder: 4.0,
                torso: 0.0,
            },
            Landing {
                kp: 700.0,
                kd_ratio: 0.1,
                torque_limit: 500.0,
                torso_lean: 0.2,
                knee_bend: 0.6,
                foot_kp: 300.0,
                foot_kd: 30.0,
                balance_kp: 3000.0,
                balance_kd: 300.0,
                ankle_limit: 300.0,
                contact_m: 0.004,
            },
        )
    }

    #[test]
    fn a_pd_push_leaves_the_ground_higher_when_stiffer_and_the_pd_landing_stands_after_it() {
        let j = Jumper::default();
        let (push, landing) = spec();
        let x0 = j.crouch(0.0, 0.5, 0.5, 0.5);
        let base = j.tree.center_of_mass(&x0[..DOF])[1];
        let mut heights = Vec::new();
        for strength in [500.0, 800.0] {
            let off =
                simulate(&j, &x0, 2000, 1e-4, 1, |x, u| push.control(x, strength, u)).unwrap();
            let x = off.xs[2000].as_slice();
            // At 0.2 s rising, the heel off the ground and the toe leaving it (the weaker push's
            // toe still touches by about 2 mm).
            let [heel, toe] = j.contact_points(&x[..DOF]);
            assert!(heel[1] > 0.01 && toe[1] > -0.005, "{heel:?} {toe:?}");
            assert!(j.com_velocity(x)[1] > 0.3, "{:?}", j.com_velocity(x));
            heights.push(jump_height(&j, x, base));
            let land = simulate(&j, x, 18000, 1e-4, 1, |x, u| landing.control(&j, x, u)).unwrap();
            for s in &land.xs {
                assert!(!j.fallen(s.as_slice()), "{strength}: fell");
            }
            assert!(
                standing(&j, land.xs[18000].as_slice()),
                "{strength}: not standing"
            );
        }
        assert!(heights[1] > heights[0] + 0.02, "{heights:?}");
    }

    #[test]
    fn a_crouch_stands_and_a_body_lying_down_has_fallen() {
        let j = Jumper::default();
        let x = j.crouch(0.0, 0.3, 0.3, 0.0);
        assert!(standing(&j, &x) && !j.fallen(&x));
        let mut y = x.clone();
        y[1] = 0.2;
        assert!(j.fallen(&y) && !standing(&j, &y));
        let mut z = x.clone();
        z[1] += 0.05;
        assert!(!standing(&j, &z), "in the air");
        let mut z = x.clone();
        z[DOF] = 1.0;
        assert!(!standing(&j, &z), "moving");
    }
}
