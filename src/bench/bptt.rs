//! The BPTT metrics: a rollout and its full gradient through the lander's net, a bare net as
//! the JAX peer times it, and the dolphin's global net.

use super::neural::{bare_emulator, lander_emulator, net_17_50_13};
use super::throughput;
use crate::emulator::catalog::NetModel;
use crate::emulator::mlp::{Mlp, WeightInit};
use crate::emulator::{Emulator, Transforms};
use std::hint::black_box;

/// BPTT iterations per second on the lander's Table 1 network shape (17-50-13, random weights,
/// its transforms): a 40-step emulated rollout and the full gradient with respect to the 80
/// control knots, under a soft-landing objective.
pub(super) fn bptt_lander(min_seconds: f64) -> f64 {
    use crate::control::bptt::{Bounds, Bptt, Knots};
    use crate::control::objective::{ControlEffort, FinalState, Objective};
    use rand::SeedableRng;
    let model = NetModel::Lander;
    let (n, m) = (model.state_dim(), model.control_dim());
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(2);
    let e = lander_emulator(net_17_50_13(&mut rng));
    let x0 = crate::physics::lander::Lander::upright_at_rest([10.0, -5.0, 60.0]);
    let target = crate::physics::lander::Lander::upright_at_rest([0.0, 0.0, 1.5]);
    let obj = Objective::default()
        .with(ControlEffort::plain(0.01, m))
        .with(FinalState {
            mu: 1.0,
            target: target.to_vec(),
            weights: vec![1.0; n],
        });
    let limits = model.control_limits();
    let bounds = Bounds::new(limits.low, limits.high);
    let knots = Knots {
        steps: 40,
        per_actuator: 20,
        m,
    };
    let mut b = Bptt::new(&e, &obj, knots, bounds, &x0).expect("dimensions agree");
    let v = vec![0.0; b.dim()];
    let mut g = vec![0.0; b.dim()];
    throughput(min_seconds, 1, || {
        black_box(b.gradient(black_box(&v), &mut g));
    })
}

/// BPTT iterations per second on the problem `../shared/peers/bench_bptt.py` times in JAX: a
/// bare 17-50-13 net predicting the state change (no frame, no normalization), 13 states and 4
/// controls, one control per step over 40 steps, J = ½ μ_u Σ|u_t|² + ½ μ_s |s₄₀ − s_d|²; an
/// iteration is the rollout, the full gradient and a plain descent update of the controls.
/// Besides `bptt.lander.iters_per_s` (the lander's frame transforms, which the peer lacks),
/// it compares the two codes on the same work.
pub(super) fn bptt_bare(min_seconds: f64) -> f64 {
    use crate::control::bptt::{Bounds, Bptt, Knots};
    use crate::control::objective::{ControlEffort, FinalState, Objective};
    use rand::{Rng, SeedableRng};
    let (n, m, steps) = (13, 4, 40);
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(4);
    let e = bare_emulator(net_17_50_13(&mut rng));
    let x0: Vec<f64> = (0..n).map(|_| rng.random_range(-1.0..1.0)).collect();
    let target: Vec<f64> = (0..n).map(|_| rng.random_range(-1.0..1.0)).collect();
    let obj = Objective::default()
        .with(ControlEffort::plain(1e-3, m))
        .with(FinalState {
            mu: 1.0,
            target,
            weights: vec![1.0; n],
        });
    let bounds = Bounds::new(vec![-1.0; m], vec![1.0; m]);
    let knots = Knots {
        steps,
        per_actuator: steps,
        m,
    };
    let mut b = Bptt::new(&e, &obj, knots, bounds, &x0).expect("dimensions agree");
    let mut v = vec![0.0; b.dim()];
    let mut g = vec![0.0; b.dim()];
    throughput(min_seconds, 1, || {
        black_box(b.gradient(black_box(&v), &mut g));
        for (v, g) in v.iter_mut().zip(&g) {
            *v -= 0.05 * g;
        }
    })
}

/// BPTT iterations per second through the dolphin's global net of the Table 1 shape (84-50-78,
/// random weights, the global transforms): a 40-step emulated swim and the full gradient with
/// respect to the 120 muscle knots (20 per muscle), under the swim objective of `na_swim`.
pub(super) fn bptt_dolphin(min_seconds: f64) -> f64 {
    use crate::control::bptt::Bptt;
    use crate::emulator::hierarchy::{global_transforms, Regularizer, GLOBAL_DIM};
    use crate::families::na::swim::SwimTask;
    use crate::physics::dolphin::{Dolphin, N_SEGMENTS};
    use rand::SeedableRng;
    let (n, m) = (GLOBAL_DIM, N_SEGMENTS);
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
    let mlp = Mlp::new(n + m, 50, n, WeightInit::FanIn, &mut rng);
    let transforms =
        Transforms::unfitted(&global_transforms(), n, m).expect("global transforms fit");
    let e = Emulator::new(transforms, mlp, 0.1).expect("shapes agree");
    let swim = SwimTask {
        horizon: 40,
        knots: 20,
        distance_mu: 1.0,
        effort_mu: 0.01,
        regularization: Regularizer {
            dt: 0.005,
            stiffness_scale: 0.1,
            damping_scale: 0.2,
        },
        regularization_steps: 5,
    };
    let obj = swim.objective();
    let (_, g0) = swim.start(&Dolphin::default());
    let mut b =
        Bptt::new(&e, &obj, swim.knot_layout(), swim.bounds(), &g0).expect("dimensions agree");
    let v = vec![0.0; b.dim()];
    let mut g = vec![0.0; b.dim()];
    throughput(min_seconds, 1, || {
        black_box(b.gradient(black_box(&v), &mut g));
    })
}
