//! Throughput of the hot loops, as `motionlab bench` and `cargo bench` report it.
//!
//! Each metric is a dotted name with its unit in the name (`sim.pendulum3.steps_per_s`) and is
//! measured by repeating the loop for at least `min_seconds` of wall time. Later models and
//! algorithms add their loops to [`metrics`].

use crate::bellman::projection::{project, GaussianReward};
use crate::physics::acrobot::Acrobot;
use crate::physics::lattice::{Lattice, LatticeModel, LatticeSim, LOW_GRAVITY};
use crate::physics::pendulum::{Pendulum3, PendulumVariant};
use crate::physics::{Dynamics, IntegratorKind, Simulator};
use crate::synthesis::controller::SimSetup;
use crate::synthesis::hill_climb::init_rng;
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
