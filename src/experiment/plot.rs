//! Figures: multi-panel line and scatter charts written as PNG and SVG.
//!
//! Log axes use plotters' logarithmic coordinates (points ≤ 0 are skipped there). The y-axis description is written horizontally above
//! the plotting area: plotters draws it unrotated in PNG output (plotters issue 655), which
//! would overlap the tick labels.
//!
//! Fonts come from the `dejavu` crate (no system fontconfig needed).

use super::output::{rename_into_place, temp_path};
use super::Error;
use plotters::coord::combinators::LogCoord;
use plotters::coord::ranged1d::{DefaultFormatting, KeyPointHint, ValueFormatter};
use plotters::coord::types::RangedCoordf64;
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};
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
    /// Text written at each point (above a bar, beside a dot), aligned with `points`; empty:
    /// none.
    pub point_labels: Vec<String>,
}

impl Series {
    /// A line series.
    pub fn line(label: impl Into<String>, points: Vec<(f64, f64)>, color: usize) -> Self {
        Self {
            label: label.into(),
            points,
            mark: Mark::Line,
            color,
            point_labels: Vec::new(),
        }
    }
    /// The same series with a text at each point (e.g. a bar's value written on it).
    pub fn labelled(mut self, labels: Vec<String>) -> Self {
        self.point_labels = labels;
        self
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
    /// Whether x counts something (an index): ticks between whole numbers get no label.
    pub x_integer: bool,
}

/// Corner of the legend box.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Legend {
    /// The corner whose legend-sized box covers the fewest drawn data (default; ties go to
    /// upper right, upper left, lower right, lower left in that order).
    #[default]
    Auto,
    /// Upper right.
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

    /// Size in pixels: the panel size times the grid.
    fn size(&self) -> (u32, u32) {
        let rows = self.count().div_ceil(self.columns) as u32;
        let cols = self.columns.min(self.count()).max(1) as u32;
        (self.panel_size.0 * cols, self.panel_size.1 * rows.max(1))
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
        write_png_svg(&self.dir, &format!("{}_{name}", self.id), fig.size(), fig)
    }

    /// Draws `frames` (figures of one layout, sized by the first) as the animated GIF
    /// `<id>_<name>.gif`, each frame shown for `delay_cs` hundredths of a second, atomically;
    /// returns its path. Each frame carries its own caption (e.g. the time in a panel title).
    pub fn gif(&self, name: &str, frames: &[Figure], delay_cs: u32) -> Result<PathBuf, Error> {
        register_fonts();
        let gif = self.dir.join(format!("{}_{name}.gif", self.id));
        let size = frames
            .first()
            .ok_or_else(|| perr(&gif, "an animation needs at least one frame".into()))?
            .size();
        write_gif_atomically(&gif, size, delay_cs.max(1) * 10, |root| {
            for f in frames {
                render(root, f)?;
                root.present().map_err(|x| x.to_string())?;
            }
            Ok(())
        })?;
        Ok(gif)
    }
}

/// Writes the animated GIF `gif` of `size` pixels, `delay_ms` between frames, atomically (a
/// temporary file beside it, renamed when complete; its folder is created): `draw` draws each
/// frame on the root area and calls `present()` after each. The one GIF path every animation
/// uses ([`FigureSink::gif`], the mass-spring films, NeuroAnimator's task animations).
pub fn write_gif_atomically(
    gif: &Path,
    size: (u32, u32),
    delay_ms: u32,
    draw: impl FnOnce(&DrawingArea<BitMapBackend<'_>, Shift>) -> Result<(), String>,
) -> Result<(), Error> {
    if let Some(dir) = gif.parent() {
        std::fs::create_dir_all(dir).map_err(|e| Error::Io {
            path: dir.to_path_buf(),
            source: e,
        })?;
    }
    let tmp = temp_path(gif);
    let made = (|| {
        let root = BitMapBackend::gif(&tmp, size, delay_ms)
            .map_err(|x| perr(gif, x.to_string()))?
            .into_drawing_area();
        draw(&root).map_err(|m| perr(gif, m))
    })();
    rename_into_place(&tmp, gif, made)
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
    let tmp = temp_path(&png);
    let made = (|| {
        let root = BitMapBackend::new(&tmp, size).into_drawing_area();
        drawing.draw_on(&root).map_err(|e| perr(&png, e))?;
        root.present().map_err(|e| perr(&png, e.to_string()))
    })();
    rename_into_place(&tmp, &png, made)?;
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

/// Whether an axis's ticks need scientific notation (one of them is >= 1e4 or < 1e-3 in
/// magnitude and not zero; whole numbers up to 1e6 stay plain): then every label of that axis
/// is written so.
fn needs_sci(ticks: &[f64], snap: f64) -> bool {
    let whole = ticks.iter().all(|v| v.fract() == 0.0 && v.abs() < 1e6);
    !whole
        && ticks
            .iter()
            .any(|&v| tick(v, snap) != "0" && (v.abs() >= 1e4 || v.abs() < 1e-3))
}

/// A tick label in one axis-wide format: scientific (`2.5e-5`, `1e3`) when `sci`, else [`tick`].
pub(crate) fn tick_as(v: f64, snap: f64, sci: bool) -> String {
    if !sci && v.fract() == 0.0 && v.abs() < 1e6 {
        return if v == 0.0 {
            "0".into()
        } else {
            format!("{v:.0}")
        };
    }
    let plain = tick(v, snap);
    if !sci || plain == "0" {
        return plain;
    }
    let s = format!("{v:.2e}");
    match s.split_once('e') {
        Some((m, e)) => {
            let m = if m.contains('.') {
                m.trim_end_matches('0').trim_end_matches('.')
            } else {
                m
            };
            format!("{m}e{e}")
        }
        None => s,
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
    let mut yr = match p.y_range {
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
    // The legend's corner, chosen before drawing; where every corner would cover data and the
    // y range is ours to choose, the top is raised to leave room for it.
    let labels: Vec<usize> = p
        .series
        .iter()
        .filter(|s| !s.label.is_empty())
        .map(|s| s.label.chars().count())
        .collect();
    let mut corner = p.legend;
    if corner == Legend::Auto && !labels.is_empty() {
        let (w, h) = plot_area.dim_in_pixel();
        let px = ((w as i32 - 82).max(50), (h as i32 - 62).max(50));
        let size = (
            labels.iter().copied().max().unwrap_or(0) as i32 * 8 + 40,
            labels.len() as i32 * 19 + 10,
        );
        let place = |yr: (f64, f64)| {
            let cover = covered_pixels(p, &data, (xr, yr), px);
            emptiest_corner(((0, 0), px), size, &cover)
        };
        let (c, n) = place(yr);
        corner = c;
        if n > 0 && p.y_range.is_none() && size.1 + 12 < px.1 / 2 {
            let (t0, t1) = (tr(yr.0, p.log_y), tr(yr.1, p.log_y));
            if let (Some(t0), Some(t1)) = (t0, t1) {
                let t1 = t0 + (t1 - t0) * px.1 as f64 / (px.1 - size.1 - 12) as f64;
                let raised = (yr.0, if p.log_y { 10f64.powf(t1) } else { t1 });
                let (c2, n2) = place(raised);
                if n2 < n {
                    (corner, yr) = (c2, raised);
                }
            }
        }
    }
    let builder = || {
        let mut b = ChartBuilder::on(&plot_area);
        b.margin(10).x_label_area_size(42).y_label_area_size(62);
        b
    };
    let snap = (
        if p.log_x { 0.0 } else { xr.1 - xr.0 },
        if p.log_y { 0.0 } else { yr.1 - yr.0 },
    );
    let xt = if p.x_categories.is_empty() {
        axis_ticks(xr.0, xr.1, p.log_x)
    } else {
        (0..p.x_categories.len())
            .map(|i| i as f64)
            .filter(|v| (xr.0.min(xr.1)..=xr.0.max(xr.1)).contains(v))
            .collect()
    };
    let yt = axis_ticks(yr.0, yr.1, p.log_y);
    let sci = (
        p.x_categories.is_empty() && needs_sci(&xt, snap.0),
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
            (snap, sci, corner),
        ),
        (true, false) => finish(
            builder().build_cartesian_2d(
                Ticked::new(LogCoord::from((xr.0..xr.1).log_scale()), xt.clone()),
                Ticked::new(RangedCoordf64::from(yr.0..yr.1), yt.clone()),
            )?,
            p,
            data,
            (snap, sci, corner),
        ),
        (false, true) => finish(
            builder().build_cartesian_2d(
                Ticked::new(RangedCoordf64::from(xr.0..xr.1), xt.clone()),
                Ticked::new(LogCoord::from((yr.0..yr.1).log_scale()), yt.clone()),
            )?,
            p,
            data,
            (snap, sci, corner),
        ),
        (true, true) => finish(
            builder().build_cartesian_2d(
                Ticked::new(LogCoord::from((xr.0..xr.1).log_scale()), xt.clone()),
                Ticked::new(LogCoord::from((yr.0..yr.1).log_scale()), yt.clone()),
            )?,
            p,
            data,
            (snap, sci, corner),
        ),
    }
}

/// An axis with our own labelled ticks ([`axis_ticks`]) over plotters' linear or log axis.
struct Ticked<R> {
    inner: R,
    ticks: Vec<f64>,
}

impl<R> Ticked<R> {
    fn new(inner: R, ticks: Vec<f64>) -> Self {
        Self { inner, ticks }
    }
}

impl<R: Ranged<ValueType = f64>> Ranged for Ticked<R> {
    type FormatOption = DefaultFormatting;
    type ValueType = f64;
    fn map(&self, value: &f64, limit: (i32, i32)) -> i32 {
        self.inner.map(value, limit)
    }
    fn key_points<Hint: KeyPointHint>(&self, _hint: Hint) -> Vec<f64> {
        self.ticks.clone()
    }
    fn range(&self) -> std::ops::Range<f64> {
        self.inner.range()
    }
}

/// A round step near `span / 6` (1, 2, 2.5 or 5 times a power of ten).
fn nice_step(span: f64) -> f64 {
    let raw = span.abs() / 6.0;
    let p = 10f64.powf(raw.log10().floor());
    [1.0, 2.0, 2.5, 5.0, 10.0]
        .iter()
        .map(|m| m * p)
        .find(|&s| s >= raw)
        .unwrap_or(10.0 * p)
}

/// Multiples of `step` in [lo, hi].
fn multiples(lo: f64, hi: f64, step: f64) -> Vec<f64> {
    let first = (lo / step - 1e-9).ceil() as i64;
    let last = (hi / step + 1e-9).floor() as i64;
    (first..=last).map(|k| k as f64 * step).collect()
}

/// The labelled ticks of an axis over [lo, hi]: round values, at least 4 of them wherever the
/// range allows. Linear axes: multiples of a 1-2-2.5-5 step. Log axes: powers of ten, then
/// 1-2-5 and 1…9 multiples of them where a decade gives too few, then round linear values for
/// ranges narrower than a factor of about 2; more than 10 decades are thinned.
pub fn axis_ticks(lo: f64, hi: f64, log: bool) -> Vec<f64> {
    let (lo, hi) = (lo.min(hi), lo.max(hi));
    if !(lo.is_finite() && hi.is_finite()) || hi <= lo {
        return Vec::new();
    }
    let linear = |lo: f64, hi: f64| {
        let mut step = nice_step(hi - lo);
        let mut t = multiples(lo, hi, step);
        while t.len() < 4 && step > 0.0 {
            step /= 2.0;
            t = multiples(lo, hi, step);
        }
        t
    };
    if !log || lo <= 0.0 {
        return linear(lo, hi);
    }
    let (d0, d1) = (lo.log10().floor() as i32, hi.log10().ceil() as i32);
    let within = |v: &f64| *v >= lo * (1.0 - 1e-9) && *v <= hi * (1.0 + 1e-9);
    for mults in [
        &[1.0][..],
        &[1.0, 2.0, 5.0],
        &[1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0],
    ] {
        let t: Vec<f64> = (d0..=d1)
            .flat_map(|d| mults.iter().map(move |m| m * 10f64.powi(d)))
            .filter(within)
            .collect();
        if t.len() >= 4 {
            let every = t.len().div_ceil(10);
            if every == 1 {
                return t;
            }
            if mults.len() > 1 {
                return t.into_iter().step_by(every).collect();
            }
            // Thin to decades whose exponent is a multiple of `every` (1e-4, 1e-2, 1e0, …).
            let aligned: Vec<f64> = t
                .iter()
                .copied()
                .filter(|v| (v.log10().round() as i64).rem_euclid(every as i64) == 0)
                .collect();
            return if aligned.len() >= 4 {
                aligned
            } else {
                t.into_iter().step_by(every).collect()
            };
        }
    }
    linear(lo, hi)
}

/// The legend corner for `Legend::Auto`: the one whose box of `size` pixels (inside `area`'s
/// pixel rectangle) covers the fewest of the drawn data's pixels `points` (polylines sampled
/// every few pixels by the caller).
pub fn emptiest_corner(
    area: ((i32, i32), (i32, i32)),
    size: (i32, i32),
    points: &[(i32, i32)],
) -> (Legend, usize) {
    let ((x0, y0), (x1, y1)) = area;
    let (w, h) = (size.0 + 12, size.1 + 12);
    let boxes = [
        (Legend::UpperRight, (x1 - w, y0, x1, y0 + h)),
        (Legend::UpperLeft, (x0, y0, x0 + w, y0 + h)),
        (Legend::LowerRight, (x1 - w, y1 - h, x1, y1)),
        (Legend::LowerLeft, (x0, y1 - h, x0 + w, y1)),
    ];
    let covered = |(a, b, c, d): (i32, i32, i32, i32)| {
        points
            .iter()
            .filter(|&&(x, y)| x >= a && x <= c && y >= b && y <= d)
            .count()
    };
    boxes
        .iter()
        .map(|&(corner, b)| (corner, covered(b)))
        .min_by_key(|&(_, n)| n)
        .unwrap_or((Legend::UpperRight, 0))
}

/// The pixels (in a `px`-sized plotting rectangle, y down) that a panel's drawn data cover:
/// points, polylines sampled every 3 pixels, bars every 4 pixels up from the axis.
fn covered_pixels(
    p: &Panel,
    data: &[Vec<(f64, f64)>],
    (xr, yr): ((f64, f64), (f64, f64)),
    px: (i32, i32),
) -> Vec<(i32, i32)> {
    let axis = |r: (f64, f64), log: bool| (tr(r.0, log), tr(r.1, log));
    let (Some(x0), Some(x1)) = axis(xr, p.log_x) else {
        return Vec::new();
    };
    let (Some(y0), Some(y1)) = axis(yr, p.log_y) else {
        return Vec::new();
    };
    let map = |(x, y): (f64, f64)| -> Option<(i32, i32)> {
        let u = (tr(x, p.log_x)? - x0) / (x1 - x0);
        let v = (tr(y, p.log_y)? - y0) / (y1 - y0);
        (u.is_finite() && v.is_finite()).then(|| {
            (
                (u.clamp(-1.0, 2.0) * px.0 as f64) as i32,
                ((1.0 - v.clamp(-1.0, 2.0)) * px.1 as f64) as i32,
            )
        })
    };
    let mut out = Vec::new();
    for (s, pts) in p.series.iter().zip(data) {
        let pix: Vec<(i32, i32)> = pts.iter().filter_map(|&q| map(q)).collect();
        match s.mark {
            Mark::Points => out.extend(&pix),
            Mark::Bars { half_width } => {
                for &(x, y) in pts {
                    let (Some(a), Some(b)) = (map((x - half_width, y)), map((x + half_width, y)))
                    else {
                        continue;
                    };
                    for xx in (a.0..=b.0).step_by(4).chain([b.0]) {
                        out.extend((a.1.min(px.1)..=px.1).step_by(4).map(|yy| (xx, yy)));
                    }
                }
            }
            _ => {
                out.extend(pix.first());
                for w in pix.windows(2) {
                    let (dx, dy) = (w[1].0 - w[0].0, w[1].1 - w[0].1);
                    let n = (dx.abs().max(dy.abs()) / 3).clamp(1, 400);
                    out.extend((1..=n).map(|k| (w[0].0 + dx * k / n, w[0].1 + dy * k / n)));
                }
            }
        }
    }
    out
}

fn finish<'a, DB, X, Y>(
    mut chart: ChartContext<'a, DB, Cartesian2d<X, Y>>,
    p: &Panel,
    data: Vec<Vec<(f64, f64)>>,
    (snap, sci, corner): ((f64, f64), (bool, bool), Legend),
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
            if p.x_integer && v.fract() != 0.0 {
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
        .label_style(("sans-serif", 13))
        .axis_desc_style(("sans-serif", 15))
        .bold_line_style(RGBColor(225, 225, 225))
        .light_line_style(RGBColor(235, 235, 235))
        .draw()?;
    let mut any_label = false;
    for (s, pts) in p.series.iter().zip(data) {
        let color = PALETTE[s.color % PALETTE.len()];
        let style = ShapeStyle::from(&color).stroke_width(2);
        if s.mark == Mark::LinePoints {
            chart.draw_series(pts.iter().map(|&q| Circle::new(q, 3, color.filled())))?;
        }
        if !s.point_labels.is_empty() {
            let font = ("sans-serif", 12)
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
            let sample = LegendSample::of(s.mark);
            anno.label(s.label.clone()).legend(move |(x, y)| {
                // One element type for every mark: unused parts are empty or transparent.
                let piece = |k: usize| sample.pieces.get(k).cloned().unwrap_or_default();
                let none = color.mix(0.0).filled();
                EmptyElement::at((x, y))
                    + PathElement::new(piece(0), color.stroke_width(3))
                    + PathElement::new(piece(1), color.stroke_width(3))
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
            .label_font(("sans-serif", 13))
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

/// What a legend entry's sample draws, relative to its anchor: line pieces, a dot, a bar.
#[derive(Debug, Clone, PartialEq)]
pub struct LegendSample {
    /// Polyline pieces (a dashed series has two with a gap).
    pub pieces: Vec<Vec<(i32, i32)>>,
    /// Radius of the marker dot at the sample's middle, if any.
    pub dot: Option<i32>,
    /// A filled bar, if any.
    pub bar: Option<[(i32, i32); 2]>,
}

impl LegendSample {
    /// The sample for a series drawn with `mark`: its own dash pattern, marker or bar.
    pub fn of(mark: Mark) -> Self {
        let line = |a: i32, b: i32| vec![(a, 0), (b, 0)];
        let (pieces, dot, bar) = match mark {
            Mark::Line => (vec![line(0, 18)], None, None),
            Mark::Dashed => (vec![line(0, 6), line(12, 18)], None, None),
            Mark::Points => (vec![], Some(3), None),
            Mark::LinePoints => (vec![line(0, 18)], Some(3), None),
            Mark::Bars { .. } => (vec![], None, Some([(0, -5), (18, 5)])),
        };
        Self { pieces, dot, bar }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A figure or animation whose drawing fails reports its path and leaves neither the
    /// figure nor a temporary file behind.
    #[test]
    fn a_failed_drawing_leaves_no_file() {
        struct Broken;
        impl Drawing for Broken {
            fn draw_on<DB: DrawingBackend>(
                &self,
                _: &DrawingArea<DB, Shift>,
            ) -> Result<(), String> {
                Err("no data".into())
            }
        }
        let dir = tempfile::tempdir().unwrap();
        let err = write_png_svg(dir.path(), "f", (64, 48), &Broken).unwrap_err();
        assert!(err.to_string().contains("f.png"), "{err}");
        let gif = dir.path().join("g.gif");
        let err = write_gif_atomically(&gif, (64, 48), 50, |root| {
            root.fill(&WHITE).map_err(|e| e.to_string())?;
            root.present().map_err(|e| e.to_string())?;
            Err("second frame".into())
        })
        .unwrap_err();
        assert!(err.to_string().contains("g.gif"), "{err}");
        let left: Vec<_> = std::fs::read_dir(dir.path()).unwrap().collect();
        assert!(left.is_empty(), "{left:?}");
    }

    #[test]
    fn every_axis_gets_at_least_four_round_labelled_ticks_log_axes_included() {
        let cases = [
            (0.0, 1.0, false),
            (-3.2, 7.9, false),
            (0.999, 1.001, false),
            (-1e-7, 3e-7, false),
            (1e3, 1.1e6, false),
            (1e-6, 1e2, true),
            (0.5, 3.0, true), // less than a decade: 1-2-5 multiples
            (1.2, 2.1, true), // within a factor of 2: round linear values
            (3e-3, 4e-3, true),
            (1e-30, 1e30, true), // sixty decades: thinned
        ];
        for (lo, hi, log) in cases {
            let t = axis_ticks(lo, hi, log);
            assert!((4..=12).contains(&t.len()), "{lo}..{hi} log={log}: {t:?}");
            for w in t.windows(2) {
                assert!(w[0] < w[1], "{t:?} not increasing");
            }
            for v in &t {
                assert!(*v >= lo - 1e-9 * (hi - lo).abs() && *v <= hi * (1.0 + 1e-9) + 1e-12);
            }
        }
        // Powers of ten first on a log axis over many decades.
        assert_eq!(
            axis_ticks(1e-3, 1e3, true),
            vec![1e-3, 1e-2, 1e-1, 1.0, 1e1, 1e2, 1e3]
        );
        // Round values on a linear one.
        assert_eq!(
            axis_ticks(0.0, 10.0, false),
            vec![0.0, 2.0, 4.0, 6.0, 8.0, 10.0]
        );
    }

    #[test]
    fn an_axis_labels_all_its_ticks_in_one_format() {
        let t = axis_ticks(1e-9, 1.0, true);
        let sci = needs_sci(&t, 0.0);
        assert!(sci);
        let labels: Vec<String> = t.iter().map(|&v| tick_as(v, 0.0, sci)).collect();
        assert!(labels.iter().all(|l| l.contains('e')), "{labels:?}");
        assert_eq!(tick_as(2.5e-5, 0.0, true), "2.5e-5");
        assert_eq!(tick_as(1.0, 0.0, true), "1e0");
        assert_eq!(tick_as(0.25, 1.0, false), "0.25");
        assert!(!needs_sci(&axis_ticks(0.0, 10.0, false), 10.0));
        // Iteration counts stay whole numbers.
        let t = axis_ticks(0.0, 15000.0, false);
        assert!(!needs_sci(&t, 15000.0));
        assert_eq!(tick_as(15000.0, 15000.0, false), "15000");
        assert_eq!(tick_as(-0.0, 1.0, false), "0");
    }

    #[test]
    fn legend_samples_show_the_dash_pattern_marker_or_bar_of_their_series() {
        let line = LegendSample::of(Mark::Line);
        let dashed = LegendSample::of(Mark::Dashed);
        assert_eq!(line.pieces.len(), 1);
        assert_eq!(dashed.pieces.len(), 2, "a dashed series shows a gap");
        assert_ne!(line, dashed);
        assert!(LegendSample::of(Mark::Points).pieces.is_empty());
        assert!(LegendSample::of(Mark::Points).dot.is_some());
        let lp = LegendSample::of(Mark::LinePoints);
        assert!(lp.dot.is_some() && lp.pieces.len() == 1);
        assert!(LegendSample::of(Mark::Bars { half_width: 0.3 })
            .bar
            .is_some());
    }

    #[test]
    fn the_auto_legend_takes_the_emptiest_corner() {
        let area = ((0, 0), (400, 300));
        // A rising line from lower left to upper right: both of those corners are covered.
        let rising: Vec<(i32, i32)> = (0..=400).map(|x| (x, 300 - x * 3 / 4)).collect();
        let (c, _) = emptiest_corner(area, (100, 40), &rising);
        assert!(matches!(c, Legend::UpperLeft | Legend::LowerRight), "{c:?}");
        // Data everywhere but the lower left.
        let mut pts = Vec::new();
        for x in (0..=400).step_by(5) {
            for y in (0..=300).step_by(5) {
                if !(x < 150 && y > 200) {
                    pts.push((x, y));
                }
            }
        }
        assert_eq!(
            emptiest_corner(area, (100, 40), &pts),
            (Legend::LowerLeft, 0)
        );
        // No data: upper right.
        assert_eq!(
            emptiest_corner(area, (100, 40), &[]),
            (Legend::UpperRight, 0)
        );
    }

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

    #[test]
    fn figures_animate_as_a_gif_written_atomically() {
        let d = tempfile::tempdir().unwrap();
        let sink = FigureSink {
            dir: d.path().to_path_buf(),
            id: "x".into(),
        };
        let frame = |t: f64| {
            let mut f = Figure::grid(
                vec![Panel {
                    title: format!("t = {t:.1} s"),
                    x_label: "x (m)".into(),
                    y_label: "y (m)".into(),
                    series: vec![Series::line("bar", vec![(0.0, 0.0), (t.cos(), t.sin())], 0)],
                    x_range: Some((-1.0, 1.0)),
                    y_range: Some((-1.0, 1.0)),
                    ..Panel::default()
                }],
                1,
            );
            f.panel_size = (200, 160);
            f
        };
        let frames: Vec<Figure> = (0..3).map(|k| frame(k as f64)).collect();
        let p = sink.gif("anim", &frames, 5).unwrap();
        assert_eq!(p, d.path().join("x_anim.gif"));
        let bytes = std::fs::read(&p).unwrap();
        assert_eq!(&bytes[..6], b"GIF89a");
        // Logical screen of the first frame's size; one image descriptor (0x2C after a
        // graphic control extension) per frame.
        assert_eq!(u16::from_le_bytes([bytes[6], bytes[7]]), 200);
        assert_eq!(u16::from_le_bytes([bytes[8], bytes[9]]), 160);
        let frames_written = bytes.windows(2).filter(|w| w == &[0x21, 0xF9]).count();
        assert!(
            frames_written >= 3,
            "{frames_written} graphic control blocks"
        );
        let names: Vec<_> = std::fs::read_dir(d.path()).unwrap().collect();
        assert_eq!(names.len(), 1, "no temp file left behind");
        assert!(sink.gif("none", &[], 5).is_err());
    }
}
