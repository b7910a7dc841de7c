//! # Random controllers and the perturbation mix (Christensen, Marks, Ngo 1995, §2.3, Table 2)
//!
//! Initialization and "pick a new …" perturbations draw regime times uniformly from
//! [0, t_per], reflex numbers uniformly from 0..=11, and reflex coefficients from the
//! arcsine distribution on [−1, 1], α = −cos(π U) with U uniform on [0, 1): its density
//! 1 / (π √(1 − α²)) is smallest at 0 and grows without bound toward ±1, so exaggerated
//! movements are more likely than twitches (the paper asks only for a distribution favouring
//! the extremes). "Adjust" perturbations multiply the value by 1 + u with u uniform on
//! (−0.1, 0.1) ("a random factor less than 10%"), clamped back into range.
//!
//! The kinds and probabilities of Table 2 are [`PERTURBATIONS`]; [`perturb`] draws one kind
//! and applies it.

use super::controller::{Controller, Regime};
use crate::physics::reflex::Reflex;
use rand::Rng;
use std::f64::consts::PI;

/// A kind of perturbation of Table 2.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Perturbation {
    /// Pick a new reflex number for one regime.
    NewReflexOne,
    /// Pick a new reflex number for every regime.
    NewReflexAll,
    /// Pick a new reflex coefficient for one regime.
    NewAlphaOne,
    /// Pick a new reflex coefficient for every regime.
    NewAlphaAll,
    /// Adjust a reflex coefficient for one regime.
    AdjustAlphaOne,
    /// Adjust a reflex coefficient for every regime.
    AdjustAlphaAll,
    /// Pick a new regime time for one regime.
    NewTimeOne,
    /// Pick a new regime time for every regime.
    NewTimeAll,
    /// Adjust a regime time for one regime.
    AdjustTimeOne,
    /// Adjust a regime time for every regime.
    AdjustTimeAll,
}

/// Table 2: every perturbation with its probability (they sum to 1).
pub const PERTURBATIONS: [(Perturbation, f64); 10] = [
    (Perturbation::NewReflexOne, 0.32),
    (Perturbation::NewReflexAll, 0.08),
    (Perturbation::NewAlphaOne, 0.10),
    (Perturbation::NewAlphaAll, 0.02),
    (Perturbation::AdjustAlphaOne, 0.22),
    (Perturbation::AdjustAlphaAll, 0.06),
    (Perturbation::NewTimeOne, 0.05),
    (Perturbation::NewTimeAll, 0.01),
    (Perturbation::AdjustTimeOne, 0.11),
    (Perturbation::AdjustTimeAll, 0.03),
];

/// Largest relative change of an "adjust" perturbation.
pub const ADJUST_FRACTION: f64 = 0.1;

/// A reflex coefficient from the arcsine distribution on [−1, 1] (favours the extremes).
pub fn random_alpha<R: Rng + ?Sized>(rng: &mut R) -> f64 {
    -crate::portable::cos(PI * rng.random::<f64>())
}

/// A random regime for period `period`.
pub fn random_regime<R: Rng + ?Sized>(rng: &mut R, period: f64) -> Regime {
    Regime {
        time: rng.random::<f64>() * period,
        reflex: rng.random_range(0..Reflex::COUNT),
        alpha: random_alpha(rng),
    }
}

/// A random controller with `regimes` regimes and period `period`.
pub fn random_controller<R: Rng + ?Sized>(rng: &mut R, regimes: usize, period: f64) -> Controller {
    Controller {
        period,
        regimes: (0..regimes).map(|_| random_regime(rng, period)).collect(),
    }
}

/// Draws a perturbation kind with the probabilities of Table 2.
pub fn draw_kind<R: Rng + ?Sized>(rng: &mut R) -> Perturbation {
    let u: f64 = rng.random();
    let mut acc = 0.0;
    for &(k, p) in &PERTURBATIONS {
        acc += p;
        if u < acc {
            return k;
        }
    }
    PERTURBATIONS[PERTURBATIONS.len() - 1].0
}

fn adjust<R: Rng + ?Sized>(rng: &mut R, v: f64, lo: f64, hi: f64) -> f64 {
    let f = 1.0 + rng.random_range(-ADJUST_FRACTION..ADJUST_FRACTION);
    (v * f).clamp(lo, hi)
}

/// Applies perturbation `kind` to `c` in place.
pub fn apply<R: Rng + ?Sized>(rng: &mut R, c: &mut Controller, kind: Perturbation) {
    use Perturbation::*;
    let period = c.period;
    let n = c.regimes.len();
    if n == 0 {
        return;
    }
    let one = matches!(
        kind,
        NewReflexOne | NewAlphaOne | AdjustAlphaOne | NewTimeOne | AdjustTimeOne
    );
    let targets: Vec<usize> = if one {
        vec![rng.random_range(0..n)]
    } else {
        (0..n).collect()
    };
    for i in targets {
        let r = &mut c.regimes[i];
        match kind {
            NewReflexOne | NewReflexAll => r.reflex = rng.random_range(0..Reflex::COUNT),
            NewAlphaOne | NewAlphaAll => r.alpha = random_alpha(rng),
            AdjustAlphaOne | AdjustAlphaAll => r.alpha = adjust(rng, r.alpha, -1.0, 1.0),
            NewTimeOne | NewTimeAll => r.time = rng.random::<f64>() * period,
            AdjustTimeOne | AdjustTimeAll => r.time = adjust(rng, r.time, 0.0, period),
        }
    }
}

/// A perturbed copy of `c` (kind drawn from Table 2) and the kind applied.
pub fn perturb<R: Rng + ?Sized>(rng: &mut R, c: &Controller) -> (Controller, Perturbation) {
    let kind = draw_kind(rng);
    let mut out = c.clone();
    apply(rng, &mut out, kind);
    (out, kind)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn probabilities_sum_to_one() {
        let s: f64 = PERTURBATIONS.iter().map(|p| p.1).sum();
        assert!((s - 1.0).abs() < 1e-12);
    }

    #[test]
    fn perturbation_mix_matches_table2_chi_square() {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let n = 200_000;
        let mut counts = [0usize; 10];
        for _ in 0..n {
            let k = draw_kind(&mut rng);
            let i = PERTURBATIONS.iter().position(|p| p.0 == k).unwrap();
            counts[i] += 1;
        }
        let chi2: f64 = counts
            .iter()
            .zip(&PERTURBATIONS)
            .map(|(&c, &(_, p))| {
                let e = p * n as f64;
                (c as f64 - e).powi(2) / e
            })
            .sum();
        // 9 degrees of freedom: the 0.999 quantile is 27.88.
        assert!(chi2 < 27.88, "chi2 = {chi2}, counts {counts:?}");
        // And through `perturb`: the kind drawn is the one applied.
        let c = random_controller(&mut rng, 4, 1.0);
        let (p, kind) = perturb(&mut rng, &c);
        p.validate().unwrap();
        let _ = kind;
    }

    #[test]
    fn alpha_favours_the_extremes() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let n = 100_000;
        let draws: Vec<f64> = (0..n).map(|_| random_alpha(&mut rng)).collect();
        assert!(draws.iter().all(|a| (-1.0..=1.0).contains(a)));
        let outer = draws.iter().filter(|a| a.abs() > 0.8).count() as f64 / n as f64;
        let inner = draws.iter().filter(|a| a.abs() < 0.2).count() as f64 / n as f64;
        // Arcsine: P(|α| > 0.8) = 1 − (2/π) asin(0.8) ≈ 0.410, P(|α| < 0.2) ≈ 0.128.
        assert!((outer - 0.4097).abs() < 0.01, "{outer}");
        assert!((inner - 0.1282).abs() < 0.01, "{inner}");
        let mean: f64 = draws.iter().sum::<f64>() / n as f64;
        assert!(mean.abs() < 0.01);
    }

    #[test]
    fn each_kind_changes_what_it_says_and_stays_in_range() {
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let base = random_controller(&mut rng, 6, 2.0);
        for &(kind, _) in &PERTURBATIONS {
            for _ in 0..200 {
                let mut c = base.clone();
                apply(&mut rng, &mut c, kind);
                c.validate().unwrap();
                let changed: Vec<usize> = (0..6)
                    .filter(|&i| c.regimes[i] != base.regimes[i])
                    .collect();
                let all = format!("{kind:?}").ends_with("All");
                assert!(changed.len() <= if all { 6 } else { 1 }, "{kind:?}");
                for i in 0..6 {
                    let (a, b) = (c.regimes[i], base.regimes[i]);
                    let name = format!("{kind:?}");
                    if !name.contains("Reflex") {
                        assert_eq!(a.reflex, b.reflex);
                    }
                    if !name.contains("Alpha") {
                        assert_eq!(a.alpha, b.alpha);
                    }
                    if !name.contains("Time") {
                        assert_eq!(a.time, b.time);
                    }
                    if name.starts_with("Adjust") && name.contains("Alpha") {
                        assert!((a.alpha - b.alpha).abs() <= 0.1 * b.alpha.abs() + 1e-12);
                    }
                    if name.starts_with("Adjust") && name.contains("Time") {
                        assert!((a.time - b.time).abs() <= 0.1 * b.time + 1e-12);
                    }
                }
            }
        }
    }
}
