//! Figures: multi-panel line and scatter charts written as PNG and SVG.
//!
//! Log axes use plotters' logarithmic coordinates (points ≤ 0 are skipped there). The y-axis description is written horizontally above
//! the plotting area: plotters draws it unrotated in PNG output (plotters-rs/plotters#655 upstream), which
//! would overlap the tick labels.
//!
//! Fonts come from the `dejavu` crate (no system fontconfig needed).
//!
//! The figure description (series, panels, heat maps, figures) is here; `style` holds the
//! colours and fonts, `sink` writes figures and animations to files, `axes` the ticks and
//! their labels, `chart` draws line, scatter and bar panels, `legend` places and samples
//! their keys, `heatmap` draws heat maps.

// Figure axes: a last-bit difference moves no table.
#![allow(clippy::disallowed_methods)]

mod axes;
mod chart;
mod heatmap;
mod legend;
mod sink;
mod style;

pub use axes::axis_ticks;
pub(crate) use axes::tick;
pub use legend::{emptiest_corner, LegendSample};
pub use sink::{perr, write_gif_atomically, write_png_svg, Drawing, FigureSink};
pub use style::{diverging, ensure_fonts, viridis, PALETTE};

/// How a series is drawn.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Mark {
    /// A polyline.
    Line,
    /// A polyline that stays solid beside others (where the panel's line styles carry a
    /// meaning of their own, e.g. solid for one substrate and dashed for another; a plain
    /// [`Mark::Line`] takes its colour's dash pattern instead).
    Solid,
    /// A dashed polyline.
    Dashed,
    /// A polyline dashed in `dash`-pixel strokes with `gap`-pixel gaps (what a plain line
    /// becomes beside others of its panel; see [`Panel::series_marks`]).
    Pattern {
        /// Stroke length in pixels.
        dash: u32,
        /// Gap length in pixels.
        gap: u32,
    },
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
    /// A translucent filled polygon through the points in order (a band: the lower edge left
    /// to right, then the upper edge right to left; [`Series::band`]).
    Area,
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
    /// Ticks at these x positions with these labels instead of numbers (e.g. a filmstrip's
    /// frames, each labelled with its time); empty: numeric ticks.
    pub x_ticks: Vec<(f64, String)>,
}

/// The strokes (dash, gap in pixels) of plain lines with colour indices 1 to 7 beside others
/// (index 0 stays solid): see [`Panel::series_marks`].
const LINE_PATTERNS: [(u32, u32); 7] = [(12, 6), (3, 4), (7, 3), (20, 4), (2, 8), (10, 2), (5, 10)];

impl Panel {
    /// How each series is drawn: as its `mark`, except that where a panel has two or more
    /// labelled plain lines, each plain line is stroked by its colour index (solid, long
    /// dashes, dots, short dashes and four more patterns, eight in all, as many as the palette
    /// has distinct hues before grey), so series differ by stroke as well as by colour (a
    /// reader who cannot tell the colours apart, or prints in grey, still can).
    pub fn series_marks(&self) -> Vec<Mark> {
        let lines = self
            .series
            .iter()
            .filter(|s| s.mark == Mark::Line && !s.label.is_empty())
            .count();
        self.series
            .iter()
            .map(|s| match (s.mark, lines >= 2) {
                (Mark::Line, true) => Mark::stroke_of(s.color),
                (m, _) => m,
            })
            .collect()
    }
}

impl Series {
    /// A band between `lower` and `upper` (points at the same x, in increasing x) as a
    /// translucent [`Mark::Area`] of colour index `color`: the spread of a quantity (lowest to
    /// highest seed, an interval) around a line drawn on top of it.
    pub fn band(
        label: impl Into<String>,
        lower: &[(f64, f64)],
        upper: &[(f64, f64)],
        color: usize,
    ) -> Self {
        let outline: Vec<(f64, f64)> = lower
            .iter()
            .copied()
            .chain(upper.iter().rev().copied())
            .collect();
        Series::line(label, outline, color).mark(Mark::Area)
    }
}

impl Mark {
    /// The stroke a plain line of colour index `color` gets beside other labelled lines
    /// ([`Panel::series_marks`]): for a panel whose lines carry no labels of their own (a
    /// second panel in the colours of a first) to match it.
    pub fn stroke_of(color: usize) -> Mark {
        match color % 8 {
            0 => Mark::Line,
            k => {
                let (dash, gap) = LINE_PATTERNS[k - 1];
                Mark::Pattern { dash, gap }
            }
        }
    }
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_band_is_the_lower_edge_then_the_upper_edge_backwards() {
        let b = Series::band(
            "spread",
            &[(0.0, 1.0), (1.0, 2.0)],
            &[(0.0, 3.0), (1.0, 5.0)],
            2,
        );
        assert_eq!(b.mark, Mark::Area);
        assert_eq!(
            b.points,
            vec![(0.0, 1.0), (1.0, 2.0), (1.0, 5.0), (0.0, 3.0)]
        );
    }

    #[test]
    fn lines_beside_others_differ_by_stroke_as_well_as_colour() {
        let pts = vec![(0.0, 0.0), (1.0, 1.0)];
        let mut p = Panel {
            series: vec![Series::line("a", pts.clone(), 0)],
            ..Panel::default()
        };
        // A lone line stays solid.
        assert_eq!(p.series_marks(), vec![Mark::Line]);
        p.series
            .extend((1..8).map(|c| Series::line(format!("s{c}"), pts.clone(), c)));
        p.series
            .push(Series::line("ref", pts.clone(), 5).mark(Mark::Dashed));
        let marks = p.series_marks();
        // Eight lines are drawn eight ways; a series with its own mark keeps it.
        for i in 0..8 {
            for j in 0..i {
                assert_ne!(marks[i], marks[j], "{marks:?}");
            }
        }
        assert_eq!(marks[8], Mark::Dashed);
    }

    #[test]
    fn wide_figures_draw_larger_text() {
        assert_eq!(sink::font_scale(640), 1.0);
        assert_eq!(sink::font_scale(1300), 1.0);
        // A tick label (13 pixels at scale 1) is at least 1% of any figure's width.
        for w in [640, 1300, 1920, 3840] {
            assert!(13.0 * sink::font_scale(w) >= 0.01 * w as f64 - 1e-9, "{w}");
        }
    }
}
