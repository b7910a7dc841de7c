//! Figures: multi-panel line and scatter charts written as PNG and SVG.
//!
//! Log axes use plotters' logarithmic coordinates (points ≤ 0 are skipped there). The y-axis description is written horizontally above
//! the plotting area: plotters draws it unrotated in PNG output (plotters issue 655), which
//! would overlap the tick labels.
//!
//! Fonts come from the `dejavu` crate (no system fontconfig needed).

use super::output::temp_path;
use super::Error;
use plotters::coord::ranged1d::ValueFormatter;
use plotters::coord::Shift;
use plotters::prelude::*;
use std::path::{Path, PathBuf};
use std::sync::Once;

/// How a series is drawn.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Mark {
    /// A polyline.
    Line,
    /// A dashed polyline.
    Dashed,
    /// Dots.
    Points,
    /// A polyline with dots at the data.
    LinePoints,
    /// A filled bar per point, from the bottom of the y axis up to y, `half_width` x units to
    /// either side of x (bar charts; works on log axes).
    Bars {
        /// Half the bar width in x units.
        half_width: f64,
    },
}

/// One data series.
#[derive(Debug, Clone)]
pub struct Series {
    /// Legend label (empty: not in the legend).
    pub label: String,
    /// Data points (non-finite ones are skipped).
    pub points: Vec<(f64, f64)>,
    /// How to draw it.
    pub mark: Mark,
    /// Index into the palette.
    pub color: usize,
}

impl Series {
    /// A line series.
    pub fn line(label: impl Into<String>, points: Vec<(f64, f64)>, color: usize) -> Self {
        Self {
            label: label.into(),
            points,
            mark: Mark::Line,
            color,
        }
    }
    /// The same series drawn with another mark.
    pub fn mark(mut self, mark: Mark) -> Self {
        self.mark = mark;
        self
    }
}

/// One chart panel.
#[derive(Debug, Clone, Default)]
pub struct Panel {
    /// Title above the panel.
    pub title: String,
    /// x-axis description with unit.
    pub x_label: String,
    /// y-axis description with unit.
    pub y_label: String,
    /// Logarithmic x axis.
    pub log_x: bool,
    /// Logarithmic y axis.
    pub log_y: bool,
    /// The series.
    pub series: Vec<Series>,
    /// Fixed y range (in data units), else fitted.
    pub y_range: Option<(f64, f64)>,
    /// Fixed x range (in data units), else fitted.
    pub x_range: Option<(f64, f64)>,
    /// Where the legend goes.
    pub legend: Legend,
    /// Category names for integer x positions 0, 1, … (a categorical x axis); empty: numeric.
    pub x_categories: Vec<String>,
}

/// Corner of the legend box.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Legend {
    /// Upper right (default).
    #[default]
    UpperRight,
    /// Upper left.
    UpperLeft,
    /// Lower right.
    LowerRight,
    /// Lower left.
    LowerLeft,
}

/// A heat map of values on a regular grid, with a colour bar.
#[derive(Debug, Clone, Default)]
pub struct Heatmap {
    /// Title above the panel.
    pub title: String,
    /// x-axis description with unit.
    pub x_label: String,
    /// y-axis description with unit.
    pub y_label: String,
    /// Centre of the first and last column.
    pub x_range: (f64, f64),
    /// Centre of the first and last row.
    pub y_range: (f64, f64),
    /// Columns.
    pub nx: usize,
    /// Rows.
    pub ny: usize,
    /// Values, row-major with x fastest (`values[j * nx + i]`); non-finite cells are grey.
    pub values: Vec<f64>,
    /// What the colour means, with unit.
    pub value_label: String,
    /// Diverging colours centred on zero (for signed differences).
    pub diverging: bool,
    /// Fixed colour range (values outside are clamped), else fitted to the data.
    pub range: Option<(f64, f64)>,
}

/// A figure: panels laid out in a grid.
#[derive(Debug, Clone)]
pub struct Figure {
    /// Heat-map panels, drawn after the line panels.
    pub heatmaps: Vec<Heatmap>,
    /// Panels, row-major.
    pub panels: Vec<Panel>,
    /// Panels per row.
    pub columns: usize,
    /// Size of one panel in pixels.
    pub panel_size: (u32, u32),
}

impl Figure {
    /// A figure of the given panels, `columns` per row, 640×440 each.
    pub fn grid(panels: Vec<Panel>, columns: usize) -> Self {
        Self {
            heatmaps: Vec::new(),
            panels,
            columns: columns.max(1),
            panel_size: (640, 440),
        }
    }

    /// A figure of heat maps, `columns` per row.
    pub fn heatmaps(maps: Vec<Heatmap>, columns: usize) -> Self {
        Self {
            heatmaps: maps,
            panels: Vec::new(),
            columns: columns.max(1),
            panel_size: (560, 440),
        }
    }

    fn count(&self) -> usize {
        self.panels.len() + self.heatmaps.len()
    }
}

/// Viridis colour at t in [0, 1].
pub fn viridis(t: f64) -> RGBColor {
    const A: [(f64, f64, f64); 5] = [
        (68.0, 1.0, 84.0),
        (59.0, 82.0, 139.0),
        (33.0, 145.0, 140.0),
        (94.0, 201.0, 98.0),
        (253.0, 231.0, 37.0),
    ];
    lerp(&A, t)
}

/// Blue–white–red colour at t in [0, 1] (0.5 is white).
pub fn diverging(t: f64) -> RGBColor {
    const A: [(f64, f64, f64); 3] = [
        (59.0, 76.0, 192.0),
        (235.0, 235.0, 235.0),
        (180.0, 4.0, 38.0),
    ];
    lerp(&A, t)
}

fn lerp(anchors: &[(f64, f64, f64)], t: f64) -> RGBColor {
    let t = if t.is_finite() {
        t.clamp(0.0, 1.0)
    } else {
        0.0
    };
    let x = t * (anchors.len() - 1) as f64;
    let i = (x.floor() as usize).min(anchors.len() - 2);
    let f = x - i as f64;
    let (a, b) = (anchors[i], anchors[i + 1]);
    let c = |p: f64, q: f64| (p + f * (q - p)).round() as u8;
    RGBColor(c(a.0, b.0), c(a.1, b.1), c(a.2, b.2))
}

/// Colour palette (colour-blind-friendly Tableau 10).
pub const PALETTE: [RGBColor; 10] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(127, 127, 127),
    RGBColor(188, 189, 34),
    RGBColor(23, 190, 207),
];

/// Registers the `dejavu` fonts as plotters' "sans-serif" family (once per process); needed
/// before drawing text outside [`FigureSink::draw`].
pub fn ensure_fonts() {
    register_fonts();
}

fn register_fonts() {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| {
        let _ = plotters::style::register_font(
            "sans-serif",
            FontStyle::Normal,
            dejavu::sans::regular(),
        );
        let _ = plotters::style::register_font("sans-serif", FontStyle::Bold, dejavu::sans::bold());
    });
}

/// Where an experiment's figures go: `<dir>/<id>_<name>.png` and `.svg`.
#[derive(Debug, Clone)]
pub struct FigureSink {
    /// The figures folder.
    pub dir: PathBuf,
    /// The experiment id (file name prefix).
    pub id: String,
}

impl FigureSink {
    /// Draws `fig` as `<id>_<name>.png` and `.svg`, atomically; returns both paths.
    pub fn draw(&self, name: &str, fig: &Figure) -> Result<Vec<PathBuf>, Error> {
        register_fonts();
        let rows = fig.count().div_ceil(fig.columns) as u32;
        let cols = fig.columns.min(fig.count()).max(1) as u32;
        let size = (fig.panel_size.0 * cols, fig.panel_size.1 * rows.max(1));
        write_png_svg(&self.dir, &format!("{}_{name}", self.id), size, fig)
    }
}

/// A plotters error on the figure `path` as an [`Error::Plot`].
pub fn perr(path: &Path, message: String) -> Error {
    Error::Plot {
        path: path.display().to_string(),
        message,
    }
}

/// Something drawn the same way on both figure backends (the PNG bitmap and the SVG).
pub trait Drawing {
    /// Draws onto `root`.
    fn draw_on<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<(), String>;
}

impl Drawing for Figure {
    fn draw_on<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<(), String> {
        render(root, self)
    }
}

/// Writes `drawing` as `<dir>/<stem>.png` and `.svg` of `size` pixels, each atomically
/// (temporary file + rename); returns both paths.
pub fn write_png_svg(
    dir: &Path,
    stem: &str,
    size: (u32, u32),
    drawing: &impl Drawing,
) -> Result<Vec<PathBuf>, Error> {
    std::fs::create_dir_all(dir).map_err(|e| Error::Io {
        path: dir.to_path_buf(),
        source: e,
    })?;
    let png = dir.join(format!("{stem}.png"));
    let svg = dir.join(format!("{stem}.svg"));
    {
        let tmp = temp_path(&png);
        let root = BitMapBackend::new(&tmp, size).into_drawing_area();
        drawing.draw_on(&root).map_err(|e| perr(&png, e))?;
        root.present().map_err(|e| perr(&png, e.to_string()))?;
        drop(root);
        std::fs::rename(&tmp, &png).map_err(|e| Error::Io {
            path: png.clone(),
            source: e,
        })?;
    }
    let mut text = String::new();
    {
        let root = SVGBackend::with_string(&mut text, size).into_drawing_area();
        drawing.draw_on(&root).map_err(|e| perr(&svg, e))?;
        root.present().map_err(|e| perr(&svg, e.to_string()))?;
    }
    super::output::atomic_write(&svg, text.as_bytes())?;
    Ok(vec![png, svg])
}

fn tr(v: f64, log: bool) -> Option<f64> {
    let t = if log {
        if v > 0.0 {
            v.log10()
        } else {
            return None;
        }
    } else {
        v
    };
    t.is_finite().then_some(t)
}

fn range(vals: impl Iterator<Item = f64>) -> (f64, f64) {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for v in vals {
        lo = lo.min(v);
        hi = hi.max(v);
    }
    if !lo.is_finite() {
        return (0.0, 1.0);
    }
    if hi - lo < 1e-12 * (1.0 + lo.abs()) {
        return (lo - 0.5, hi + 0.5);
    }
    let pad = 0.05 * (hi - lo);
    (lo - pad, hi + pad)
}

/// Tick label; `snap` > 0 (a linear axis's span) turns round-off around zero into `0`.
/// A tick label: `v` with at most 3 decimals, "0" near zero (relative to the span `snap`).
pub(crate) fn tick(v: f64, snap: f64) -> String {
    if v == 0.0 || v.abs() < 1e-9 * snap {
        "0".into()
    } else if v.abs() >= 1e4 || v.abs() < 1e-3 {
        format!("{v:.1e}")
    } else {
        let s = format!("{v:.3}");
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    }
}

fn render<DB: DrawingBackend>(root: &DrawingArea<DB, Shift>, fig: &Figure) -> Result<(), String> {
    root.fill(&WHITE).map_err(|e| e.to_string())?;
    let rows = fig.count().div_ceil(fig.columns);
    let areas = root.split_evenly((rows.max(1), fig.columns.min(fig.count()).max(1)));
    for (panel, area) in fig.panels.iter().zip(areas.iter()) {
        draw_panel(area, panel).map_err(|e| e.to_string())?;
    }
    for (map, area) in fig.heatmaps.iter().zip(areas.iter().skip(fig.panels.len())) {
        draw_heatmap(area, map).map_err(|e| e.to_string())?;
    }
    Ok(())
}

fn draw_heatmap<DB: DrawingBackend>(
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

fn draw_panel<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    p: &Panel,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
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
                .zip(&data)
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
    let area = area.titled(
        &p.title,
        ("sans-serif", 20).into_font().style(FontStyle::Bold),
    )?;
    let (label_strip, plot_area) = area.split_vertically(22);
    label_strip.draw(&Text::new(
        format!("↑ {}", p.y_label),
        (12, 4),
        ("sans-serif", 15).into_font().color(&BLACK),
    ))?;
    let builder = || {
        let mut b = ChartBuilder::on(&plot_area);
        b.margin(10).x_label_area_size(42).y_label_area_size(62);
        b
    };
    let snap = (
        if p.log_x { 0.0 } else { xr.1 - xr.0 },
        if p.log_y { 0.0 } else { yr.1 - yr.0 },
    );
    match (p.log_x, p.log_y) {
        (false, false) => finish(
            builder().build_cartesian_2d(xr.0..xr.1, yr.0..yr.1)?,
            p,
            data,
            snap,
        ),
        (true, false) => finish(
            builder().build_cartesian_2d((xr.0..xr.1).log_scale(), yr.0..yr.1)?,
            p,
            data,
            snap,
        ),
        (false, true) => finish(
            builder().build_cartesian_2d(xr.0..xr.1, (yr.0..yr.1).log_scale())?,
            p,
            data,
            snap,
        ),
        (true, true) => finish(
            builder().build_cartesian_2d((xr.0..xr.1).log_scale(), (yr.0..yr.1).log_scale())?,
            p,
            data,
            snap,
        ),
    }
}

fn finish<'a, DB, X, Y>(
    mut chart: ChartContext<'a, DB, Cartesian2d<X, Y>>,
    p: &Panel,
    data: Vec<Vec<(f64, f64)>>,
    snap: (f64, f64),
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>>
where
    DB: DrawingBackend + 'a,
    X: Ranged<ValueType = f64> + ValueFormatter<f64>,
    Y: Ranged<ValueType = f64> + ValueFormatter<f64>,
{
    chart
        .configure_mesh()
        .x_desc(p.x_label.as_str())
        .x_label_formatter(&|v| {
            if p.x_categories.is_empty() {
                tick(*v, snap.0)
            } else {
                let i = v.round();
                match p.x_categories.get(i as usize) {
                    Some(name) if (v - i).abs() < 1e-6 && i >= 0.0 => name.clone(),
                    _ => String::new(),
                }
            }
        })
        .y_label_formatter(&|v| tick(*v, snap.1))
        .x_labels(8)
        .y_labels(8)
        .label_style(("sans-serif", 13))
        .axis_desc_style(("sans-serif", 15))
        .light_line_style(RGBColor(235, 235, 235))
        .draw()?;
    let mut any_label = false;
    for (s, pts) in p.series.iter().zip(data) {
        let color = PALETTE[s.color % PALETTE.len()];
        let style = ShapeStyle::from(&color).stroke_width(2);
        if s.mark == Mark::LinePoints {
            chart.draw_series(pts.iter().map(|&q| Circle::new(q, 3, color.filled())))?;
        }
        let anno = match s.mark {
            Mark::Line | Mark::LinePoints => chart.draw_series(LineSeries::new(pts, style))?,
            Mark::Dashed => chart.draw_series(DashedLineSeries::new(pts, 8, 5, style))?,
            Mark::Points => {
                chart.draw_series(pts.iter().map(|&q| Circle::new(q, 2, color.filled())))?
            }
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
            anno.label(s.label.clone()).legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 18, y)], color.stroke_width(3))
            });
        }
    }
    if any_label {
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.85))
            .border_style(RGBColor(180, 180, 180))
            .label_font(("sans-serif", 13))
            .position(match p.legend {
                Legend::UpperRight => SeriesLabelPosition::UpperRight,
                Legend::UpperLeft => SeriesLabelPosition::UpperLeft,
                Legend::LowerRight => SeriesLabelPosition::LowerRight,
                Legend::LowerLeft => SeriesLabelPosition::LowerLeft,
            })
            .draw()?;
    }
    Ok(())
}
