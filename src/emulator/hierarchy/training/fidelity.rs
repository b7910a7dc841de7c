//! Fidelity of the trained hierarchy: multi-step rollout errors against the simulator
//! ([`hierarchy_rollout_error`]) and the global net's held-out error per output.

use super::super::{global_state, global_state_after, DolphinEmulator, GLOBAL_DIM, MASS_DIM};
use super::sampling::{
    control_limits, control_process, global_transitions, sample_dolphin, simulator, start_state,
};
use super::HierarchySpec;
use crate::emulator::catalog::{rollout_errors, BuildError};
use crate::emulator::dataset::{draw_lag, run_signal, ControlSignal};
use crate::physics::dolphin::N_SEGMENTS;
use crate::physics::Dynamics;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

/// Multi-step fidelity of the trained hierarchy (as [`crate::emulator::catalog::rollout_error`]
/// for the catalog nets): from `episodes` start states drawn as the training examples' states
/// are (a stream of its own: an episode start, then one lag under the episode's signal), the
/// simulator, the global net alone (fed its own outputs) and the composed hierarchy
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
    let mut sim = simulator(d);
    let mut hsc = emulator.scratch();
    let mut u = vec![0.0; N_SEGMENTS];
    let (mut gt, mut ge, mut mt, mut me) = (vec![], vec![], vec![], vec![]);
    let (mut g_sim, mut g_emu) = (vec![0.0; GLOBAL_DIM], vec![0.0; GLOBAL_DIM]);
    let (mut g_next, mut x_next) = (vec![0.0; GLOBAL_DIM], vec![0.0; MASS_DIM]);
    let dt = spec.physical_dt;
    for _ in 0..episodes {
        let mut x0 = start_state(d, &mut rng);
        let lag = draw_lag(spec.steps, &mut rng);
        let signal = ControlSignal::sample(
            control_process(),
            &control_limits(),
            (lag + horizon * spec.steps) as f64 * dt,
            &mut rng,
        );
        run_signal(&mut sim, &mut x0, &signal, &mut u, 0..lag, dt);
        crate::physics::check_finite("dolphin", lag, lag as f64 * dt, &x0)?;
        let (mut xs, mut xe) = (x0.clone(), x0);
        global_state(d, &xs, &mut g_sim);
        g_emu.copy_from_slice(&g_sim);
        for k in 0..horizon {
            let at = lag + k * spec.steps;
            signal.at(at as f64 * dt, &mut u);
            for i in 0..spec.steps {
                sim.step(&mut xs, &u, dt);
                let step = at + i + 1;
                crate::physics::check_finite("dolphin", step, step as f64 * dt, &xs)?;
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
