//! The figure: wall time of each physical simulator against its emulators, and the speedup at
//! the training step against the speedup at equal accuracy (`speedup`).

use super::job::{EqualAccuracyRow, SpeedupRow};
use super::DOLPHIN_IMPLICIT;
use crate::experiment::output::{unique, Tables};
use crate::experiment::plot::{Figure, FigureSink, Mark, Panel, Series};
use crate::experiment::report::sig;
use crate::experiment::rows::TableRow;
use crate::experiment::Error;
use std::path::PathBuf;

/// Draws the `speedup` figure.
pub(super) fn draw(fig: &FigureSink, tables: &Tables) -> Result<Vec<PathBuf>, Error> {
    let rows = SpeedupRow::from_table(tables.require("speedup")?);
    // One group of bars per physical simulator: model and integrator.
    let group: Vec<String> = rows
        .iter()
        .map(|r| format!("{} ({})", r.model, r.physical_integrator))
        .collect();
    let groups = unique(&group);
    let kinds = unique(&rows.iter().map(|r| r.emulator.clone()).collect::<Vec<_>>());
    // Groups of bars per model: physical, then each emulator kind.
    let slots = kinds.len() + 1;
    let w = 0.8 / slots as f64;
    let pos = |mi: usize, slot: usize| mi as f64 + (slot as f64 + 0.5) * w - 0.4;
    // Physical bars carry their seconds, emulator bars their speedup (physical / emulator).
    let phys_rows: Vec<(f64, f64)> = groups
        .iter()
        .enumerate()
        .filter_map(|(mi, g)| {
            let r = group.iter().position(|x| x == g)?;
            Some((pos(mi, 0), rows[r].physical_s))
        })
        .collect();
    let phys_text = phys_rows
        .iter()
        .map(|q| format!("{} s", sig(q.1)))
        .collect();
    let mut series = vec![Series::line("physical simulator", phys_rows, 0)
        .mark(Mark::Bars {
            half_width: 0.45 * w,
        })
        .labelled(phys_text)];
    for (ki, k) in kinds.iter().enumerate() {
        let of_kind: Vec<usize> = groups
            .iter()
            .filter_map(|g| (0..rows.len()).find(|&r| &group[r] == g && rows[r].emulator == *k))
            .collect();
        let pts = of_kind
            .iter()
            .map(|&r| {
                let mi = groups.iter().position(|g| *g == group[r]).unwrap_or(0);
                (pos(mi, ki + 1), rows[r].emulator_s)
            })
            .collect();
        let text = of_kind
            .iter()
            .map(|&r| format!("{:.0}×", rows[r].physical_s / rows[r].emulator_s))
            .collect();
        series.push(
            Series::line(format!("{k} (×: speedup)"), pts, ki + 1)
                .mark(Mark::Bars {
                    half_width: 0.45 * w,
                })
                .labelled(text),
        );
    }
    let panel = Panel {
        title: format!(
            "Seconds for the simulated time of {} physical steps (log scale)",
            rows.first().map_or(0.0, |r| r.physical_steps as f64)
        ),
        x_label: "physical simulator".into(),
        x_categories: groups,
        y_label: "wall time (s)".into(),
        log_y: true,
        series,
        ..Panel::default()
    };
    let mut panels = vec![panel];
    // Speedup at the training step against speedup at equal accuracy, per emulator.
    if let Ok(eq) = tables.require("equal_accuracy") {
        let eq = EqualAccuracyRow::from_table(eq);
        let cats: Vec<String> = eq
            .iter()
            .map(|e| format!("{} {}", e.model.trim_start_matches("pendulum_"), e.emulator))
            .collect();
        let at_dt: Vec<(f64, f64)> = eq
            .iter()
            .enumerate()
            .filter_map(|(r, e)| {
                let s = rows.iter().find(|q| {
                    q.model == e.model
                        && q.emulator == e.emulator
                        && q.physical_integrator != DOLPHIN_IMPLICIT
                })?;
                Some((r as f64 - 0.2, s.physical_s / s.emulator_s))
            })
            .collect();
        let at_dt_text = at_dt.iter().map(|p| format!("{:.0}×", p.1)).collect();
        let eq_pts: Vec<(f64, f64)> = eq
            .iter()
            .enumerate()
            .map(|(r, e)| (r as f64 + 0.2, e.speedup))
            .collect();
        let eq_text = eq
            .iter()
            .map(|e| format!("{}× (j={})", sig(e.speedup), e.substeps))
            .collect();
        panels.push(Panel {
                title: "Speedup over the physical simulator at the training δt and at the largest step Δt/j as accurate as the emulator (log scale)".into(),
                x_label: "emulator".into(),
                x_categories: cats,
                y_label: "speedup (physical s / emulator s)".into(),
                log_y: true,
                series: vec![
                    Series::line("at the training δt", at_dt, 0)
                        .mark(Mark::Bars { half_width: 0.18 })
                        .labelled(at_dt_text),
                    Series::line("at equal accuracy", eq_pts, 3)
                        .mark(Mark::Bars { half_width: 0.18 })
                        .labelled(eq_text),
                ],
                ..Panel::default()
            });
    }
    let mut fig_ = Figure::grid(panels, 1);
    fig_.panel_size = (1100, 560);
    fig.draw("speedup", &fig_)
}
