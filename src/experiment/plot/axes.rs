//! Axis ticks and their labels: round tick values on linear and log axes, one label format
//! per axis, and the plotters axis type that draws our ticks.

use plotters::coord::ranged1d::{DefaultFormatting, KeyPointHint};
use plotters::prelude::*;

pub(super) fn tr(v: f64, log: bool) -> Option<f64> {
    let t = if log {
        if v > 0.0 {
            v.log10()
        } else {
            return None;
        }
    } else {
        v
    };
    t.is_finite().then_some(t)
}

pub(super) fn range(vals: impl Iterator<Item = f64>) -> (f64, f64) {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for v in vals {
        lo = lo.min(v);
        hi = hi.max(v);
    }
    if !lo.is_finite() {
        return (0.0, 1.0);
    }
    if hi - lo < 1e-12 * (1.0 + lo.abs()) {
        return (lo - 0.5, hi + 0.5);
    }
    let pad = 0.05 * (hi - lo);
    (lo - pad, hi + pad)
}

/// Tick label; `snap` > 0 (a linear axis's span) turns round-off around zero into `0`.
/// A tick label: `v` with at most 3 decimals, "0" near zero (relative to the span `snap`).
pub(crate) fn tick(v: f64, snap: f64) -> String {
    if v == 0.0 || v.abs() < 1e-9 * snap {
        "0".into()
    } else if v.abs() >= 1e4 || v.abs() < 1e-3 {
        format!("{v:.1e}")
    } else {
        let s = format!("{v:.3}");
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    }
}

/// Whether an axis's ticks need scientific notation (one of them is >= 1e4 or < 1e-3 in
/// magnitude and not zero; whole numbers up to 1e6 stay plain): then every label of that axis
/// is written so.
pub(super) fn needs_sci(ticks: &[f64], snap: f64) -> bool {
    let whole = ticks.iter().all(|v| v.fract() == 0.0 && v.abs() < 1e6);
    !whole
        && ticks
            .iter()
            .any(|&v| tick(v, snap) != "0" && (v.abs() >= 1e4 || v.abs() < 1e-3))
}

/// A tick label in one axis-wide format: scientific (`2.5e-5`, `1e3`) when `sci`, else [`tick`].
pub(crate) fn tick_as(v: f64, snap: f64, sci: bool) -> String {
    if !sci && v.fract() == 0.0 && v.abs() < 1e6 {
        return if v == 0.0 {
            "0".into()
        } else {
            format!("{v:.0}")
        };
    }
    let plain = tick(v, snap);
    if !sci || plain == "0" {
        return plain;
    }
    let s = format!("{v:.2e}");
    match s.split_once('e') {
        Some((m, e)) => {
            let m = if m.contains('.') {
                m.trim_end_matches('0').trim_end_matches('.')
            } else {
                m
            };
            format!("{m}e{e}")
        }
        None => s,
    }
}

/// An axis with our own labelled ticks ([`axis_ticks`]) over plotters' linear or log axis.
pub(super) struct Ticked<R> {
    inner: R,
    ticks: Vec<f64>,
}

impl<R> Ticked<R> {
    pub(super) fn new(inner: R, ticks: Vec<f64>) -> Self {
        Self { inner, ticks }
    }
}

impl<R: Ranged<ValueType = f64>> Ranged for Ticked<R> {
    type FormatOption = DefaultFormatting;
    type ValueType = f64;
    fn map(&self, value: &f64, limit: (i32, i32)) -> i32 {
        self.inner.map(value, limit)
    }
    fn key_points<Hint: KeyPointHint>(&self, _hint: Hint) -> Vec<f64> {
        self.ticks.clone()
    }
    fn range(&self) -> std::ops::Range<f64> {
        self.inner.range()
    }
}

/// A round step near `span / 6` (1, 2, 2.5 or 5 times a power of ten).
fn nice_step(span: f64) -> f64 {
    let raw = span.abs() / 6.0;
    let p = 10f64.powf(raw.log10().floor());
    [1.0, 2.0, 2.5, 5.0, 10.0]
        .iter()
        .map(|m| m * p)
        .find(|&s| s >= raw)
        .unwrap_or(10.0 * p)
}

/// Multiples of `step` in [lo, hi].
fn multiples(lo: f64, hi: f64, step: f64) -> Vec<f64> {
    let first = (lo / step - 1e-9).ceil() as i64;
    let last = (hi / step + 1e-9).floor() as i64;
    (first..=last).map(|k| k as f64 * step).collect()
}

/// The labelled ticks of an axis over [lo, hi]: round values, at least 4 of them wherever the
/// range allows. Linear axes: multiples of a 1-2-2.5-5 step. Log axes: powers of ten, then
/// 1-2-5 and 1…9 multiples of them where a decade gives too few, then round linear values for
/// ranges narrower than a factor of about 2; more than 10 decades are thinned.
pub fn axis_ticks(lo: f64, hi: f64, log: bool) -> Vec<f64> {
    let (lo, hi) = (lo.min(hi), lo.max(hi));
    if !(lo.is_finite() && hi.is_finite()) || hi <= lo {
        return Vec::new();
    }
    let linear = |lo: f64, hi: f64| {
        let mut step = nice_step(hi - lo);
        let mut t = multiples(lo, hi, step);
        while t.len() < 4 && step > 0.0 {
            step /= 2.0;
            t = multiples(lo, hi, step);
        }
        t
    };
    if !log || lo <= 0.0 {
        return linear(lo, hi);
    }
    let (d0, d1) = (lo.log10().floor() as i32, hi.log10().ceil() as i32);
    let within = |v: &f64| *v >= lo * (1.0 - 1e-9) && *v <= hi * (1.0 + 1e-9);
    for mults in [
        &[1.0][..],
        &[1.0, 2.0, 5.0],
        &[1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0],
    ] {
        let t: Vec<f64> = (d0..=d1)
            .flat_map(|d| mults.iter().map(move |m| m * 10f64.powi(d)))
            .filter(within)
            .collect();
        if t.len() >= 4 {
            let every = t.len().div_ceil(10);
            if every == 1 {
                return t;
            }
            if mults.len() > 1 {
                return t.into_iter().step_by(every).collect();
            }
            // Thin to decades whose exponent is a multiple of `every` (1e-4, 1e-2, 1e0, …).
            let aligned: Vec<f64> = t
                .iter()
                .copied()
                .filter(|v| (v.log10().round() as i64).rem_euclid(every as i64) == 0)
                .collect();
            return if aligned.len() >= 4 {
                aligned
            } else {
                t.into_iter().step_by(every).collect()
            };
        }
    }
    linear(lo, hi)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_axis_gets_at_least_four_round_labelled_ticks_log_axes_included() {
        let cases = [
            (0.0, 1.0, false),
            (-3.2, 7.9, false),
            (0.999, 1.001, false),
            (-1e-7, 3e-7, false),
            (1e3, 1.1e6, false),
            (1e-6, 1e2, true),
            (0.5, 3.0, true), // less than a decade: 1-2-5 multiples
            (1.2, 2.1, true), // within a factor of 2: round linear values
            (3e-3, 4e-3, true),
            (1e-30, 1e30, true), // sixty decades: thinned
        ];
        for (lo, hi, log) in cases {
            let t = axis_ticks(lo, hi, log);
            assert!((4..=12).contains(&t.len()), "{lo}..{hi} log={log}: {t:?}");
            for w in t.windows(2) {
                assert!(w[0] < w[1], "{t:?} not increasing");
            }
            for v in &t {
                assert!(*v >= lo - 1e-9 * (hi - lo).abs() && *v <= hi * (1.0 + 1e-9) + 1e-12);
            }
        }
        // Powers of ten first on a log axis over many decades.
        assert_eq!(
            axis_ticks(1e-3, 1e3, true),
            vec![1e-3, 1e-2, 1e-1, 1.0, 1e1, 1e2, 1e3]
        );
        // Round values on a linear one.
        assert_eq!(
            axis_ticks(0.0, 10.0, false),
            vec![0.0, 2.0, 4.0, 6.0, 8.0, 10.0]
        );
    }

    #[test]
    fn an_axis_labels_all_its_ticks_in_one_format() {
        let t = axis_ticks(1e-9, 1.0, true);
        let sci = needs_sci(&t, 0.0);
        assert!(sci);
        let labels: Vec<String> = t.iter().map(|&v| tick_as(v, 0.0, sci)).collect();
        assert!(labels.iter().all(|l| l.contains('e')), "{labels:?}");
        assert_eq!(tick_as(2.5e-5, 0.0, true), "2.5e-5");
        assert_eq!(tick_as(1.0, 0.0, true), "1e0");
        assert_eq!(tick_as(0.25, 1.0, false), "0.25");
        assert!(!needs_sci(&axis_ticks(0.0, 10.0, false), 10.0));
        // Iteration counts stay whole numbers.
        let t = axis_ticks(0.0, 15000.0, false);
        assert!(!needs_sci(&t, 15000.0));
        assert_eq!(tick_as(15000.0, 15000.0, false), "15000");
        assert_eq!(tick_as(-0.0, 1.0, false), "0");
    }
}
