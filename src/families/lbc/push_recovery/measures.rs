//! The measures of the weight trace and the lean that the verdict judges: swings of α,
//! settling gap and range over a window, the mirror gap and the largest lean.

use std::f64::consts::FRAC_PI_2;

/// Swings of the forward weight `a` before time `before`: moves from one side to the other,
/// a side being below 0.25 (backward) or above 0.75 (forward). Leaving the undecided middle
/// for a first side is not a swing, and wobbles around 0.5 (a symmetric start, where rounding
/// decides) count for nothing.
pub fn swings(t: &[f64], a: &[f64], before: f64) -> usize {
    let mut n = 0;
    let mut side: Option<bool> = None;
    for k in 0..t.len() {
        if t[k] >= before {
            break;
        }
        let s = if a[k] > 0.75 {
            Some(true)
        } else if a[k] < 0.25 {
            Some(false)
        } else {
            None
        };
        if let Some(s) = s {
            if side.is_some_and(|prev| prev != s) {
                n += 1;
            }
            side = Some(s);
        }
    }
    n
}

/// Largest |a − b| over the steps with `t` in `window` (NaN when none is).
pub fn window_gap(t: &[f64], a: &[f64], b: &[f64], window: [f64; 2]) -> f64 {
    (0..t.len())
        .filter(|&k| t[k] >= window[0] && t[k] <= window[1])
        .map(|k| (a[k] - b[k]).abs())
        .fold(f64::NAN, f64::max)
}

/// Largest lean from upright (rad) over runs of body angles.
pub(super) fn largest_lean(runs: &[Vec<f64>]) -> f64 {
    runs.iter()
        .flatten()
        .map(|b| (b - FRAC_PI_2).abs())
        .fold(0.0, f64::max)
}

/// Range (max − min) of `a` over the steps with `t` in `window` (NaN when none is).
pub fn window_range(t: &[f64], a: &[f64], window: [f64; 2]) -> f64 {
    let w = (0..t.len()).filter(|&k| t[k] >= window[0] && t[k] <= window[1]);
    let (lo, hi) = w.fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), k| {
        (lo.min(a[k]), hi.max(a[k]))
    });
    if lo > hi {
        f64::NAN
    } else {
        hi - lo
    }
}

/// Largest |α_forward(tugs) − α_backward(mirrored tugs)|, with α_backward = 1 − α_forward.
pub fn mirror_gap(a: &[f64], mirrored: &[f64]) -> f64 {
    a.iter()
        .zip(mirrored)
        .map(|(x, m)| (x - (1.0 - m)).abs())
        .fold(0.0, f64::max)
}
