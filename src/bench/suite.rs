//! The list of metrics ([`metrics`]): the simulators', solvers' and synthesis loops measured
//! here, the neural, BPTT and processor ones from the sibling modules, in a fixed order.

use super::bptt::{bptt_bare, bptt_dolphin, bptt_lander};
use super::cpu::fma_peaks;
use super::neural::{dolphin_metrics, emulator_metrics, emulator_rollouts};
use super::{throughput, Metric};
use crate::bellman::projection::{project, GaussianReward};
use crate::control::search::init_rng;
use crate::emulator::catalog::NetModel;
use crate::physics::acrobot::Acrobot;
use crate::physics::lattice::{Lattice, LatticeModel, LatticeSim, LOW_GRAVITY};
use crate::physics::pendulum::{Pendulum3, PendulumVariant};
use crate::physics::{Dynamics, IntegratorKind, Simulator};
use crate::synthesis::controller::SimSetup;
use crate::synthesis::objective::{Objective, Term, Weighted};
use crate::synthesis::perturb::random_controller;
use crate::synthesis::Problem;
use std::hint::black_box;

fn sim_steps<D: Dynamics>(sim: &mut D, x0: &[f64], u: &[f64], dt: f64, steps: usize) {
    let mut x = x0.to_vec();
    for _ in 0..steps {
        sim.step(&mut x, u, dt);
    }
    black_box(&x);
}

/// Where a stage hands its measured metrics, in the order measured.
type Push<'a> = &'a mut dyn FnMut(&str, f64);

/// Every metric, each measured for about `min_seconds`.
pub fn metrics(min_seconds: f64) -> Vec<Metric> {
    let mut out = Vec::new();
    let mut push = |name: &str, value: f64| {
        out.push(Metric {
            name: name.to_string(),
            value,
        })
    };
    pendulum_and_acrobot_sims(min_seconds, &mut push);
    lbc_metrics(min_seconds, &mut push);
    truck_lander_dolphin_sims(min_seconds, &mut push);
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
    lattice_metrics(min_seconds, &mut push);
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

/// The pendulum's and the acrobot's simulators, 1000 steps of 10 ms per call.
fn pendulum_and_acrobot_sims(min_seconds: f64, push: Push) {
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
}

/// LBC: the value projection, then DDP iteration, LQR backward pass and blended-policy
/// evaluation on the acrobot swing-up horizon (4 s at 0.01 s).
fn lbc_metrics(min_seconds: f64, push: Push) {
    use crate::bellman::combine::{BlendMode, TrackerBlend};
    use crate::control::ddp::{solve, DdpOptions};
    use crate::control::lqr::track;
    use crate::control::{QuadraticCost, Rk4Map};
    use nalgebra::{DMatrix, DVector};
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

/// The truck's, the lander's and the dolphin's simulators, 1000 steps per call.
fn truck_lander_dolphin_sims(min_seconds: f64, push: Push) {
    let steps = 1000;
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
    leaper3d_metrics(min_seconds, push);
    let dolphin = crate::physics::dolphin::Dolphin::default();
    let d0 = dolphin.rest_state();
    let mut d = Simulator::new(dolphin, IntegratorKind::SemiImplicitEuler);
    push(
        "sim.dolphin.steps_per_s",
        throughput(min_seconds, steps as u64, || {
            sim_steps(&mut d, &d0, &[0.5, -0.3, 0.2, 0.8, -0.6, 0.1], 0.002, steps)
        }),
    );
}

/// The 3-D leaper standing on the penalty ground: its right-hand side, RK4 steps at its
/// default step, and the central-difference Jacobians (A and B, 2(d + m) right-hand sides) a
/// trajectory optimizer would take through [`crate::physics::linearize::FiniteDifference`].
fn leaper3d_metrics(min_seconds: f64, push: Push) {
    use crate::physics::body3d::leaper3d::{leaper3d, standing};
    use crate::physics::linearize::{FiniteDifference, Linearize};
    use crate::physics::{Model, Ode};
    let model = leaper3d();
    let x0 = standing(&model.tree);
    let (d, m) = (model.state_dim(), model.control_dim());
    let u = vec![0.0; m];
    let mut dx = vec![0.0; d];
    let calls = 1000;
    push(
        "sim.leaper3d.derivatives_per_s",
        throughput(min_seconds, calls as u64, || {
            for _ in 0..calls {
                model.derivative(black_box(&x0), &u, &mut dx);
            }
            black_box(&dx);
        }),
    );
    let dt = model.default_dt();
    let mut sim = Simulator::new(model.clone(), IntegratorKind::Rk4);
    let steps = 100;
    push(
        "sim.leaper3d.steps_per_s",
        throughput(min_seconds, steps as u64, || {
            sim_steps(&mut sim, &x0, &u, dt, steps)
        }),
    );
    let fd = FiniteDifference::new(model);
    let (mut a, mut b) = (
        nalgebra::DMatrix::zeros(d, d),
        nalgebra::DMatrix::zeros(d, m),
    );
    push(
        "linearize.leaper3d.fd_jacobians_per_s",
        throughput(min_seconds, 1, || {
            fd.jacobians(black_box(&x0), &u, &mut a, &mut b);
            black_box(&a);
        }),
    );
}

/// The cube lattice's simulator and one hill-climbing evaluation on it.
fn lattice_metrics(min_seconds: f64, push: Push) {
    let steps = 1000;
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
}
