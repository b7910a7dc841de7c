//! The processor's f64 multiply–add peak, the roofline the neural metrics are read against.

use super::throughput;
use std::hint::black_box;

/// The f64 multiply–add throughput of one core (`cpu.fma_f64.<lanes>.gmac_per_s`, 10⁹ per
/// second): 12 independent chains of fused multiply–adds, on 4-lane AVX2 registers (the
/// single-example kernels' lanes) and, where the processor has AVX-512, 8-lane registers
/// (which the batch products' GEMM uses there); none on other processors. The roofline the
/// neural metrics are measured against: `mlp.<shape>.*_gmac_per_s` count a batch example's
/// multiply–adds as 2pq + 3qr (forward pq + qr, backward qr for h̄ and qr + pq for the
/// weight gradient).
pub(super) fn fma_peaks(min_seconds: f64) -> Vec<(String, f64)> {
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
