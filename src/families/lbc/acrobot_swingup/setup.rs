//! The acrobot swing-up's setup: the handstand, the DDP swing-ups and their family markers,
//! the trackers and their blends, and the closed-loop rollouts of the compared policies.

use super::{Params, CONTROL_WEIGHT, FIRST_SWING, VALUE_MODELS};
use crate::bellman::combine::{normalized_entropy, BlendMode, TrackerBlend};
use crate::control::ddp::{solve, ControlBounds, DdpOptions, DdpSolution, DdpVariant};
use crate::control::lqr::{track_with, TrackingController, ValueModel};
use crate::control::{QuadraticCost, Rk4Map};
use crate::experiment::{other, Error};
use crate::families::lbc::alpha_deviation;
use crate::physics::acrobot::Acrobot;
use nalgebra::{DMatrix, DVector};
use rayon::prelude::*;
use std::f64::consts::{FRAC_PI_2, PI};

/// The handstand.
pub(super) fn handstand() -> DVector<f64> {
    DVector::from_vec(vec![FRAC_PI_2, 0.0, 0.0, 0.0])
}

pub(super) fn radians(s: &[f64; 4]) -> DVector<f64> {
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

/// Direction (±1) of the shoulder's first excursion beyond [`FIRST_SWING`] from its start
/// angle; 0 when it never moves that far.
pub fn first_swing_sign(xs: &[DVector<f64>]) -> i64 {
    let t0 = xs[0][0];
    xs.iter()
        .map(|x| x[0] - t0)
        .find(|d| d.abs() > FIRST_SWING)
        .map_or(0, |d| d.signum() as i64)
}

/// Sign (±1) of the first hip-torque lobe: of the first control reaching a quarter of the
/// tape's largest magnitude; 0 for an all-zero tape.
pub fn first_torque_sign(us: &[DVector<f64>]) -> i64 {
    let peak = us.iter().map(|u| u[0].abs()).fold(0.0, f64::max);
    if peak == 0.0 {
        return 0;
    }
    us.iter()
        .map(|u| u[0])
        .find(|u| u.abs() >= 0.25 * peak)
        .map_or(0, |u| u.signum() as i64)
}

/// Pearson correlation of two control tapes of equal length.
pub fn tape_correlation(a: &[DVector<f64>], b: &[DVector<f64>]) -> f64 {
    let n = a.len().min(b.len()) as f64;
    let (ma, mb) = (
        a.iter().map(|u| u[0]).sum::<f64>() / n,
        b.iter().map(|u| u[0]).sum::<f64>() / n,
    );
    let (mut sab, mut saa, mut sbb) = (0.0, 0.0, 0.0);
    for (x, y) in a.iter().zip(b) {
        let (da, db) = (x[0] - ma, y[0] - mb);
        sab += da * db;
        saa += da * da;
        sbb += db * db;
    }
    sab / (saa * sbb).sqrt()
}

/// Result of running one policy from one start (stops where the closed loop diverges).
pub(super) struct Rollout {
    pub(super) xs: Vec<DVector<f64>>,
    pub(super) us: Vec<f64>,
    pub(super) alpha1: Vec<f64>,
    pub(super) entropy: Vec<f64>,
    /// max_i |α_i − ŵ_i| at each step (ŵ the fixed weights normalized).
    pub(super) alpha_deviation: Vec<f64>,
    pub(super) control_cost: f64,
    /// Step at which the closed loop diverged (non-finite state), if it did.
    pub(super) diverged: Option<usize>,
}

impl Rollout {
    /// Distance of the final state to the handstand; infinite when the closed loop diverged.
    pub(super) fn final_distance(&self) -> f64 {
        match self.diverged {
            Some(_) => f64::INFINITY,
            None => distance_to_handstand(self.xs[self.xs.len() - 1].as_slice()),
        }
    }

    pub(super) fn max_abs_torque(&self) -> f64 {
        self.us.iter().fold(0.0, |m, u| m.max(u.abs()))
    }

    pub(super) fn mean_entropy(&self) -> f64 {
        if self.entropy.is_empty() {
            f64::NAN
        } else {
            self.entropy.iter().sum::<f64>() / self.entropy.len() as f64
        }
    }
}

/// One DDP swing-up: from which start and initial guess, and its solution.
pub(super) struct Candidate {
    pub(super) start: usize,
    pub(super) guess: String,
    pub(super) sol: DdpSolution,
}

impl Params {
    fn steps(&self) -> usize {
        (self.horizon / self.dt).round() as usize
    }

    /// λ = σ² R of the stated hip-torque noise (eq. 8).
    pub fn lambda(&self) -> f64 {
        self.torque_noise * self.torque_noise * CONTROL_WEIGHT
    }

    pub(super) fn cost(&self) -> QuadraticCost {
        let mut c = QuadraticCost::effort(
            self.dt,
            1,
            DMatrix::from_diagonal(&DVector::from_row_slice(&self.terminal_weights)),
            handstand(),
        );
        c.r *= CONTROL_WEIGHT;
        c
    }

    fn options(&self) -> DdpOptions {
        DdpOptions {
            variant: if self.variant == "full" {
                DdpVariant::Full
            } else {
                DdpVariant::Ilqr
            },
            max_iterations: self.max_iterations,
            bounds: Some(ControlBounds {
                lower: DVector::from_element(1, -self.torque_limit),
                upper: DVector::from_element(1, self.torque_limit),
            }),
            ..DdpOptions::default()
        }
    }

    /// The [`ValueModel`] named `name` (one of [`VALUE_MODELS`]); DDP's second-order terms by
    /// central differences with DDP's own step.
    pub(super) fn model(&self, name: &str) -> ValueModel {
        if name == "ddp" {
            ValueModel::Ddp {
                fd_step: self.options().fd_step,
            }
        } else {
            ValueModel::Lqr
        }
    }

    /// The value model run beside the spec's for comparison.
    pub(super) fn other_model(&self) -> &'static str {
        VALUE_MODELS[(self.value_model == VALUE_MODELS[0]) as usize]
    }

    /// The tracker weight scales tried: `tracker_weight_scales`, or 1 alone when empty.
    pub(super) fn scales(&self) -> Vec<f64> {
        if self.tracker_weight_scales.is_empty() {
            vec![1.0]
        } else {
            self.tracker_weight_scales.clone()
        }
    }

    /// Trackers of `sols` under the value model `name`, from the LQR recursion with the
    /// terminal weights × `scale`.
    pub(super) fn trackers(
        &self,
        map: &Rk4Map<Acrobot>,
        sols: &[&DdpSolution],
        name: &str,
        scale: f64,
    ) -> Result<Vec<TrackingController>, Error> {
        let mut cost = self.cost();
        cost.q_final *= scale;
        sols.iter()
            .map(|s| track_with(map, &cost, &s.x, &s.u, self.model(name)).map_err(other))
            .collect()
    }

    /// The spec's combination of `trackers` in mode `m` at temperature `lambda`.
    pub(super) fn blend<'a>(
        &self,
        trackers: &'a [TrackingController],
        limits: &'a [f64],
        m: BlendMode,
        lambda: f64,
    ) -> TrackerBlend<'a> {
        TrackerBlend {
            trackers,
            weights: self.weights.clone(),
            lambda,
            mode: m,
            limits: Some(limits),
        }
    }

    fn sinusoid(&self, g: &[f64; 3]) -> Vec<DVector<f64>> {
        (0..self.steps())
            .map(|k| {
                DVector::from_element(
                    1,
                    g[0] * crate::portable::sin(k as f64 * self.dt * g[1] + g[2]),
                )
            })
            .collect()
    }

    fn solve_from(
        &self,
        map: &Rk4Map<Acrobot>,
        start: usize,
        guess: String,
        u0: &[DVector<f64>],
    ) -> Result<Candidate, Error> {
        let sol = solve(
            map,
            &self.cost(),
            &radians(&self.starts[start]),
            u0,
            &self.options(),
        )
        .map_err(other)?;
        Ok(Candidate { start, guess, sol })
    }

    /// Every DDP run (sinusoid guesses, then warm starts from the other start's cheapest), and
    /// the index of the kept run per start: the cheapest pair of one family (same first-swing
    /// sign, [`first_swing_sign`]), i.e. the family with the lowest summed cost over the starts;
    /// the cheapest run per start when no family has a run for every start.
    pub(super) fn swing_ups(
        &self,
        map: &Rk4Map<Acrobot>,
    ) -> Result<(Vec<Candidate>, Vec<usize>), Error> {
        let n = self.starts.len();
        let jobs: Vec<(usize, usize)> = (0..n)
            .flat_map(|s| (0..self.init_guesses.len()).map(move |g| (s, g)))
            .collect();
        let mut cands: Vec<Candidate> = jobs
            .par_iter()
            .map(|&(s, g)| {
                let guess = self.init_guesses[g];
                let label = format!("sin a={} w={} phi={}", guess[0], guess[1], guess[2]);
                self.solve_from(map, s, label, &self.sinusoid(&guess))
            })
            .collect::<Result<_, _>>()?;
        if self.warm_start {
            let first = cheapest(&cands, n, |_| true);
            let warm: Vec<Candidate> = (0..n)
                .flat_map(|s| (0..n).filter(move |&o| o != s).map(move |o| (s, o)))
                .collect::<Vec<_>>()
                .par_iter()
                .map(|&(s, o)| {
                    let tape = cands[first[o].expect("a run per start")].sol.u.clone();
                    self.solve_from(map, s, format!("warm from swing-up {}", o + 1), &tape)
                })
                .collect::<Result<_, _>>()?;
            cands.extend(warm);
        }
        let mut kept: Option<(f64, Vec<usize>)> = None;
        for sign in [-1, 1] {
            let best = cheapest(&cands, n, |c| first_swing_sign(&c.sol.x) == sign);
            if let Some(b) = best.into_iter().collect::<Option<Vec<usize>>>() {
                let total: f64 = b.iter().map(|&i| cands[i].sol.cost).sum();
                if kept.as_ref().is_none_or(|(t, _)| total < *t) {
                    kept = Some((total, b));
                }
            }
        }
        let kept = match kept {
            Some((_, b)) => b,
            None => cheapest(&cands, n, |_| true)
                .into_iter()
                .map(|b| b.expect("a run per start"))
                .collect(),
        };
        Ok((cands, kept))
    }

    pub(super) fn run_policy(
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
            entropy: Vec::with_capacity(steps),
            alpha_deviation: Vec::with_capacity(steps),
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
            out.control_cost += 0.5 * CONTROL_WEIGHT * u[0] * u[0] * self.dt;
            out.us.push(u[0]);
            out.alpha1.push(alpha[0]);
            out.entropy.push(normalized_entropy(&alpha));
            out.alpha_deviation
                .push(alpha_deviation(&alpha, &blend.weights));
            out.xs.push(x.clone());
        }
        Ok(out)
    }
}

/// Index of the cheapest run per start among those passing `filter` (the first on ties).
pub(super) fn cheapest(
    cands: &[Candidate],
    n: usize,
    filter: impl Fn(&Candidate) -> bool,
) -> Vec<Option<usize>> {
    (0..n)
        .map(|s| {
            let mut b: Option<usize> = None;
            for (i, c) in cands.iter().enumerate() {
                if c.start == s && filter(c) && b.is_none_or(|j| c.sol.cost < cands[j].sol.cost) {
                    b = Some(i);
                }
            }
            b
        })
        .collect()
}

/// A state component beyond this magnitude (rad or rad/s) counts as a diverged closed loop.
const DIVERGED: f64 = 1e4;

/// A compared policy: a tracker alone, or the two combined.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Policy {
    /// The first tracker alone.
    Tracker1,
    /// The second tracker alone.
    Tracker2,
    /// The naive blend, the weighted average (w_i / Σw).
    Naive,
    /// Linear Bellman combination.
    Lbc,
    /// The naive blend as the paper writes it, the weighted sum.
    NaiveSum,
}

impl Policy {
    /// Every policy, in table order.
    pub(super) const ALL: [Policy; 5] = [
        Policy::Tracker1,
        Policy::Tracker2,
        Policy::Naive,
        Policy::Lbc,
        Policy::NaiveSum,
    ];

    /// Its name in the tables.
    pub(super) const fn name(self) -> &'static str {
        match self {
            Policy::Tracker1 => "tracker1",
            Policy::Tracker2 => "tracker2",
            Policy::Naive => "naive",
            Policy::Lbc => "lbc",
            Policy::NaiveSum => "naive_sum",
        }
    }

    /// How it blends the trackers.
    pub(super) fn mode(self) -> BlendMode {
        match self {
            Policy::Tracker1 => BlendMode::Single(0),
            Policy::Tracker2 => BlendMode::Single(1),
            Policy::Naive => BlendMode::Naive,
            Policy::Lbc => BlendMode::Lbc,
            Policy::NaiveSum => BlendMode::Sum,
        }
    }
}

/// The compared policies' names, in table order ([`Policy::ALL`]).
pub(super) const POLICIES: [&str; 5] = [
    Policy::ALL[0].name(),
    Policy::ALL[1].name(),
    Policy::ALL[2].name(),
    Policy::ALL[3].name(),
    Policy::ALL[4].name(),
];

/// The blend mode of the `i`-th policy of [`POLICIES`].
pub(super) fn mode(i: usize) -> BlendMode {
    Policy::ALL[i].mode()
}

/// Index in `POLICIES` of the policy of `m` (inverse of [`mode`] on its range).
pub(super) fn mode_index(m: BlendMode) -> usize {
    (0..POLICIES.len())
        .find(|&i| mode(i) == m)
        .expect("a policy per mode")
}
