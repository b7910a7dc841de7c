//! The same digits on every machine: FNV-1a hashes of the bits of short rollouts of every
//! model that feeds a verdict (the jumper's crouch among them), of one DDP iteration and one
//! LQR tracker of the diver, of the Bellman combination and of the portable elementary
//! functions, and of tiny emulators trained by each method and rolled out, against recorded
//! constants. The constants were recorded on a Zen 3 with AVX2 + FMA and checked there with
//! glibc forced onto its generic code, `matrixmultiply` onto its plain kernel and
//! `MOTIONLAB_SIMD=scalar` and `avx2` (PERFORMANCE.md says how); a constant changes only with a
//! deliberate change of its model, data or solver, which the commit that changes it names.
//!
//! A failure on a machine where the rest of the suite passes means some operation on that
//! path picks its implementation by processor (a libm call, a dispatched matrix kernel):
//! find it and route it through `motionlab::portable` or `motionlab::linalg::gemm`, rather
//! than updating the constant. A deliberate change to a model or a solver updates it.

use motionlab::bellman::combine::{blend_weights, normalized_entropy};
use motionlab::control::ddp::{solve, ControlBounds, DdpOptions};
use motionlab::control::lqr::track;
use motionlab::control::{QuadraticCost, Rk4Map};
use motionlab::emulator::catalog::{
    train_emulator, BuildSpec, NetModel, NetSpec, TrainMethod, TrainSettings,
};
use motionlab::physics::lattice::{Floor, Lattice, LatticeModel};
use motionlab::physics::linearize::FiniteDifference;
use motionlab::physics::{
    diver, dolphin, lander, model_by_name, IntegratorKind, Model, Simulator, MODEL_NAMES,
};
use motionlab::portable;
use nalgebra::{DMatrix, DVector};
use rand::SeedableRng;

/// FNV-1a over the bits of a sequence of doubles.
#[derive(Clone, Copy)]
struct Fnv(u64);

impl Fnv {
    fn new() -> Self {
        Fnv(0xcbf2_9ce4_8422_2325)
    }
    fn add(&mut self, v: f64) {
        for byte in v.to_bits().to_le_bytes() {
            self.0 ^= u64::from(byte);
            self.0 = self.0.wrapping_mul(0x0000_0100_0000_01b3);
        }
    }
    fn all<'a>(&mut self, vs: impl IntoIterator<Item = &'a f64>) {
        vs.into_iter().for_each(|&v| self.add(v));
    }
}

/// Compares every (name, hash) with the recorded one and reports all mismatches at once.
fn check(got: &[(String, u64)], want: &[(&str, u64)]) {
    let mut bad = Vec::new();
    for (name, h) in got {
        match want.iter().find(|(n, _)| n == name) {
            Some(&(_, w)) if w == *h => {}
            _ => bad.push(format!("(\"{name}\", {h:#018x}),")),
        }
    }
    assert!(
        bad.is_empty() && got.len() == want.len(),
        "bits changed (see the module docs); got:\n{}",
        bad.join("\n")
    );
}

/// A deterministic control pattern in [−amp, amp].
fn pattern(k: usize, j: usize, amp: f64) -> f64 {
    amp * ((((k * 7 + j * 3) % 11) as f64) / 5.0 - 1.0)
}

/// The start of a model's rollout: a physical state for the lander and the dolphin, the
/// diver's take-off, a moving truck, and a spread of angles and rates for the rest.
fn start(name: &str, n: usize) -> Vec<f64> {
    match name {
        "lander" => {
            let mut x = lander::Lander::upright_at_rest([0.5, 2.0, 0.1]).to_vec();
            x[n / 2 + 1] = 0.3;
            x
        }
        "dolphin" => {
            let mut x = dolphin::Dolphin::default().rest_state();
            for (i, v) in x[n / 2..].iter_mut().enumerate() {
                *v = pattern(i, 1, 0.05);
            }
            x
        }
        "biped" => {
            // Standing 1 cm above the ground, every joint moving a little.
            let mut x = motionlab::physics::biped::Biped::default().standing(0.0, 0.01);
            for (i, v) in x[n / 2..].iter_mut().enumerate() {
                *v = pattern(i, 1, 0.3);
            }
            x
        }
        "jumper" => {
            // A crouch 1 cm above the ground, every joint moving a little.
            let j = motionlab::physics::jumper::Jumper::default();
            let mut x = j.crouch(0.0, 0.3, 0.3, 0.2);
            x[1] += 0.01;
            for (i, v) in x[n / 2..].iter_mut().enumerate() {
                *v = pattern(i, 1, 0.3);
            }
            x
        }
        "diver" => {
            let mut x = vec![0.0; n];
            (x[2], x[6], x[9], x[10], x[11]) = (1.5, 3.1, 1.0, 4.0, 1.0);
            x
        }
        _ => {
            let mut x: Vec<f64> = (0..n).map(|i| pattern(i, 2, 0.4)).collect();
            if name == "truck" {
                x[3] = 3.0;
            }
            x
        }
    }
}

fn rollout_hash<M: motionlab::physics::Ode>(
    model: M,
    kind: IntegratorKind,
    x0: &[f64],
    steps: usize,
    control: impl Fn(usize, usize) -> f64,
) -> u64 {
    let dt = model.default_dt();
    let mut sim = Simulator::new(model, kind);
    let mut h = Fnv::new();
    sim.rollout(
        x0,
        dt,
        steps,
        |k, _, _, u| {
            for (j, v) in u.iter_mut().enumerate() {
                *v = control(k, j);
            }
        },
        |_, _, x| h.all(x),
    )
    .expect("rollout stays finite");
    h.0
}

#[test]
fn rollouts_of_every_model_keep_their_bits() {
    let mut got = Vec::new();
    for &name in MODEL_NAMES {
        let model = model_by_name(name).unwrap();
        let x0 = start(name, model.state_dim());
        got.push((
            name.to_string(),
            rollout_hash(model, IntegratorKind::Rk4, &x0, 100, |k, j| {
                pattern(k, j, 0.5)
            }),
        ));
    }
    // The adaptive integrator's step rule (physics_validation).
    let model = model_by_name("pendulum3_passive").unwrap();
    let x0 = start("pendulum3_passive", model.state_dim());
    got.push((
        "pendulum3_passive_rk45".into(),
        rollout_hash(model, IntegratorKind::Rk45, &x0, 50, |_, _| 0.0),
    ));
    // A mass-spring cube placed tilted and sliding, rest lengths driven (the MS families).
    let lattice = Lattice::cube();
    let rest = lattice.rest_lengths();
    let x0 = lattice.placed_state([0.1, 0.2, 0.3], 0.05, [0.5, 0.0, 0.0]);
    let model = LatticeModel::new(lattice)
        .unwrap()
        .with_floor(Floor::default())
        .unwrap();
    got.push((
        "lattice_cube".into(),
        rollout_hash(
            model,
            IntegratorKind::SemiImplicitEuler,
            &x0,
            300,
            |k, j| rest[j] * (1.0 + pattern(k / 20, j, 0.1)),
        ),
    ));
    check(
        &got,
        &[
            ("pendulum3", 0xadb961642be1e3b7),
            ("pendulum3_passive", 0xbd2e63dd1e33d620),
            ("pendulum3_ext", 0x9e75eecee4eff72f),
            ("acrobot", 0x7dd8b5d5ec3defcb),
            ("biped", 0x59cc847aa9382477),
            ("diver", 0x3311cf476a8a696c),
            ("jumper", 0xfcdc369ed752d342),
            ("push_recovery", 0xb2d6bc1ce7f73cce),
            ("truck", 0x4a85f3df3a90e50d),
            ("lander", 0x4df91033582ba475),
            ("dolphin", 0xd09f9220c00e3aa0),
            ("chain3d", 0xec2bdfb1cdb8b32a),
            ("leaper3d", 0x95bb4ebefe15f654),
            ("pendulum3_passive_rk45", 0x075cff40cfa12027),
            ("lattice_cube", 0xbc6c1aea5f810db9),
        ],
    );
}

#[test]
fn one_diver_ddp_iteration_and_its_tracker_keep_their_bits() {
    // The quick lbc_diver_coordination dive: 1.4 s at 0.04 s, torque-limited.
    let (dt, steps) = (0.04, 35);
    let map = Rk4Map::new(FiniteDifference::new(diver::diver()), dt).unwrap();
    let mut x0 = DVector::zeros(18);
    (x0[2], x0[6], x0[9], x0[10], x0[11]) = (
        std::f64::consts::FRAC_PI_2,
        std::f64::consts::PI,
        1.0,
        4.0,
        1.0,
    );
    let mut target = DVector::zeros(18);
    target[2] = std::f64::consts::FRAC_PI_2 + std::f64::consts::PI;
    target[6] = std::f64::consts::PI;
    let mut q = vec![0.0; 18];
    q[2] = 2.0;
    q[3..9].iter_mut().for_each(|v| *v = 2.0);
    q[11..18].iter_mut().for_each(|v| *v = 0.1);
    let cost = QuadraticCost {
        dt,
        r: DMatrix::identity(6, 6) * 1e-3,
        state: None,
        q_final: DMatrix::from_diagonal(&DVector::from_vec(q)),
        x_final: target,
    };
    let limits = DVector::from_row_slice(&[40.0, 140.0, 100.0, 300.0, 300.0, 200.0]);
    let options = DdpOptions {
        max_iterations: 1,
        bounds: Some(ControlBounds {
            lower: -limits.clone(),
            upper: limits,
        }),
        ..DdpOptions::default()
    };
    let u0 = vec![DVector::zeros(6); steps];
    let sol = solve(&map, &cost, &x0, &u0, &options).unwrap();
    let mut h = Fnv::new();
    sol.x.iter().for_each(|x| h.all(x.iter()));
    sol.u.iter().for_each(|u| h.all(u.iter()));
    h.all(sol.gains.as_slice());
    h.all(sol.feedforward.as_slice());
    h.add(sol.cost);
    let ddp = h.0;
    let tracker = track(&map, &cost, &sol.x, &sol.u).unwrap();
    let mut h = Fnv::new();
    h.all(tracker.gains.as_slice());
    h.all(tracker.value_hessian.as_slice());
    h.all(&tracker.value_ref);
    check(
        &[("ddp".into(), ddp), ("lqr".into(), h.0)],
        &[("ddp", 0xc216a3d6ffc4564b), ("lqr", 0x6e539821c95cf2bb)],
    );
}

#[test]
fn bellman_combination_and_portable_functions_keep_their_bits() {
    let mut h = Fnv::new();
    let mut alpha = [0.0; 3];
    for k in 0..200 {
        let values = [
            pattern(k, 0, 40.0) + 50.0,
            pattern(k, 1, 40.0) + 51.0,
            pattern(k, 2, 40.0) + 49.0,
        ];
        let lambda = 0.1 + k as f64 * 0.05;
        let v = blend_weights(&[1.0, 0.7, 0.4], &values, lambda, &mut alpha).unwrap();
        h.add(v);
        h.all(&alpha);
        h.add(normalized_entropy(&alpha));
    }
    let bellman = h.0;
    let mut h = Fnv::new();
    for i in 0..2000 {
        let x = (i as f64 - 1000.0) * 0.0137 + 1e-3;
        let (s, c) = portable::sin_cos(x * 7.0);
        h.all(&[s, c, portable::exp(x * 0.7), portable::ln(x.abs() * 3.0)]);
        h.all(&[
            portable::atan2(x, 1.0 - x),
            portable::tanh(x),
            portable::exp_m1(x),
        ]);
        h.all(&[portable::hypot(x, 2.0), portable::powf(x.abs(), 1.7)]);
    }
    // The local frame's heading norm on quaternion-like pairs (the correction changes the
    // naive square root's last bit on 661 of these 4000).
    let mut g = Fnv::new();
    for i in 0..4000 {
        let w = ((i * 7919) % 4001) as f64 / 2000.5 - 1.0;
        let z = ((i * 104_729) % 3989) as f64 / 1994.5 - 1.0;
        g.add(portable::hypot_corrected(w, z));
    }
    check(
        &[
            ("bellman".into(), bellman),
            ("portable".into(), h.0),
            ("hypot_corrected".into(), g.0),
        ],
        &[
            ("bellman", 0xc847e1b27af1a25a),
            ("portable", 0x36d05a7346521db0),
            ("hypot_corrected", 0x7c21d96d16f408fc),
        ],
    );
}

/// The jumper's crouch (an inverse-kinematics pose built with the portable sine, cosine and
/// arctangent, the start state of every jump DDP optimizes) over a grid of leans, shin angles
/// and arm angles.
#[test]
fn the_jumpers_crouch_keeps_its_bits() {
    let j = motionlab::physics::jumper::Jumper::default();
    let mut h = Fnv::new();
    for k in 0..24 {
        let (lean, shin, arm) = (
            0.1 + 0.03 * k as f64,
            0.4 + 0.025 * k as f64,
            -0.5 + 0.05 * k as f64,
        );
        h.all(&j.crouch(0.2 * k as f64, lean, shin, arm));
    }
    check(&[("crouch".into(), h.0)], &[("crouch", 0xa0c7ec33f18649d9)]);
}

/// The jumper's standing test (the `landed` of every jump: not fallen, a foot point on the
/// ground, the centre of mass over the sole and slow, its speed through the portable
/// `hypot`) over crouches at several heights above the ground and centre-of-mass velocities
/// around its 0.5 m/s bar: the speed's bits and each decision.
#[test]
fn the_jumpers_standing_test_keeps_its_bits() {
    use motionlab::families::lbc::jumping::standing;
    let j = motionlab::physics::jumper::Jumper::default();
    let dof = motionlab::physics::jumper::DOF;
    let mut h = Fnv::new();
    let mut stood = 0;
    for k in 0..12 {
        let mut x = j.crouch(0.0, 0.1 + 0.02 * k as f64, 0.3, 0.2);
        x[1] += [0.0, 0.004, 0.02][k % 3];
        for m in 0..12 {
            // Base velocities whose speed crosses 0.5 m/s (the joints still).
            let a = 0.3 * m as f64;
            let (vx, vy) = (
                0.12 * m as f64 * motionlab::portable::cos(a),
                0.05 * motionlab::portable::sin(a),
            );
            x[dof] = vx;
            x[dof + 1] = vy;
            let v = j.com_velocity(&x);
            h.add(motionlab::portable::hypot(v[0], v[1]));
            let ok = standing(&j, &x);
            stood += ok as usize;
            h.add(if ok { 1.0 } else { 0.0 });
        }
    }
    assert!(
        stood > 0 && stood < 144,
        "the grid must cross the bar: {stood} of 144 stand"
    );
    check(
        &[("standing".into(), h.0)],
        &[("standing", 0xd6aa2c28ce3531dd)],
    );
}

/// A tiny emulator of `model` trained by `method` (a few iterations on a few hundred
/// examples): sampling (start states, control processes, the frame transforms), weight
/// initialization, the batch and single-example kernels, the trainers and, with `rollout`, the
/// k-step fine-tuning; `noise` exercises the normal draws of the input noise.
fn tiny_spec(model: NetModel, method: TrainMethod, noise: f64, rollout: bool) -> BuildSpec {
    BuildSpec {
        net: NetSpec {
            model,
            hidden: 12,
            examples: 300,
            method,
            physical_dt: 0.01,
            input_noise: None,
            anchor: false,
            normalization: Default::default(),
            transforms: Default::default(),
            data: Default::default(),
        },
        steps: 10,
        settings: TrainSettings {
            held_out_fraction: 0.25,
            cg_max_iters: 25,
            max_epochs: 4,
            patience: 100,
            min_improvement: 1e-4,
            learning_rate: 0.05,
            momentum: 0.9,
            batch_size: 30,
            input_noise: noise,
            rollout_k: if rollout { 3 } else { 0 },
            rollout_weight: if rollout { 1.0 } else { 0.0 },
            rollout_iters: if rollout { 5 } else { 0 },
        },
        seed: 60,
    }
}

#[test]
fn tiny_emulators_train_and_roll_out_with_their_bits() {
    let cases = [
        (
            "truck_lbfgs_rollout",
            NetModel::Truck,
            TrainMethod::Lbfgs,
            0.0,
            true,
        ),
        ("lander_cg", NetModel::Lander, TrainMethod::Cg, 0.0, false),
        (
            "pendulum_active_momentum_noise",
            NetModel::PendulumActive,
            TrainMethod::Momentum,
            0.05,
            false,
        ),
    ];
    let mut got = Vec::new();
    for (name, model, method, noise, rollout) in cases {
        let trained = train_emulator(&tiny_spec(model, method, noise, rollout)).unwrap();
        let e = &trained.emulator;
        let mut h = Fnv::new();
        h.all(e.mlp().weights());
        h.add(trained.train_error);
        h.add(trained.heldout_error);
        let weights = h.0;
        // 40 super-steps from a drawn start under a pattern of controls within the limits.
        let mut x = model.start_state(&mut rand_chacha::ChaCha8Rng::seed_from_u64(7));
        let limits = model.control_limits();
        let (mut next, mut scratch) = (vec![0.0; x.len()], e.scratch());
        let mut u = vec![0.0; model.control_dim()];
        let mut h = Fnv::new();
        for k in 0..40 {
            for (j, u) in u.iter_mut().enumerate() {
                let (lo, hi) = (limits.low[j], limits.high[j]);
                *u = lo + (hi - lo) * (0.5 + 0.5 * pattern(k, j, 1.0));
            }
            e.predict(&x, &u, &mut scratch, &mut next);
            x.copy_from_slice(&next);
            h.all(&x);
        }
        got.push((format!("{name}_weights"), weights));
        got.push((format!("{name}_rollout"), h.0));
    }
    check(
        &got,
        &[
            ("truck_lbfgs_rollout_weights", 0x030da68297953824),
            ("truck_lbfgs_rollout_rollout", 0xce5ae43ac20c66ce),
            ("lander_cg_weights", 0xb1fe4070ca53806a),
            ("lander_cg_rollout", 0x682c6ec8049015ad),
            ("pendulum_active_momentum_noise_weights", 0x4835f27dcd1e567a),
            ("pendulum_active_momentum_noise_rollout", 0x442c179db04f6e82),
        ],
    );
}
