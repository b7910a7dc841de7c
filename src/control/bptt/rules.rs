//! The update rules and their settings: plain or momentum descent ([`Descent`]), how the step
//! scale evolves ([`StepRule`], with its validation) and both together ([`Schedule`]).

use serde::{Deserialize, Serialize};

/// The update rule: plain descent (eq. 13) or descent with momentum (eq. 14–15).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Descent {
    /// δ = −η/λ ∇J.
    Plain {
        /// Learning rate η (in units of 1/λ).
        eta: f64,
    },
    /// δ^{l+1} = −η/λ ∇J + α δ^l.
    Momentum {
        /// Learning rate η (in units of 1/λ).
        eta: f64,
        /// Momentum α ∈ [0, 1).
        alpha: f64,
    },
}

/// Optimizer state: the previous step δ^l (empty before the first).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct DescentState {
    /// The previous step.
    pub delta: Vec<f64>,
}

impl Descent {
    /// η.
    pub fn eta(&self) -> f64 {
        match *self {
            Self::Plain { eta } | Self::Momentum { eta, .. } => eta,
        }
    }
    /// α (0 for plain descent).
    pub fn alpha(&self) -> f64 {
        match *self {
            Self::Plain { .. } => 0.0,
            Self::Momentum { alpha, .. } => alpha,
        }
    }
    /// The step for gradient `grad` with step scale λ = `scale`, and the next state.
    pub fn update(
        &self,
        grad: &[f64],
        scale: f64,
        state: DescentState,
    ) -> (Vec<f64>, DescentState) {
        let (eta, alpha) = (self.eta(), self.alpha());
        let step: Vec<f64> = grad
            .iter()
            .enumerate()
            .map(|(i, g)| -eta / scale * g + alpha * state.delta.get(i).copied().unwrap_or(0.0))
            .collect();
        let next = DescentState {
            delta: step.clone(),
        };
        (step, next)
    }
}

/// How the step size evolves during learning (the paper: fixed).
///
/// - `Fixed`: λ measured once at the initial knots (the paper's η in units of 1/λ);
/// - `Reestimate`: λ re-measured ([`Bptt::curvature`], as many power iterations as the
///   first estimate) at the current iterate every `every` iterations, so η keeps its meaning
///   where the curvature grows or shrinks along the way;
/// - `Armijo`: a backtracking line search on the step η t/λ (t = 1 at the start): the step
///   p = −(η t/λ) ∇J + α δ (momentum dropped when p is not a descent direction) is tried at
///   σ = 1, `shrink`, `shrink`², … until the projected point v' = Π(v + σ p) satisfies the
///   sufficient-decrease test J(v') ≤ J(v) + c ∇J·(v' − v); then t ← σ t, and t ← `grow` t when
///   the first try passed. After `max_backtracks` failures the iterate stays put and the
///   momentum is reset.
///
/// [`Bptt::curvature`]: super::Bptt::curvature
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum StepRule {
    /// λ fixed at the initial knots.
    #[default]
    Fixed,
    /// λ re-measured every `every` iterations.
    Reestimate {
        /// Iterations between estimates (≥ 1).
        every: usize,
    },
    /// Backtracking (Armijo) line search with step growth.
    Armijo {
        /// Sufficient-decrease constant c ∈ (0, 1).
        c: f64,
        /// Backtracking factor ∈ (0, 1).
        shrink: f64,
        /// Growth after a first-try acceptance (≥ 1).
        grow: f64,
        /// Backtracks per iteration before giving up (≥ 1).
        max_backtracks: usize,
    },
    /// Levenberg–Marquardt on the Gauss–Newton matrix of the objective ([`Bptt::gauss_newton`];
    /// ours, not the paper's: η and α are not used).
    ///
    /// [`Bptt::gauss_newton`]: super::Bptt::gauss_newton
    LevenbergMarquardt {
        /// Initial damping μ relative to the diagonal of the Gauss–Newton matrix (> 0).
        damping: f64,
        /// Trials per iteration, each with more damping, before giving up (≥ 1).
        max_tries: usize,
    },
}

impl StepRule {
    /// Its name in tables: `fixed`, `reestimate`, `armijo` or `levenberg_marquardt`.
    pub fn name(&self) -> &'static str {
        match self {
            Self::Fixed => "fixed",
            Self::Reestimate { .. } => "reestimate",
            Self::Armijo { .. } => "armijo",
            Self::LevenbergMarquardt { .. } => "levenberg_marquardt",
        }
    }

    /// Checks the settings; `key` names the spec key in messages.
    pub fn validate(&self, key: &str) -> Result<(), crate::params::ParamError> {
        use crate::params::ensure;
        match *self {
            Self::Fixed => Ok(()),
            Self::Reestimate { every } => {
                ensure(every >= 1, &format!("{key}.every"), "must be >= 1")
            }
            Self::Armijo {
                c,
                shrink,
                grow,
                max_backtracks,
            } => {
                ensure(c > 0.0 && c < 1.0, &format!("{key}.c"), "must be in (0, 1)")?;
                ensure(
                    shrink > 0.0 && shrink < 1.0,
                    &format!("{key}.shrink"),
                    "must be in (0, 1)",
                )?;
                ensure(
                    grow >= 1.0 && grow.is_finite(),
                    &format!("{key}.grow"),
                    "must be >= 1",
                )?;
                ensure(
                    max_backtracks >= 1,
                    &format!("{key}.max_backtracks"),
                    "must be >= 1",
                )
            }
            Self::LevenbergMarquardt { damping, max_tries } => {
                ensure(
                    damping > 0.0 && damping.is_finite(),
                    &format!("{key}.damping"),
                    "must be > 0",
                )?;
                ensure(max_tries >= 1, &format!("{key}.max_tries"), "must be >= 1")
            }
        }
    }
}

/// The update rule, its step rule, the initial step scale λ and the power iterations of each
/// re-estimate ([`StepRule::Reestimate`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Schedule {
    /// Plain descent or momentum, η in units of 1/λ.
    pub descent: Descent,
    /// How λ evolves.
    pub rule: StepRule,
    /// The initial λ.
    pub scale: f64,
    /// Power iterations per re-estimate.
    pub curvature_iterations: usize,
}
