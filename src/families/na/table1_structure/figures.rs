//! Figures: each net's training curves (`training`) and its rollout error against the
//! simulator over 40 super-steps (`rollout`).

use super::rows::{RolloutRow, StructureRow, TrainingRow};
use crate::experiment::output::{unique, Tables};
use crate::experiment::plot::{Figure, FigureSink, Mark, Panel, Series};
use crate::experiment::report::sig;
use crate::experiment::rows::TableRow;
use crate::experiment::rule::rule_setting;
use crate::experiment::Error;
use std::path::PathBuf;

/// Draws the `training` and `rollout` figures.
pub(super) fn draw(fig: &FigureSink, tables: &Tables) -> Result<Vec<PathBuf>, Error> {
    let training = TrainingRow::from_table(tables.require("training")?);
    let names = unique(&training.iter().map(|r| r.net.clone()).collect::<Vec<_>>());
    // The table's errors, after the whole training (rollout fine-tuning included).
    let structure = StructureRow::from_table(tables.require("structure")?);
    let panels = names
        .iter()
        .map(|name| {
            let pick = |v: fn(&TrainingRow) -> f64| -> Vec<(f64, f64)> {
                training
                    .iter()
                    .filter(|r| r.net == *name)
                    .map(|r| (r.iteration as f64, v(r)))
                    .collect()
            };
            let (train, held) = (pick(|r| r.train_error), pick(|r| r.heldout_error));
            let x_end = train.iter().map(|p| p.0).fold(0.0, f64::max);
            let mut series = vec![
                Series::line("train (noisy inputs where set)", train, 0),
                Series::line("held-out", held, 1).mark(Mark::Dashed),
            ];
            if let Some(r) = structure.iter().find(|r| r.net == *name) {
                for (label, v, c, dash) in [
                    ("train, final (Table 1)", r.train_error, 2, 3),
                    ("held-out, final (Table 1)", r.heldout_error, 3, 10),
                ] {
                    series.push(
                        Series::line(label, vec![(0.0, v), (x_end, v)], c)
                            .mark(Mark::Pattern { dash, gap: 4 }),
                    );
                }
            }
            // The verdict's bar on the final held-out error (ours, the run's rule table).
            if let Some(bar) = rule_setting(tables, "heldout_max") {
                series.push(
                    Series::line(
                        format!("rule: held-out below {}", sig(bar)),
                        vec![(0.0, bar), (x_end, bar)],
                        7,
                    )
                    .mark(Mark::Dashed),
                );
            }
            Panel {
                title: format!("{name}: first training stage"),
                x_label: "iteration (CG, L-BFGS) or epoch (momentum)".into(),
                y_label: "MSE per output (normalized)".into(),
                log_y: true,
                series,
                ..Panel::default()
            }
        })
        .collect::<Vec<Panel>>();
    // One legend for the figure, in the first panel: every panel draws the same series.
    let panels: Vec<Panel> = panels
        .into_iter()
        .enumerate()
        .map(|(k, mut p)| {
            if k > 0 {
                for s in &mut p.series {
                    s.label.clear();
                }
            }
            p
        })
        .collect();
    let mut files = fig.draw("training", &Figure::grid(panels, 3))?;
    let rollout = RolloutRow::from_table(tables.require("rollout")?);
    let series = unique(&rollout.iter().map(|r| r.net.clone()).collect::<Vec<_>>())
        .iter()
        .enumerate()
        .map(|(c, name)| {
            let pts = rollout
                .iter()
                .filter(|r| r.net == *name && r.error > 0.0)
                .map(|r| (r.step as f64, r.error))
                .collect();
            Series::line(name, pts, c)
        })
        .collect();
    let panel = Panel {
        title: "emulator vs simulator over 40 super-steps (fresh episodes)".into(),
        x_label: "super-steps k".into(),
        y_label: "mean squared error / state variance".into(),
        log_y: true,
        series,
        ..Panel::default()
    };
    files.extend(fig.draw("rollout", &Figure::grid(vec![panel], 1))?);
    Ok(files)
}
