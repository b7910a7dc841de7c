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
//! output's target).

use crate::emulator::cache::{fnv1a, EmulatorCache};
use crate::emulator::catalog::{
    anchor_of, rollout_error, BuildSpec, NetModel, NetSpec, TrainSettings, Trained,
};
use crate::emulator::hierarchy::{
    build_dolphin, global_heldout_errors, hierarchy_rollout_error, BuiltDolphin, DolphinEmulator,
    HierarchyNet, HierarchySpec,
};
use crate::emulator::mlp::Mlp;
use crate::experiment::output::{df_f64, df_str, read_csv, unique, Table, Tables};
use crate::experiment::plot::{Figure, FigureSink, Mark, Panel, Series};
use crate::experiment::report::{sig, Findings, Verdict};
use crate::experiment::resolve::{ensure, positive, ParamError, Validate};
use crate::experiment::{other, Error, Family, Job, RunContext};
use crate::row;
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
}

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
        }
    }
}

/// The dolphin hierarchy of `spec`, from the cache or trained now.
pub fn build_dolphin_emulator(spec: &HierarchySpec) -> Result<BuiltDolphin, Error> {
    build_dolphin(spec, &EmulatorCache::from_env()).map_err(other)
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
                &format!("needs {} values", m.state_dim()),
            )?;
            ensure(
                t.control.is_empty() || t.control.len() == m.control_dim(),
                &format!("{key}.control"),
                &format!("needs {} values (or none)", m.control_dim()),
            )?;
        }
        validate_training(&self.training)
    }
}

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
fn dolphin_drift(
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

/// The build spec of `net` at `steps` physical steps per emulator step. The seed depends only on
/// the run seed, the model and n, so experiments that need the same network share it through
/// the cache.
pub fn build_spec(
    seed: u64,
    net: &NetSpec,
    steps: usize,
    example_scale: f64,
    settings: &TrainSettings,
) -> BuildSpec {
    let mut net = net.clone();
    net.examples = (net.examples as f64 * example_scale).round() as usize;
    let stream = fnv1a(format!("{}-n{steps}", net.model.name()).as_bytes());
    BuildSpec {
        net,
        steps,
        settings: *settings,
        seed: mix_seed(seed, stream),
    }
}

/// The emulator of `spec`, from the cache ([`EmulatorCache::from_env`]) or trained now.
pub fn build_emulator(spec: &BuildSpec) -> Result<Trained, Error> {
    EmulatorCache::from_env().get_or_train(spec).map_err(other)
}

/// The emulators of `specs`, in order, each as [`build_emulator`] builds it, the ones not in the
/// cache trained side by side (rayon): nets are independent and each is seeded by its spec, so
/// the nets, and everything made from them, are the same as built one by one. A cold run
/// otherwise trains its nets serially on one core.
pub fn build_emulators(specs: &[BuildSpec]) -> Result<Vec<Trained>, Error> {
    use rayon::prelude::*;
    specs.par_iter().map(build_emulator).collect()
}

/// A Table 1 emulator ready to step, catalog net or dolphin hierarchy (`motionlab emulate`).
pub enum Table1Emulator {
    /// A single net (pendulums, truck, lander).
    Net(NetModel, Box<crate::emulator::Emulator>),
    /// The hierarchical dolphin.
    Dolphin(Box<DolphinEmulator>),
}

/// Net names `motionlab emulate` accepts.
pub const EMULATOR_NAMES: [&str; 6] = [
    "pendulum_passive",
    "pendulum_active",
    "pendulum_ext",
    "truck",
    "lander",
    "dolphin",
];

impl Table1Emulator {
    /// The physical model it emulates, by its `describe` name.
    pub fn physics_name(&self) -> &'static str {
        match self {
            Self::Net(m, _) => m.physics_name(),
            Self::Dolphin(_) => "dolphin",
        }
    }

    /// The super timestep Δt (s).
    pub fn dt(&self) -> f64 {
        match self {
            Self::Net(_, e) => e.dt(),
            Self::Dolphin(d) => d.dt(),
        }
    }

    /// Emulates `steps` super-steps from `x0` with controls `control(k, t, u)` held over each;
    /// `observe(t, x)` sees the start and every step.
    pub fn rollout(
        &self,
        x0: &[f64],
        steps: usize,
        mut control: impl FnMut(f64, &mut [f64]),
        mut observe: impl FnMut(f64, &[f64]),
    ) -> Result<(), crate::physics::BlowUp> {
        let n = x0.len();
        let (mut x, mut next) = (x0.to_vec(), vec![0.0; n]);
        let name = self.physics_name();
        observe(0.0, &x);
        let dt = self.dt();
        let mut u = vec![0.0; crate::physics::model_by_name(name).map_or(0, |m| m.control_dim())];
        // One scratch per kind, made once.
        let mut net_scratch = match self {
            Self::Net(_, e) => Some(e.scratch()),
            Self::Dolphin(_) => None,
        };
        let mut dolphin_scratch = match self {
            Self::Dolphin(d) => Some(d.scratch()),
            Self::Net(..) => None,
        };
        for k in 0..steps {
            let t = k as f64 * dt;
            control(t, &mut u);
            match self {
                Self::Net(_, e) => {
                    e.predict(&x, &u, net_scratch.as_mut().expect("made"), &mut next)
                }
                Self::Dolphin(d) => {
                    d.predict(&x, &u, dolphin_scratch.as_mut().expect("made"), &mut next)
                }
            }
            std::mem::swap(&mut x, &mut next);
            let t1 = (k + 1) as f64 * dt;
            crate::physics::check_finite(name, k + 1, t1, &x)?;
            observe(t1, &x);
        }
        Ok(())
    }
}

/// The Table 1 emulator `name` (one of [`EMULATOR_NAMES`]) at `steps` physical steps per
/// emulator step, built exactly as `na_table1_structure` with these parameters and `seed` builds
/// it (size, data, training, seed), so it comes from the cache when any experiment trained it.
pub fn table1_emulator(
    params: &Params,
    seed: u64,
    name: &str,
    steps: usize,
) -> Result<Table1Emulator, Error> {
    if name == "dolphin" {
        let d = params
            .dolphin
            .as_ref()
            .ok_or_else(|| Error::Other("the Table 1 spec has no [params.dolphin]".into()))?;
        let built = build_dolphin_emulator(&d.spec(seed, steps, params.example_scale))?;
        return Ok(Table1Emulator::Dolphin(Box::new(built.emulator)));
    }
    let net = params
        .nets
        .iter()
        .find(|n| n.model.name() == name)
        .ok_or_else(|| {
            Error::Other(format!(
                "no net `{name}` in the Table 1 spec (nets: {})",
                EMULATOR_NAMES.join(", ")
            ))
        })?;
    let spec = build_spec(seed, net, steps, params.example_scale, &params.training);
    let t = build_emulator(&spec)?;
    Ok(Table1Emulator::Net(net.model, Box::new(t.emulator)))
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
        let mut structure = Table::new(&[
            "net",
            "inputs",
            "hidden",
            "outputs",
            "examples",
            "train_error",
            "heldout_error",
            "train_s",
            "weights",
            "examples_per_weight",
            "stop",
            "cached",
            "rollout40_error_mean",
            "rollout40_error_final",
            "anchored",
        ]);
        let mut training = Table::new(&["net", "iteration", "train_error", "heldout_error"]);
        let mut rollout = Table::new(&["net", "step", "error"]);
        // The k-step rollout fine-tuning (training.rollout_k): one-step loss + rollout_weight x
        // k-step rollout loss, on the training and held-out examples and windows.
        let mut rollout_training = Table::new(&["net", "iteration", "train_loss", "heldout_loss"]);
        let mut global_error = Table::new(&[
            "segment",
            "quantity",
            "component",
            "heldout_mse",
            "target_variance",
        ]);
        let mut drift = Table::new(&[
            "net",
            "task",
            "horizon_s",
            "emulator_drift",
            "simulator_drift",
            "gap",
            "tolerance",
            "at_anchor",
        ]);
        let dist = |a: &[f64], b: &[f64]| {
            a.iter()
                .zip(b)
                .map(|(x, y)| (x - y).powi(2))
                .sum::<f64>()
                .sqrt()
        };
        // at_anchor: the start and control encode to the net's anchor (NetSpec::anchor), so
        // the emulator's first step is exact by construction, not by fit.
        let mut push_drift =
            |t: &DriftTask, horizon_s: f64, [e, s, x0]: [Vec<f64>; 3], at_anchor: bool| {
                drift.push(row![
                    t.net.as_str(),
                    t.task.as_str(),
                    horizon_s,
                    dist(&e, &x0),
                    dist(&s, &x0),
                    dist(&e, &s),
                    t.tolerance,
                    i64::from(at_anchor)
                ]);
            };
        let pb = ctx.progress(self.nets.len() as u64, "training emulators");
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
        for ((net, spec), t) in self.nets.iter().zip(&specs).zip(built) {
            let name = net.model.name();
            let m = net.model;
            let (n_in, n_out) = (m.state_dim() + m.control_dim(), m.state_dim());
            let w = Mlp::weight_count(n_in, net.hidden, n_out);
            let errors = ctx.stage(&format!("rollouts {name}"), || {
                rollout_error(&t.emulator, &spec, ROLLOUT_EPISODES, ROLLOUT_STEPS).map_err(other)
            })?;
            for (k, e) in errors.iter().enumerate() {
                rollout.push(row![name, (k + 1) as i64, *e]);
            }
            for task in self.drift.iter().filter(|d| d.net == name) {
                let u = if task.control.is_empty() {
                    vec![0.0; m.control_dim()]
                } else {
                    task.control.clone()
                };
                let ends = catalog_drift(&t.emulator, &spec, &task.start, &u, ROLLOUT_STEPS)?;
                let tf = t.emulator.transforms();
                let at_anchor = anchor_of(spec, tf).is_some_and(|a| a.covers(tf, &task.start, &u));
                push_drift(
                    task,
                    ROLLOUT_STEPS as f64 * spec.super_dt(),
                    ends,
                    at_anchor,
                );
            }
            let mean = errors.iter().sum::<f64>() / errors.len() as f64;
            structure.push(row![
                name,
                n_in as i64,
                net.hidden as i64,
                n_out as i64,
                spec.net.examples as i64,
                t.train_error,
                t.heldout_error,
                t.train_s,
                w as i64,
                spec.net.examples as f64 / w as f64,
                t.stop.as_str(),
                i64::from(t.from_cache),
                mean,
                errors[errors.len() - 1],
                i64::from(net.anchor)
            ]);
            for p in &t.trace {
                training.push(row![
                    name,
                    p.iteration as i64,
                    p.train_error,
                    p.held_out_error
                ]);
            }
            for p in &t.rollout_trace {
                rollout_training.push(row![
                    name,
                    p.iteration as i64,
                    p.train_error,
                    p.held_out_error
                ]);
            }
            pb.inc(1);
        }
        if let Some(d) = &self.dolphin {
            let spec = d.spec(ctx.seed, self.steps, self.example_scale);
            let built = ctx.stage("train dolphin hierarchy", || build_dolphin_emulator(&spec))?;
            let (global_err, composed_err) = ctx.stage("rollouts dolphin", || {
                hierarchy_rollout_error(&built.emulator, &spec, ROLLOUT_EPISODES, ROLLOUT_STEPS)
                    .map_err(other)
            })?;
            for (name, errors) in [("dolphin_global", &global_err), ("dolphin", &composed_err)] {
                for (k, e) in errors.iter().enumerate() {
                    rollout.push(row![name, (k + 1) as i64, *e]);
                }
            }
            let per_output = ctx.stage("dolphin global error by output", || {
                global_heldout_errors(&built.emulator, &spec).map_err(other)
            })?;
            for (j, (e, v)) in per_output.iter().enumerate() {
                let (quantity, component) = GLOBAL_OUTPUTS[j % 13];
                global_error.push(row![(j / 13) as i64, quantity, component, *e, *v]);
            }
            for task in self.drift.iter().filter(|d| d.net == "dolphin") {
                let u = if task.control.is_empty() {
                    vec![0.0; 6]
                } else {
                    task.control.clone()
                };
                let ends = dolphin_drift(&built.emulator, &spec, &u, ROLLOUT_STEPS)?;
                push_drift(task, ROLLOUT_STEPS as f64 * spec.super_dt(), ends, false);
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
                structure.push(row![
                    n.name.as_str(),
                    n.inputs as i64,
                    n.hidden as i64,
                    n.outputs as i64,
                    n.examples as i64,
                    n.train_error,
                    n.heldout_error,
                    n.train_s,
                    w as i64,
                    n.examples as f64 / w as f64,
                    n.stop.as_str(),
                    i64::from(n.from_cache),
                    mean,
                    last,
                    0_i64
                ]);
                for p in &n.trace {
                    training.push(row![
                        n.name.as_str(),
                        p.iteration as i64,
                        p.train_error,
                        p.held_out_error
                    ]);
                }
                for p in &n.rollout_trace {
                    rollout_training.push(row![
                        n.name.as_str(),
                        p.iteration as i64,
                        p.train_error,
                        p.held_out_error
                    ]);
                }
            }
        }
        pb.finish_and_clear();
        Ok(Tables::from([
            ("structure", structure),
            ("training", training),
            ("rollout", rollout),
            ("drift", drift),
            ("rollout_training", rollout_training),
            ("global_error", global_error),
        ]))
    }
}

impl Family for NaStructure {
    const KIND: &'static str = "na_table1_structure";
    type Params = Params;

    fn figures(&self, fig: &FigureSink, tables: &Tables) -> Result<Vec<PathBuf>, Error> {
        let t = tables.require("training")?;
        let (net, it, tr, ho) = (
            t.strs("net"),
            t.f64s("iteration"),
            t.f64s("train_error"),
            t.f64s("heldout_error"),
        );
        let names = unique(&net);
        let panels = names
            .iter()
            .map(|name| {
                let pick = |v: &[f64]| -> Vec<(f64, f64)> {
                    (0..net.len())
                        .filter(|&r| &net[r] == name)
                        .map(|r| (it[r], v[r]))
                        .collect()
                };
                Panel {
                    title: name.clone(),
                    x_label: "iteration (CG) or epoch (momentum)".into(),
                    y_label: "MSE per output (normalized)".into(),
                    log_y: true,
                    series: vec![
                        Series::line("train", pick(&tr), 0),
                        Series::line("held-out", pick(&ho), 1).mark(Mark::Dashed),
                    ],
                    ..Panel::default()
                }
            })
            .collect();
        let mut files = fig.draw("training", &Figure::grid(panels, 3))?;
        let r = tables.require("rollout")?;
        let (net, step, err) = (r.strs("net"), r.f64s("step"), r.f64s("error"));
        let series = unique(&net)
            .iter()
            .enumerate()
            .map(|(c, name)| {
                let pts = (0..net.len())
                    .filter(|&k| &net[k] == name && err[k] > 0.0)
                    .map(|k| (step[k], err[k]))
                    .collect();
                Series::line(name, pts, c)
            })
            .collect();
        let panel = Panel {
            title: "emulator vs simulator over 40 super-steps (fresh episodes)".into(),
            x_label: "super-steps k".into(),
            y_label: "mean squared error / state variance".into(),
            log_y: true,
            series,
            ..Panel::default()
        };
        files.extend(fig.draw("rollout", &Figure::grid(vec![panel], 1))?);
        Ok(files)
    }

    fn report(&self, dir: &Path) -> Result<Findings, Error> {
        let df = read_csv(&dir.join("structure.csv"))?;
        let net = df_str(&df, "net")?;
        let (inp, hid, out, ex) = (
            df_f64(&df, "inputs")?,
            df_f64(&df, "hidden")?,
            df_f64(&df, "outputs")?,
            df_f64(&df, "examples")?,
        );
        let (tr, ho, secs) = (
            df_f64(&df, "train_error")?,
            df_f64(&df, "heldout_error")?,
            df_f64(&df, "train_s")?,
        );
        let (roll, roll_end) = (
            df_f64(&df, "rollout40_error_mean")?,
            df_f64(&df, "rollout40_error_final")?,
        );
        let mut md = String::from(
            "| net | inputs | hidden | outputs | examples | train MSE | held-out MSE | train s | 40-step rollout error, mean / final |\n| --- | --- | --- | --- | --- | --- | --- | --- | --- |\n",
        );
        let mut good = 0;
        let mut rolled = 0;
        let anchored = df_f64(&df, "anchored").unwrap_or_else(|_| vec![0.0; net.len()]);
        for r in 0..net.len() {
            let name = if anchored[r] > 0.5 {
                format!("{} (anchored)", net[r])
            } else {
                net[r].clone()
            };
            md.push_str(&format!(
                "| {} | {} | {} | {} | {} | {} | {} | {} | {} / {} |\n",
                name,
                inp[r],
                hid[r],
                out[r],
                ex[r],
                sig(tr[r]),
                sig(ho[r]),
                sig(secs[r]),
                sig(roll[r]),
                sig(roll_end[r])
            ));
            // Our rule (the paper gives no number): learned — held-out one-step MSE below 0.05
            // of the normalized state-change variance (1.0 is predicting the mean) — not
            // overfitted — held-out at most 0.02 above training, an absolute gap — and, where
            // measured, faithful over the 40 super-steps control uses: mean squared rollout
            // error below 0.1 of the state variance.
            let rollout_ok = roll[r].is_nan() || roll[r] < 0.1;
            rolled += usize::from(!roll[r].is_nan());
            if ho[r] < 0.05 && ho[r] - tr[r] <= 0.02 && rollout_ok {
                good += 1;
            }
        }
        let drift_path = dir.join("drift.csv");
        if drift_path.exists() {
            let df = read_csv(&drift_path)?;
            let (dn, task) = (df_str(&df, "net")?, df_str(&df, "task")?);
            let (hz, de, ds, gap, tol) = (
                df_f64(&df, "horizon_s")?,
                df_f64(&df, "emulator_drift")?,
                df_f64(&df, "simulator_drift")?,
                df_f64(&df, "gap")?,
                df_f64(&df, "tolerance")?,
            );
            let at_anchor = df_f64(&df, "at_anchor").unwrap_or_else(|_| vec![0.0; dn.len()]);
            md.push_str("\nNeutral-control drift from the Fig. 13 task starts and near them (`drift.csv`; position part, not part of the verdict). *At the anchor*: the start and control are the anchored net's equilibrium (ours, `anchor = true`), so the first step is exact by construction and the drift measures only whether the net is stable there; the rows off the anchor measure the fit near rest:\n\n| net | task | horizon s | emulator moved | simulator moved | end gap | tolerance (ours) | at the anchor |\n| --- | --- | --- | --- | --- | --- | --- | --- |\n");
            for r in 0..dn.len() {
                md.push_str(&format!(
                    "| {} | {} | {} | {} | {} | {} | {} | {} |\n",
                    dn[r],
                    task[r],
                    sig(hz[r]),
                    sig(de[r]),
                    sig(ds[r]),
                    sig(gap[r]),
                    sig(tol[r]),
                    if at_anchor[r] > 0.5 { "yes" } else { "no" }
                ));
            }
        }
        let ge_path = dir.join("global_error.csv");
        if ge_path.exists() {
            let df = read_csv(&ge_path)?;
            let (seg, mse, var) = (
                df_f64(&df, "segment")?,
                df_f64(&df, "heldout_mse")?,
                df_f64(&df, "target_variance")?,
            );
            let (mut by_seg, mut seg_var) = ([0.0; 6], [0.0; 6]);
            for ((s, e), v) in seg.iter().zip(&mse).zip(&var) {
                by_seg[(*s as usize).min(5)] += e / 13.0;
                seg_var[(*s as usize).min(5)] += v / 13.0;
            }
            let unexplained: Vec<String> = by_seg
                .iter()
                .zip(&seg_var)
                .enumerate()
                .map(|(s, (e, v))| format!("{s}: {}", sig(e / v.max(f64::MIN_POSITIVE))))
                .collect();
            let total: f64 = by_seg.iter().sum();
            let parts: Vec<String> = by_seg
                .iter()
                .enumerate()
                .map(|(s, e)| format!("{s}: {}", sig(*e)))
                .collect();
            md.push_str(&format!(
                "\nThe dolphin's global net, held-out one-step MSE by segment (0 nose … 5 fluke; mean over each segment's 13 outputs, in the units it trains in; `global_error.csv` has every output): {}. The fluke segment carries {:.0}% of the sum. Each segment's error over its outputs' own variance (the share left unexplained): {}.\n",
                parts.join(", "),
                100.0 * by_seg[5] / total.max(f64::MIN_POSITIVE),
                unexplained.join(", ")
            ));
        }
        let verdict = Verdict::from_counts(good, net.len());
        Ok(Findings {
            ours: md,
            verdict,
            why: format!(
                "{good} of {} Table 1 nets (the dolphin counts its global and six local nets) reach a held-out one-step MSE below 0.05 of the normalized state-change variance, held-out at most 0.02 above training, and (for the {rolled} nets whose rollouts are measured; the dolphin's local-net rows carry the composed hierarchy's) a mean 40-step rollout error below 0.1 of the state variance, at about 8-10 examples per weight. The thresholds are ours; the paper states none.",
                net.len()
            ),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::experiment::resolve::merge;

    /// The `[params]` table of an experiment file, with its `[quick]` table merged when asked.
    fn params(id: &str, quick: bool) -> toml::Value {
        let path = format!("{}/experiments/{id}.toml", env!("CARGO_MANIFEST_DIR"));
        let spec: toml::Table = toml::from_str(&std::fs::read_to_string(path).unwrap()).unwrap();
        let mut p = spec["params"].as_table().unwrap().clone();
        if quick {
            merge(&mut p, spec["quick"].as_table().unwrap());
        }
        toml::Value::Table(p)
    }

    #[test]
    fn control_experiments_use_table_1s_rollout_faithful_nets() {
        // Fig. 13 and Fig. 14 must learn through the very nets Table 1 trains and reports (the
        // same cache key: same model, size, data, settings, rollout fine-tuning), full and quick.
        for quick in [false, true] {
            let t1: Params = params("na_table1_structure", quick).try_into().unwrap();
            let key = |net: &NetSpec, steps: usize, scale: f64, s: &TrainSettings| {
                EmulatorCache::key(&build_spec(1, net, steps, scale, s))
            };
            let table1 = |model: NetModel| {
                let net = t1.nets.iter().find(|n| n.model == model).unwrap();
                key(net, t1.steps, t1.example_scale, &t1.training)
            };
            assert!(
                t1.training.rollout_k > 0,
                "Table 1 nets are rollout fine-tuned"
            );
            let f13: crate::families::na::fig13_control::Params =
                params("na_fig13_control", quick).try_into().unwrap();
            for task in &f13.tasks {
                assert_eq!(
                    key(&task.net, f13.steps, f13.example_scale, &f13.training),
                    table1(task.net.model),
                    "Fig. 13 {} (quick {quick})",
                    task.name
                );
            }
            let f14: crate::families::na::fig14_momentum::Params =
                params("na_fig14_momentum", quick).try_into().unwrap();
            assert_eq!(
                key(&f14.net, f14.steps, f14.example_scale, &f14.training),
                table1(f14.net.model),
                "Fig. 14 (quick {quick})"
            );
        }
    }

    #[test]
    fn fig14_learns_through_fig13s_lander_dagger_nets() {
        // Fig. 14's DAgger comparison must load the very nets Fig. 13's DAgger stage caches for
        // its lander task: the same base net and, for every round, the same derived key.
        use crate::families::na::fig13_control::dagger::derived_key;
        for quick in [false, true] {
            let f13: crate::families::na::fig13_control::Params =
                params("na_fig13_control", quick).try_into().unwrap();
            let f14: crate::families::na::fig14_momentum::Params =
                params("na_fig14_momentum", quick).try_into().unwrap();
            let d13 = f13.dagger.clone().expect("Fig. 13 runs DAgger");
            let t13 = f13.tasks.iter().find(|t| t.name == "lander").unwrap();
            let (g, d14) = f14.fig13(f14.dagger.as_ref().expect("Fig. 14 runs DAgger"));
            let t14 = &g.tasks[0];
            let base = |p: &crate::families::na::fig13_control::Params,
                        t: &crate::families::na::fig13_control::Task| {
                EmulatorCache::key(&build_spec(
                    1,
                    &t.net,
                    p.steps,
                    p.example_scale,
                    &p.training,
                ))
            };
            assert_eq!(base(&g, t14), base(&f13, t13), "base net (quick {quick})");
            assert_eq!(t14.name, t13.name);
            for round in 1..=d13.settings.rounds {
                assert_eq!(
                    derived_key(t14, &d14, g.curvature_iterations, round),
                    derived_key(t13, &d13, f13.curvature_iterations, round),
                    "round {round} (quick {quick})"
                );
            }
            assert_eq!(d14.settings.rounds, d13.settings.rounds);
        }
    }
}
