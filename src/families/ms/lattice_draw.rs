//! Drawing 3-D mass-spring lattices with plotters: an orthographic camera (azimuth about the
//! vertical, then elevation) projects world points to pixels; springs are lines, masses dots,
//! the floor a light grid with the masses' shadows. Used by the mass-spring experiments for
//! lattice figures, filmstrips and animated GIFs.

// Drawing: a last-bit difference moves no table.
#![allow(clippy::disallowed_methods)]

use crate::experiment::plot::{write_gif_atomically, write_png_svg, Drawing};
use crate::experiment::Error;
use plotters::coord::Shift;
use plotters::prelude::*;
use std::path::{Path, PathBuf};

/// An orthographic view: world point p ↦ pixel.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct View {
    /// Camera azimuth about the vertical (rad).
    pub azimuth: f64,
    /// Camera elevation above the floor (rad).
    pub elevation: f64,
    /// Pixels per metre.
    pub scale: f64,
    /// Screen coordinates (u, v) mapped to `offset`.
    pub center: (f64, f64),
    /// Pixel position of `center`.
    pub offset: (f64, f64),
}

/// Screen coordinates (u right, v up, in metres) of a world point seen from the camera.
pub fn screen(azimuth: f64, elevation: f64, p: [f64; 3]) -> (f64, f64) {
    let (sa, ca) = azimuth.sin_cos();
    let (se, ce) = elevation.sin_cos();
    let x1 = p[0] * ca + p[1] * sa;
    let y1 = -p[0] * sa + p[1] * ca;
    (x1, p[2] * ce + y1 * se)
}

impl View {
    /// The view that fits `points` (world, m) into a `size` pixel area with a margin.
    pub fn fit(
        points: impl Iterator<Item = [f64; 3]>,
        size: (u32, u32),
        azimuth: f64,
        elevation: f64,
        margin: u32,
    ) -> Self {
        let (mut lo, mut hi) = (
            (f64::INFINITY, f64::INFINITY),
            (f64::NEG_INFINITY, f64::NEG_INFINITY),
        );
        for p in points {
            let (u, v) = screen(azimuth, elevation, p);
            lo = (lo.0.min(u), lo.1.min(v));
            hi = (hi.0.max(u), hi.1.max(v));
        }
        if !lo.0.is_finite() {
            lo = (-1.0, -1.0);
            hi = (1.0, 1.0);
        }
        let w = (size.0.saturating_sub(2 * margin)).max(1) as f64;
        let h = (size.1.saturating_sub(2 * margin)).max(1) as f64;
        let scale = (w / (hi.0 - lo.0).max(1e-3)).min(h / (hi.1 - lo.1).max(1e-3));
        Self {
            azimuth,
            elevation,
            scale,
            center: (0.5 * (lo.0 + hi.0), 0.5 * (lo.1 + hi.1)),
            offset: (0.5 * size.0 as f64, 0.5 * size.1 as f64),
        }
    }

    /// Pixel of world point `p`.
    pub fn pixel(&self, p: [f64; 3]) -> (i32, i32) {
        let (u, v) = screen(self.azimuth, self.elevation, p);
        (
            (self.offset.0 + (u - self.center.0) * self.scale).round() as i32,
            (self.offset.1 - (v - self.center.1) * self.scale).round() as i32,
        )
    }
}

/// Colour of a drawn lattice.
pub const LATTICE: RGBColor = RGBColor(31, 119, 180);
/// Colour of a faint reference lattice.
pub const GHOST: RGBColor = RGBColor(200, 200, 200);

/// Colour of the marked face's masses and springs.
pub const MARKED: RGBColor = RGBColor(255, 127, 14);

/// How a lattice picture is framed and annotated.
#[derive(Debug, Clone, PartialEq)]
pub struct Scene {
    /// A line of text above the panels (or the frames of a GIF).
    pub caption: Option<String>,
    /// Camera azimuth about the vertical (rad).
    pub azimuth: f64,
    /// Camera elevation above the floor (rad).
    pub elevation: f64,
    /// Masses of one face, drawn in [`MARKED`] with the springs between them, so that a
    /// rotation of the body is visible.
    pub marked: Vec<usize>,
    /// A 1 m bar on the floor (the first panel of a filmstrip, every GIF frame).
    pub scale_bar: bool,
}

impl Default for Scene {
    fn default() -> Self {
        Self {
            caption: None,
            azimuth: -0.45,
            elevation: 0.35,
            marked: Vec::new(),
            scale_bar: false,
        }
    }
}

/// The masses of the face at the largest x (within 5 cm) of `positions`: the front face.
pub fn front_face(positions: &[[f64; 3]]) -> Vec<usize> {
    let xmax = positions
        .iter()
        .map(|p| p[0])
        .fold(f64::NEG_INFINITY, f64::max);
    (0..positions.len())
        .filter(|&i| positions[i][0] >= xmax - 0.05)
        .collect()
}

/// The ends of the 1 m scale bar: along x on the floor at the extent's near corner.
fn scale_bar_ends(extent: ([f64; 2], [f64; 2])) -> [[f64; 3]; 2] {
    let (x0, y0) = (extent.0[0] + 0.25, extent.1[0]);
    [[x0, y0, 0.0], [x0 + 1.0, y0, 0.0]]
}

/// Draws a 1 m bar along x on the floor at the extent's near corner, labelled.
fn draw_scale_bar<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    view: &View,
    extent: ([f64; 2], [f64; 2]),
) -> Result<(), String> {
    let e = |e: DrawingAreaErrorKind<DB::ErrorType>| e.to_string();
    let [p, q] = scale_bar_ends(extent);
    let (a, b) = (view.pixel(p), view.pixel(q));
    area.draw(&PathElement::new(
        vec![a, b],
        ShapeStyle::from(&BLACK).stroke_width(3),
    ))
    .map_err(e)?;
    area.draw(&Text::new(
        "1 m",
        // Below the bar: the bodies stand above the floor, so a label above it would sit on
        // the body in the first frame.
        ((a.0 + b.0) / 2 - 10, (a.1 + b.1) / 2 + 5),
        ("sans-serif", 13).into_font().color(&BLACK),
    ))
    .map_err(e)
}

/// The floor extent (x and y ranges, m) around `points`, padded.
pub fn floor_extent(points: impl Iterator<Item = [f64; 3]>) -> ([f64; 2], [f64; 2]) {
    let mut x = [f64::INFINITY, f64::NEG_INFINITY];
    let mut y = [f64::INFINITY, f64::NEG_INFINITY];
    for p in points {
        x = [x[0].min(p[0]), x[1].max(p[0])];
        y = [y[0].min(p[1]), y[1].max(p[1])];
    }
    if !x[0].is_finite() {
        return ([-1.0, 1.0], [-1.0, 1.0]);
    }
    (
        [(x[0] - 0.3).floor(), (x[1] + 0.3).ceil()],
        [(y[0] - 0.3).floor(), (y[1] + 0.3).ceil()],
    )
}

/// Draws the floor grid (0.5 m spacing) over `extent`.
pub fn draw_floor<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    view: &View,
    extent: ([f64; 2], [f64; 2]),
) -> Result<(), String> {
    let style = ShapeStyle::from(&RGBColor(225, 225, 225)).stroke_width(1);
    let (xr, yr) = extent;
    let e = |e: DrawingAreaErrorKind<DB::ErrorType>| e.to_string();
    let mut x = xr[0];
    while x <= xr[1] + 1e-9 {
        area.draw(&PathElement::new(
            vec![view.pixel([x, yr[0], 0.0]), view.pixel([x, yr[1], 0.0])],
            style,
        ))
        .map_err(e)?;
        x += 0.5;
    }
    let mut y = yr[0];
    while y <= yr[1] + 1e-9 {
        area.draw(&PathElement::new(
            vec![view.pixel([xr[0], y, 0.0]), view.pixel([xr[1], y, 0.0])],
            style,
        ))
        .map_err(e)?;
        y += 0.5;
    }
    Ok(())
}

/// Draws one lattice: shadows on the floor, springs, masses.
pub fn draw_lattice<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    view: &View,
    positions: &[[f64; 3]],
    springs: &[(usize, usize)],
    color: RGBColor,
    shadow: bool,
    marked: &[usize],
) -> Result<(), String> {
    let e = |e: DrawingAreaErrorKind<DB::ErrorType>| e.to_string();
    if shadow {
        for p in positions {
            area.draw(&Circle::new(
                view.pixel([p[0], p[1], 0.0]),
                2,
                RGBColor(170, 170, 170).filled(),
            ))
            .map_err(e)?;
        }
    }
    let style = ShapeStyle::from(&color).stroke_width(2);
    let face = ShapeStyle::from(&MARKED).stroke_width(3);
    // The marked face's springs last, so that they stay visible.
    let on_face = |a: usize, b: usize| marked.contains(&a) && marked.contains(&b);
    for pass in [false, true] {
        for &(a, b) in springs {
            if a < positions.len() && b < positions.len() && on_face(a, b) == pass {
                area.draw(&PathElement::new(
                    vec![view.pixel(positions[a]), view.pixel(positions[b])],
                    if pass { face } else { style },
                ))
                .map_err(e)?;
            }
        }
    }
    for (i, p) in positions.iter().enumerate() {
        let fill = if marked.contains(&i) {
            MARKED
        } else {
            RGBColor(20, 20, 20)
        };
        area.draw(&Circle::new(view.pixel(*p), 4, fill.filled()))
            .map_err(e)?;
    }
    Ok(())
}

/// One panel of a lattice picture.
#[derive(Debug, Clone)]
pub struct LatticePanel {
    /// Title above the panel.
    pub title: String,
    /// Lattice positions (m).
    pub positions: Vec<[f64; 3]>,
    /// A faint reference shape drawn behind (e.g. the rest shape).
    pub ghost: Option<Vec<[f64; 3]>>,
    /// A polyline drawn on top (e.g. the centre-of-mass path).
    pub trail: Vec<[f64; 3]>,
}

fn render_panels<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    panels: &[LatticePanel],
    springs: &[(usize, usize)],
    columns: usize,
    shared_view: bool,
    scene: &Scene,
) -> Result<(), String> {
    root.fill(&WHITE).map_err(|e| e.to_string())?;
    let root = match &scene.caption {
        Some(text) => {
            let (top, rest) = root.split_vertically(CAPTION_PX);
            top.draw(&Text::new(
                text.clone(),
                (10, 6),
                ("sans-serif", 16).into_font().color(&BLACK),
            ))
            .map_err(|e| e.to_string())?;
            rest
        }
        None => root.clone(),
    };
    let rows = panels.len().div_ceil(columns.max(1)).max(1);
    let areas = root.split_evenly((rows, columns.max(1)));
    let all = |p: &LatticePanel| {
        let mut v = p.positions.clone();
        v.extend(p.ghost.iter().flatten().copied());
        v.extend(p.trail.iter().copied());
        v
    };
    let every: Vec<[f64; 3]> = panels.iter().flat_map(all).collect();
    let extent = floor_extent(every.iter().copied());
    for (k, (p, area)) in panels.iter().zip(areas.iter()).enumerate() {
        register();
        let area = area
            .titled(&p.title, ("sans-serif", 16).into_font())
            .map_err(|e| e.to_string())?;
        let size = area.dim_in_pixel();
        let mut pts: Vec<[f64; 3]> = if shared_view { every.clone() } else { all(p) };
        let bar = scene.scale_bar && (k == 0 || !shared_view);
        if scene.scale_bar {
            // Every panel frames the bar's place, so a shared view stays shared.
            let ext = if shared_view {
                extent
            } else {
                floor_extent(pts.iter().copied())
            };
            pts.extend(scale_bar_ends(ext));
        }
        let view = View::fit(
            pts.iter().copied(),
            size,
            scene.azimuth,
            scene.elevation,
            18,
        );
        let ext = if shared_view {
            extent
        } else {
            floor_extent(pts.iter().copied())
        };
        draw_floor(&area, &view, ext)?;
        if let Some(g) = &p.ghost {
            draw_lattice(&area, &view, g, springs, GHOST, false, &[])?;
        }
        draw_lattice(
            &area,
            &view,
            &p.positions,
            springs,
            LATTICE,
            true,
            &scene.marked,
        )?;
        // The bar and its label on top of the lattice, so that neither hides them.
        if bar {
            draw_scale_bar(&area, &view, ext)?;
        }
        if p.trail.len() > 1 {
            area.draw(&PathElement::new(
                p.trail.iter().map(|q| view.pixel(*q)).collect::<Vec<_>>(),
                ShapeStyle::from(&RGBColor(214, 39, 40)).stroke_width(1),
            ))
            .map_err(|e| e.to_string())?;
        }
    }
    Ok(())
}

fn register() {
    // FigureSink registers the fonts; drawing a tiny figure through it is not needed here
    // because `titled` falls back on the registered "sans-serif" family.
    crate::experiment::plot::ensure_fonts();
}

/// Height of a caption line (pixels).
const CAPTION_PX: u32 = 28;

/// Draws `panels` (`columns` per row, `panel` pixels each) as `<dir>/<stem>.png` and `.svg`,
/// framed and annotated by `scene`; with `shared_view` every panel uses one camera fitted to
/// all of them.
#[allow(clippy::too_many_arguments)]
pub fn draw_panels(
    dir: &Path,
    stem: &str,
    panels: &[LatticePanel],
    springs: &[(usize, usize)],
    columns: usize,
    panel: (u32, u32),
    shared_view: bool,
    scene: &Scene,
) -> Result<Vec<PathBuf>, Error> {
    register();
    let rows = panels.len().div_ceil(columns.max(1)).max(1) as u32;
    let caption = if scene.caption.is_some() {
        CAPTION_PX
    } else {
        0
    };
    let size = (
        panel.0 * columns.min(panels.len()).max(1) as u32,
        panel.1 * rows + caption,
    );
    let drawing = Panels {
        panels,
        springs,
        columns,
        shared_view,
        scene,
    };
    write_png_svg(dir, stem, size, &drawing)
}

/// The arguments of [`render_panels`], drawn on either backend.
struct Panels<'a> {
    panels: &'a [LatticePanel],
    springs: &'a [(usize, usize)],
    columns: usize,
    shared_view: bool,
    scene: &'a Scene,
}

impl Drawing for Panels<'_> {
    fn draw_on<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<(), String> {
        render_panels(
            root,
            self.panels,
            self.springs,
            self.columns,
            self.shared_view,
            self.scene,
        )
    }
}

/// Writes an animated GIF `<dir>/<stem>.gif` of `frames` (title, positions), one camera for
/// all frames, `delay_ms` between frames; the centre-of-mass path `trail` is drawn up to
/// each frame's time; `scene` frames it, marks its face and scale, and its caption is written
/// at the foot of every frame (a key).
#[allow(clippy::too_many_arguments)]
pub fn write_gif(
    dir: &Path,
    stem: &str,
    frames: &[(String, Vec<[f64; 3]>)],
    trail: &[[f64; 3]],
    springs: &[(usize, usize)],
    size: (u32, u32),
    delay_ms: u32,
    scene: &Scene,
) -> Result<PathBuf, Error> {
    register();
    let gif = dir.join(format!("{stem}.gif"));
    let every: Vec<[f64; 3]> = frames.iter().flat_map(|f| f.1.iter().copied()).collect();
    let extent = floor_extent(every.iter().copied());
    write_gif_atomically(&gif, size, delay_ms, |root| {
        let s = |e: DrawingAreaErrorKind<_>| e.to_string();
        let (_, body) = root.split_vertically(24);
        let foot = if scene.caption.is_some() { 22 } else { 0 };
        let (body, _) = body.split_vertically(body.dim_in_pixel().1.saturating_sub(foot));
        let bar = if scene.scale_bar {
            scale_bar_ends(extent).to_vec()
        } else {
            vec![]
        };
        let view = View::fit(
            every.iter().chain(&bar).copied(),
            body.dim_in_pixel(),
            scene.azimuth,
            scene.elevation,
            16,
        );
        let n = frames.len().max(1);
        for (k, (title, pos)) in frames.iter().enumerate() {
            root.fill(&WHITE).map_err(s)?;
            root.draw(&Text::new(
                title.clone(),
                (10, 4),
                ("sans-serif", 16).into_font().color(&BLACK),
            ))
            .map_err(s)?;
            draw_floor(&body, &view, extent)?;
            if let Some(key) = &scene.caption {
                root.draw(&Text::new(
                    key.clone(),
                    (10, size.1 as i32 - 20),
                    ("sans-serif", 13).into_font().color(&BLACK),
                ))
                .map_err(s)?;
            }
            let upto = ((k + 1) * trail.len()) / n;
            if upto > 1 {
                body.draw(&PathElement::new(
                    trail[..upto]
                        .iter()
                        .map(|q| view.pixel(*q))
                        .collect::<Vec<_>>(),
                    ShapeStyle::from(&RGBColor(214, 39, 40)).stroke_width(1),
                ))
                .map_err(s)?;
            }
            draw_lattice(&body, &view, pos, springs, LATTICE, true, &scene.marked)?;
            if scene.scale_bar {
                draw_scale_bar(&body, &view, extent)?;
            }
            root.present().map_err(s)?;
        }
        Ok(())
    })?;
    Ok(gif)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn view_fits_points_inside_the_area() {
        let pts = [[0.0, 0.0, 0.0], [1.0, 1.0, 1.0], [3.0, -1.0, 0.5]];
        let v = View::fit(pts.iter().copied(), (200, 100), -0.45, 0.35, 10);
        for p in pts {
            let (x, y) = v.pixel(p);
            assert!((9..=191).contains(&x) && (9..=91).contains(&y), "{x},{y}");
        }
        // Higher points are higher on screen (smaller pixel row).
        assert!(v.pixel([0.0, 0.0, 1.0]).1 < v.pixel([0.0, 0.0, 0.0]).1);
    }
}
