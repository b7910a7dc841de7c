//! The neural metrics: emulator steps and rollouts, network training and full gradients,
//! rollout-loss gradients, and the dolphin hierarchy's nets, on random weights of the real shapes.

use super::throughput;
use crate::emulator::catalog::NetModel;
use crate::emulator::mlp::{Mlp, WeightInit};
use crate::emulator::train::{Dataset, MomentumBatches, MomentumState};
use crate::emulator::{Emulator, Transforms};
use std::hint::black_box;

/// The 17-50-13 net of the BPTT and rollout metrics, random weights drawn from `rng`.
pub(super) fn net_17_50_13(rng: &mut rand_chacha::ChaCha8Rng) -> Mlp {
    Mlp::new(17, 50, 13, WeightInit::FanIn, rng)
}

/// `mlp` in the lander's transforms (heading frame, normalization, state change).
pub(super) fn lander_emulator(mlp: Mlp) -> Emulator {
    let model = NetModel::Lander;
    let (n, m) = (model.state_dim(), model.control_dim());
    let transforms =
        Transforms::unfitted(&model.transform_config(), n, m).expect("catalog transforms fit");
    Emulator::new(transforms, mlp, 0.5).expect("shapes agree")
}

/// `mlp` bare, as the peers run it: predicting the state change of 13 states under 4 controls,
/// no frame, no normalization.
pub(super) fn bare_emulator(mlp: Mlp) -> Emulator {
    use crate::emulator::transform::TransformConfig;
    let config = TransformConfig {
        delta: true,
        ..TransformConfig::none()
    };
    let transforms = Transforms::unfitted(&config, 13, 4).expect("no frame to check");
    Emulator::new(transforms, mlp, 0.5).expect("shapes agree")
}

/// Mini-batch (30, momentum) training and full-gradient throughput of an `n_in`-`hidden`-`n_out`
/// net on `examples` random examples. The mini-batches are shuffled and gathered, the way
/// [`crate::emulator::train::train_momentum`] takes them.
fn mlp_training_metrics(
    n_in: usize,
    hidden: usize,
    n_out: usize,
    examples: usize,
    min_seconds: f64,
) -> (Mlp, Vec<(String, f64)>) {
    use rand::seq::SliceRandom;
    use rand::{Rng, SeedableRng};
    let shape = format!("{n_in}-{hidden}-{n_out}");
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
    let mut mlp = Mlp::new(n_in, hidden, n_out, WeightInit::FanIn, &mut rng);
    let x = ndarray::Array2::from_shape_fn((examples, n_in), |_| rng.random_range(-1.0..1.0));
    let y = ndarray::Array2::from_shape_fn((examples, n_out), |_| rng.random_range(-1.0..1.0));
    let data = Dataset::new(x, y).expect("as many targets as inputs");
    let mut state = MomentumState::new(mlp.n_weights());
    // Mini-batches of 30 in a shuffled order, each gathered from the training set and stepped
    // by `train_momentum`'s own update (as NumPy's epoch in `compare.py` gathers X[idx]).
    let batch = 30;
    let mut order: Vec<usize> = (0..examples).collect();
    order.shuffle(&mut rng);
    let mut batches = MomentumBatches::new(&mlp, &data, batch);
    let per_call = 600.min(examples / batch * batch);
    let mut next = 0;
    let train = throughput(min_seconds, per_call as u64, || {
        for _ in 0..per_call / batch {
            if next + batch > examples {
                next = 0;
            }
            // This batch, and the next one (fetched while this one computes).
            let after = next + batch;
            let ahead = if after + batch <= examples {
                &order[after..after + batch]
            } else {
                &order[..batch]
            };
            let rows = (&order[next..after], ahead);
            batches.step(&mut mlp, &data, rows, &mut state, (1e-3, 0.9), None);
            next = after;
        }
    });
    let mut grad = vec![0.0; mlp.n_weights()];
    let full = throughput(min_seconds, 1, || {
        black_box(mlp.loss_grad(data.inputs.view(), data.targets.view(), &mut grad));
    });
    let macs = (2 * n_in * hidden + 3 * hidden * n_out) as f64;
    (
        mlp,
        vec![
            (format!("mlp.{shape}.train_examples_per_s"), train),
            (format!("mlp.{shape}.full_grad_per_s"), full),
            (format!("mlp.{shape}.train_gmac_per_s"), train * macs / 1e9),
            (
                format!("mlp.{shape}.full_grad_gmac_per_s"),
                full * examples as f64 * macs / 1e9,
            ),
        ],
    )
}

/// The dolphin's Table 1 shapes: the global net (84-50-78, with its frame transforms, batch-1
/// steps of the 78-variable frame state), a middle segment's local net (70-40-24, batch-1
/// forward), and the whole hierarchical step of the 138-variable mass state
/// (`emulator.dolphin_hierarchy.steps_per_s`: six frame fits, the global net, six local nets).
pub(super) fn dolphin_metrics(min_seconds: f64) -> Vec<(String, f64)> {
    use crate::emulator::hierarchy::{
        global_state, global_transforms, DolphinEmulator, LocalLayout, LocalNet, GLOBAL_DIM,
    };
    use crate::emulator::transform::Normalizer;
    use crate::physics::dolphin::{Dolphin, N_SEGMENTS};
    let mut out = vec![];
    let (gmlp, m) =
        mlp_training_metrics(GLOBAL_DIM + N_SEGMENTS, 50, GLOBAL_DIM, 64000, min_seconds);
    out.extend(m);
    let t = Transforms::unfitted(&global_transforms(), GLOBAL_DIM, N_SEGMENTS)
        .expect("dolphin transforms fit");
    let global = Emulator::new(t, gmlp, 0.1).expect("shapes agree");
    let d = Dolphin::default();
    let x0 = d.rest_state();
    let mut g0 = vec![0.0; GLOBAL_DIM];
    global_state(&d, &x0, &mut g0);
    let u = [0.3, -0.2, 0.1, 0.5, -0.4, 0.2];
    let (mut sc, mut g1) = (global.scratch(), vec![0.0; GLOBAL_DIM]);
    let k = 1000;
    out.push((
        format!(
            "emulator.{}-50-{GLOBAL_DIM}.steps_per_s",
            GLOBAL_DIM + N_SEGMENTS
        ),
        throughput(min_seconds, k, || {
            for _ in 0..k {
                global.predict(black_box(&g0), &u, &mut sc, &mut g1);
                black_box(&g1);
            }
        }),
    ));
    out.push((
        format!(
            "rollout.{}-50-{GLOBAL_DIM}.k8_window_grads_per_s",
            GLOBAL_DIM + N_SEGMENTS
        ),
        rollout_grad_metric(&global, &g0, &u, min_seconds),
    ));
    let locals: Vec<LocalNet> = (0..N_SEGMENTS)
        .map(|s| {
            let layout = LocalLayout::new(s);
            let (n_in, n_out) = (layout.n_in(), layout.n_out());
            let (mlp, m) = if s == 2 {
                mlp_training_metrics(n_in, 40, n_out, 32000, min_seconds)
            } else {
                let mut rng =
                    <rand_chacha::ChaCha8Rng as rand::SeedableRng>::seed_from_u64(s as u64);
                (
                    Mlp::new(n_in, 40, n_out, WeightInit::FanIn, &mut rng),
                    vec![],
                )
            };
            out.extend(m);
            LocalNet {
                layout,
                mlp,
                input_norm: Normalizer::identity(n_in),
                output_norm: Normalizer {
                    mean: vec![0.0; n_out],
                    std: vec![1e-3; n_out],
                },
            }
        })
        .collect();
    let l = &locals[2].mlp;
    let shape = format!("{}-40-{}", l.n_in(), l.n_out());
    let z = vec![0.1; l.n_in()];
    let (mut lsc, mut y) = (l.scratch(), vec![0.0; l.n_out()]);
    out.push((
        format!("emulator.{shape}.steps_per_s"),
        throughput(min_seconds, k, || {
            for _ in 0..k {
                l.forward(black_box(&z), &mut lsc, &mut y);
                black_box(&y);
            }
        }),
    ));
    let emu = DolphinEmulator::new(d, global, locals);
    let (mut hs, mut x1) = (emu.scratch(), vec![0.0; x0.len()]);
    let k = 200;
    out.push((
        "emulator.dolphin_hierarchy.steps_per_s".into(),
        throughput(min_seconds, k, || {
            for _ in 0..k {
                emu.predict(black_box(&x0), &u, &mut hs, &mut x1);
                black_box(&x1);
            }
        }),
    ));
    out
}

/// Emulator steps per second along dependent rollouts of 400 steps at batch 1 with a 17-50-13
/// net (random weights, per-step controls in ±0.1), the way `../shared/peers/bench_rollout.py`
/// times JAX's `lax.scan` (`jax_jit_scan_f64_b1`): each step reads the state the step before
/// wrote, so a step's latency counts, where `emulator.<shape>.steps_per_s` steps from one state
/// again and again (independent steps, which overlap in the core). Two problems: the lander's
/// net with its transforms (`emulator.17-50-13.rollout_steps_per_s`) and the peer's own, a bare
/// net predicting the state change (`emulator.17-50-13.bare.rollout_steps_per_s`).
pub(super) fn emulator_rollouts(min_seconds: f64) -> Vec<(String, f64)> {
    use rand::{Rng, SeedableRng};
    const STEPS: usize = 400;
    let model = NetModel::Lander;
    let (n, m) = (model.state_dim(), model.control_dim());
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
    let mlp = net_17_50_13(&mut rng);
    let (lander, bare) = (lander_emulator(mlp.clone()), bare_emulator(mlp));
    let lander_x0 = model.start_state(&mut rng);
    let bare_x0: Vec<f64> = (0..n).map(|_| rng.random_range(-1.0..1.0)).collect();
    let controls: Vec<f64> = (0..STEPS * m)
        .map(|_| rng.random_range(-0.1..0.1))
        .collect();
    let problems = [
        ("emulator.17-50-13.rollout_steps_per_s", &lander, lander_x0),
        ("emulator.17-50-13.bare.rollout_steps_per_s", &bare, bare_x0),
    ];
    problems
        .into_iter()
        .map(|(name, e, x0)| {
            let (mut sc, mut s, mut next) = (e.scratch(), x0.clone(), vec![0.0; n]);
            let mut rollout = |s: &mut Vec<f64>| {
                s.copy_from_slice(&x0);
                for u in controls.chunks_exact(m) {
                    e.predict(s, u, &mut sc, &mut next);
                    std::mem::swap(s, &mut next);
                }
                black_box(&s);
            };
            rollout(&mut s);
            // A rollout that left the finite range would time NaN arithmetic, not the step.
            assert!(
                s.iter().all(|x| x.is_finite()),
                "{name}: rollout not finite"
            );
            let steps = throughput(min_seconds, STEPS as u64, || rollout(&mut s));
            (name.to_string(), steps)
        })
        .collect()
}

/// Training and stepping throughput of the Table 1 network of `model` (random weights and data
/// of the real shapes; the emulator uses the model's transforms).
/// Gradients per second of the k-step rollout loss (k = 8) over 64 windows through `e` (its
/// net and transforms), the loss `fine_tune` minimizes: windows are the emulator's
/// own rollouts from `s0` under per-step controls around `u`, with targets moved off them by a
/// little, so every step's cotangent is nonzero. Counted in windows per second.
pub fn rollout_grad_metric(e: &Emulator, s0: &[f64], u: &[f64], min_seconds: f64) -> f64 {
    use crate::emulator::dataset::Windows;
    use crate::emulator::rollout::RolloutLoss;
    let (n, m, k, count) = (s0.len(), u.len(), 8, 64);
    let (mut states, mut controls) = (vec![], vec![]);
    let (mut sc, mut next) = (e.scratch(), vec![0.0; n]);
    for r in 0..count {
        let mut s = s0.to_vec();
        states.extend_from_slice(&s);
        for i in 0..k {
            let ui: Vec<f64> = (0..m)
                .map(|j| u[j] * (1.0 + 0.1 * (((r * 7 + i * 3 + j) % 11) as f64 - 5.0) / 5.0))
                .collect();
            e.predict(&s, &ui, &mut sc, &mut next);
            s.copy_from_slice(&next);
            states.extend(
                s.iter()
                    .enumerate()
                    .map(|(v, x)| x + 1e-3 * (1.0 + (v % 3) as f64)),
            );
            controls.extend_from_slice(&ui);
        }
    }
    let w = Windows {
        k,
        state_dim: n,
        control_dim: m,
        states,
        controls,
        episode: (0..count).collect(),
        start_step: vec![0; count],
    };
    let loss = RolloutLoss::new(e.transforms(), &w, &vec![1.0; n]).expect("shapes agree");
    let mut g = vec![0.0; e.mlp().n_weights()];
    throughput(min_seconds, count as u64, || {
        g.fill(0.0);
        black_box(loss.value_grad(e.mlp(), &mut g));
    })
}

pub(super) fn emulator_metrics(
    model: NetModel,
    hidden: usize,
    examples: usize,
    min_seconds: f64,
) -> Vec<(String, f64)> {
    use rand::SeedableRng;
    let (n, m) = (model.state_dim(), model.control_dim());
    let shape = format!("{}-{hidden}-{n}", n + m);
    let (mlp, mut out) = mlp_training_metrics(n + m, hidden, n, examples, min_seconds);
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
    let transforms =
        Transforms::unfitted(&model.transform_config(), n, m).expect("catalog transforms fit");
    let e = Emulator::new(transforms, mlp, 0.5).expect("shapes agree");
    let s0 = model.start_state(&mut rng);
    let u: Vec<f64> = (0..m).map(|_| 0.1).collect();
    let mut scratch = e.scratch();
    let mut s1 = vec![0.0; n];
    let k = 1000;
    let steps = throughput(min_seconds, k, || {
        for _ in 0..k {
            e.predict(black_box(&s0), &u, &mut scratch, &mut s1);
            black_box(&s1);
        }
    });
    out.push((format!("emulator.{shape}.steps_per_s"), steps));
    out.push((
        format!("rollout.{shape}.k8_window_grads_per_s"),
        rollout_grad_metric(&e, &s0, &u, min_seconds),
    ));
    out
}
