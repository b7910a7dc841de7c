//! The figure: wall time of each physical simulator against its emulators, and the speedup at
//! the training step against the speedup at equal accuracy (`speedup`).

use super::DOLPHIN_IMPLICIT;
use crate::experiment::output::{unique, Tables};
use crate::experiment::plot::{Figure, FigureSink, Mark, Panel, Series};
use crate::experiment::report::sig;
use crate::experiment::Error;
use std::path::PathBuf;

/// Draws the `speedup` figure.
pub(super) fn draw(fig: &FigureSink, tables: &Tables) -> Result<Vec<PathBuf>, Error> {
    let t = tables.require("speedup")?;
    let (model, emu, phys, es, integ) = (
        t.strs("model"),
        t.strs("emulator"),
        t.f64s("physical_s"),
        t.f64s("emulator_s"),
        t.strs("physical_integrator"),
    );
    // One group of bars per physical simulator: model and integrator.
    let group: Vec<String> = (0..model.len())
        .map(|r| format!("{} ({})", model[r], integ[r]))
        .collect();
    let groups = unique(&group);
    let kinds = unique(&emu);
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
            Some((pos(mi, 0), phys[r]))
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
        let rows: Vec<usize> = groups
            .iter()
            .filter_map(|g| (0..model.len()).find(|&r| &group[r] == g && &emu[r] == k))
            .collect();
        let pts = rows
            .iter()
            .map(|&r| {
                let mi = groups.iter().position(|g| *g == group[r]).unwrap_or(0);
                (pos(mi, ki + 1), es[r])
            })
            .collect();
        let text = rows
            .iter()
            .map(|&r| format!("{:.0}×", phys[r] / es[r]))
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
            t.f64s("physical_steps").first().copied().unwrap_or(0.0)
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
        let (em, ee, esp, ej) = (
            eq.strs("model"),
            eq.strs("emulator"),
            eq.f64s("speedup"),
            eq.f64s("substeps"),
        );
        let cats: Vec<String> = (0..em.len())
            .map(|r| format!("{} {}", em[r].trim_start_matches("pendulum_"), ee[r]))
            .collect();
        let at_dt: Vec<(f64, f64)> = (0..em.len())
            .filter_map(|r| {
                let s = (0..model.len()).find(|&q| {
                    model[q] == em[r] && emu[q] == ee[r] && integ[q] != DOLPHIN_IMPLICIT
                })?;
                Some((r as f64 - 0.2, phys[s] / es[s]))
            })
            .collect();
        let at_dt_text = at_dt.iter().map(|p| format!("{:.0}×", p.1)).collect();
        let eq_pts: Vec<(f64, f64)> = (0..em.len()).map(|r| (r as f64 + 0.2, esp[r])).collect();
        let eq_text = (0..em.len())
            .map(|r| format!("{}× (j={})", sig(esp[r]), ej[r]))
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
