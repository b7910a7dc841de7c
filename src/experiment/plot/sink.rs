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
use plotters_backend::{
    BackendColor, BackendCoord, BackendStyle, BackendTextStyle, DrawingErrorKind,
};
use plotters_bitmap::BitMapBackendError;
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
///
/// The frames are drawn by plotters' bitmap backend (the pixels a PNG of them would have) and
/// encoded with one palette of 256 colours for the whole animation, learned by NeuQuant from a
/// sample of every frame's pixels: plotters' own GIF backend learns a palette for each frame,
/// which took most of the time of every experiment that animates.
pub fn write_gif_atomically(
    gif: &Path,
    size: (u32, u32),
    delay_ms: u32,
    draw: impl FnOnce(&DrawingArea<FrameRecorder, Shift>) -> Result<(), String>,
) -> Result<(), Error> {
    if let Some(dir) = gif.parent() {
        std::fs::create_dir_all(dir).map_err(|e| Error::Io {
            path: dir.to_path_buf(),
            source: e,
        })?;
    }
    let frames = std::rc::Rc::new(std::cell::RefCell::new(Vec::new()));
    let root = FrameRecorder::new(size, frames.clone()).into_drawing_area();
    draw(&root).map_err(|m| perr(gif, m))?;
    drop(root);
    let frames = std::mem::take(&mut *frames.borrow_mut());
    let tmp = temp_path(gif);
    let made = (|| {
        let file = std::fs::File::create(&tmp).map_err(|e| perr(gif, e.to_string()))?;
        encode_gif(std::io::BufWriter::new(file), size, delay_ms, &frames).map_err(|m| perr(gif, m))
    })();
    rename_into_place(&tmp, gif, made)
}

/// One frame as runs of one colour, row after row: a plot frame is mostly long runs, so an
/// animation of a few hundred frames is held in tens of megabytes, not a megabyte (RGB) a frame.
type Runs = Vec<([u8; 3], u32)>;

/// The runs of the RGB pixels `rgb`.
fn runs_of(rgb: &[u8]) -> Runs {
    let mut runs: Runs = Vec::new();
    for p in rgb.chunks_exact(3) {
        let c = [p[0], p[1], p[2]];
        match runs.last_mut() {
            Some((last, n)) if *last == c => *n += 1,
            _ => runs.push((c, 1)),
        }
    }
    runs
}

/// A drawing backend that keeps every presented frame: each drawing call goes to plotters'
/// [`BitMapBackend`] on one RGB buffer, and `present()` appends the buffer's runs to the
/// frames.
pub struct FrameRecorder {
    size: (u32, u32),
    buffer: Vec<u8>,
    frames: std::rc::Rc<std::cell::RefCell<Vec<Runs>>>,
}

impl FrameRecorder {
    fn new(size: (u32, u32), frames: std::rc::Rc<std::cell::RefCell<Vec<Runs>>>) -> Self {
        FrameRecorder {
            size,
            buffer: vec![255; size.0 as usize * size.1 as usize * 3],
            frames,
        }
    }

    fn bitmap(&mut self) -> BitMapBackend<'_> {
        BitMapBackend::with_buffer(&mut self.buffer, self.size)
    }
}

type Drawn = Result<(), DrawingErrorKind<BitMapBackendError>>;

impl DrawingBackend for FrameRecorder {
    type ErrorType = BitMapBackendError;

    fn get_size(&self) -> (u32, u32) {
        self.size
    }

    fn ensure_prepared(&mut self) -> Drawn {
        Ok(())
    }

    fn present(&mut self) -> Drawn {
        self.frames.borrow_mut().push(runs_of(&self.buffer));
        Ok(())
    }

    fn draw_pixel(&mut self, point: BackendCoord, color: BackendColor) -> Drawn {
        self.bitmap().draw_pixel(point, color)
    }

    fn draw_line<S: BackendStyle>(
        &mut self,
        from: BackendCoord,
        to: BackendCoord,
        style: &S,
    ) -> Drawn {
        self.bitmap().draw_line(from, to, style)
    }

    fn draw_rect<S: BackendStyle>(
        &mut self,
        upper_left: BackendCoord,
        bottom_right: BackendCoord,
        style: &S,
        fill: bool,
    ) -> Drawn {
        self.bitmap()
            .draw_rect(upper_left, bottom_right, style, fill)
    }

    fn draw_path<S: BackendStyle, I: IntoIterator<Item = BackendCoord>>(
        &mut self,
        path: I,
        style: &S,
    ) -> Drawn {
        self.bitmap().draw_path(path, style)
    }

    fn draw_circle<S: BackendStyle>(
        &mut self,
        center: BackendCoord,
        radius: u32,
        style: &S,
        fill: bool,
    ) -> Drawn {
        self.bitmap().draw_circle(center, radius, style, fill)
    }

    fn fill_polygon<S: BackendStyle, I: IntoIterator<Item = BackendCoord>>(
        &mut self,
        vert: I,
        style: &S,
    ) -> Drawn {
        self.bitmap().fill_polygon(vert, style)
    }

    fn draw_text<T: BackendTextStyle>(
        &mut self,
        text: &str,
        style: &T,
        pos: BackendCoord,
    ) -> Drawn {
        self.bitmap().draw_text(text, style, pos)
    }

    fn blit_bitmap(&mut self, pos: BackendCoord, size: (u32, u32), src: &[u8]) -> Drawn {
        self.bitmap().blit_bitmap(pos, size, src)
    }
}

/// Encodes `frames` (runs) of `size` pixels as a looping GIF with one global palette: NeuQuant
/// (sampling factor 10, as plotters' GIF backend) trained once on about a million pixels
/// taken evenly from all the frames (every `every`-th pixel of the whole animation), every
/// colour then mapped to its nearest palette entry.
fn encode_gif(
    out: impl std::io::Write,
    (w, h): (u32, u32),
    delay_ms: u32,
    frames: &[Runs],
) -> Result<(), String> {
    let pixels = frames.len() * w as usize * h as usize;
    let every = pixels.div_ceil(1 << 20).max(1);
    let mut sample: Vec<u8> = Vec::new();
    let mut at = 0usize;
    for &(c, n) in frames.iter().flatten() {
        // The pixels of the run whose index is a multiple of `every`.
        let next = at + n as usize;
        let picked = next.div_ceil(every) - at.div_ceil(every);
        for _ in 0..picked {
            sample.extend_from_slice(&[c[0], c[1], c[2], 255]);
        }
        at = next;
    }
    let quant = color_quant::NeuQuant::new(10, 256, &sample);
    let e = |x: gif::EncodingError| x.to_string();
    let mut enc = gif::Encoder::new(out, w as u16, h as u16, &quant.color_map_rgb()).map_err(e)?;
    enc.set_repeat(gif::Repeat::Infinite).map_err(e)?;
    // Plot frames hold few colours: remember every colour's index.
    let mut index: std::collections::HashMap<[u8; 3], u8> = std::collections::HashMap::new();
    let mut buffer: Vec<u8> = Vec::with_capacity(w as usize * h as usize);
    for f in frames {
        buffer.clear();
        for &(c, n) in f {
            let i = *index
                .entry(c)
                .or_insert_with(|| quant.index_of(&[c[0], c[1], c[2], 255]) as u8);
            buffer.extend(std::iter::repeat_n(i, n as usize));
        }
        let frame = gif::Frame {
            width: w as u16,
            height: h as u16,
            // Hundredths of a second, rounded as plotters' backend does.
            delay: (delay_ms.saturating_add(5) / 10) as u16,
            buffer: std::borrow::Cow::Borrowed(&buffer),
            ..gif::Frame::default()
        };
        enc.write_frame(&frame).map_err(e)?;
    }
    Ok(())
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
    fn runs_hold_every_pixel_in_order() {
        let rgb = [1, 2, 3, 1, 2, 3, 9, 9, 9, 1, 2, 3];
        let runs = runs_of(&rgb);
        assert_eq!(runs, vec![([1, 2, 3], 2), ([9, 9, 9], 1), ([1, 2, 3], 1)]);
        let back: Vec<u8> = runs
            .iter()
            .flat_map(|&(c, n)| std::iter::repeat_n(c, n as usize).flatten())
            .collect();
        assert_eq!(back, rgb);
    }

    #[test]
    fn every_frame_is_kept_and_its_colours_come_back_from_the_one_palette() {
        let d = tempfile::tempdir().unwrap();
        let gif = d.path().join("c.gif");
        let colours = [WHITE, RGBColor(214, 39, 40), RGBColor(31, 119, 180), BLACK];
        write_gif_atomically(&gif, (40, 30), 70, |root| {
            for c in &colours {
                root.fill(c).map_err(|e| e.to_string())?;
                // A second colour in a corner: frames are not one flat colour.
                root.draw(&Rectangle::new([(0, 0), (9, 9)], GREEN.filled()))
                    .map_err(|e| e.to_string())?;
                root.present().map_err(|e| e.to_string())?;
            }
            Ok(())
        })
        .unwrap();
        let mut options = gif::DecodeOptions::new();
        options.set_color_output(gif::ColorOutput::RGBA);
        let mut dec = options
            .read_info(std::fs::File::open(&gif).unwrap())
            .unwrap();
        let mut seen = Vec::new();
        while let Some(f) = dec.read_next_frame().unwrap() {
            assert_eq!((f.width, f.height, f.delay), (40, 30, 7));
            let px = |x: usize, y: usize| {
                let i = 4 * (y * 40 + x);
                [f.buffer[i], f.buffer[i + 1], f.buffer[i + 2]]
            };
            seen.push((px(30, 20), px(2, 2)));
        }
        assert_eq!(seen.len(), colours.len(), "one GIF frame per present()");
        let close = |a: [u8; 3], b: &RGBColor| {
            let b = [b.0, b.1, b.2];
            a.iter()
                .zip(b)
                .all(|(x, y)| (*x as i32 - y as i32).abs() <= 8)
        };
        for ((body, corner), c) in seen.iter().zip(&colours) {
            assert!(close(*body, c), "{body:?} for {c:?}");
            assert!(close(*corner, &GREEN), "{corner:?}");
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
