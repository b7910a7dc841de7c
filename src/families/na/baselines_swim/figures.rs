//! The figure: each run's best objective against iterations and wall-clock time (`objective`).

use super::job::BaselineRow;
use super::{DAGGER_SUBSTRATE, METHODS};
use crate::experiment::output::Tables;
use crate::experiment::plot::{Figure, FigureSink, Mark, Panel, Series};
use crate::experiment::rows::TableRow;
use crate::experiment::Error;
use std::path::PathBuf;

/// (method, substrate) pairs in first-seen order.
fn curves(method: &[String], substrate: &[String]) -> Vec<(String, String)> {
    let mut out: Vec<(String, String)> = vec![];
    for (m, s) in method.iter().zip(substrate) {
        if !out.iter().any(|(a, b)| a == m && b == s) {
            out.push((m.clone(), s.clone()));
        }
    }
    out
}

/// Draws the `objective` figure.
pub(super) fn draw(fig: &FigureSink, tables: &Tables) -> Result<Vec<PathBuf>, Error> {
    let rows = BaselineRow::from_table(tables.require("baselines")?);
    let meth: Vec<String> = rows.iter().map(|r| r.method.clone()).collect();
    let sub: Vec<String> = rows.iter().map(|r| r.substrate.clone()).collect();
    // `dagger`: the runs on the DAgger net alone, else the others.
    let series = |x: &dyn Fn(&BaselineRow) -> f64, dagger: bool| -> Vec<Series> {
        curves(&meth, &sub)
            .iter()
            .filter(|(_, s)| (s == DAGGER_SUBSTRATE) == dagger)
            .map(|(m, s)| {
                let pts = rows
                    .iter()
                    .filter(|r| r.method == *m && r.substrate == *s && r.objective.is_finite())
                    .map(|r| (x(r), r.objective))
                    .filter(|p| p.0 > 0.0)
                    .collect();
                let color = METHODS.iter().position(|x| x == m).unwrap_or(0);
                // The key names each method once (its colour); the line says the substrate
                // (dashed: the simulator), so the key stays small enough to find a free
                // corner.
                if s == "simulator" {
                    Series::line(String::new(), pts, color).mark(Mark::Dashed)
                } else {
                    Series::line(m.clone(), pts, color).mark(Mark::Solid)
                }
            })
            .collect()
    };
    // Every panel draws the methods in the same colours, so the key is drawn once, in the
    // wall-clock panel: in the iteration panel every corner's key box hid part of a curve
    // (hill_climbing on the simulator around iterations 10-40).
    let mut by_iteration = series(&|r| r.iteration as f64 + 1.0, false);
    by_iteration.iter_mut().for_each(|s| s.label.clear());
    let mut panels = vec![
        Panel {
            title: "dolphin swim: J vs iterations (dashed: simulator)".into(),
            x_label: "iteration + 1 (log)".into(),
            y_label: "best objective J (effort - distance in m)".into(),
            log_x: true,
            series: by_iteration,
            ..Panel::default()
        },
        Panel {
            title: "J vs wall-clock seconds (dashed: simulator)".into(),
            x_label: "wall-clock seconds (log)".into(),
            y_label: "best objective J (effort - distance in m)".into(),
            log_x: true,
            series: series(&|r| r.seconds, false),
            ..Panel::default()
        },
    ];
    let mut on_dagger = series(&|r| r.iteration as f64 + 1.0, true);
    on_dagger.iter_mut().for_each(|s| s.label.clear());
    if !on_dagger.is_empty() {
        panels.push(Panel {
            title: "on the DAgger global net (ours; key: middle panel)".into(),
            x_label: "iteration + 1 (log)".into(),
            y_label: "best objective J on the DAgger net".into(),
            log_x: true,
            series: on_dagger,
            ..Panel::default()
        });
    }
    let cols = panels.len();
    fig.draw("objective", &Figure::grid(panels, cols))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn curves_keep_first_seen_order() {
        let m: Vec<String> = ["a", "a", "b", "a"].map(String::from).to_vec();
        let s: Vec<String> = ["e", "e", "e", "s"].map(String::from).to_vec();
        assert_eq!(
            curves(&m, &s),
            vec![
                ("a".into(), "e".into()),
                ("b".into(), "e".into()),
                ("a".into(), "s".into())
            ]
        );
    }
}
