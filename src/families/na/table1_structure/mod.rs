//! `na_table1_structure` (NeuroAnimator §3.5–3.6, Table 1): train every emulator network of
//! Table 1 (the dolphin as a global net and six local nets, [`crate::emulator::hierarchy`]) on data sampled as in §3.4 — small nets by
//! full-batch conjugate gradient, large ones by momentum mini-batches, both stopping early on a
//! held-out set — and report the shapes, the example counts and the errors reached.
//!
//! Errors are mean squared errors per output in the normalized network space (Fig. 6c), where
//! 1.0 is the error of always predicting the mean state change; so they compare across models.
//! Networks come from the trained-emulator cache ([`crate::emulator::cache`]) when an identical
//! one was trained before (`train_s` then repeats the original training time).
//!
//! Tables: `structure` (net, inputs, hidden, outputs, examples, train_error, heldout_error,
//! train_s, weights, examples_per_weight, stop, cached, rollout40_error_mean,
//! rollout40_error_final), `training` (net, iteration, train_error, heldout_error), `rollout`
//! (net, step, error; the dolphin as `dolphin_global`, its global net alone, and `dolphin`, the
//! composed hierarchy) and `drift` (net, task, horizon_s, emulator_drift, simulator_drift, gap,
//! tolerance: neutral-control drift from the control tasks' starts, [`DriftTask`]) and
//! `rollout_training` (net, iteration, train_loss, heldout_loss: the k-step rollout
//! fine-tuning, [`crate::emulator::rollout`], when `training.rollout_k` is set; the `stop`
//! column then ends with `; rollout: <its stop reason>`), and for the dolphin `global_error`
//! (segment, quantity, component, heldout_mse, target_variance: the global net's held-out
//! one-step error per output, whose mean is its `heldout_error`, and the variance of that
//! output's target), and when `normalizations` is set `normalization` (net, normalization,
//! in_spec, rollout1_error, rollout40_error_mean, rollout40_error_final, train_s, cached: every
//! catalog net built under each normalization and rolled out as in `rollout`; in_spec = 1 on the
//! net's own, [`normalization_pick`] the rule that chose it).
//!
//! Here: the parameters and their validation, and the family; `nets` builds the Table 1
//! networks (also for the other NeuroAnimator experiments and `motionlab emulate`), `job` trains
//! them and measures them, `figures` and `report` present the results.

mod figures;
mod job;
mod nets;
mod report;
mod rows;

pub(crate) use job::dolphin_drift;
pub use job::{ROLLOUT_EPISODES, ROLLOUT_STEPS};
pub use nets::{
    build_dolphin_emulator, build_emulator, build_emulators, build_spec, table1_emulator,
    Table1Emulator, EMULATOR_NAMES,
};

use crate::emulator::cache::fnv1a;
use crate::emulator::catalog::{DataRegime, NetModel, NetSpec, Normalization, TrainSettings};
use crate::emulator::hierarchy::{HierarchyNet, HierarchySpec};
use crate::experiment::output::Tables;
use crate::experiment::plot::FigureSink;
use crate::experiment::report::Findings;
use crate::experiment::resolve::{ensure, positive, ParamError, Validate};
use crate::experiment::{Error, Family};
use crate::seed::mix_seed;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// The family.
pub struct NaStructure;

/// Parameters of `na_table1_structure`.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Params {
    /// Physical steps per emulator step n (the paper's N50: 50).
    pub steps: usize,
    /// Multiplies every net's example count (1 = Table 1; quick runs use less).
    pub example_scale: f64,
    /// The networks.
    pub nets: Vec<NetSpec>,
    /// Training settings.
    pub training: TrainSettings,
    /// The hierarchical dolphin (a global net and six local nets), if built.
    #[serde(default)]
    pub dolphin: Option<DolphinNets>,
    /// Neutral-control drift checks from the control tasks' starts (`drift.csv`).
    #[serde(default)]
    pub drift: Vec<DriftTask>,
    /// Normalizations (Appendix A) under which every catalog net is also built and rolled out
    /// (`normalization.csv`; the net's own is reused): how each net's `normalization` was
    /// chosen, [`normalization_pick`]. Empty: no comparison.
    #[serde(default)]
    pub normalizations: Vec<Normalization>,
    /// Per catalog net, the tolerances its fidelity on the control tasks' inputs is measured in
    /// (`regime_fidelity.csv`, [`crate::emulator::catalog::regime_fidelity`]).
    #[serde(default)]
    pub regime: Vec<RegimeTolerance>,
    /// Second lines: every catalog net that has a `regime` entry built again with one change
    /// and measured the same way (`regime_fidelity.csv`'s `variant`; the nets above are
    /// `paper`).
    #[serde(default)]
    pub variants: Vec<NetVariant>,
    /// The verdict's thresholds (ours; the paper states no number).
    pub rule: Table1Rule,
}

/// The verdict's thresholds ([`report::table1_rule`]; ours, the paper states no number). A net
/// passes when it has learned, is not overfitted, is faithful over 40 super-steps and, for a
/// catalog net, is faithful on the control tasks' inputs.
#[derive(Debug, Clone, Copy, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Table1Rule {
    /// Learned: held-out one-step MSE below this fraction of the normalized state-change
    /// variance (1 is what predicting the mean scores).
    pub heldout_max: f64,
    /// Not overfitted: held-out MSE at most this much above training (an absolute gap).
    pub overfit_gap: f64,
    /// Faithful: mean 40-step rollout error below this fraction of the state variance, where
    /// measured.
    pub rollout_max: f64,
    /// Faithful on the tasks' inputs: every toleranced quantity's median 40-step open-loop
    /// error on the tasks' regime ([`crate::emulator::catalog::regime_fidelity`]) within this
    /// many of its Fig. 13 task's tolerances.
    pub regime_rollout_max: f64,
}

impl Table1Rule {
    fn validate(&self) -> Result<(), ParamError> {
        for (key, v) in [
            ("heldout_max", self.heldout_max),
            ("rollout_max", self.rollout_max),
        ] {
            ensure(
                v > 0.0 && v < 1.0,
                &format!("rule.{key}"),
                "must be in (0, 1): 1 is what predicting the mean scores",
            )?;
        }
        positive("rule.overfit_gap", self.overfit_gap)?;
        positive("rule.regime_rollout_max", self.regime_rollout_max)
    }
}

/// The tolerances of one catalog net's regime fidelity: the Fig. 13 task's final tolerance per
/// state variable (0: not measured).
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RegimeTolerance {
    /// The catalog net's model name.
    pub net: String,
    /// One tolerance per state variable, in the variable's units.
    pub tolerance: Vec<f64>,
}

/// A second line of every catalog net: the net of `nets` with its data regime or its input
/// noise changed.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NetVariant {
    /// Its name in `regime_fidelity.csv` (not `paper`).
    pub name: String,
    /// Where its data come from, if not the net's own.
    #[serde(default)]
    pub data: Option<DataRegime>,
    /// Its input noise, if not the net's own.
    #[serde(default)]
    pub input_noise: Option<f64>,
}

impl NetVariant {
    /// `net` with this variant's change.
    pub fn apply(&self, net: &NetSpec) -> NetSpec {
        let mut v = net.clone();
        if let Some(d) = self.data {
            v.data = d;
        }
        if let Some(noise) = self.input_noise {
            v.input_noise = Some(noise);
        }
        v
    }
}

/// Relative margin within which a grouped normalization is preferred to a lower-error one
/// (ours; `experiments/na_table1_structure.toml` states the rule).
pub const NORMALIZATION_MARGIN: f64 = 0.10;

/// The normalization the spec's rule picks from `(normalization, mean 40-step rollout error)`
/// rows of one net: among those within [`NORMALIZATION_MARGIN`] of the lowest error, the first
/// in the order quantity groups, Appendix A's state/control groups, per variable (Appendix A
/// prescribes groups). `None` when no row has a finite error.
pub fn normalization_pick(rows: &[(Normalization, f64)]) -> Option<Normalization> {
    let best = rows
        .iter()
        .map(|r| r.1)
        .filter(|e| e.is_finite())
        .fold(f64::INFINITY, f64::min);
    if !best.is_finite() {
        return None;
    }
    [
        Normalization::Quantities,
        Normalization::StateControl,
        Normalization::Variable,
    ]
    .into_iter()
    .find(|n| {
        rows.iter()
            .any(|r| r.0 == *n && r.1 <= best * (1.0 + NORMALIZATION_MARGIN))
    })
}

/// A drift check: from a control task's start, `ROLLOUT_STEPS` super-steps of a neutral control
/// held on the emulator and on the simulator; the position part of the state (pendulum: the
/// three joint angles; truck: x, y; lander: x, y, z; dolphin: the mean segment centroid) must
/// end within `tolerance` of the simulator's.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DriftTask {
    /// The net: a catalog model name or `dolphin` (the hierarchy's global net).
    pub net: String,
    /// The control task whose start it is.
    pub task: String,
    /// The start state (catalog nets; the dolphin starts from its rest shape at rest).
    #[serde(default)]
    pub start: Vec<f64>,
    /// The neutral control held throughout (empty: all zero).
    #[serde(default)]
    pub control: Vec<f64>,
    /// Largest emulator-vs-simulator gap of the position part at the end (ours: the task's
    /// final position tolerance).
    pub tolerance: f64,
}

/// Indices of the position part of a catalog model's state, for the drift checks.
pub fn position_part(m: NetModel) -> std::ops::Range<usize> {
    match m {
        NetModel::Truck => 0..2,
        _ => 0..3,
    }
}

/// The dolphin hierarchy of Table 1 as experiment files give it (§3.3).
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DolphinNets {
    /// The global net (Table 1: 50 hidden units, 64,000 examples).
    pub global: HierarchyNet,
    /// Each of the six local nets (Table 1: 40 hidden units, 32,000 examples).
    pub local: HierarchyNet,
    /// Physical step δt of the dolphin simulator (s).
    pub physical_dt: f64,
    /// Training settings of the dolphin nets.
    pub training: TrainSettings,
}

impl DolphinNets {
    /// Checks the settings; `key` prefixes the keys in messages.
    pub fn validate(&self, key: &str, scale: f64) -> Result<(), ParamError> {
        for (name, n) in [("global", &self.global), ("local", &self.local)] {
            ensure(
                n.hidden >= 1,
                &format!("{key}.{name}.hidden"),
                "must be >= 1",
            )?;
            ensure(
                (n.examples as f64 * scale).round() >= 10.0,
                &format!("{key}.{name}.examples"),
                "need at least 10 examples after example_scale",
            )?;
            ensure(
                n.max_epochs.is_none_or(|e| e >= 1),
                &format!("{key}.{name}.max_epochs"),
                "must be >= 1",
            )?;
        }
        ensure(
            self.physical_dt > 0.0 && self.physical_dt <= 0.004,
            &format!("{key}.physical_dt"),
            "must be in (0, 0.004] s: the dolphin's semi-implicit Euler step is stable up to about 0.006 s",
        )?;
        validate_training(&self.training).map_err(|e| e.prefixed(key))
    }

    /// The build spec at n = `steps` physical steps per emulator step.
    pub fn spec(&self, seed: u64, steps: usize, example_scale: f64) -> HierarchySpec {
        let scaled = |n: &HierarchyNet| HierarchyNet {
            examples: (n.examples as f64 * example_scale).round() as usize,
            ..*n
        };
        HierarchySpec {
            global: scaled(&self.global),
            local: scaled(&self.local),
            physical_dt: self.physical_dt,
            steps,
            settings: self.training,
            seed: mix_seed(seed, fnv1a(format!("dolphin-n{steps}").as_bytes())),
            global_transforms: crate::emulator::catalog::TransformSet::Full,
        }
    }
}

/// Checks the shared training settings.
pub fn validate_training(t: &TrainSettings) -> Result<(), ParamError> {
    ensure(
        t.held_out_fraction > 0.0 && t.held_out_fraction <= 1.0,
        "training.held_out_fraction",
        "must be in (0, 1]",
    )?;
    ensure(t.cg_max_iters >= 1, "training.cg_max_iters", "must be >= 1")?;
    ensure(t.max_epochs >= 1, "training.max_epochs", "must be >= 1")?;
    ensure(t.patience >= 1, "training.patience", "must be >= 1")?;
    ensure(
        (0.0..1.0).contains(&t.min_improvement),
        "training.min_improvement",
        "must be in [0, 1)",
    )?;
    positive("training.learning_rate", t.learning_rate)?;
    ensure(
        (0.0..1.0).contains(&t.momentum),
        "training.momentum",
        "must be in [0, 1)",
    )?;
    ensure(t.batch_size >= 1, "training.batch_size", "must be >= 1")?;
    ensure(
        t.input_noise >= 0.0 && t.input_noise.is_finite(),
        "training.input_noise",
        "must be >= 0",
    )?;
    if t.rollout_k > 0 {
        positive("training.rollout_weight", t.rollout_weight)?;
        ensure(
            t.rollout_iters >= 1,
            "training.rollout_iters",
            "must be >= 1 when rollout_k is set",
        )?;
    }
    Ok(())
}

/// Checks a list of second lines (`key` names it in messages): unique names other than
/// `paper`, each changing something, any input noise non-negative.
pub fn validate_variants(variants: &[NetVariant], key: &str) -> Result<(), ParamError> {
    for (i, v) in variants.iter().enumerate() {
        let key = format!("{key}[{i}]");
        ensure(
            v.name != "paper" && !variants[..i].iter().any(|w| w.name == v.name),
            &format!("{key}.name"),
            "must be unique and not `paper`",
        )?;
        ensure(
            v.data.is_some() || v.input_noise.is_some(),
            &key,
            "must change `data` or `input_noise`",
        )?;
        if let Some(noise) = v.input_noise {
            ensure(
                noise >= 0.0 && noise.is_finite(),
                &format!("{key}.input_noise"),
                "must be >= 0",
            )?;
        }
    }
    Ok(())
}

/// Checks a list of nets.
pub fn validate_nets(nets: &[NetSpec], scale: f64) -> Result<(), ParamError> {
    ensure(!nets.is_empty(), "nets", "need at least one net")?;
    positive("example_scale", scale)?;
    for (i, n) in nets.iter().enumerate() {
        ensure(n.hidden >= 1, &format!("nets[{i}].hidden"), "must be >= 1")?;
        positive(&format!("nets[{i}].physical_dt"), n.physical_dt)?;
        if let Some(v) = n.input_noise {
            ensure(
                v >= 0.0 && v.is_finite(),
                &format!("nets[{i}].input_noise"),
                "must be >= 0",
            )?;
        }
        ensure(
            (n.examples as f64 * scale).round() >= 10.0,
            &format!("nets[{i}].examples"),
            "need at least 10 examples after example_scale",
        )?;
    }
    Ok(())
}

impl Validate for Params {
    fn validate(&self) -> Result<(), ParamError> {
        ensure(self.steps >= 1, "steps", "must be >= 1")?;
        self.rule.validate()?;
        validate_nets(&self.nets, self.example_scale)?;
        if let Some(d) = &self.dolphin {
            d.validate("dolphin", self.example_scale)?;
        }
        for (i, t) in self.drift.iter().enumerate() {
            let key = format!("drift[{i}]");
            positive(&format!("{key}.tolerance"), t.tolerance)?;
            if t.net == "dolphin" {
                ensure(
                    self.dolphin.is_some(),
                    &format!("{key}.net"),
                    "the dolphin drift check needs [params.dolphin]",
                )?;
                ensure(
                    t.control.is_empty() || t.control.len() == 6,
                    &format!("{key}.control"),
                    "needs 6 muscle values (or none)",
                )?;
                continue;
            }
            let m = self
                .nets
                .iter()
                .find(|n| n.model.name() == t.net)
                .map(|n| n.model);
            ensure(
                m.is_some(),
                &format!("{key}.net"),
                "must name a net of `nets` or `dolphin`",
            )?;
            let m = m.expect("checked");
            ensure(
                t.start.len() == m.state_dim(),
                &format!("{key}.start"),
                format!("needs {} values", m.state_dim()),
            )?;
            ensure(
                t.control.is_empty() || t.control.len() == m.control_dim(),
                &format!("{key}.control"),
                format!("needs {} values (or none)", m.control_dim()),
            )?;
        }
        for (i, r) in self.regime.iter().enumerate() {
            let key = format!("regime[{i}]");
            let m = self
                .nets
                .iter()
                .find(|n| n.model.name() == r.net)
                .map(|n| n.model);
            ensure(
                m.is_some(),
                &format!("{key}.net"),
                "must name a net of `nets`",
            )?;
            let m = m.expect("checked");
            ensure(
                r.tolerance.len() == m.state_dim(),
                &format!("{key}.tolerance"),
                format!("needs {} values", m.state_dim()),
            )?;
            ensure(
                r.tolerance.iter().all(|t| t.is_finite() && *t >= 0.0)
                    && r.tolerance.iter().any(|t| *t > 0.0),
                &format!("{key}.tolerance"),
                "must be >= 0 and finite, at least one positive",
            )?;
        }
        validate_variants(&self.variants, "variants")?;
        for (i, n) in self.normalizations.iter().enumerate() {
            ensure(
                !self.normalizations[..i].contains(n),
                &format!("normalizations[{i}]"),
                "is listed twice",
            )?;
        }
        validate_training(&self.training)
    }
}

impl Family for NaStructure {
    const CAPTIONS: &'static [(&'static str, &'static str)] = &[
        (
            "training",
            "each Table 1 net's one-step MSE per output (normalized) on its training and held-out sets vs iteration (L-BFGS) or epoch (momentum), with the table's final errors as dotted lines (the dolphin's global net's after its rollout fine-tuning); the catalog nets train one step ahead without input noise, the dolphin's nets with it, which is why their training error can lie above the clean held-out error; the grey dashed line is the verdict's bar on the final held-out error; one legend, in the first panel, serves all.",
        ),
        (
            "rollout",
            "each net's mean squared error (over the state variance) against the simulator over 40 super-steps on fresh episodes.",
        ),
    ];
    const KIND: &'static str = "na_table1_structure";
    type Params = Params;

    fn figures(&self, fig: &FigureSink, tables: &Tables) -> Result<Vec<PathBuf>, Error> {
        figures::draw(fig, tables)
    }

    fn report(&self, dir: &Path) -> Result<Findings, Error> {
        report::findings(dir)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use Normalization::{Quantities, StateControl, Variable};

    /// The spec's rule: groups win within 10% of the lowest mean 40-step error, quantity groups
    /// first; per variable only when every grouping is clearly worse; no pick without a finite
    /// error.
    #[test]
    fn normalization_pick_prefers_groups_within_the_margin() {
        let pick = |v: f64, q: f64, s: f64| {
            normalization_pick(&[(Variable, v), (Quantities, q), (StateControl, s)])
        };
        assert_eq!(pick(1.0, 1.09, 2.0), Some(Quantities));
        assert_eq!(pick(1.0, 1.2, 1.05), Some(StateControl));
        assert_eq!(pick(1.0, 1.2, 1.3), Some(Variable));
        assert_eq!(pick(1.5, 1.0, 1.0), Some(Quantities));
        assert_eq!(pick(1.0, f64::NAN, 5.0), Some(Variable));
        assert_eq!(pick(f64::NAN, f64::NAN, f64::INFINITY), None);
    }

    /// Every net of the shipped spec carries the normalization the rule picked from the
    /// committed comparison, and every NeuroAnimator spec builds each model with the same one
    /// (so they share the cached net).
    #[test]
    fn shipped_nets_carry_the_rules_pick() {
        let root = Path::new(env!("CARGO_MANIFEST_DIR"));
        let csv = root.join("results/na_table1_structure/normalization.csv");
        let text = std::fs::read_to_string(&csv).expect("committed normalization.csv");
        let mut rows: Vec<(String, Normalization, f64, bool)> = Vec::new();
        for line in text.lines().skip(1) {
            let f: Vec<&str> = line.split(',').collect();
            let norm = Normalization::ALL
                .into_iter()
                .find(|n| n.name() == f[1])
                .expect("known normalization");
            rows.push((f[0].to_string(), norm, f[4].parse().unwrap(), f[2] == "1"));
        }
        assert!(!rows.is_empty());
        let spec =
            std::fs::read_to_string(root.join("experiments/na_table1_structure.toml")).unwrap();
        let value: toml::Value = toml::from_str(&spec).unwrap();
        let nets: Vec<NetSpec> = value["params"]["nets"]
            .clone()
            .try_into()
            .expect("nets parse");
        for net in &nets {
            let these: Vec<(Normalization, f64)> = rows
                .iter()
                .filter(|r| r.0 == net.model.name())
                .map(|r| (r.1, r.2))
                .collect();
            assert_eq!(
                normalization_pick(&these),
                Some(net.normalization),
                "{}",
                net.model.name()
            );
        }
        for entry in std::fs::read_dir(root.join("experiments")).unwrap() {
            let path = entry.unwrap().path();
            if path.extension().and_then(|e| e.to_str()) != Some("toml") {
                continue;
            }
            let text = std::fs::read_to_string(&path).unwrap();
            for net in &nets {
                let needle = format!("model = \"{}\"", net.model.name());
                for line in text.lines().filter(|l| l.contains(&needle)) {
                    let want = format!("normalization = \"{}\"", net.normalization.name());
                    let grouped = net.normalization != Normalization::Variable;
                    assert!(
                        line.contains(&want) || (!grouped && !line.contains("normalization")),
                        "{}: {line}",
                        path.display()
                    );
                }
            }
        }
    }
}
