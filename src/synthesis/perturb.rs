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
//! and applies it. Other probabilities are spec keys ([`PerturbationMix`], [`MixSpec`]), and
//! [`apply_to`] perturbs any regime type that has a time, a coefficient and an actuation
//! ([`PerturbRegime`]: a reflex number, or `ms_representation`'s free rest lengths).

use super::controller::{Controller, Regime};
use crate::physics::reflex::Reflex;
use rand::Rng;
use serde::{Deserialize, Serialize};
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

/// Perturbation probabilities, one per kind of Table 2 (the spec's `perturbations` keys);
/// [`PerturbationMix::TABLE_2`] is the paper's.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PerturbationMix {
    /// Pick a new reflex number (or rest-length vector) for one regime.
    pub new_reflex_one: f64,
    /// Pick a new reflex number (or rest-length vector) for every regime.
    pub new_reflex_all: f64,
    /// Pick a new reflex coefficient for one regime.
    pub new_alpha_one: f64,
    /// Pick a new reflex coefficient for every regime.
    pub new_alpha_all: f64,
    /// Adjust a reflex coefficient for one regime.
    pub adjust_alpha_one: f64,
    /// Adjust a reflex coefficient for every regime.
    pub adjust_alpha_all: f64,
    /// Pick a new regime time for one regime.
    pub new_time_one: f64,
    /// Pick a new regime time for every regime.
    pub new_time_all: f64,
    /// Adjust a regime time for one regime.
    pub adjust_time_one: f64,
    /// Adjust a regime time for every regime.
    pub adjust_time_all: f64,
}

impl Default for PerturbationMix {
    fn default() -> Self {
        Self::TABLE_2
    }
}

impl PerturbationMix {
    /// Table 2 of the paper.
    pub const TABLE_2: Self = Self {
        new_reflex_one: 0.32,
        new_reflex_all: 0.08,
        new_alpha_one: 0.10,
        new_alpha_all: 0.02,
        adjust_alpha_one: 0.22,
        adjust_alpha_all: 0.06,
        new_time_one: 0.05,
        new_time_all: 0.01,
        adjust_time_one: 0.11,
        adjust_time_all: 0.03,
    };

    /// Table 2 without the small adjustments: each "adjust" probability moved to the "pick a
    /// new value" of the same quantity and reach (ours, for `ms_search_settings`).
    pub const NEW_VALUES_ONLY: Self = Self {
        new_reflex_one: 0.32,
        new_reflex_all: 0.08,
        new_alpha_one: 0.32,
        new_alpha_all: 0.08,
        adjust_alpha_one: 0.0,
        adjust_alpha_all: 0.0,
        new_time_one: 0.16,
        new_time_all: 0.04,
        adjust_time_one: 0.0,
        adjust_time_all: 0.0,
    };

    /// Table 2 without the disruptive "every regime" kinds: each one's probability moved to
    /// its "one regime" kind (ours, for `ms_search_settings`).
    pub const ONE_REGIME_ONLY: Self = Self {
        new_reflex_one: 0.40,
        new_reflex_all: 0.0,
        new_alpha_one: 0.12,
        new_alpha_all: 0.0,
        adjust_alpha_one: 0.28,
        adjust_alpha_all: 0.0,
        new_time_one: 0.06,
        new_time_all: 0.0,
        adjust_time_one: 0.14,
        adjust_time_all: 0.0,
    };

    /// The named mixes a spec may give as `perturbations = "<name>"`.
    pub const NAMED: [(&'static str, Self); 3] = [
        ("table2", Self::TABLE_2),
        ("new_values_only", Self::NEW_VALUES_ONLY),
        ("one_regime_only", Self::ONE_REGIME_ONLY),
    ];

    /// The mix called `name` ([`Self::NAMED`]).
    pub fn named(name: &str) -> Option<Self> {
        Self::NAMED
            .iter()
            .find(|(n, _)| *n == name)
            .map(|(_, m)| *m)
    }

    /// Every kind with its probability, in the order of Table 2.
    pub fn probabilities(&self) -> [(Perturbation, f64); 10] {
        use Perturbation::*;
        [
            (NewReflexOne, self.new_reflex_one),
            (NewReflexAll, self.new_reflex_all),
            (NewAlphaOne, self.new_alpha_one),
            (NewAlphaAll, self.new_alpha_all),
            (AdjustAlphaOne, self.adjust_alpha_one),
            (AdjustAlphaAll, self.adjust_alpha_all),
            (NewTimeOne, self.new_time_one),
            (NewTimeAll, self.new_time_all),
            (AdjustTimeOne, self.adjust_time_one),
            (AdjustTimeAll, self.adjust_time_all),
        ]
    }

    /// Each probability finite and in [0, 1], summing to 1 within 1e-9.
    pub fn check(&self) -> Result<(), String> {
        let p = self.probabilities();
        if let Some((k, v)) = p
            .iter()
            .find(|(_, v)| !(v.is_finite() && (0.0..=1.0).contains(v)))
        {
            return Err(format!(
                "probability of {k:?} is {v}; each must lie in [0, 1]"
            ));
        }
        let sum: f64 = p.iter().map(|(_, v)| v).sum();
        if (sum - 1.0).abs() > 1e-9 {
            return Err(format!("the probabilities sum to {sum}, not 1"));
        }
        Ok(())
    }

    /// Draws a perturbation kind with these probabilities.
    pub fn draw<R: Rng + ?Sized>(&self, rng: &mut R) -> Perturbation {
        let u: f64 = rng.random();
        let mut acc = 0.0;
        let p = self.probabilities();
        for &(k, q) in &p {
            acc += q;
            if u < acc {
                return k;
            }
        }
        // Rounding left u above the sum: the last kind with a non-zero probability.
        p.iter()
            .rev()
            .find(|(_, q)| *q > 0.0)
            .map_or(p[p.len() - 1].0, |(k, _)| *k)
    }
}

/// The perturbation probabilities of a spec: a named mix ([`PerturbationMix::NAMED`]) or
/// the ten probabilities given one by one.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum MixSpec {
    /// `perturbations = "table2"` (or another name of [`PerturbationMix::NAMED`]).
    Named(String),
    /// `[params.perturbations]` with the ten probabilities.
    Explicit(PerturbationMix),
}

impl Default for MixSpec {
    fn default() -> Self {
        MixSpec::Named("table2".into())
    }
}

impl MixSpec {
    /// The probabilities, or why they are not valid.
    pub fn mix(&self) -> Result<PerturbationMix, String> {
        let m = match self {
            MixSpec::Named(n) => PerturbationMix::named(n).ok_or_else(|| {
                let names: Vec<&str> = PerturbationMix::NAMED.iter().map(|(n, _)| *n).collect();
                format!(
                    "unknown mix `{n}` (named mixes: {}; or give the ten probabilities)",
                    names.join(", ")
                )
            })?,
            MixSpec::Explicit(m) => *m,
        };
        m.check()?;
        Ok(m)
    }
}

/// Draws a perturbation kind with the probabilities of Table 2.
pub fn draw_kind<R: Rng + ?Sized>(rng: &mut R) -> Perturbation {
    PerturbationMix::TABLE_2.draw(rng)
}

fn adjust<R: Rng + ?Sized>(rng: &mut R, v: f64, lo: f64, hi: f64) -> f64 {
    let f = 1.0 + rng.random_range(-ADJUST_FRACTION..ADJUST_FRACTION);
    (v * f).clamp(lo, hi)
}

/// What the perturbations of Table 2 change in a regime: its time, its coefficient and its
/// actuation (a reflex number; in the free representation of `ms_representation`, a vector of
/// rest lengths).
pub trait PerturbRegime {
    /// The regime time t_i (s).
    fn time_mut(&mut self) -> &mut f64;
    /// The coefficient α_i ∈ [−1, 1].
    fn alpha_mut(&mut self) -> &mut f64;
    /// "Pick a new reflex": draws a new actuation.
    fn redraw_actuation<R: Rng + ?Sized>(&mut self, rng: &mut R);
}

impl PerturbRegime for Regime {
    fn time_mut(&mut self) -> &mut f64 {
        &mut self.time
    }
    fn alpha_mut(&mut self) -> &mut f64 {
        &mut self.alpha
    }
    fn redraw_actuation<R: Rng + ?Sized>(&mut self, rng: &mut R) {
        self.reflex = rng.random_range(0..Reflex::COUNT);
    }
}

/// Applies perturbation `kind` to the regimes of a controller with period `period`.
pub fn apply_to<R: Rng + ?Sized, G: PerturbRegime>(
    rng: &mut R,
    period: f64,
    regimes: &mut [G],
    kind: Perturbation,
) {
    use Perturbation::*;
    let n = regimes.len();
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
        let r = &mut regimes[i];
        match kind {
            NewReflexOne | NewReflexAll => r.redraw_actuation(rng),
            NewAlphaOne | NewAlphaAll => *r.alpha_mut() = random_alpha(rng),
            AdjustAlphaOne | AdjustAlphaAll => {
                let a = *r.alpha_mut();
                *r.alpha_mut() = adjust(rng, a, -1.0, 1.0)
            }
            NewTimeOne | NewTimeAll => *r.time_mut() = rng.random::<f64>() * period,
            AdjustTimeOne | AdjustTimeAll => {
                let t = *r.time_mut();
                *r.time_mut() = adjust(rng, t, 0.0, period)
            }
        }
    }
}

/// Applies perturbation `kind` to `c` in place.
pub fn apply<R: Rng + ?Sized>(rng: &mut R, c: &mut Controller, kind: Perturbation) {
    apply_to(rng, c.period, &mut c.regimes, kind);
}

/// A perturbed copy of `c` (kind drawn from Table 2) and the kind applied.
pub fn perturb<R: Rng + ?Sized>(rng: &mut R, c: &Controller) -> (Controller, Perturbation) {
    perturb_with(rng, c, &PerturbationMix::TABLE_2)
}

/// A perturbed copy of `c` (kind drawn from `mix`) and the kind applied.
pub fn perturb_with<R: Rng + ?Sized>(
    rng: &mut R,
    c: &Controller,
    mix: &PerturbationMix,
) -> (Controller, Perturbation) {
    let kind = mix.draw(rng);
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
    fn named_mixes_are_valid_and_table2_is_the_constant() {
        assert_eq!(PerturbationMix::TABLE_2.probabilities(), PERTURBATIONS);
        for (name, m) in PerturbationMix::NAMED {
            m.check().unwrap_or_else(|e| panic!("{name}: {e}"));
            assert_eq!(MixSpec::Named(name.into()).mix().unwrap(), m);
        }
        assert!(MixSpec::Named("fast".into()).mix().is_err());
        let bad = PerturbationMix {
            new_reflex_one: 0.5,
            ..PerturbationMix::TABLE_2
        };
        assert!(bad.check().unwrap_err().contains("sum"));
        let neg = PerturbationMix {
            new_reflex_one: -0.1,
            new_reflex_all: 0.5,
            ..PerturbationMix::TABLE_2
        };
        assert!(neg.check().is_err());
        // A spec gives either a name or the ten probabilities.
        #[derive(Deserialize)]
        struct S {
            perturbations: MixSpec,
        }
        let s: S = toml::from_str("perturbations = \"one_regime_only\"").unwrap();
        assert_eq!(
            s.perturbations.mix().unwrap(),
            PerturbationMix::ONE_REGIME_ONLY
        );
        let text = "[perturbations]\nnew_reflex_one = 1.0\nnew_reflex_all = 0.0\nnew_alpha_one = 0.0\nnew_alpha_all = 0.0\nadjust_alpha_one = 0.0\nadjust_alpha_all = 0.0\nnew_time_one = 0.0\nnew_time_all = 0.0\nadjust_time_one = 0.0\nadjust_time_all = 0.0\n";
        let s: S = toml::from_str(text).unwrap();
        let m = s.perturbations.mix().unwrap();
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        assert!((0..1000).all(|_| m.draw(&mut rng) == Perturbation::NewReflexOne));
    }

    #[test]
    fn a_mix_draws_its_kinds_only_and_table2_draws_as_before() {
        let mut a = ChaCha8Rng::seed_from_u64(5);
        let mut b = ChaCha8Rng::seed_from_u64(5);
        for _ in 0..10_000 {
            assert_eq!(draw_kind(&mut a), PerturbationMix::TABLE_2.draw(&mut b));
        }
        let m = PerturbationMix::NEW_VALUES_ONLY;
        let zero: Vec<Perturbation> = m
            .probabilities()
            .iter()
            .filter(|(_, p)| *p == 0.0)
            .map(|(k, _)| *k)
            .collect();
        assert_eq!(zero.len(), 4);
        assert!((0..20_000).all(|_| !zero.contains(&m.draw(&mut a))));
    }

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
