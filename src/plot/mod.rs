//! Plots, drawn with `plotters`: anti-aliased lines, axis labels in a real font (a subset
//! of DejaVu Sans embedded in the binary, `assets/fonts/`), log axes with decade ticks, and
//! legends. Every figure is written as PNG (`plotters`' bitmap backend, encoded by the
//! `png` crate) and, for the charts, also as SVG (`plotters`' SVG backend, text as text).
//!
//! The plot set: loss and per-frame EPE of a run, the three-view error scatters, the weight
//! search, the fluid learning curves, the image2d pictures and the scaling plots.

use std::path::Path;
use std::sync::Once;

use plotters::coord::Shift;
use plotters::prelude::*;

use crate::{DomaError, Result};

mod draw;

use draw::*;

/// An 8-bit RGB colour.
pub type Rgb = [u8; 3];

const FONT: &str = "sans-serif";
static FONT_BYTES: &[u8] = include_bytes!("../../assets/fonts/DejaVuSans-subset.ttf");
static REGISTER: Once = Once::new();

/// Registers the embedded font with `plotters` (once per process).
fn register_font() {
    REGISTER.call_once(|| {
        // The font is a valid TrueType file compiled into the binary.
        let _ = plotters::style::register_font(FONT, FontStyle::Normal, FONT_BYTES);
    });
}

/// One curve of a [`line_plot`].
pub struct Series<'a> {
    /// Its legend.
    pub name: &'a str,
    /// Its colour.
    pub color: Rgb,
    /// `(x, y)` points (non-finite ones, and non-positive ones on a log axis, are skipped).
    pub points: Vec<(f64, f64)>,
}

/// A curve: its legend, colour and points.
type Curve = (String, Rgb, Vec<(f64, f64)>);

/// What a figure shows.
enum Content {
    Lines {
        x_label: String,
        y_label: String,
        series: Vec<Curve>,
        log_x: bool,
        log_y: bool,
    },
    Views {
        canonical: Vec<[f32; 3]>,
        truth: Vec<[f32; 3]>,
        predicted: Vec<[f32; 3]>,
        max_error: f64,
    },
    Points {
        points: Vec<[f32; 3]>,
        colours: Vec<Rgb>,
    },
}

/// A figure, ready to be written as PNG or SVG.
pub struct Figure {
    title: String,
    width: u32,
    height: u32,
    content: Content,
}

type DrawResult<DB> =
    std::result::Result<(), DrawingAreaErrorKind<<DB as DrawingBackend>::ErrorType>>;

impl Figure {
    /// Puts the x axis of a line plot on a log scale.
    pub fn log_x(mut self) -> Self {
        if let Content::Lines { log_x, .. } = &mut self.content {
            *log_x = true;
        }
        self
    }

    /// The figure as PNG bytes.
    pub fn png(&self) -> Result<Vec<u8>> {
        register_font();
        let (w, h) = (self.width, self.height);
        let mut rgb = vec![0u8; (w * h * 3) as usize];
        {
            let root = BitMapBackend::with_buffer(&mut rgb, (w, h)).into_drawing_area();
            self.draw(&root)
                .and_then(|()| root.present())
                .map_err(|e| {
                    DomaError::InvalidData(format!("cannot draw `{}`: {e}", self.title))
                })?;
        }
        let mut out = Vec::new();
        let mut encoder = png::Encoder::new(&mut out, w, h);
        encoder.set_color(png::ColorType::Rgb);
        encoder.set_depth(png::BitDepth::Eight);
        encoder
            .write_header()
            .and_then(|mut writer| writer.write_image_data(&rgb))
            .map_err(|e| DomaError::InvalidData(format!("cannot encode `{}`: {e}", self.title)))?;
        Ok(out)
    }

    /// The figure as an SVG document.
    pub fn svg(&self) -> Result<String> {
        register_font();
        let mut text = String::new();
        {
            let root =
                SVGBackend::with_string(&mut text, (self.width, self.height)).into_drawing_area();
            self.draw(&root)
                .and_then(|()| root.present())
                .map_err(|e| {
                    DomaError::InvalidData(format!("cannot draw `{}`: {e}", self.title))
                })?;
        }
        Ok(text)
    }

    /// Writes the figure to `path` atomically, as PNG or SVG by its extension.
    pub fn save(&self, path: &Path) -> Result<()> {
        match path.extension().and_then(|e| e.to_str()) {
            Some("svg") => crate::io::write_atomic(path, self.svg()?.as_bytes()),
            Some("png") => crate::io::write_atomic(path, &self.png()?),
            _ => Err(DomaError::InvalidConfig(format!(
                "{}: a figure is written as .png or .svg",
                path.display()
            ))),
        }
    }

    /// Writes `path` (a `.png`) and the same figure as `.svg` beside it.
    pub fn save_png_and_svg(&self, path: &Path) -> Result<()> {
        self.save(&path.with_extension("png"))?;
        self.save(&path.with_extension("svg"))
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> DrawResult<DB> {
        root.fill(&WHITE)?;
        let titled = root.titled(&self.title, (FONT, 22))?;
        match &self.content {
            Content::Lines {
                x_label,
                y_label,
                series,
                log_x,
                log_y,
            } => draw_lines(&titled, x_label, y_label, series, *log_x, *log_y),
            Content::Views {
                canonical,
                truth,
                predicted,
                max_error,
            } => draw_views(&titled, canonical, truth, predicted, *max_error),
            Content::Points { points, colours } => draw_points(&titled, points, colours),
        }
    }
}

/// A line plot with axes, ticks, labels and a legend; `log_y` puts y on a log scale
/// (`Figure::log_x` does the same for x).
pub fn line_plot(
    title: &str,
    x_label: &str,
    y_label: &str,
    series: &[Series<'_>],
    log_y: bool,
) -> Figure {
    Figure {
        title: title.into(),
        width: 900,
        height: 540,
        content: Content::Lines {
            x_label: x_label.into(),
            y_label: y_label.into(),
            series: series
                .iter()
                .map(|s| (s.name.to_string(), s.color, s.points.clone()))
                .collect(),
            log_x: false,
            log_y,
        },
    }
}

/// A colour for `t ∈ [0, 1]` on a blue → green → yellow → red ramp.
pub fn ramp(t: f64) -> Rgb {
    let t = t.clamp(0.0, 1.0);
    let stops: [[f64; 3]; 4] = [
        [40.0, 60.0, 200.0],
        [40.0, 180.0, 90.0],
        [240.0, 220.0, 40.0],
        [220.0, 40.0, 30.0],
    ];
    let x = t * 3.0;
    let i = (x.floor() as usize).min(2);
    let f = x - i as f64;
    std::array::from_fn(|c| (stops[i][c] * (1.0 - f) + stops[i + 1][c] * f) as u8)
}

/// Three orthographic views (x–y, x–z, z–y) of the canonical points (grey), the true
/// positions (black) and the predicted positions coloured by their L1 error on the
/// `ramp` from 0 to `max_error`, with a colour bar.
pub fn three_views(
    title: &str,
    canonical: &[[f32; 3]],
    truth: &[[f32; 3]],
    predicted: &[[f32; 3]],
    max_error: f64,
) -> Figure {
    Figure {
        title: title.into(),
        width: 1260,
        height: 500,
        content: Content::Views {
            canonical: canonical.to_vec(),
            truth: truth.to_vec(),
            predicted: predicted.to_vec(),
            max_error,
        },
    }
}

/// A picture of 2-D `points` (x, y of each; the square `[−2.5, 2.5]²`), each pixel in its
/// colour (the image2d experiment's deformed images).
pub fn point_picture(title: &str, points: &[[f32; 3]], colours: &[Rgb], size: u32) -> Figure {
    Figure {
        title: title.into(),
        width: size,
        height: size + 34,
        content: Content::Points {
            points: points.to_vec(),
            colours: colours.to_vec(),
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn labels_read_as_numbers() {
        assert_eq!(number(0.0), "0");
        assert_eq!(number(-2.2e-16), "0");
        assert_eq!(number(10.0), "10");
        assert_eq!(number(0.25), "0.25");
        assert_eq!(number(1e-5), "1e-5");
        assert_eq!(number(3e6), "3.0e6");
        assert_eq!(number(100000.0), "100000");
        assert_eq!(number(1e6), "1e6");
    }

    #[test]
    fn a_line_plot_is_a_png_and_an_svg_with_its_text() {
        let s = [Series {
            name: "loss",
            color: [200, 40, 40],
            points: (1..50).map(|i| (i as f64, 1.0 / (i * i) as f64)).collect(),
        }];
        let fig = line_plot("A title", "iteration", "loss", &s, true);
        let png = fig.png().unwrap();
        assert!(png.starts_with(b"\x89PNG\r\n\x1a\n"));
        let svg = fig.svg().unwrap();
        assert!(svg.starts_with("<svg") && svg.contains("A title") && svg.contains("loss"));
        // Decade ticks on the log axis, as text.
        let label = |t: &str| svg.lines().any(|l| l.trim() == t);
        assert!(label("0.1") && label("0.01"), "{svg}");
    }

    #[test]
    fn the_ramp_runs_blue_to_red() {
        assert_eq!(ramp(0.0), [40, 60, 200]);
        assert_eq!(ramp(1.0), [220, 40, 30]);
    }
}
