//! # `na_transforms_ablation` (NeuroAnimator §3.2, Fig. 6): the emulator's transforms, one at a time
//!
//! The paper wraps each emulator net in fixed transforms (Fig. 6): the net predicts the state
//! change (T^Δ) in the model's local frame (T'), on normalized inputs and outputs (T^σ,
//! Appendix A's groups), and says each operator makes the net easier to train and that the
//! invariant emulator was crucial. This experiment builds the emulator of each Fig. 13 task
//! four ways on the same data, net size, training and budget ([`TransformSet`]: `plain`, the
//! bare net predicting the next state; `delta`; `delta_frame`; `full`, the Fig. 13 net itself,
//! so a warm run loads it from the cache) and measures, for each:
//!
//! - the one-step and 40-step rollout error against the simulator, in units of each state
//!   variable's spread ([`rollout_error`], Table 1's measure);
//! - the zero-control drift from the task's start: 40 super-steps under the rest control, the
//!   emulator's and the simulator's end positions apart (m);
//! - Fig. 13's control learned through it (the task's momentum, η, α and iteration count;
//!   actuator gains and final-state weights calibrated once through the `full` net and then
//!   fixed for every variant, so all learn the same objective), replayed on the simulator.
//!
//! Tables: `nets` (task, variant, inputs, hidden, outputs, examples, weights, train_s, stop,
//! cached, failed), `errors` (task, variant, rollout1_error, rollout40_error_mean,
//! rollout40_error_final, drift_emulator_m, drift_simulator_m, drift_gap_m), `rollout` (task,
//! variant, step, error), `control` (task, variant, iterations, best_iteration, j_start, j_best,
//! emulator_error, simulator_error, at_goal, start_simulator_error: the start's controls
//! replayed, the same on every row of a task), `rule` (setting, value). Figures: `<id>_rollout` (rollout error against the
//! super-step, one line per variant, a panel per task) and `<id>_summary` (each measure against
//! the variant, one line per task). A variant whose training fails (non-finite) is a row with
//! `failed = 1` and empty measures: it counts as an infinite error in the rule.
//!
//! Verdict ([`ablation_rule`], thresholds ours in the spec's `[params.rule]`): per task, (a)
//! the full chain's 40-step error at most `full_over_plain` of the plain net's; (b) every added
//! operator lowers the 40-step error below `operator_ratio` of the previous variant's (an
//! operator that changes nothing scores 1 and fails); (c) the control learned through the full
//! chain ends within tolerance on the simulator (its null: the start's controls replayed);
//! (d) that control's simulator error below `control_over_plain` of the plain net's control's.
//! Held: every check; partly: (a) for every task (the training half of the claim).

mod figures;
mod job;
mod report;

pub use report::{ablation_rule, TaskRows, VariantRow};

use crate::emulator::catalog::{TrainSettings, TransformSet};
use crate::experiment::output::Tables;
use crate::experiment::plot::FigureSink;
use crate::experiment::report::Findings;
use crate::experiment::resolve::{each_bar, ensure, ParamError, Validate};
use crate::experiment::{Error, Family};
use crate::families::na::fig13_control::{DolphinControl, Formulation, Task};
use crate::families::na::table1_structure::{validate_nets, validate_training};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// The family.
pub struct NaTransforms;

/// Parameters of `na_transforms_ablation`.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Params {
    /// Physical steps per emulator step (Fig. 13: N50).
    pub steps: usize,
    /// Scale of every net's training examples (1 = Table 1's).
    pub example_scale: f64,
    /// Power iterations of the step scale λ (as Fig. 13).
    pub curvature_iterations: usize,
    /// The variants, operators added in order; must include `full` (it calibrates the tasks).
    pub variants: Vec<TransformSet>,
    /// Rollout episodes of the rollout error.
    pub rollout_episodes: usize,
    /// Super-steps of the rollouts and of the drift.
    pub rollout_steps: usize,
    /// The Fig. 13 tasks (paper formulation), their nets as Fig. 13's.
    pub tasks: Vec<Task>,
    /// Training settings (Fig. 13's, so the `full` nets are the cached Fig. 13 nets).
    pub training: TrainSettings,
    /// The dolphin's global net (Fig. 13's hierarchy and swim), its variants composed with the
    /// whole chain's local nets, if run.
    #[serde(default)]
    pub dolphin: Option<DolphinControl>,
    /// The verdict's thresholds (ours).
    pub rule: AblationRule,
    /// Further seeds of the tasks' nets (beside the run's own): every variant of every task
    /// (not the dolphin) is built and measured again through each (`net_seeds.csv`), and the
    /// tasks' checks read the median over the seeds. At most [`MAX_NET_SEEDS`].
    #[serde(default)]
    pub net_seeds: Vec<u64>,
}

/// The most net seeds a run may name (each is a set of variant nets to train when not cached).
pub const MAX_NET_SEEDS: usize = 16;

/// The verdict's thresholds ([`ablation_rule`]; ours).
#[derive(Debug, Clone, Copy, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AblationRule {
    /// An added operator helps when it lowers the 40-step error below this fraction of the
    /// previous variant's (an operator that changes nothing scores 1, so it must be below 1).
    pub operator_ratio: f64,
    /// The full chain's 40-step error must be at most this fraction of the plain net's.
    pub full_over_plain: f64,
    /// The control learned through the full chain must end on the simulator below this
    /// fraction of the plain net's control's final error.
    pub control_over_plain: f64,
}

impl AblationRule {
    /// Every ratio in (0, 1): 1 is what a variant that changes nothing scores.
    fn validate(&self) -> Result<(), ParamError> {
        each_bar(
            self,
            |v| v > 0.0 && v < 1.0,
            "must be in (0, 1): a ratio of 1 is what a variant that changes nothing scores",
        )
    }
}

/// A final error of at most 1 is within the task's tolerance (the unit of the final error).
const WITHIN_TOLERANCE: f64 = 1.0;

impl Validate for Params {
    fn validate(&self) -> Result<(), ParamError> {
        ensure(self.steps >= 1, "steps", "must be >= 1")?;
        ensure(
            self.curvature_iterations >= 1,
            "curvature_iterations",
            "must be >= 1",
        )?;
        ensure(
            self.variants.contains(&TransformSet::Full),
            "variants",
            "must include `full` (the tasks are calibrated through it)",
        )?;
        for (i, v) in self.variants.iter().enumerate() {
            ensure(
                !self.variants[..i].contains(v),
                &format!("variants[{i}]"),
                format!("`{}` is listed twice", v.name()),
            )?;
        }
        ensure(
            self.rollout_episodes >= 1 && self.rollout_steps >= 1,
            "rollout_episodes",
            "rollout_episodes and rollout_steps must be >= 1",
        )?;
        ensure(!self.tasks.is_empty(), "tasks", "need at least one task")?;
        for (i, t) in self.tasks.iter().enumerate() {
            t.validate_at(i)?;
            ensure(
                t.net.transforms == TransformSet::Full,
                &format!("tasks[{i}].net.transforms"),
                "leave it out: the experiment builds every variant of `variants`",
            )?;
            ensure(
                t.formulation == Formulation::Paper,
                &format!("tasks[{i}].formulation"),
                "the ablation runs the paper's formulation",
            )?;
        }
        let nets: Vec<_> = self.tasks.iter().map(|t| t.net.clone()).collect();
        validate_nets(&nets, self.example_scale)?;
        if let Some(d) = &self.dolphin {
            d.validate("dolphin", self.example_scale)?;
            ensure(
                d.dagger.is_none() && d.ours_swim.is_none(),
                "dolphin",
                "leave out `dagger` and `ours_swim`: the ablation learns the paper's swim only",
            )?;
        }
        self.rule.validate()?;
        ensure(
            self.net_seeds.len() <= MAX_NET_SEEDS,
            "net_seeds",
            format!("at most {MAX_NET_SEEDS}"),
        )?;
        validate_training(&self.training)
    }
}

impl Family for NaTransforms {
    const KIND: &'static str = "na_transforms_ablation";
    type Params = Params;
    const CAPTIONS: &'static [(&'static str, &'static str)] = &[
        (
            "rollout",
            "each emulator variant's rollout error against the simulator (mean over episodes and state variables of the squared error in units of each variable's spread) against the emulator step, one panel per task; the operators are added left to right in the legend.",
        ),
        (
            "summary",
            "per variant (operators added left to right): one-step and 40-step rollout error, the zero-control drift gap from the Fig. 13 start, and the simulator final error of the Fig. 13 control learned through it (1 = tolerance, dashed; for the dolphin, the swim's distance short of the hand-made wave's in units of half of it); one line per task.",
        ),
    ];

    fn figures(&self, fig: &FigureSink, tables: &Tables) -> Result<Vec<PathBuf>, Error> {
        figures::figures(fig, tables)
    }

    fn report(&self, dir: &Path) -> Result<Findings, Error> {
        report::report(dir)
    }
}

#[cfg(test)]
mod tests {
    use super::job::{ControlRow, ErrorsRow, NetRow, SeedRow};
    use super::report::seeded_rows;
    use super::*;
    use crate::experiment::output::write_table;
    use crate::experiment::report::Verdict;
    use crate::experiment::rows::table_of;

    const RULE: AblationRule = AblationRule {
        operator_ratio: 0.95,
        full_over_plain: 0.5,
        control_over_plain: 0.5,
    };

    /// A task of (variant, 40-step error, simulator error) rows from a start scoring 40.
    fn task(rows: &[(&str, f64, f64)]) -> TaskRows {
        TaskRows {
            task: "t".into(),
            rows: rows
                .iter()
                .map(|r| VariantRow {
                    variant: r.0.to_string(),
                    rollout40: r.1,
                    simulator: r.2,
                    best_iteration: 15,
                })
                .collect(),
            start: 40.0,
        }
    }

    /// Each task at one net seed.
    fn one_seed(tasks: &[TaskRows]) -> Vec<Vec<TaskRows>> {
        tasks.iter().map(|t| vec![t.clone()]).collect()
    }

    fn verdict(tasks: &[TaskRows]) -> Verdict {
        ablation_rule(&one_seed(tasks), &RULE)
            .expect("nulls fail")
            .verdict()
    }

    #[test]
    fn the_rule_needs_every_operator_to_help_and_contradicting_rows_fail() {
        let good = task(&[
            ("plain", 1.0, 10.0),
            ("delta", 0.5, 5.0),
            ("delta_frame", 0.3, 3.0),
            ("full", 0.1, 0.5),
        ]);
        assert_eq!(verdict(std::slice::from_ref(&good)), Verdict::Held);
        // An operator that changes nothing (the null of check (b)) fails it: only partly.
        let no_op = task(&[
            ("plain", 1.0, 10.0),
            ("delta", 0.5, 5.0),
            ("delta_frame", 0.5, 3.0),
            ("full", 0.1, 0.5),
        ]);
        assert!((no_op.worst_operator_ratio() - 1.0).abs() < 1e-12);
        assert_eq!(verdict(&[no_op]), Verdict::Partly);
        // The full chain's control beats the plain net's but misses the tolerance: partly.
        let misses = task(&[
            ("plain", 1.0, 100.0),
            ("delta", 0.5, 5.0),
            ("delta_frame", 0.3, 3.0),
            ("full", 0.1, 3.0),
        ]);
        assert_eq!(verdict(&[good.clone(), misses]), Verdict::Partly);
        // The full chain no better than plain (the contradicting data): not held.
        let flat = task(&[
            ("plain", 0.2, 1.5),
            ("delta", 0.2, 1.5),
            ("delta_frame", 0.2, 1.5),
            ("full", 0.2, 1.5),
        ]);
        assert_eq!(verdict(std::slice::from_ref(&flat)), Verdict::NotHeld);
        // Partly needs the training half in every task.
        assert_eq!(verdict(&[good.clone(), flat]), Verdict::NotHeld);
        // A plain net whose training failed counts as an infinite error.
        let failed = task(&[
            ("plain", f64::NAN, f64::NAN),
            ("delta", 0.5, 5.0),
            ("delta_frame", 0.3, 3.0),
            ("full", 0.1, 0.5),
        ]);
        assert_eq!(verdict(&[failed]), Verdict::Held);
    }

    #[test]
    fn a_start_already_within_tolerance_leaves_no_rule_and_stuck_descents_are_named() {
        let mut t = task(&[
            ("plain", 1.0, 10.0),
            ("delta", 0.5, 5.0),
            ("delta_frame", 0.3, 3.0),
            ("full", 0.1, 0.5),
        ]);
        t.rows[0].best_iteration = 0;
        assert_eq!(t.stuck(), vec!["plain"]);
        t.start = 0.9;
        assert!(ablation_rule(&one_seed(&[t]), &RULE).is_none());
    }

    #[test]
    fn a_ratio_of_one_is_refused_as_a_threshold() {
        assert!(RULE.validate().is_ok());
        for bad in [1.0, 1.1, 0.0] {
            let r = AblationRule {
                operator_ratio: bad,
                ..RULE
            };
            assert!(r.validate().is_err(), "{bad}");
        }
    }

    #[test]
    fn over_net_seeds_each_check_reads_the_median_and_its_interval() {
        let good = task(&[
            ("plain", 1.0, 10.0),
            ("delta", 0.5, 5.0),
            ("delta_frame", 0.3, 3.0),
            ("full", 0.1, 0.5),
        ]);
        // One seed of five whose full-chain control misses by far: the median is within
        // tolerance, but resamples that draw it three times or more are not.
        let mut miss = good.clone();
        miss.rows[3].simulator = 6.0;
        let seeds = vec![vec![
            good.clone(),
            miss,
            good.clone(),
            good.clone(),
            good.clone(),
        ]];
        let rule = ablation_rule(&seeds, &RULE).unwrap();
        let c = &rule.held[2];
        assert_eq!(c.value, 0.5);
        assert!(c.label.ends_with("median over 5 net seeds"), "{}", c.label);
        assert_eq!(c.interval, Some((0.5, 6.0)));
        assert_eq!(rule.verdict(), Verdict::Inconclusive);
        // Five alike seeds: intervals collapse and the verdict is the one seed's.
        let alike = vec![vec![good.clone(); 5]];
        assert_eq!(
            ablation_rule(&alike, &RULE).unwrap().verdict(),
            Verdict::Held
        );
    }

    #[test]
    fn a_truncated_seed_table_is_an_error_not_a_verdict_on_fewer_variants() {
        let dir = tempfile::tempdir().unwrap();
        let write = |name: &str, t| write_table(dir.path(), name, &t).unwrap();
        let variants = ["plain", "delta", "delta_frame", "full"];
        let (mut nets, mut errors, mut control, mut seeds) = (vec![], vec![], vec![], vec![]);
        for (k, v) in variants.iter().enumerate() {
            let e = 1.0 / (k + 1) as f64;
            let (task, variant) = ("truck".to_string(), v.to_string());
            nets.push(NetRow {
                task: task.clone(),
                variant: variant.clone(),
                inputs: 8,
                hidden: 20,
                outputs: 6,
                examples: 100,
                weights: 306,
                train_s: 0.1,
                stop: "max_iterations".into(),
                cached: 0,
                failed: 0,
            });
            errors.push(ErrorsRow {
                task: task.clone(),
                variant: variant.clone(),
                rollout1_error: e,
                rollout40_error_mean: e,
                rollout40_error_final: e,
                drift_emulator_m: 0.0,
                drift_simulator_m: 0.0,
                drift_gap_m: 0.0,
            });
            control.push(ControlRow {
                task: task.clone(),
                variant: variant.clone(),
                iterations: 20,
                best_iteration: 15,
                j_start: 1.0,
                j_best: 0.5,
                emulator_error: 10.0 * e,
                simulator_error: 10.0 * e,
                at_goal: 0,
                start_simulator_error: 40.0,
            });
            for s in [1, 2] {
                seeds.push(SeedRow {
                    net_seed: s,
                    task: task.clone(),
                    variant: variant.clone(),
                    rollout40_error_mean: e,
                    best_iteration: 15,
                    simulator_error: 10.0 * e,
                    start_simulator_error: 40.0,
                    failed: 0,
                });
            }
        }
        write("nets", table_of(&nets));
        write("errors", table_of(&errors));
        write("control", table_of(&control));
        write("net_seeds", table_of(&seeds));
        let rows = seeded_rows(dir.path()).unwrap();
        assert_eq!(rows.tasks.len(), 1);
        assert_eq!(rows.tasks[0].len(), 2);
        assert_eq!(rows.seeds[0], [1, 2]);
        assert_eq!(rows.tasks[0][1].rows[3].rollout40, 0.25);
        // Seed 2's last variant cut off.
        write("net_seeds", table_of(&seeds[..seeds.len() - 1]));
        let err = seeded_rows(dir.path()).unwrap_err().to_string();
        assert!(
            err.contains("net_seeds.csv") && err.contains("net seed 2"),
            "{err}"
        );
    }
}
