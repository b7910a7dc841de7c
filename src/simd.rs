//! # Which vector instructions the dispatched code may use
//!
//! A few hot loops are compiled twice or three times (plain x86-64, AVX/AVX2 with FMA,
//! AVX-512F) and pick a copy when they run, by what the processor has: the perceptron's kernels
//! (`emulator::mlp::kernels`), the emulator's transforms, the momentum step, the RK45 trial,
//! the mass-spring forces, the four-knot RK4 Jacobians and [`crate::fastmath`]. Every copy
//! evaluates the same IEEE operations in the same order (a multiply–add is
//! [`f64::mul_add`], rounded once, on every path; a wider vector holds more independent
//! outputs, never a different sum), so all give the same bits; the tests compare them, and
//! this switch lets a whole run be forced onto one path to compare its tables.
//!
//! The environment variable [`ENV`] (`MOTIONLAB_SIMD`), read once when first needed (the
//! binary reads it at start-up and rejects an unknown value), caps the level:
//!
//! - `scalar`: no dispatched copy at all; each multiply–add is libm's `fma` (exact, and slow
//!   without the instruction);
//! - `avx2`: AVX, AVX2 and FMA where the processor has them, never AVX-512;
//! - `avx512` (or unset): whatever the processor has.
//!
//! `MOTIONLAB_NO_AVX512` (any value) is the older spelling of `avx2`. A level above what the
//! processor has gives what it has.

use std::sync::OnceLock;

/// The environment variable that caps the level ([`Level`]).
pub const ENV: &str = "MOTIONLAB_SIMD";

/// How far up the dispatched copies may go, in order.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum Level {
    /// The plain x86-64 (or other target's) code.
    Scalar,
    /// AVX, AVX2 and FMA, where present.
    Avx2,
    /// AVX-512F too, where present.
    Avx512,
}

impl Level {
    /// The name [`ENV`] takes for this level.
    pub fn name(self) -> &'static str {
        match self {
            Level::Scalar => "scalar",
            Level::Avx2 => "avx2",
            Level::Avx512 => "avx512",
        }
    }

    /// The level named `s` (as [`Level::name`] writes it, any case).
    pub fn parse(s: &str) -> Result<Self, String> {
        match s.trim().to_ascii_lowercase().as_str() {
            "scalar" | "none" => Ok(Level::Scalar),
            "avx2" => Ok(Level::Avx2),
            "avx512" => Ok(Level::Avx512),
            other => Err(format!("{ENV}={other:?}: expected scalar, avx2 or avx512")),
        }
    }
}

/// The cap the environment asks for ([`ENV`], then `MOTIONLAB_NO_AVX512`): `Ok(None)` when
/// neither is set, an error for a value [`Level::parse`] does not take.
pub fn requested() -> Result<Option<Level>, String> {
    let asked = match std::env::var(ENV) {
        Ok(s) if !s.trim().is_empty() => Some(Level::parse(&s)?),
        Ok(_) | Err(std::env::VarError::NotPresent) => None,
        Err(e) => return Err(format!("{ENV}: {e}")),
    };
    let no512 = std::env::var_os("MOTIONLAB_NO_AVX512").is_some();
    Ok(match (asked, no512) {
        (Some(l), true) => Some(l.min(Level::Avx2)),
        (None, true) => Some(Level::Avx2),
        (l, false) => l,
    })
}

/// The highest level the processor supports (AVX-512F; else AVX; else none).
fn detected() -> Level {
    #[cfg(target_arch = "x86_64")]
    {
        if std::arch::is_x86_feature_detected!("avx512f") {
            return Level::Avx512;
        }
        if std::arch::is_x86_feature_detected!("avx") {
            return Level::Avx2;
        }
    }
    Level::Scalar
}

/// The level every dispatched copy obeys: what the processor has, capped by [`requested`]
/// (an unusable value is reported once on standard error and ignored; the binary refuses it
/// before this is read).
pub fn level() -> Level {
    static LEVEL: OnceLock<Level> = OnceLock::new();
    let level = *LEVEL.get_or_init(|| {
        let cap = requested().unwrap_or_else(|e| {
            eprintln!("warning: {e}; ignored");
            None
        });
        let have = detected();
        cap.map_or(have, |c| c.min(have))
    });
    #[cfg(test)]
    if let Some(cap) = FORCED.get() {
        return level.min(cap);
    }
    level
}

#[cfg(test)]
thread_local! {
    /// This thread's cap in unit tests ([`with_level`]).
    static FORCED: std::cell::Cell<Option<Level>> = const { std::cell::Cell::new(None) };
}

/// `f` run on this thread with the level capped at `cap` (unit tests: every dispatched path
/// on one machine; work handed to other threads keeps the process's level).
#[cfg(test)]
pub(crate) fn with_level<T>(cap: Level, f: impl FnOnce() -> T) -> T {
    let before = FORCED.replace(Some(cap));
    let out = f();
    FORCED.set(before);
    out
}

/// Bits of [`flags`]: set once the others are known, then what the level allows.
const KNOWN: u8 = 1;
const AVX: u8 = 2;
const AVX2: u8 = 4;
const FMA: u8 = 8;
const AVX512F: u8 = 16;

/// What the dispatched copies may use, computed on the first call ([`level`] and the
/// processor's features) and then one relaxed load: the kernels ask at every call, and a call
/// to [`level`] there (a `OnceLock` behind a function call) measured 5–10% of a small net's
/// emulator step.
static FLAGS: std::sync::atomic::AtomicU8 = std::sync::atomic::AtomicU8::new(0);

/// The feature bits `level` allows on this processor.
#[cold]
fn flags_for(level: Level) -> u8 {
    let mut f = KNOWN;
    #[cfg(target_arch = "x86_64")]
    {
        let on = |b: bool, bit: u8| if b { bit } else { 0 };
        if level >= Level::Avx2 {
            f |= on(std::arch::is_x86_feature_detected!("avx"), AVX);
            f |= on(std::arch::is_x86_feature_detected!("avx2"), AVX2);
            f |= on(std::arch::is_x86_feature_detected!("fma"), FMA);
        }
        if level >= Level::Avx512 {
            f |= on(std::arch::is_x86_feature_detected!("avx512f"), AVX512F);
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = level;
    f
}

/// The feature bits of the current level ([`FLAGS`]).
#[inline(always)]
fn flags() -> u8 {
    use std::sync::atomic::Ordering::Relaxed;
    #[cfg(test)]
    if FORCED.get().is_some() {
        return flags_for(level());
    }
    let f = FLAGS.load(Relaxed);
    if f & KNOWN != 0 {
        return f;
    }
    let f = flags_for(level());
    FLAGS.store(f, Relaxed);
    f
}

/// Whether the AVX copies may run: the level allows it and the processor has AVX.
#[inline]
pub fn avx() -> bool {
    flags() & AVX != 0
}

/// Whether the AVX2 copies may run.
#[inline]
pub fn avx2() -> bool {
    flags() & AVX2 != 0
}

/// Whether the copies with the FMA instruction may run.
#[inline]
pub fn fma() -> bool {
    flags() & FMA != 0
}

/// Whether the copies with AVX2 and FMA may run.
#[inline]
pub fn avx2_fma() -> bool {
    flags() & (AVX2 | FMA) == AVX2 | FMA
}

/// Whether the AVX-512F copies may run.
#[inline]
pub fn avx512f() -> bool {
    flags() & AVX512F != 0
}

/// The levels this processor can run, lowest first (for tests that compare every path).
pub fn available() -> Vec<Level> {
    let have = detected();
    [Level::Scalar, Level::Avx2, Level::Avx512]
        .into_iter()
        .filter(|&l| l <= have)
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_parse_back_and_unknown_ones_are_refused() {
        for l in [Level::Scalar, Level::Avx2, Level::Avx512] {
            assert_eq!(Level::parse(l.name()), Ok(l));
            assert_eq!(Level::parse(&l.name().to_uppercase()), Ok(l));
        }
        assert!(Level::parse("sse9").is_err());
        assert!(Level::Scalar < Level::Avx2 && Level::Avx2 < Level::Avx512);
    }

    #[test]
    fn the_level_never_exceeds_the_processor() {
        assert!(level() <= detected());
        assert_eq!(available().last(), Some(&detected()));
        if avx512f() {
            assert!(avx());
        }
        with_level(Level::Scalar, || {
            assert_eq!(level(), Level::Scalar);
            assert!(!avx() && !avx2() && !fma() && !avx512f());
        });
        with_level(Level::Avx2, || assert!(!avx512f()));
    }
}
