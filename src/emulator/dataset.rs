//! # Training data by simulation (NeuroAnimator §3.4, Fig. 8)
//!
//! The physical model is simulated over long episodes with a fixed step δt under *typical*
//! controls ([`ControlSignal`]: random piecewise-constant or smooth functions within the
//! model's limits). At well-separated times t_k of each episode the current state s_{t_k} and
//! control u_{t_k} are recorded, a copy of the simulation is run n steps with that control held
//! (Δt = n δt, the emulator's super timestep), and the example
//!
//! ```text
//! x = [s_{t_k}, u_{t_k}],   y = s_{t_k + Δt}
//! ```
//!
//! is kept. The lag between successive sample times is drawn uniformly,
//! Δt ≤ t_{k+1} − t_k ≤ 5Δt (in whole physical steps: n … 5n), so the examples are only weakly
//! correlated; the examples are then shuffled. Each episode starts from a state drawn by the
//! caller's start-state distribution, and the first sample of an episode is one random lag after
//! its start. Every random choice comes from the one [`ChaCha8Rng`] passed in.
//!
//! The control is held constant over each sampled window because that is how an emulator is
//! used: one network evaluation per super timestep with the control of that step (eq. 9).

use super::{EmulatorError, Transitions};
use crate::physics::{check_finite, BlowUp, Dynamics};
use ndarray::Array2;
use rand::seq::SliceRandom;
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

/// Box limits of the controls (and external forces), per channel, and for
/// [`ControlProcess::Manoeuvre`] how far into the box a channel's typical amplitude reaches.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ControlLimits {
    /// Lower bound per channel.
    pub low: Vec<f64>,
    /// Upper bound per channel.
    pub high: Vec<f64>,
    /// Per channel, the smallest per-episode amplitude of a [`ControlProcess::Manoeuvre`], as
    /// a fraction of the half-range about the box's centre (1: every episode spans the whole
    /// box). Empty (the default, left out of the serialized form) for the other processes.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub amplitude_min: Vec<f64>,
}

impl ControlLimits {
    /// No controls (a passive model).
    pub fn none() -> Self {
        Self {
            low: vec![],
            high: vec![],
            amplitude_min: vec![],
        }
    }

    /// Symmetric limits ±`bound[i]`.
    pub fn symmetric(bound: &[f64]) -> Self {
        Self {
            low: bound.iter().map(|b| -b).collect(),
            high: bound.to_vec(),
            amplitude_min: vec![],
        }
    }

    /// The same box with per-channel smallest amplitudes for [`ControlProcess::Manoeuvre`].
    pub fn with_amplitude_min(mut self, amplitude_min: &[f64]) -> Self {
        assert_eq!(amplitude_min.len(), self.len(), "one amplitude per channel");
        self.amplitude_min = amplitude_min.to_vec();
        self
    }

    /// The centre of channel `c`'s box (the neutral control of every model here: zero torque,
    /// drive and steering; the lander's hover thrust, half its [0, 2 m g] range).
    pub fn centre(&self, c: usize) -> f64 {
        0.5 * (self.low[c] + self.high[c])
    }

    /// Number of channels.
    pub fn len(&self) -> usize {
        self.low.len()
    }

    /// Whether there are no channels.
    pub fn is_empty(&self) -> bool {
        self.low.is_empty()
    }
}

/// How typical controls vary in time.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", deny_unknown_fields)]
pub enum ControlProcess {
    /// Values drawn uniformly within the limits, held for durations drawn from
    /// U[`hold_min`, `hold_max`] seconds; a knot is idle (every control 0, clamped to the limits,
    /// except a channel whose range starts or ends at 0, which keeps its draw) with probability
    /// `idle`, so rest and coasting are sampled too.
    PiecewiseConstant {
        /// Shortest hold (s).
        hold_min: f64,
        /// Longest hold (s).
        hold_max: f64,
        /// Probability that a knot's controls are all zero.
        idle: f64,
        /// Probability that an episode's first knot is idle (instead of `idle`): with the
        /// model's at-rest starts, the parked (or coasting) state under idle controls that a
        /// task starts from. 0 (the default, left out of the serialized form) draws nothing.
        #[serde(default, skip_serializing_if = "is_zero")]
        idle_first: f64,
    },
    /// Knots as for `PiecewiseConstant`, joined by half-cosine blends (continuous, with zero
    /// slope at the knots).
    Smooth {
        /// Shortest knot spacing (s).
        hold_min: f64,
        /// Longest knot spacing (s).
        hold_max: f64,
    },
    /// Manoeuvres, the typical controls of a model's user (§4: "typical control input
    /// functions"; ours in detail): knots held for U[`hold_min`, `hold_max`] seconds. Per
    /// episode each channel c draws an amplitude a_c log-uniform in [`ControlLimits::
    /// amplitude_min`]_c, 1]; a knot sets channel c to centre_c + a_c · half_c · U[−1, 1]
    /// (centre and half of its box), so small corrections are sampled as densely per decade as
    /// large moves. A knot is idle (every channel at its centre) with probability `idle`. With
    /// `paired`, every drawn knot is followed by its mirror image about the centres for the
    /// same hold (a drive then a brake, a push then a pull), so the states that integrate the
    /// controls (speed, tilt, rates) return to where the pair began instead of drifting.
    Manoeuvre {
        /// Shortest hold (s).
        hold_min: f64,
        /// Longest hold (s).
        hold_max: f64,
        /// Probability that a knot (or a pair) is idle.
        idle: f64,
        /// Whether each knot is followed by its mirror image.
        paired: bool,
    },
    /// Coordinated actions that travel along a chain of actuators (a swimming wave, §3.4's
    /// "coordinated muscle actions that produce locomotion"): per episode a frequency f, a
    /// phase lag φ per channel (either direction), an amplitude a (0 in a fifth of the episodes,
    /// else U[0, 1]; a fraction of each
    /// channel's half-range) and a phase ψ are drawn; at knots held for U[`hold_min`,
    /// `hold_max`] seconds channel c takes centre_c + half_c (a sin(2π f t − c φ + ψ) + ε),
    /// ε ~ U[−ν, ν] with ν ~ U[0, `noise`] per episode, clamped to the limits, and holds it until the next knot.
    TravellingWave {
        /// Shortest hold (s).
        hold_min: f64,
        /// Longest hold (s).
        hold_max: f64,
        /// Lowest wave frequency (Hz).
        freq_min: f64,
        /// Highest wave frequency (Hz).
        freq_max: f64,
        /// Largest phase lag between neighbouring channels (rad).
        lag_max: f64,
        /// Knot noise, as a fraction of the half-range.
        noise: f64,
    },
}

/// Serde: leaves a zero probability out, so older serialized processes (and cache keys) stay.
fn is_zero(v: &f64) -> bool {
    *v == 0.0
}

/// One realisation of a [`ControlProcess`] over `[0, duration]`.
#[derive(Debug, Clone, PartialEq)]
pub struct ControlSignal {
    smooth: bool,
    /// Knot times (s), increasing, starting at 0.
    times: Vec<f64>,
    /// Knot values, `times.len()` × channels, row-major.
    values: Vec<f64>,
    channels: usize,
}

impl ControlSignal {
    /// Draws a signal covering `[0, duration]` from `rng`.
    pub fn sample(
        process: ControlProcess,
        limits: &ControlLimits,
        duration: f64,
        rng: &mut ChaCha8Rng,
    ) -> Self {
        let (smooth, lo, hi) = match process {
            ControlProcess::PiecewiseConstant {
                hold_min, hold_max, ..
            }
            | ControlProcess::TravellingWave {
                hold_min, hold_max, ..
            } => (false, hold_min, hold_max),
            ControlProcess::Smooth { hold_min, hold_max } => (true, hold_min, hold_max),
            ControlProcess::Manoeuvre { .. } => {
                return Self::manoeuvre(process, limits, duration, rng);
            }
        };
        let channels = limits.len();
        // (frequency, lag, amplitude, phase, noise) of a travelling wave.
        let wave = match process {
            ControlProcess::TravellingWave {
                freq_min,
                freq_max,
                lag_max,
                noise,
                ..
            } => Some((
                if freq_max > freq_min {
                    rng.random_range(freq_min..freq_max)
                } else {
                    freq_min
                },
                if lag_max > 0.0 {
                    rng.random_range(-lag_max..lag_max)
                } else {
                    0.0
                },
                // A fifth of the episodes idle (no wave): the body at or near rest.
                if rng.random_range(0.0..1.0) < 0.2 {
                    0.0
                } else {
                    rng.random_range(0.0..1.0)
                },
                rng.random_range(0.0..std::f64::consts::TAU),
                noise * rng.random_range(0.0..1.0),
            )),
            _ => None,
        };
        let (idle, idle_first) = match process {
            ControlProcess::PiecewiseConstant {
                idle, idle_first, ..
            } => (idle, idle_first),
            _ => (0.0, 0.0),
        };
        let mut times = vec![];
        let mut values = vec![];
        let mut t = 0.0;
        loop {
            times.push(t);
            // Drawn only where idle knots are possible, so other processes keep their streams.
            let p = if times.len() == 1 && idle_first > 0.0 {
                idle_first
            } else {
                idle
            };
            let rest = p > 0.0 && rng.random_range(0.0..1.0) < p;
            for c in 0..channels {
                let (low, high) = (limits.low[c], limits.high[c]);
                values.push(match wave {
                    // Idle: every channel rests at zero (clamped to its limits) except one
                    // whose range starts or ends at zero (the lander's thrust), which keeps its
                    // draw: idle attitude jets then coast at any thrust.
                    None if rest && low != 0.0 && high != 0.0 => 0.0f64.clamp(low, high),
                    None => rng.random_range(low..=high),
                    Some((f, lag, amp, psi, noise)) => {
                        let (mid, half) = (0.5 * (low + high), 0.5 * (high - low));
                        let arg = std::f64::consts::TAU * f * t - c as f64 * lag + psi;
                        let eps = if noise > 0.0 {
                            rng.random_range(-noise..noise)
                        } else {
                            0.0
                        };
                        (mid + half * (amp * crate::portable::sin(arg) + eps)).clamp(low, high)
                    }
                });
            }
            if t > duration {
                break;
            }
            t += if hi > lo {
                rng.random_range(lo..hi)
            } else {
                lo.max(1e-9)
            };
        }
        Self {
            smooth,
            times,
            values,
            channels,
        }
    }

    /// A [`ControlProcess::Manoeuvre`] realisation (see there).
    fn manoeuvre(
        process: ControlProcess,
        limits: &ControlLimits,
        duration: f64,
        rng: &mut ChaCha8Rng,
    ) -> Self {
        let ControlProcess::Manoeuvre {
            hold_min,
            hold_max,
            idle,
            paired,
        } = process
        else {
            unreachable!("called for manoeuvres only")
        };
        let channels = limits.len();
        let amplitude: Vec<f64> = (0..channels)
            .map(|c| {
                let a_min = limits.amplitude_min.get(c).copied().unwrap_or(1.0);
                let u: f64 = rng.random_range(0.0..1.0);
                if a_min < 1.0 {
                    crate::portable::exp(u * crate::portable::ln(a_min))
                } else {
                    1.0
                }
            })
            .collect();
        let (mut times, mut values) = (vec![], vec![]);
        let mut t = 0.0;
        let mut deviation = vec![0.0; channels];
        while t <= duration {
            let rest = idle > 0.0 && rng.random_range(0.0..1.0) < idle;
            for (c, d) in deviation.iter_mut().enumerate() {
                let half = 0.5 * (limits.high[c] - limits.low[c]);
                let v: f64 = rng.random_range(-1.0..=1.0);
                *d = if rest { 0.0 } else { amplitude[c] * half * v };
            }
            let hold = if hold_max > hold_min {
                rng.random_range(hold_min..hold_max)
            } else {
                hold_min.max(1e-9)
            };
            for sign in if paired { &[1.0, -1.0][..] } else { &[1.0][..] } {
                times.push(t);
                for (c, d) in deviation.iter().enumerate() {
                    values.push((limits.centre(c) + sign * d).clamp(limits.low[c], limits.high[c]));
                }
                t += hold;
            }
        }
        Self {
            smooth: false,
            times,
            values,
            channels,
        }
    }

    /// Writes the control at time `t` (s) into `u`; beyond the last knot the last value holds.
    pub fn at(&self, t: f64, u: &mut [f64]) {
        if self.channels == 0 {
            return;
        }
        let k = self.times.partition_point(|&s| s <= t).max(1) - 1;
        let a = &self.values[k * self.channels..(k + 1) * self.channels];
        if !self.smooth || k + 1 >= self.times.len() {
            u.copy_from_slice(a);
            return;
        }
        let b = &self.values[(k + 1) * self.channels..(k + 2) * self.channels];
        let (t0, t1) = (self.times[k], self.times[k + 1]);
        let w = 0.5
            - 0.5
                * crate::portable::cos(
                    std::f64::consts::PI * ((t - t0) / (t1 - t0)).clamp(0.0, 1.0),
                );
        for ((o, a), b) in u.iter_mut().zip(a).zip(b) {
            *o = a + w * (b - a);
        }
    }
}

/// How to sample transitions.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SamplingConfig {
    /// Physical time step δt (s).
    pub dt: f64,
    /// Physical steps per super timestep, n (Δt = n δt).
    pub steps_per_sample: usize,
    /// Number of examples to produce.
    pub examples: usize,
    /// Length of one simulated episode before a fresh start state is drawn (s).
    pub episode_duration: f64,
    /// How the typical controls vary.
    pub control: ControlProcess,
}

impl SamplingConfig {
    /// Checks the settings.
    pub fn validate(&self) -> Result<(), EmulatorError> {
        let bad = |name, value| Err(EmulatorError::Setting { name, value });
        if !(self.dt.is_finite() && self.dt > 0.0) {
            return bad("dt", self.dt);
        }
        if self.steps_per_sample == 0 {
            return bad("steps_per_sample", 0.0);
        }
        let window = 6.0 * self.steps_per_sample as f64 * self.dt;
        if !(self.episode_duration >= window) {
            // An episode must hold at least one lag (≤ 5Δt) plus one window (Δt).
            return bad("episode_duration", self.episode_duration);
        }
        if let ControlProcess::Manoeuvre {
            idle,
            hold_min,
            hold_max,
            ..
        } = self.control
        {
            if !(0.0..=1.0).contains(&idle) {
                return bad("idle", idle);
            }
            if !(hold_min > 0.0 && hold_max >= hold_min) {
                return bad("hold_min", hold_min);
            }
        }
        if let ControlProcess::PiecewiseConstant {
            idle, idle_first, ..
        } = self.control
        {
            if !(0.0..=1.0).contains(&idle) {
                return bad("idle", idle);
            }
            if !(0.0..=1.0).contains(&idle_first) {
                return bad("idle_first", idle_first);
            }
        }
        Ok(())
    }
}

/// Sampled transitions with where each came from (rows in the same shuffled order).
#[derive(Debug, Clone, PartialEq)]
pub struct Sampled {
    /// The examples (s_t, u_t, s_{t+Δt}), shuffled.
    pub transitions: Transitions,
    /// Episode index of each example.
    pub episode: Vec<usize>,
    /// Physical step within its episode at which each example starts (t_k = step · δt).
    pub start_step: Vec<usize>,
}

/// Simulates `sim` as described in the module docs and returns `cfg.examples` shuffled
/// examples. `start` draws an episode's initial state; `limits` and `cfg.control` define the
/// typical controls. Fails with [`BlowUp`] when a simulated state is not finite.
pub fn sample_transitions<D: Dynamics + ?Sized>(
    sim: &mut D,
    start: &dyn Fn(&mut ChaCha8Rng) -> Vec<f64>,
    limits: &ControlLimits,
    cfg: &SamplingConfig,
    rng: &mut ChaCha8Rng,
) -> Result<Sampled, BlowUp> {
    let w = sample_windows(sim, start, limits, cfg, 1, rng)?;
    let (n_state, m, rows) = (w.state_dim, w.control_dim, w.len());
    let pick = |src: &[f64], stride: usize, offset: usize, width: usize| -> Array2<f64> {
        Array2::from_shape_fn((rows, width), |(r, c)| src[r * stride + offset + c])
    };
    let transitions = Transitions::new(
        pick(&w.states, 2 * n_state, 0, n_state),
        pick(&w.controls, m, 0, m),
        pick(&w.states, 2 * n_state, n_state, n_state),
    )
    .expect("rows agree by construction");
    Ok(Sampled {
        transitions,
        episode: w.episode,
        start_step: w.start_step,
    })
}

/// Windows of `k` consecutive super-steps (k-step rollout training): per window the
/// k + 1 simulated states s_0 … s_k and the k controls u_0 … u_{k−1}, u_j read from the
/// episode's control signal at the start of super-step j and held over it. Rows (windows) are
/// shuffled; row r's states are `states[r (k+1) n ..]`, its controls `controls[r k m ..]`.
#[derive(Debug, Clone, PartialEq)]
pub struct Windows {
    /// Super-steps per window, k.
    pub k: usize,
    /// State dimension n.
    pub state_dim: usize,
    /// Control dimension m.
    pub control_dim: usize,
    /// States, windows × (k + 1) × n, row-major.
    pub states: Vec<f64>,
    /// Controls, windows × k × m, row-major.
    pub controls: Vec<f64>,
    /// Episode index of each window.
    pub episode: Vec<usize>,
    /// Physical step within its episode at which each window starts.
    pub start_step: Vec<usize>,
}

impl Windows {
    /// Number of windows.
    pub fn len(&self) -> usize {
        self.episode.len()
    }

    /// Whether there are none.
    pub fn is_empty(&self) -> bool {
        self.episode.is_empty()
    }

    /// State j (0 … k) of window r.
    pub fn state(&self, r: usize, j: usize) -> &[f64] {
        let n = self.state_dim;
        let o = (r * (self.k + 1) + j) * n;
        &self.states[o..o + n]
    }

    /// Control j (0 … k − 1) of window r.
    pub fn control(&self, r: usize, j: usize) -> &[f64] {
        let m = self.control_dim;
        let o = (r * self.k + j) * m;
        &self.controls[o..o + m]
    }

    /// Appends `other`'s windows after every one already held.
    ///
    /// # Panics
    /// When the two differ in k or in their state or control dimension.
    pub fn extend(&mut self, other: &Windows) {
        assert_eq!(
            (self.k, self.state_dim, self.control_dim),
            (other.k, other.state_dim, other.control_dim),
            "windows of different shapes"
        );
        self.states.extend_from_slice(&other.states);
        self.controls.extend_from_slice(&other.controls);
        self.episode.extend_from_slice(&other.episode);
        self.start_step.extend_from_slice(&other.start_step);
    }
}

/// One lag between an episode's examples (§4: uniform in [Δt, 5Δt]), in physical steps, for
/// super-steps of `n` physical steps.
pub fn draw_lag(n: usize, rng: &mut ChaCha8Rng) -> usize {
    rng.random_range(n..=5 * n)
}

/// Advances `x` over the physical steps `steps` (indices from the episode's start) of `dt`,
/// each under `signal` read at its own start (`u` is scratch for the control).
pub fn run_signal<D: Dynamics + ?Sized>(
    sim: &mut D,
    x: &mut [f64],
    signal: &ControlSignal,
    u: &mut [f64],
    steps: std::ops::Range<usize>,
    dt: f64,
) {
    for s in steps {
        signal.at(s as f64 * dt, u);
        sim.step(x, u, dt);
    }
}

/// Samples `cfg.examples` windows of `k` super-steps exactly as [`sample_transitions`] samples
/// its examples (which are the windows of k = 1, drawn from the same random stream): episodes
/// from `start`, window starts one lag U[n, 5n] physical steps after the previous one (a
/// window is a copy of the simulation, the episode goes on under its own signal), shuffled.
pub fn sample_windows<D: Dynamics + ?Sized>(
    sim: &mut D,
    start: &dyn Fn(&mut ChaCha8Rng) -> Vec<f64>,
    limits: &ControlLimits,
    cfg: &SamplingConfig,
    k: usize,
    rng: &mut ChaCha8Rng,
) -> Result<Windows, BlowUp> {
    let n_state = sim.state_dim();
    let m = sim.control_dim();
    assert_eq!(
        limits.len(),
        m,
        "control limits must match the control dimension"
    );
    assert!(k >= 1, "a window needs at least one super-step");
    let n = cfg.steps_per_sample;
    let rows = cfg.examples;
    let mut states = Vec::with_capacity(rows * (k + 1) * n_state);
    let mut controls = Vec::with_capacity(rows * k * m);
    let mut episode = Vec::with_capacity(rows);
    let mut start_step = Vec::with_capacity(rows);
    let episode_steps = (cfg.episode_duration / cfg.dt).floor() as usize;
    assert!(
        episode_steps >= (k + 1) * n,
        "episodes of {episode_steps} steps cannot hold a lag and a window of {k} x {n} steps"
    );
    let mut u = vec![0.0; m];
    let mut y = vec![0.0; n_state];
    let mut e = 0;
    while episode.len() < rows {
        let mut x = start(rng);
        assert_eq!(x.len(), n_state, "start state has the wrong size");
        let signal = ControlSignal::sample(cfg.control, limits, cfg.episode_duration, rng);
        let mut step = 0usize;
        while episode.len() < rows {
            let lag = draw_lag(n, rng);
            if step + lag + k * n > episode_steps {
                break;
            }
            run_signal(sim, &mut x, &signal, &mut u, step..step + lag, cfg.dt);
            step += lag;
            check_finite("sampling", step, step as f64 * cfg.dt, &x)?;
            states.extend_from_slice(&x);
            y.copy_from_slice(&x);
            for j in 0..k {
                let at = step + j * n;
                signal.at(at as f64 * cfg.dt, &mut u);
                for _ in 0..n {
                    sim.step(&mut y, &u, cfg.dt);
                }
                check_finite("sampling", at + n, (at + n) as f64 * cfg.dt, &y)?;
                controls.extend_from_slice(&u);
                states.extend_from_slice(&y);
            }
            episode.push(e);
            start_step.push(step);
        }
        e += 1;
    }
    let mut order: Vec<usize> = (0..rows).collect();
    order.shuffle(rng);
    let permute = |src: &[f64], w: usize| -> Vec<f64> {
        order
            .iter()
            .flat_map(|&r| src[r * w..(r + 1) * w].iter().copied())
            .collect()
    };
    Ok(Windows {
        k,
        state_dim: n_state,
        control_dim: m,
        states: permute(&states, (k + 1) * n_state),
        controls: permute(&controls, k * m),
        episode: order.iter().map(|&r| episode[r]).collect(),
        start_step: order.iter().map(|&r| start_step[r]).collect(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::physics::pendulum::{Pendulum3, PendulumVariant};
    use crate::physics::{IntegratorKind, Simulator};
    use rand::SeedableRng;

    fn run(seed: u64, n: usize, rows: usize) -> Sampled {
        let mut sim = Simulator::new(Pendulum3::new(PendulumVariant::Active), IntegratorKind::Rk4);
        let cfg = SamplingConfig {
            dt: 0.01,
            steps_per_sample: n,
            examples: rows,
            episode_duration: 5.0,
            control: ControlProcess::PiecewiseConstant {
                hold_min: 0.2,
                hold_max: 1.0,
                idle: 0.0,
                idle_first: 0.0,
            },
        };
        cfg.validate().unwrap();
        let start = |r: &mut ChaCha8Rng| -> Vec<f64> {
            (0..6)
                .map(|i| {
                    if i < 3 {
                        r.random_range(-1.0..1.0)
                    } else {
                        0.0
                    }
                })
                .collect()
        };
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        sample_transitions(
            &mut sim,
            &start,
            &ControlLimits::symmetric(&[2.0; 3]),
            &cfg,
            &mut rng,
        )
        .unwrap()
    }

    #[test]
    fn lags_are_within_one_to_five_super_steps_and_rows_are_shuffled() {
        let n = 10;
        let s = run(1, n, 200);
        assert_eq!(s.transitions.states.dim(), (200, 6));
        assert_eq!(s.transitions.controls.dim(), (200, 3));
        assert_eq!(s.transitions.next_states.dim(), (200, 6));
        let mut keys: Vec<(usize, usize)> = s
            .episode
            .iter()
            .copied()
            .zip(s.start_step.iter().copied())
            .collect();
        assert_ne!(keys, {
            let mut k = keys.clone();
            k.sort();
            k
        });
        keys.sort();
        let mut lags = vec![];
        let mut prev: Option<(usize, usize)> = None;
        for &(e, t) in &keys {
            match prev {
                Some((pe, pt)) if pe == e => lags.push(t - pt),
                _ => assert!((n..=5 * n).contains(&t), "first lag {t}"),
            }
            prev = Some((e, t));
        }
        assert!(lags.iter().all(|l| (n..=5 * n).contains(l)), "{lags:?}");
        // Uniform over [n, 5n]: the mean is near 3n and both ends occur.
        let mean = lags.iter().sum::<usize>() as f64 / lags.len() as f64;
        assert!((mean - 3.0 * n as f64).abs() < 0.4 * n as f64, "{mean}");
        assert!(lags.iter().any(|&l| l < 2 * n) && lags.iter().any(|&l| l > 4 * n));
        // Controls respect their limits.
        assert!(s.transitions.controls.iter().all(|u| u.abs() <= 2.0));
    }

    #[test]
    fn each_example_is_n_steps_with_the_control_held() {
        let n = 7;
        let s = run(2, n, 20);
        let mut sim = Simulator::new(Pendulum3::new(PendulumVariant::Active), IntegratorKind::Rk4);
        for r in 0..20 {
            let mut x = s.transitions.states.row(r).to_vec();
            let u = s.transitions.controls.row(r).to_vec();
            for _ in 0..n {
                sim.step(&mut x, &u, 0.01);
            }
            assert_eq!(x, s.transitions.next_states.row(r).to_vec());
        }
    }

    #[test]
    fn same_seed_same_data_other_seed_other_data() {
        assert_eq!(run(3, 5, 50), run(3, 5, 50));
        assert_ne!(run(3, 5, 50), run(4, 5, 50));
    }

    /// Manoeuvres: each drawn knot is followed by its mirror image about the box's centre for
    /// the same hold (a pair), idle pairs sit at the centre, every value stays in the box, and a
    /// channel's deviations stay within its episode amplitude, which is log-uniform in
    /// [amplitude_min, 1] (so about half the episodes lie below the geometric middle).
    #[test]
    fn manoeuvres_come_in_mirrored_pairs_at_log_uniform_amplitudes() {
        let lim = ControlLimits {
            low: vec![0.0, -2.0],
            high: vec![10.0, 2.0],
            amplitude_min: vec![0.01, 1.0],
        };
        let p = ControlProcess::Manoeuvre {
            hold_min: 0.5,
            hold_max: 2.0,
            idle: 0.25,
            paired: true,
        };
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let mut below_middle = 0;
        let episodes = 400;
        let mut idle_pairs = 0;
        let mut pairs = 0;
        for _ in 0..episodes {
            let s = ControlSignal::sample(p, &lim, 10.0, &mut rng);
            assert!(
                s.times.len().is_multiple_of(2) && s.times.last().copied().unwrap() <= 10.0 + 2.0
            );
            let mut largest: f64 = 0.0;
            for k in (0..s.times.len()).step_by(2) {
                let (a, b) = (&s.values[2 * k..2 * k + 2], &s.values[2 * k + 2..2 * k + 4]);
                for c in 0..2 {
                    let centre = lim.centre(c);
                    assert!((lim.low[c]..=lim.high[c]).contains(&a[c]));
                    assert!(((a[c] - centre) + (b[c] - centre)).abs() < 1e-12, "mirror");
                }
                if k + 2 < s.times.len() {
                    let h1 = s.times[k + 1] - s.times[k];
                    let h2 = s.times[k + 2] - s.times[k + 1];
                    assert!((h1 - h2).abs() < 1e-12 && (0.5..2.0).contains(&h1));
                }
                largest = largest.max((a[0] - 5.0).abs() / 5.0);
                pairs += 1;
                idle_pairs += usize::from(a[0] == 5.0 && a[1] == 0.0);
            }
            assert!(largest <= 1.0);
            // The amplitude bounds every deviation; 0.1 is the geometric middle of [0.01, 1].
            below_middle += usize::from(largest < 0.1);
        }
        assert!(
            (120..=280).contains(&below_middle),
            "{below_middle} of {episodes}"
        );
        let share = idle_pairs as f64 / pairs as f64;
        assert!((0.15..0.35).contains(&share), "idle share {share}");
        // Same seed, same signal.
        let draw =
            |seed| ControlSignal::sample(p, &lim, 10.0, &mut ChaCha8Rng::seed_from_u64(seed));
        assert_eq!(draw(3), draw(3));
        assert_ne!(draw(3), draw(4));
    }

    #[test]
    fn smooth_signal_is_continuous_and_hits_its_knots() {
        let mut rng = ChaCha8Rng::seed_from_u64(9);
        let lim = ControlLimits::symmetric(&[1.0, 3.0]);
        let p = ControlProcess::Smooth {
            hold_min: 0.5,
            hold_max: 1.5,
        };
        let s = ControlSignal::sample(p, &lim, 10.0, &mut rng);
        let (mut a, mut b) = ([0.0; 2], [0.0; 2]);
        let mut t = 0.0;
        while t < 10.0 {
            s.at(t, &mut a);
            s.at(t + 1e-4, &mut b);
            assert!((a[0] - b[0]).abs() < 1e-2 && (a[1] - b[1]).abs() < 1e-2);
            assert!(a[0].abs() <= 1.0 && a[1].abs() <= 3.0);
            t += 0.01;
        }
        s.at(s.times[1], &mut a);
        assert_eq!(a.to_vec(), s.values[2..4].to_vec());
    }
}
