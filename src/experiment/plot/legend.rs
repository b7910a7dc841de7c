//! Chart keys: the corner an automatic legend takes (the one covering the fewest drawn data)
//! and what each entry's sample draws.

use super::axes::tr;
use super::{Legend, Mark, Panel};

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
pub(super) fn covered_pixels(
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
            Mark::Line | Mark::Solid => (vec![line(0, 18)], None, None),
            Mark::Dashed => (vec![line(0, 6), line(12, 18)], None, None),
            Mark::Pattern { dash, gap } => {
                // The pattern over 24 pixels (strokes shortened to at most 8 so it shows).
                let (d, g) = (dash.clamp(1, 8) as i32, gap.clamp(1, 8) as i32);
                let pieces = (0..)
                    .map(|k| k * (d + g))
                    .take_while(|&a| a < 24)
                    .map(|a| line(a, (a + d).min(24)))
                    .collect();
                (pieces, None, None)
            }
            Mark::Points => (vec![], Some(3), None),
            Mark::LinePoints => (vec![line(0, 18)], Some(3), None),
            Mark::Bars { .. } | Mark::Area => (vec![], None, Some([(0, -5), (18, 5)])),
        };
        Self { pieces, dot, bar }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn legend_samples_show_the_dash_pattern_marker_or_bar_of_their_series() {
        let line = LegendSample::of(Mark::Line);
        let dashed = LegendSample::of(Mark::Dashed);
        assert_eq!(line.pieces.len(), 1);
        assert_eq!(dashed.pieces.len(), 2, "a dashed series shows a gap");
        assert_ne!(line, dashed);
        let dots = LegendSample::of(Mark::Pattern { dash: 3, gap: 4 });
        let long = LegendSample::of(Mark::Pattern { dash: 12, gap: 6 });
        assert!(dots.pieces.len() > long.pieces.len() && long.pieces.len() >= 2);
        assert_ne!(dots, dashed);
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
}
