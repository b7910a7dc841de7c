//! The figure: each run's best objective against iterations and wall-clock time (`objective`).

use super::{DAGGER_SUBSTRATE, METHODS};
use crate::experiment::output::Tables;
use crate::experiment::plot::{Figure, FigureSink, Mark, Panel, Series};
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
    let t = tables.require("baselines")?;
    let (meth, sub, it, secs, obj) = (
        t.strs("method"),
        t.strs("substrate"),
        t.f64s("iteration"),
        t.f64s("seconds"),
        t.f64s("objective"),
    );
    // `dagger`: the runs on the DAgger net alone, else the others.
    let series = |x: &dyn Fn(usize) -> f64, dagger: bool| -> Vec<Series> {
        curves(&meth, &sub)
            .iter()
            .filter(|(_, s)| (s == DAGGER_SUBSTRATE) == dagger)
            .map(|(m, s)| {
                let pts = (0..meth.len())
                    .filter(|&r| &meth[r] == m && &sub[r] == s && obj[r].is_finite())
                    .map(|r| (x(r), obj[r]))
                    .filter(|p| p.0 > 0.0)
                    .collect();
                let color = METHODS.iter().position(|x| x == m).unwrap_or(0);
                let line = Series::line(format!("{m} ({s})"), pts, color);
                if s == "simulator" {
                    line.mark(Mark::Dashed)
                } else {
                    line
                }
            })
            .collect()
    };
    // The first two panels draw the same series in the same colours, so the key is drawn
    // once, in the wall-clock panel: in the iteration panel every corner's key box hid part
    // of a curve (hill_climbing (simulator) around iterations 10-40).
    let mut by_iteration = series(&|r| it[r] + 1.0, false);
    by_iteration.iter_mut().for_each(|s| s.label.clear());
    let mut panels = vec![
        Panel {
            title: "dolphin swim: objective vs iterations (key: next panel)".into(),
            x_label: "iteration + 1 (log)".into(),
            y_label: "best objective J (effort - distance in m)".into(),
            log_x: true,
            series: by_iteration,
            ..Panel::default()
        },
        Panel {
            title: "dolphin swim: objective vs wall-clock time".into(),
            x_label: "wall-clock seconds (log)".into(),
            y_label: "best objective J (effort - distance in m)".into(),
            log_x: true,
            series: series(&|r| secs[r], false),
            ..Panel::default()
        },
    ];
    let on_dagger = series(&|r| it[r] + 1.0, true);
    if !on_dagger.is_empty() {
        panels.push(Panel {
            title: "the same on the DAgger global net (ours)".into(),
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
