//! Where figures go: the per-experiment [`FigureSink`], the atomic PNG + SVG and animated GIF
//! writers, and the grid layout that draws a [`Figure`]'s panels.

use super::chart::draw_panel;
use super::heatmap::draw_heatmap;
use super::style::register_fonts;
use super::Figure;
use crate::experiment::output::{rename_into_place, temp_path};
use crate::experiment::Error;
use plotters::coord::Shift;
use plotters::prelude::*;
use std::path::{Path, PathBuf};

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
    crate::experiment::output::atomic_write(&svg, text.as_bytes())?;
    Ok(vec![png, svg])
}

/// How much larger than at a 640-pixel panel every text is drawn in a figure `width` pixels
/// wide: 1 up to 1300 pixels, then in proportion, so a tick label (13 pixels at scale 1) stays
/// at least 1% of the figure's width when the figure is shown scaled to a report's width.
pub fn font_scale(width: u32) -> f64 {
    (width as f64 / 1300.0).max(1.0)
}

fn render<DB: DrawingBackend>(root: &DrawingArea<DB, Shift>, fig: &Figure) -> Result<(), String> {
    root.fill(&WHITE).map_err(|e| e.to_string())?;
    let rows = fig.count().div_ceil(fig.columns);
    let areas = root.split_evenly((rows.max(1), fig.columns.min(fig.count()).max(1)));
    let scale = font_scale(root.dim_in_pixel().0);
    for (panel, area) in fig.panels.iter().zip(areas.iter()) {
        draw_panel(area, panel, scale).map_err(|e| e.to_string())?;
    }
    for (map, area) in fig.heatmaps.iter().zip(areas.iter().skip(fig.panels.len())) {
        draw_heatmap(area, map).map_err(|e| e.to_string())?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::experiment::plot::{Panel, Series};

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
