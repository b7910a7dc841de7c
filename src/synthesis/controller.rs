//! # Time-based reflex controllers (Christensen, Marks, Ngo 1995, §2.2, Fig. 2)
//!
//! A controller splits a period of length t_per into C regimes. Regime i has a regime time
//! t_i ∈ [0, t_per], a reflex number R_i ∈ 0..=11 and a coefficient α_i ∈ [−1, 1]. At time t
//! the phase is s = t mod t_per (s = t when t_per ≥ T, the aperiodic case) and the active
//! regime is the one whose regime time is nearest to s on the segment [0, t_per]:
//!
//! i(t) = argmin_i |s − t_i|, ties going to the lower index.
//!
//! So with the regime times sorted, t_(0) ≤ … ≤ t_(C−1), the regime changes at the midpoints
//! (t_(j) + t_(j+1)) / 2; the first regime also covers [0, t_(0)] and the last
//! [t_(C−1), t_per). The phase line is a segment, not a circle (Fig. 2 draws a segment): the
//! regime active at the end of one period is followed by the first one of the next.
//!
//! While regime i is active the lattice's rest lengths are those of reflex R_i with
//! coefficient α_i ([`crate::physics::reflex::deform`]); they change instantly at a switch.
//! [`simulate`] integrates the lattice with [`LatticeSim`] over the horizon T, stopping exactly
//! at every switch and at every sample time, and returns the sampled [`Trajectory`].

use super::SynthesisError;
use crate::physics::lattice::{LatticeModel, LatticeSim};
use crate::physics::reflex::{deform, Reflex};
use crate::physics::{check_finite, BlowUp, Dynamics};
use serde::{Deserialize, Serialize};

/// One regime of a controller.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Regime {
    /// Regime time t_i ∈ [0, t_per] (s).
    pub time: f64,
    /// Reflex number R_i ∈ 0..=11 ([`Reflex::from_number`]).
    pub reflex: usize,
    /// Reflex coefficient α_i ∈ [−1, 1].
    pub alpha: f64,
}

/// A time-based controller: a period and its regimes.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Controller {
    /// The period t_per (s); the regime sequence repeats every t_per.
    pub period: f64,
    /// The C regimes (at least one).
    pub regimes: Vec<Regime>,
}

impl Controller {
    /// Checks the period, the regime times, reflex numbers and coefficients.
    pub fn validate(&self) -> Result<(), SynthesisError> {
        if !(self.period.is_finite() && self.period > 0.0) {
            return Err(SynthesisError::Invalid("period", self.period));
        }
        if self.regimes.is_empty() {
            return Err(SynthesisError::Invalid("regime count", 0.0));
        }
        for r in &self.regimes {
            if !(r.time.is_finite() && (0.0..=self.period).contains(&r.time)) {
                return Err(SynthesisError::Invalid("regime time", r.time));
            }
            if r.reflex >= Reflex::COUNT {
                return Err(SynthesisError::Invalid("reflex number", r.reflex as f64));
            }
            if !(r.alpha.is_finite() && (-1.0..=1.0).contains(&r.alpha)) {
                return Err(SynthesisError::Invalid("reflex coefficient", r.alpha));
            }
        }
        Ok(())
    }

    /// The phase s = t mod t_per ∈ [0, t_per).
    pub fn phase(&self, t: f64) -> f64 {
        t.rem_euclid(self.period)
    }

    /// Index of the regime active at time `t` (s): the nearest regime time to the phase,
    /// ties to the lower index.
    pub fn regime_at(&self, t: f64) -> usize {
        let s = self.phase(t);
        let mut best = 0;
        let mut dist = f64::INFINITY;
        for (i, r) in self.regimes.iter().enumerate() {
            let d = (s - r.time).abs();
            if d < dist {
                dist = d;
                best = i;
            }
        }
        best
    }

    /// The regime intervals of one period, in order: `(start, regime index)`, the first
    /// starting at 0; each lasts until the next start (the last until t_per). Empty regimes
    /// (shadowed by a regime with an equal time) do not appear.
    pub fn period_schedule(&self) -> Vec<(f64, usize)> {
        let mut order: Vec<usize> = (0..self.regimes.len()).collect();
        // Sort by time, ties by index, so that of equal times the lower index wins.
        order.sort_by(|&a, &b| {
            self.regimes[a]
                .time
                .total_cmp(&self.regimes[b].time)
                .then(a.cmp(&b))
        });
        order.dedup_by(|b, a| self.regimes[*a].time == self.regimes[*b].time);
        let mut out = Vec::with_capacity(order.len());
        for (k, &i) in order.iter().enumerate() {
            let start = if k == 0 {
                0.0
            } else {
                0.5 * (self.regimes[order[k - 1]].time + self.regimes[i].time)
            };
            // A switch at or beyond the period end never happens.
            if start < self.period {
                out.push((start, i));
            }
        }
        out
    }

    /// Every regime switch over `[0, horizon)`: `(time, regime index)`, the first at 0,
    /// repeating the period schedule to fill the horizon.
    pub fn schedule(&self, horizon: f64) -> Vec<(f64, usize)> {
        let one = self.period_schedule();
        let mut out: Vec<(f64, usize)> = Vec::new();
        let mut k = 0usize;
        loop {
            let base = k as f64 * self.period;
            if base >= horizon {
                break;
            }
            for &(s, i) in &one {
                let t = base + s;
                if t >= horizon {
                    break;
                }
                // Consecutive periods may start with the regime that ended the previous one.
                if out.last().is_some_and(|&(_, j)| j == i) {
                    continue;
                }
                out.push((t, i));
            }
            k += 1;
        }
        out
    }
}

/// What an evaluation simulates: the lattice model (gravity, floor, reflex gains), the start
/// state, the horizon and how the trajectory is sampled.
#[derive(Debug, Clone)]
pub struct SimSetup {
    /// The lattice with gravity and floor.
    pub model: LatticeModel,
    /// Initial state `[positions, velocities]`.
    pub initial: Vec<f64>,
    /// The horizon T (s).
    pub horizon: f64,
    /// Sample interval of the trajectory (s).
    pub sample_dt: f64,
    /// Relative tolerance of the RK45 integrator.
    pub rtol: f64,
    /// Absolute tolerance of the RK45 integrator.
    pub atol: f64,
    /// Smallest internal RK45 step (s), accepted whatever its error: contact chattering
    /// cannot stall an evaluation.
    pub min_step: f64,
    /// Most internal RK45 steps (accepted + rejected) an evaluation may take; beyond it the
    /// evaluation fails with [`SynthesisError::Budget`].
    pub max_steps: u64,
}

impl SimSetup {
    /// A setup starting from the lattice's resting state.
    pub fn new(model: LatticeModel, horizon: f64, sample_dt: f64) -> Self {
        let initial = model.lattice.resting_state();
        Self {
            model,
            initial,
            horizon,
            sample_dt,
            rtol: 1e-6,
            atol: 1e-8,
            min_step: 1e-6,
            max_steps: 200_000,
        }
    }

    /// The same setup with integrator tolerances `rtol`, `atol`.
    pub fn with_tolerances(mut self, rtol: f64, atol: f64) -> Self {
        self.rtol = rtol;
        self.atol = atol;
        self
    }

    /// Number of samples after the initial one: ⌈T / sample_dt⌉.
    pub fn samples(&self) -> usize {
        (self.horizon / self.sample_dt - 1e-9).ceil().max(1.0) as usize
    }
}

/// One sample of a simulated trajectory.
#[derive(Debug, Clone, PartialEq)]
pub struct Frame {
    /// Time (s).
    pub t: f64,
    /// Positions of the masses (m).
    pub positions: Vec<[f64; 3]>,
    /// The regime that drove the interval ending at this time (the first regime at t = 0).
    pub regime: usize,
}

/// A sampled trajectory of a lattice under a controller.
#[derive(Debug, Clone, PartialEq)]
pub struct Trajectory {
    /// Masses of the point masses (kg), for the centre of mass.
    pub masses: Vec<f64>,
    /// Rest positions of the lattice (m), the frame of the lattice-centric axes.
    pub rest: Vec<[f64; 3]>,
    /// The samples, at t = 0, sample_dt, 2·sample_dt, …, T.
    pub frames: Vec<Frame>,
}

impl Trajectory {
    /// Centre of mass of `positions`.
    pub fn com(&self, positions: &[[f64; 3]]) -> [f64; 3] {
        let mut c = [0.0; 3];
        let mut total = 0.0;
        for (m, p) in self.masses.iter().zip(positions) {
            total += m;
            for k in 0..3 {
                c[k] += m * p[k];
            }
        }
        c.map(|v| v / total)
    }

    /// Centre of mass of every frame.
    pub fn coms(&self) -> Vec<[f64; 3]> {
        self.frames.iter().map(|f| self.com(&f.positions)).collect()
    }
}

/// The rest lengths of each regime of `c` on `model`'s lattice.
pub fn regime_rest_lengths(
    model: &LatticeModel,
    c: &Controller,
) -> Result<Vec<Vec<f64>>, SynthesisError> {
    c.regimes
        .iter()
        .map(|r| {
            deform(&model.lattice, r.reflex, r.alpha, &model.reflex_gains)
                .map(|d| d.rest_lengths)
                .map_err(SynthesisError::from)
        })
        .collect()
}

/// Simulates `setup` under controller `c` over the horizon; the integration stops exactly at
/// every regime switch and sample time.
pub fn simulate(setup: &SimSetup, c: &Controller) -> Result<Trajectory, SynthesisError> {
    c.validate()?;
    let rest = regime_rest_lengths(&setup.model, c)?;
    simulate_with_rest(setup, c, &rest)
}

/// Simulates `setup` switching by `c`'s regime times and period, with regime i's spring rest
/// lengths `rest[i]` (its reflex numbers and coefficients are not used).
pub fn simulate_with_rest(
    setup: &SimSetup,
    c: &Controller,
    rest: &[Vec<f64>],
) -> Result<Trajectory, SynthesisError> {
    if rest.len() != c.regimes.len() {
        return Err(SynthesisError::Invalid(
            "rest-length sets",
            rest.len() as f64,
        ));
    }
    let schedule = c.schedule(setup.horizon);
    let mut sim = LatticeSim::new(setup.model.clone())
        .with_tolerances(setup.rtol, setup.atol)
        .with_min_step(setup.min_step)
        .with_fsal();
    let n = setup.model.lattice.n_masses();
    let mut x = setup.initial.clone();
    let positions = |x: &[f64]| -> Vec<[f64; 3]> {
        (0..n)
            .map(|i| [x[3 * i], x[3 * i + 1], x[3 * i + 2]])
            .collect()
    };
    let samples = setup.samples();
    let mut frames = Vec::with_capacity(samples + 1);
    frames.push(Frame {
        t: 0.0,
        positions: positions(&x),
        regime: schedule[0].1,
    });
    let mut t = 0.0;
    let mut next_switch = 1; // index into schedule
    let mut active = schedule[0].1;
    let mut last_used = active;
    let mut steps = 0usize;
    for k in 1..=samples {
        let t_sample = (k as f64 * setup.sample_dt).min(setup.horizon);
        while t < t_sample {
            let stop = match schedule.get(next_switch) {
                Some(&(ts, _)) if ts < t_sample => ts,
                _ => t_sample,
            };
            if stop > t {
                sim.step(&mut x, &rest[active], stop - t);
                last_used = active;
                steps += 1;
                check_finite(&setup.model.lattice.name, steps, stop, &x).map_err(Box::new)?;
                let st = sim.integrator_stats();
                if st.accepted + st.rejected > setup.max_steps {
                    return Err(SynthesisError::Budget(st.accepted + st.rejected));
                }
            }
            t = stop;
            if let Some(&(ts, i)) = schedule.get(next_switch) {
                if ts <= t {
                    active = i;
                    next_switch += 1;
                }
            }
        }
        frames.push(Frame {
            t: t_sample,
            positions: positions(&x),
            regime: last_used,
        });
    }
    Ok(Trajectory {
        masses: setup.model.lattice.masses.iter().map(|m| m.mass).collect(),
        rest: setup.model.lattice.rest_positions(),
        frames,
    })
}

/// A blow-up of the simulation, boxed into the error type.
impl From<Box<BlowUp>> for SynthesisError {
    fn from(b: Box<BlowUp>) -> Self {
        SynthesisError::BlowUp(b)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::physics::lattice::{Lattice, LOW_GRAVITY};

    fn ctl(period: f64, times: &[f64]) -> Controller {
        Controller {
            period,
            regimes: times
                .iter()
                .enumerate()
                .map(|(i, &t)| Regime {
                    time: t,
                    reflex: i % 12,
                    alpha: 0.5,
                })
                .collect(),
        }
    }

    #[test]
    fn nearest_regime_rule_fig2() {
        // Fig. 2: C = 3, t_per = T = 5. Regime times 1, 2, 4 → switches at 1.5 and 3.
        let c = ctl(5.0, &[4.0, 1.0, 2.0]);
        assert_eq!(c.regime_at(0.0), 1);
        assert_eq!(c.regime_at(1.49), 1);
        assert_eq!(c.regime_at(1.51), 2);
        assert_eq!(c.regime_at(2.99), 2);
        assert_eq!(c.regime_at(3.01), 0);
        assert_eq!(c.regime_at(4.99), 0);
        // Exactly at a midpoint the tie goes to the lower index (regime 0 at time 4 vs
        // regime 2 at time 2: midpoint 3).
        assert_eq!(c.regime_at(3.0), 0);
        assert_eq!(c.period_schedule(), vec![(0.0, 1), (1.5, 2), (3.0, 0)]);
    }

    #[test]
    fn periodic_repetition_and_schedule_agree_with_the_rule() {
        let c = ctl(1.0, &[0.1, 0.5, 0.8, 0.95]);
        // t and t + t_per are in the same regime.
        for k in 0..100 {
            let t = k as f64 * 0.0137;
            assert_eq!(c.regime_at(t), c.regime_at(t + 1.0), "t = {t}");
            assert_eq!(c.regime_at(t), c.regime_at(t + 3.0), "t = {t}");
        }
        // The switch list over 4.5 periods reproduces regime_at everywhere.
        let sched = c.schedule(4.5);
        for k in 0..4500 {
            let t = k as f64 * 0.001 + 0.0005;
            let from_sched = sched.iter().rev().find(|&&(ts, _)| ts <= t).unwrap().1;
            assert_eq!(from_sched, c.regime_at(t), "t = {t}");
        }
        // The last regime of a period is followed by the first one of the next.
        assert!(sched
            .iter()
            .any(|&(t, i)| (t - 1.0).abs() < 1e-12 && i == 0));
    }

    #[test]
    fn equal_regime_times_shadow_the_higher_index() {
        let c = ctl(2.0, &[1.0, 1.0]);
        assert_eq!(c.regime_at(0.3), 0);
        assert_eq!(c.regime_at(1.9), 0);
        assert_eq!(c.period_schedule(), vec![(0.0, 0)]);
    }

    #[test]
    fn validation_rejects_bad_controllers() {
        assert!(ctl(0.0, &[0.0]).validate().is_err());
        assert!(ctl(1.0, &[]).validate().is_err());
        assert!(ctl(1.0, &[1.5]).validate().is_err());
        let mut c = ctl(1.0, &[0.5]);
        c.regimes[0].reflex = 12;
        assert!(c.validate().is_err());
        c.regimes[0].reflex = 3;
        c.regimes[0].alpha = -1.2;
        assert!(c.validate().is_err());
    }

    #[test]
    fn simulation_samples_the_horizon_and_follows_the_regimes() {
        let model = LatticeModel::new(Lattice::cube())
            .unwrap()
            .with_gravity(LOW_GRAVITY);
        let setup = SimSetup::new(model, 1.0, 0.05).with_tolerances(1e-5, 1e-7);
        let c = Controller {
            period: 0.5,
            regimes: vec![
                Regime {
                    time: 0.1,
                    reflex: 2,
                    alpha: 1.0,
                },
                Regime {
                    time: 0.4,
                    reflex: 2,
                    alpha: -1.0,
                },
            ],
        };
        let tr = simulate(&setup, &c).unwrap();
        assert_eq!(tr.frames.len(), 21);
        assert!((tr.frames.last().unwrap().t - 1.0).abs() < 1e-12);
        for f in &tr.frames[1..] {
            // The frame records the regime active over the interval ending at its time.
            assert_eq!(f.regime, c.regime_at(f.t - 1e-9), "t = {}", f.t);
        }
        // Stretching and squashing along z moves the centre of mass up and down.
        let z: Vec<f64> = tr.coms().iter().map(|c| c[2]).collect();
        let (lo, hi) = z
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| {
                (a.min(v), b.max(v))
            });
        assert!(hi - lo > 0.1, "com height range {lo}..{hi}");
        assert!(lo > 0.0);
    }
}
