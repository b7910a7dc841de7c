//! The rows of `na_fig14_momentum`'s tables that its figures and report read back, and the
//! descents' method as the tables name it.

use crate::control::bptt::Descent;

/// A descent's method, as the tables' `method` column names it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Method {
    /// Gradient descent with momentum (eq. 14–15).
    Momentum,
    /// Plain gradient descent (eq. 13).
    Plain,
}

impl Method {
    /// The method of descent `d`.
    pub fn of(d: &Descent) -> Self {
        match d {
            Descent::Plain { .. } => Method::Plain,
            Descent::Momentum { .. } => Method::Momentum,
        }
    }

    /// The name the tables write.
    pub fn name(self) -> &'static str {
        match self {
            Method::Momentum => "momentum",
            Method::Plain => "plain",
        }
    }

    /// Whether `name` (a `method` cell) is this method.
    pub fn is(self, name: &str) -> bool {
        name == self.name()
    }
}

crate::result_rows! {
    /// One iteration of one descent: a row of `objective.csv`, `dagger_objective.csv` and
    /// `unclipped_objective.csv`.
    pub struct ObjectiveRow {
        /// The descent's method ([`Method::name`]).
        method: String = "method",
        /// Its learning rate, in units of 1/λ.
        eta: f64 = "eta",
        /// Its momentum α (0 for plain descent).
        alpha: f64 = "alpha",
        /// The iteration (0: the start).
        iteration: i64 = "iteration",
        /// The objective J there.
        objective: f64 = "objective",
    }
}

crate::result_rows! {
    /// One iteration of one descent: a row of `gradient.csv`.
    pub struct GradientRow {
        /// The descent's method ([`Method::name`]).
        method: String = "method",
        /// Its learning rate, in units of 1/λ.
        eta: f64 = "eta",
        /// Its momentum α (0 for plain descent).
        alpha: f64 = "alpha",
        /// The iteration (0: the start).
        iteration: i64 = "iteration",
        /// The norm of the gradient of J there.
        grad_norm: f64 = "grad_norm",
    }
}

/// What one descent scores, replayed on the simulator: the `runs.csv` columns from `scale` to
/// `final_gap`, shared with `dagger.csv` and `converged.csv`.
#[derive(Debug, Clone, PartialEq)]
pub struct Scores {
    /// λ, the largest Hessian eigenvalue magnitude of J at hover (the step's unit).
    pub scale: f64,
    /// J at the start.
    pub initial_objective: f64,
    /// J at the last iteration.
    pub final_objective: f64,
    /// The least J over the run.
    pub min_objective: f64,
    /// The final centre of mass's distance to the target on the emulator (m).
    pub emulator_landing_error: f64,
    /// The same on the simulator replay (m).
    pub simulator_landing_error: f64,
    /// The final speed on the emulator (m/s).
    pub emulator_final_speed: f64,
    /// The same on the simulator replay (m/s).
    pub simulator_final_speed: f64,
    /// |s_emulated − s_simulated| at the end.
    pub final_gap: f64,
}

crate::result_rows! {
    /// One descent through the run's own net: a row of `runs.csv`.
    pub struct RunRow {
        /// The descent's method ([`Method::name`]).
        method: String = "method",
        /// Its learning rate, in units of 1/λ.
        eta: f64 = "eta",
        /// Its momentum α (0 for plain descent).
        alpha: f64 = "alpha",
        /// λ (see [`Scores`]).
        scale: f64 = "scale",
        /// J at the start.
        initial_objective: f64 = "initial_objective",
        /// J at the last iteration.
        final_objective: f64 = "final_objective",
        /// The least J over the run.
        min_objective: f64 = "min_objective",
        /// Landing distance on the emulator (m).
        emulator_landing_error: f64 = "emulator_landing_error",
        /// Landing distance on the simulator replay (m).
        simulator_landing_error: f64 = "simulator_landing_error",
        /// Final speed on the emulator (m/s).
        emulator_final_speed: f64 = "emulator_final_speed",
        /// Final speed on the simulator replay (m/s).
        simulator_final_speed: f64 = "simulator_final_speed",
        /// |s_emulated − s_simulated| at the end.
        final_gap: f64 = "final_gap",
    }
}

impl RunRow {
    /// The row of descent `d` and its scores.
    pub fn new(d: &Descent, s: &Scores) -> Self {
        RunRow {
            method: Method::of(d).name().into(),
            eta: d.eta(),
            alpha: d.alpha(),
            scale: s.scale,
            initial_objective: s.initial_objective,
            final_objective: s.final_objective,
            min_objective: s.min_objective,
            emulator_landing_error: s.emulator_landing_error,
            simulator_landing_error: s.simulator_landing_error,
            emulator_final_speed: s.emulator_final_speed,
            simulator_final_speed: s.simulator_final_speed,
            final_gap: s.final_gap,
        }
    }
}

crate::result_rows! {
    /// One compared descent through one net (`table1`, `dagger`, `momentum_dagger`): a row of
    /// `dagger.csv`.
    pub struct DaggerRow {
        /// The net learned through: `table1` (round 0), `dagger` (Fig. 13's lander chain) or
        /// `momentum_dagger` (the chain whose learner is momentum descent).
        net: String = "net",
        /// Its DAgger round.
        round: i64 = "round",
        /// The descent's method ([`Method::name`]).
        method: String = "method",
        /// Its learning rate, in units of 1/λ.
        eta: f64 = "eta",
        /// Its momentum α (0 for plain descent).
        alpha: f64 = "alpha",
        /// λ through that net.
        scale: f64 = "scale",
        /// J at the start.
        initial_objective: f64 = "initial_objective",
        /// J at the last iteration.
        final_objective: f64 = "final_objective",
        /// The least J over the run.
        min_objective: f64 = "min_objective",
        /// Landing distance on the net (m).
        emulator_landing_error: f64 = "emulator_landing_error",
        /// Landing distance on the simulator replay (m).
        simulator_landing_error: f64 = "simulator_landing_error",
        /// Final speed on the net (m/s).
        emulator_final_speed: f64 = "emulator_final_speed",
        /// Final speed on the simulator replay (m/s).
        simulator_final_speed: f64 = "simulator_final_speed",
        /// |s_emulated − s_simulated| at the end.
        final_gap: f64 = "final_gap",
        /// RMS over the weighted state variables of (s_M − s_d)/σ on the net (Fig. 13's
        /// measure; ≤ 1: within tolerance).
        emulator_final_error: f64 = "emulator_final_error",
        /// The same on the simulator replay.
        simulator_final_error: f64 = "simulator_final_error",
    }
}

impl DaggerRow {
    /// The row of descent `d` through net `net` of round `round`, its scores and its final
    /// errors (emulator, simulator).
    pub fn new(
        (net, round): (&str, i64),
        d: &Descent,
        s: &Scores,
        (emulator_final_error, simulator_final_error): (f64, f64),
    ) -> Self {
        DaggerRow {
            net: net.into(),
            round,
            method: Method::of(d).name().into(),
            eta: d.eta(),
            alpha: d.alpha(),
            scale: s.scale,
            initial_objective: s.initial_objective,
            final_objective: s.final_objective,
            min_objective: s.min_objective,
            emulator_landing_error: s.emulator_landing_error,
            simulator_landing_error: s.simulator_landing_error,
            emulator_final_speed: s.emulator_final_speed,
            simulator_final_speed: s.simulator_final_speed,
            final_gap: s.final_gap,
            emulator_final_error,
            simulator_final_error,
        }
    }
}

crate::result_rows! {
    /// One compared descent through one net run to convergence: a row of `converged.csv`, the
    /// columns of [`DaggerRow`] and two more.
    pub struct ConvergedRow {
        /// As [`DaggerRow::net`].
        net: String = "net",
        /// Its DAgger round.
        round: i64 = "round",
        /// The descent's method ([`Method::name`]).
        method: String = "method",
        /// Its learning rate, in units of 1/λ.
        eta: f64 = "eta",
        /// Its momentum α (0 for plain descent).
        alpha: f64 = "alpha",
        /// λ through that net.
        scale: f64 = "scale",
        /// J at the start.
        initial_objective: f64 = "initial_objective",
        /// J at the last iteration.
        final_objective: f64 = "final_objective",
        /// The least J over the run.
        min_objective: f64 = "min_objective",
        /// Landing distance on the net (m).
        emulator_landing_error: f64 = "emulator_landing_error",
        /// Landing distance on the simulator replay (m).
        simulator_landing_error: f64 = "simulator_landing_error",
        /// Final speed on the net (m/s).
        emulator_final_speed: f64 = "emulator_final_speed",
        /// Final speed on the simulator replay (m/s).
        simulator_final_speed: f64 = "simulator_final_speed",
        /// |s_emulated − s_simulated| at the end.
        final_gap: f64 = "final_gap",
        /// As [`DaggerRow::emulator_final_error`].
        emulator_final_error: f64 = "emulator_final_error",
        /// The same on the simulator replay.
        simulator_final_error: f64 = "simulator_final_error",
        /// The iterations run.
        iterations: i64 = "iterations",
        /// 1 when J converged by the spec's stop rule, 0 when the cap ended the run.
        converged: i64 = "converged",
    }
}

impl ConvergedRow {
    /// The `dagger.csv` row `d` of a run to convergence, its `iterations` and whether it
    /// `converged`.
    pub fn new(d: DaggerRow, iterations: i64, converged: bool) -> Self {
        ConvergedRow {
            net: d.net,
            round: d.round,
            method: d.method,
            eta: d.eta,
            alpha: d.alpha,
            scale: d.scale,
            initial_objective: d.initial_objective,
            final_objective: d.final_objective,
            min_objective: d.min_objective,
            emulator_landing_error: d.emulator_landing_error,
            simulator_landing_error: d.simulator_landing_error,
            emulator_final_speed: d.emulator_final_speed,
            simulator_final_speed: d.simulator_final_speed,
            final_gap: d.final_gap,
            emulator_final_error: d.emulator_final_error,
            simulator_final_error: d.simulator_final_error,
            iterations,
            converged: i64::from(converged),
        }
    }

    /// J converged by the rule (else the cap ended the run).
    pub fn converged(&self) -> bool {
        self.converged == 1
    }
}

crate::result_rows! {
    /// One descent of the sweep with its knots clipped to the actuators' boxes or not (ours): a
    /// row of `unclipped.csv`. On a quadratic with largest Hessian eigenvalue λ, plain descent
    /// with step η/λ converges iff η < 2 and the heavy ball with momentum α iff η < 2 (1 + α).
    pub struct UnclippedRow {
        /// The descent's method ([`Method::name`]).
        method: String = "method",
        /// Its learning rate, in units of 1/λ.
        eta: f64 = "eta",
        /// Its momentum α (0 for plain descent).
        alpha: f64 = "alpha",
        /// 1 when the knots were clipped to the boxes, 0 when free.
        clipped: i64 = "clipped",
        /// J at the start.
        initial_objective: f64 = "initial_objective",
        /// J at the last iteration.
        final_objective: f64 = "final_objective",
        /// The least J over the run (NaN left out).
        min_objective: f64 = "min_objective",
        /// The largest J over the run (NaN when any J is: a run that blew up).
        max_objective: f64 = "max_objective",
        /// 1 when the run diverged: the last J not finite or above the start's (the rule,
        /// ours, fixed before any run of it); else 0.
        diverged: i64 = "diverged",
    }
}

impl UnclippedRow {
    /// The knots were clipped to the boxes.
    pub fn clipped(&self) -> bool {
        self.clipped == 1
    }

    /// The run diverged.
    pub fn diverged(&self) -> bool {
        self.diverged == 1
    }
}

crate::result_rows! {
    /// One descent of the headline through one Table 1 lander net seed (ours): a row of
    /// `net_seeds.csv`, the run's own seed first, then the spec's `net_seeds`; per seed momentum,
    /// then plain descent at every rate of the sweep.
    pub struct NetSeedRow {
        /// The seed the Table 1 lander net was trained under.
        net_seed: i64 = "net_seed",
        /// The descent's method ([`Method::name`]).
        method: String = "method",
        /// Its learning rate, in units of 1/λ.
        eta: f64 = "eta",
        /// Its momentum α (0 for plain descent).
        alpha: f64 = "alpha",
        /// 1 for the paper's pair (momentum, and plain at `plain_eta`), else 0.
        compared: i64 = "compared",
        /// λ through that seed's net.
        scale: f64 = "scale",
        /// The iterations run.
        iterations: i64 = "iterations",
        /// J at the start.
        initial_objective: f64 = "initial_objective",
        /// J at the last iteration.
        final_objective: f64 = "final_objective",
        /// The least J over the run (NaN left out).
        min_objective: f64 = "min_objective",
        /// 1 when the spec's rule ([`super::Fig14Rule::converges`]) holds on the objective
        /// curve, else 0.
        converges: i64 = "converges",
        /// The first iteration at which J is at or below the final J of plain descent at
        /// `plain_eta` through the same net (NaN: never).
        iterations_to_plain_final: f64 = "iterations_to_plain_final",
    }
}

impl NetSeedRow {
    /// One of the paper's pair.
    pub fn compared(&self) -> bool {
        self.compared == 1
    }

    /// J converges by the spec's rule.
    pub fn converges(&self) -> bool {
        self.converges == 1
    }

    /// The first iteration at which momentum reaches plain's final J (None: never).
    pub fn reach(&self) -> Option<usize> {
        let k = self.iterations_to_plain_final;
        (k.is_finite() && k >= 0.0).then_some(k as usize)
    }
}
