//! Colours (the series palette, viridis and diverging colour maps) and the fonts every figure
//! uses.

use plotters::prelude::*;
use std::sync::Once;

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
/// before drawing text outside [`FigureSink::draw`](super::FigureSink::draw).
pub fn ensure_fonts() {
    register_fonts();
}

pub(super) fn register_fonts() {
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
