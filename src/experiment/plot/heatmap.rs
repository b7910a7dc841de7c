//! Heat-map panels: cells coloured by value on a regular grid, with a colour bar.

use super::axes::tick;
use super::style::{diverging, viridis};
use super::Heatmap;
use plotters::coord::Shift;
use plotters::prelude::*;

pub(super) fn draw_heatmap<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    h: &Heatmap,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    let area = area.titled(
        &h.title,
        ("sans-serif", 18).into_font().style(FontStyle::Bold),
    )?;
    let (label_strip, rest) = area.split_vertically(22);
    label_strip.draw(&Text::new(
        format!("↑ {}", h.y_label),
        (12, 4),
        ("sans-serif", 15).into_font().color(&BLACK),
    ))?;
    let (w, _) = rest.dim_in_pixel();
    let (plot_area, bar_area) = rest.split_horizontally(w.saturating_sub(110));
    let finite = h.values.iter().copied().filter(|v| v.is_finite());
    let (mut lo, mut hi) = finite.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
        (a.min(v), b.max(v))
    });
    if !lo.is_finite() {
        (lo, hi) = (0.0, 1.0);
    }
    if h.diverging {
        let m = lo.abs().max(hi.abs()).max(1e-300);
        (lo, hi) = (-m, m);
    }
    if let Some(r) = h.range {
        (lo, hi) = r;
    }
    if hi - lo <= 0.0 {
        hi = lo + 1.0;
    }
    let color = |v: f64| -> RGBColor {
        if !v.is_finite() {
            return RGBColor(160, 160, 160);
        }
        let t = (v - lo) / (hi - lo);
        if h.diverging {
            diverging(t)
        } else {
            viridis(t)
        }
    };
    let dx = if h.nx > 1 {
        (h.x_range.1 - h.x_range.0) / (h.nx - 1) as f64
    } else {
        1.0
    };
    let dy = if h.ny > 1 {
        (h.y_range.1 - h.y_range.0) / (h.ny - 1) as f64
    } else {
        1.0
    };
    let mut chart = ChartBuilder::on(&plot_area)
        .margin(10)
        .x_label_area_size(42)
        .y_label_area_size(56)
        .build_cartesian_2d(
            h.x_range.0 - dx / 2.0..h.x_range.1 + dx / 2.0,
            h.y_range.0 - dy / 2.0..h.y_range.1 + dy / 2.0,
        )?;
    let (sx, sy) = (h.x_range.1 - h.x_range.0, h.y_range.1 - h.y_range.0);
    chart
        .configure_mesh()
        .disable_mesh()
        .x_desc(h.x_label.as_str())
        .x_label_formatter(&|v| tick(*v, sx))
        .y_label_formatter(&|v| tick(*v, sy))
        .label_style(("sans-serif", 13))
        .axis_desc_style(("sans-serif", 15))
        .draw()?;
    chart.draw_series((0..h.ny).flat_map(|j| {
        (0..h.nx).map(move |i| {
            let (x, y) = (h.x_range.0 + i as f64 * dx, h.y_range.0 + j as f64 * dy);
            let v = h.values.get(j * h.nx + i).copied().unwrap_or(f64::NAN);
            Rectangle::new(
                [(x - dx / 2.0, y - dy / 2.0), (x + dx / 2.0, y + dy / 2.0)],
                color(v).filled(),
            )
        })
    }))?;
    // Colour bar.
    let (_, bh) = bar_area.dim_in_pixel();
    let (top, bottom) = (20i32, bh as i32 - 52);
    let steps = 64;
    for k in 0..steps {
        let t0 = k as f64 / steps as f64;
        let y1 = bottom - ((bottom - top) as f64 * t0) as i32;
        let y0 = bottom - ((bottom - top) as f64 * (t0 + 1.0 / steps as f64)) as i32;
        let c = color(lo + (t0 + 0.5 / steps as f64) * (hi - lo));
        bar_area.draw(&Rectangle::new([(8, y0), (28, y1)], c.filled()))?;
    }
    let font = ("sans-serif", 12).into_font().color(&BLACK);
    for k in 0..=4 {
        let t = k as f64 / 4.0;
        let y = bottom - ((bottom - top) as f64 * t) as i32;
        bar_area.draw(&Text::new(
            tick(lo + t * (hi - lo), hi - lo),
            (32, y - 6),
            font.clone(),
        ))?;
    }
    bar_area.draw(&Text::new(h.value_label.clone(), (2, 2), font))?;
    Ok(())
}
