//! Parameters of `na_fig13_control` ([`Params`]): the tasks, the step-size sweeps, the dolphin
//! swim task, and their validation.

use super::{dagger, dolphin_dagger, Formulation, Task};
use crate::control::bptt::StepRule;
use crate::emulator::catalog::{NetSpec, TrainSettings};
use crate::experiment::resolve::{each_bar, ensure, positive, ParamError, Validate};
use crate::families::na::swim::SwimTask;
use crate::families::na::table1_structure::{
    validate_nets, validate_training, validate_variants, DolphinNets, NetVariant,
};
use serde::{Deserialize, Serialize};

/// The step-size sweep beside the headline runs: every task (dolphin excluded) learned with
/// every η and step rule at momentum α, each run stopped at its goal (emulator final error
/// ≤ 1) or after `iterations`.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Sweep {
    /// Learning rates η (units of 1/λ).
    pub eta: Vec<f64>,
    /// Momentum α.
    pub alpha: f64,
    /// Iteration budget per run.
    pub iterations: usize,
    /// Step rules.
    pub rules: Vec<StepRule>,
}

impl Sweep {
    fn validate(&self, key: &str) -> Result<(), ParamError> {
        let k = |s: &str| format!("{key}.{s}");
        ensure(!self.eta.is_empty(), &k("eta"), "needs at least one rate")?;
        for (i, e) in self.eta.iter().enumerate() {
            positive(&k(&format!("eta[{i}]")), *e)?;
        }
        ensure(
            (0.0..1.0).contains(&self.alpha),
            &k("alpha"),
            "must be in [0, 1)",
        )?;
        ensure(self.iterations >= 1, &k("iterations"), "must be >= 1")?;
        ensure(
            !self.rules.is_empty(),
            &k("rules"),
            "needs at least one rule",
        )?;
        for (i, r) in self.rules.iter().enumerate() {
            r.validate(&k(&format!("rules[{i}]")))?;
        }
        Ok(())
    }
}

/// Parameters of `na_fig13_control`.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Params {
    /// Physical steps per emulator step n (N50: 50).
    pub steps: usize,
    /// Power iterations for the step scale λ.
    pub curvature_iterations: usize,
    /// Multiplies every net's example count.
    pub example_scale: f64,
    /// The tasks.
    pub tasks: Vec<Task>,
    /// Training settings.
    pub training: TrainSettings,
    /// The dolphin swim task (Fig. 13d), if run.
    #[serde(default)]
    pub dolphin: Option<DolphinControl>,
    /// The step-size sweep, if run.
    #[serde(default)]
    pub sweep: Option<Sweep>,
    /// The same kind of sweep learned through the physical model itself (its RK4 step with
    /// finite-difference Jacobians, `steps` RK4 steps per emulator step), if run: whether
    /// descent reaches the goal without the emulator.
    #[serde(default)]
    pub physics_sweep: Option<Sweep>,
    /// The DAgger stage (ours; [`dagger`]), if run.
    #[serde(default)]
    pub dagger: Option<dagger::DaggerControl>,
    /// Further Table 1 net seeds (ours; [`super::seeds`]): the headline of every
    /// task of the paper's formulation (the dolphin aside) is learned again through the net
    /// `na_table1_structure` trains under each seed, and the verdict counts a task at its goal
    /// when a strict majority of its seeds (the run's own and these) reach it. The run's own
    /// seed and repeats are skipped; empty: the run's own net only. At most
    /// [`super::seeds::MAX_NET_SEEDS`].
    #[serde(default)]
    pub net_seeds: Vec<u64>,
    /// Tasks of our formulations also learned through every further net seed, beside the
    /// paper's (ours; reported, never counted in the verdict). Each must name a task.
    #[serde(default)]
    pub net_seeds_ours: Vec<String>,
    /// Second lines of the paper's tasks' nets ([`super::seeds`], `net_lines.csv`): each task
    /// of the paper's formulation (the dolphin aside) learned again over the run's own and the
    /// further net seeds through its net with one change (the data of the whole box, or input
    /// noise), so a before/after table shows which change mattered. Reported, never counted.
    #[serde(default)]
    pub net_lines: Vec<NetVariant>,
    /// The verdict's thresholds for the dolphin (ours; the control tasks' goal is their
    /// tolerance, a final error of at most 1). Absent in the parameters other experiments
    /// build to key their DAgger nets, which are never judged.
    #[serde(default)]
    pub rule: Option<Fig13Rule>,
}

/// The dolphin's goal in the verdict (ours; the paper says "learns to swim forward with a
/// natural, periodic swimming pattern").
#[derive(Debug, Clone, Copy, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Fig13Rule {
    /// The learned swim must cover at least this fraction of the hand-made wave's distance on
    /// the simulator, on the emulator and on the simulator alike.
    pub wave_fraction: f64,
    /// Its muscle pattern's periodicity must be at least this (1: a sinusoid, 0: noise or
    /// constant controls).
    pub periodicity: f64,
}

impl Fig13Rule {
    /// Both in (0, 1]: 0 is what a dolphin at rest scores on each.
    fn validate(&self) -> Result<(), ParamError> {
        each_bar(
            self,
            |v| v > 0.0 && v <= 1.0,
            "must be in (0, 1]: 0 is what a dolphin at rest scores",
        )
    }
}

/// The dolphin swim task of Fig. 13(d) ([`crate::families::na::swim`]).
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DolphinControl {
    /// The hierarchy (as in `na_table1_structure`).
    pub nets: DolphinNets,
    /// The task.
    pub swim: SwimTask,
    /// Descent iterations.
    pub iterations: usize,
    /// Learning rate η (units of 1/λ).
    pub eta: f64,
    /// Momentum α (0: plain descent).
    pub alpha: f64,
    /// Half-width of the uniform random initial knots (muscle units): J's gradient vanishes
    /// at exactly zero activation, where the forward distance is even in u, so starts near
    /// zero see almost no gradient; 1 = the full range.
    pub init_spread: f64,
    /// Random starts (seeded streams 400, 401, …); the run with the lowest best-so-far
    /// emulator J is scored.
    #[serde(default = "one")]
    pub restarts: usize,
    /// How the step scale evolves (default `fixed`).
    #[serde(default)]
    pub step_rule: StepRule,
    /// DAgger of the global net (ours; [`dolphin_dagger`]), if run.
    #[serde(default)]
    pub dagger: Option<dolphin_dagger::DolphinDagger>,
    /// An earlier swim task of ours learned the same way beside the paper's (the
    /// 4 s swim, `dolphin_4s` in final.csv, formulation `ours`, not counted), if set.
    #[serde(default)]
    pub ours_swim: Option<SwimTask>,
}

fn one() -> usize {
    1
}

impl DolphinControl {
    /// Checks it as the table `key` of a spec whose nets scale by `example_scale`.
    pub fn validate(&self, key: &str, example_scale: f64) -> Result<(), ParamError> {
        let k = |f: &str| format!("{key}.{f}");
        self.nets.validate(&k("nets"), example_scale)?;
        self.swim.validate(&k("swim"))?;
        if let Some(o) = &self.ours_swim {
            o.validate(&k("ours_swim"))?;
        }
        ensure(self.iterations >= 1, &k("iterations"), "must be >= 1")?;
        positive(&k("eta"), self.eta)?;
        ensure(
            (0.0..1.0).contains(&self.alpha),
            &k("alpha"),
            "must be in [0, 1)",
        )?;
        ensure(
            (0.0..=1.0).contains(&self.init_spread),
            &k("init_spread"),
            "must be in [0, 1]",
        )?;
        ensure(self.restarts >= 1, &k("restarts"), "must be >= 1")?;
        self.step_rule.validate(&k("step_rule"))?;
        if let Some(dd) = &self.dagger {
            dd.validate(&k("dagger"))?;
        }
        Ok(())
    }
}

impl Validate for Params {
    fn validate(&self) -> Result<(), ParamError> {
        ensure(self.steps >= 1, "steps", "must be >= 1")?;
        ensure(
            self.curvature_iterations >= 1,
            "curvature_iterations",
            "must be >= 1",
        )?;
        ensure(!self.tasks.is_empty(), "tasks", "need at least one task")?;
        for (i, t) in self.tasks.iter().enumerate() {
            t.validate_at(i)?;
        }
        for (key, sw) in [
            ("sweep", &self.sweep),
            ("physics_sweep", &self.physics_sweep),
        ] {
            if let Some(sw) = sw {
                sw.validate(key)?;
            }
        }
        if let Some(d) = &self.dagger {
            d.validate(self)?;
        }
        ensure(
            self.net_seeds.len() <= super::seeds::MAX_NET_SEEDS,
            "net_seeds",
            format!(
                "at most {} seeds (each trains one net per task)",
                super::seeds::MAX_NET_SEEDS
            ),
        )?;
        for name in &self.net_seeds_ours {
            ensure(
                self.tasks
                    .iter()
                    .any(|t| &t.name == name && t.formulation == Formulation::Ours),
                "net_seeds_ours",
                format!("`{name}` is not a task of formulation \"ours\""),
            )?;
        }
        validate_variants(&self.net_lines, "net_lines")?;
        if let Some(r) = &self.rule {
            r.validate()?;
        }
        let nets: Vec<NetSpec> = self.tasks.iter().map(|t| t.net.clone()).collect();
        validate_nets(&nets, self.example_scale)?;
        if let Some(d) = &self.dolphin {
            d.validate("dolphin", self.example_scale)?;
        }
        validate_training(&self.training)
    }
}
