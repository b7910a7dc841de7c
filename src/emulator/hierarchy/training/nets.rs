//! Training the seven nets ([`train_hierarchy`]): the global net's one-step data and
//! rollout fine-tuning, the local nets' teacher-forced data with their noise injection.

use super::super::{global_transforms_of, Frame, LocalLayout, GLOBAL_DIM};
use super::sampling::{global_rollout_windows, global_transitions, sample_dolphin};
use super::HierarchySpec;
use crate::emulator::cache::NetRecord;
use crate::emulator::catalog::{
    noisy, rollout_phase, stop_name, train_mlp, BuildError, TrainingData,
};
use crate::emulator::mlp::{Mlp, WeightInit};
use crate::emulator::rollout::change_spread;
use crate::emulator::train::{mse, Dataset};
use crate::emulator::transform::Normalizer;
use crate::emulator::{Emulator, Transforms, Transitions};
use crate::physics::dolphin::{Dolphin, N_SEGMENTS};
use ndarray::Array2;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use std::time::Instant;

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

/// The global net's one-step data from the sampled mass transitions `train` and `held`: their
/// global transitions, the transforms fitted on the training ones, both encoded, the training
/// set with the settings' input noise (stream 30 of the spec's seed), and the rollout-loss
/// scales ([`change_spread`]). What [`train_hierarchy`] trains the global net on, and what
/// DAgger ([`super::super::dagger`]) aggregates onto.
fn global_data(
    d: &Dolphin,
    spec: &HierarchySpec,
    train: &Transitions,
    held: &Transitions,
) -> Result<TrainingData, BuildError> {
    let (gt, gh) = (global_transitions(d, train), global_transitions(d, held));
    let transforms = Transforms::fit(&global_transforms_of(spec.global_transforms), &gt)?;
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
    let jobs: Vec<usize> = (0..=N_SEGMENTS).collect();
    let recs: Vec<NetRecord> = jobs
        .par_iter()
        .map(|&k| -> Result<NetRecord, BuildError> {
            let t1 = Instant::now();
            let rng = ChaCha8Rng::seed_from_u64(mix(10 + k as u64));
            if k == 0 {
                train_global(d, spec, &train, &held, sampling_s, rng)
            } else {
                train_local(d, spec, LocalLayout::new(k - 1), &train, &held, rng, t1)
            }
        })
        .collect::<Result<_, _>>()?;
    Ok(recs)
}

/// Samples the data and trains the global net alone, wrapped in `spec.global_transforms`: the
/// same examples, initial weights and training as [`train_hierarchy`]'s global net.
pub fn train_global_only(d: &Dolphin, spec: &HierarchySpec) -> Result<NetRecord, BuildError> {
    let t0 = Instant::now();
    let (train, held) = sample_spec(d, spec)?;
    let rng = ChaCha8Rng::seed_from_u64(crate::seed::mix_seed(spec.seed, 10));
    train_global(d, spec, &train, &held, t0.elapsed().as_secs_f64(), rng)
}

/// The global net on the sampled transitions: one-step training, then the k-step rollout
/// fine-tuning when the settings ask for it; `sampling_s` is added to its training time.
fn train_global(
    d: &Dolphin,
    spec: &HierarchySpec,
    train: &Transitions,
    held: &Transitions,
    sampling_s: f64,
    mut rng: ChaCha8Rng,
) -> Result<NetRecord, BuildError> {
    let t1 = Instant::now();
    let s = &spec.settings;
    let data = global_data(d, spec, train, held)?;
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
        crate::seed::mix_seed(spec.seed, 20),
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
}

/// Noise injection for a local net (as [`Transforms::perturb`] for the global net):
/// each local coordinate of each seen mass (positions and velocities in frame F₀,
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
            *d = scale * sd[c] * crate::portable::standard_normal(rng);
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

#[cfg(test)]
mod tests {
    use super::super::fixtures::spec;
    use super::*;
    use crate::emulator::catalog::TrainMethod;
    use crate::emulator::hierarchy::training::simulator;
    use crate::emulator::hierarchy::{global_state, global_transforms, FRAME_DIM};
    use crate::physics::Dynamics;
    use nalgebra::Vector3;

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
        // Until the held-out error stops improving (about 700 iterations), not a cap.
        st.cg_max_iters = 3000;
        st.patience = 30;
        let r = train_mlp(&mut mlp, &tr, &ho, TrainMethod::Lbfgs, &st, 24, None).unwrap();
        assert_eq!(r.stop, crate::emulator::train::StopReason::NoImprovement);
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

    /// With all controls zero, the global net does not swim. From the
    /// swim start (the rest shape at rest) the simulator stays exactly put; the emulator's
    /// mean segment centroid must stay within 0.078 m over the swim's 40 steps (ours: a tenth
    /// of the 0.78 m a 1 Hz travelling wave, 30° a segment, swims on the simulator in those
    /// 4 s). This small net, trained until its held-out error stops improving, drifts about
    /// 0.056 m; stopped at 300 iterations it drifted 0.10 m.
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
        assert!(emu_drift < 0.078, "emulator drift {emu_drift} m");
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
}
