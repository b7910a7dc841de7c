//! `lbc_diver_interpolation` (LBC Fig. 6) and `lbc_diver_coordination` (LBC Fig. 8): dives of
//! the seven-link planar diver optimized by torque-limited DDP (finite-difference Jacobians),
//! tracked by LQR controllers with eq. 12 value functions, and combined.
//!
//! A dive starts from a straight take-off pose (arms overhead) with an upward and forward
//! velocity and a whole-body angular velocity ω₀; to enter the water head first it must tuck or
//! pike to turn through half a revolution, then open up. Each dive minimizes
//! (x_T − x̄)ᵀ Q_T (x_T − x̄) + ∫ ½ uᵀRu dt, where x̄ is the straight, head-down pose rotated by
//! the dive's target offset (Q_T weights the torso angle, the joint angles and all rates; the
//! ballistic position is not controllable and not weighted).
//!
//! - **Torque limits** |u_j| ≤ `torque_limits[j]` (neck, shoulder, elbow, hip, knee, ankle; the
//!   lumped limbs carry both sides) in DDP (box constraints) and in every closed loop.
//! - **λ from a noise model.** With R = `control_weight`·I the linear Bellman equation holds
//!   for joint-torque noise of covariance λR⁻¹ (eq. 8); the spec states the noise intensity σ
//!   (N·m·√s), so λ = σ²R in z = exp(−v̂/λ), and the projection is onto exp(−g_i/λ).
//! - *Interpolation*: an under-rotating and an over-rotating dive (targets −δ and +δ) from one
//!   take-off; for each desired entry angle strictly between them, weights w from projecting
//!   the desired reward exp(−ḡ/λ) onto exp(−g_i/λ) (§4.1); LBC vs a naive fixed-weight average,
//!   scored at the desired entry angle and by the objective with the reconstructed terminal
//!   cost ĝ = −λ log Σ w_i exp(−g_i/λ), against a DDP dive optimized directly for ĝ (ground
//!   truth). `interpolation.csv`: desired_angle, method (lbc, naive, direct), reached_angle,
//!   weight1, weight2, objective, excess_objective, mean_entropy, max_torque_fraction.
//! - *Coordination*: three vertical dives for ω₀ = 0.85, 1, 1.15 rad/s combined with w = 1 vs
//!   the single tracker of the ω₀ = 1 dive, from take-off rates well beyond the components.
//!   `coordination.csv`: initial_omega, method, entry_error, objective, mean_entropy,
//!   max_torque_fraction, objective_outcome.
//!
//! Here: what both families share (dive settings, DDP dives and their trackers, the closed loop,
//! the reconstructed cost); `interpolation`, `coordination`, `figures` and `report` hold the rest.

mod coordination;
mod disturbance;
mod figures;
mod interpolation;
mod report;
mod rows;

pub use coordination::{
    compare_objectives, coordination_rule, CoordinationCounts, CoordinationParams,
    CoordinationRule, LbcDiverCoordination,
};
pub use disturbance::{disturbance_rule, DisturbanceParams, LbcDiveDisturbance};
pub use interpolation::{choose_offset, InterpolationParams, LbcDiverInterpolation, OffsetTrial};

use crate::bellman::combine::{blend_weights, normalized_entropy, TrackerBlend};
use crate::control::ddp::{solve, ControlBounds, DdpOptions, DdpSolution};
use crate::control::lqr::{track, TrackingController};
use crate::control::{QuadraticCost, Rk4Map, StateCost};
use crate::experiment::resolve::{ensure, positive, ParamError};
use crate::experiment::{other, Error, RunContext};
use crate::families::lbc::alpha_deviation;
use crate::physics::diver::{diver, entry_angle};
use crate::physics::linearize::FiniteDifference;
use crate::physics::planar::PlanarTree;
use nalgebra::{DMatrix, DVector};
use rayon::prelude::*;
use rows::DiveRow;
use serde::{Deserialize, Serialize};
use std::f64::consts::{FRAC_PI_2, PI};

/// Relative difference step of the second-order dynamics terms of the DDP value function
/// (differences of finite-difference Jacobians, so larger than DDP's default).
const DDP_VALUE_STEP: f64 = 1e-4;

/// Index of the torso angle in the diver's state.
const TORSO: usize = 2;

/// Shared settings of the dive optimizations.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DiveSettings {
    /// Flight time to water entry (s).
    pub horizon: f64,
    /// RK4 time step (s).
    pub dt: f64,
    /// Take-off velocity of the hip (m/s, horizontal and vertical).
    pub takeoff_velocity: [f64; 2],
    /// Terminal weight of the torso angle (1/rad²).
    pub torso_weight: f64,
    /// Terminal weight of each joint angle (1/rad²).
    pub joint_weight: f64,
    /// Terminal weight of every angular rate (s²/rad²).
    pub rate_weight: f64,
    /// Control weight R (per N²·m²).
    pub control_weight: f64,
    /// DDP iteration limit.
    pub max_iterations: usize,
    /// Joint torque limits |u_j| ≤ this (N·m): neck, shoulder, elbow, hip, knee, ankle.
    pub torque_limits: [f64; 6],
    /// Intensity σ of the white joint-torque noise (N·m·√s); λ = σ² R (eq. 8: noise λR⁻¹).
    pub torque_noise: f64,
    /// The §6.1 running term (LBC paper: "we found it important to include a term in the
    /// integrated cost of the objective which penalized deviations from some form of average
    /// trajectory"): (x − x̄(t))ᵀ Q (x − x̄(t)) in every dive's running cost, x̄ the mean state
    /// of the component dives at each step (optimized first without the term), Q the terminal
    /// weights' angle block (torso and joints) × `average_scale` / `horizon`, so that at scale
    /// 1 a deviation held over the whole flight costs what it costs at entry (our rule; the
    /// paper gives no Q). 0 (the default): off.
    #[serde(default)]
    pub average_scale: f64,
    /// x̄ once [`DiveSettings::averaged`] has computed it (one state per step k < N).
    #[serde(skip)]
    average: Option<std::sync::Arc<Vec<DVector<f64>>>>,
}

/// A closed-loop dive under a blended policy.
#[derive(Debug, Clone)]
pub struct DiveRun {
    /// Final state; `None` when the closed loop diverged.
    pub final_state: Option<DVector<f64>>,
    /// Running cost Σ dt ½uᵀRu of the executed controls.
    pub running: f64,
    /// Mean normalized entropy of α over the dive.
    pub mean_entropy: f64,
    /// Normalized entropy of α at each control step.
    pub entropy: Vec<f64>,
    /// max_i |α_i − ŵ_i| at each control step, ŵ the blend's fixed weights normalized.
    pub alpha_deviation: Vec<f64>,
    /// Largest |u_j| / limit_j over the dive (at most 1: the limits are enforced).
    pub max_torque_fraction: f64,
    /// Executed states (every step), for filmstrips.
    pub states: Vec<DVector<f64>>,
}

impl DiveSettings {
    fn validate(&self) -> Result<(), ParamError> {
        positive("horizon", self.horizon)?;
        positive("dt", self.dt)?;
        ensure(
            self.horizon >= 2.0 * self.dt,
            "horizon",
            "must cover at least two steps",
        )?;
        for (k, v) in [
            ("torso_weight", self.torso_weight),
            ("joint_weight", self.joint_weight),
            ("rate_weight", self.rate_weight),
            ("control_weight", self.control_weight),
            ("torque_noise", self.torque_noise),
        ] {
            positive(k, v)?;
        }
        for (i, l) in self.torque_limits.iter().enumerate() {
            positive(&format!("torque_limits[{i}]"), *l)?;
        }
        ensure(
            self.average_scale.is_finite() && self.average_scale >= 0.0,
            "average_scale",
            "must be finite and >= 0",
        )?;
        ensure(
            self.max_iterations >= 1,
            "max_iterations",
            "must be at least 1",
        )
    }

    /// Checks these settings (keys under `dive.`) and the component dives `omegas` (at least
    /// two), with `index` (spec key `key`) naming one of them.
    fn validate_with(&self, omegas: &[f64], index: usize, key: &str) -> Result<(), ParamError> {
        self.validate()
            .map_err(|e| ParamError::new(format!("dive.{}", e.key), e.message))?;
        ensure(omegas.len() >= 2, "omegas", "need at least two dives")?;
        ensure(index < omegas.len(), key, "must index `omegas`")
    }

    fn steps(&self) -> usize {
        (self.horizon / self.dt).round() as usize
    }

    /// λ = σ² R of the stated joint-torque noise (eq. 8).
    pub fn lambda(&self) -> f64 {
        self.torque_noise * self.torque_noise * self.control_weight
    }

    /// Take-off state: straight body, arms overhead, angular velocity `omega` of every link.
    fn takeoff(&self, omega: f64) -> DVector<f64> {
        let mut x = DVector::zeros(18);
        x[TORSO] = FRAC_PI_2; // torso up
        x[6] = PI; // thighs down
        x[9] = self.takeoff_velocity[0];
        x[10] = self.takeoff_velocity[1];
        x[11] = omega;
        x
    }

    /// Torso angle of the straight, head-down pose after half a turn, rotated by `offset`.
    fn target_torso(offset: f64) -> f64 {
        FRAC_PI_2 + PI + offset
    }

    /// Target: straight, head-down pose after half a turn, rotated by `offset` (rad).
    fn target(&self, offset: f64) -> DVector<f64> {
        let mut x = DVector::zeros(18);
        x[TORSO] = Self::target_torso(offset);
        x[6] = PI;
        x
    }

    fn q_final(&self, torso_weight: f64) -> DMatrix<f64> {
        let mut d = vec![0.0; 18];
        d[TORSO] = torso_weight;
        for v in &mut d[3..9] {
            *v = self.joint_weight;
        }
        for v in &mut d[11..18] {
            *v = self.rate_weight;
        }
        DMatrix::from_diagonal(&DVector::from_vec(d))
    }

    /// The §6.1 running weight Q: the terminal angle weights × `average_scale` / horizon.
    fn average_weight(&self) -> DMatrix<f64> {
        let mut d = vec![0.0; 18];
        d[TORSO] = self.torso_weight;
        for v in &mut d[3..9] {
            *v = self.joint_weight;
        }
        DMatrix::from_diagonal(&DVector::from_vec(d)) * (self.average_scale / self.horizon)
    }

    /// These settings with the §6.1 average trajectory of the dives of `cases` (each optimized
    /// without the term): their mean state at each step. Unchanged when `average_scale` is 0.
    fn averaged(&self, ctx: &RunContext, cases: &[(f64, f64)]) -> Result<DiveSettings, Error> {
        let mut d = self.clone();
        d.average = None;
        if self.average_scale > 0.0 {
            let (sols, _, _) = d.optimize_all(ctx, cases)?;
            d.average = Some(std::sync::Arc::new(mean_trajectory(&sols, self.steps())));
        }
        Ok(d)
    }

    fn cost(&self, offset: f64) -> QuadraticCost {
        QuadraticCost {
            dt: self.dt,
            r: DMatrix::identity(6, 6) * self.control_weight,
            state: self.average.as_ref().map(|a| StateCost {
                weight: self.average_weight(),
                reference: a.to_vec(),
            }),
            q_final: self.q_final(self.torso_weight),
            x_final: self.target(offset),
        }
    }

    /// The terminal terms every component shares (joints and rates; no torso term).
    fn common_cost(&self) -> QuadraticCost {
        let mut c = self.cost(0.0);
        c.q_final = self.q_final(0.0);
        c
    }

    fn map(&self) -> Result<Rk4Map<FiniteDifference<PlanarTree>>, Error> {
        Rk4Map::new(FiniteDifference::new(diver()), self.dt).map_err(other)
    }

    fn options(&self) -> DdpOptions {
        DdpOptions {
            max_iterations: self.max_iterations,
            bounds: Some(ControlBounds {
                lower: -DVector::from_row_slice(&self.torque_limits),
                upper: DVector::from_row_slice(&self.torque_limits),
            }),
            ..DdpOptions::default()
        }
    }

    /// DDP dive from take-off rate `omega` to the target `offset`, and its LQR tracker.
    fn dive(&self, omega: f64, offset: f64) -> Result<(DdpSolution, TrackingController), Error> {
        let map = self.map()?;
        let cost = self.cost(offset);
        let u0 = vec![DVector::zeros(6); self.steps()];
        let sol = solve(&map, &cost, &self.takeoff(omega), &u0, &self.options()).map_err(other)?;
        let tracker = track(&map, &cost, &sol.x, &sol.u).map_err(other)?;
        Ok((sol, tracker))
    }

    /// DDP dives (in parallel) for each `(omega, offset)`, their solutions and LQR trackers,
    /// and the rows of the `dives` table describing them.
    fn optimize_all(
        &self,
        ctx: &RunContext,
        cases: &[(f64, f64)],
    ) -> Result<(Vec<DdpSolution>, Vec<TrackingController>, Vec<DiveRow>), Error> {
        let pb = ctx.progress(cases.len() as u64, "DDP dives");
        let dives: Vec<Result<(DdpSolution, TrackingController), Error>> = ctx.stage("ddp", || {
            cases
                .par_iter()
                .map(|&(omega, offset)| {
                    let r = self.dive(omega, offset);
                    pb.inc(1);
                    r
                })
                .collect()
        });
        pb.finish_and_clear();
        let mut table = Vec::with_capacity(cases.len());
        let (mut sols, mut trackers) = (Vec::new(), Vec::new());
        for (i, (r, &(omega, offset))) in dives.into_iter().zip(cases).enumerate() {
            let (sol, tracker) = r?;
            let xn = Some(sol.x[sol.u.len()].clone());
            table.push(DiveRow {
                dive: i as i64 + 1,
                initial_omega: omega,
                target_offset: offset,
                iterations: sol.trace.len() as i64,
                cost: sol.cost,
                entry_angle: entry(&xn),
                termination: format!("{:?}", sol.termination),
                max_torque_fraction: self.torque_fraction(&sol.u),
            });
            sols.push(sol);
            trackers.push(tracker);
        }
        Ok((sols, trackers, table))
    }

    /// Largest |u_j| / limit_j over a control tape.
    fn torque_fraction(&self, us: &[DVector<f64>]) -> f64 {
        us.iter()
            .flat_map(|u| u.iter().zip(&self.torque_limits).map(|(v, l)| v.abs() / l))
            .fold(0.0, f64::max)
    }

    /// Closed-loop dive from `x0` under a blended policy (torque limits enforced).
    pub fn execute(&self, blend: &TrackerBlend, x0: &DVector<f64>) -> Result<DiveRun, Error> {
        let map = self.map()?;
        let mut ws = map.workspace();
        let cost = self.cost(0.0);
        let (mut x, mut next) = (x0.clone(), x0.clone());
        let (mut u, mut ui, mut alpha) =
            (vec![0.0; 6], vec![0.0; 6], vec![0.0; blend.trackers.len()]);
        let mut uu = DVector::zeros(6);
        let mut run = DiveRun {
            final_state: None,
            running: 0.0,
            mean_entropy: 0.0,
            entropy: Vec::with_capacity(self.steps()),
            alpha_deviation: Vec::with_capacity(self.steps()),
            max_torque_fraction: 0.0,
            states: vec![x0.clone()],
        };
        let steps = self.steps();
        for k in 0..steps {
            if blend
                .control(x.as_slice(), k, &mut u, &mut alpha, &mut ui)
                .is_err()
            {
                run.running = f64::INFINITY;
                return Ok(run);
            }
            uu.copy_from_slice(&u);
            run.running += cost.running(k, &x, &uu);
            let h = normalized_entropy(&alpha);
            run.mean_entropy += h / steps as f64;
            run.entropy.push(h);
            run.alpha_deviation
                .push(alpha_deviation(&alpha, &blend.weights));
            for (v, l) in u.iter().zip(&self.torque_limits) {
                run.max_torque_fraction = run.max_torque_fraction.max(v.abs() / l);
            }
            map.step(&x, &uu, &mut next, &mut ws);
            if next.iter().any(|v| !(v.abs() < 1e4)) {
                run.running = f64::INFINITY;
                return Ok(run);
            }
            std::mem::swap(&mut x, &mut next);
            run.states.push(x.clone());
        }
        run.final_state = Some(x);
        Ok(run)
    }
}

/// The mean of the solutions' states at each step k < `steps` (the §6.1 average trajectory).
fn mean_trajectory(sols: &[DdpSolution], steps: usize) -> Vec<DVector<f64>> {
    let scale = 1.0 / sols.len().max(1) as f64;
    (0..steps)
        .map(|k| sols.iter().map(|s| &s.x[k]).sum::<DVector<f64>>() * scale)
        .collect()
}

/// RMS over the steps k < x̄'s length and the angle coordinates (torso and joints) of
/// `states` minus the average trajectory `average`.
fn angle_deviation(states: &[DVector<f64>], average: &[DVector<f64>]) -> f64 {
    let (mut sum, mut count) = (0.0, 0usize);
    for (x, a) in states.iter().zip(average) {
        for i in TORSO..9 {
            sum += (x[i] - a[i]).powi(2);
            count += 1;
        }
    }
    (sum / count.max(1) as f64).sqrt()
}

/// Entry angle of a final state relative to vertical (rad); NaN when the dive diverged.
fn entry(x: &Option<DVector<f64>>) -> f64 {
    match x {
        Some(x) => entry_angle(&diver(), &x.as_slice()[..9]),
        None => f64::NAN,
    }
}

fn wrap(a: f64) -> f64 {
    (a + PI).rem_euclid(2.0 * PI) - PI
}

/// The reconstructed terminal cost ĝ = −λ log Σ_i w_i exp(−g_i/λ) of components that differ
/// only in their torso targets: ĝ(x) = common(x) + ĝ_torso(θ) with
/// ĝ_torso(θ) = −λ log Σ_i w_i exp(−q (θ − c_i)²/λ).
#[derive(Debug, Clone, PartialEq)]
pub struct ReconstructedCost {
    /// Torso weight q of every component.
    pub q: f64,
    /// Torso targets c_i (rad).
    pub centers: Vec<f64>,
    /// Fixed weights w_i.
    pub weights: Vec<f64>,
    /// Temperature λ.
    pub lambda: f64,
}

impl ReconstructedCost {
    /// ĝ_torso(θ), its first and second derivatives; `None` where Σ w_i h_i ≤ 0.
    pub fn torso(&self, theta: f64) -> Option<(f64, f64, f64)> {
        let n = self.centers.len();
        let (mut g, mut a) = ([0.0f64; 8], [0.0f64; 8]);
        for (gi, c) in g.iter_mut().zip(&self.centers) {
            *gi = self.q * (theta - c).powi(2);
        }
        let v = blend_weights(&self.weights, &g[..n], self.lambda, &mut a[..n]).ok()?;
        let (mut d1, mut s2, mut d2) = (0.0, 0.0, 0.0);
        for i in 0..n {
            let gi = 2.0 * self.q * (theta - self.centers[i]);
            d1 += a[i] * gi;
            s2 += a[i] * gi * gi;
            d2 += a[i] * 2.0 * self.q;
        }
        Some((v, d1, d2 - (s2 - d1 * d1) / self.lambda))
    }

    /// The torso angle where ĝ_torso is smallest, by a fine scan over the span of the centres
    /// widened by a quarter of it.
    pub fn minimum(&self) -> f64 {
        let lo = self.centers.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = self
            .centers
            .iter()
            .copied()
            .fold(f64::NEG_INFINITY, f64::max);
        let pad = 0.25 * (hi - lo).max(1e-3);
        let n = 4000;
        (0..=n)
            .map(|i| lo - pad + (hi - lo + 2.0 * pad) * i as f64 / n as f64)
            .filter_map(|t| self.torso(t).map(|(v, _, _)| (t, v)))
            .fold(
                (f64::NAN, f64::INFINITY),
                |b, (t, v)| if v < b.1 { (t, v) } else { b },
            )
            .0
    }
}

impl DiveSettings {
    /// Objective of a dive with the reconstructed terminal cost: running cost plus the shared
    /// terminal terms plus ĝ_torso of the final torso angle; infinite for a diverged dive.
    fn reconstructed_objective(
        &self,
        rec: &ReconstructedCost,
        running: f64,
        xn: &Option<DVector<f64>>,
    ) -> f64 {
        match xn {
            Some(x) => {
                let g = rec.torso(x[TORSO]).map_or(f64::INFINITY, |t| t.0);
                running + self.common_cost().terminal(x) + g
            }
            None => f64::INFINITY,
        }
    }

    /// A DDP dive optimized directly for the reconstructed terminal cost (the ground truth of
    /// interpolation). ĝ_torso is not quadratic, so each outer iteration replaces it by its
    /// second-order expansion at the current final torso angle (curvature floored at q/5 so
    /// that the model is convex) and re-solves warm-started; at a fixed point the model and ĝ
    /// have the same gradient, so the dive is a stationary point of the true objective.
    /// Returns the solution and the number of outer iterations.
    fn direct(
        &self,
        x0: &DVector<f64>,
        rec: &ReconstructedCost,
        u_init: &[DVector<f64>],
        outer: usize,
    ) -> Result<(DdpSolution, usize), Error> {
        let map = self.map()?;
        let mut cost = self.common_cost();
        let mut us = u_init.to_vec();
        let xs = map.rollout(x0, &us).map_err(other)?;
        let mut theta = xs[us.len()][TORSO];
        let mut best: Option<(DdpSolution, usize)> = None;
        for it in 1..=outer {
            let (_, d1, d2) = rec.torso(theta).ok_or_else(|| {
                Error::Other(format!(
                    "reconstructed reward not positive at torso angle {theta}"
                ))
            })?;
            let curv = d2.max(0.2 * rec.q);
            cost.q_final[(TORSO, TORSO)] = 0.5 * curv;
            cost.x_final[TORSO] = theta - d1 / curv;
            let s = solve(&map, &cost, x0, &us, &self.options()).map_err(other)?;
            let next = s.x[s.u.len()][TORSO];
            let done = (next - theta).abs() < 1e-7;
            theta = next;
            us.clone_from(&s.u);
            best = Some((s, it));
            if done {
                break;
            }
        }
        best.ok_or_else(|| Error::Other("no outer iteration".into()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bellman::combine::BlendMode;
    use crate::experiment::resolve::Validate;

    fn settings() -> DiveSettings {
        DiveSettings {
            horizon: 1.4,
            dt: 0.04,
            takeoff_velocity: [1.0, 4.0],
            torso_weight: 2.0,
            joint_weight: 2.0,
            rate_weight: 0.1,
            control_weight: 1e-3,
            max_iterations: 15,
            torque_limits: [40.0, 140.0, 100.0, 300.0, 300.0, 200.0],
            torque_noise: 10.0,
            average_scale: 0.0,
            average: None,
        }
    }

    #[test]
    fn the_average_term_pulls_the_component_dives_toward_their_average() {
        // §6.1: with the running penalty on deviation from the components' average
        // trajectory, each re-optimized component dive stays closer to that average.
        let ctx = RunContext::new(1, true, false);
        let cases = [(1.0, -0.6), (1.0, 0.6)];
        let mut d = settings();
        d.average_scale = 4.0;
        let (plain, _, _) = d.optimize_all(&ctx, &cases).unwrap();
        let averaged = d.averaged(&ctx, &cases).unwrap();
        let x_bar = averaged.average.clone().expect("the scale is on");
        assert_eq!(x_bar.len(), d.steps());
        assert_eq!(*x_bar, mean_trajectory(&plain, d.steps()));
        let (pulled, _, _) = averaged.optimize_all(&ctx, &cases).unwrap();
        for (a, b) in plain.iter().zip(&pulled) {
            let (before, after) = (angle_deviation(&a.x, &x_bar), angle_deviation(&b.x, &x_bar));
            assert!(after < 0.9 * before, "{before} -> {after}");
        }
        // Off by default: no average, the cost without a state term.
        let off = settings().averaged(&ctx, &cases).unwrap();
        assert!(off.average.is_none() && off.cost(0.0).state.is_none());
    }

    #[test]
    fn closed_loops_respect_the_torque_limits() {
        let mut d = settings();
        let (s1, t1) = d.dive(0.85, 0.0).unwrap();
        let (s2, t2) = d.dive(1.15, 0.0).unwrap();
        // DDP honours the box constraint.
        for s in [&s1, &s2] {
            assert!(d.torque_fraction(&s.u) <= 1.0 + 1e-12);
        }
        // Tight limits on the closed loops, from take-off rates far from the components.
        d.torque_limits = [5.0; 6];
        let trackers = [t1, t2];
        let mut binds = 0;
        for w in [0.4, 1.6] {
            for mode in [BlendMode::Lbc, BlendMode::Naive, BlendMode::Single(0)] {
                let blend = TrackerBlend {
                    trackers: &trackers,
                    weights: vec![1.0, 1.0],
                    lambda: d.lambda(),
                    limits: Some(&d.torque_limits),
                    mode,
                };
                let r = d.execute(&blend, &d.takeoff(w)).unwrap();
                assert!(
                    r.max_torque_fraction <= 1.0,
                    "{mode:?} at {w}: {}",
                    r.max_torque_fraction
                );
                binds += (r.max_torque_fraction == 1.0) as usize;
            }
        }
        assert!(binds > 0, "the limit never binds");
    }

    #[test]
    fn reconstructed_cost_derivatives_match_differences() {
        let rec = ReconstructedCost {
            q: 0.7,
            centers: vec![-0.6, 0.6],
            weights: vec![0.8, 0.45],
            lambda: 0.9,
        };
        for theta in [-0.9, -0.2, 0.0, 0.35, 1.1] {
            let (v, d1, d2) = rec.torso(theta).unwrap();
            let h = 1e-5;
            let (vp, d1p, _) = rec.torso(theta + h).unwrap();
            let (vm, d1m, _) = rec.torso(theta - h).unwrap();
            assert!(((vp - vm) / (2.0 * h) - d1).abs() < 1e-7, "{theta}");
            assert!(((d1p - d1m) / (2.0 * h) - d2).abs() < 1e-6, "{theta}");
            // −λ log Σ w exp(−g/λ), directly.
            let direct = -rec.lambda
                * (0..2)
                    .map(|i| {
                        rec.weights[i]
                            * (-rec.q * (theta - rec.centers[i]).powi(2) / rec.lambda).exp()
                    })
                    .sum::<f64>()
                    .ln();
            assert!((v - direct).abs() < 1e-12);
        }
        // Equal weights: the minimum lies midway.
        let sym = ReconstructedCost {
            weights: vec![1.0, 1.0],
            ..rec
        };
        assert!(sym.minimum().abs() < 1e-3, "{}", sym.minimum());
    }

    #[test]
    fn objectives_compare_with_a_tolerance() {
        assert_eq!(compare_objectives(1.0, 1.0001, 0.02), "tie");
        assert_eq!(compare_objectives(1.0, 1.05, 0.02), "better");
        assert_eq!(compare_objectives(1.05, 1.0, 0.02), "worse");
        assert_eq!(compare_objectives(1.0, f64::INFINITY, 0.02), "better");
        assert_eq!(
            compare_objectives(f64::INFINITY, f64::INFINITY, 0.02),
            "tie"
        );
    }

    #[test]
    fn lambda_comes_from_the_noise_model_and_validation_names_the_key() {
        let mut d = settings();
        assert!((d.lambda() - 100.0 * 1e-3).abs() < 1e-12);
        d.torque_limits[3] = 0.0;
        let e = d.validate().unwrap_err();
        assert_eq!(e.key, "torque_limits[3]");
        let p = InterpolationParams {
            dive: settings(),
            omega: 1.0,
            offset: 0.6,
            offsets: vec![],
            scale_torso_weight: false,
            desired: vec![-0.3, 0.0, 0.6],
            direct_outer_iterations: 5,
            entry_tolerance: 0.05,
            objective_tolerance: 0.02,
            lambda_sweep: vec![],
            average_scales: vec![],
        };
        let e = p.validate().unwrap_err();
        assert_eq!(e.key, "desired[2]");
        // LBC §4.1's scale ∝ 1/spacing²: with the rule on, the torso weight at twice the
        // first offset is a quarter of the given one; off, it stays.
        let search = InterpolationParams {
            offsets: vec![0.6, 1.2],
            offset: 0.0,
            ..p.clone()
        };
        let w = search.dive.torso_weight;
        assert_eq!(search.at(1.2).dive.torso_weight, w);
        let scaled = InterpolationParams {
            scale_torso_weight: true,
            ..search
        };
        assert!((scaled.at(1.2).dive.torso_weight - w / 4.0).abs() < 1e-15);
        assert_eq!(scaled.at(0.6).dive.torso_weight, w);
        let p = InterpolationParams {
            desired: vec![0.0],
            average_scales: vec![0.1, 0.0],
            ..p
        };
        assert_eq!(p.validate().unwrap_err().key, "average_scales[1]");
        // The offset search: ascending, distinct, positive, finite; `offset` left out with it;
        // desired angles inside the smallest offset.
        let p = InterpolationParams {
            average_scales: vec![],
            desired: vec![-0.3, 0.0, 0.3],
            ..p
        };
        assert!(p.validate().is_ok());
        let with = |offset: f64, offsets: Vec<f64>| InterpolationParams {
            offset,
            offsets,
            ..p.clone()
        };
        assert!(with(0.0, vec![0.6, 0.8, 1.5]).validate().is_ok());
        assert_eq!(
            with(0.6, vec![0.6, 0.8]).validate().unwrap_err().key,
            "offset"
        );
        assert_eq!(with(0.0, vec![]).validate().unwrap_err().key, "offset");
        for bad in [
            vec![0.6, 0.6],
            vec![0.8, 0.6],
            vec![0.6, f64::NAN],
            vec![0.6, f64::INFINITY],
        ] {
            assert_eq!(with(0.0, bad).validate().unwrap_err().key, "offsets[1]");
        }
        assert_eq!(
            with(0.0, vec![-0.6]).validate().unwrap_err().key,
            "offsets[0]"
        );
        assert_eq!(
            with(0.0, vec![0.3, 0.6]).validate().unwrap_err().key,
            "desired[0]"
        );
        // An old spec (no `offsets`) still parses.
        let json = serde_json::to_value(&p).unwrap();
        let mut obj = json.as_object().unwrap().clone();
        obj.remove("offsets");
        let back: InterpolationParams = serde_json::from_value(obj.into()).unwrap();
        assert!(back.offsets.is_empty() && back.offset == 0.6);
    }

    #[test]
    fn the_offset_search_takes_the_smallest_offset_whose_naive_blend_misses() {
        let t = |offset: f64, naive: f64| OffsetTrial {
            offset,
            average_scale: 0.0,
            torso_weight: 0.625,
            under_entry: -offset,
            over_entry: offset,
            naive_entry: naive,
            lbc_entry: 0.0,
        };
        let tol = 0.05;
        // Naive vertical at 0.6 and 0.8, off by more than tol from 1.0 on: 1.0.
        let trials = [t(0.6, 0.01), t(0.8, -0.05), t(1.0, 0.07), t(1.2, -0.2)];
        assert_eq!(choose_offset(&trials, tol), Some(2));
        // Order of the list does not matter: the smallest offset wins.
        let shuffled = [t(1.2, -0.2), t(1.0, 0.07), t(0.6, 0.01)];
        assert_eq!(choose_offset(&shuffled, tol), Some(1));
        // A diverged naive dive misses.
        assert_eq!(choose_offset(&[t(0.6, f64::NAN)], tol), Some(0));
        // None misses: premise not reproduced.
        assert_eq!(choose_offset(&[t(0.6, 0.0), t(1.5, 0.05)], tol), None);
        assert_eq!(choose_offset(&[], tol), None);
        // Components that do not straddle vertical by more than tol: no premise.
        let mut c = t(0.8, 0.3);
        c.under_entry = -0.04;
        assert!(!c.premise_holds(tol));
        assert_eq!(choose_offset(&[c], tol), None);
    }
}
