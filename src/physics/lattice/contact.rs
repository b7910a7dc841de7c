//! # Floor contact: friction law and impact events
//!
//! The floor z = 0 ([`Floor`]) has a Coulomb coefficient μ, a larger μ_d along a preferred
//! horizontal direction d (μ_eff = μ + (μ_d − μ)·max(0, ŝ·d) for sliding direction ŝ), a
//! friction time constant τ and contact tolerances ε_z, ε_v. Resting contact and friction are
//! forces of the model's right-hand side (parent module); *impacts* are events:
//! [`LatticeSim`] integrates with adaptive Dormand–Prince RK45 and, when a mass ends an
//! interval below −ε_z, redoes the interval up to the first crossing time, found from the
//! cubic Hermite interpolant of each mass's height,
//!
//! ```text
//! z(s) = h00(s) z₀ + h10(s) h v_z0 + h01(s) z₁ + h11(s) h v_z1,   s ∈ [0, 1],
//! ```
//!
//! then applies the impact impulse: v_z ← 0, |v_t| reduced by at most μ_eff |v_z|, z ← 0.
//!
//! ## References
//! - J. Christensen, J. Marks, J. T. Ngo, *Automatic Motion Synthesis for 3D Mass-Spring
//!   Models*, The Visual Computer 13(1), 1997 (MERL TR95-01), §2.1.
//! - E. Hairer, S. P. Nørsett, G. Wanner, *Solving Ordinary Differential Equations I*,
//!   Springer 1993, §II.6 (dense output, event location).

use super::{LatticeError, LatticeModel};
use crate::physics::integrate::{Integrator, IntegratorKind, Rk45Stats};
use crate::physics::{Dynamics, Model};
use serde::{Deserialize, Serialize};

/// The floor z = 0 and its friction.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Floor {
    /// Coulomb friction coefficient μ for sliding against or across the preferred direction.
    pub friction: f64,
    /// Coulomb friction coefficient μ_d for sliding along the preferred direction (equal to
    /// `friction` for isotropic friction).
    pub preferred_friction: f64,
    /// Preferred horizontal direction d = (x, y) in the world frame (normalized on use).
    pub preferred_direction: [f64; 2],
    /// Time constant τ of the regularized static friction (s): below the Coulomb limit,
    /// friction stops tangential motion within about τ.
    pub stick_time: f64,
    /// Height below which a mass with small normal velocity is in contact (m); also the
    /// penetration tolerated before an impact event is localized.
    pub contact_tolerance: f64,
    /// Normal speed below which a mass near the floor is in resting contact (m/s).
    pub velocity_tolerance: f64,
}

impl Default for Floor {
    fn default() -> Self {
        Self {
            friction: 1.0,
            preferred_friction: 1.0,
            preferred_direction: [1.0, 0.0],
            stick_time: 0.01,
            contact_tolerance: 1e-6,
            velocity_tolerance: 1e-6,
        }
    }
}

impl Floor {
    /// Checks that coefficients are ≥ 0, the direction is non-zero and the time constant and
    /// tolerances are positive.
    // A settings check (a length > 0), no data path.
    #[allow(clippy::disallowed_methods)]
    pub fn validate(&self) -> Result<(), LatticeError> {
        let [dx, dy] = self.preferred_direction;
        for (name, value, ok) in [
            ("friction", self.friction, self.friction >= 0.0),
            (
                "preferred_friction",
                self.preferred_friction,
                self.preferred_friction >= 0.0,
            ),
            ("preferred_direction", dx.hypot(dy), dx.hypot(dy) > 0.0),
            ("stick_time", self.stick_time, self.stick_time > 0.0),
            (
                "contact_tolerance",
                self.contact_tolerance,
                self.contact_tolerance > 0.0,
            ),
            (
                "velocity_tolerance",
                self.velocity_tolerance,
                self.velocity_tolerance > 0.0,
            ),
        ] {
            if !(ok && value.is_finite()) {
                return Err(LatticeError::InvalidFloor(name, value));
            }
        }
        Ok(())
    }

    /// Friction coefficient for sliding in horizontal direction `s` (any length).
    pub fn coefficient(&self, s: [f64; 2]) -> f64 {
        self.coefficient_with_norm(s, self.direction_norm())
    }

    /// |d|, the length of the preferred direction as given.
    pub(super) fn direction_norm(&self) -> f64 {
        let [dx, dy] = self.preferred_direction;
        (dx * dx + dy * dy).sqrt()
    }

    /// [`Floor::coefficient`] with |d| computed beforehand ([`Floor::direction_norm`]).
    pub(super) fn coefficient_with_norm(&self, s: [f64; 2], dn: f64) -> f64 {
        let [dx, dy] = self.preferred_direction;
        let sn = (s[0] * s[0] + s[1] * s[1]).sqrt();
        if dn == 0.0 || sn == 0.0 {
            return self.friction;
        }
        let cos = (s[0] * dx + s[1] * dy) / (sn * dn);
        self.friction + (self.preferred_friction - self.friction) * cos.max(0.0)
    }
}

/// Counters of the contact events of a [`LatticeSim`].
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct ContactStats {
    /// Masses whose normal velocity was removed by an impact.
    pub impacts: u64,
    /// Integration intervals cut short at an impact time.
    pub events: u64,
    /// Re-integrations while localizing impact times.
    pub retries: u64,
    /// Deepest penetration below the floor at the end of an integration interval, before the
    /// impact projection (m, ≥ 0).
    pub deepest: f64,
}

/// Adaptive RK45 integration of a [`LatticeModel`] with impacts handled as events.
///
/// `step(x, u, dt)` integrates with the crate's adaptive Dormand–Prince integrator (step size
/// carried over between calls). When a mass ends an interval more than
/// [`Floor::contact_tolerance`] below the floor, the interval is redone up to the first
/// crossing time, estimated from the cubic Hermite interpolant of each mass's height
/// (z, v_z at both ends); repeated until no mass is below the tolerance. Then the impact
/// impulses are applied (normal velocity removed, tangential velocity reduced by at most
/// μ_eff·|v_z|, height set to 0) and integration continues from there. Between impacts the
/// right-hand side is smooth apart from contact making and breaking, so the step-size control
/// never has to resolve a collision by shrinking its steps.
#[derive(Debug, Clone)]
pub struct LatticeSim {
    /// The model.
    pub model: LatticeModel,
    integrator: Integrator,
    start: Vec<f64>,
    stats: ContactStats,
}

/// Largest number of re-integrations spent localizing one impact.
const MAX_LOCALIZE: usize = 40;

impl LatticeSim {
    /// A simulator with relative tolerance 1e−6 and absolute tolerance 1e−8.
    pub fn new(model: LatticeModel) -> Self {
        let n = model.state_dim();
        Self {
            model,
            integrator: Integrator::new(IntegratorKind::Rk45, n).with_tolerances(1e-6, 1e-8),
            start: vec![0.0; n],
            stats: ContactStats::default(),
        }
    }

    /// Sets the integrator's relative and absolute tolerances.
    pub fn with_tolerances(mut self, rtol: f64, atol: f64) -> Self {
        self.integrator = self.integrator.with_tolerances(rtol, atol);
        self
    }

    /// Reuses the first RK45 stage when a step starts from the exact state and rest lengths
    /// of the last evaluation kept ([`Integrator::with_fsal`]): fewer evaluations, the same
    /// bits. Only while [`Self::model`] is left unchanged between steps.
    pub fn with_fsal(mut self) -> Self {
        self.integrator = self.integrator.with_fsal();
        self
    }

    /// Sets the smallest internal RK45 step (s), below which a step is accepted whatever its
    /// error estimate: bounds the work when contact making and breaking chatters.
    pub fn with_min_step(mut self, min_step: f64) -> Self {
        self.integrator.min_step = min_step;
        self
    }

    /// The integrator's counters (accepted and rejected RK45 steps, evaluations).
    pub fn integrator_stats(&self) -> Rk45Stats {
        self.integrator.stats()
    }

    /// The contact counters.
    pub fn contact_stats(&self) -> ContactStats {
        self.stats
    }

    /// Lowest height (m) of any mass in `x`.
    fn lowest(&self, x: &[f64]) -> f64 {
        let n = self.model.lattice.n_masses();
        (0..n).map(|i| x[3 * i + 2]).fold(f64::INFINITY, f64::min)
    }

    /// Earliest time in (0, h] at which a mass that ends below the tolerance crosses z = 0,
    /// from the cubic Hermite interpolant between `self.start` and `x`.
    fn first_crossing(&self, x: &[f64], h: f64) -> f64 {
        let n = self.model.lattice.n_masses();
        let tol = self.model.floor.contact_tolerance;
        let mut first = h;
        for i in 0..n {
            let (z1, v1) = (x[3 * i + 2], x[3 * n + 3 * i + 2]);
            if z1 >= -tol {
                continue;
            }
            let (z0, v0) = (self.start[3 * i + 2], self.start[3 * n + 3 * i + 2]);
            let z = |s: f64| {
                let (s2, s3) = (s * s, s * s * s);
                (2.0 * s3 - 3.0 * s2 + 1.0) * z0
                    + (s3 - 2.0 * s2 + s) * h * v0
                    + (-2.0 * s3 + 3.0 * s2) * z1
                    + (s3 - s2) * h * v1
            };
            // First sample below the floor, then bisection.
            const SAMPLES: usize = 32;
            let mut lo = 0.0;
            let mut hi = 1.0;
            for k in 1..=SAMPLES {
                let s = k as f64 / SAMPLES as f64;
                if z(s) < 0.0 {
                    hi = s;
                    break;
                }
                lo = s;
            }
            for _ in 0..60 {
                let mid = 0.5 * (lo + hi);
                if z(mid) < 0.0 {
                    hi = mid;
                } else {
                    lo = mid;
                }
            }
            first = first.min(hi * h);
        }
        first
    }

    /// Applies impacts to the masses on or below the floor; returns how many were moving
    /// down faster than the velocity tolerance.
    fn impacts(&mut self, x: &mut [f64]) -> u64 {
        let n = self.model.lattice.n_masses();
        let floor = self.model.floor;
        let mut count = 0;
        for i in 0..n {
            let (iz, iv) = (3 * i + 2, 3 * n + 3 * i);
            let (z, vz) = (x[iz], x[iv + 2]);
            if z < 0.0 {
                x[iz] = 0.0;
            }
            if z <= floor.contact_tolerance && vz < 0.0 {
                x[iz] = 0.0;
                x[iv + 2] = 0.0;
                if vz < -floor.velocity_tolerance {
                    count += 1;
                }
                // Coulomb impulse: the tangential velocity loses at most μ·|Δv_n|.
                let vt = [x[iv], x[iv + 1]];
                let speed = (vt[0] * vt[0] + vt[1] * vt[1]).sqrt();
                if speed > 0.0 {
                    let cut = (floor.coefficient(vt) * -vz).min(speed);
                    x[iv] -= vt[0] / speed * cut;
                    x[iv + 1] -= vt[1] / speed * cut;
                }
            }
        }
        count
    }
}

impl Dynamics for LatticeSim {
    fn state_dim(&self) -> usize {
        self.model.state_dim()
    }
    fn control_dim(&self) -> usize {
        self.model.control_dim()
    }
    fn step(&mut self, x: &mut [f64], u: &[f64], dt: f64) {
        let tol = self.model.floor.contact_tolerance;
        self.stats.impacts += self.impacts(x);
        let mut left = dt;
        while left > 0.0 {
            self.start.copy_from_slice(x);
            let mut h = left;
            self.integrator.step(&self.model, x, u, h);
            let mut tries = 0;
            while self.lowest(x) < -tol && tries < MAX_LOCALIZE {
                let s = self.first_crossing(x, h);
                // Always shrink, so the loop makes progress even on a poor estimate, but never
                // below the integrator's smallest step: a step of f64::MIN_POSITIVE would leave
                // `left` unchanged and loop forever (seen when contact chatters).
                h = s.min(0.9 * h).max(self.integrator.min_step.min(left));
                x.copy_from_slice(&self.start);
                self.integrator.step(&self.model, x, u, h);
                self.stats.retries += 1;
                tries += 1;
            }
            if h < left {
                self.stats.events += 1;
            }
            self.stats.deepest = self.stats.deepest.max(-self.lowest(x));
            self.stats.impacts += self.impacts(x);
            left = if h < left { left - h } else { 0.0 };
        }
    }
}
