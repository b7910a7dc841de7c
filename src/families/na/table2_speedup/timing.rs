//! The timed loops: physical steps, emulator steps and dolphin emulator steps with their
//! regularization, each the fastest of several repeats.

use crate::emulator::hierarchy::{BoundRegularizer, DolphinEmulator, Schedule};
use crate::emulator::Emulator;
use crate::physics::Dynamics;
use std::hint::black_box;
use std::time::Instant;

/// `u` (rows of `m` controls) with each row repeated `times` times.
pub(super) fn hold(u: &[f64], m: usize, times: usize) -> Vec<f64> {
    u.chunks(m.max(1))
        .flat_map(|r| std::iter::repeat_n(r, times).flatten().copied())
        .collect()
}

/// Fastest of `repeats` runs of `f`, in seconds.
fn best_time(repeats: usize, mut f: impl FnMut()) -> f64 {
    (0..repeats)
        .map(|_| {
            let t0 = Instant::now();
            f();
            t0.elapsed().as_secs_f64()
        })
        .fold(f64::INFINITY, f64::min)
}

/// Seconds for `steps` physical steps of `sim` from `x0` under per-step controls `u` (row-major).
pub(super) fn time_physical(
    sim: &mut dyn Dynamics,
    x0: &[f64],
    u: &[f64],
    dt: f64,
    steps: usize,
    repeats: usize,
) -> f64 {
    let m = sim.control_dim();
    let mut x = x0.to_vec();
    best_time(repeats, || {
        x.copy_from_slice(x0);
        for k in 0..steps {
            sim.step(&mut x, &u[k * m..(k + 1) * m], dt);
        }
        black_box(&x);
    })
}

/// Seconds for `steps` emulator steps from `x0` under per-step controls `u` (row-major).
pub(super) fn time_emulator(
    e: &Emulator,
    x0: &[f64],
    u: &[f64],
    steps: usize,
    repeats: usize,
) -> f64 {
    let m = e.control_dim();
    let mut scratch = e.scratch();
    let mut x = x0.to_vec();
    let mut y = x0.to_vec();
    best_time(repeats, || {
        x.copy_from_slice(x0);
        for k in 0..steps {
            e.predict(&x, &u[k * m..(k + 1) * m], &mut scratch, &mut y);
            std::mem::swap(&mut x, &mut y);
        }
        black_box(&x);
    })
}

/// Seconds for the dolphin emulator to take one step per control in `u`, each followed by
/// `reg_steps` regularization steps (fastest of `repeats`).
pub(super) fn time_dolphin(
    e: &DolphinEmulator,
    reg: &mut BoundRegularizer,
    reg_steps: usize,
    x0: &[f64],
    u: &[f64],
    repeats: usize,
) -> f64 {
    let mut scratch = e.scratch();
    let schedule = Schedule {
        steps: reg_steps,
        every: 1,
    };
    best_time(repeats, || {
        let x = e.emulate(reg, schedule, x0, u, &mut scratch, |_, _| {});
        black_box(&x);
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn held_controls_repeat_each_row() {
        let u = [1.0, 2.0, 3.0, 4.0];
        assert_eq!(
            hold(&u, 2, 3),
            [1.0, 2.0, 1.0, 2.0, 1.0, 2.0, 3.0, 4.0, 3.0, 4.0, 3.0, 4.0]
        );
        assert_eq!(hold(&u, 2, 1), u);
    }
}
