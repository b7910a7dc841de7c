//! # Time integrators
//!
//! All integrators advance ẋ = f(x, u) over an interval `dt` with `u` held constant:
//!
//! - **explicit Euler** (order 1): x ← x + dt·f(x).
//! - **semi-implicit (symplectic) Euler** (order 1, bounded energy error): for `x = [q, q̇]`,
//!   q̇ ← q̇ + dt·q̈(q, q̇), then q ← q + dt·q̇ (new velocity).
//! - **classic RK4** (order 4).
//! - **Dormand–Prince 5(4)** as a fixed-step fifth-order method (`dopri5`), and
//! - **adaptive RK45**: the same embedded pair with error control
//!   err = ‖e_i / (atol + rtol·max(|x_i|, |x̃_i|))‖_rms, accepted when err ≤ 1, next step
//!   h·min(5, max(0.2, 0.9·err^(−1/5))). The step size carries over between calls.
//!
//! Scratch buffers are allocated once, in [`Integrator::new`]; stepping never allocates.
//!
//! ## References
//! - J. R. Dormand, P. J. Prince, *A family of embedded Runge–Kutta formulae*, J. Comp. Appl.
//!   Math. 6 (1980).
//! - E. Hairer, S. P. Nørsett, G. Wanner, *Solving Ordinary Differential Equations I*, §II.4.

use super::Ode;
use serde::{Deserialize, Serialize};

/// Which integration scheme to use.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Hash)]
#[serde(rename_all = "snake_case")]
pub enum IntegratorKind {
    /// Explicit (forward) Euler, order 1.
    Euler,
    /// Semi-implicit (symplectic) Euler, order 1; needs a `[q, q̇]` state.
    SemiImplicitEuler,
    /// Classic fourth-order Runge–Kutta.
    Rk4,
    /// Dormand–Prince fifth-order solution at a fixed step.
    Dopri5,
    /// Adaptive Dormand–Prince 5(4) with error control.
    Rk45,
}

impl IntegratorKind {
    /// All kinds, in the order tables list them.
    pub const ALL: [IntegratorKind; 5] = [
        IntegratorKind::Euler,
        IntegratorKind::SemiImplicitEuler,
        IntegratorKind::Rk4,
        IntegratorKind::Dopri5,
        IntegratorKind::Rk45,
    ];

    /// The snake_case name used in experiment files and CSVs.
    pub fn name(self) -> &'static str {
        match self {
            IntegratorKind::Euler => "euler",
            IntegratorKind::SemiImplicitEuler => "semi_implicit_euler",
            IntegratorKind::Rk4 => "rk4",
            IntegratorKind::Dopri5 => "dopri5",
            IntegratorKind::Rk45 => "rk45",
        }
    }

    /// Parses a snake_case name.
    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|k| k.name() == name)
    }

    /// Theoretical global order of accuracy (for the adaptive method, that of its solution).
    pub fn order(self) -> u32 {
        match self {
            IntegratorKind::Euler | IntegratorKind::SemiImplicitEuler => 1,
            IntegratorKind::Rk4 => 4,
            IntegratorKind::Dopri5 | IntegratorKind::Rk45 => 5,
        }
    }
}

/// Counters of the adaptive integrator.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Rk45Stats {
    /// Accepted internal steps.
    pub accepted: u64,
    /// Rejected internal steps.
    pub rejected: u64,
    /// Calls to the right-hand side f(x, u).
    pub evaluations: u64,
}

/// An integrator of a given kind with its scratch buffers.
#[derive(Debug, Clone)]
pub struct Integrator {
    kind: IntegratorKind,
    /// Relative tolerance of the adaptive method.
    pub rtol: f64,
    /// Absolute tolerance of the adaptive method.
    pub atol: f64,
    /// Smallest internal step the adaptive method takes before accepting regardless (s).
    pub min_step: f64,
    n: usize,
    scratch: Vec<f64>,
    h: f64,
    stats: Rk45Stats,
    fsal: Fsal,
}

/// "First same as last" reuse of the Dormand–Prince first stage: k1 = f(x, u) is kept with
/// the exact bits of the `x` and `u` it was computed for, so that a trial step from the same
/// state and control (the next step after an accepted one, whose k7 = f(x_new, u) is k1 of
/// the next step; a retry after a rejection; a later call continuing from where the last one
/// stopped) skips that evaluation. The model is a pure function of (x, u), so the result is
/// bit-identical to evaluating again.
#[derive(Debug, Clone, Default)]
struct Fsal {
    enabled: bool,
    valid: bool,
    x: Vec<f64>,
    u: Vec<f64>,
}

impl Fsal {
    /// Whether the stored k1 was computed at exactly `x`, `u`.
    fn hit(&self, x: &[f64], u: &[f64]) -> bool {
        let same = |a: &[f64], b: &[f64]| {
            a.len() == b.len() && a.iter().zip(b).all(|(p, q)| p.to_bits() == q.to_bits())
        };
        self.enabled && self.valid && same(&self.x, x) && same(&self.u, u)
    }

    /// Records that k1 now holds f(x, u).
    fn store(&mut self, x: &[f64], u: &[f64]) {
        if self.enabled {
            self.x.clear();
            self.x.extend_from_slice(x);
            self.u.clear();
            self.u.extend_from_slice(u);
            self.valid = true;
        }
    }
}

// Dormand–Prince tableau (the system is autonomous, so the nodes c_i are not needed).
const A21: f64 = 1.0 / 5.0;
const A31: f64 = 3.0 / 40.0;
const A32: f64 = 9.0 / 40.0;
const A41: f64 = 44.0 / 45.0;
const A42: f64 = -56.0 / 15.0;
const A43: f64 = 32.0 / 9.0;
const A51: f64 = 19372.0 / 6561.0;
const A52: f64 = -25360.0 / 2187.0;
const A53: f64 = 64448.0 / 6561.0;
const A54: f64 = -212.0 / 729.0;
const A61: f64 = 9017.0 / 3168.0;
const A62: f64 = -355.0 / 33.0;
const A63: f64 = 46732.0 / 5247.0;
const A64: f64 = 49.0 / 176.0;
const A65: f64 = -5103.0 / 18656.0;
const B1: f64 = 35.0 / 384.0;
const B3: f64 = 500.0 / 1113.0;
const B4: f64 = 125.0 / 192.0;
const B5: f64 = -2187.0 / 6784.0;
const B6: f64 = 11.0 / 84.0;
const E1: f64 = 71.0 / 57600.0;
const E3: f64 = -71.0 / 16695.0;
const E4: f64 = 71.0 / 1920.0;
const E5: f64 = -17253.0 / 339200.0;
const E6: f64 = 22.0 / 525.0;
const E7: f64 = -1.0 / 40.0;

impl Integrator {
    /// Creates an integrator for states of dimension `n`.
    pub fn new(kind: IntegratorKind, n: usize) -> Self {
        Self {
            kind,
            rtol: 1e-6,
            atol: 1e-9,
            min_step: 1e-10,
            n,
            scratch: vec![0.0; 9 * n],
            h: f64::INFINITY,
            stats: Rk45Stats::default(),
            fsal: Fsal::default(),
        }
    }

    /// Reuses the Dormand–Prince first stage across trial steps and calls ("first same as
    /// last"; Rk45 and Dopri5 kinds): f(x, u) is not evaluated again for the exact `x` and `u`
    /// of the last evaluation kept. Results are bit-identical and [`Rk45Stats::evaluations`]
    /// counts only the evaluations made. Valid only while every call passes the same model
    /// (or an identical one): the cache is keyed on `x` and `u`, not on the model.
    pub fn with_fsal(mut self) -> Self {
        self.fsal.enabled = true;
        self.fsal.x.reserve(self.n);
        self
    }

    /// Sets the adaptive method's tolerances.
    pub fn with_tolerances(mut self, rtol: f64, atol: f64) -> Self {
        self.rtol = rtol;
        self.atol = atol;
        self
    }

    /// The scheme.
    pub fn kind(&self) -> IntegratorKind {
        self.kind
    }

    /// Counters (meaningful for the Runge–Kutta kinds).
    pub fn stats(&self) -> Rk45Stats {
        self.stats
    }

    /// Advances `x` by `dt` seconds with control `u` held constant.
    pub fn step<M: Ode + ?Sized>(&mut self, model: &M, x: &mut [f64], u: &[f64], dt: f64) {
        debug_assert_eq!(x.len(), self.n);
        match self.kind {
            IntegratorKind::Euler => self.euler(model, x, u, dt),
            IntegratorKind::SemiImplicitEuler => self.semi_implicit(model, x, u, dt),
            IntegratorKind::Rk4 => self.rk4(model, x, u, dt),
            IntegratorKind::Dopri5 => {
                self.dopri_trial(model, x, u, dt, false);
                let n = self.n;
                x.copy_from_slice(&self.scratch[7 * n..8 * n]);
            }
            IntegratorKind::Rk45 => self.adaptive(model, x, u, dt),
        }
    }

    fn euler<M: Ode + ?Sized>(&mut self, model: &M, x: &mut [f64], u: &[f64], dt: f64) {
        let k = &mut self.scratch[..self.n];
        model.derivative(x, u, k);
        self.stats.evaluations += 1;
        for (xi, ki) in x.iter_mut().zip(k.iter()) {
            *xi += dt * ki;
        }
    }

    fn semi_implicit<M: Ode + ?Sized>(&mut self, model: &M, x: &mut [f64], u: &[f64], dt: f64) {
        let nq = model
            .position_dim()
            .expect("semi-implicit Euler needs a model whose state is [q, qdot]");
        let k = &mut self.scratch[..self.n];
        model.derivative(x, u, k);
        self.stats.evaluations += 1;
        for i in 0..nq {
            x[nq + i] += dt * k[nq + i];
        }
        for i in 0..nq {
            x[i] += dt * x[nq + i];
        }
    }

    fn rk4<M: Ode + ?Sized>(&mut self, model: &M, x: &mut [f64], u: &[f64], dt: f64) {
        let n = self.n;
        let (k1, rest) = self.scratch.split_at_mut(n);
        let (k2, rest) = rest.split_at_mut(n);
        let (k3, rest) = rest.split_at_mut(n);
        let (k4, rest) = rest.split_at_mut(n);
        let tmp = &mut rest[..n];
        model.derivative(x, u, k1);
        for i in 0..n {
            tmp[i] = x[i] + 0.5 * dt * k1[i];
        }
        model.derivative(tmp, u, k2);
        for i in 0..n {
            tmp[i] = x[i] + 0.5 * dt * k2[i];
        }
        model.derivative(tmp, u, k3);
        for i in 0..n {
            tmp[i] = x[i] + dt * k3[i];
        }
        model.derivative(tmp, u, k4);
        self.stats.evaluations += 4;
        for i in 0..n {
            x[i] += dt / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
        }
    }

    /// One Dormand–Prince trial step of size `h` from `x`: the fifth-order result goes to
    /// scratch block 7; with `want_error`, returns the scaled RMS error estimate.
    ///
    /// Compiled a second time with AVX2 and chosen where the processor has it: the stage
    /// combinations and the error's divisions then take 4 values an instruction. Each value
    /// is the same IEEE operations in the same order either way (the compiler neither fuses
    /// nor reorders them; the error's sum of squares stays one sequential sum), so the same
    /// bits.
    fn dopri_trial<M: Ode + ?Sized>(
        &mut self,
        model: &M,
        x: &[f64],
        u: &[f64],
        h: f64,
        want_error: bool,
    ) -> f64 {
        #[cfg(target_arch = "x86_64")]
        {
            #[target_feature(enable = "avx2")]
            fn avx2<M: Ode + ?Sized>(
                it: &mut Integrator,
                model: &M,
                x: &[f64],
                u: &[f64],
                h: f64,
                want_error: bool,
            ) -> f64 {
                it.dopri_body(model, x, u, h, want_error)
            }
            if crate::simd::avx2() {
                // SAFETY: the processor supports AVX2 (checked just above).
                return unsafe { avx2(self, model, x, u, h, want_error) };
            }
        }
        self.dopri_body(model, x, u, h, want_error)
    }

    /// [`Integrator::dopri_trial`]'s body, for each instruction set.
    #[inline(always)]
    fn dopri_body<M: Ode + ?Sized>(
        &mut self,
        model: &M,
        x: &[f64],
        u: &[f64],
        h: f64,
        want_error: bool,
    ) -> f64 {
        let n = self.n;
        let (k1, rest) = self.scratch.split_at_mut(n);
        let (k2, rest) = rest.split_at_mut(n);
        let (k3, rest) = rest.split_at_mut(n);
        let (k4, rest) = rest.split_at_mut(n);
        let (k5, rest) = rest.split_at_mut(n);
        let (k6, rest) = rest.split_at_mut(n);
        let (k7, rest) = rest.split_at_mut(n);
        let (xn, rest) = rest.split_at_mut(n);
        let tmp = &mut rest[..n];
        let x = &x[..n];
        if self.fsal.hit(x, u) {
            // k1 already holds f(x, u).
        } else {
            model.derivative(x, u, k1);
            self.stats.evaluations += 1;
            self.fsal.store(x, u);
        }
        for i in 0..n {
            tmp[i] = x[i] + h * A21 * k1[i];
        }
        model.derivative(tmp, u, k2);
        for i in 0..n {
            tmp[i] = x[i] + h * (A31 * k1[i] + A32 * k2[i]);
        }
        model.derivative(tmp, u, k3);
        for i in 0..n {
            tmp[i] = x[i] + h * (A41 * k1[i] + A42 * k2[i] + A43 * k3[i]);
        }
        model.derivative(tmp, u, k4);
        for i in 0..n {
            tmp[i] = x[i] + h * (A51 * k1[i] + A52 * k2[i] + A53 * k3[i] + A54 * k4[i]);
        }
        model.derivative(tmp, u, k5);
        for i in 0..n {
            tmp[i] =
                x[i] + h * (A61 * k1[i] + A62 * k2[i] + A63 * k3[i] + A64 * k4[i] + A65 * k5[i]);
        }
        model.derivative(tmp, u, k6);
        for i in 0..n {
            xn[i] = x[i] + h * (B1 * k1[i] + B3 * k3[i] + B4 * k4[i] + B5 * k5[i] + B6 * k6[i]);
        }
        self.stats.evaluations += 5;
        if !want_error {
            return 0.0;
        }
        model.derivative(xn, u, k7);
        self.stats.evaluations += 1;
        // Each scaled error first (independent divisions), then their squares summed in order.
        for i in 0..n {
            let e =
                h * (E1 * k1[i] + E3 * k3[i] + E4 * k4[i] + E5 * k5[i] + E6 * k6[i] + E7 * k7[i]);
            let sc = self.atol + self.rtol * x[i].abs().max(xn[i].abs());
            tmp[i] = e / sc;
        }
        let sum = tmp.iter().fold(0.0, |sum, q| sum + q * q);
        (sum / n.max(1) as f64).sqrt()
    }

    fn adaptive<M: Ode + ?Sized>(&mut self, model: &M, x: &mut [f64], u: &[f64], dt: f64) {
        let n = self.n;
        let mut t = 0.0;
        let mut h = self.h.min(dt);
        while t < dt {
            let last = t + h >= dt * (1.0 - 1e-12);
            let hh = if last { dt - t } else { h };
            let err = self.dopri_trial(model, x, u, hh, true);
            let accept = err <= 1.0 || hh <= self.min_step;
            let factor = if err == 0.0 {
                5.0
            } else if err.is_finite() {
                (0.9 * crate::portable::powf(err, -0.2)).clamp(0.2, 5.0)
            } else {
                0.2
            };
            if accept {
                x.copy_from_slice(&self.scratch[7 * n..8 * n]);
                if self.fsal.enabled {
                    // k7 = f(x_new, u) is the next step's k1.
                    self.scratch.copy_within(6 * n..7 * n, 0);
                    self.fsal.store(x, u);
                }
                t += hh;
                self.stats.accepted += 1;
                // Keep the proposed size for the next call unless this was a clipped last step.
                if !last || hh >= h {
                    self.h = (hh * factor).max(self.min_step);
                }
                h = (hh * factor).max(self.min_step);
                if last {
                    break;
                }
            } else {
                self.stats.rejected += 1;
                h = (hh * factor).max(self.min_step);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::physics::{Model, Parameter};

    /// Harmonic oscillator q̈ = −q, exact solution q = cos t.
    struct Oscillator;
    impl Model for Oscillator {
        fn name(&self) -> &str {
            "oscillator"
        }
        fn state_names(&self) -> Vec<String> {
            vec!["q".into(), "v".into()]
        }
        fn control_names(&self) -> Vec<String> {
            vec![]
        }
        fn parameters(&self) -> Vec<Parameter> {
            vec![]
        }
        fn default_dt(&self) -> f64 {
            0.01
        }
    }
    impl Ode for Oscillator {
        fn derivative(&self, x: &[f64], _u: &[f64], dx: &mut [f64]) {
            dx[0] = x[1];
            dx[1] = -x[0];
        }
        fn position_dim(&self) -> Option<usize> {
            Some(1)
        }
    }

    fn error_at(kind: IntegratorKind, dt: f64) -> f64 {
        let mut integ = Integrator::new(kind, 2);
        let mut x = [1.0, 0.0];
        let steps = (2.0 / dt).round() as usize;
        for _ in 0..steps {
            integ.step(&Oscillator, &mut x, &[], dt);
        }
        let t = steps as f64 * dt;
        ((x[0] - t.cos()).powi(2) + (x[1] + t.sin()).powi(2)).sqrt()
    }

    #[test]
    fn measured_orders_match_theory() {
        for kind in [
            IntegratorKind::Euler,
            IntegratorKind::SemiImplicitEuler,
            IntegratorKind::Rk4,
            IntegratorKind::Dopri5,
        ] {
            let (h1, h2) = (0.04, 0.02);
            let order = (error_at(kind, h1) / error_at(kind, h2)).log2();
            assert!(
                (order - kind.order() as f64).abs() < 0.25,
                "{:?}: measured order {order}",
                kind
            );
        }
    }

    #[test]
    fn adaptive_meets_tolerance_and_counts_steps() {
        let mut integ = Integrator::new(IntegratorKind::Rk45, 2).with_tolerances(1e-9, 1e-12);
        let mut x = [1.0, 0.0];
        integ.step(&Oscillator, &mut x, &[], 3.0);
        assert!((x[0] - 3f64.cos()).abs() < 1e-7, "{}", x[0] - 3f64.cos());
        assert!(integ.stats().accepted > 5);
        // Tighter tolerance means more steps.
        let mut loose = Integrator::new(IntegratorKind::Rk45, 2).with_tolerances(1e-4, 1e-7);
        let mut y = [1.0, 0.0];
        loose.step(&Oscillator, &mut y, &[], 3.0);
        assert!(loose.stats().accepted < integ.stats().accepted);
    }

    /// A damped oscillator driven by its control: q̈ = −q − 0.3 q̇ + u.
    struct Driven;
    impl Model for Driven {
        fn name(&self) -> &str {
            "driven"
        }
        fn state_names(&self) -> Vec<String> {
            vec!["q".into(), "v".into()]
        }
        fn control_names(&self) -> Vec<String> {
            vec!["u".into()]
        }
        fn parameters(&self) -> Vec<Parameter> {
            vec![]
        }
        fn default_dt(&self) -> f64 {
            0.01
        }
    }
    impl Ode for Driven {
        fn derivative(&self, x: &[f64], u: &[f64], dx: &mut [f64]) {
            dx[0] = x[1];
            dx[1] = -x[0] - 0.3 * x[1] + u[0];
        }
    }

    #[test]
    fn fsal_reuse_is_bit_identical_and_saves_evaluations() {
        // Calls that continue from the last state, a control change, and a state changed
        // from outside between calls (as an impact does): the same bits either way.
        let mut plain = Integrator::new(IntegratorKind::Rk45, 2).with_tolerances(1e-8, 1e-10);
        let mut fsal = plain.clone().with_fsal();
        let (mut x, mut y) = ([1.0, 0.0], [1.0, 0.0]);
        for k in 0..40 {
            let u = [if (k / 10) % 2 == 0 { 0.5 } else { -0.5 }];
            if k == 25 {
                x[1] = 0.0;
                y[1] = 0.0;
            }
            plain.step(&Driven, &mut x, &u, 0.1);
            fsal.step(&Driven, &mut y, &u, 0.1);
            assert_eq!(x.map(f64::to_bits), y.map(f64::to_bits), "call {k}");
        }
        let (a, b) = (plain.stats(), fsal.stats());
        assert_eq!((a.accepted, a.rejected), (b.accepted, b.rejected));
        assert_eq!(a.evaluations, 7 * (a.accepted + a.rejected));
        // Each trial step evaluates 6 stages instead of 7; k1 is evaluated only for a new
        // (x, u): the first call, the three control changes and the state change.
        assert_eq!(b.evaluations, 6 * (b.accepted + b.rejected) + 5, "{b:?}");
    }

    #[test]
    fn dispatched_dopri_trial_is_the_plain_body_bit_for_bit() {
        // The trial as called (compiled for AVX2 where the processor has it) against its body
        // compiled for the baseline, and its error against the sum of squares written as one
        // loop, (e/sc)² added in order, over many states and step sizes.
        // The pyramid lattice on the floor: 30 state values, so the 4-lane loops have a tail.
        use crate::physics::lattice::{Lattice, LatticeModel};
        use rand::{Rng, SeedableRng};
        let model = LatticeModel::new(Lattice::pyramid()).unwrap();
        let n = 30;
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let base = Integrator::new(IntegratorKind::Rk45, n).with_tolerances(1e-6, 1e-9);
        for trial in 0..500 {
            let mut x = model.lattice.resting_state();
            for v in x.iter_mut() {
                *v += rng.random_range(-0.1..0.1);
            }
            let h = 10f64.powf(rng.random_range(-5.0..-1.0));
            let (mut a, mut b) = (base.clone(), base.clone());
            let ea = a.dopri_trial(&model, &x, &[], h, true);
            let eb = b.dopri_body(&model, &x, &[], h, true);
            assert_eq!(ea.to_bits(), eb.to_bits(), "trial {trial}");
            let bits = |s: &[f64]| s.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
            assert_eq!(
                bits(&a.scratch[..8 * n]),
                bits(&b.scratch[..8 * n]),
                "trial {trial}"
            );
            let k = |j: usize, i: usize| a.scratch[j * n + i];
            let mut sum = 0.0;
            for (i, xi) in x.iter().enumerate() {
                let e = h
                    * (E1 * k(0, i)
                        + E3 * k(2, i)
                        + E4 * k(3, i)
                        + E5 * k(4, i)
                        + E6 * k(5, i)
                        + E7 * k(6, i));
                let sc = a.atol + a.rtol * xi.abs().max(k(7, i).abs());
                sum += (e / sc) * (e / sc);
            }
            assert_eq!(
                ea.to_bits(),
                (sum / n as f64).sqrt().to_bits(),
                "trial {trial}"
            );
        }
    }

    #[test]
    fn names_round_trip() {
        for k in IntegratorKind::ALL {
            assert_eq!(IntegratorKind::from_name(k.name()), Some(k));
        }
        assert_eq!(IntegratorKind::from_name("leapfrog"), None);
    }
}
