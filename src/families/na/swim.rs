//! The dolphin swim task of NeuroAnimator §6 / Fig. 13(d), shared by `na_fig13_control` and
//! `na_baselines_swim`.
//!
//! The dolphin starts at rest in its rest shape at the origin, heading +x. Controls are the six
//! muscle activations in [−1, 1], piecewise constant with `knots` values per muscle over
//! `horizon` emulator steps (the paper: one value per 2 emulator steps per muscle). As in §6,
//! controllers are learned through the hierarchy's **global net** alone (the local deformation
//! "does not significantly impact the locomotion"): its state is the 6 segment frames
//! ([`crate::emulator::hierarchy::global_state`]). The objective is
//!
//! ```text
//! J(u) = μ_u/2 Σ_i |u_i|² − μ_d x̂ · (c̄_M − c̄_0)
//! ```
//!
//! actuator effort minus the distance swum forward by the mean of the six segment centroids
//! ([`Progress`]). The same J is evaluated on the physical simulator by mapping its mass states
//! to segment frames at the emulator step times ([`SwimTask::simulate`]).
//!
//! The **reference swim** is a hand-made travelling wave, u_s(t) = sin(2π t − s·30°) sampled at
//! the knots (1 Hz, a 30° lag per segment from head to tail, the wave the dolphin model is
//! documented with); a task's "final error" is how far (m) a controller falls short of the
//! distance the reference swims on the simulator.

use crate::control::bptt::{Bounds, Knots};
use crate::control::objective::{ControlEffort, Objective, Progress};
use crate::emulator::hierarchy::{self, global_state, Regularizer, FRAME_DIM, GLOBAL_DIM};
use crate::experiment::resolve::{ensure, positive, ParamError};
use crate::experiment::{other, Error};
use crate::physics::dolphin::{Dolphin, N_SEGMENTS};
use crate::physics::{check_finite, BlowUp, Dynamics};
use serde::{Deserialize, Serialize};
use std::f64::consts::TAU;

/// The swim task's parameters (everything but the nets).
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SwimTask {
    /// Emulator steps M.
    pub horizon: usize,
    /// Knots per muscle K.
    pub knots: usize,
    /// Weight μ_d of the forward distance (per metre).
    pub distance_mu: f64,
    /// Weight μ_u of the effort.
    pub effort_mu: f64,
    /// Regularization of the full hierarchical emulator when its motion is replayed for
    /// pictures (not used for learning).
    pub regularization: Regularizer,
    /// Regularization steps after each emulation step in that replay.
    pub regularization_steps: usize,
}

impl SwimTask {
    /// Checks the parameters; `key` prefixes the keys in messages.
    pub fn validate(&self, key: &str) -> Result<(), ParamError> {
        ensure(self.horizon >= 1, &format!("{key}.horizon"), "must be >= 1")?;
        ensure(
            self.knots >= 1 && self.knots <= self.horizon,
            &format!("{key}.knots"),
            "must be in [1, horizon]",
        )?;
        positive(&format!("{key}.distance_mu"), self.distance_mu)?;
        ensure(
            self.effort_mu >= 0.0 && self.effort_mu.is_finite(),
            &format!("{key}.effort_mu"),
            "must be >= 0",
        )?;
        super::table2_speedup::validate_regularizer(
            &format!("{key}.regularization"),
            &self.regularization,
        )
    }

    /// The objective over global states (see the module docs).
    pub fn objective(&self) -> Objective {
        Objective::default()
            .with(ControlEffort::plain(self.effort_mu, N_SEGMENTS))
            .with(Progress {
                mu: self.distance_mu,
                direction: [1.0, 0.0, 0.0],
                points: (0..N_SEGMENTS).map(|s| FRAME_DIM * s).collect(),
            })
    }

    /// The knot layout.
    pub fn knot_layout(&self) -> Knots {
        Knots {
            steps: self.horizon,
            per_actuator: self.knots,
            m: N_SEGMENTS,
        }
    }

    /// Muscle bounds [−1, 1].
    pub fn bounds(&self) -> Bounds {
        let l = hierarchy::control_limits();
        Bounds::new(l.low, l.high)
    }

    /// The start: the rest shape at rest, heading +x (mass state and global state).
    pub fn start(&self, d: &Dolphin) -> (Vec<f64>, Vec<f64>) {
        let x0 = d.rest_state();
        let mut g0 = vec![0.0; GLOBAL_DIM];
        global_state(d, &x0, &mut g0);
        (x0, g0)
    }

    /// Knot values of the reference travelling wave (module docs), K m.
    pub fn reference_knots(&self, super_dt: f64) -> Vec<f64> {
        let m = N_SEGMENTS;
        let layout = self.knot_layout();
        let mut v = vec![0.0; layout.len()];
        for k in 0..self.knots {
            // The knot's first step time.
            let i = (0..self.horizon)
                .find(|&i| layout.knot_of(i) == k)
                .unwrap_or(0);
            let t = i as f64 * super_dt;
            for s in 0..m {
                v[k * m + s] = crate::portable::sin(TAU * t - (30f64).to_radians() * s as f64);
            }
        }
        v
    }

    /// Runs the physical simulator from `x0` under per-step `controls` (M m), each held for
    /// `substeps` steps of `dt`; returns the mass states and the global states at the emulator
    /// step times (M + 1 each).
    pub fn simulate(
        &self,
        d: &Dolphin,
        x0: &[f64],
        controls: &[f64],
        dt: f64,
        substeps: usize,
    ) -> Result<(Vec<Vec<f64>>, Vec<f64>), BlowUp> {
        let mut sim = hierarchy::simulator(d);
        let mut x = x0.to_vec();
        let mut masses = vec![x.clone()];
        let mut g = vec![0.0; GLOBAL_DIM];
        global_state(d, &x, &mut g);
        let mut globals = g.clone();
        for (i, u) in controls.chunks_exact(N_SEGMENTS).enumerate() {
            for _ in 0..substeps {
                sim.step(&mut x, u, dt);
            }
            check_finite(
                "dolphin",
                (i + 1) * substeps,
                (i + 1) as f64 * substeps as f64 * dt,
                &x,
            )?;
            global_state(d, &x, &mut g);
            globals.extend_from_slice(&g);
            masses.push(x.clone());
        }
        Ok((masses, globals))
    }

    /// Forward distance (m) of the mean segment centroid between the first and last of
    /// `globals` (M + 1 global states).
    pub fn distance(&self, globals: &[f64]) -> f64 {
        let mean_x =
            |g: &[f64]| (0..N_SEGMENTS).map(|s| g[FRAME_DIM * s]).sum::<f64>() / N_SEGMENTS as f64;
        mean_x(&globals[globals.len() - GLOBAL_DIM..]) - mean_x(&globals[..GLOBAL_DIM])
    }
}

/// Replays per-step `controls` through the full hierarchical emulator (global and local nets,
/// with `reg_steps` regularization steps after each emulation step) for pictures of the
/// emulated body; returns the mass states (M + 1).
pub fn emulated_masses(
    emu: &hierarchy::DolphinEmulator,
    reg: &Regularizer,
    reg_steps: usize,
    x0: &[f64],
    controls: &[f64],
) -> Result<Vec<Vec<f64>>, Error> {
    let mut r = reg.bind(emu.dolphin()).map_err(other)?;
    let schedule = hierarchy::Schedule {
        steps: reg_steps,
        every: 1,
    };
    let mut out = vec![x0.to_vec()];
    emu.emulate(
        &mut r,
        schedule,
        x0,
        controls,
        &mut emu.scratch(),
        |_, x| out.push(x.to_vec()),
    );
    Ok(out)
}

/// How periodic per-step controls `u` (m actuators, row after row) are: per actuator the
/// largest autocorrelation of its demeaned sequence at lags 3 … N/2 steps (each lag's mean
/// product over the variance; a sinusoid with a period in that range scores about 1, white
/// noise about 0, a constant 0), averaged over the actuators; and the median lag of those
/// maxima (steps; per actuator the shortest lag within 10% of its maximum), the dominant
/// period. Empty or too short sequences give (0, NaN).
pub fn periodicity(u: &[f64], m: usize) -> (f64, f64) {
    let n = u.len().checked_div(m).unwrap_or(0);
    if n < 6 {
        return (0.0, f64::NAN);
    }
    let mut scores = Vec::with_capacity(m);
    let mut lags = Vec::with_capacity(m);
    for j in 0..m {
        let x: Vec<f64> = (0..n).map(|i| u[i * m + j]).collect();
        let mean = x.iter().sum::<f64>() / n as f64;
        let x: Vec<f64> = x.iter().map(|v| v - mean).collect();
        let var = x.iter().map(|v| v * v).sum::<f64>() / n as f64;
        if var <= 1e-12 {
            scores.push(0.0);
            continue;
        }
        let r: Vec<(usize, f64)> = (3..=n / 2)
            .map(|l| {
                let c = (0..n - l).map(|i| x[i] * x[i + l]).sum::<f64>() / (n - l) as f64;
                (l, c / var)
            })
            .collect();
        let best = r.iter().map(|p| p.1).fold(f64::NEG_INFINITY, f64::max);
        // The period: the shortest lag within 10% of the best (not one of its multiples).
        let lag = r
            .iter()
            .find(|p| p.1 >= best - 0.1 * best.abs())
            .map_or(0, |p| p.0);
        scores.push(best.max(0.0));
        lags.push(lag as f64);
    }
    lags.sort_by(f64::total_cmp);
    let median = if lags.is_empty() {
        f64::NAN
    } else {
        lags[lags.len() / 2]
    };
    (scores.iter().sum::<f64>() / m as f64, median)
}

#[cfg(test)]
mod periodicity_tests {
    use super::periodicity;
    use rand::{Rng, SeedableRng};

    #[test]
    fn a_travelling_sine_is_periodic_and_noise_or_a_constant_is_not() {
        let (n, m) = (40, 6);
        // A 10-step period travelling along the actuators.
        let wave: Vec<f64> = (0..n * m)
            .map(|k| {
                let (i, j) = (k / m, k % m);
                (std::f64::consts::TAU * (i as f64 / 10.0 - j as f64 / 6.0)).sin()
            })
            .collect();
        let (p, lag) = periodicity(&wave, m);
        assert!(p > 0.9, "{p}");
        assert_eq!(lag, 10.0);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let noise: Vec<f64> = (0..n * m).map(|_| rng.random_range(-1.0..1.0)).collect();
        let (q, _) = periodicity(&noise, m);
        assert!(q < 0.6, "{q}");
        assert_eq!(periodicity(&vec![0.3; n * m], m).0, 0.0);
    }
}
