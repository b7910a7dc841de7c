//! # Neural-network emulators (NeuroAnimator)
//!
//! An emulator replaces n steps δt of a physical simulator by one "super timestep"
//! Δt = n·δt of a trained network (Grzeszczuk, Terzopoulos, Hinton 1998, §3, eq. 9):
//!
//! ```text
//! s_{t+Δt} = N_Φ[s_t, u_t]
//! ```
//!
//! [`Emulator`] composes the fixed transforms of Fig. 6(c) ([`Transforms`]: local frame,
//! normalization, state change; see [`transform`]) around a three-layer perceptron
//! ([`mlp::Mlp`]). It implements [`crate::physics::Dynamics`], so controllers run unchanged on an
//! emulator or on the simulator, and [`crate::physics::DifferentiableStep`]: the
//! vector–Jacobian product of one step with respect to state and control that backpropagation
//! through time needs (§4.3).
//!
//! Training data are simulated transitions ([`Transitions`]) mapped through the inverse output
//! transforms into network space (Fig. 9, [`Transforms::encode`]); [`train`] fits the weights
//! by conjugate gradient / L-BFGS (small nets) or momentum mini-batches (large nets), §3.5.
//!
//! External forces f_t (§3.1) are treated as extra control inputs: put them after the controls.
//!
//! The emulator type is in `model`, its [`crate::physics::Dynamics`] and
//! [`crate::physics::DifferentiableStep`] implementations in `dynamics`, the step and its
//! vector–Jacobian product through transforms and network in `step`, and the batched steps of
//! many rollouts in `many`.

pub mod anchor;
pub mod cache;
pub mod catalog;
pub mod dagger;
pub mod dataset;
mod dynamics;
pub mod hierarchy;
mod many;
pub mod mlp;
mod model;
pub mod rollout;
mod step;
pub mod train;
pub mod transform;

pub(crate) use many::{steps_many, vjps_many, ManyScratch};
pub use model::Emulator;
use ndarray::Array2;
pub use step::{predict_with, step_vjp, EmulatorScratch};
pub use transform::{TransformConfig, Transforms};

/// Errors of emulator construction and training.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum EmulatorError {
    /// A vector or matrix has the wrong size.
    #[error("{what}: expected size {expected}, got {got}")]
    Dimension {
        /// What was measured.
        what: &'static str,
        /// Expected size.
        expected: usize,
        /// Actual size.
        got: usize,
    },
    /// A state index of a local frame is out of range.
    #[error("state index {index} out of range for state dimension {dim}")]
    Index {
        /// The bad index.
        index: usize,
        /// The state dimension.
        dim: usize,
    },
    /// A state index appears twice in a local frame.
    #[error("state index {0} is listed twice in the local frame")]
    DuplicateIndex(usize),
    /// Too few examples to fit statistics or to train.
    #[error("need at least 2 examples, got {0}")]
    TooFewExamples(usize),
    /// The super timestep is not positive and finite.
    #[error("super timestep must be positive and finite, got {0}")]
    TimeStep(f64),
    /// A training setting is out of range.
    #[error("invalid training setting `{name}` = {value}")]
    Setting {
        /// Setting name.
        name: &'static str,
        /// Its value.
        value: f64,
    },
    /// The optimizer reported an error.
    #[error("optimizer failed: {0}")]
    Optimizer(String),
}

/// Simulated state transitions (s, u) → s' over one super timestep, one per row (§3.4).
#[derive(Debug, Clone, PartialEq)]
pub struct Transitions {
    /// States s_t, N × state_dim.
    pub states: Array2<f64>,
    /// Controls (and external forces) u_t, N × control_dim.
    pub controls: Array2<f64>,
    /// Next states s_{t+Δt}, N × state_dim.
    pub next_states: Array2<f64>,
}

impl Transitions {
    /// Checks that the three tables agree in rows and state columns.
    pub fn new(
        states: Array2<f64>,
        controls: Array2<f64>,
        next_states: Array2<f64>,
    ) -> Result<Self, EmulatorError> {
        let n = states.nrows();
        for (what, got) in [
            ("control rows", controls.nrows()),
            ("next-state rows", next_states.nrows()),
        ] {
            if got != n {
                return Err(EmulatorError::Dimension {
                    what,
                    expected: n,
                    got,
                });
            }
        }
        if next_states.ncols() != states.ncols() {
            return Err(EmulatorError::Dimension {
                what: "next-state columns",
                expected: states.ncols(),
                got: next_states.ncols(),
            });
        }
        Ok(Self {
            states,
            controls,
            next_states,
        })
    }

    /// Number of transitions.
    pub fn len(&self) -> usize {
        self.states.nrows()
    }

    /// Whether there are none.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

#[cfg(test)]
mod tests {
    use super::mlp::{Mlp, WeightInit};
    use super::train::{
        mse, train_full_batch, train_momentum, Dataset, FullBatchConfig, FullBatchMethod,
        MomentumConfig, StopReason, TrainingProblem,
    };
    use super::*;
    use crate::physics::Dynamics;
    use argmin::core::{CostFunction, Gradient};
    use ndarray::Array1;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;
    use transform::{FrameMap, PlanarFrame};

    const N: usize = 6;
    const M: usize = 2;

    /// A made-up planar rigid body: x, y, θ, vx, vy, ω; controls: thrust, torque.
    fn fake_body(s: &[f64], u: &[f64]) -> Vec<f64> {
        let dt = 0.1;
        let (sn, c) = s[2].sin_cos();
        vec![
            s[0] + dt * s[3],
            s[1] + dt * s[4],
            s[2] + dt * s[5],
            s[3] + dt * (u[0] * c - 0.3 * s[3]),
            s[4] + dt * (u[0] * sn - 0.3 * s[4]),
            s[5] + dt * (u[1] - 0.5 * s[5]),
        ]
    }

    fn body_transitions(rows: usize, seed: u64) -> Transitions {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let states = Array2::from_shape_fn((rows, N), |(_, c)| {
            rng.random_range(-1.0..1.0) * [20.0, 20.0, 3.0, 2.0, 2.0, 1.0][c]
        });
        let controls = Array2::from_shape_fn((rows, M), |_| rng.random_range(-1.0..1.0));
        let mut next = Array2::zeros((rows, N));
        for r in 0..rows {
            let s1 = fake_body(
                states.row(r).as_slice().unwrap(),
                controls.row(r).as_slice().unwrap(),
            );
            next.row_mut(r).assign(&Array1::from(s1));
        }
        Transitions::new(states, controls, next).unwrap()
    }

    fn config(delta: bool) -> TransformConfig {
        TransformConfig {
            delta,
            frame: Some(PlanarFrame::rigid_body(0, 1, 2, 3, 4).into()),
            normalize: true,
            input_groups: Some(vec![0, 0, 1, 2, 2, 3, 4, 5]),
            output_groups: None,
        }
    }

    fn random_mlp(n_in: usize, n_out: usize) -> Mlp {
        let mut rng = ChaCha8Rng::seed_from_u64(2);
        let init = WeightInit::Uniform {
            low: -1.0,
            high: 1.0,
        };
        Mlp::new(n_in, 7, n_out, init, &mut rng)
    }

    fn emulator(delta: bool) -> (Emulator, Transitions) {
        let data = body_transitions(200, 1);
        let t = Transforms::fit(&config(delta), &data).unwrap();
        (Emulator::new(t, random_mlp(N + M, N), 0.1).unwrap(), data)
    }

    /// A 3D rigid body (position, quaternion, velocity, angular velocity; 2 controls) with
    /// made-up transitions; the quaternions are deliberately not exactly unit.
    fn spatial_emulator(delta: bool) -> (Emulator, Transitions) {
        let mut rng = ChaCha8Rng::seed_from_u64(4);
        let rows = 100;
        let states = Array2::from_shape_fn((rows, 13), |(_, c)| match c {
            0..=2 => rng.random_range(-10.0..10.0),
            3..=6 => rng.random_range(-1.0..1.0),
            _ => rng.random_range(-2.0..2.0),
        });
        let controls = Array2::from_shape_fn((rows, 2), |_| rng.random_range(-1.0..1.0));
        let next = &states + &Array2::from_shape_fn((rows, 13), |_| rng.random_range(-0.1..0.1));
        let data = Transitions::new(states, controls, next).unwrap();
        let config = TransformConfig {
            delta,
            frame: Some(transform::SpatialFrame::rigid_body(0, 3, 7, 10).into()),
            normalize: true,
            input_groups: None,
            output_groups: Some(vec![0, 0, 0, 1, 1, 1, 1, 2, 2, 2, 3, 3, 3]),
        };
        let t = Transforms::fit(&config, &data).unwrap();
        (Emulator::new(t, random_mlp(15, 13), 0.1).unwrap(), data)
    }

    fn all_emulators() -> Vec<(&'static str, Emulator, Transitions)> {
        let mut out = Vec::new();
        for delta in [true, false] {
            let (e, d) = emulator(delta);
            out.push((if delta { "planar delta" } else { "planar" }, e, d));
            let (e, d) = spatial_emulator(delta);
            out.push((if delta { "spatial delta" } else { "spatial" }, e, d));
        }
        let data = body_transitions(100, 3);
        let t = Transforms::fit(&TransformConfig::none(), &data).unwrap();
        let e = Emulator::new(t, random_mlp(N + M, N), 0.1).unwrap();
        out.push(("none", e, data));
        out
    }

    fn same_bits(a: &[f64], b: &[f64]) -> bool {
        a.len() == b.len() && a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits())
    }

    /// The taped step and VJP, and the transforms at a frame read once per step, give bit for
    /// bit what the untaped step and VJP and the transforms reading the frame per map give.
    #[test]
    fn taped_and_frame_sharing_paths_are_bit_identical() {
        use crate::physics::DifferentiableStep;
        let mut emulators = all_emulators();
        let mut heading = transform::SpatialFrame::rigid_body(0, 3, 7, 10);
        heading.attitude = transform::Attitude::Heading;
        let (e, d) = spatial_emulator(true);
        let t = Transforms {
            frame: Some(heading.into()),
            ..e.transforms().clone()
        };
        emulators.push((
            "spatial heading",
            Emulator::new(t, e.mlp().clone(), 0.1).unwrap(),
            d,
        ));
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        for (name, e, data) in &emulators {
            let (n, m) = (e.transforms.state_dim, e.transforms.control_dim);
            let t = &e.transforms;
            let mut sc = e.scratch();
            let mut tape = vec![0.0; e.tape_len()];
            for r in 0..10 {
                let s = data.states.row(r).to_vec();
                let u = data.controls.row(r).to_vec();
                let sb1: Vec<f64> = (0..n).map(|_| rng.random_range(-1.0..1.0)).collect();
                let (mut a, mut b) = (vec![0.0; n], vec![0.0; n]);
                e.predict(&s, &u, &mut sc, &mut a);
                e.step_taped(&s, &u, &mut sc, &mut b, &mut tape);
                assert!(same_bits(&a, &b), "{name}: step");
                let (mut sb_a, mut ub_a) = (vec![0.0; n], vec![0.0; m]);
                let (mut sb_b, mut ub_b) = (vec![1.0; n], vec![1.0; m]);
                e.vjp(&s, &u, &sb1, &mut sc, &mut sb_a, &mut ub_a);
                e.vjp_taped(&s, &u, &tape, &sb1, &mut sc, &mut sb_b, &mut ub_b);
                assert!(
                    same_bits(&sb_a, &sb_b) && same_bits(&ub_a, &ub_b),
                    "{name}: vjp"
                );
                // Each transform with the frame read per map (at = None) and read once.
                for at in [t.frame_at(&s, false), t.frame_at(&s, true)] {
                    let (mut z0, mut z1) = (vec![0.0; n + m], vec![0.0; n + m]);
                    t.encode_input_with(None, &s, &u, &mut z0);
                    t.encode_input_with(at.as_ref(), &s, &u, &mut z1);
                    assert!(same_bits(&z0, &z1), "{name}: encode");
                    let y: Vec<f64> = (0..n).map(|_| rng.random_range(-1.0..1.0)).collect();
                    let mut tmp = vec![0.0; n];
                    let (mut s0, mut s1) = (vec![0.0; n], vec![0.0; n]);
                    t.decode_output_with(None, &s, &y, &mut tmp, &mut s0);
                    t.decode_output_with(at.as_ref(), &s, &y, &mut tmp, &mut s1);
                    assert!(same_bits(&s0, &s1), "{name}: decode");
                    let mut t2 = vec![0.0; n];
                    let (mut yb0, mut yb1) = (vec![0.0; n], vec![0.0; n]);
                    let (mut sb0, mut sb1_) = (vec![0.5; n], vec![0.5; n]);
                    let bufs = (&mut tmp[..], &mut t2[..]);
                    t.decode_output_vjp_with(None, &s, &y, &sb1, bufs, &mut yb0, &mut sb0);
                    let bufs = (&mut tmp[..], &mut t2[..]);
                    t.decode_output_vjp_with(at.as_ref(), &s, &y, &sb1, bufs, &mut yb1, &mut sb1_);
                    assert!(
                        same_bits(&yb0, &yb1) && same_bits(&sb0, &sb1_),
                        "{name}: decode vjp"
                    );
                    let zb: Vec<f64> = (0..n + m).map(|_| rng.random_range(-1.0..1.0)).collect();
                    let (mut ub0, mut ub1) = (vec![0.0; m], vec![0.0; m]);
                    t.encode_input_vjp_with(None, &s, &zb, &mut tmp, &mut sb0, &mut ub0);
                    t.encode_input_vjp_with(at.as_ref(), &s, &zb, &mut tmp, &mut sb1_, &mut ub1);
                    assert!(
                        same_bits(&ub0, &ub1) && same_bits(&sb0, &sb1_),
                        "{name}: encode vjp"
                    );
                }
            }
        }
    }

    /// [`fake_body`] as a simulator (one call = one 0.1 s step, whatever `dt`).
    struct FakeBody;

    impl Dynamics for FakeBody {
        fn state_dim(&self) -> usize {
            N
        }
        fn control_dim(&self) -> usize {
            M
        }
        fn step(&mut self, x: &mut [f64], u: &[f64], _dt: f64) {
            let next = fake_body(x, u);
            x.copy_from_slice(&next);
        }
    }

    fn body_start(r: &mut ChaCha8Rng) -> Vec<f64> {
        (0..N)
            .map(|c| r.random_range(-1.0..1.0) * [20.0, 20.0, 3.0, 2.0, 2.0, 1.0][c])
            .collect()
    }

    /// Sampling of `count` windows of `k` super-steps of one fake-body step each,
    /// piecewise-constant controls.
    fn body_sampling(count: usize, k: usize) -> dataset::SamplingConfig {
        dataset::SamplingConfig {
            dt: 0.1,
            steps_per_sample: 1,
            examples: count,
            episode_duration: 0.1 * (k + 6) as f64,
            control: dataset::ControlProcess::PiecewiseConstant {
                hold_min: 0.3,
                hold_max: 1.0,
                idle: 0.0,
                idle_first: 0.0,
            },
        }
    }

    fn body_windows(count: usize, k: usize, seed: u64) -> dataset::Windows {
        dataset::sample_windows(
            &mut FakeBody,
            &body_start,
            &dataset::ControlLimits::symmetric(&[1.0, 1.0]),
            &body_sampling(count, k),
            k,
            &mut ChaCha8Rng::seed_from_u64(seed),
        )
        .unwrap()
    }

    #[test]
    fn windows_are_consecutive_super_steps_with_held_controls() {
        let w = body_windows(20, 4, 1);
        assert_eq!(w.len(), 20);
        for r in 0..w.len() {
            for j in 0..4 {
                let mut x = w.state(r, j).to_vec();
                x = fake_body(&x, w.control(r, j));
                assert_eq!(x, w.state(r, j + 1), "window {r} step {j}");
            }
        }
        // k = 1 windows are the one-step examples, drawn from the same stream.
        let one = body_windows(30, 1, 5);
        let t = dataset::sample_transitions(
            &mut FakeBody,
            &body_start,
            &dataset::ControlLimits::symmetric(&[1.0, 1.0]),
            &body_sampling(30, 1),
            &mut ChaCha8Rng::seed_from_u64(5),
        )
        .unwrap()
        .transitions;
        for r in 0..30 {
            assert_eq!(t.states.row(r).to_vec(), one.state(r, 0));
            assert_eq!(t.next_states.row(r).to_vec(), one.state(r, 1));
            assert_eq!(t.controls.row(r).to_vec(), one.control(r, 0));
        }
    }

    #[test]
    fn rollout_loss_gradient_matches_finite_differences() {
        // Backpropagation through 4 chained steps of a planar-frame, state-change emulator:
        // the output of each step goes back through the local frame and normalization.
        let (e, data) = emulator(true);
        let w = body_windows(6, 4, 2);
        let sigma = rollout::change_spread(&data);
        let loss = rollout::RolloutLoss::new(e.transforms(), &w, &sigma).unwrap();
        let mut net = e.mlp().clone();
        // Small weights keep the random net's rollout in a sane range.
        net.weights_mut().iter_mut().for_each(|v| *v *= 0.3);
        let mut g = vec![0.0; net.n_weights()];
        let value = loss.value_grad(&net, &mut g);
        assert_eq!(value, loss.value(&net));
        assert!(value.is_finite() && value > 0.0);
        let h = 1e-6;
        for (k, gk) in g.iter().enumerate() {
            let (mut p, mut m) = (net.clone(), net.clone());
            p.weights_mut()[k] += h;
            m.weights_mut()[k] -= h;
            let fd = (loss.value(&p) - loss.value(&m)) / (2.0 * h);
            assert!(
                (fd - gk).abs() < 1e-5 * (1.0 + fd.abs()),
                "w{k}: {fd} vs {gk}"
            );
        }
    }

    /// The rollout loss runs the windows of a chunk through each step together and adds its
    /// weight-gradient terms in one batch per chunk: the bits of running each window alone and
    /// adding each term at once, during the backward pass through every window (the oracle
    /// below, one [`predict_with`] and one [`step_vjp`] per step), for the loss and its
    /// gradient, for windows filling one chunk, several chunks, and a partial last chunk,
    /// through a planar frame and a spatial one (with and without the heading attitude, the
    /// dolphin's frames).
    #[test]
    fn rollout_loss_and_gradient_are_the_one_window_at_a_time_sums_bit_for_bit() {
        let (planar, data) = emulator(true);
        // 20 hidden units, so that the output layer's gradient fills whole register tiles
        // (3 rows × 16 columns) as well as edge ones.
        let init = WeightInit::Uniform {
            low: -1.0,
            high: 1.0,
        };
        let mut net = Mlp::new(N + M, 20, N, init, &mut ChaCha8Rng::seed_from_u64(8));
        net.weights_mut().iter_mut().for_each(|v| *v *= 0.3);
        let planar_sigma = rollout::change_spread(&data);
        let (spatial, sdata) = spatial_emulator(true);
        let mut heading = transform::SpatialFrame::rigid_body(0, 3, 7, 10);
        heading.attitude = transform::Attitude::Heading;
        let heading_t = Transforms {
            frame: Some(heading.into()),
            ..spatial.transforms().clone()
        };
        let spatial_sigma = rollout::change_spread(&sdata);
        let mut snet = spatial.mlp().clone();
        snet.weights_mut().iter_mut().for_each(|v| *v *= 0.3);
        // Windows of the 3D body: random states near its data's (not a simulation: the loss
        // and its gradient are defined for any targets).
        let spatial_windows = |count: usize, k: usize| {
            let mut rng = ChaCha8Rng::seed_from_u64(40 + count as u64);
            let mut states = Vec::new();
            for _ in 0..count * (k + 1) {
                let r = rng.random_range(0..sdata.states.nrows());
                for v in sdata.states.row(r) {
                    states.push(v + rng.random_range(-0.05..0.05));
                }
            }
            let controls = (0..count * k * 2)
                .map(|_| rng.random_range(-1.0..1.0))
                .collect();
            dataset::Windows {
                k,
                state_dim: 13,
                control_dim: 2,
                states,
                controls,
                episode: vec![0; count],
                start_step: vec![0; count],
            }
        };
        // The larger body first, on one thread: the smaller then runs in buffers a larger
        // net's chunks left behind (each thread keeps its own).
        let cases: Vec<(&str, &Transforms, &Mlp, &[f64], Vec<dataset::Windows>)> = vec![
            (
                "spatial",
                spatial.transforms(),
                &snet,
                &spatial_sigma,
                [7, 33].map(|c| spatial_windows(c, 3)).to_vec(),
            ),
            (
                "planar",
                planar.transforms(),
                &net,
                &planar_sigma,
                [5, 16, 37].map(|c| body_windows(c, 4, 2)).to_vec(),
            ),
            (
                "spatial heading",
                &heading_t,
                &snet,
                &spatial_sigma,
                [17].map(|c| spatial_windows(c, 5)).to_vec(),
            ),
        ];
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .unwrap();
        pool.install(|| {
            for (name, t, net, sigma, windows) in cases {
                let inv_var: Vec<f64> = sigma.iter().map(|s| 1.0 / (s * s)).collect();
                let (n, m) = (t.state_dim, t.control_dim);
                for w in &windows {
                    let loss = rollout::RolloutLoss::new(t, w, sigma).unwrap();
                    let mut g = vec![0.0; net.n_weights()];
                    let value = loss.value_grad(net, &mut g);
                    assert!(value.is_finite() && value > 0.0);
                    let mut want = vec![0.0; net.n_weights()];
                    let mut total = 0.0;
                    let mut scratch = Emulator::make_scratch(net, n, m);
                    let scale = 1.0 / (w.len() * w.k * n) as f64;
                    for rows in (0..w.len()).collect::<Vec<_>>().chunks(16) {
                        let mut part = vec![0.0; net.n_weights()];
                        let mut part_loss = 0.0;
                        for &r in rows {
                            let mut traj = vec![w.state(r, 0).to_vec()];
                            for i in 0..w.k {
                                let mut next = vec![0.0; n];
                                let u = w.control(r, i);
                                predict_with(t, net, &traj[i], u, &mut scratch, &mut next);
                                for v in 0..n {
                                    part_loss +=
                                        (next[v] - w.state(r, i + 1)[v]).powi(2) * inv_var[v];
                                }
                                traj.push(next);
                            }
                            let (mut next_bar, mut prev_bar, mut u_bar) =
                                (vec![0.0; n], vec![0.0; n], vec![0.0; m]);
                            for i in (1..=w.k).rev() {
                                for v in 0..n {
                                    next_bar[v] +=
                                        2.0 * (traj[i][v] - w.state(r, i)[v]) * inv_var[v];
                                }
                                prev_bar.fill(0.0);
                                step_vjp(
                                    t,
                                    net,
                                    &traj[i - 1],
                                    w.control(r, i - 1),
                                    &next_bar,
                                    &mut scratch,
                                    &mut prev_bar,
                                    &mut u_bar,
                                    Some(&mut part),
                                );
                                std::mem::swap(&mut next_bar, &mut prev_bar);
                            }
                        }
                        total += part_loss;
                        for (o, v) in want.iter_mut().zip(&part) {
                            *o += scale * v;
                        }
                    }
                    let at = format!("{name}, {} windows", w.len());
                    assert_eq!(value.to_bits(), (scale * total).to_bits(), "{at}: loss");
                    assert_eq!(loss.value(net).to_bits(), value.to_bits(), "{at}: value");
                    assert!(same_bits(&g, &want), "{at}: gradient");
                }
            }
        });
    }

    #[test]
    fn rollout_fine_tuning_cuts_the_k_step_error_of_a_one_step_net() {
        // Tiny (5 hidden units) one-step nets of the planar body, trained by L-BFGS until the
        // held-out error stops improving (at most 1500 iterations): the one-step error is
        // spread evenly over the normalized outputs, but velocity errors compound into
        // position over 8 steps. Fine-tuning on the 8-step rollout loss must cut the 8-step
        // error on fresh windows without ruining the one-step fit. How much it can cut
        // depends on where the one-step fit landed: over 12 initial weights the fresh-window
        // ratio (after / before) ran from 0.28 to 1.10, so a single net is a coin flip
        // against any fixed bar. The claim is tested on 8 nets: their median ratio below
        // 0.8 (ours), and none worse than 1.25 (fine-tuning may not help a net whose one-step
        // fit is already good over 8 steps, but early stopping on held-out windows must keep
        // it from hurting much).
        let data = body_transitions(600, 8);
        let t = Transforms::fit(&config(true), &data).unwrap();
        let ds = t.encode(&data);
        let (train, held) = ds.split(0.25, 3).unwrap();
        let sigma = rollout::change_spread(&data);
        let test = body_windows(100, 8, 30);
        let (tw, hw) = (body_windows(150, 8, 31), body_windows(40, 8, 32));
        let mut ratios = vec![];
        for seed in 1..=8 {
            let mut rng = ChaCha8Rng::seed_from_u64(seed);
            let mlp = Mlp::new(N + M, 5, N, WeightInit::FanIn, &mut rng);
            let mut e = Emulator::new(t.clone(), mlp, 0.1).unwrap();
            let config = FullBatchConfig {
                method: FullBatchMethod::Lbfgs { memory: 10 },
                max_iters: 1500,
                patience: 50,
                min_improvement: 1e-4,
            };
            train_full_batch(e.mlp_mut(), &train, &held, &config, None).unwrap();
            let before = rollout::rollout_loss(&e, &test, &sigma).unwrap();
            let one_step_before = mse(e.mlp(), &held);
            rollout::fine_tune(
                &mut e,
                &rollout::FineTune {
                    train: &train,
                    held: &held,
                    train_windows: &tw,
                    held_windows: &hw,
                    sigma: &sigma,
                    weight: 1.0,
                    max_iters: 150,
                    patience: 30,
                    min_improvement: 1e-4,
                    anchor: None,
                },
            )
            .unwrap();
            let after = rollout::rollout_loss(&e, &test, &sigma).unwrap();
            let one_step_after = mse(e.mlp(), &held);
            assert!(
                after < 1.25 * before,
                "seed {seed}: 8-step loss {before} -> {after}"
            );
            assert!(
                one_step_after < 2.0 * one_step_before + 1e-3,
                "seed {seed}: one-step {one_step_before} -> {one_step_after}"
            );
            ratios.push(after / before);
        }
        ratios.sort_by(f64::total_cmp);
        let median = 0.5 * (ratios[3] + ratios[4]);
        assert!(
            median < 0.8,
            "8-step loss ratios after / before: {ratios:?}"
        );
    }

    #[test]
    fn transforms_round_trip_exactly() {
        for (name, e, data) in all_emulators() {
            let (n, m) = (e.state_dim(), e.control_dim());
            let t = e.transforms();
            let mut z = vec![0.0; n + m];
            let mut y = vec![0.0; n];
            let mut tmp = vec![0.0; n];
            let (mut s_back, mut u_back, mut s1_back) = (vec![0.0; n], vec![0.0; m], vec![0.0; n]);
            for r in 0..data.len() {
                let s = data.states.row(r).to_vec();
                let u = data.controls.row(r).to_vec();
                let s1 = data.next_states.row(r).to_vec();
                t.encode_input(&s, &u, &mut z);
                t.decode_input(&s, &z, &mut s_back, &mut u_back);
                t.encode_target(&s, &s1, &mut y);
                t.decode_output(&s, &y, &mut tmp, &mut s1_back);
                for k in 0..n {
                    assert!(
                        (s_back[k] - s[k]).abs() < 1e-12 * (1.0 + s[k].abs()),
                        "{name}"
                    );
                    assert!(
                        (s1_back[k] - s1[k]).abs() < 1e-12 * (1.0 + s1[k].abs()),
                        "{name}"
                    );
                }
                for k in 0..m {
                    assert!((u_back[k] - u[k]).abs() < 1e-12, "{name}");
                }
            }
        }
    }

    #[test]
    fn step_vjp_and_jacobians_match_finite_differences() {
        for (name, e, data) in all_emulators() {
            let (n, m) = (e.state_dim(), e.control_dim());
            let mut sc = e.scratch();
            let s = data.states.row(3).to_vec();
            let u = data.controls.row(3).to_vec();
            let lam: Vec<f64> = (0..n).map(|i| ((i * 7 % 5) as f64 - 2.0) * 0.6).collect();
            let (mut sb, mut ub) = (vec![0.0; n], vec![0.0; m]);
            crate::physics::DifferentiableStep::vjp(&e, &s, &u, &lam, &mut sc, &mut sb, &mut ub);
            let (a, b) = e.jacobians(&s, &u);
            let f = |s: &[f64], u: &[f64]| {
                let mut out = vec![0.0; n];
                e.predict(s, u, &mut e.scratch(), &mut out);
                out
            };
            let h = 1e-6;
            for k in 0..n + m {
                let (mut sp, mut sm, mut up, mut um) = (s.clone(), s.clone(), u.clone(), u.clone());
                if k < n {
                    sp[k] += h;
                    sm[k] -= h;
                } else {
                    up[k - n] += h;
                    um[k - n] -= h;
                }
                let (fp, fm) = (f(&sp, &up), f(&sm, &um));
                let col: Vec<f64> = (0..n).map(|i| (fp[i] - fm[i]) / (2.0 * h)).collect();
                let vjp_fd: f64 = col.iter().zip(&lam).map(|(a, b)| a * b).sum();
                let got = if k < n { sb[k] } else { ub[k - n] };
                assert!(
                    (vjp_fd - got).abs() < 1e-6 * (1.0 + got.abs()),
                    "{name} k {k}: {vjp_fd} vs {got}"
                );
                for i in 0..n {
                    let j = if k < n { a[[i, k]] } else { b[[i, k - n]] };
                    assert!(
                        (col[i] - j).abs() < 1e-6 * (1.0 + j.abs()),
                        "{name} J[{i},{k}]"
                    );
                }
            }
        }
    }

    #[test]
    fn weight_gradient_through_transformed_data_matches_finite_differences() {
        let (e, data) = emulator(true);
        let ds = e.transforms().encode(&data);
        let problem = TrainingProblem::new(e.mlp(), &ds);
        let w = Array1::from(e.mlp().weights().to_vec());
        let g = problem.gradient(&w).unwrap();
        let h = 1e-6;
        for k in 0..w.len() {
            let (mut wp, mut wm) = (w.clone(), w.clone());
            wp[k] += h;
            wm[k] -= h;
            let fd = (problem.cost(&wp).unwrap() - problem.cost(&wm).unwrap()) / (2.0 * h);
            assert!((fd - g[k]).abs() < 1e-6 * (1.0 + fd.abs()), "w{k}");
        }
    }

    /// The training problem's cost and gradient come from one pass and are kept for the same
    /// weights: the cost is [`mse`] bit for bit, the gradient the separate loss-gradient pass's,
    /// whichever is asked first and after other weights were evaluated in between.
    #[test]
    fn training_problem_cost_and_gradient_are_the_separate_passes_bit_for_bit() {
        let (e, data) = emulator(true);
        let ds = e.transforms().encode(&data);
        let net = e.mlp().clone();
        let w = Array1::from(net.weights().to_vec());
        let mut w2 = w.clone();
        w2[3] += 0.01;
        let mut raw = vec![0.0; net.n_weights()];
        net.loss_grad(ds.inputs.view(), ds.targets.view(), &mut raw);
        let scale = 2.0 / (ds.len() * net.n_out()) as f64;
        let want_g: Vec<u64> = raw.iter().map(|v| (v * scale).to_bits()).collect();
        let want_c = mse(&net, &ds).to_bits();
        let bits = |g: &Array1<f64>| g.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
        let p = TrainingProblem::new(&net, &ds);
        assert_eq!(p.cost(&w).unwrap().to_bits(), want_c);
        assert_eq!(bits(&p.gradient(&w).unwrap()), want_g);
        p.gradient(&w2).unwrap();
        assert_eq!(bits(&p.gradient(&w).unwrap()), want_g);
        assert_eq!(p.cost(&w).unwrap().to_bits(), want_c);
        let q = p.clone();
        assert_eq!(bits(&q.gradient(&w).unwrap()), want_g);
    }

    #[test]
    fn dynamics_step_equals_transforms_and_mlp_by_hand() {
        let (mut e, _) = emulator(true);
        let s = [3.0, -4.0, 0.8, 1.1, -0.6, 0.4];
        let u = [0.5, -0.3];
        let t = e.transforms().clone();
        let frame = PlanarFrame::rigid_body(0, 1, 2, 3, 4);
        assert_eq!(t.frame, Some(frame.clone().into()));
        let pose = frame.pose(&s);
        let mut a = vec![0.0; N + M];
        frame.apply(FrameMap::ToLocal, pose, &s, &mut a[..N]);
        a[N..].copy_from_slice(&u);
        let mut z = vec![0.0; N + M];
        t.input_norm.normalize(&a, &mut z);
        let mut y = vec![0.0; N];
        e.mlp().forward(&z, &mut e.mlp().scratch(), &mut y);
        let mut dl = vec![0.0; N];
        t.output_norm.denormalize(&y, &mut dl);
        let mut dw = vec![0.0; N];
        frame.apply(FrameMap::DeltaToWorld, pose, &dl, &mut dw);
        let mut by_hand = vec![0.0; N];
        transform::delta_forward(&s, &dw, &mut by_hand);
        let mut x = s.to_vec();
        e.step(&mut x, &u, 0.1);
        assert_eq!(x, by_hand);
        assert_eq!(e.state_dim(), N);
        assert_eq!(e.control_dim(), M);
    }

    #[test]
    #[should_panic(expected = "trained for")]
    fn step_rejects_a_different_dt() {
        let (mut e, _) = emulator(true);
        let mut x = vec![0.0; N];
        e.step(&mut x, &[0.0; M], 0.01);
    }

    #[test]
    fn construction_checks_shapes() {
        let data = body_transitions(10, 1);
        let t = Transforms::fit(&config(true), &data).unwrap();
        let mut rng = ChaCha8Rng::seed_from_u64(2);
        let bad = Mlp::new(N, 4, N, WeightInit::FanIn, &mut rng);
        assert!(matches!(
            Emulator::new(t.clone(), bad, 0.1),
            Err(EmulatorError::Dimension { .. })
        ));
        let ok = Mlp::new(N + M, 4, N, WeightInit::FanIn, &mut rng);
        assert_eq!(
            Emulator::new(t, ok, -1.0).unwrap_err(),
            EmulatorError::TimeStep(-1.0)
        );
    }

    /// x_{k+1} = A x_k + B u_k sampled at random states and controls.
    fn linear_system(rows: usize, seed: u64) -> Transitions {
        let a = [[0.9, 0.2], [-0.2, 0.9]];
        let b = [0.0, 0.5];
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let states = Array2::from_shape_fn((rows, 2), |_| rng.random_range(-2.0..2.0));
        let controls = Array2::from_shape_fn((rows, 1), |_| rng.random_range(-1.0..1.0));
        let next = Array2::from_shape_fn((rows, 2), |(r, i)| {
            a[i][0] * states[[r, 0]] + a[i][1] * states[[r, 1]] + b[i] * controls[[r, 0]]
        });
        Transitions::new(states, controls, next).unwrap()
    }

    fn linear_setup() -> (Emulator, Dataset, Dataset, Transitions) {
        let data = linear_system(400, 5);
        let t = Transforms::fit(&TransformConfig::standard(None), &data).unwrap();
        let ds = t.encode(&data);
        let (train, held) = ds.split(0.25, 9).unwrap();
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let mlp = Mlp::new(3, 8, 2, WeightInit::FanIn, &mut rng);
        (
            Emulator::new(t, mlp, 0.1).unwrap(),
            train,
            held,
            linear_system(200, 6),
        )
    }

    #[test]
    fn full_batch_training_learns_a_linear_system() {
        for method in [
            FullBatchMethod::ConjugateGradient { restart_iters: 20 },
            FullBatchMethod::Lbfgs { memory: 10 },
        ] {
            let (mut e, train, held, test) = linear_setup();
            let before = mse(e.mlp(), &held);
            let config = FullBatchConfig {
                method,
                max_iters: 300,
                patience: 20,
                min_improvement: 1e-3,
            };
            let report = train_full_batch(e.mlp_mut(), &train, &held, &config, None).unwrap();
            let after = mse(e.mlp(), &held);
            assert_eq!(after, report.best_held_out_error, "{method:?}");
            assert!(
                after < 1e-3 && after < 1e-2 * before,
                "{method:?}: {before} -> {after} ({:?})",
                report.stop
            );
            assert!(report.trace.len() > 2);
            assert_eq!(report.trace[0].iteration, 0);
            assert!(
                !matches!(report.stop, StopReason::OptimizerFailed(_)),
                "{:?}",
                report.stop
            );
            // Held-out physical error is small compared with the state spread (~1.3).
            assert!(
                e.one_step_error(&test) < 1e-2,
                "{}",
                e.one_step_error(&test)
            );
        }
    }

    #[test]
    fn momentum_training_learns_a_linear_system() {
        let (mut e, train, held, test) = linear_setup();
        let before = mse(e.mlp(), &held);
        let config = MomentumConfig {
            learning_rate: 0.1,
            momentum: 0.9,
            batch_size: 30,
            max_epochs: 150,
            patience: 15,
            min_improvement: 1e-3,
            seed: 3,
        };
        let report = train_momentum(e.mlp_mut(), &train, &held, &config, None).unwrap();
        let after = mse(e.mlp(), &held);
        assert!(
            after < 5e-3 && after < 1e-2 * before,
            "{before} -> {after} ({:?})",
            report.stop
        );
        assert_eq!(report.best_held_out_error, after);
        assert!(
            e.one_step_error(&test) < 5e-2,
            "{}",
            e.one_step_error(&test)
        );
        // Same seed, same result.
        let (mut e2, ..) = linear_setup();
        let report2 = train_momentum(e2.mlp_mut(), &train, &held, &config, None).unwrap();
        assert_eq!(report, report2);
        assert_eq!(e.mlp(), e2.mlp());
    }

    #[test]
    fn training_stops_early_and_keeps_the_best_weights() {
        // Held-out targets are noise unrelated to the inputs: the held-out error cannot keep
        // improving, so both methods must stop on patience well before their limits.
        let (e, train, held, _) = linear_setup();
        let mut rng = ChaCha8Rng::seed_from_u64(21);
        let noise = Dataset::new(
            held.inputs.clone(),
            Array2::from_shape_fn(held.targets.dim(), |_| rng.random_range(-3.0..3.0)),
        )
        .unwrap();
        let mut m1 = e.mlp().clone();
        let config = MomentumConfig {
            max_epochs: 1000,
            patience: 5,
            ..MomentumConfig::default()
        };
        let r1 = train_momentum(&mut m1, &train, &noise, &config, None).unwrap();
        assert_eq!(r1.stop, StopReason::NoImprovement);
        assert!(r1.trace.len() < 1000);
        assert!(r1.trace.len() <= r1.best_iteration + 1 + 5);
        assert_eq!(mse(&m1, &noise), r1.best_held_out_error);
        let mut m2 = e.mlp().clone();
        let config = FullBatchConfig {
            max_iters: 1000,
            patience: 5,
            ..FullBatchConfig::default()
        };
        let r2 = train_full_batch(&mut m2, &train, &noise, &config, None).unwrap();
        assert_eq!(r2.stop, StopReason::NoImprovement);
        assert!(r2.trace.len() < 1000);
        assert_eq!(mse(&m2, &noise), r2.best_held_out_error);
        let best = r2
            .trace
            .iter()
            .map(|p| p.held_out_error)
            .fold(f64::INFINITY, f64::min);
        assert_eq!(best, r2.best_held_out_error);
    }

    #[test]
    fn split_is_deterministic_and_disjoint() {
        let (e, ..) = linear_setup();
        let ds = e.transforms().encode(&linear_system(50, 1));
        let (a, b) = ds.split(0.2, 4).unwrap();
        let (a2, b2) = ds.split(0.2, 4).unwrap();
        assert_eq!((&a, &b), (&a2, &b2));
        assert_eq!((a.len(), b.len()), (40, 10));
        for r in b.inputs.rows() {
            assert!(a.inputs.rows().into_iter().all(|q| q != r));
        }
        assert!(ds.split(1.0, 4).is_err());
    }
}
