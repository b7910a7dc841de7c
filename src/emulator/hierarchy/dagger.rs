//! # DAgger for the dolphin's global net
//!
//! Swim controllers are learned through the global net alone (§6), so that is the net whose
//! errors steer them wrong, and the one data aggregation refines ([`crate::emulator::dagger`]
//! has the method). The simulator runs in the 138-variable mass state; the global net's
//! examples are its segment frames. [`global_visits`] maps a round's mass-state visits to
//! global-state visits exactly as the training data are mapped ([`super::global_transitions`]:
//! the start frames as [`global_state`] writes them, the next frames signed to agree with the
//! start's), and each k-step window to a chain of frames whose quaternion signs follow the
//! window's own previous step ([`global_state_after`]), as the net's own rollout does.
//! [`load_derived`] / [`store_derived`] keep the fine-tuned nets in the emulator cache under
//! the base net's key and what derived them.

use super::training::{cache_key, global_emulator, net_name, shape, HierarchySpec};
use super::{global_state, global_state_after, global_transitions, GLOBAL_DIM, MASS_DIM};
use crate::emulator::cache::{fnv1a, read_record, write_record, EmulatorCache, NetRecord};
use crate::emulator::catalog::BuildError;
use crate::emulator::dagger::Visits;
use crate::emulator::dataset::Windows;
use crate::emulator::Emulator;
use crate::physics::dolphin::Dolphin;
use std::path::PathBuf;

/// The global-state visits of mass-state `visits` (see the module docs).
///
/// # Panics
/// When `visits` are not mass-state visits of the dolphin.
pub fn global_visits(d: &Dolphin, visits: &Visits) -> Visits {
    assert_eq!(visits.state_dim, MASS_DIM, "mass-state visits");
    let (m, k) = (visits.control_dim, visits.windows.k);
    let mut out = Visits::empty(GLOBAL_DIM, m, k);
    if !visits.is_empty() {
        let t = global_transitions(d, &visits.transitions());
        let flat = |a: &ndarray::Array2<f64>| a.iter().copied().collect::<Vec<f64>>();
        out.states = flat(&t.states);
        out.controls = flat(&t.controls);
        out.next_states = flat(&t.next_states);
    }
    out.windows = global_windows(d, &visits.windows);
    out
}

/// The global-state chains of mass-state windows `w`: each window's first state as
/// [`global_state`] writes it, every later one with its quaternion signs following the
/// window's own previous step ([`global_state_after`]), as the net's own rollout continues them.
///
/// # Panics
/// When `w` are not mass-state windows of the dolphin.
pub fn global_windows(d: &Dolphin, w: &Windows) -> Windows {
    assert_eq!(w.state_dim, MASS_DIM, "mass-state windows");
    let k = w.k;
    let mut states = Vec::with_capacity(w.len() * (k + 1) * GLOBAL_DIM);
    let (mut g, mut prev) = (vec![0.0; GLOBAL_DIM], vec![0.0; GLOBAL_DIM]);
    for win in w.states.chunks_exact((k + 1) * MASS_DIM) {
        let mut steps = win.chunks_exact(MASS_DIM);
        global_state(d, steps.next().expect("k + 1 states"), &mut g);
        states.extend_from_slice(&g);
        for x in steps {
            std::mem::swap(&mut g, &mut prev);
            global_state_after(d, x, &prev, &mut g);
            states.extend_from_slice(&g);
        }
    }
    Windows {
        k,
        state_dim: GLOBAL_DIM,
        control_dim: w.control_dim,
        states,
        controls: w.controls.clone(),
        episode: w.episode.clone(),
        start_step: w.start_step.clone(),
    }
}

fn derived_key(spec: &HierarchySpec, d: &Dolphin, derived: &serde_json::Value) -> String {
    serde_json::json!({ "base": cache_key(spec, d, 0), "derived": derived }).to_string()
}

fn derived_path(cache: &EmulatorCache, spec: &HierarchySpec, key: &str) -> PathBuf {
    cache.dir.join(format!(
        "{}-n{}-dagger-{:016x}.json",
        net_name(0),
        spec.steps,
        fnv1a(key.as_bytes())
    ))
}

/// The name of the file that holds (or would hold) the global net derived from `spec`'s
/// under `derived`.
pub fn derived_file_name(
    cache: &EmulatorCache,
    spec: &HierarchySpec,
    d: &Dolphin,
    derived: &serde_json::Value,
) -> String {
    let path = derived_path(cache, spec, &derived_key(spec, d, derived));
    path.file_name()
        .map_or(String::new(), |f| f.to_string_lossy().into_owned())
}

/// The cached global net derived from `spec`'s under `derived`, with its record.
pub fn load_derived(
    cache: &EmulatorCache,
    spec: &HierarchySpec,
    d: &Dolphin,
    derived: &serde_json::Value,
) -> Option<(Emulator, NetRecord)> {
    let key = derived_key(spec, d, derived);
    let rec = read_record(&derived_path(cache, spec, &key), &key, shape(spec, 0))?;
    let emulator = global_emulator(spec, rec.clone()).ok()?;
    Some((emulator, rec))
}

/// Stores `rec` as the global net derived from `spec`'s under `derived` (atomically).
pub fn store_derived(
    cache: &EmulatorCache,
    spec: &HierarchySpec,
    d: &Dolphin,
    derived: &serde_json::Value,
    rec: &NetRecord,
) -> Result<PathBuf, BuildError> {
    let key = derived_key(spec, d, derived);
    let path = derived_path(cache, spec, &key);
    write_record(&path, &key, rec)?;
    Ok(path)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::emulator::dagger::{collect, DaggerSettings, Plan};
    use crate::emulator::hierarchy::{control_limits, simulator};
    use crate::physics::dolphin::N_SEGMENTS;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    /// Global visits are the frames of true simulator steps: every one-step example's start
    /// is the global state of a visited mass state, its target continues it without a
    /// quaternion sign jump, and every window is a sign-continuous chain whose steps are the
    /// one-step examples' (up to the chain's signs).
    #[test]
    fn global_visits_are_sign_continuous_frames_of_simulator_steps() {
        let d = Dolphin::default();
        let x0 = d.rest_state();
        let steps = 6;
        let controls: Vec<f64> = (0..steps * N_SEGMENTS)
            .map(|i| (0.7 * i as f64).sin())
            .collect();
        let limits = control_limits();
        let neutral = vec![0.0; N_SEGMENTS];
        let plan = Plan {
            x0: &x0,
            controls: &controls,
            neutral: &neutral,
            limits: &limits,
            physical_dt: 0.002,
            substeps: 50,
        };
        let settings = DaggerSettings {
            rounds: 1,
            perturbations: 1,
            perturbed_rollouts: 1,
            control_noise: 0.1,
            iters: 1,
            rollout_k: 0,
            rollout_weight: 0.0,
        };
        let mut sim = simulator(&d);
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let (train, _) = collect(&mut sim, &plan, &settings, 3, true, &mut rng).unwrap();
        let g = global_visits(&d, &train);
        assert_eq!(g.len(), train.len());
        assert_eq!(g.windows.len(), train.windows.len());
        assert_eq!(g.windows.states.len(), g.windows.len() * 4 * GLOBAL_DIM);
        let mut expect = vec![0.0; GLOBAL_DIM];
        for r in 0..train.len() {
            let x = &train.states[r * MASS_DIM..(r + 1) * MASS_DIM];
            global_state(&d, x, &mut expect);
            assert_eq!(&g.states[r * GLOBAL_DIM..(r + 1) * GLOBAL_DIM], &expect[..]);
            let (s, n) = (
                &g.states[r * GLOBAL_DIM..(r + 1) * GLOBAL_DIM],
                &g.next_states[r * GLOBAL_DIM..(r + 1) * GLOBAL_DIM],
            );
            for seg in 0..N_SEGMENTS {
                let q = 13 * seg + 3;
                let dot: f64 = (0..4).map(|j| s[q + j] * n[q + j]).sum();
                assert!(dot > 0.0, "example {r} segment {seg}: sign jump");
            }
        }
        for win in g.windows.states.chunks_exact(4 * GLOBAL_DIM) {
            for pair in win.windows(2 * GLOBAL_DIM).step_by(GLOBAL_DIM) {
                let (a, b) = pair.split_at(GLOBAL_DIM);
                for seg in 0..N_SEGMENTS {
                    let q = 13 * seg + 3;
                    let dot: f64 = (0..4).map(|j| a[q + j] * b[q + j]).sum();
                    assert!(dot > 0.0, "window sign jump in segment {seg}");
                }
            }
        }
        // The first window is the learned rollout's first k + 1 states.
        global_state(&d, &x0, &mut expect);
        assert_eq!(&g.windows.states[..GLOBAL_DIM], &expect[..]);
        assert_eq!(g.windows.controls, train.windows.controls);
    }
}
