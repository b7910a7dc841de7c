//! Line, scatter and bar panels: the ranges, the legend's corner, the axes, the marks and
//! the key.

use super::axes::{axis_ticks, needs_sci, range, tick_as, tr, Ticked};
use super::legend::{covered_pixels, emptiest_corner, LegendSample};
use super::style::PALETTE;
use super::{Legend, Mark, Panel};
use plotters::coord::combinators::LogCoord;
use plotters::coord::ranged1d::ValueFormatter;
use plotters::coord::types::RangedCoordf64;
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

/// Draws panel `p` on `area`, every text and margin `scale` times its size at a 640-pixel
/// panel (the figure's width decides it, [`font_scale`], so tick labels stay readable when a
/// wide figure is shown at report width).
pub(super) fn draw_panel<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    p: &Panel,
    scale: f64,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    let px = |v: f64| (v * scale).round() as i32;
    // Data in plot coordinates (log10 where the axis is logarithmic) for the ranges.
    let data: Vec<Vec<(f64, f64)>> = p
        .series
        .iter()
        .map(|s| {
            s.points
                .iter()
                .filter(|&&(x, y)| tr(x, p.log_x).is_some() && tr(y, p.log_y).is_some())
                .copied()
                .collect()
        })
        .collect();
    let (xr, yr) = data_ranges(p, &data);
    // The title at the scaled size, or smaller where that would not fit the panel's width
    // (a bold sans-serif character is about 0.6 of the font size wide).
    let chars = p.title.chars().count().max(1) as f64;
    let fit = (0.95 * area.dim_in_pixel().0 as f64 / (0.6 * chars)).floor();
    let title_size = (px(20.0) as f64).min(fit).max(10.0);
    // A strip above the title, so a top row's title does not touch the figure's edge.
    let area = area.margin(px(8.0), 0, 0, 0);
    let area = area.titled(
        &p.title,
        ("sans-serif", title_size)
            .into_font()
            .style(FontStyle::Bold),
    )?;
    let (label_strip, plot_area) = area.split_vertically(px(22.0));
    label_strip.draw(&Text::new(
        format!("↑ {}", p.y_label),
        (px(12.0), px(4.0)),
        ("sans-serif", px(15.0)).into_font().color(&BLACK),
    ))?;
    let (corner, yr) = legend_corner(p, &data, (xr, yr), plot_area.dim_in_pixel(), scale);
    let builder = || {
        let mut b = ChartBuilder::on(&plot_area);
        b.margin(px(10.0))
            .x_label_area_size(px(42.0))
            .y_label_area_size(px(62.0));
        b
    };
    let snap = (
        if p.log_x { 0.0 } else { xr.1 - xr.0 },
        if p.log_y { 0.0 } else { yr.1 - yr.0 },
    );
    let xt = x_ticks(p, xr);
    let yt = axis_ticks(yr.0, yr.1, p.log_y);
    let sci = (
        p.x_categories.is_empty() && p.x_ticks.is_empty() && needs_sci(&xt, snap.0),
        needs_sci(&yt, snap.1),
    );
    match (p.log_x, p.log_y) {
        (false, false) => finish(
            builder().build_cartesian_2d(
                Ticked::new(RangedCoordf64::from(xr.0..xr.1), xt.clone()),
                Ticked::new(RangedCoordf64::from(yr.0..yr.1), yt.clone()),
            )?,
            p,
            data,
            (snap, sci, corner, scale),
        ),
        (true, false) => finish(
            builder().build_cartesian_2d(
                Ticked::new(LogCoord::from((xr.0..xr.1).log_scale()), xt.clone()),
                Ticked::new(RangedCoordf64::from(yr.0..yr.1), yt.clone()),
            )?,
            p,
            data,
            (snap, sci, corner, scale),
        ),
        (false, true) => finish(
            builder().build_cartesian_2d(
                Ticked::new(RangedCoordf64::from(xr.0..xr.1), xt.clone()),
                Ticked::new(LogCoord::from((yr.0..yr.1).log_scale()), yt.clone()),
            )?,
            p,
            data,
            (snap, sci, corner, scale),
        ),
        (true, true) => finish(
            builder().build_cartesian_2d(
                Ticked::new(LogCoord::from((xr.0..xr.1).log_scale()), xt.clone()),
                Ticked::new(LogCoord::from((yr.0..yr.1).log_scale()), yt.clone()),
            )?,
            p,
            data,
            (snap, sci, corner, scale),
        ),
    }
}

/// The x and y ranges: the panel's own, else the data's (`data` in plot coordinates, bars
/// extending half a width to either side of their x).
fn data_ranges(p: &Panel, data: &[Vec<(f64, f64)>]) -> ((f64, f64), (f64, f64)) {
    let span = |vals: Vec<f64>, log: bool| -> (f64, f64) {
        let t: Vec<f64> = vals.into_iter().filter_map(|v| tr(v, log)).collect();
        let (a, b) = range(t.into_iter());
        if log {
            (10f64.powf(a), 10f64.powf(b))
        } else {
            (a, b)
        }
    };
    // Bars extend half a width to either side of their x.
    let xr = match p.x_range {
        Some(r) => r,
        None => span(
            p.series
                .iter()
                .zip(data)
                .flat_map(|(s, pts)| {
                    let hw = match s.mark {
                        Mark::Bars { half_width } => half_width,
                        _ => 0.0,
                    };
                    pts.iter().flat_map(move |q| [q.0 - hw, q.0 + hw])
                })
                .collect(),
            p.log_x,
        ),
    };
    let yr = match p.y_range {
        Some(r) => r,
        None => span(data.iter().flatten().map(|q| q.1).collect(), p.log_y),
    };
    (xr, yr)
}

/// The legend's corner, chosen before drawing on a plot area of `dims` pixels, and the y
/// range: where every corner would cover data and the y range is ours to choose, its top is
/// raised to leave room for the legend.
fn legend_corner(
    p: &Panel,
    data: &[Vec<(f64, f64)>],
    (xr, mut yr): ((f64, f64), (f64, f64)),
    (w, h): (u32, u32),
    scale: f64,
) -> (Legend, (f64, f64)) {
    let px = |v: f64| (v * scale).round() as i32;
    let labels: Vec<usize> = p
        .series
        .iter()
        .filter(|s| !s.label.is_empty())
        .map(|s| s.label.chars().count())
        .collect();
    let mut corner = p.legend;
    if corner == Legend::Auto && !labels.is_empty() {
        let plot_px = ((w as i32 - px(82.0)).max(50), (h as i32 - px(62.0)).max(50));
        let size = (
            labels.iter().copied().max().unwrap_or(0) as i32 * px(8.0) + px(40.0),
            labels.len() as i32 * px(19.0) + px(10.0),
        );
        let place = |yr: (f64, f64)| {
            let cover = covered_pixels(p, data, (xr, yr), plot_px);
            emptiest_corner(((0, 0), plot_px), size, &cover)
        };
        let (c, n) = place(yr);
        corner = c;
        if n > 0 && p.y_range.is_none() && size.1 + 12 < plot_px.1 / 2 {
            let (t0, t1) = (tr(yr.0, p.log_y), tr(yr.1, p.log_y));
            if let (Some(t0), Some(t1)) = (t0, t1) {
                let t1 = t0 + (t1 - t0) * plot_px.1 as f64 / (plot_px.1 - size.1 - 12) as f64;
                let raised = (yr.0, if p.log_y { 10f64.powf(t1) } else { t1 });
                let (c2, n2) = place(raised);
                if n2 < n {
                    (corner, yr) = (c2, raised);
                }
            }
        }
    }
    (corner, yr)
}

/// The x axis's ticks: the panel's own within the range, else the axis's, or one per
/// category.
fn x_ticks(p: &Panel, xr: (f64, f64)) -> Vec<f64> {
    if !p.x_ticks.is_empty() {
        p.x_ticks
            .iter()
            .map(|t| t.0)
            .filter(|v| (xr.0.min(xr.1)..=xr.0.max(xr.1)).contains(v))
            .collect()
    } else if p.x_categories.is_empty() {
        axis_ticks(xr.0, xr.1, p.log_x)
    } else {
        (0..p.x_categories.len())
            .map(|i| i as f64)
            .filter(|v| (xr.0.min(xr.1)..=xr.0.max(xr.1)).contains(v))
            .collect()
    }
}

fn finish<'a, DB, X, Y>(
    mut chart: ChartContext<'a, DB, Cartesian2d<X, Y>>,
    p: &Panel,
    data: Vec<Vec<(f64, f64)>>,
    (snap, sci, corner, scale): ((f64, f64), (bool, bool), Legend, f64),
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>>
where
    DB: DrawingBackend + 'a,
    X: Ranged<ValueType = f64> + ValueFormatter<f64>,
    Y: Ranged<ValueType = f64> + ValueFormatter<f64>,
{
    let px = |v: f64| (v * scale).round() as i32;
    chart
        .configure_mesh()
        .x_desc(p.x_label.as_str())
        .x_label_formatter(&|v| {
            if !p.x_ticks.is_empty() {
                let tol = 1e-9 * (snap.0.abs() + 1.0);
                p.x_ticks
                    .iter()
                    .find(|t| (t.0 - v).abs() <= tol)
                    .map_or(String::new(), |t| t.1.clone())
            } else if p.x_integer && v.fract() != 0.0 {
                String::new()
            } else if p.x_categories.is_empty() {
                tick_as(*v, snap.0, sci.0)
            } else {
                let i = v.round();
                match p.x_categories.get(i as usize) {
                    Some(name) if (v - i).abs() < 1e-6 && i >= 0.0 => name.clone(),
                    _ => String::new(),
                }
            }
        })
        .y_label_formatter(&|v| tick_as(*v, snap.1, sci.1))
        .label_style(("sans-serif", px(13.0)))
        .axis_desc_style(("sans-serif", px(15.0)))
        .bold_line_style(RGBColor(225, 225, 225))
        .light_line_style(RGBColor(235, 235, 235))
        .draw()?;
    let mut any_label = false;
    let marks = p.series_marks();
    let (width, dot) = (px(2.0).max(1) as u32, px(3.0).max(2) as u32);
    for ((s, pts), &mark) in p.series.iter().zip(data).zip(&marks) {
        let color = PALETTE[s.color % PALETTE.len()];
        let style = ShapeStyle::from(&color).stroke_width(width);
        if mark == Mark::LinePoints {
            chart.draw_series(pts.iter().map(|&q| Circle::new(q, dot, color.filled())))?;
        }
        if !s.point_labels.is_empty() {
            let font = ("sans-serif", px(12.0))
                .into_font()
                .color(&BLACK)
                .pos(Pos::new(HPos::Center, VPos::Bottom));
            chart.draw_series(
                s.points
                    .iter()
                    .zip(&s.point_labels)
                    .filter(|(q, _)| pts.contains(q))
                    .map(|(&q, text)| {
                        EmptyElement::at(q) + Text::new(text.clone(), (0, -4), font.clone())
                    }),
            )?;
        }
        let dash = |d: u32| (d as f64 * scale).round().max(1.0) as u32;
        let anno = match mark {
            Mark::Line | Mark::Solid | Mark::LinePoints => {
                chart.draw_series(LineSeries::new(pts, style))?
            }
            Mark::Dashed => {
                chart.draw_series(DashedLineSeries::new(pts, dash(8), dash(5), style))?
            }
            Mark::Pattern { dash: d, gap } => {
                chart.draw_series(DashedLineSeries::new(pts, dash(d), dash(gap), style))?
            }
            Mark::Points => chart.draw_series(
                pts.iter()
                    .map(|&q| Circle::new(q, (dot - 1).max(2), color.filled())),
            )?,
            Mark::Area => chart.draw_series(std::iter::once(Polygon::new(
                pts.clone(),
                color.mix(0.18).filled(),
            )))?,
            Mark::Bars { half_width } => {
                let bottom = chart.y_range().start;
                chart.draw_series(pts.iter().map(|&(x, y)| {
                    Rectangle::new(
                        [(x - half_width, bottom), (x + half_width, y)],
                        color.filled(),
                    )
                }))?
            }
        };
        if !s.label.is_empty() {
            any_label = true;
            let sample = LegendSample::of(mark);
            anno.label(s.label.clone()).legend(move |(x, y)| {
                // One element type for every mark: unused parts are empty or transparent.
                let piece = |k: usize| sample.pieces.get(k).cloned().unwrap_or_default();
                let none = color.mix(0.0).filled();
                EmptyElement::at((x, y))
                    + PathElement::new(piece(0), color.stroke_width(3))
                    + PathElement::new(piece(1), color.stroke_width(3))
                    + PathElement::new(piece(2), color.stroke_width(3))
                    + PathElement::new(piece(3), color.stroke_width(3))
                    + Circle::new(
                        (9, 0),
                        sample.dot.unwrap_or(0),
                        if sample.dot.is_some() {
                            color.filled()
                        } else {
                            none
                        },
                    )
                    + Rectangle::new(
                        sample.bar.unwrap_or([(0, 0), (0, 0)]),
                        if sample.bar.is_some() {
                            color.filled()
                        } else {
                            none
                        },
                    )
            });
        }
    }
    if any_label {
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.85))
            .border_style(RGBColor(180, 180, 180))
            .label_font(("sans-serif", px(13.0)))
            .position(match corner {
                Legend::Auto | Legend::UpperRight => SeriesLabelPosition::UpperRight,
                Legend::UpperLeft => SeriesLabelPosition::UpperLeft,
                Legend::LowerRight => SeriesLabelPosition::LowerRight,
                Legend::LowerLeft => SeriesLabelPosition::LowerLeft,
            })
            .draw()?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::experiment::plot::{Figure, FigureSink, Series};

    #[test]
    fn a_chart_with_every_mark_and_log_axes_draws() {
        let d = tempfile::tempdir().unwrap();
        let pts: Vec<(f64, f64)> = (1..20).map(|i| (i as f64, (i as f64).powi(2))).collect();
        let series = vec![
            Series::line("line", pts.clone(), 0),
            Series::line("dashed", pts.clone(), 1).mark(Mark::Dashed),
            Series::line("points", pts.clone(), 2).mark(Mark::Points),
            Series::line("line+points", pts.clone(), 3).mark(Mark::LinePoints),
            Series::line("bars", pts, 4).mark(Mark::Bars { half_width: 0.3 }),
        ];
        let panel = |log_x, log_y| Panel {
            title: "t".into(),
            x_label: "x (m)".into(),
            y_label: "y (m)".into(),
            log_x,
            log_y,
            series: series.clone(),
            ..Panel::default()
        };
        let fig = Figure::grid(
            vec![
                panel(false, false),
                panel(true, false),
                panel(false, true),
                panel(true, true),
            ],
            2,
        );
        let sink = FigureSink {
            dir: d.path().to_path_buf(),
            id: "x".into(),
        };
        for p in sink.draw("marks", &fig).unwrap() {
            assert!(std::fs::metadata(p).unwrap().len() > 1000);
        }
    }
}
