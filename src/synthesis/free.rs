//! # Free rest lengths: the representation the paper replaced (MS §2.2)
//!
//! "An earlier, less-compact representation in which an actuation reflex could be an arbitrary
//! combination of spring rest lengths produced less coordinated motions, and the search process
//! was much slower." `ms_representation` tests that sentence, so this module builds the earlier
//! representation as the same controller with the 12 canonical reflexes replaced by arbitrary
//! vectors:
//!
//! - a regime has a time t_i and a coefficient α_i exactly as a reflex regime
//!   ([`super::controller`]), and instead of a reflex number a vector d_i ∈ [−1, 1]^m, one entry
//!   per spring;
//! - while regime i is active spring j's rest length is L_j (1 + κ α_i d_ij), with L_j the
//!   natural rest length and κ the scale reflex's gain (0.5 by default, so each spring ranges
//!   over the same ±50 % as a scaling reflex stretches the lattice along its axis);
//! - initialization and "pick a new reflex" draw every d_ij uniformly from [−1, 1]; times and
//!   coefficients are drawn and adjusted as for reflexes, with the same perturbation mix
//!   ([`super::perturb::apply_to`]), so both representations get the same search and budget.
//!
//! Switching follows [`Controller::schedule`] of the same times and period.

use super::controller::{simulate_with_rest, Controller, Regime, Trajectory};
use super::perturb::{apply_to, random_alpha, PerturbRegime, PerturbationMix};
use super::{Problem, SynthesisError};
use crate::control::search::{init_rng, Perturb};
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

/// One regime of a free controller.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FreeRegime {
    /// Regime time t_i ∈ [0, t_per] (s).
    pub time: f64,
    /// Coefficient α_i ∈ [−1, 1].
    pub alpha: f64,
    /// The actuation d_i ∈ [−1, 1]^m, one entry per spring.
    pub vector: Vec<f64>,
}

/// A time-based controller whose regimes set arbitrary spring rest lengths.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FreeController {
    /// The period t_per (s).
    pub period: f64,
    /// The regimes (at least one).
    pub regimes: Vec<FreeRegime>,
}

impl PerturbRegime for FreeRegime {
    fn time_mut(&mut self) -> &mut f64 {
        &mut self.time
    }
    fn alpha_mut(&mut self) -> &mut f64 {
        &mut self.alpha
    }
    fn redraw_actuation<R: Rng + ?Sized>(&mut self, rng: &mut R) {
        for d in &mut self.vector {
            *d = rng.random_range(-1.0..=1.0);
        }
    }
}

/// A random free regime for period `period` and `springs` springs.
pub fn random_free_regime<R: Rng + ?Sized>(rng: &mut R, period: f64, springs: usize) -> FreeRegime {
    let time = rng.random::<f64>() * period;
    let alpha = random_alpha(rng);
    let mut r = FreeRegime {
        time,
        alpha,
        vector: vec![0.0; springs],
    };
    r.redraw_actuation(rng);
    r
}

/// `n` random free controllers, controller j drawn from stream j ([`init_rng`]).
pub fn random_free_controllers(
    n: usize,
    regimes: usize,
    period: f64,
    springs: usize,
    seed: u64,
) -> Vec<FreeController> {
    (0..n)
        .map(|j| {
            let mut rng = init_rng(seed, j);
            FreeController {
                period,
                regimes: (0..regimes)
                    .map(|_| random_free_regime(&mut rng, period, springs))
                    .collect(),
            }
        })
        .collect()
}

impl FreeController {
    /// The reflex controller with the same period and regime times (reflex 0, α 0): its
    /// schedule is this controller's.
    pub fn timing(&self) -> Controller {
        Controller {
            period: self.period,
            regimes: self
                .regimes
                .iter()
                .map(|r| Regime {
                    time: r.time,
                    reflex: 0,
                    alpha: 0.0,
                })
                .collect(),
        }
    }

    /// Each regime's rest lengths L_j (1 + κ α d_j) for natural rest lengths `natural` and
    /// gain `kappa`.
    pub fn rest_lengths(
        &self,
        natural: &[f64],
        kappa: f64,
    ) -> Result<Vec<Vec<f64>>, SynthesisError> {
        self.regimes
            .iter()
            .map(|r| {
                if r.vector.len() != natural.len() {
                    return Err(SynthesisError::Invalid(
                        "rest-length vector",
                        r.vector.len() as f64,
                    ));
                }
                if !(r.alpha.is_finite() && (-1.0..=1.0).contains(&r.alpha)) {
                    return Err(SynthesisError::Invalid("reflex coefficient", r.alpha));
                }
                r.vector
                    .iter()
                    .zip(natural)
                    .map(|(&d, &l)| {
                        if !(d.is_finite() && (-1.0..=1.0).contains(&d)) {
                            return Err(SynthesisError::Invalid("rest-length entry", d));
                        }
                        Ok(l * (1.0 + kappa * r.alpha * d))
                    })
                    .collect()
            })
            .collect()
    }
}

impl Problem {
    /// Simulates free controller `c`: rest lengths from the model's natural ones and its scale
    /// reflex gain κ.
    pub fn trajectory_free(&self, c: &FreeController) -> Result<Trajectory, SynthesisError> {
        let timing = c.timing();
        timing.validate()?;
        let model = &self.setup.model;
        let rest = c.rest_lengths(&model.rest_lengths, model.reflex_gains.scale)?;
        simulate_with_rest(&self.setup, &timing, &rest)
    }

    /// The objective value of free controller `c` (as [`Problem::evaluate`]).
    pub fn evaluate_free(&self, c: &FreeController) -> f64 {
        self.score(self.trajectory_free(c))
    }
}

/// The perturbation mix as a search operator on free controllers.
#[derive(Debug, Clone, Copy, Default)]
pub struct FreePerturbation {
    /// The kinds' probabilities.
    pub mix: PerturbationMix,
}

impl Perturb<FreeController> for FreePerturbation {
    fn perturb(&self, rng: &mut ChaCha8Rng, c: &FreeController, _scale: f64) -> FreeController {
        let kind = self.mix.draw(rng);
        let mut out = c.clone();
        apply_to(rng, out.period, &mut out.regimes, kind);
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::physics::lattice::{Lattice, LatticeModel};
    use crate::synthesis::controller::{simulate, SimSetup};
    use crate::synthesis::perturb::PERTURBATIONS;
    use rand::SeedableRng;

    fn setup() -> SimSetup {
        let model = LatticeModel::new(Lattice::pyramid()).unwrap();
        SimSetup::new(model, 0.6, 0.05).with_tolerances(1e-4, 1e-6)
    }

    #[test]
    fn a_free_vector_equal_to_a_scale_reflex_moves_the_lattice_as_the_reflex() {
        // Reflex 0 scales along x: each spring's rest length changes by its own factor. A free
        // regime whose vector reproduces those factors (κ α d_j = L'_j / L_j − 1) must give the
        // same rest lengths and hence the same trajectory as the reflex controller.
        let s = setup();
        let model = &s.model;
        let c = Controller {
            period: 0.6,
            regimes: vec![
                Regime {
                    time: 0.1,
                    reflex: 0,
                    alpha: 0.8,
                },
                Regime {
                    time: 0.4,
                    reflex: 5,
                    alpha: -0.6,
                },
            ],
        };
        let rest = crate::synthesis::controller::regime_rest_lengths(model, &c).unwrap();
        let kappa = model.reflex_gains.scale;
        let free = FreeController {
            period: 0.6,
            regimes: c
                .regimes
                .iter()
                .zip(&rest)
                .map(|(r, l)| FreeRegime {
                    time: r.time,
                    alpha: 1.0,
                    vector: l
                        .iter()
                        .zip(&model.rest_lengths)
                        .map(|(a, b)| (a / b - 1.0) / kappa)
                        .collect(),
                })
                .collect(),
        };
        let p = Problem {
            setup: s.clone(),
            objective: crate::synthesis::objective::Objective {
                terms: vec![],
                contact_height: 0.01,
                frame_masses: [0, 1, 3],
            },
        };
        let a = simulate(&s, &c).unwrap();
        let b = p.trajectory_free(&free).unwrap();
        let last = |t: &Trajectory| t.frames.last().unwrap().positions.clone();
        for (x, y) in last(&a).iter().zip(last(&b)) {
            for k in 0..3 {
                assert!((x[k] - y[k]).abs() < 1e-9, "{x:?} vs {y:?}");
            }
        }
    }

    #[test]
    fn random_and_perturbed_free_controllers_stay_in_range_and_are_seeded() {
        let a = random_free_controllers(5, 3, 1.0, 10, 42);
        assert_eq!(a, random_free_controllers(5, 3, 1.0, 10, 42));
        assert_ne!(a, random_free_controllers(5, 3, 1.0, 10, 43));
        let natural = vec![1.0; 10];
        let op = FreePerturbation::default();
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let mut changed_vectors = 0;
        for c in &a {
            let mut x = c.clone();
            for _ in 0..300 {
                let y = op.perturb(&mut rng, &x, 1.0);
                y.timing().validate().unwrap();
                let rest = y.rest_lengths(&natural, 0.5).unwrap();
                assert!(rest.iter().flatten().all(|l| (0.5..=1.5).contains(l)));
                changed_vectors += y
                    .regimes
                    .iter()
                    .zip(&x.regimes)
                    .filter(|(p, q)| p.vector != q.vector)
                    .count();
                x = y;
            }
        }
        // "Pick a new reflex" (0.32 one regime + 0.08 all three) redraws vectors.
        let expect = 1500.0 * (PERTURBATIONS[0].1 + 3.0 * PERTURBATIONS[1].1);
        assert!(
            (changed_vectors as f64 - expect).abs() < 0.15 * expect,
            "{changed_vectors} vs {expect}"
        );
    }
}
