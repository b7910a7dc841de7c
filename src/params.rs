//! # Settings validation
//!
//! The small vocabulary every layer uses to check its own settings: a [`ParamError`] names the
//! dotted key and says what is wrong with its value, and [`ensure`], [`positive`] and
//! [`all_positive`] build one. A solver's or trainer's `validate` returns these errors; the
//! harness ([`crate::experiment`]) places them in the experiment file (file, line, key).
//! This module depends on nothing else in the crate.

use std::fmt::Display;

/// A parameter problem found by a family, at a dotted key inside `[params]`.
#[derive(Debug, Clone, thiserror::Error, PartialEq)]
#[error("`{key}`: {message}")]
pub struct ParamError {
    /// Dotted key inside `[params]`, e.g. `dts[2]`.
    pub key: String,
    /// What is wrong.
    pub message: String,
}

impl ParamError {
    /// A new error at `key`.
    pub fn new(key: impl Into<String>, message: impl Display) -> Self {
        Self {
            key: key.into(),
            message: message.to_string(),
        }
    }

    /// The same error with its key under `prefix` (`training.patience` → `dolphin.training.patience`).
    pub fn prefixed(self, prefix: &str) -> Self {
        Self {
            key: format!("{prefix}.{}", self.key),
            message: self.message,
        }
    }
}

/// Fails with `message` at `key` unless `ok`.
pub fn ensure(ok: bool, key: &str, message: impl Display) -> Result<(), ParamError> {
    if ok {
        Ok(())
    } else {
        Err(ParamError::new(key, message))
    }
}

/// A finite value > 0.
pub fn positive(key: &str, v: f64) -> Result<(), ParamError> {
    ensure(
        v.is_finite() && v > 0.0,
        key,
        format!("must be > 0, got {v}"),
    )
}

/// The numeric fields of a verdict's thresholds struct `bars`, by their serde names (the
/// settings of its `rule` table), sorted by name; an error names a field that is not a number.
pub fn bars_of<T: serde::Serialize>(bars: &T) -> Result<Vec<(String, f64)>, ParamError> {
    let value = serde_json::to_value(bars).map_err(|e| ParamError::new("rule", e))?;
    let map = value
        .as_object()
        .ok_or_else(|| ParamError::new("rule", "the thresholds are not a table"))?;
    map.iter()
        .map(|(k, v)| {
            v.as_f64()
                .map(|x| (k.clone(), x))
                .ok_or_else(|| ParamError::new(format!("rule.{k}"), "must be a number"))
        })
        .collect()
}

/// Every threshold of `bars` ([`bars_of`]) satisfies `ok`; the error names the first that does
/// not (`rule.<name>`) and says `why`.
pub fn each_bar<T: serde::Serialize>(
    bars: &T,
    ok: impl Fn(f64) -> bool,
    why: &str,
) -> Result<(), ParamError> {
    for (key, v) in bars_of(bars)? {
        ensure(ok(v), &format!("rule.{key}"), why)?;
    }
    Ok(())
}

/// Every element finite and > 0, and at least one.
pub fn all_positive(key: &str, vs: &[f64]) -> Result<(), ParamError> {
    ensure(!vs.is_empty(), key, "must not be empty")?;
    for (i, &v) in vs.iter().enumerate() {
        positive(&format!("{key}[{i}]"), v)?;
    }
    Ok(())
}

/// No value listed twice: a repeated entry of a list the experiment runs one by one (time
/// steps, models, spacings) would only repeat its rows. The error names the second occurrence.
pub fn distinct<T: PartialEq + std::fmt::Debug>(key: &str, values: &[T]) -> Result<(), ParamError> {
    for (i, v) in values.iter().enumerate() {
        if let Some(j) = values[..i].iter().position(|w| w == v) {
            return Err(ParamError::new(
                format!("{key}[{i}]"),
                format!("{v:?} is listed twice (also at {key}[{j}]); it would only repeat rows"),
            ));
        }
    }
    Ok(())
}

/// A count no larger than `max` (a stated limit, so that a typo such as `1e10` is refused
/// before anything is allocated).
pub fn at_most(key: &str, v: usize, max: usize) -> Result<(), ParamError> {
    ensure(v <= max, key, format!("must be at most {max}, got {v}"))
}
