//! Linear Bellman combination (da Silva, Durand, Popović 2009), experiment ids `lbc_*`.

pub mod acrobot_swingup;
pub mod diver;
pub mod film;
pub mod grid_optimality;
pub mod jumping;
pub mod projection;
pub mod push_recovery;
pub mod stepping;
pub mod walking;

use crate::bellman::projection::{project, GaussianReward};
use crate::control::ddp::{solve, ControlBounds, DdpOptions, DdpSolution};
use crate::control::lqr::{track, TrackingController};
use crate::control::{QuadraticCost, Rk4Map};
use crate::experiment::output::Table;
use crate::experiment::plot::{Legend, Panel, Series};
use crate::experiment::report::sig;
use crate::experiment::resolve::{ensure, positive, ParamError};
use crate::experiment::rows::{written_rows, TableRow};
use crate::experiment::{other, Error};
use crate::physics::linearize::Linearize;
use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// Scales of §6.1's objective for the DDP-optimized contact motions (stepping, jumping):
/// Q_T = diag(1/scale²) over the family's position, angle, velocity and angular-rate features
/// (each family's job says which: the pelvis for a step, the centre of mass for a jump);
/// R = I / torque²; the running weight Q is a family's chosen Q_T entries × `average_scale` / T.
#[derive(Debug, Clone, Copy, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CostScales {
    /// Position features (m).
    pub position_m: f64,
    /// Torso and joint angles (rad).
    pub angle_rad: f64,
    /// Velocity features (m/s).
    pub speed_m_s: f64,
    /// Torso and joint rates (rad/s).
    pub rate_rad_s: f64,
    /// Torque (N m).
    pub torque_n_m: f64,
    /// Weight of the average-trajectory term relative to the terminal angle weights.
    pub average_scale: f64,
}

impl CostScales {
    /// Q_T's diagonal over a floating planar body's `2 dof` state features (the position's two
    /// coordinates, then `dof - 2` angles, the velocity's two, then `dof - 2` rates):
    /// 1/scale² of each group.
    pub fn terminal_diagonal(&self, dof: usize) -> Vec<f64> {
        let mut d = vec![0.0; 2 * dof];
        d[..2].fill(self.position_m.powi(-2));
        d[2..dof].fill(self.angle_rad.powi(-2));
        d[dof..dof + 2].fill(self.speed_m_s.powi(-2));
        d[dof + 2..].fill(self.rate_rad_s.powi(-2));
        d
    }

    /// R = I / torque² over `m` torques.
    pub fn control_weight(&self, m: usize) -> DMatrix<f64> {
        DMatrix::identity(m, m) * self.torque_n_m.powi(-2)
    }

    /// Every scale positive, `average_scale` finite and non-negative (keys `cost.*`).
    pub fn validate(&self) -> Result<(), ParamError> {
        for (key, v) in [
            ("cost.position_m", self.position_m),
            ("cost.angle_rad", self.angle_rad),
            ("cost.speed_m_s", self.speed_m_s),
            ("cost.rate_rad_s", self.rate_rad_s),
            ("cost.torque_n_m", self.torque_n_m),
        ] {
            positive(key, v)?;
        }
        ensure(
            self.average_scale >= 0.0 && self.average_scale.is_finite(),
            "cost.average_scale",
            "must be finite and non-negative",
        )
    }
}

/// A contact family's `knot_dt`: positive and at most the ground's stable RK4 step
/// ([`crate::physics::ground::GROUND_RK4_MAX_DT`]).
pub(crate) fn knot_dt_on_ground(knot_dt: f64) -> Result<(), ParamError> {
    use crate::physics::ground::GROUND_RK4_MAX_DT;
    ensure(
        knot_dt > 0.0 && knot_dt <= GROUND_RK4_MAX_DT,
        "knot_dt",
        format!(
            "must be in (0, {:.2} ms]: RK4 on the ground's 6000 N s/m damping is unstable above",
            GROUND_RK4_MAX_DT * 1e3
        ),
    )
}

/// §4.1's scale rule ("the quadratic cost functions should share the same scale factor which
/// is inversely proportional to the square of the distance between each minimum point"): the
/// squared distance between two examples' terminal targets in the terminal metric `q`, so their
/// exp-transformed terminal costs exp(−g_i/λ) lie one unit apart.
pub fn scale_lambda(q: &DMatrix<f64>, a: &DVector<f64>, b: &DVector<f64>) -> f64 {
    let d = a - b;
    (d.transpose() * q * &d)[0]
}

/// DDP from `x0` and the initial torques `u_init` (each torque within ±`limit`, at most
/// `max_iterations`, stopping when an iteration improves the cost by less than `tol_cost`),
/// then the TV-LQR tracker of its solution (LBC §5.2), with the seconds both took.
pub(crate) fn optimized_tracker<M: Linearize>(
    map: &Rk4Map<M>,
    cost: &QuadraticCost,
    x0: &[f64],
    u_init: &[DVector<f64>],
    limit: f64,
    max_iterations: usize,
    tol_cost: f64,
) -> Result<(DdpSolution, TrackingController, f64), Error> {
    let t0 = std::time::Instant::now();
    let bound = DVector::from_element(map.control_dim(), limit);
    let options = DdpOptions {
        max_iterations,
        tol_cost,
        bounds: Some(ControlBounds {
            lower: -bound.clone(),
            upper: bound,
        }),
        ..DdpOptions::default()
    };
    let x0 = DVector::from_row_slice(x0);
    let sol = solve(map, cost, &x0, u_init, &options).map_err(other)?;
    let tracker = track(map, cost, &sol.x, &sol.u).map_err(other)?;
    Ok((sol, tracker, t0.elapsed().as_secs_f64()))
}

/// A panel of LBC's weight α over time, one line per run: `keys[i]` names row i's run (a
/// desired length or height in m; rows grouped by run), `t` its time, `alpha` its α.
pub(crate) fn alpha_panel(
    title: &str,
    x_label: &str,
    y_label: &str,
    keys: &[f64],
    t: &[f64],
    alpha: &[f64],
) -> Panel {
    let mut runs = keys.to_vec();
    runs.dedup();
    let series = runs
        .iter()
        .enumerate()
        .map(|(k, &d)| {
            let points = (0..keys.len())
                .filter(|&i| keys[i] == d)
                .map(|i| (t[i], alpha[i]))
                .collect();
            Series::line(format!("{} m", sig(d)), points, k)
        })
        .collect();
    Panel {
        title: title.into(),
        x_label: x_label.into(),
        y_label: y_label.into(),
        series,
        y_range: Some((-0.02, 1.02)),
        legend: Legend::Auto,
        ..Panel::default()
    }
}

/// Projected weights (LBC §4.1): the quadratic q/λ centred on `desired` projected in reward
/// space onto the same quadratic centred on each of `centers`. Weights below 1e-9 of their
/// sum snap to zero (at an example's own target the other's weight is zero up to rounding);
/// a negative weight is an error naming `what`.
pub(crate) fn projected_weights(
    q: &DMatrix<f64>,
    lambda: f64,
    centers: &[DVector<f64>],
    desired: &DVector<f64>,
    what: &str,
) -> Result<Vec<f64>, Error> {
    let q = q / lambda;
    let comps: Vec<GaussianReward> = centers
        .iter()
        .map(|c| GaussianReward {
            center: c.clone(),
            q: q.clone(),
        })
        .collect();
    let goal = GaussianReward {
        center: desired.clone(),
        q,
    };
    let mut w = project(&comps, &goal).map_err(other)?.weights;
    let scale: f64 = w.iter().map(|v| v.abs()).sum();
    w.iter_mut()
        .filter(|v| v.abs() <= 1e-9 * scale)
        .for_each(|v| *v = 0.0);
    if w.iter().any(|&v| !(v >= 0.0)) || !(scale > 0.0) {
        return Err(other(format!(
            "{what}: projected weights {w:?} are negative"
        )));
    }
    Ok(w)
}

pub(crate) use crate::experiment::rule::{rule_setting, rule_settings, rule_table};

crate::result_rows! {
    /// One row of every LBC family's `entropy.csv`: one main LBC run and method at one control
    /// step.
    pub struct EntropyRow {
        /// The run's name (a desired angle, a start, a take-off rate…).
        run: String = "run",
        /// The method: `lbc`, or the fixed-weight blend beside it.
        method: String = "method",
        /// Time of the control step (s).
        t_s: f64 = "t",
        /// Normalized entropy of the blend weights α
        /// ([`normalized_entropy`](crate::bellman::combine::normalized_entropy): 1 for uniform
        /// α, 0 for one component).
        entropy: f64 = "entropy",
        /// max_i |α_i − ŵ_i| with ŵ the fixed weights normalized to sum 1 (what the naive blend
        /// uses).
        alpha_deviation: f64 = "alpha_deviation",
    }
}

/// Columns of every LBC family's `entropy.csv` ([`EntropyRow`]'s), for the families that build
/// the table a run at a time with [`push_entropy`]; an array, as those families' `Table::new`
/// calls take it by reference.
pub(crate) const ENTROPY_COLUMNS: [&str; 5] = {
    let c = EntropyRow::COLUMNS;
    assert!(c.len() == 5, "EntropyRow has five columns");
    [c[0], c[1], c[2], c[3], c[4]]
};

/// Ours: α "stays at the fixed weights" in a run when `alpha_deviation` ≤ this at every step;
/// there LBC's control is the fixed-weight average's (to this precision in α) by construction.
pub(crate) const FIXED_ALPHA_TOLERANCE: f64 = 1e-3;

/// max_i |α_i − w_i / Σw| (NaN when Σw is not positive).
pub(crate) fn alpha_deviation(alpha: &[f64], weights: &[f64]) -> f64 {
    let s: f64 = weights.iter().sum();
    if !(s > 0.0) {
        return f64::NAN;
    }
    alpha
        .iter()
        .zip(weights)
        .map(|(a, w)| (a - w / s).abs())
        .fold(0.0, f64::max)
}

/// One run's per-step entropies and α deviations (step k at t = k·dt) as `entropy.csv` rows.
pub(crate) fn entropy_rows(
    run: &str,
    method: &str,
    dt: f64,
    entropy: &[f64],
    deviation: &[f64],
) -> Vec<EntropyRow> {
    entropy
        .iter()
        .zip(deviation)
        .enumerate()
        .map(|(k, (h, d))| EntropyRow {
            run: run.to_string(),
            method: method.to_string(),
            t_s: k as f64 * dt,
            entropy: *h,
            alpha_deviation: *d,
        })
        .collect()
}

/// Appends one run's [`entropy_rows`] to `table` (columns [`ENTROPY_COLUMNS`]).
pub(crate) fn push_entropy(
    table: &mut Table,
    run: &str,
    method: &str,
    dt: f64,
    entropy: &[f64],
    deviation: &[f64],
) {
    for r in entropy_rows(run, method, dt, entropy, deviation) {
        table.push(r.cells());
    }
}

/// Whether α stayed at the fixed weights throughout: every deviation finite and at most `tol`
/// (an empty run never did).
pub(crate) fn stays_fixed(deviations: &[f64], tol: f64) -> bool {
    !deviations.is_empty() && deviations.iter().all(|d| *d <= tol)
}

/// One (run, method) of `entropy.csv`, summarized.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct EntropySummary {
    /// The run's name.
    pub run: String,
    /// The method.
    pub method: String,
    /// Smallest, mean and largest normalized entropy of α over the steps.
    pub min: f64,
    /// Mean over the steps.
    pub mean: f64,
    /// Largest.
    pub max: f64,
    /// Largest α deviation from the fixed weights.
    pub max_deviation: f64,
    /// Whether α stayed at the fixed weights ([`stays_fixed`] with [`FIXED_ALPHA_TOLERANCE`]).
    pub fixed: bool,
}

/// The (run, method) summaries of the rows of an `entropy.csv`, in order of first appearance.
pub(crate) fn summarize_entropy(rows: &[EntropyRow]) -> Vec<EntropySummary> {
    let mut keys: Vec<(&str, &str)> = Vec::new();
    for e in rows {
        if !keys.contains(&(e.run.as_str(), e.method.as_str())) {
            keys.push((&e.run, &e.method));
        }
    }
    keys.into_iter()
        .map(|(r, m)| {
            let of: Vec<&EntropyRow> = rows
                .iter()
                .filter(|e| e.run == r && e.method == m)
                .collect();
            let h: Vec<f64> = of.iter().map(|e| e.entropy).collect();
            let d: Vec<f64> = of.iter().map(|e| e.alpha_deviation).collect();
            EntropySummary {
                run: r.to_string(),
                method: m.to_string(),
                min: h.iter().copied().fold(f64::INFINITY, f64::min),
                mean: h.iter().sum::<f64>() / h.len().max(1) as f64,
                max: h.iter().copied().fold(f64::NEG_INFINITY, f64::max),
                max_deviation: d.iter().copied().fold(0.0, |a, b| {
                    if b.is_nan() || a.is_nan() {
                        f64::NAN
                    } else {
                        a.max(b)
                    }
                }),
                fixed: stays_fixed(&d, FIXED_ALPHA_TOLERANCE),
            }
        })
        .collect()
}

/// The report paragraph on α's entropy over time (from `entropy.csv` in `dir`; empty when the
/// file is absent): a table per LBC run and, where α stayed at the fixed weights, the statement
/// that LBC equals `fixed_blend` there by construction. `one_means` says what entropy 1 means in
/// the family.
pub(crate) fn entropy_section(
    dir: &Path,
    one_means: &str,
    fixed_blend: &str,
) -> Result<String, Error> {
    let Some(rows) = written_rows::<EntropyRow>(dir, "entropy.csv")? else {
        return Ok(String::new());
    };
    let s = summarize_entropy(&rows);
    let sig = crate::experiment::report::sig;
    let mut md = format!(
        "\nα's normalized entropy over time (`entropy.csv`, every control step; {one_means}). α stays at the fixed weights when max_i |α_i − ŵ_i| ≤ {} at every step (ours; ŵ the fixed weights normalized).\n\n| run | method | entropy min | mean | max | max \\|α − ŵ\\| | α stays at the fixed weights |\n| --- | --- | --- | --- | --- | --- | --- |\n",
        sig(FIXED_ALPHA_TOLERANCE)
    );
    for e in &s {
        md.push_str(&format!(
            "| {} | {} | {} | {} | {} | {} | {} |\n",
            e.run,
            e.method,
            sig(e.min),
            sig(e.mean),
            sig(e.max),
            sig(e.max_deviation),
            if e.fixed { "yes" } else { "no" }
        ));
    }
    let fixed: Vec<&str> = s
        .iter()
        .filter(|e| e.method == "lbc" && e.fixed)
        .map(|e| e.run.as_str())
        .collect();
    let lbc = s.iter().filter(|e| e.method == "lbc").count();
    if fixed.is_empty() {
        md.push_str(&format!(
            "\nα leaves the fixed weights at some step in every LBC run here ({lbc}).\n"
        ));
    } else {
        md.push_str(&format!(
            "\nIn {} of the {lbc} LBC runs ({}) α stays at the fixed weights throughout: there LBC equals {fixed_blend} by construction (to the tolerance on α above).\n",
            fixed.len(),
            fixed.join(", ")
        ));
    }
    Ok(md)
}

/// A figure of α's normalized entropy against time, one series per LBC run of the `entropy`
/// table (colour and line style both tell them apart); nothing when the table is absent.
pub(crate) fn entropy_figure(
    fig: &crate::experiment::plot::FigureSink,
    tables: &crate::experiment::output::Tables,
    title: &str,
) -> Result<Vec<std::path::PathBuf>, Error> {
    use crate::experiment::plot::{Figure, Mark, Panel, Series};
    let Some(t) = tables.get("entropy") else {
        return Ok(Vec::new());
    };
    let rows = EntropyRow::from_table(t);
    let mut runs: Vec<&str> = Vec::new();
    for e in &rows {
        if e.method == "lbc" && !runs.contains(&e.run.as_str()) {
            runs.push(&e.run);
        }
    }
    let marks = [Mark::Line, Mark::Dashed, Mark::LinePoints, Mark::Points];
    let series = runs
        .iter()
        .enumerate()
        .map(|(c, r)| {
            let pts = rows
                .iter()
                .filter(|e| e.run == *r && e.method == "lbc")
                .map(|e| (e.t_s, e.entropy))
                .collect();
            Series::line(format!("lbc, {r}"), pts, c).mark(marks[c % marks.len()])
        })
        .collect();
    let panel = Panel {
        title: title.into(),
        x_label: "time (s)".into(),
        y_label: "normalized entropy of α (1 = uniform)".into(),
        series,
        y_range: Some((0.0, 1.05)),
        ..Default::default()
    };
    fig.draw("entropy", &Figure::grid(vec![panel], 1))
}

#[cfg(test)]
mod entropy_tests {
    use super::*;

    #[test]
    fn alpha_stays_fixed_only_within_the_tolerance_at_every_step() {
        assert_eq!(alpha_deviation(&[0.5, 0.5], &[1.0, 1.0]), 0.0);
        assert!((alpha_deviation(&[0.7, 0.3], &[2.0, 2.0]) - 0.2).abs() < 1e-12);
        assert!(alpha_deviation(&[0.5, 0.5], &[0.0, 0.0]).is_nan());
        assert!(stays_fixed(&[0.0, 5e-4, 1e-3], 1e-3));
        assert!(!stays_fixed(&[0.0, 2e-3], 1e-3));
        assert!(!stays_fixed(&[0.0, f64::NAN], 1e-3));
        assert!(!stays_fixed(&[], 1e-3));
        let row = |run: &str, entropy: f64, alpha_deviation: f64| EntropyRow {
            run: run.into(),
            method: "lbc".into(),
            t_s: 0.0,
            entropy,
            alpha_deviation,
        };
        let sum = summarize_entropy(&[
            row("a", 1.0, 0.0),
            row("a", 0.8, 0.1),
            row("b", 1.0, 0.0),
            row("b", 1.0, 1e-4),
        ]);
        assert_eq!(sum.len(), 2);
        assert!(!sum[0].fixed && sum[1].fixed);
        assert!((sum[0].mean - 0.9).abs() < 1e-12 && sum[0].min == 0.8);
    }
}

#[cfg(test)]
mod scale_tests {
    use super::*;

    #[test]
    fn lambda_puts_the_targets_one_unit_apart_and_projection_recovers_an_example() {
        let q = DMatrix::from_diagonal(&DVector::from_vec(vec![4.0, 1.0]));
        let (a, b) = (
            DVector::from_vec(vec![1.0, 0.0]),
            DVector::from_vec(vec![0.0, 2.0]),
        );
        let lambda = scale_lambda(&q, &a, &b);
        assert!((lambda - 8.0).abs() < 1e-12);
        let centers = [a.clone(), b.clone()];
        let w = projected_weights(&q, lambda, &centers, &a, "a").unwrap();
        assert!(w[1] == 0.0 && w[0] > 0.0, "{w:?}");
        let mid = (&a + &b) * 0.5;
        let w = projected_weights(&q, lambda, &centers, &mid, "mid").unwrap();
        assert!((w[0] - w[1]).abs() < 1e-9 * w[0], "{w:?}");
    }
}
