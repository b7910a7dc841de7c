//! The job: the DDP reaches and their trackers, the closed loops of the walled scene under the
//! tugs (scripted, mirrored, none; with and without a reach) and the λ sweep, as tables.

use super::measures::{largest_lean, mirror_gap, swings, window_gap, window_range};
use super::{choose_reach_scale, Params, COMMITTED};
use crate::bellman::combine::{normalized_entropy, BlendMode, TrackerBlend};
use crate::control::ddp::{solve, ControlBounds, DdpOptions, Termination};
use crate::control::lqr::{track, TrackingController};
use crate::control::{QuadraticCost, Rk4Map, StateCost};
use crate::experiment::output::Tables;
use crate::experiment::rows::table_of;
use crate::experiment::{other, Error, Job, RunContext};
use crate::families::lbc::{alpha_deviation, entropy_rows, rule_table};
use crate::physics::integrate::Integrator;
use crate::physics::linearize::FiniteDifference;
use crate::physics::push::{push_figure, PushScene};
use crate::physics::IntegratorKind;
use nalgebra::{DMatrix, DVector};
use std::f64::consts::{FRAC_PI_2, PI};

crate::result_rows! {
    /// One row of `weights.csv`: one control step of the closed loops (LBC under the tugs as
    /// scripted, mirrored and none; the premise's run without a reach). Angles in rad, the
    /// body's from the floor (π/2 upright), the arm's absolute.
    pub struct WeightRow {
        /// Time (s).
        t_s: f64 = "t",
        /// LBC's weight of the forward reach under the scripted tugs.
        alpha_forward: f64 = "alpha_forward",
        /// Its weight of the backward reach there.
        alpha_backward: f64 = "alpha_backward",
        /// The scripted tug force on the hand (N, + pulls forward).
        force_x_n: f64 = "force_x",
        /// Body angle under the scripted tugs.
        body_angle_rad: f64 = "body_angle",
        /// Absolute arm angle under the scripted tugs.
        arm_angle_rad: f64 = "arm_angle",
        /// Hand x under the scripted tugs (m, + forward).
        hand_x_m: f64 = "hand_x",
        /// The forward weight under the mirrored tugs.
        alpha_forward_mirrored: f64 = "alpha_forward_mirrored",
        /// The forward weight without tugs.
        alpha_forward_baseline: f64 = "alpha_forward_baseline",
        /// Body angle under the mirrored tugs.
        body_angle_mirrored_rad: f64 = "body_angle_mirrored",
        /// The walls' force on the hand under the scripted tugs (N).
        wall_force_n: f64 = "wall_force",
        /// Body angle without a reach (arm held), under the scripted tugs.
        body_angle_no_reach_rad: f64 = "body_angle_no_reach",
    }
}

crate::result_rows! {
    /// One row of `reaches.csv`: one optimized reach (DDP).
    pub struct ReachRow {
        /// `forward` or `backward`.
        reach: String = "reach",
        /// DDP iterations.
        iterations: i64 = "iterations",
        /// DDP's cost.
        cost: f64 = "cost",
        /// Distance of the final state from the hold pose (state-space norm).
        final_error: f64 = "final_error",
        /// Why DDP stopped.
        termination: String = "termination",
        /// DDP's final gradient norm.
        gradient_norm: f64 = "gradient_norm",
    }
}

crate::result_rows! {
    /// One row of `reach_scales.csv`: one scale of the reaches' state weights tried.
    pub struct ReachScaleRow {
        /// The scale.
        reach_scale: f64 = "reach_scale",
        /// Either reach's largest weight under LBC, first tug alone, before the second tug
        /// (NaN: a reach that did not converge at this scale).
        max_weight_before_second_tug: f64 = "max_weight_before_second_tug",
        /// 1 when that weight is not below the commitment threshold, else 0.
        committed: i64 = "committed",
        /// 1 for the scale the run uses, else 0.
        chosen: i64 = "chosen",
    }
}

crate::result_rows! {
    /// One row of `lambda_sweep.csv`: the verdict's measures at one temperature (not judged).
    pub struct LambdaRow {
        /// The temperature λ.
        lambda: f64 = "lambda",
        /// Side-to-side swings of the forward weight before the settling window.
        swings: i64 = "swings",
        /// Largest gap of the tugged forward weight to the no-tug baseline's over the window.
        settle_gap: f64 = "settle_gap",
        /// Largest |α_forward(tugs) − α_backward(mirrored tugs)|.
        mirror_gap: f64 = "mirror_gap",
        /// Mean normalized entropy of α under the tugs.
        mean_entropy: f64 = "mean_entropy",
        /// Largest lean from upright (rad), scripted and mirrored tugs.
        max_lean_rad: f64 = "max_lean",
        /// Range of the tugged forward weight over the window.
        settle_range: f64 = "settle_range",
    }
}

impl Params {
    /// These parameters with the reaches' state weights (terminal and hold) × `scale`, and no
    /// scale search.
    pub(super) fn scaled(&self, scale: f64) -> Params {
        let mut p = self.clone();
        p.reach_scales.clear();
        for w in &mut p.terminal_weights {
            *w *= scale;
        }
        if let Some(h) = &mut p.hold_weights {
            for w in h.iter_mut() {
                *w *= scale;
            }
        }
        p
    }

    /// The reach-scale search: per scale tried (`reach_scales`, or 1 alone), the largest
    /// weight of either reach under LBC with the first tug alone before the second tug starts;
    /// the index the rule picks.
    fn reach_scale_trials(&self) -> Result<(Vec<(f64, f64)>, Option<usize>), Error> {
        let scales = if self.reach_scales.is_empty() {
            vec![1.0]
        } else {
            self.reach_scales.clone()
        };
        let mut tugs = self.tugs.clone();
        tugs.sort_by(|a, b| a.start.total_cmp(&b.start));
        let next = tugs.get(1).map_or(self.horizon, |g| g.start);
        let mut trials = Vec::new();
        for s in scales {
            let mut q = self.scaled(s);
            q.tugs = tugs[..tugs.len().min(1)].to_vec();
            // A reach that does not converge at this scale cannot be used: committed (NaN).
            let w = match q.reaches() {
                Ok((trackers, _)) => q
                    .closed_loop(&trackers, 1.0, q.lambda())?
                    .iter()
                    .enumerate()
                    .filter(|(k, _)| (*k as f64 * q.dt) < next)
                    .map(|(_, r)| r[0].max(r[1]))
                    .fold(0.0, f64::max),
                Err(_) => f64::NAN,
            };
            trials.push((s, w));
        }
        let pick = choose_reach_scale(&trials, COMMITTED);
        Ok((trials, pick))
    }

    pub(super) fn steps(&self) -> usize {
        (self.horizon / self.dt).round() as usize
    }

    /// Upright body, arm hanging.
    pub(super) fn start(&self) -> DVector<f64> {
        DVector::from_vec(vec![FRAC_PI_2, -PI, 0.0, 0.0, 0.0, 0.0])
    }

    /// The hold pose in front (`forward`) or behind, in unwrapped joint angles from the start.
    fn target(&self, forward: bool) -> DVector<f64> {
        let (body, arm_abs) = if forward {
            (FRAC_PI_2 - self.lean, 0.0)
        } else {
            (FRAC_PI_2 + self.lean, -PI)
        };
        DVector::from_vec(vec![body, arm_abs - body, 0.0, 0.0, 0.0, 0.0])
    }

    pub(super) fn cost(&self, forward: bool) -> QuadraticCost {
        QuadraticCost {
            dt: self.dt,
            r: DMatrix::identity(3, 3) * self.control_weight,
            state: self.hold_weights.map(|w| StateCost {
                weight: DMatrix::from_diagonal(&DVector::from_row_slice(&w)),
                reference: vec![self.target(forward)],
            }),
            q_final: DMatrix::from_diagonal(&DVector::from_row_slice(&self.terminal_weights)),
            x_final: self.target(forward),
        }
    }

    /// λ = σ² R of the stated motor noise (R = `control_weight` I).
    pub fn lambda(&self) -> f64 {
        self.torque_noise * self.torque_noise * self.control_weight
    }

    fn options(&self) -> DdpOptions {
        let l = DVector::from_row_slice(&self.torque_limits);
        DdpOptions {
            max_iterations: self.max_iterations,
            bounds: Some(ControlBounds {
                lower: -l.clone(),
                upper: l,
            }),
            ..DdpOptions::default()
        }
    }

    /// The forward and backward reaches (DDP, then LQR), with their table rows.
    pub(super) fn reaches(&self) -> Result<(Vec<TrackingController>, Vec<ReachRow>), Error> {
        let mut torque_only = push_figure();
        torque_only.forces.clear();
        let map = Rk4Map::new(FiniteDifference::new(torque_only), self.dt).map_err(other)?;
        let x0 = self.start();
        let mut reaches = Vec::new();
        let mut trackers = Vec::new();
        for (name, fwd) in [("forward", true), ("backward", false)] {
            let cost = self.cost(fwd);
            let u0 = vec![DVector::zeros(3); self.steps()];
            let sol = solve(&map, &cost, &x0, &u0, &self.options()).map_err(other)?;
            if sol.termination == Termination::MaxIterations
                || sol.termination == Termination::RegularizationLimit
            {
                return Err(other(format!(
                    "the {name} reach did not converge ({:?} after {} iterations, gradient {:e}): raise max_iterations",
                    sol.termination,
                    sol.trace.len(),
                    sol.gradient_norm
                )));
            }
            let err = (&sol.x[sol.u.len()] - &cost.x_final).norm();
            reaches.push(ReachRow {
                reach: name.to_string(),
                iterations: sol.trace.len() as i64,
                cost: sol.cost,
                final_error: err,
                termination: format!("{:?}", sol.termination),
                gradient_norm: sol.gradient_norm,
            });
            trackers.push(track(&map, &cost, &sol.x, &sol.u).map_err(other)?);
        }
        Ok((trackers, reaches))
    }

    /// The closed loop at temperature `lambda` under the tugs scaled by `sign` (1: as scripted,
    /// −1: mirrored, 0: none): per step (α_forward, α_backward, force, body angle, absolute
    /// arm angle, hand x, wall force).
    pub(super) fn closed_loop(
        &self,
        trackers: &[TrackingController],
        sign: f64,
        lambda: f64,
    ) -> Result<Vec<[f64; 7]>, Error> {
        let blend = TrackerBlend {
            trackers,
            weights: vec![1.0, 1.0],
            lambda,
            limits: Some(&self.torque_limits),
            mode: BlendMode::Lbc,
        };
        let mut ui = [0.0; 3];
        self.rollout(sign, |x, k, u, alpha| {
            blend.control(x, k, u, alpha, &mut ui).map_err(other)
        })
    }

    /// The premise's test: the same tugs with no reach. The arm is held at its start pose and
    /// the ankle pushes the body back to upright (stiff PD, both torque-limited, gains ours:
    /// the ankle saturates at 0.05 rad of lean, well inside the 0.11 rad it can hold against
    /// gravity). Returns the body angle per step.
    pub(super) fn no_reach(&self, sign: f64) -> Result<Vec<f64>, Error> {
        let x0 = self.start();
        let (kp_ankle, kd_ankle) = (
            self.torque_limits[0] / 0.05,
            0.2 * self.torque_limits[0] / 0.05,
        );
        let (kp_arm, kd_arm) = (300.0, 30.0);
        let run = self.rollout(sign, |x, _, u, alpha| {
            u[0] = -kp_ankle * (x[0] - x0[0]) - kd_ankle * x[3];
            u[1] = -kp_arm * (x[1] - x0[1]) - kd_arm * x[4];
            u[2] = -kp_arm * (x[2] - x0[2]) - kd_arm * x[5];
            for (v, l) in u.iter_mut().zip(&self.torque_limits) {
                *v = v.clamp(-l, *l);
            }
            alpha.fill(f64::NAN);
            Ok(())
        })?;
        Ok(run.iter().map(|v| v[3]).collect())
    }

    /// Largest lean from upright (rad) of the premise's runs, as scripted and mirrored.
    pub fn no_reach_lean(&self) -> Result<f64, Error> {
        Ok(largest_lean(&[self.no_reach(1.0)?, self.no_reach(-1.0)?]))
    }

    /// Simulates the figure between the walls under the tugs scaled by `sign` with
    /// `policy(x, k, u, alpha)` writing the three motor torques (and the blend weights, if any)
    /// once per control step; a body that leans a right angle has hit the floor and stays
    /// there (the model has no floor contact of its own). Per step: (α_forward, α_backward,
    /// tug force, body angle, absolute arm angle, hand x, wall force on the hand).
    pub(super) fn rollout(
        &self,
        sign: f64,
        mut policy: impl FnMut(&[f64], usize, &mut [f64], &mut [f64]) -> Result<(), Error>,
    ) -> Result<Vec<[f64; 7]>, Error> {
        let scene = PushScene::new(self.walls);
        let mut rk4 = Integrator::new(IntegratorKind::Rk4, 6);
        let h = self.dt / self.substeps as f64;
        let mut x = [0.0; 6];
        x.copy_from_slice(self.start().as_slice());
        let (mut u, mut alpha) = ([0.0; 3], [0.0; 2]);
        let mut full_u = [0.0; 5];
        let mut out = Vec::with_capacity(self.steps());
        for k in 0..self.steps() {
            let t = k as f64 * self.dt;
            policy(&x, k, &mut u, &mut alpha)?;
            let f = sign * self.force_at(t);
            full_u[..3].copy_from_slice(&u);
            full_u[3] = f;
            let (hand, v) = scene.hand(&x);
            out.push([
                alpha[0],
                alpha[1],
                f,
                x[0],
                x[0] + x[1],
                hand[0],
                self.walls.force(hand[0], v[0]),
            ]);
            // A body that has fallen to the floor (lean of a right angle) lies there.
            if (x[0] - FRAC_PI_2).abs() < FRAC_PI_2 {
                for _ in 0..self.substeps {
                    rk4.step(&scene, &mut x, &full_u, h);
                }
                if (x[0] - FRAC_PI_2).abs() >= FRAC_PI_2 {
                    x[0] = if x[0] < FRAC_PI_2 { 0.0 } else { PI };
                    x[3..].fill(0.0);
                }
            }
            crate::physics::check_finite("push_recovery", k, t + self.dt, &x)?;
        }
        Ok(out)
    }

    fn force_at(&self, t: f64) -> f64 {
        self.tugs
            .iter()
            .filter(|g| t >= g.start && t < g.start + g.duration)
            .map(|g| g.force)
            .sum()
    }
}

impl Job for Params {
    fn params_json(&self) -> serde_json::Value {
        serde_json::to_value(self).unwrap_or_default()
    }

    fn run(&self, ctx: &RunContext) -> Result<Tables, Error> {
        // The reach scale: the first whose weights, with the first tug alone, have
        // not committed before the second tug; every table below uses it.
        let (trials, pick) = ctx.stage("reach scales", || self.reach_scale_trials())?;
        let scale = trials[pick.unwrap_or(0)].0;
        let scales_t: Vec<ReachScaleRow> = trials
            .iter()
            .enumerate()
            .map(|(i, &(s, w))| ReachScaleRow {
                reach_scale: s,
                max_weight_before_second_tug: w,
                committed: !(w < COMMITTED) as i64,
                chosen: (pick == Some(i)) as i64,
            })
            .collect();
        let scaled = self.scaled(scale);
        scaled.judge(ctx, scales_t, scale, pick.is_some())
    }
}

impl Params {
    /// Everything the run judges, with these parameters' reaches; `scales_t` the reach-scale
    /// search's table, `scale` the scale chosen, `found` whether the rule found one.
    fn judge(
        &self,
        ctx: &RunContext,
        scales_t: Vec<ReachScaleRow>,
        scale: f64,
        found: bool,
    ) -> Result<Tables, Error> {
        let (trackers, reaches) = ctx.stage("ddp + lqr", || self.reaches())?;
        let (tugged, mirrored, baseline) = ctx.stage("tugs", || -> Result<_, Error> {
            Ok((
                self.closed_loop(&trackers, 1.0, self.lambda())?,
                self.closed_loop(&trackers, -1.0, self.lambda())?,
                self.closed_loop(&trackers, 0.0, self.lambda())?,
            ))
        })?;
        // α's entropy over time of the three LBC runs (w = (1, 1): ŵ = (1/2, 1/2)).
        let mut entropy_t = Vec::new();
        for (run, r) in [
            ("tugged", &tugged),
            ("mirrored", &mirrored),
            ("no tugs", &baseline),
        ] {
            let h: Vec<f64> = r.iter().map(|v| normalized_entropy(&v[..2])).collect();
            let d: Vec<f64> = r
                .iter()
                .map(|v| alpha_deviation(&v[..2], &[1.0, 1.0]))
                .collect();
            entropy_t.extend(entropy_rows(run, "lbc", self.dt, &h, &d));
        }
        let mut table = Vec::new();
        // The premise's runs (no reach), as scripted and mirrored.
        let no_reach = ctx.stage("no reach", || -> Result<_, Error> {
            Ok([self.no_reach(1.0)?, self.no_reach(-1.0)?])
        })?;
        for (k, ((a, m), b)) in tugged.iter().zip(&mirrored).zip(&baseline).enumerate() {
            table.push(WeightRow {
                t_s: k as f64 * self.dt,
                alpha_forward: a[0],
                alpha_backward: a[1],
                force_x_n: a[2],
                body_angle_rad: a[3],
                arm_angle_rad: a[4],
                hand_x_m: a[5],
                alpha_forward_mirrored: m[0],
                alpha_forward_baseline: b[0],
                body_angle_mirrored_rad: m[3],
                wall_force_n: a[6],
                body_angle_no_reach_rad: no_reach[0][k],
            });
        }
        // The same checks at each swept λ (not judged).
        let mut lam = Vec::new();
        ctx.stage("lambda sweep", || -> Result<(), Error> {
            for &l in &self.lambda_sweep {
                let runs = [1.0, -1.0, 0.0]
                    .map(|sign| self.closed_loop(&trackers, sign, l))
                    .into_iter()
                    .collect::<Result<Vec<_>, _>>()?;
                let col = |r: &[[f64; 7]], i: usize| r.iter().map(|v| v[i]).collect::<Vec<f64>>();
                let t: Vec<f64> = (0..runs[0].len()).map(|k| k as f64 * self.dt).collect();
                let a = col(&runs[0], 0);
                let h = runs[0]
                    .iter()
                    .map(|v| normalized_entropy(&v[..2]))
                    .sum::<f64>()
                    / runs[0].len().max(1) as f64;
                let lean = runs[..2]
                    .iter()
                    .flat_map(|r| r.iter().map(|v| (v[3] - FRAC_PI_2).abs()))
                    .fold(0.0, f64::max);
                lam.push(LambdaRow {
                    lambda: l,
                    swings: swings(&t, &a, self.settle_window[0]) as i64,
                    settle_gap: window_gap(&t, &a, &col(&runs[2], 0), self.settle_window),
                    mirror_gap: mirror_gap(&a, &col(&runs[1], 0)),
                    mean_entropy: h,
                    max_lean_rad: lean,
                    settle_range: window_range(&t, &a, self.settle_window),
                });
            }
            Ok(())
        })?;
        let rule = rule_table(&[
            ("lambda", self.lambda()),
            ("torque_noise", self.torque_noise),
            ("min_swings", self.min_swings as f64),
            ("settle_start", self.settle_window[0]),
            ("settle_end", self.settle_window[1]),
            ("settle_tolerance", self.settle_tolerance),
            ("mirror_tolerance", self.mirror_tolerance),
            ("fall_angle", self.fall_angle),
            ("horizon", self.horizon),
            ("no_reach_lean", largest_lean(&no_reach)),
            ("walls_distance", self.walls.distance),
            ("rest_rate", self.rest_rate),
            ("reach_scale", scale),
            ("reach_premise_found", found as u8 as f64),
        ]);
        Ok(Tables::from([
            ("weights", table_of(&table)),
            ("reaches", table_of(&reaches)),
            ("lambda_sweep", table_of(&lam)),
            ("reach_scales", table_of(&scales_t)),
            ("entropy", table_of(&entropy_t)),
            ("rule", rule),
        ]))
    }
}
