//! Summary statistics the reports share: medians and their bootstrap intervals.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Resamples of [`median_interval`]'s bootstrap.
pub const BOOTSTRAP_RESAMPLES: usize = 2000;

/// The median of the finite values of `v` (the mean of the two middle ones for an even count;
/// NaN when none is finite).
pub fn median(v: &[f64]) -> f64 {
    middle(v.iter().copied().filter(|x| x.is_finite()).collect())
}

/// The median of the values of `v` that are not NaN, infinities kept (the mean of the two
/// middle ones for an even count; NaN when none is left): where +∞ codes "never", a run that
/// never got there counts as the slowest, not as missing.
pub fn median_with_infinities(v: &[f64]) -> f64 {
    middle(v.iter().copied().filter(|x| !x.is_nan()).collect())
}

/// The median of sorted-or-not `s` (the mean of the two middle ones for an even count).
fn middle(mut s: Vec<f64>) -> f64 {
    if s.is_empty() {
        return f64::NAN;
    }
    s.sort_by(f64::total_cmp);
    let n = s.len();
    if n % 2 == 1 {
        s[n / 2]
    } else {
        0.5 * (s[n / 2 - 1] + s[n / 2])
    }
}

/// The median of `v` with its 95% percentile-bootstrap interval: [`BOOTSTRAP_RESAMPLES`]
/// resamples of the finite values with replacement, drawn from a ChaCha8 stream seeded with
/// `seed` (so a report is the same on every machine), and the 2.5th and 97.5th percentiles of
/// their medians. `(median, lo, hi)`; all NaN without a finite value.
pub fn median_interval(v: &[f64], seed: u64) -> (f64, f64, f64) {
    resampled_median(v.iter().copied().filter(|x| x.is_finite()).collect(), seed)
}

/// [`median_interval`] over the values that are not NaN, infinities kept (as
/// [`median_with_infinities`]): an interval bound may be infinite.
pub fn median_interval_with_infinities(v: &[f64], seed: u64) -> (f64, f64, f64) {
    resampled_median(v.iter().copied().filter(|x| !x.is_nan()).collect(), seed)
}

/// The median of `x` and the 2.5th and 97.5th percentiles of the medians of
/// [`BOOTSTRAP_RESAMPLES`] resamples with replacement (a ChaCha8 stream seeded with `seed`).
fn resampled_median(x: Vec<f64>, seed: u64) -> (f64, f64, f64) {
    if x.is_empty() {
        return (f64::NAN, f64::NAN, f64::NAN);
    }
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut sample = vec![0.0; x.len()];
    let mut medians: Vec<f64> = (0..BOOTSTRAP_RESAMPLES)
        .map(|_| {
            for s in sample.iter_mut() {
                *s = x[rng.random_range(0..x.len())];
            }
            middle(sample.clone())
        })
        .collect();
    medians.sort_by(f64::total_cmp);
    let at = |q: f64| medians[((q * (medians.len() - 1) as f64).round()) as usize];
    (middle(x), at(0.025), at(0.975))
}

/// The difference of medians `median(a) - median(b)` of two independent samples with its 95%
/// percentile-bootstrap interval (each sample resampled on its own, [`BOOTSTRAP_RESAMPLES`]
/// times, from a ChaCha8 stream seeded with `seed`). `(difference, lo, hi)`; all NaN when a
/// sample has no finite value.
pub fn median_difference_interval(a: &[f64], b: &[f64], seed: u64) -> (f64, f64, f64) {
    let finite = |v: &[f64]| -> Vec<f64> { v.iter().copied().filter(|x| x.is_finite()).collect() };
    let (a, b) = (finite(a), finite(b));
    if a.is_empty() || b.is_empty() {
        return (f64::NAN, f64::NAN, f64::NAN);
    }
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let (mut sa, mut sb) = (vec![0.0; a.len()], vec![0.0; b.len()]);
    let mut diffs: Vec<f64> = (0..BOOTSTRAP_RESAMPLES)
        .map(|_| {
            for s in sa.iter_mut() {
                *s = a[rng.random_range(0..a.len())];
            }
            for s in sb.iter_mut() {
                *s = b[rng.random_range(0..b.len())];
            }
            median(&sa) - median(&sb)
        })
        .collect();
    diffs.sort_by(f64::total_cmp);
    let at = |q: f64| diffs[((q * (diffs.len() - 1) as f64).round()) as usize];
    (median(&a) - median(&b), at(0.025), at(0.975))
}

/// The 95% percentile-bootstrap interval of a statistic of `n` paired units (trials, seeds):
/// [`BOOTSTRAP_RESAMPLES`] resamples of the unit indices `0..n` with replacement, from a
/// ChaCha8 stream seeded with `seed`, each passed to `stat`; the 2.5th and 97.5th percentiles
/// of its finite values. NaN without a unit or a finite value.
pub fn bootstrap_interval(n: usize, seed: u64, stat: impl Fn(&[usize]) -> f64) -> (f64, f64) {
    bootstrap_intervals(n, seed, 1, |idx, out| out[0] = stat(idx))[0]
}

/// [`bootstrap_interval`] of `k` statistics computed together from each resample (`stat`
/// writes them into its slice): the same resamples for all, so a statistic costs nothing
/// extra where its siblings share the work, and each interval is the one
/// [`bootstrap_interval`] would give it alone.
pub fn bootstrap_intervals(
    n: usize,
    seed: u64,
    k: usize,
    stat: impl Fn(&[usize], &mut [f64]),
) -> Vec<(f64, f64)> {
    if n == 0 {
        return vec![(f64::NAN, f64::NAN); k];
    }
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut idx = vec![0; n];
    let mut one = vec![0.0; k];
    let mut values: Vec<Vec<f64>> = vec![Vec::with_capacity(BOOTSTRAP_RESAMPLES); k];
    for _ in 0..BOOTSTRAP_RESAMPLES {
        for i in idx.iter_mut() {
            *i = rng.random_range(0..n);
        }
        one.fill(f64::NAN);
        stat(&idx, &mut one);
        for (v, &x) in values.iter_mut().zip(&one) {
            if x.is_finite() {
                v.push(x);
            }
        }
    }
    values
        .into_iter()
        .map(|mut v| {
            if v.is_empty() {
                return (f64::NAN, f64::NAN);
            }
            v.sort_by(f64::total_cmp);
            let at = |q: f64| v[((q * (v.len() - 1) as f64).round()) as usize];
            (at(0.025), at(0.975))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_difference_interval_holds_the_difference_and_separates_distant_samples() {
        let a: Vec<f64> = (0..5).map(|i| 10.0 + i as f64).collect();
        let b: Vec<f64> = (0..5).map(|i| i as f64).collect();
        let (d, lo, hi) = median_difference_interval(&a, &b, 3);
        assert_eq!(d, 10.0);
        assert!(lo <= d && d <= hi && lo > 0.0, "{lo} {d} {hi}");
        // Overlapping samples: the interval straddles zero.
        let c: Vec<f64> = (0..5).map(|i| 1.0 + i as f64).collect();
        let (d, lo, hi) = median_difference_interval(&c, &b, 3);
        assert!(lo < 0.0 && 0.0 < hi && d == 1.0, "{lo} {d} {hi}");
        assert_eq!(
            median_difference_interval(&a, &b, 3),
            median_difference_interval(&a, &b, 3)
        );
        assert!(median_difference_interval(&[], &b, 3).0.is_nan());
    }

    #[test]
    fn the_bootstrap_interval_holds_the_median_narrows_with_more_data_and_is_seeded() {
        let few: Vec<f64> = (0..5).map(|i| i as f64).collect();
        let many: Vec<f64> = (0..200)
            .map(|i| (i % 5) as f64 + 0.001 * i as f64)
            .collect();
        let (m, lo, hi) = median_interval(&few, 7);
        assert!(lo <= m && m <= hi && lo < hi, "{lo} {m} {hi}");
        let (_, lo2, hi2) = median_interval(&many, 7);
        assert!(hi2 - lo2 < hi - lo, "{lo2}-{hi2} vs {lo}-{hi}");
        assert_eq!(median_interval(&few, 7), median_interval(&few, 7));
        assert_eq!(median_interval(&[3.0], 1), (3.0, 3.0, 3.0));
        assert!(median_interval(&[], 1).0.is_nan());
    }

    #[test]
    fn the_median_skips_non_finite_values_and_averages_an_even_middle() {
        assert_eq!(median(&[3.0, 1.0, 2.0]), 2.0);
        assert_eq!(median(&[4.0, 1.0, 3.0, 2.0]), 2.5);
        assert_eq!(median(&[f64::NAN, 5.0, f64::INFINITY]), 5.0);
        assert!(median(&[]).is_nan());
    }

    /// Where +∞ codes "never", it counts as the slowest value; NaN is still skipped; the
    /// interval's upper bound reaches +∞ once enough resamples draw it.
    #[test]
    fn the_median_with_infinities_counts_never_as_slowest() {
        let inf = f64::INFINITY;
        assert_eq!(median_with_infinities(&[1.0, inf, inf]), inf);
        assert_eq!(median_with_infinities(&[1.0, 2.0, inf]), 2.0);
        assert_eq!(median_with_infinities(&[1.0, f64::NAN, 3.0]), 2.0);
        let (m, lo, hi) = median_interval_with_infinities(&[1.0, 2.0, 3.0, 4.0, inf], 5);
        assert_eq!(m, 3.0);
        assert!((1.0..=3.0).contains(&lo) && hi == inf, "{lo} {hi}");
        assert_eq!(median_interval(&[1.0, 2.0, 3.0, 4.0, inf], 5).0, 2.5);
    }

    /// The bootstrap of the mean of paired units brackets the mean; a constant statistic has
    /// a point interval; the same seed gives the same interval.
    #[test]
    fn the_paired_bootstrap_brackets_the_statistic_and_is_seeded() {
        let x = [1.0, 2.0, 3.0, 4.0, 10.0];
        let mean = |idx: &[usize]| idx.iter().map(|&i| x[i]).sum::<f64>() / idx.len() as f64;
        let (lo, hi) = bootstrap_interval(x.len(), 3, mean);
        assert!(lo < 4.0 && 4.0 < hi && lo >= 1.0 && hi <= 10.0, "{lo} {hi}");
        assert_eq!(bootstrap_interval(x.len(), 3, mean), (lo, hi));
        assert_eq!(bootstrap_interval(4, 1, |_| 2.5), (2.5, 2.5));
        assert!(bootstrap_interval(0, 1, |_| 1.0).0.is_nan());
        // Two statistics from the same resamples: each interval as it would be alone.
        let max = |idx: &[usize]| idx.iter().map(|&i| x[i]).fold(f64::MIN, f64::max);
        let both = bootstrap_intervals(x.len(), 3, 2, |idx, out| {
            out[0] = mean(idx);
            out[1] = max(idx);
        });
        assert_eq!(both, vec![(lo, hi), bootstrap_interval(x.len(), 3, max)]);
    }
}
