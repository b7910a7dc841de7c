//! The dolphin's sampling runs: episode starts, the muscle-wave controls, transitions and
//! rollout windows sampled in parallel seeded chunks, and their global-state form.

use super::super::{global_state, global_state_after, point, put, GLOBAL_DIM, MASS_DIM};
use super::HierarchySpec;
use crate::emulator::catalog::BuildError;
use crate::emulator::dataset::{
    sample_transitions, sample_windows, ControlLimits, ControlProcess, SamplingConfig, Windows,
};
use crate::emulator::Transitions;
use crate::physics::dolphin::{Dolphin, N_MASSES, N_POS, N_SEGMENTS};
use crate::physics::{IntegratorKind, Simulator};
use nalgebra::{UnitQuaternion, Vector3};
use ndarray::{s, Array2};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use std::f64::consts::PI;

/// Examples per sampling chunk (each chunk is simulated from its own seeded stream).
pub(super) const CHUNK: usize = 2000;

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
/// held-out, as global-state chains ([`super::super::dagger::global_windows`]): examples / k windows
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
        Ok(super::super::dagger::global_windows(d, &w))
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
    use crate::emulator::hierarchy::{global_transforms, FRAME_DIM, REF_SEGMENT};
    use crate::emulator::Transforms;
    use crate::physics::Dynamics;

    /// The global net's training data have no quaternion sign jumps.
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
}
