//! Throughput of the hot loops, as `motionlab bench` and `cargo bench` report it.
//!
//! Each metric is a dotted name with its unit in the name (`sim.pendulum3.steps_per_s`) and is
//! measured by repeating the loop for at least `min_seconds` of wall time. Later models and
//! algorithms add their loops to [`metrics`].
//!
//! The list of metrics is in `suite`; the neural loops in `neural`, the BPTT ones in `bptt` and
//! the processor's peak in `cpu`. This module holds the timing rule and the output.

// Benchmark inputs, never written to a results table: the platform's functions are fine here.
#![allow(clippy::disallowed_methods)]

mod bptt;
mod cpu;
mod neural;
mod suite;

pub use neural::rollout_grad_metric;
pub use suite::metrics;

use std::time::Instant;

/// One measured metric.
#[derive(Debug, Clone, PartialEq)]
pub struct Metric {
    /// Dotted name with unit, e.g. `sim.pendulum3.steps_per_s`.
    pub name: String,
    /// Value.
    pub value: f64,
}

/// Runs `f` (which does `work` units per call) until `min_seconds` passed; units per second.
pub fn throughput(min_seconds: f64, work: u64, mut f: impl FnMut()) -> f64 {
    f(); // warm-up
    let t0 = Instant::now();
    let mut n = 0u64;
    loop {
        f();
        n += work;
        let dt = t0.elapsed().as_secs_f64();
        if dt >= min_seconds {
            return n as f64 / dt;
        }
    }
}

/// The metrics as one JSON object of named numbers.
pub fn to_json(metrics: &[Metric]) -> serde_json::Value {
    serde_json::Value::Object(
        metrics
            .iter()
            .map(|m| (m.name.clone(), serde_json::json!(m.value)))
            .collect(),
    )
}
