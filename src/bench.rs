//! Throughput of the hot loops, as `motionlab bench` and `cargo bench` report it.
//!
//! Each metric is a dotted name with its unit in the name (`sim.pendulum3.steps_per_s`) and is
//! measured by repeating the loop for at least `min_seconds` of wall time. Later models and
//! algorithms add their loops to [`metrics`].

use crate::bellman::projection::{project, GaussianReward};
use crate::control::search::init_rng;
use crate::emulator::catalog::NetModel;
use crate::emulator::mlp::{Mlp, WeightInit};
use crate::emulator::train::{Dataset, MomentumBatches, MomentumState};
use crate::emulator::{Emulator, Transforms};
use crate::physics::acrobot::Acrobot;
use crate::physics::lattice::{Lattice, LatticeModel, LatticeSim, LOW_GRAVITY};
use crate::physics::pendulum::{Pendulum3, PendulumVariant};
use crate::physics::{Dynamics, IntegratorKind, Simulator};
use crate::synthesis::controller::SimSetup;
use crate::synthesis::objective::{Objective, Term, Weighted};
use crate::synthesis::perturb::random_controller;
use crate::synthesis::Problem;
use std::hint::black_box;
use std::time::Instant;

/// One measured metric.
#[derive(Debug, Clone, PartialEq)]
pub struct Metric {
    /// Dotted name with unit, e.g. `sim.pendulum3.steps_per_s`.
    pub name: String,
    /// Value.
    pub value: f64,
}

/// Runs `f` (which does `work` units per call) until `min_seconds` passed; units per second.
pub fn throughput(min_seconds: f64, work: u64, mut f: impl FnMut()) -> f64 {
    f(); // warm-up
    let t0 = Instant::now();
    let mut n = 0u64;
    loop {
        f();
        n += work;
        let dt = t0.elapsed().as_secs_f64();
        if dt >= min_seconds {
            return n as f64 / dt;
        }
    }
}

fn sim_steps<D: Dynamics>(sim: &mut D, x0: &[f64], u: &[f64], dt: f64, steps: usize) {
    let mut x = x0.to_vec();
    for _ in 0..steps {
        sim.step(&mut x, u, dt);
    }
    black_box(&x);
}

/// Every metric, each measured for about `min_seconds`.
pub fn metrics(min_seconds: f64) -> Vec<Metric> {
    let mut out = Vec::new();
    let mut push = |name: &str, value: f64| {
        out.push(Metric {
            name: name.to_string(),
            value,
        })
    };
    let steps = 1000;
    let mut p = Simulator::new(Pendulum3::new(PendulumVariant::Active), IntegratorKind::Rk4);
    let x0 = [0.5, -0.3, 0.2, 0.0, 0.0, 0.0];
    push(
        "sim.pendulum3.steps_per_s",
        throughput(min_seconds, steps as u64, || {
            sim_steps(&mut p, &x0, &[0.1, 0.0, -0.1], 0.01, steps)
        }),
    );
    let mut p = Simulator::new(
        Pendulum3::new(PendulumVariant::Active),
        IntegratorKind::SemiImplicitEuler,
    );
    push(
        "sim.pendulum3.semi_implicit_steps_per_s",
        throughput(min_seconds, steps as u64, || {
            sim_steps(&mut p, &x0, &[0.1, 0.0, -0.1], 0.01, steps)
        }),
    );
    let mut a = Simulator::new(Acrobot::default(), IntegratorKind::Rk4);
    let a0 = [-1.4, 0.1, 0.0, 0.0];
    push(
        "sim.acrobot.steps_per_s",
        throughput(min_seconds, steps as u64, || {
            sim_steps(&mut a, &a0, &[0.5], 0.01, steps)
        }),
    );
    let mut a = Simulator::new(Acrobot::default(), IntegratorKind::Rk45);
    push(
        "sim.acrobot.rk45_outer_steps_per_s",
        throughput(min_seconds, steps as u64, || {
            sim_steps(&mut a, &a0, &[0.5], 0.01, steps)
        }),
    );
    let comps: Vec<GaussianReward> = (0..4)
        .map(|i| GaussianReward::isotropic(&[i as f64, 0.5 * i as f64, 0.0, 1.0], 2.0))
        .collect();
    let desired = GaussianReward::isotropic(&[1.5, 0.7, 0.1, 1.0], 2.0);
    push(
        "lbc.projection_4x4d.solves_per_s",
        throughput(min_seconds, 1, || {
            black_box(project(black_box(&comps), black_box(&desired)).ok());
        }),
    );
    // LBC: DDP iteration, LQR backward pass and blended-policy evaluation on the acrobot
    // swing-up horizon (4 s at 0.01 s).
    {
        use crate::bellman::combine::{BlendMode, TrackerBlend};
        use crate::control::ddp::{solve, DdpOptions};
        use crate::control::lqr::track;
        use crate::control::{QuadraticCost, Rk4Map};
        use nalgebra::{DMatrix, DVector};
        let dt = 0.01;
        let steps = 400;
        let map = Rk4Map::new(Acrobot::default(), dt).expect("valid dt");
        let cost = QuadraticCost::effort(
            dt,
            1,
            DMatrix::from_diagonal(&DVector::from_vec(vec![1e3, 1e3, 1e2, 1e2])),
            DVector::from_vec(vec![std::f64::consts::FRAC_PI_2, 0.0, 0.0, 0.0]),
        );
        let x0 = DVector::from_vec(vec![-std::f64::consts::FRAC_PI_2, 0.0, 0.0, 0.0]);
        let u0: Vec<DVector<f64>> = (0..steps)
            .map(|k| DVector::from_element(1, (k as f64 * dt * 3.0).sin()))
            .collect();
        let one_iter = DdpOptions {
            max_iterations: 1,
            ..DdpOptions::default()
        };
        let ddp_iters = throughput(min_seconds, 1, || {
            black_box(solve(&map, &cost, &x0, &u0, &one_iter).ok());
        });
        push("ddp.acrobot.iters_per_s", ddp_iters);
        // Derived: microseconds per knot of one DDP iteration (the peers' unit). This is a
        // whole one-iteration `solve`: its first rollout and its stopping test's second
        // linearization and backward pass are counted against the one iteration.
        push("ddp.acrobot.us_per_knot", 1e6 / (ddp_iters * steps as f64));
        // The same problem solved for ten iterations (line searches included), the time per
        // knot and iteration: the first rollout and the last stopping test spread over ten.
        let ten = DdpOptions {
            max_iterations: 10,
            ..DdpOptions::default()
        };
        let done = solve(&map, &cost, &x0, &u0, &ten).map_or(0, |s| s.trace.len());
        if done > 0 {
            let solves = throughput(min_seconds, 1, || {
                black_box(solve(&map, &cost, &x0, &u0, &ten).ok());
            });
            push("ddp.acrobot.solves10_per_s", solves);
            push(
                "ddp.acrobot.us_per_knot_iteration",
                1e6 / (solves * (done * steps) as f64),
            );
        }
        let xs = map.rollout(&x0, &u0).expect("finite rollout");
        let lqr_passes = throughput(min_seconds, 1, || {
            black_box(track(&map, &cost, &xs, &u0).ok());
        });
        push("lqr.acrobot.backward_passes_per_s", lqr_passes);
        // Derived: microseconds per Riccati step of the tracker's backward pass.
        push("lqr.acrobot.us_per_step", 1e6 / (lqr_passes * steps as f64));
        // The Riccati recursion alone, on the same trajectory and cost with its A_k, B_k
        // computed beforehand: the problem `../shared/peers/bench_scipy_lqr.py` times in NumPy
        // (compare.py's LQR row times `track`, linearization included).
        {
            use crate::control::lqr::track_linearized;
            let (n, m) = (map.state_dim(), map.control_dim());
            let mut ws = map.workspace();
            let (mut a_k, mut b_k) = (vec![], vec![]);
            for k in 0..steps {
                let (mut a, mut b) = (DMatrix::zeros(n, n), DMatrix::zeros(n, m));
                map.jacobians(&xs[k], &u0[k], &mut a, &mut b, &mut ws);
                a_k.push(a);
                b_k.push(b);
            }
            let riccati_passes = throughput(min_seconds, 1, || {
                let mut given = |k: usize,
                                 _: &DVector<f64>,
                                 _: &DVector<f64>,
                                 a: &mut DMatrix<f64>,
                                 b: &mut DMatrix<f64>| {
                    a.copy_from(&a_k[k]);
                    b.copy_from(&b_k[k]);
                };
                black_box(track_linearized((n, m), &cost, &xs, &u0, &mut given).ok());
            });
            push(
                "lqr.riccati_n4_m1.us_per_step",
                1e6 / (riccati_passes * steps as f64),
            );
        }
        let t = track(&map, &cost, &xs, &u0).expect("tracker");
        let trackers = vec![t.clone(), t];
        let blend = TrackerBlend {
            trackers: &trackers,
            weights: vec![1.0, 1.0],
            lambda: 1.0,
            limits: None,
            mode: BlendMode::Lbc,
        };
        let (mut u, mut a, mut ui) = ([0.0], [0.0; 2], [0.0]);
        let xq = [-1.4, 0.1, 0.2, -0.1];
        push(
            "lbc.acrobot.policy_evals_per_s",
            throughput(min_seconds, steps as u64, || {
                for k in 0..steps {
                    black_box(blend.control(&xq, k, &mut u, &mut a, &mut ui).ok());
                }
            }),
        );
    }
    let mut t = Simulator::new(crate::physics::truck::Truck::default(), IntegratorKind::Rk4);
    let t0 = [0.0, 0.0, 0.3, 4.0, 1.0, 0.1];
    push(
        "sim.truck.steps_per_s",
        throughput(min_seconds, steps as u64, || {
            sim_steps(&mut t, &t0, &[1.0, 0.2], 0.01, steps)
        }),
    );
    let lander = crate::physics::lander::Lander::default();
    let mut l = crate::physics::lander::NormalizedLander::new(lander, IntegratorKind::Rk4);
    let mut l0 = crate::physics::lander::Lander::upright_at_rest([0.0, 0.0, 100.0]).to_vec();
    l0[4] = 0.1;
    l0[crate::physics::lander::VEL] = 1.0;
    push(
        "sim.lander.steps_per_s",
        throughput(min_seconds, steps as u64, || {
            sim_steps(&mut l, &l0, &[4000.0, 10.0, -20.0, 5.0], 0.01, steps)
        }),
    );
    let dolphin = crate::physics::dolphin::Dolphin::default();
    let d0 = dolphin.rest_state();
    let mut d = Simulator::new(dolphin, IntegratorKind::SemiImplicitEuler);
    push(
        "sim.dolphin.steps_per_s",
        throughput(min_seconds, steps as u64, || {
            sim_steps(&mut d, &d0, &[0.5, -0.3, 0.2, 0.8, -0.6, 0.1], 0.002, steps)
        }),
    );
    for (model, hidden, examples) in [
        (NetModel::PendulumPassive, 20, 2400),
        (NetModel::PendulumActive, 20, 3000),
        (NetModel::PendulumExt, 20, 3000),
        (NetModel::Lander, 50, 13500),
        (NetModel::Truck, 40, 5200),
    ] {
        for (name, value) in emulator_metrics(model, hidden, examples, min_seconds) {
            push(&name, value);
        }
    }
    for (name, value) in emulator_rollouts(min_seconds) {
        push(&name, value);
    }
    // The cube lattice under alternating scale_z reflexes (a squash-and-stretch hop): 1000
    // steps of 10 ms, switching every 0.25 s.
    let model = LatticeModel::new(Lattice::cube())
        .expect("cube is valid")
        .with_gravity(LOW_GRAVITY);
    let up = crate::physics::reflex::deform(&model.lattice, 2, 1.0, &model.reflex_gains)
        .expect("valid reflex")
        .rest_lengths;
    let down = crate::physics::reflex::deform(&model.lattice, 2, -1.0, &model.reflex_gains)
        .expect("valid reflex")
        .rest_lengths;
    let x0 = model.lattice.resting_state();
    let mut sim = LatticeSim::new(model.clone());
    push(
        "sim.lattice_cube.steps_per_s",
        throughput(min_seconds, steps as u64, || {
            let mut x = x0.clone();
            for k in 0..steps {
                let u = if (k / 25) % 2 == 0 { &up } else { &down };
                sim.step(&mut x, u, 0.01);
            }
            black_box(&x);
        }),
    );
    // One hill-climbing evaluation: a random 8-regime controller simulated on the cube in
    // low gravity over T = 5 s (sampled at 30 Hz) and scored, as in `ms_poodle_somersault`.
    let problem = Problem {
        setup: SimSetup::new(model, 5.0, 1.0 / 30.0).with_tolerances(1e-4, 1e-6),
        objective: Objective {
            terms: vec![
                Weighted {
                    weight: 1.0,
                    term: Term::MaxHeight,
                },
                Weighted {
                    weight: -0.1,
                    term: Term::ContactTime,
                },
            ],
            contact_height: 0.01,
            frame_masses: [0, 1, 2],
        },
    };
    let controllers: Vec<_> = (0..16)
        .map(|j| random_controller(&mut init_rng(1, j), 8, 5.0))
        .collect();
    let mut j = 0;
    push(
        "hill_climb.cube.evals_per_s",
        throughput(min_seconds, 1, || {
            black_box(problem.evaluate(&controllers[j % controllers.len()]));
            j += 1;
        }),
    );
    push("bptt.lander.iters_per_s", bptt_lander(min_seconds));
    push("bptt.17-50-13.bare.iters_per_s", bptt_bare(min_seconds));
    for (name, value) in fma_peaks(min_seconds) {
        push(&name, value);
    }
    for (name, value) in dolphin_metrics(min_seconds) {
        push(&name, value);
    }
    push("bptt.dolphin.iters_per_s", bptt_dolphin(min_seconds));
    out
}

/// The 17-50-13 net of the BPTT and rollout metrics, random weights drawn from `rng`.
fn net_17_50_13(rng: &mut rand_chacha::ChaCha8Rng) -> Mlp {
    Mlp::new(17, 50, 13, WeightInit::FanIn, rng)
}

/// `mlp` in the lander's transforms (heading frame, normalization, state change).
fn lander_emulator(mlp: Mlp) -> Emulator {
    let model = NetModel::Lander;
    let (n, m) = (model.state_dim(), model.control_dim());
    let transforms =
        Transforms::unfitted(&model.transform_config(), n, m).expect("catalog transforms fit");
    Emulator::new(transforms, mlp, 0.5).expect("shapes agree")
}

/// `mlp` bare, as the peers run it: predicting the state change of 13 states under 4 controls,
/// no frame, no normalization.
fn bare_emulator(mlp: Mlp) -> Emulator {
    use crate::emulator::transform::TransformConfig;
    let config = TransformConfig {
        delta: true,
        ..TransformConfig::none()
    };
    let transforms = Transforms::unfitted(&config, 13, 4).expect("no frame to check");
    Emulator::new(transforms, mlp, 0.5).expect("shapes agree")
}

/// BPTT iterations per second on the lander's Table 1 network shape (17-50-13, random weights,
/// its transforms): a 40-step emulated rollout and the full gradient with respect to the 80
/// control knots, under a soft-landing objective.
fn bptt_lander(min_seconds: f64) -> f64 {
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
    let bounds = Bounds {
        low: limits.low,
        high: limits.high,
    };
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
fn bptt_bare(min_seconds: f64) -> f64 {
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
    let bounds = Bounds {
        low: vec![-1.0; m],
        high: vec![1.0; m],
    };
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

/// The f64 multiply–add throughput of one core (`cpu.fma_f64.<lanes>.gmac_per_s`, 10⁹ per
/// second): 12 independent chains of fused multiply–adds, on 4-lane AVX2 registers (the
/// single-example kernels' lanes) and, where the processor has AVX-512, 8-lane registers
/// (which the batch products' GEMM uses there); none on other processors. The roofline the
/// neural metrics are measured against: `mlp.<shape>.*_gmac_per_s` count a batch example's
/// multiply–adds as 2pq + 3qr (forward pq + qr, backward qr for h̄ and qr + pq for the
/// weight gradient).
fn fma_peaks(min_seconds: f64) -> Vec<(String, f64)> {
    const CHAINS: usize = 12;
    const ITERS: u64 = 100_000;
    let mut out = vec![];
    let mut rate = |name: &str, lanes: usize, run: &dyn Fn(u64) -> f64| {
        let macs = ITERS * (CHAINS * lanes) as u64;
        let per_s = throughput(min_seconds, macs, || {
            black_box(run(black_box(ITERS)));
        });
        out.push((format!("cpu.fma_f64.{name}.gmac_per_s"), per_s / 1e9));
    };
    #[cfg(target_arch = "x86_64")]
    {
        if is_x86_feature_detected!("avx2") && is_x86_feature_detected!("fma") {
            #[target_feature(enable = "avx2,fma")]
            fn chains(iters: u64) -> f64 {
                use std::arch::x86_64::*;
                let (a, b) = (_mm256_set1_pd(0.999_999), _mm256_set1_pd(1e-7));
                let mut acc = [_mm256_set1_pd(0.5); CHAINS];
                for _ in 0..iters {
                    for x in acc.iter_mut() {
                        *x = _mm256_fmadd_pd(*x, a, b);
                    }
                }
                let mut lanes = [0.0; 4];
                let s = acc
                    .iter()
                    .fold(_mm256_set1_pd(0.0), |s, x| _mm256_add_pd(s, *x));
                // SAFETY: four f64 values are written to a 4-value array.
                unsafe { _mm256_storeu_pd(lanes.as_mut_ptr(), s) };
                lanes.iter().sum()
            }
            // SAFETY: the processor has AVX2 and FMA (checked just above).
            rate("avx2", 4, &|iters| unsafe { chains(iters) });
        }
        if is_x86_feature_detected!("avx512f") {
            #[target_feature(enable = "avx512f")]
            fn chains(iters: u64) -> f64 {
                use std::arch::x86_64::*;
                let (a, b) = (_mm512_set1_pd(0.999_999), _mm512_set1_pd(1e-7));
                let mut acc = [_mm512_set1_pd(0.5); CHAINS];
                for _ in 0..iters {
                    for x in acc.iter_mut() {
                        *x = _mm512_fmadd_pd(*x, a, b);
                    }
                }
                let s = acc
                    .iter()
                    .fold(_mm512_set1_pd(0.0), |s, x| _mm512_add_pd(s, *x));
                _mm512_reduce_add_pd(s)
            }
            // SAFETY: the processor has AVX-512F (checked just above).
            rate("avx512", 8, &|iters| unsafe { chains(iters) });
        }
    }
    out
}

/// BPTT iterations per second through the dolphin's global net of the Table 1 shape (84-50-78,
/// random weights, the global transforms): a 40-step emulated swim and the full gradient with
/// respect to the 120 muscle knots (20 per muscle), under the swim objective of `na_swim`.
fn bptt_dolphin(min_seconds: f64) -> f64 {
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
            damping_scale: 1.5,
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
fn dolphin_metrics(min_seconds: f64) -> Vec<(String, f64)> {
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
fn emulator_rollouts(min_seconds: f64) -> Vec<(String, f64)> {
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
/// net and transforms), the loss `fine_tune` minimizes (issue 11): windows are the emulator's
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

fn emulator_metrics(
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

/// The metrics as one JSON object of named numbers.
pub fn to_json(metrics: &[Metric]) -> serde_json::Value {
    serde_json::Value::Object(
        metrics
            .iter()
            .map(|m| (m.name.clone(), serde_json::json!(m.value)))
            .collect(),
    )
}
