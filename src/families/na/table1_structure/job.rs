//! The job: train every Table 1 net (side by side), measure its rollouts against the
//! simulator and its neutral-control drift from the control tasks' starts, and tabulate it all.

use super::nets::{build_dolphin_emulator, build_emulators, build_spec};
use super::rows::{
    DriftRow, GlobalErrorRow, NormalizationRow, RegimeFidelityRow, RolloutRow, RolloutTrainingRow,
    StructureRow, TrainingRow,
};
use super::{position_part, DolphinNets, DriftTask, Params};
use crate::emulator::catalog::{
    anchor_of, regime_fidelity, regime_share, rollout_error, training_transitions, BuildSpec,
    DataRegime, NetModel, NetSpec, Trained,
};
use crate::emulator::hierarchy::{
    global_heldout_errors, hierarchy_rollout_error, DolphinEmulator, HierarchySpec,
};
use crate::emulator::mlp::Mlp;
use crate::emulator::train::TracePoint;
use crate::experiment::output::Tables;
use crate::experiment::rows::table_of;
use crate::experiment::rule::rule_table_of;
use crate::experiment::{other, Error, Job, RunContext};

/// Quantity and component of each of a segment's 13 global-state numbers (`global_error.csv`).
const GLOBAL_OUTPUTS: [(&str, &str); 13] = [
    ("centroid", "x"),
    ("centroid", "y"),
    ("centroid", "z"),
    ("orientation", "w"),
    ("orientation", "x"),
    ("orientation", "y"),
    ("orientation", "z"),
    ("velocity", "x"),
    ("velocity", "y"),
    ("velocity", "z"),
    ("angular_velocity", "x"),
    ("angular_velocity", "y"),
    ("angular_velocity", "z"),
];

/// Position part at the end of `steps` emulator steps and of the simulator over the same time,
/// from `start` under the constant control `u`: (emulator, simulator, start) positions.
fn catalog_drift(
    e: &crate::emulator::Emulator,
    spec: &BuildSpec,
    start: &[f64],
    u: &[f64],
    steps: usize,
) -> Result<[Vec<f64>; 3], Error> {
    let m = spec.net.model;
    let (mut xe, mut xs, mut next) = (start.to_vec(), start.to_vec(), start.to_vec());
    let mut sc = e.scratch();
    let mut sim = m.simulator();
    for k in 0..steps {
        e.predict(&xe, u, &mut sc, &mut next);
        xe.copy_from_slice(&next);
        for _ in 0..spec.steps {
            sim.step(&mut xs, u, spec.net.physical_dt);
        }
        let t = (k + 1) as f64 * spec.super_dt();
        crate::physics::check_finite(m.name(), k + 1, t, &xs).map_err(other)?;
    }
    let p = position_part(m);
    Ok([
        xe[p.clone()].to_vec(),
        xs[p.clone()].to_vec(),
        start[p].to_vec(),
    ])
}

/// As [`catalog_drift`] for the dolphin's global net from the rest shape at rest, the position
/// being the mean segment centroid.
pub(crate) fn dolphin_drift(
    e: &DolphinEmulator,
    spec: &HierarchySpec,
    u: &[f64],
    steps: usize,
) -> Result<[Vec<f64>; 3], Error> {
    use crate::emulator::hierarchy::{global_state, simulator, FRAME_DIM, GLOBAL_DIM};
    use crate::physics::Dynamics;
    let d = e.dolphin();
    let mean = |g: &[f64]| -> Vec<f64> {
        (0..3)
            .map(|c| (0..6).map(|s| g[FRAME_DIM * s + c]).sum::<f64>() / 6.0)
            .collect()
    };
    let x0 = d.rest_state();
    let mut g = vec![0.0; GLOBAL_DIM];
    global_state(d, &x0, &mut g);
    let start = mean(&g);
    let (mut next, mut sc) = (g.clone(), e.global().scratch());
    let (mut sim, mut xs) = (simulator(d), x0);
    for k in 0..steps {
        e.global().predict(&g, u, &mut sc, &mut next);
        g.copy_from_slice(&next);
        for _ in 0..spec.steps {
            sim.step(&mut xs, u, spec.physical_dt);
        }
        let t = (k + 1) as f64 * spec.super_dt();
        crate::physics::check_finite("dolphin", k + 1, t, &xs).map_err(other)?;
    }
    let emu = mean(&g);
    global_state(d, &xs, &mut g);
    Ok([emu, mean(&g), start])
}

/// Fresh episodes per net for the multi-step fidelity columns.
pub const ROLLOUT_EPISODES: usize = 32;
/// Super-steps per rollout: the 40 of the Fig. 13 control tasks.
pub const ROLLOUT_STEPS: usize = 40;

impl Job for Params {
    fn params_json(&self) -> serde_json::Value {
        serde_json::to_value(self).unwrap_or_default()
    }

    fn run(&self, ctx: &RunContext) -> Result<Tables, Error> {
        let mut t = StructureTables::default();
        let pb = ctx.progress(self.nets.len() as u64, "training emulators");
        let mut shares = Shares::default();
        let specs: Vec<BuildSpec> = self
            .nets
            .iter()
            .map(|net| {
                build_spec(
                    ctx.seed,
                    net,
                    self.steps,
                    self.example_scale,
                    &self.training,
                )
            })
            .collect();
        let built = ctx.stage("train emulators (side by side)", || build_emulators(&specs))?;
        for ((net, spec), trained) in self.nets.iter().zip(&specs).zip(built) {
            self.record_net(ctx, net, spec, &trained, &mut shares, &mut t)?;
            pb.inc(1);
        }
        let normalization = self.normalization_table(ctx, &specs)?;
        let regime_fidelity = self.regime_table(ctx, &specs, &mut shares)?;
        if let Some(d) = &self.dolphin {
            self.record_dolphin(ctx, d, &mut t)?;
        }
        pb.finish_and_clear();
        Ok(Tables::from([
            ("structure", table_of(&t.structure)),
            ("training", table_of(&t.training)),
            ("rollout", table_of(&t.rollout)),
            ("drift", table_of(&t.drift)),
            ("rollout_training", table_of(&t.rollout_training)),
            ("global_error", table_of(&t.global_error)),
            ("normalization", table_of(&normalization)),
            ("regime_fidelity", table_of(&regime_fidelity)),
            ("rule", rule_table_of(&self.rule)?),
        ]))
    }
}

/// The tables every net's rows go to (the normalization and regime tables are built apart).
#[derive(Default)]
struct StructureTables {
    structure: Vec<StructureRow>,
    training: Vec<TrainingRow>,
    rollout: Vec<RolloutRow>,
    /// The k-step rollout fine-tuning (training.rollout_k): one-step loss + rollout_weight x
    /// k-step rollout loss, on the training and held-out examples and windows.
    rollout_training: Vec<RolloutTrainingRow>,
    global_error: Vec<GlobalErrorRow>,
    drift: Vec<DriftRow>,
}

impl StructureTables {
    /// A drift task's row from its ends (emulated, simulated, start) after `horizon_s`.
    /// at_anchor: the start and control encode to the net's anchor (NetSpec::anchor), so
    /// the emulator's first step is exact by construction, not by fit.
    fn push_drift(
        &mut self,
        t: &DriftTask,
        horizon_s: f64,
        [e, s, x0]: [Vec<f64>; 3],
        at_anchor: bool,
    ) {
        self.drift.push(DriftRow {
            net: t.net.clone(),
            task: t.task.clone(),
            horizon_s,
            emulator_drift: dist(&e, &x0),
            simulator_drift: dist(&s, &x0),
            gap: dist(&e, &s),
            tolerance: t.tolerance,
            at_anchor: i64::from(at_anchor),
        });
    }

    /// A net's training curves: its one-step `training` rows and its rollout fine-tuning's.
    fn push_traces(&mut self, name: &str, trace: &[TracePoint], rollout_trace: &[TracePoint]) {
        for p in trace {
            self.training.push(TrainingRow {
                net: name.to_string(),
                iteration: p.iteration as i64,
                train_error: p.train_error,
                heldout_error: p.held_out_error,
            });
        }
        for p in rollout_trace {
            self.rollout_training.push(RolloutTrainingRow {
                net: name.to_string(),
                iteration: p.iteration as i64,
                train_loss: p.train_error,
                heldout_loss: p.held_out_error,
            });
        }
    }
}

/// The Euclidean distance of `a` and `b`.
fn dist(a: &[f64], b: &[f64]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).powi(2))
        .sum::<f64>()
        .sqrt()
}

impl Params {
    /// One trained Table 1 net: its rollout errors, its drift tasks, its `structure` row
    /// (with its regime share) and its training curves.
    fn record_net(
        &self,
        ctx: &RunContext,
        net: &NetSpec,
        spec: &BuildSpec,
        t: &Trained,
        shares: &mut Shares,
        tables: &mut StructureTables,
    ) -> Result<(), Error> {
        let name = net.model.name();
        let m = net.model;
        let (n_in, n_out) = (m.state_dim() + m.control_dim(), m.state_dim());
        let w = Mlp::weight_count(n_in, net.hidden, n_out);
        let errors = ctx.stage(&format!("rollouts {name}"), || {
            rollout_error(&t.emulator, spec, ROLLOUT_EPISODES, ROLLOUT_STEPS).map_err(other)
        })?;
        for (k, e) in errors.iter().enumerate() {
            tables.rollout.push(RolloutRow {
                net: name.to_string(),
                step: (k + 1) as i64,
                error: *e,
            });
        }
        for task in self.drift.iter().filter(|d| d.net == name) {
            let u = if task.control.is_empty() {
                vec![0.0; m.control_dim()]
            } else {
                task.control.clone()
            };
            let ends = catalog_drift(&t.emulator, spec, &task.start, &u, ROLLOUT_STEPS)?;
            let tf = t.emulator.transforms();
            let at_anchor = anchor_of(spec, tf).is_some_and(|a| a.covers(tf, &task.start, &u));
            tables.push_drift(
                task,
                ROLLOUT_STEPS as f64 * spec.super_dt(),
                ends,
                at_anchor,
            );
        }
        let mean = errors.iter().sum::<f64>() / errors.len() as f64;
        tables.structure.push(StructureRow {
            net: name.to_string(),
            inputs: n_in as i64,
            hidden: net.hidden as i64,
            outputs: n_out as i64,
            examples: spec.net.examples as i64,
            train_error: t.train_error,
            heldout_error: t.heldout_error,
            train_s: t.train_s,
            weights: w as i64,
            examples_per_weight: spec.net.examples as f64 / w as f64,
            stop: t.stop.clone(),
            cached: i64::from(t.from_cache),
            rollout40_error_mean: mean,
            rollout40_error_final: errors[errors.len() - 1],
            anchored: i64::from(net.anchor),
            regime_share: ctx.stage(&format!("regime share {name}"), || shares.get(spec))?,
            data: spec.net.data.name().to_string(),
        });
        tables.push_traces(name, &t.trace, &t.rollout_trace);
        Ok(())
    }

    /// The dolphin hierarchy: trained, its global and composed rollout errors, the global
    /// net's held-out error per output, its drift tasks, and every net's `structure` row and
    /// training curves.
    fn record_dolphin(
        &self,
        ctx: &RunContext,
        d: &DolphinNets,
        tables: &mut StructureTables,
    ) -> Result<(), Error> {
        let spec = d.spec(ctx.seed, self.steps, self.example_scale);
        let built = ctx.stage("train dolphin hierarchy", || build_dolphin_emulator(&spec))?;
        let (global_err, composed_err) = ctx.stage("rollouts dolphin", || {
            hierarchy_rollout_error(&built.emulator, &spec, ROLLOUT_EPISODES, ROLLOUT_STEPS)
                .map_err(other)
        })?;
        for (name, errors) in [("dolphin_global", &global_err), ("dolphin", &composed_err)] {
            for (k, e) in errors.iter().enumerate() {
                tables.rollout.push(RolloutRow {
                    net: name.to_string(),
                    step: (k + 1) as i64,
                    error: *e,
                });
            }
        }
        let per_output = ctx.stage("dolphin global error by output", || {
            global_heldout_errors(&built.emulator, &spec).map_err(other)
        })?;
        for (j, (e, v)) in per_output.iter().enumerate() {
            let (quantity, component) = GLOBAL_OUTPUTS[j % 13];
            tables.global_error.push(GlobalErrorRow {
                segment: (j / 13) as i64,
                quantity: quantity.to_string(),
                component: component.to_string(),
                heldout_mse: *e,
                target_variance: *v,
            });
        }
        for task in self.drift.iter().filter(|d| d.net == "dolphin") {
            let u = if task.control.is_empty() {
                vec![0.0; 6]
            } else {
                task.control.clone()
            };
            let ends = dolphin_drift(&built.emulator, &spec, &u, ROLLOUT_STEPS)?;
            tables.push_drift(task, ROLLOUT_STEPS as f64 * spec.super_dt(), ends, false);
        }
        let summary = |e: &[f64]| (e.iter().sum::<f64>() / e.len() as f64, e[e.len() - 1]);
        for n in &built.nets {
            // The global net's own rollout; the local nets act only composed, so their rows
            // carry the composed hierarchy's mass-state rollout.
            let (mean, last) = if n.name == "dolphin_global" {
                summary(&global_err)
            } else {
                summary(&composed_err)
            };
            let w = Mlp::weight_count(n.inputs, n.hidden, n.outputs);
            tables.structure.push(StructureRow {
                net: n.name.clone(),
                inputs: n.inputs as i64,
                hidden: n.hidden as i64,
                outputs: n.outputs as i64,
                examples: n.examples as i64,
                train_error: n.train_error,
                heldout_error: n.heldout_error,
                train_s: n.train_s,
                weights: w as i64,
                examples_per_weight: n.examples as f64 / w as f64,
                stop: n.stop.clone(),
                cached: i64::from(n.from_cache),
                rollout40_error_mean: mean,
                rollout40_error_final: last,
                anchored: 0,
                regime_share: f64::NAN,
                data: "typical".into(),
            });
            tables.push_traces(n.name.as_str(), &n.trace, &n.rollout_trace);
        }
        Ok(())
    }
}

/// The share of a net's training examples in its model's task regime, sampled once per model
/// and data regime: it depends on the data alone, so the nets that differ only in training
/// (input noise, normalization) share it.
#[derive(Default)]
struct Shares(Vec<((NetModel, DataRegime), f64)>);

impl Shares {
    fn get(&mut self, spec: &BuildSpec) -> Result<f64, Error> {
        let key = (spec.net.model, spec.net.data);
        if let Some(s) = self.0.iter().find(|s| s.0 == key) {
            return Ok(s.1);
        }
        let train = training_transitions(spec).map_err(other)?;
        let share = regime_share(spec.net.model, &train);
        self.0.push((key, share));
        Ok(share)
    }
}

impl Params {
    /// `regime_fidelity.csv`: each catalog net with a `regime` entry (variant `paper`) and its
    /// `variants` (built side by side, cached), measured on the control tasks' inputs in
    /// tolerance units ([`regime_fidelity`]), with the share of its training examples in the
    /// tasks' regime.
    fn regime_table(
        &self,
        ctx: &RunContext,
        specs: &[BuildSpec],
        shares: &mut Shares,
    ) -> Result<Vec<RegimeFidelityRow>, Error> {
        let mut table = Vec::new();
        let mut lines: Vec<(&str, BuildSpec, &[f64])> = Vec::new();
        for r in &self.regime {
            let Some(spec) = specs.iter().find(|s| s.net.model.name() == r.net) else {
                continue;
            };
            lines.push(("paper", spec.clone(), &r.tolerance));
            for v in &self.variants {
                let mut vs = spec.clone();
                vs.net = v.apply(&spec.net);
                lines.push((v.name.as_str(), vs, &r.tolerance));
            }
        }
        let all: Vec<BuildSpec> = lines.iter().map(|l| l.1.clone()).collect();
        let built = ctx.stage("train regime variants (side by side)", || {
            build_emulators(&all)
        })?;
        for ((variant, spec, tolerance), t) in lines.iter().zip(&built) {
            let model = spec.net.model;
            let label = format!("regime fidelity {} ({variant})", model.name());
            let rows = ctx.stage(&label, || {
                regime_fidelity(
                    &t.emulator,
                    spec,
                    tolerance,
                    ROLLOUT_EPISODES,
                    ROLLOUT_STEPS,
                )
                .map_err(other)
            })?;
            let share = shares.get(spec)?;
            let names = model.state_names();
            for f in rows {
                table.push(RegimeFidelityRow {
                    net: model.name().to_string(),
                    quantity: names[f.variable].clone(),
                    bias_tol: f.bias_tol,
                    rms_tol: f.rms_tol,
                    rollout40_tol: f.rollout_tol,
                    variant: variant.to_string(),
                    data: spec.net.data.name().to_string(),
                    input_noise: spec.effective_settings().input_noise,
                    tolerance: f.tolerance,
                    regime_share: share,
                    stop: t.stop.clone(),
                });
            }
        }
        Ok(table)
    }

    /// `normalization.csv`: every catalog net of `specs` built under each of
    /// `self.normalizations` (the ones not already built, side by side, cached) and rolled out
    /// beside the simulator as `rollout.csv` is.
    fn normalization_table(
        &self,
        ctx: &RunContext,
        specs: &[BuildSpec],
    ) -> Result<Vec<NormalizationRow>, Error> {
        let mut table = Vec::new();
        if self.normalizations.is_empty() {
            return Ok(table);
        }
        let variants: Vec<BuildSpec> = specs
            .iter()
            .flat_map(|s| {
                self.normalizations.iter().map(move |&n| {
                    let mut v = s.clone();
                    v.net.normalization = n;
                    v
                })
            })
            .collect();
        let built = ctx.stage("train normalization variants (side by side)", || {
            build_emulators(&variants)
        })?;
        for (spec, t) in variants.iter().zip(&built) {
            let errors = ctx.stage(
                &format!(
                    "rollouts {} ({})",
                    spec.net.model.name(),
                    spec.net.normalization.name()
                ),
                || rollout_error(&t.emulator, spec, ROLLOUT_EPISODES, ROLLOUT_STEPS).map_err(other),
            )?;
            let in_spec = specs.iter().any(|s| s.net == spec.net);
            table.push(NormalizationRow {
                net: spec.net.model.name().to_string(),
                normalization: spec.net.normalization.name().to_string(),
                in_spec: i64::from(in_spec),
                rollout1_error: errors[0],
                rollout40_error_mean: errors.iter().sum::<f64>() / errors.len() as f64,
                rollout40_error_final: errors[errors.len() - 1],
                train_s: t.train_s,
                cached: i64::from(t.from_cache),
            });
        }
        Ok(table)
    }
}
