//! # Sampling and training the dolphin hierarchy (NeuroAnimator §3.4, §3.5, Table 1)
//!
//! Training data are episodes of 20 s ([`EPISODE_S`]) from the rest shape at a random position,
//! heading, pitch and roll ([`start_state`]), driven by travelling muscle waves
//! ([`control_process`]) and sampled at random lags; sampling runs in parallel chunks, each from
//! its own seeded stream ([`crate::seed::mix_seed`]), so the data do not depend on the thread
//! count ([`sample_dolphin`]). The global net learns the segment-frame transitions
//! ([`global_transitions`]); each local net learns, with teacher forcing (the true next frame
//! as its parent input), the change of its masses' local coordinates from frame F₀ to F₁, with
//! normalization by quantity groups. [`train_hierarchy`] trains the seven nets in parallel;
//! [`build_dolphin`] reuses them from the emulator cache under a key hashed from everything
//! that determines them ([`HierarchySpec`], the dolphin, [`super::HIERARCHY_FORMAT`]).
//!
//! ## References
//! - R. Grzeszczuk, D. Terzopoulos, G. Hinton, *NeuroAnimator*, SIGGRAPH 1998, §3.4–3.5,
//!   Table 1.
use super::{
    global_state, global_state_after, global_transforms, point, put, DolphinEmulator, Frame,
    LocalLayout, LocalNet, GLOBAL_DIM, HIERARCHY_FORMAT, MASS_DIM,
};
use crate::emulator::cache::{fnv1a, read_record, write_record, EmulatorCache, NetRecord};
use crate::emulator::catalog::{
    noisy, rollout_errors, rollout_phase, stop_name, train_mlp, BuildError, TrainMethod,
    TrainSettings, TrainingData,
};
use crate::emulator::dataset::{
    sample_transitions, sample_windows, ControlLimits, ControlProcess, ControlSignal,
    SamplingConfig, Windows,
};
use crate::emulator::mlp::{Mlp, WeightInit};
use crate::emulator::rollout::change_spread;
use crate::emulator::train::{mse, Dataset, TracePoint};
use crate::emulator::transform::Normalizer;
use crate::emulator::{Emulator, Transforms, Transitions};
use crate::physics::dolphin::{Dolphin, N_MASSES, N_POS, N_SEGMENTS};
use crate::physics::{Dynamics, IntegratorKind, Simulator};
use nalgebra::{UnitQuaternion, Vector3};
use ndarray::{s, Array2};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::f64::consts::PI;
use std::path::PathBuf;
use std::time::Instant;

/// Examples per sampling chunk (each chunk is simulated from its own seeded stream).
const CHUNK: usize = 2000;

/// Size and data of one net of the hierarchy.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct HierarchyNet {
    /// Hidden units.
    pub hidden: usize,
    /// Training examples.
    pub examples: usize,
    /// How to train.
    pub method: TrainMethod,
    /// Mini-batch epoch limit of this net, overriding the settings' `max_epochs` (left out of
    /// cache keys when not set).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_epochs: Option<usize>,
}

impl HierarchyNet {
    /// The training settings `s` with this net's own epoch limit, if it has one.
    pub fn settings(&self, s: &TrainSettings) -> TrainSettings {
        TrainSettings {
            max_epochs: self.max_epochs.unwrap_or(s.max_epochs),
            ..*s
        }
    }
}

/// Everything that determines the trained dolphin hierarchy.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct HierarchySpec {
    /// The global net (Table 1: 50 hidden, 64,000 examples).
    pub global: HierarchyNet,
    /// Each local net (Table 1: 40 hidden, 32,000 examples).
    pub local: HierarchyNet,
    /// Physical step δt of the simulator (s).
    pub physical_dt: f64,
    /// Physical steps per emulator step n.
    pub steps: usize,
    /// Training settings.
    pub settings: TrainSettings,
    /// Seed of sampling, initialization and shuffles.
    pub seed: u64,
}

impl HierarchySpec {
    /// Super timestep Δt = n δt (s).
    pub fn super_dt(&self) -> f64 {
        self.steps as f64 * self.physical_dt
    }

    fn held_out(&self) -> usize {
        ((self.global.examples as f64 * self.settings.held_out_fraction).round() as usize).max(2)
    }
}

/// Muscle activations: [−1, 1] each.
pub fn control_limits() -> ControlLimits {
    ControlLimits::symmetric(&[1.0; N_SEGMENTS])
}

/// The typical controls of §3.4 for the dolphin: travelling waves of 0.3–1.5 Hz, up to 60° of
/// lag per segment either way, held for 0.1–0.4 s, with 20% knot noise.
pub fn control_process() -> ControlProcess {
    ControlProcess::TravellingWave {
        hold_min: 0.1,
        hold_max: 0.4,
        freq_min: 0.3,
        freq_max: 1.5,
        lag_max: 60f64.to_radians(),
        noise: 0.2,
    }
}

/// Episode length of the sampling runs (s).
pub const EPISODE_S: f64 = 20.0;

/// An episode start: the rest shape at a random position (±20 m), heading, pitch (±0.5 rad)
/// and roll (±0.3 rad), moving along its axis at U[−0.5, 1] m/s.
pub fn start_state(d: &Dolphin, rng: &mut ChaCha8Rng) -> Vec<f64> {
    let yaw = rng.random_range(-PI..PI);
    let pitch = rng.random_range(-0.5..0.5);
    let roll = rng.random_range(-0.3..0.3);
    let r = UnitQuaternion::from_euler_angles(roll, pitch, yaw);
    let t = Vector3::new(
        rng.random_range(-20.0..20.0),
        rng.random_range(-20.0..20.0),
        rng.random_range(-20.0..20.0),
    );
    let speed = rng.random_range(-0.5..1.0);
    let v = r * Vector3::new(speed, 0.0, 0.0);
    let rest = d.rest_state();
    let mut x = vec![0.0; MASS_DIM];
    for i in 0..N_MASSES {
        put(&mut x[..N_POS], i, &(t + r * point(&rest, i)));
        put(&mut x[N_POS..], i, &v);
    }
    x
}

/// The dolphin's physical simulator: semi-implicit Euler.
pub fn simulator(d: &Dolphin) -> Simulator<Dolphin> {
    Simulator::new(d.clone(), IntegratorKind::SemiImplicitEuler)
}

/// The sampling runs of `examples` rows, `steps` physical steps of `dt` per super-step, in
/// episodes of [`EPISODE_S`] or of `min_super_steps` super-steps if longer, under the typical
/// muscle waves.
fn sampling(dt: f64, steps: usize, examples: usize, min_super_steps: usize) -> SamplingConfig {
    SamplingConfig {
        dt,
        steps_per_sample: steps,
        examples,
        episode_duration: EPISODE_S.max(min_super_steps as f64 * steps as f64 * dt),
        control: control_process(),
    }
}

/// `sample(simulator, rows, stream)` over chunks of at most `chunk` of `total` rows, in
/// parallel, chunk c drawing from stream c of `seed`: the parts do not depend on the thread
/// count.
fn in_chunks<T: Send, E: Send>(
    d: &Dolphin,
    total: usize,
    chunk: usize,
    seed: u64,
    sample: impl Fn(&mut Simulator<Dolphin>, usize, &mut ChaCha8Rng) -> Result<T, E> + Sync,
) -> Result<Vec<T>, E> {
    let sizes: Vec<usize> = (0..total.div_ceil(chunk))
        .map(|c| chunk.min(total - c * chunk))
        .collect();
    sizes
        .par_iter()
        .enumerate()
        .map(|(c, &n)| {
            let mut sim = simulator(d);
            let mut rng = ChaCha8Rng::seed_from_u64(crate::seed::mix_seed(seed, c as u64));
            sample(&mut sim, n, &mut rng)
        })
        .collect()
}

/// Samples `examples` transitions of the mass state over `steps` physical steps of `dt`, in
/// parallel chunks seeded from `seed` (independent of the thread count).
pub fn sample_dolphin(
    d: &Dolphin,
    dt: f64,
    steps: usize,
    examples: usize,
    seed: u64,
) -> Result<Transitions, BuildError> {
    let parts = in_chunks(d, examples, CHUNK, seed, |sim, n, rng| {
        let cfg = sampling(dt, steps, n, 6);
        let start = |r: &mut ChaCha8Rng| start_state(d, r);
        sample_transitions(sim, &start, &control_limits(), &cfg, rng).map(|s| s.transitions)
    })?;
    let cat = |f: fn(&Transitions) -> &Array2<f64>| -> Array2<f64> {
        let views: Vec<_> = parts.iter().map(|p| f(p).view()).collect();
        ndarray::concatenate(ndarray::Axis(0), &views).expect("equal widths")
    };
    Ok(Transitions::new(
        cat(|t| &t.states),
        cat(|t| &t.controls),
        cat(|t| &t.next_states),
    )?)
}

/// Windows per sampling chunk of [`sample_dolphin_windows`].
const WINDOW_CHUNK: usize = 250;

/// Samples `count` windows of `k` super-steps of the mass state (`steps` physical steps of `dt`
/// each) from the same episodes, starts and controls as [`sample_dolphin`], in parallel chunks
/// seeded from `seed` (independent of the thread count); episode indices are unique across
/// chunks.
pub fn sample_dolphin_windows(
    d: &Dolphin,
    dt: f64,
    steps: usize,
    count: usize,
    k: usize,
    seed: u64,
) -> Result<Windows, BuildError> {
    let parts = in_chunks(d, count, WINDOW_CHUNK, seed, |sim, n, rng| {
        let cfg = sampling(dt, steps, n, k + 6);
        let start = |r: &mut ChaCha8Rng| start_state(d, r);
        sample_windows(sim, &start, &control_limits(), &cfg, k, rng)
    })?;
    let mut out = Windows {
        k,
        state_dim: MASS_DIM,
        control_dim: N_SEGMENTS,
        states: Vec::new(),
        controls: Vec::new(),
        episode: Vec::new(),
        start_step: Vec::new(),
    };
    // Each chunk counts its episodes from 0: offset them so that indices stay unique.
    let mut next = 0;
    for p in &parts {
        let from = out.len();
        out.extend(p);
        out.episode[from..].iter_mut().for_each(|e| *e += next);
        next += p.episode.iter().max().map_or(0, |m| m + 1);
    }
    Ok(out)
}

/// The global net's k-step rollout windows of `spec` (k = `rollout_k` ≥ 1), training and
/// held-out, as global-state chains ([`super::dagger::global_windows`]): examples / k windows
/// (streams 40 and 41 of its seed), the held-out share as for the one-step data.
pub fn global_rollout_windows(
    d: &Dolphin,
    spec: &HierarchySpec,
) -> Result<(Windows, Windows), BuildError> {
    let k = spec.settings.rollout_k.max(1);
    let count = spec.global.examples.div_ceil(k).max(2);
    let held_count = ((count as f64 * spec.settings.held_out_fraction).round() as usize).max(2);
    let windows = |n: usize, stream: u64| -> Result<Windows, BuildError> {
        let seed = crate::seed::mix_seed(spec.seed, stream);
        let w = sample_dolphin_windows(d, spec.physical_dt, spec.steps, n, k, seed)?;
        Ok(super::dagger::global_windows(d, &w))
    };
    Ok((windows(count, 40)?, windows(held_count, 41)?))
}

/// The global-state transitions of mass-state transitions: the start state as
/// [`global_state`] writes it, the next state with each quaternion signed to agree with the
/// start's ([`global_state_after`]), so no target jumps between q and −q.
pub fn global_transitions(d: &Dolphin, data: &Transitions) -> Transitions {
    let rows = data.len();
    let mut g0 = Array2::zeros((rows, GLOBAL_DIM));
    let mut g1 = Array2::zeros((rows, GLOBAL_DIM));
    let (mut buf, mut next) = (vec![0.0; GLOBAL_DIM], vec![0.0; GLOBAL_DIM]);
    for r in 0..rows {
        global_state(
            d,
            data.states.row(r).as_slice().expect("standard layout"),
            &mut buf,
        );
        g0.row_mut(r).assign(&ndarray::ArrayView1::from(&buf));
        global_state_after(
            d,
            data.next_states.row(r).as_slice().expect("standard layout"),
            &buf,
            &mut next,
        );
        g1.row_mut(r).assign(&ndarray::ArrayView1::from(&next));
    }
    Transitions::new(g0, data.controls.clone(), g1).expect("rows agree")
}

/// Raw (input, target) rows of segment `layout` for the first `rows` transitions, with the
/// true next frame as the parent input.
fn local_raw(
    d: &Dolphin,
    layout: &LocalLayout,
    data: &Transitions,
    rows: usize,
) -> (Array2<f64>, Array2<f64>) {
    let rows = rows.min(data.len());
    let mut inp = Array2::zeros((rows, layout.n_in()));
    let mut out = Array2::zeros((rows, layout.n_out()));
    let (mut z, mut y) = (vec![0.0; layout.n_in()], vec![0.0; layout.n_out()]);
    for r in 0..rows {
        let x0 = data.states.row(r);
        let x1 = data.next_states.row(r);
        let (x0, x1) = (
            x0.as_slice().expect("layout"),
            x1.as_slice().expect("layout"),
        );
        let f0 = Frame::from_segment(&d.segment_frame(x0, layout.segment));
        let f1 = Frame::from_segment(&d.segment_frame(x1, layout.segment));
        let u = data.controls.row(r);
        layout.input(x0, &f0, &f1, u.as_slice().expect("layout"), &mut z);
        layout.target(x0, &f0, x1, &f1, &mut y);
        inp.row_mut(r).assign(&ndarray::ArrayView1::from(&z));
        out.row_mut(r).assign(&ndarray::ArrayView1::from(&y));
    }
    (inp, out)
}

fn normalized(norm: &Normalizer, raw: &Array2<f64>) -> Array2<f64> {
    let mut out = raw.clone();
    let mut buf = vec![0.0; raw.ncols()];
    for (mut o, r) in out.rows_mut().into_iter().zip(raw.rows()) {
        norm.normalize(r.as_slice().expect("layout"), &mut buf);
        o.assign(&ndarray::ArrayView1::from(&buf));
    }
    out
}

/// Training record of one net of the hierarchy (a Table 1 row).
#[derive(Debug, Clone, PartialEq)]
pub struct NetReport {
    /// `dolphin_global` or `dolphin_local1` … `dolphin_local6`.
    pub name: String,
    /// Network inputs.
    pub inputs: usize,
    /// Hidden units.
    pub hidden: usize,
    /// Network outputs.
    pub outputs: usize,
    /// Training examples.
    pub examples: usize,
    /// Training MSE per output (normalized space).
    pub train_error: f64,
    /// Held-out MSE per output (normalized space).
    pub heldout_error: f64,
    /// Wall time of its training (the shared sampling time is added to the global net) (s).
    pub train_s: f64,
    /// Why training stopped.
    pub stop: String,
    /// Whether it came from the cache.
    pub from_cache: bool,
    /// Training trace.
    pub trace: Vec<TracePoint>,
    /// Trace of the k-step rollout fine-tuning (the global net's, when its settings ask for
    /// one; empty otherwise).
    pub rollout_trace: Vec<TracePoint>,
}

/// The trained hierarchy with a record per net.
#[derive(Debug, Clone)]
pub struct BuiltDolphin {
    /// The composed emulator.
    pub emulator: DolphinEmulator,
    /// Global net first, then the six local nets.
    pub nets: Vec<NetReport>,
}

/// Name of net `k` of the hierarchy (0 = global, 1..=6 local).
pub fn net_name(k: usize) -> String {
    if k == 0 {
        "dolphin_global".into()
    } else {
        format!("dolphin_local{k}")
    }
}

pub(super) fn cache_key(spec: &HierarchySpec, d: &Dolphin, k: usize) -> String {
    let mut rng = ChaCha8Rng::seed_from_u64(0);
    let starts: Vec<Vec<f64>> = (0..2).map(|_| start_state(d, &mut rng)).collect();
    serde_json::json!({
        "format": crate::emulator::cache::CACHE_FORMAT,
        "hierarchy_format": HIERARCHY_FORMAT,
        "hierarchy": spec,
        "net": net_name(k),
        "physics": d,
        "recipe": {
            "process": control_process(),
            "episode": EPISODE_S,
            "chunk": CHUNK,
            "transforms": format!("{:?}", global_transforms()),
            "starts": starts,
        },
    })
    .to_string()
}

fn cache_path(cache: &EmulatorCache, spec: &HierarchySpec, key: &str, k: usize) -> PathBuf {
    cache.dir.join(format!(
        "{}-n{}-{:016x}.json",
        net_name(k),
        spec.steps,
        fnv1a(key.as_bytes())
    ))
}

pub(super) fn shape(spec: &HierarchySpec, k: usize) -> [usize; 3] {
    if k == 0 {
        [GLOBAL_DIM + N_SEGMENTS, spec.global.hidden, GLOBAL_DIM]
    } else {
        let l = LocalLayout::new(k - 1);
        [l.n_in(), spec.local.hidden, l.n_out()]
    }
}

/// The global net of a stored record as an [`Emulator`].
pub(super) fn global_emulator(spec: &HierarchySpec, g: NetRecord) -> Result<Emulator, BuildError> {
    let mut t = Transforms::unfitted(&global_transforms(), GLOBAL_DIM, N_SEGMENTS)?;
    t.input_norm = g.input_norm;
    t.output_norm = g.output_norm;
    Ok(Emulator::new(t, g.mlp, spec.super_dt())?)
}

fn assemble(
    d: &Dolphin,
    spec: &HierarchySpec,
    recs: Vec<NetRecord>,
) -> Result<DolphinEmulator, BuildError> {
    let mut it = recs.into_iter();
    let global = global_emulator(spec, it.next().expect("seven records"))?;
    let locals = it
        .enumerate()
        .map(|(s, r)| LocalNet {
            layout: LocalLayout::new(s),
            mlp: r.mlp,
            input_norm: r.input_norm,
            output_norm: r.output_norm,
        })
        .collect();
    Ok(DolphinEmulator::new(d.clone(), global, locals))
}

fn report(k: usize, spec: &HierarchySpec, r: &NetRecord, from_cache: bool) -> NetReport {
    let [inputs, hidden, outputs] = shape(spec, k);
    NetReport {
        name: net_name(k),
        inputs,
        hidden,
        outputs,
        examples: if k == 0 {
            spec.global.examples
        } else {
            spec.local.examples.min(spec.global.examples)
        },
        train_error: r.train_error,
        heldout_error: r.heldout_error,
        train_s: r.train_s,
        stop: r.stop.clone(),
        from_cache,
        trace: r.trace.clone(),
        rollout_trace: r.rollout_trace.clone(),
    }
}

/// The trained hierarchy of `spec` for the default dolphin, from `cache` when all seven nets
/// are there, else sampled and trained now (and stored).
pub fn build_dolphin(
    spec: &HierarchySpec,
    cache: &EmulatorCache,
) -> Result<BuiltDolphin, BuildError> {
    let d = Dolphin::default();
    let keys: Vec<String> = (0..=N_SEGMENTS).map(|k| cache_key(spec, &d, k)).collect();
    let cached: Option<Vec<NetRecord>> = (0..=N_SEGMENTS)
        .map(|k| {
            read_record(
                &cache_path(cache, spec, &keys[k], k),
                &keys[k],
                shape(spec, k),
            )
        })
        .collect();
    if let Some(recs) = cached {
        let nets = recs
            .iter()
            .enumerate()
            .map(|(k, r)| report(k, spec, r, true))
            .collect();
        return Ok(BuiltDolphin {
            emulator: assemble(&d, spec, recs)?,
            nets,
        });
    }
    let recs = train_hierarchy(&d, spec)?;
    for (k, r) in recs.iter().enumerate() {
        write_record(&cache_path(cache, spec, &keys[k], k), &keys[k], r)?;
    }
    let nets = recs
        .iter()
        .enumerate()
        .map(|(k, r)| report(k, spec, r, false))
        .collect();
    Ok(BuiltDolphin {
        emulator: assemble(&d, spec, recs)?,
        nets,
    })
}

/// The global net's one-step data from the sampled mass transitions `train` and `held`: their
/// global transitions, the transforms fitted on the training ones, both encoded, the training
/// set with the settings' input noise (stream 30 of the spec's seed), and the rollout-loss
/// scales ([`change_spread`]). What [`train_hierarchy`] trains the global net on, and what
/// DAgger ([`super::dagger`]) aggregates onto.
fn global_data(
    d: &Dolphin,
    spec: &HierarchySpec,
    train: &Transitions,
    held: &Transitions,
) -> Result<TrainingData, BuildError> {
    let (gt, gh) = (global_transitions(d, train), global_transitions(d, held));
    let transforms = Transforms::fit(&global_transforms(), &gt)?;
    let (clean_ds, held_ds) = (transforms.encode(&gt), transforms.encode(&gh));
    let train_ds = noisy(
        &transforms,
        &clean_ds,
        &spec.settings,
        &mut ChaCha8Rng::seed_from_u64(crate::seed::mix_seed(spec.seed, 30)),
    );
    let sigma = change_spread(&gt);
    Ok(TrainingData {
        train: gt,
        held: gh,
        transforms,
        train_ds,
        clean_ds,
        held_ds,
        sigma,
    })
}

/// The global net's training data of `spec`, sampled again from the spec's streams (the same
/// examples [`train_hierarchy`] trained on).
pub fn global_training_data(d: &Dolphin, spec: &HierarchySpec) -> Result<TrainingData, BuildError> {
    let (train, held) = sample_spec(d, spec)?;
    global_data(d, spec, &train, &held)
}

/// The mass-state training and held-out transitions of `spec` (streams 1 and 2 of its seed).
fn sample_spec(
    d: &Dolphin,
    spec: &HierarchySpec,
) -> Result<(Transitions, Transitions), BuildError> {
    let mix = |k: u64| crate::seed::mix_seed(spec.seed, k);
    let train = sample_dolphin(
        d,
        spec.physical_dt,
        spec.steps,
        spec.global.examples,
        mix(1),
    )?;
    let held = sample_dolphin(d, spec.physical_dt, spec.steps, spec.held_out(), mix(2))?;
    Ok((train, held))
}

/// Samples the data and trains the global net and the six local nets (in parallel).
pub fn train_hierarchy(d: &Dolphin, spec: &HierarchySpec) -> Result<Vec<NetRecord>, BuildError> {
    let t0 = Instant::now();
    let mix = |k: u64| crate::seed::mix_seed(spec.seed, k);
    let (train, held) = sample_spec(d, spec)?;
    let sampling_s = t0.elapsed().as_secs_f64();
    let s = &spec.settings;
    let jobs: Vec<usize> = (0..=N_SEGMENTS).collect();
    let recs: Vec<NetRecord> = jobs
        .par_iter()
        .map(|&k| -> Result<NetRecord, BuildError> {
            let t1 = Instant::now();
            let mut rng = ChaCha8Rng::seed_from_u64(mix(10 + k as u64));
            if k == 0 {
                let data = global_data(d, spec, &train, &held)?;
                let mut mlp = Mlp::new(
                    GLOBAL_DIM + N_SEGMENTS,
                    spec.global.hidden,
                    GLOBAL_DIM,
                    WeightInit::FanIn,
                    &mut rng,
                );
                let rep = train_mlp(
                    &mut mlp,
                    &data.train_ds,
                    &data.held_ds,
                    spec.global.method,
                    &spec.global.settings(s),
                    mix(20),
                    None,
                )?;
                let mut emulator = Emulator::new(data.transforms.clone(), mlp, spec.super_dt())?;
                let mut stop = stop_name(&rep.stop);
                let rollout_trace = if s.rollout_k > 0 {
                    let windows = global_rollout_windows(d, spec)?;
                    rollout_phase(&mut emulator, &data, &windows, s, None, &mut stop)?
                } else {
                    Vec::new()
                };
                let mlp = emulator.mlp().clone();
                Ok(NetRecord {
                    train_error: mse(&mlp, &data.clean_ds),
                    heldout_error: mse(&mlp, &data.held_ds),
                    mlp,
                    input_norm: data.transforms.input_norm,
                    output_norm: data.transforms.output_norm,
                    dt: spec.super_dt(),
                    train_s: sampling_s + t1.elapsed().as_secs_f64(),
                    stop,
                    trace: rep.trace,
                    rollout_trace,
                })
            } else {
                train_local(d, spec, LocalLayout::new(k - 1), &train, &held, rng, t1)
            }
        })
        .collect::<Result<_, _>>()?;
    Ok(recs)
}

/// Noise injection for a local net (as [`Transforms::perturb`] for the global net, issue 11
/// defect 5): each local coordinate of each seen mass (positions and velocities in frame F₀,
/// raw inputs `inp`) moves by δ ~ N(0, (`scale` · sd)²), sd that column's spread, and the target
/// of each owned mass becomes the change from the perturbed local state to the true next one
/// (Δl − δ), so that the net learns to pull its own deformation errors back. The frame inputs
/// and controls are not perturbed.
fn local_perturbed(
    layout: &LocalLayout,
    inp: &Array2<f64>,
    out: &Array2<f64>,
    scale: f64,
    rng: &mut ChaCha8Rng,
) -> (Array2<f64>, Array2<f64>) {
    let seen = 6 * layout.frame_masses.len();
    let sd: Vec<f64> = (0..seen).map(|c| inp.column(c).std(0.0)).collect();
    // Input column of each target column (owned masses are frame masses).
    let source: Vec<usize> = layout
        .owned
        .iter()
        .flat_map(|i| {
            let f = layout
                .frame_masses
                .iter()
                .position(|m| m == i)
                .expect("owned masses are frame masses");
            (0..6).map(move |c| 6 * f + c)
        })
        .collect();
    let (mut inp, mut out) = (inp.clone(), out.clone());
    let mut delta = vec![0.0; seen];
    for (mut z, mut y) in inp.rows_mut().into_iter().zip(out.rows_mut()) {
        for (c, d) in delta.iter_mut().enumerate() {
            *d = scale * sd[c] * rng.sample::<f64, _>(rand_distr::StandardNormal);
            z[c] += *d;
        }
        for (t, &c) in source.iter().enumerate() {
            y[t] -= delta[c];
        }
    }
    (inp, out)
}

/// Trains the local net of `layout` (net k = segment + 1) on the first `spec.local.examples`
/// of `train` (teacher forcing), held out on `held`, from the weights `rng` draws.
fn train_local(
    d: &Dolphin,
    spec: &HierarchySpec,
    layout: LocalLayout,
    train: &Transitions,
    held: &Transitions,
    mut rng: ChaCha8Rng,
    t1: Instant,
) -> Result<NetRecord, BuildError> {
    let s = &spec.local.settings(&spec.settings);
    let k = layout.segment + 1;
    let rows = spec.local.examples;
    let held_rows = ((rows as f64 * s.held_out_fraction).round() as usize).max(2);
    let (ti, tt) = local_raw(d, &layout, train, rows);
    let (hi, ht) = local_raw(d, &layout, held, held_rows);
    let in_norm = Normalizer::fit(ti.view(), &layout.input_groups())?;
    let out_norm = Normalizer::fit(tt.view(), &layout.output_groups())?;
    let tr = Dataset::new(normalized(&in_norm, &ti), normalized(&out_norm, &tt))?;
    let ho = Dataset::new(normalized(&in_norm, &hi), normalized(&out_norm, &ht))?;
    let noisy = if s.input_noise > 0.0 {
        let mut rng = ChaCha8Rng::seed_from_u64(crate::seed::mix_seed(spec.seed, 50 + k as u64));
        let (ni, nt) = local_perturbed(&layout, &ti, &tt, s.input_noise, &mut rng);
        Some(Dataset::new(
            normalized(&in_norm, &ni),
            normalized(&out_norm, &nt),
        )?)
    } else {
        None
    };
    let train_ds = noisy.as_ref().unwrap_or(&tr);
    let mut mlp = Mlp::new(
        layout.n_in(),
        spec.local.hidden,
        layout.n_out(),
        WeightInit::FanIn,
        &mut rng,
    );
    let rep = train_mlp(
        &mut mlp,
        train_ds,
        &ho,
        spec.local.method,
        s,
        crate::seed::mix_seed(spec.seed, 20 + k as u64),
        None,
    )?;
    Ok(NetRecord {
        train_error: mse(&mlp, &tr),
        heldout_error: mse(&mlp, &ho),
        mlp,
        input_norm: in_norm,
        output_norm: out_norm,
        dt: spec.super_dt(),
        train_s: t1.elapsed().as_secs_f64(),
        stop: stop_name(&rep.stop),
        trace: rep.trace,
        rollout_trace: Vec::new(),
    })
}

/// Multi-step fidelity of the trained hierarchy (as [`crate::emulator::catalog::rollout_error`]
/// for the catalog nets): from `episodes` start states drawn as for training (a stream of its
/// own), the simulator, the global net alone (fed its own outputs) and the composed hierarchy
/// run `horizon` super-steps side by side under the training control process, read at each
/// super-step's start and held over it. Returns per step k the mean squared error over
/// episodes and variables, each variable divided by its spread over the simulated states: of
/// the global state (global net) and of the 138-variable mass state (composed hierarchy,
/// carrying its global state, [`DolphinEmulator::predict_carried`]).
/// Simulated global states keep their quaternion signs continuous from the start
/// ([`global_state_after`]), as the emulated ones are.
pub fn hierarchy_rollout_error(
    emulator: &DolphinEmulator,
    spec: &HierarchySpec,
    episodes: usize,
    horizon: usize,
) -> Result<(Vec<f64>, Vec<f64>), BuildError> {
    let d = emulator.dolphin();
    let mut rng = ChaCha8Rng::seed_from_u64(crate::seed::mix_seed(spec.seed, 3));
    let big_dt = spec.super_dt();
    let mut sim = simulator(d);
    let mut hsc = emulator.scratch();
    let mut u = vec![0.0; N_SEGMENTS];
    let (mut gt, mut ge, mut mt, mut me) = (vec![], vec![], vec![], vec![]);
    let (mut g_sim, mut g_emu) = (vec![0.0; GLOBAL_DIM], vec![0.0; GLOBAL_DIM]);
    let (mut g_next, mut x_next) = (vec![0.0; GLOBAL_DIM], vec![0.0; MASS_DIM]);
    for _ in 0..episodes {
        let x0 = start_state(d, &mut rng);
        let signal = ControlSignal::sample(
            control_process(),
            &control_limits(),
            horizon as f64 * big_dt,
            &mut rng,
        );
        let (mut xs, mut xe) = (x0.clone(), x0);
        global_state(d, &xs, &mut g_sim);
        g_emu.copy_from_slice(&g_sim);
        for k in 0..horizon {
            signal.at(k as f64 * big_dt, &mut u);
            for i in 0..spec.steps {
                sim.step(&mut xs, &u, spec.physical_dt);
                let step = k * spec.steps + i + 1;
                crate::physics::check_finite("dolphin", step, step as f64 * spec.physical_dt, &xs)?;
            }
            global_state_after(d, &xs, &g_sim, &mut g_next);
            g_sim.copy_from_slice(&g_next);
            // The composed step carries the global net's own rollout (its frames are exactly
            // the global net's alone), so one global prediction serves both.
            emulator.predict_carried(&xe, &g_emu, &u, &mut hsc, &mut x_next, &mut g_next);
            g_emu.copy_from_slice(&g_next);
            xe.copy_from_slice(&x_next);
            gt.extend_from_slice(&g_sim);
            ge.extend_from_slice(&g_emu);
            mt.extend_from_slice(&xs);
            me.extend_from_slice(&xe);
        }
    }
    Ok((
        rollout_errors(&gt, &ge, episodes, horizon, GLOBAL_DIM),
        rollout_errors(&mt, &me, episodes, horizon, MASS_DIM),
    ))
}

/// The global net's held-out one-step error per output (the 78 numbers of
/// [`global_state`]: segment s's centroid, quaternion, velocity and angular velocity at
/// 13 s … 13 s + 12), in the units it trains in (reference-segment frame, normalized by quantity
/// groups): per output, the mean squared error over the spec's held-out transitions (stream 2,
/// sampled again) and the variance of its target there (the error of predicting the mean).
/// The errors' mean is the global net's held-out MSE of Table 1.
pub fn global_heldout_errors(
    emulator: &DolphinEmulator,
    spec: &HierarchySpec,
) -> Result<Vec<(f64, f64)>, BuildError> {
    let d = emulator.dolphin();
    let held = sample_dolphin(
        d,
        spec.physical_dt,
        spec.steps,
        spec.held_out(),
        crate::seed::mix_seed(spec.seed, 2),
    )?;
    let global = emulator.global();
    let ds = global.transforms().encode(&global_transitions(d, &held));
    let mlp = global.mlp();
    let (mut sc, mut y) = (mlp.scratch(), vec![0.0; mlp.n_out()]);
    let mut sum = vec![0.0; mlp.n_out()];
    for (z, t) in ds.inputs.rows().into_iter().zip(ds.targets.rows()) {
        mlp.forward(z.as_slice().expect("layout"), &mut sc, &mut y);
        for ((a, p), q) in sum.iter_mut().zip(&y).zip(t) {
            *a += (p - q).powi(2);
        }
    }
    let n = ds.len().max(1) as f64;
    Ok(sum
        .into_iter()
        .zip(ds.targets.columns())
        .map(|(a, t)| (a / n, t.var(0.0)))
        .collect())
}

/// The `rows`-row slice of a transitions table (for tests and small experiments).
pub fn head(data: &Transitions, rows: usize) -> Transitions {
    let r = rows.min(data.len());
    Transitions::new(
        data.states.slice(s![..r, ..]).to_owned(),
        data.controls.slice(s![..r, ..]).to_owned(),
        data.next_states.slice(s![..r, ..]).to_owned(),
    )
    .expect("rows agree")
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::emulator::hierarchy::{FRAME_DIM, REF_SEGMENT};

    fn spec(examples: usize) -> HierarchySpec {
        HierarchySpec {
            global: HierarchyNet {
                hidden: 8,
                examples,
                method: TrainMethod::Lbfgs,
                max_epochs: None,
            },
            local: HierarchyNet {
                hidden: 6,
                examples: examples / 2,
                method: TrainMethod::Lbfgs,
                max_epochs: None,
            },
            physical_dt: 0.002,
            steps: 10,
            settings: TrainSettings {
                held_out_fraction: 0.25,
                cg_max_iters: 5,
                max_epochs: 2,
                patience: 3,
                min_improvement: 0.001,
                learning_rate: 0.05,
                momentum: 0.9,
                batch_size: 30,
                input_noise: 0.0,
                rollout_k: 0,
                rollout_weight: 0.0,
                rollout_iters: 0,
            },
            seed: 3,
        }
    }

    /// Noise injection for the local nets: every seen mass's local coordinates move by about
    /// the requested fraction of their spread, each owned mass's target moves back by exactly
    /// its input's move (the change to the true next state), and neither the frame inputs, the
    /// controls nor the targets of masses a net does not own change.
    #[test]
    fn local_noise_targets_the_true_next_state() {
        let d = Dolphin::default();
        let data = sample_dolphin(&d, 0.002, 10, 400, 9).unwrap();
        for segment in [0, 3, 5] {
            let layout = LocalLayout::new(segment);
            let (inp, out) = local_raw(&d, &layout, &data, 400);
            let mut rng = ChaCha8Rng::seed_from_u64(4);
            let (ni, nt) = local_perturbed(&layout, &inp, &out, 0.05, &mut rng);
            let seen = 6 * layout.frame_masses.len();
            for c in 0..inp.ncols() {
                let moved = &ni.column(c) - &inp.column(c);
                if c < seen {
                    let ratio = moved.std(0.0) / inp.column(c).std(0.0);
                    assert!((ratio - 0.05).abs() < 0.01, "column {c}: {ratio}");
                } else {
                    assert!(moved.iter().all(|&v| v == 0.0), "column {c} moved");
                }
            }
            for (j, &i) in layout.owned.iter().enumerate() {
                let f = layout.frame_masses.iter().position(|&m| m == i).unwrap();
                for c in 0..6 {
                    let input_move = &ni.column(6 * f + c) - &inp.column(6 * f + c);
                    let target_move = &nt.column(6 * j + c) - &out.column(6 * j + c);
                    for (a, b) in input_move.iter().zip(&target_move) {
                        assert!((a + b).abs() <= 1e-12, "mass {i}: {a} vs {b}");
                    }
                }
            }
            let (same_i, same_t) = local_perturbed(&layout, &inp, &out, 0.0, &mut rng);
            assert_eq!((same_i, same_t), (inp, out), "no noise, no change");
        }
    }

    /// Issue 11, defect 2: the global net's training data have no quaternion sign jumps.
    /// Episodes start at uniform headings, so segments pass through half-turn rotations where
    /// a w ≥ 0 convention flips q to −q; with signs chosen against the reference segment (inputs)
    /// and the previous step (targets), every relative quaternion the net sees has w > 0 and
    /// every quaternion change it is trained on is small.
    #[test]
    fn global_training_data_have_no_quaternion_sign_jumps() {
        let d = Dolphin::default();
        // The §3.4 sampler, plus episodes that start (as it does, tilted) heading within 0.02 rad
        // of the half turn
        // (uniform headings reach it in only a few dozen of 64,000 examples).
        let mut data = sample_dolphin(&d, 0.002, 50, 200, 7).unwrap();
        let half_turn = |r: &mut ChaCha8Rng| -> Vec<f64> {
            let (roll, pitch) = (r.random_range(-0.3..0.3), r.random_range(-0.5..0.5));
            let yaw = PI + r.random_range(-0.02..0.02);
            let rot = UnitQuaternion::from_euler_angles(roll, pitch, yaw);
            let (rest, mut x) = (d.rest_state(), vec![0.0; MASS_DIM]);
            for i in 0..N_MASSES {
                put(&mut x[..N_POS], i, &(rot * point(&rest, i)));
                put(&mut x[N_POS..], i, &(rot * Vector3::new(0.5, 0.0, 0.0)));
            }
            x
        };
        let cfg = SamplingConfig {
            dt: 0.002,
            steps_per_sample: 50,
            examples: 100,
            episode_duration: 4.0,
            control: control_process(),
        };
        let extra = sample_transitions(
            &mut simulator(&d),
            &half_turn,
            &control_limits(),
            &cfg,
            &mut ChaCha8Rng::seed_from_u64(8),
        )
        .unwrap()
        .transitions;
        let cat = |a: &Array2<f64>, b: &Array2<f64>| {
            ndarray::concatenate(ndarray::Axis(0), &[a.view(), b.view()]).unwrap()
        };
        data = Transitions::new(
            cat(&data.states, &extra.states),
            cat(&data.controls, &extra.controls),
            cat(&data.next_states, &extra.next_states),
        )
        .unwrap();
        let g = global_transitions(&d, &data);
        let tf = Transforms::unfitted(&global_transforms(), GLOBAL_DIM, N_SEGMENTS).unwrap();
        let raw = tf.encode(&g);
        // A sign jump changes a unit quaternion by about |q − (−q)| = 2; a change of norm 1
        // would be a turn of 2.1 rad in one super-step (0.1 s), far beyond any segment's swing
        // (the fluke's fastest are about 0.75 rad).
        let quat = |row: ndarray::ArrayView1<f64>, s: usize| -> [f64; 4] {
            let q = FRAME_DIM * s + 3;
            [row[q], row[q + 1], row[q + 2], row[q + 3]]
        };
        let mut worst: f64 = 0.0;
        for r in 0..g.len() {
            for s in 0..N_SEGMENTS {
                let w = quat(raw.inputs.row(r), s)[0];
                assert!(
                    w > 0.5,
                    "example {r} segment {s}: relative quaternion w = {w}"
                );
                let dq = quat(raw.targets.row(r), s);
                worst = worst.max(dq.iter().map(|a| a * a).sum::<f64>().sqrt());
            }
        }
        assert!(worst < 1.0, "largest quaternion change {worst}");
        // The data do reach the half turns where a per-segment w ≥ 0 convention disagrees
        // with the reference segment (input) or with the previous step (target).
        let dot = |a: &[f64; 13], b: &[f64; 13]| (3..7).map(|k| a[k] * b[k]).sum::<f64>();
        let jumps = (0..g.len())
            .flat_map(|r| (0..N_SEGMENTS).map(move |s| (r, s)))
            .filter(|&(r, s)| {
                let (x0, x1) = (data.states.row(r), data.next_states.row(r));
                let (x0, x1) = (x0.as_slice().unwrap(), x1.as_slice().unwrap());
                let a = d.segment_frame(x0, s).to_array();
                let b = d.segment_frame(x1, s).to_array();
                let r0 = d.segment_frame(x0, REF_SEGMENT).to_array();
                dot(&a, &b) < 0.0 || dot(&a, &r0) < 0.0
            })
            .count();
        assert!(jumps > 0, "no half-turn crossings in the sample");
    }

    /// A small global net (N50, 0.1 s steps) and the drift of its mean segment centroid from
    /// the swim start (rest shape, at rest, heading +x) over 40 steps with all controls zero.
    fn global_zero_control_drift(
        tc: &crate::emulator::TransformConfig,
        examples: usize,
        hidden: usize,
    ) -> f64 {
        let d = Dolphin::default();
        let (train, held) = (
            sample_dolphin(&d, 0.002, 50, examples, 21).unwrap(),
            sample_dolphin(&d, 0.002, 50, examples / 4, 22).unwrap(),
        );
        let (gt, gh) = (
            global_transitions(&d, &train),
            global_transitions(&d, &held),
        );
        let tf = Transforms::fit(tc, &gt).unwrap();
        let (tr, ho) = (tf.encode(&gt), tf.encode(&gh));
        let mut rng = ChaCha8Rng::seed_from_u64(23);
        let mut mlp = Mlp::new(
            GLOBAL_DIM + N_SEGMENTS,
            hidden,
            GLOBAL_DIM,
            WeightInit::FanIn,
            &mut rng,
        );
        let mut st = spec(examples).settings;
        st.cg_max_iters = 300;
        st.patience = 30;
        train_mlp(&mut mlp, &tr, &ho, TrainMethod::Lbfgs, &st, 24, None).unwrap();
        let e = Emulator::new(tf, mlp, 0.1).unwrap();
        let mut g = vec![0.0; GLOBAL_DIM];
        global_state(&d, &d.rest_state(), &mut g);
        let g0 = g.clone();
        let (mut next, mut sc) = (g.clone(), e.scratch());
        for _ in 0..40 {
            e.predict(&g, &[0.0; N_SEGMENTS], &mut sc, &mut next);
            g.copy_from_slice(&next);
        }
        let mean = |g: &[f64]| -> Vector3<f64> {
            (0..N_SEGMENTS)
                .map(|s| Vector3::new(g[FRAME_DIM * s], g[FRAME_DIM * s + 1], g[FRAME_DIM * s + 2]))
                .sum::<Vector3<f64>>()
                / N_SEGMENTS as f64
        };
        (mean(&g) - mean(&g0)).norm()
    }

    /// Issue 11, defect 3: with all controls zero, the global net does not swim. From the
    /// swim start (the rest shape at rest) the simulator stays exactly put; the emulator's
    /// mean segment centroid must stay within 0.1 m over the swim's 40 steps (ours: a tenth of
    /// the ≈ 1 m the reference travelling wave swims on the simulator in those 4 s). With
    /// per-variable normalization this small net drifts about 1.1 m, with groups 0.03 m.
    #[test]
    fn a_global_net_with_zero_controls_does_not_swim() {
        let d = Dolphin::default();
        let mut sim = simulator(&d);
        let mut x = d.rest_state();
        for _ in 0..40 * 50 {
            sim.step(&mut x, &[0.0; N_SEGMENTS], 0.002);
        }
        let sim_drift = (d.centre_of_mass(&x) - d.centre_of_mass(&d.rest_state())).norm();
        let emu_drift = global_zero_control_drift(&global_transforms(), 2000, 20);
        assert!(sim_drift < 1e-9, "simulator drift {sim_drift}");
        assert!(emu_drift < 0.1, "emulator drift {emu_drift} m");
    }

    /// A tiny hierarchy trains end to end, deterministically, and round-trips the cache.
    /// Each sampled window is a chain of true simulator super-steps under its held controls,
    /// and the global chains continue every quaternion without a sign jump.
    #[test]
    fn dolphin_windows_are_simulator_super_steps_and_their_global_chains_are_continuous() {
        let d = Dolphin::default();
        let (dt, n, k) = (0.002, 10, 3);
        let w = sample_dolphin_windows(&d, dt, n, 2 * WINDOW_CHUNK + 3, k, 9).unwrap();
        assert_eq!(w.len(), 2 * WINDOW_CHUNK + 3);
        assert_eq!(w.states.len(), w.len() * (k + 1) * MASS_DIM);
        // Chunks keep their order; their episodes do not share indices.
        let (a, b) = w.episode.split_at(WINDOW_CHUNK);
        let (a_max, b_min) = (
            a.iter().max().unwrap(),
            b[..WINDOW_CHUNK].iter().min().unwrap(),
        );
        assert!(
            a_max < b_min,
            "chunk 0 episodes up to {a_max}, chunk 1 from {b_min}"
        );
        let mut sim = simulator(&d);
        for r in (0..w.len()).step_by(97) {
            for j in 0..k {
                let mut x = w.state(r, j).to_vec();
                for _ in 0..n {
                    sim.step(&mut x, w.control(r, j), dt);
                }
                assert_eq!(&x[..], w.state(r, j + 1), "window {r} step {j}");
            }
        }
        let g = crate::emulator::hierarchy::dagger::global_windows(&d, &w);
        assert_eq!(g.states.len(), w.len() * (k + 1) * GLOBAL_DIM);
        assert_eq!(g.controls, w.controls);
        let mut first = vec![0.0; GLOBAL_DIM];
        for r in 0..g.len() {
            global_state(&d, w.state(r, 0), &mut first);
            assert_eq!(g.state(r, 0), &first[..]);
            for j in 0..k {
                let (a, b) = (g.state(r, j), g.state(r, j + 1));
                for seg in 0..N_SEGMENTS {
                    let q = FRAME_DIM * seg + 3;
                    let dot: f64 = (0..4).map(|i| a[q + i] * b[q + i]).sum();
                    assert!(dot > 0.0, "window {r} step {j} segment {seg}: sign jump");
                }
            }
        }
    }

    /// With `rollout_k` set, the global net is fine-tuned on its k-step rollouts: the record
    /// carries the trace, the stop names both phases, and the fine-tuned net's held-out
    /// rollout loss is below the one-step net's (the trace's first point); the local nets stay
    /// one-step.
    #[test]
    fn a_global_net_with_rollout_k_is_fine_tuned_on_its_rollouts() {
        let d = Dolphin::default();
        let mut sp = spec(400);
        sp.settings.rollout_k = 3;
        sp.settings.rollout_weight = 1.0;
        sp.settings.rollout_iters = 30;
        sp.settings.patience = 30;
        let recs = train_hierarchy(&d, &sp).unwrap();
        let g = &recs[0];
        assert!(g.stop.contains("; rollout: "), "{}", g.stop);
        assert!(g.rollout_trace.len() > 1);
        let first = g.rollout_trace[0].held_out_error;
        let best = g
            .rollout_trace
            .iter()
            .map(|t| t.held_out_error)
            .fold(f64::INFINITY, f64::min);
        assert!(best < first, "held-out {first} -> {best}");
        assert!(recs[1..].iter().all(|r| r.rollout_trace.is_empty()));
    }

    #[test]
    fn tiny_hierarchy_trains_and_caches() {
        let dir = tempfile::tempdir().unwrap();
        let cache = EmulatorCache::new(dir.path());
        let sp = spec(60);
        let a = build_dolphin(&sp, &cache).unwrap();
        assert_eq!(a.nets.len(), 7);
        assert!(a
            .nets
            .iter()
            .all(|n| !n.from_cache && n.heldout_error.is_finite()));
        let b = build_dolphin(&sp, &cache).unwrap();
        assert!(b.nets.iter().all(|n| n.from_cache));
        let d = Dolphin::default();
        let x = start_state(&d, &mut ChaCha8Rng::seed_from_u64(1));
        let u = [0.3; 6];
        let (mut xa, mut xb) = (x.clone(), x.clone());
        let (mut ea, mut eb) = (a.emulator.clone(), b.emulator.clone());
        ea.step(&mut xa, &u, sp.super_dt());
        eb.step(&mut xb, &u, sp.super_dt());
        assert_eq!(xa, xb, "a cached hierarchy is bit-identical");
        assert!(xa.iter().all(|v| v.is_finite()));
        // The per-output breakdown of the global net's held-out error averages to its
        // held-out MSE (the same held-out examples, sampled again).
        let per = global_heldout_errors(&a.emulator, &sp).unwrap();
        assert_eq!(per.len(), GLOBAL_DIM);
        let mean = per.iter().map(|p| p.0).sum::<f64>() / per.len() as f64;
        assert!(per.iter().all(|p| p.1 >= 0.0));
        let reported = a.nets[0].heldout_error;
        assert!(
            (mean - reported).abs() <= 1e-9 * reported,
            "{mean} vs {reported}"
        );
    }
}
