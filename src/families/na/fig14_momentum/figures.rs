//! Figure `objective` of `na_fig14_momentum`: momentum against plain descent, the same through
//! the DAgger net, and the plain learning-rate sweep.

use crate::experiment::output::{Table, Tables};
use crate::experiment::plot::{Figure, FigureSink, Mark, Panel, Series};
use crate::experiment::Error;
use std::path::PathBuf;

/// The (iteration, objective) points of descent `method` at rate `eta` in a table with columns
/// method, eta, iteration, objective (`objective`, `dagger_objective`, `unclipped_objective`).
fn curve(t: &Table, method: &str, eta: f64) -> Vec<(f64, f64)> {
    let (m, e, i, o) = (
        t.strs("method"),
        t.f64s("eta"),
        t.f64s("iteration"),
        t.f64s("objective"),
    );
    (0..m.len())
        .filter(|&r| m[r] == method && e[r] == eta)
        .map(|r| (i[r], o[r]))
        .collect()
}

/// Every figure of the experiment ([`crate::experiment::Family::figures`]).
pub(super) fn figures(fig: &FigureSink, tables: &Tables) -> Result<Vec<PathBuf>, Error> {
    let t = tables.require("objective")?;
    let runs = tables.require("runs")?;
    let (meth, eta) = (t.strs("method"), t.f64s("eta"));
    let plain_eta = runs
        .strs("method")
        .iter()
        .zip(runs.f64s("eta"))
        .filter(|(m, _)| m.as_str() == "plain")
        .map(|(_, e)| e)
        .collect::<Vec<_>>();
    let pick = |mm: &str, e: f64| curve(t, mm, e);
    let mom_eta = (0..meth.len())
        .find(|&r| meth[r] == "momentum")
        .map(|r| eta[r]);
    let mut main = vec![];
    if let Some(e) = mom_eta {
        main.push(Series::line(
            format!("momentum (eta {e})"),
            pick("momentum", e),
            0,
        ));
    }
    // The plain rate of the comparison is the one nearest 1.0.
    if let Some(&e) = plain_eta
        .iter()
        .min_by(|a, b| (*a - 1.0).abs().total_cmp(&(*b - 1.0).abs()))
    {
        let plain = pick("plain", e);
        // The verdict's bar: momentum must reach plain's final J within half the iterations.
        if let (Some(&(x_end, j_end)), Some(&(x0, _))) = (plain.last(), plain.first()) {
            let hi = main
                .iter()
                .chain(std::iter::once(&Series::line("", plain.clone(), 1)))
                .flat_map(|s| s.points.iter().map(|p| p.1))
                .filter(|v| v.is_finite() && *v > 0.0)
                .fold(j_end, f64::max);
            main.push(
                Series::line(
                    "held bar: plain's final J, reached within half the iterations",
                    vec![(x0, j_end), (0.5 * x_end, j_end), (0.5 * x_end, hi)],
                    2,
                )
                .mark(Mark::Dashed),
            );
        }
        main.push(Series::line(format!("plain (eta {e})"), plain, 1).mark(Mark::Dashed));
    }
    // The same two runs through the lander's DAgger net (ours), a panel of their own (the
    // curves lie almost on the Table 1 net's), same colours and line styles.
    let mut dagger = vec![];
    if let Some(dt) = tables.get("dagger_objective").filter(|t| !t.is_empty()) {
        let (dm, de) = (dt.strs("method"), dt.f64s("eta"));
        for (c, (mm, mark)) in [("momentum", Mark::Line), ("plain", Mark::Dashed)]
            .into_iter()
            .enumerate()
        {
            let Some(e) = (0..dm.len()).find(|&r| dm[r] == mm).map(|r| de[r]) else {
                continue;
            };
            let pts = curve(dt, mm, e);
            dagger.push(Series::line(format!("{mm} (eta {e}), DAgger net"), pts, c).mark(mark));
        }
    }
    let sweep = plain_eta
        .iter()
        .enumerate()
        .map(|(i, &e)| Series::line(format!("eta {e}"), pick("plain", e), i))
        .collect();
    let mut panels = vec![
        Panel {
            title: "lander soft landing: momentum vs plain descent".into(),
            x_label: "iteration".into(),
            y_label: "objective J".into(),
            log_y: true,
            series: main,
            ..Panel::default()
        },
        Panel {
            title: "plain descent, learning-rate sweep".into(),
            x_label: "iteration".into(),
            y_label: "objective J".into(),
            log_y: true,
            series: sweep,
            ..Panel::default()
        },
    ];
    if !dagger.is_empty() {
        panels.insert(
            1,
            Panel {
                title: "the same through the lander's DAgger net (ours)".into(),
                x_label: "iteration".into(),
                y_label: "objective J".into(),
                log_y: true,
                series: dagger,
                ..Panel::default()
            },
        );
    }
    // The same sweep with the knots free of the actuators' boxes (ours: the boxes
    // can hide divergence above the stability limit), the start's J drawn as the rule's line.
    if let Some(ut) = tables.get("unclipped_objective").filter(|t| !t.is_empty()) {
        let mut series: Vec<Series> = plain_eta
            .iter()
            .enumerate()
            .map(|(i, &e)| Series::line(format!("eta {e}"), curve(ut, "plain", e), i))
            .collect();
        let (ui, uo) = (ut.f64s("iteration"), ut.f64s("objective"));
        let start = (0..ui.len()).find(|&r| ui[r] == 0.0).map(|r| uo[r]);
        let last = ui.iter().copied().fold(0.0, f64::max);
        if let Some(j0) = start {
            series.push(
                Series::line(
                    "start's J (diverged if the last J ends above)".to_string(),
                    vec![(0.0, j0), (last, j0)],
                    plain_eta.len(),
                )
                .mark(Mark::Dashed),
            );
        }
        panels.push(Panel {
            title: "plain descent, knots not clipped to the boxes (ours)".into(),
            x_label: "iteration".into(),
            y_label: "objective J".into(),
            log_y: true,
            series,
            ..Panel::default()
        });
    }
    let cols = panels.len().min(2);
    fig.draw("objective", &Figure::grid(panels, cols))
}
