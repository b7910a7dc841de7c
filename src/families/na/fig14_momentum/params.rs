//! Parameters of `na_fig14_momentum` ([`Params`]): the landing task, the compared descents, the
//! DAgger comparisons and the run to convergence, their validation, and the landing objective.

use crate::control::bptt::{Descent, IterationTrace, StepRule};
use crate::control::objective::{ControlEffort, FinalState, Objective, StateWindow};
use crate::emulator::catalog::{NetModel, NetSpec, TrainSettings};
use crate::emulator::dagger::DaggerSettings;
use crate::experiment::resolve::{at_most, distinct, ensure, positive, ParamError, Validate};
use crate::families::na::control_task::{keyed, ControlTask};
use crate::families::na::fig13_control::dagger::DaggerControl;
use crate::families::na::fig13_control::seeds::MAX_NET_SEEDS;
use crate::families::na::fig13_control::{
    Calibration, ControlUnits, FinalWeights, Formulation, Task,
};
use crate::families::na::table1_structure::{validate_nets, validate_training};
use crate::physics::lander::{Lander, VEL};
use serde::{Deserialize, Serialize};

/// Parameters of `na_fig14_momentum`.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Params {
    /// Physical steps per emulator step n (N50: 50).
    pub steps: usize,
    /// The landing task: `horizon` emulator steps M (40 = 20 s at N50, δt = 0.01 s), `knots`
    /// per actuator (20: 80 controls for 4 actuators), `iterations` per descent run, `start`
    /// (13: p, q, v, ω; the quaternion is normalized), `target` (13), `final_tolerance` and
    /// `effort_mu` (keys beside the others).
    #[serde(flatten, deserialize_with = "keyed")]
    pub task: ControlTask,
    /// Plain descent learning rate η (units of 1/λ, see the module docs).
    pub plain_eta: f64,
    /// Momentum learning rate η.
    pub momentum_eta: f64,
    /// Momentum α.
    pub momentum_alpha: f64,
    /// Plain-descent learning rates of the sweep.
    pub sweep_eta: Vec<f64>,
    /// Power iterations for the step scale λ.
    pub curvature_iterations: usize,
    /// Table 1 lander net seeds beyond the run's own (ours; as `na_fig13_control`'s): the
    /// headline pair (momentum and the plain sweep) is learned again through the net trained
    /// under each, and the verdict reads the median over all of them, the run's own included
    /// (`net_seeds.csv`). Empty: the run's own net only. At most [`MAX_NET_SEEDS`], no
    /// repeats; the run's own seed is skipped. Left out of the serialized parameters when
    /// empty.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub net_seeds: Vec<u64>,
    /// Last states w whose vertical velocity the touchdown term penalizes.
    pub touchdown_states: usize,
    /// Tolerance σ_v of the descent velocity before touchdown (m/s).
    pub touchdown_tolerance: f64,
    /// Multiplies the net's example count.
    pub example_scale: f64,
    /// The lander net.
    pub net: NetSpec,
    /// Training settings.
    pub training: TrainSettings,
    /// The comparison through the lander's DAgger net (ours), if run.
    #[serde(default)]
    pub dagger: Option<DaggerNet>,
    /// The comparison through the last net of a DAgger chain whose learner is this
    /// experiment's momentum descent itself (ours), if run.
    #[serde(default)]
    pub momentum_dagger: Option<MomentumDagger>,
    /// The compared descents through every net above continued until J stops falling
    /// (ours), if run.
    #[serde(default)]
    pub converged: Option<Converged>,
    /// The optimizer's unit of each actuator, as na_fig13_control's lander ([`ControlUnits`];
    /// default `box`; left out of the serialized parameters when `box`).
    #[serde(default, skip_serializing_if = "ControlUnits::is_box")]
    pub control_units: ControlUnits,
    /// The final-state term's weights, as na_fig13_control's lander ([`FinalWeights`];
    /// default `tolerance`; left out of the serialized parameters when `tolerance`).
    #[serde(default, skip_serializing_if = "FinalWeights::is_tolerance")]
    pub final_weights: FinalWeights,
    /// The verdict's bar (ours).
    pub rule: Fig14Rule,
}

/// The verdict's bars (ours; [`super::report`] builds the rules).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Fig14Rule {
    /// Momentum must reach plain descent's final J within this fraction of plain's iterations
    /// (plain itself takes all of them: a fraction of 1, its null).
    pub iteration_ratio: f64,
    /// A plain run converges when its last J is below this fraction of its start's ...
    pub converge_fraction: f64,
    /// ... and at most this multiple of its smallest J (it has not climbed back).
    pub converge_climb: f64,
    /// The DAgger lines: held when momentum's controls, replayed on the simulator, end with
    /// a final error (RMS in tolerances) at most this.
    pub dagger_final_error: f64,
    /// The DAgger lines: partly when they land within this distance of the target (m).
    pub dagger_landing_distance: f64,
}

impl Fig14Rule {
    /// Whether a plain-descent trace converges: it ends below `converge_fraction` of its
    /// start and has not climbed back above `converge_climb` × its minimum.
    pub fn converges(&self, trace: &[f64]) -> bool {
        let (first, last) = (trace[0], trace[trace.len() - 1]);
        let min = trace.iter().copied().fold(f64::INFINITY, f64::min);
        last.is_finite()
            && last < self.converge_fraction * first
            && last <= self.converge_climb * min
    }
}

/// `[params.converged]` (ours): beside the paper's budget, the compared descents (same η, α,
/// start) continued until J is converged — it fell by at most `tolerance` × |J| over the last
/// `window` iterations — or `max_iterations`; `converged.csv`, one row per net and descent.
#[derive(Debug, Clone, Copy, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Converged {
    /// Iteration cap.
    pub max_iterations: usize,
    /// Iterations over which J's fall is measured.
    pub window: usize,
    /// Relative fall of J over `window` iterations at or below which J is converged.
    pub tolerance: f64,
}

impl Converged {
    /// The stop rule of [`learn_until`] and a flag it raises when the rule (not the cap)
    /// ends the run.
    pub(super) fn rule(self) -> impl FnMut(&IterationTrace, &[f64]) -> bool {
        let mut history: Vec<f64> = Vec::new();
        move |t: &IterationTrace, _: &[f64]| {
            history.push(t.objective);
            let l = history.len();
            l > self.window && {
                let (then, now) = (history[l - 1 - self.window], history[l - 1]);
                then - now <= self.tolerance * now.abs()
            }
        }
    }
}

/// `[params.momentum_dagger]`: DAgger rounds whose learner is Fig. 14's momentum descent on its
/// landing objective from hover (`iterations`, `momentum_eta`, `momentum_alpha`), from the
/// Table 1 lander net, aggregating on the states those controls visit.
#[derive(Debug, Clone, Copy, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MomentumDagger {
    /// Rounds, perturbations, fine-tuning budget.
    pub settings: DaggerSettings,
}

/// `[params.dagger]`: the settings of `na_fig13_control`'s lander DAgger stage (so the nets
/// come from its cache).
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DaggerNet {
    /// The DAgger learner's iterations per round (Fig. 13's lander task: the paper's 15).
    pub iterations: usize,
    /// The DAgger learner's step rule.
    pub learner: StepRule,
    /// Rounds, perturbations, fine-tuning budget.
    pub settings: DaggerSettings,
}

impl Validate for Params {
    fn validate(&self) -> Result<(), ParamError> {
        ensure(self.steps >= 1, "steps", "must be >= 1")?;
        let r = self.rule.iteration_ratio;
        ensure(
            r > 0.0 && r < 1.0,
            "rule.iteration_ratio",
            "must be in (0, 1): plain descent itself takes all its iterations (1)",
        )?;
        ensure(
            self.rule.converge_fraction > 0.0 && self.rule.converge_fraction < 1.0,
            "rule.converge_fraction",
            "must be in (0, 1): a run that stays at its start does not converge",
        )?;
        ensure(
            self.rule.converge_climb >= 1.0,
            "rule.converge_climb",
            "must be >= 1: a run's last J is at least its smallest",
        )?;
        positive("rule.dagger_final_error", self.rule.dagger_final_error)?;
        positive(
            "rule.dagger_landing_distance",
            self.rule.dagger_landing_distance,
        )?;
        self.task.validate(NetModel::Lander.state_dim())?;
        positive("plain_eta", self.plain_eta)?;
        positive("momentum_eta", self.momentum_eta)?;
        ensure(
            (0.0..1.0).contains(&self.momentum_alpha),
            "momentum_alpha",
            "must be in [0, 1)",
        )?;
        for (i, e) in self.sweep_eta.iter().enumerate() {
            positive(&format!("sweep_eta[{i}]"), *e)?;
        }
        ensure(
            self.curvature_iterations >= 1,
            "curvature_iterations",
            "must be >= 1",
        )?;
        at_most("net_seeds", self.net_seeds.len(), MAX_NET_SEEDS)?;
        distinct("net_seeds", &self.net_seeds)?;
        ensure(
            self.task.final_tolerance.iter().all(|&t| t >= 0.0),
            "final_tolerance",
            "must be >= 0",
        )?;
        positive("touchdown_tolerance", self.touchdown_tolerance)?;
        ensure(
            self.task.effort_mu >= 0.0 && self.task.effort_mu.is_finite(),
            "effort_mu",
            "must be >= 0",
        )?;
        ensure(
            self.net.model == NetModel::Lander,
            "net.model",
            "Fig. 14 is the lander",
        )?;
        validate_nets(std::slice::from_ref(&self.net), self.example_scale)?;
        if let Some(d) = &self.dagger {
            ensure(d.iterations >= 1, "dagger.iterations", "must be >= 1")?;
            let (f13, control) = self.fig13(d);
            control.validate(&f13)?;
        }
        if let Some(md) = &self.momentum_dagger {
            let (f13, control) = self.fig13(&self.momentum_chain(md));
            control.validate(&f13)?;
        }
        if let Some(c) = &self.converged {
            ensure(
                c.window >= 1 && c.max_iterations > c.window,
                "converged.window",
                "must be >= 1 and below converged.max_iterations",
            )?;
            positive("converged.tolerance", c.tolerance)?;
            ensure(
                self.dagger.is_some(),
                "converged",
                "needs [params.dagger] (its task scores the final error)",
            )?;
        }
        validate_training(&self.training)
    }
}

impl Params {
    /// The landing objective (see the module docs).
    pub fn objective(&self) -> Objective {
        self.objective_with(None)
    }

    /// The landing objective with the final-state weights of `calibration` (the 1/σ² weights
    /// of the tolerances when `None`).
    pub fn objective_with(&self, calibration: Option<&Calibration>) -> Objective {
        let model = NetModel::Lander;
        let (n, m) = (model.state_dim(), model.control_dim());
        let limits = model.control_limits();
        let l = Lander::default();
        let mut offset = vec![0.0; m];
        offset[0] = l.mass * l.gravity;
        let scale = (0..m)
            .map(|j| 0.5 * (limits.high[j] - limits.low[j]))
            .collect();
        let weights = match calibration {
            Some(c) => c.weights.clone(),
            None => self
                .task
                .final_tolerance
                .iter()
                .map(|&t| if t > 0.0 { 1.0 / (t * t) } else { 0.0 })
                .collect(),
        };
        let mut vz = vec![0.0; n];
        vz[VEL + 2] = 1.0 / (self.touchdown_tolerance * self.touchdown_tolerance);
        Objective::default()
            .with(ControlEffort {
                mu: self.task.effort_mu,
                offset,
                scale,
            })
            .with(FinalState {
                mu: 1.0,
                target: self.task.target.clone(),
                weights,
            })
            .with(StateWindow {
                mu: 1.0,
                from: (self.task.horizon + 1).saturating_sub(self.touchdown_states),
                to: self.task.horizon,
                reference: vec![0.0; n],
                weights: vz,
            })
    }

    /// Fig. 13's lander task as this spec states it (same start, target, tolerances, horizon,
    /// knots, effort weight and net; the DAgger learner's budget `d.iterations`).
    pub fn dagger_task(&self, d: &DaggerNet) -> Task {
        self.lander_task(d.iterations)
    }

    /// Fig. 13's lander task as this spec states it, with a budget of `iterations`.
    pub fn lander_task(&self, iterations: usize) -> Task {
        Task {
            name: "lander".into(),
            net: self.net.clone(),
            task: ControlTask {
                iterations,
                ..self.task.clone()
            },
            limit_fraction: 1.0,
            eta: self.momentum_eta,
            alpha: self.momentum_alpha,
            step_rule: StepRule::Fixed,
            formulation: Formulation::Paper,
            initial_knots: None,
            control_units: self.control_units,
            final_weights: self.final_weights,
            calibration: None,
        }
    }

    /// `na_fig13_control`'s parameters with the lander task alone and its DAgger stage: what
    /// keys and builds the DAgger nets.
    pub fn fig13(
        &self,
        d: &DaggerNet,
    ) -> (crate::families::na::fig13_control::Params, DaggerControl) {
        let control = DaggerControl {
            learner: d.learner,
            settings: d.settings,
        };
        let p = crate::families::na::fig13_control::Params {
            steps: self.steps,
            curvature_iterations: self.curvature_iterations,
            example_scale: self.example_scale,
            tasks: vec![self.dagger_task(d)],
            training: self.training,
            dolphin: None,
            sweep: None,
            physics_sweep: None,
            dagger: Some(control.clone()),
            net_seeds: vec![],
            net_seeds_ours: vec![],
            net_lines: vec![],
            rule: None,
        };
        (p, control)
    }

    /// The momentum chain as a [`DaggerNet`] (its `learner` only keys the nets: the rounds
    /// are learned by this experiment's momentum descent).
    pub fn momentum_chain(&self, md: &MomentumDagger) -> DaggerNet {
        DaggerNet {
            iterations: self.task.iterations,
            learner: StepRule::Fixed,
            settings: md.settings,
        }
    }

    /// The net seeds beyond the run's own (`own`), in the spec's order.
    pub fn further_net_seeds(&self, own: u64) -> Vec<u64> {
        crate::experiment::seeds::further_seeds(&self.net_seeds, own)
    }

    /// The start state with a unit quaternion.
    pub fn start_state(&self) -> Vec<f64> {
        let mut s = self.task.start.clone();
        Lander::default().normalize_state(&mut s);
        s
    }

    /// The runs: momentum, then plain descent at `plain_eta` and at every sweep rate.
    pub fn descents(&self) -> Vec<Descent> {
        let mut etas = vec![self.plain_eta];
        for &e in &self.sweep_eta {
            if !etas.iter().any(|&x| (x - e).abs() < 1e-12) {
                etas.push(e);
            }
        }
        etas.sort_by(f64::total_cmp);
        let mut out = vec![Descent::Momentum {
            eta: self.momentum_eta,
            alpha: self.momentum_alpha,
        }];
        out.extend(etas.into_iter().map(|eta| Descent::Plain { eta }));
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// J = 1 + 0.9^l: the rule fires at the first l where J fell by at most 1e-3 · J over
    /// the last 5 iterations, i.e. 0.9^(l−5) (1 − 0.9⁵) ≤ 1e-3 (1 + 0.9^l), and never
    /// on a J still falling fast.
    #[test]
    fn the_convergence_rule_fires_when_j_stops_falling() {
        let c = Converged {
            max_iterations: 1000,
            window: 5,
            tolerance: 1e-3,
        };
        let trace = |l: usize| IterationTrace {
            iteration: l,
            objective: 1.0 + 0.9f64.powi(l as i32),
            grad_norm: 0.0,
            seconds: 0.0,
            evaluations: 0,
            scale: 0.0,
        };
        let mut rule = c.rule();
        let fired = (0..1000).find(|&l| rule(&trace(l), &[])).unwrap();
        let expected = (5..1000)
            .find(|&l| {
                let (then, now) = (trace(l - 5).objective, trace(l).objective);
                then - now <= 1e-3 * now
            })
            .unwrap();
        assert_eq!(fired, expected);
        assert!(fired > 40, "{fired}");
        let mut rule = c.rule();
        assert!((0..40).all(|l| !rule(&trace(l), &[])));
    }
}
