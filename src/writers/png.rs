//! PNG figures drawn with plotters: line plots with interval bands and bird's-eye panels.
//!
//! Text is rendered by plotters' ab_glyph backend from the DejaVu Sans font kept in
//! `assets/fonts/` and compiled into the binary, so no system font library is needed.
//! Images are rendered into memory and encoded with the `png` crate through
//! [`super::atomic::write_atomically`].

use crate::error::{Error, Result};
use plotters::prelude::*;
use std::path::Path;
use std::sync::Once;

/// The font compiled into the binary (DejaVu Sans, Bitstream Vera licence).
pub const FONT: &[u8] = include_bytes!("../../assets/fonts/DejaVuSans.ttf");
/// Family name the font is registered under.
pub(crate) const FAMILY: &str = "sans-serif";

/// Categorical colours for lines and clusters (Tableau 10 without its grey).
pub const PALETTE: [RGBColor; 9] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(188, 189, 34),
    RGBColor(23, 190, 207),
];

pub(crate) fn register_font() -> Result<()> {
    static ONCE: Once = Once::new();
    let mut ok = true;
    ONCE.call_once(|| {
        ok = plotters::style::register_font(FAMILY, FontStyle::Normal, FONT).is_ok();
    });
    if ok {
        Ok(())
    } else {
        Err(Error::Invalid(
            "the built-in font could not be loaded".into(),
        ))
    }
}

pub(crate) fn draw_err<E: std::fmt::Display>(e: E) -> std::io::Error {
    std::io::Error::other(format!("drawing failed: {e}"))
}

/// Encodes an RGB buffer as PNG to `path`, atomically.
pub(crate) fn write_png(
    path: &Path,
    protected: &[&Path],
    buf: &[u8],
    (w, h): (u32, u32),
) -> Result<()> {
    super::atomic::write_atomically(path, protected, |out| {
        let mut enc = png::Encoder::new(out, w, h);
        enc.set_color(png::ColorType::Rgb);
        enc.set_depth(png::BitDepth::Eight);
        let mut writer = enc.write_header().map_err(std::io::Error::other)?;
        writer
            .write_image_data(buf)
            .map_err(std::io::Error::other)?;
        writer.finish().map_err(std::io::Error::other)
    })
}

/// One line of a line plot: (x, mean, lower bound, upper bound) points.
#[derive(Clone, Debug)]
pub struct Series {
    /// Legend text.
    pub label: String,
    /// Points sorted by x.
    pub points: Vec<(f64, f64, f64, f64)>,
}

/// A line plot of one metric against one parameter.
#[derive(Clone, Debug)]
pub struct LinePlot {
    /// Title above the plot.
    pub title: String,
    /// X axis label with unit.
    pub x_label: String,
    /// Y axis label with unit.
    pub y_label: String,
    /// The lines.
    pub series: Vec<Series>,
}

fn padded(lo: f64, hi: f64) -> (f64, f64) {
    if !(lo.is_finite() && hi.is_finite()) {
        return (0.0, 1.0);
    }
    if hi - lo < 1e-9 {
        let pad = (hi.abs() * 0.1).max(0.5);
        return (lo - pad, hi + pad);
    }
    let pad = (hi - lo) * 0.05;
    (lo - pad, hi + pad)
}

/// Draws `plot` to `path` (PNG, 900 x 560).
pub fn line_plot(plot: &LinePlot, path: &Path, protected: &[&Path]) -> Result<()> {
    register_font()?;
    let size = (900u32, 560u32);
    let mut buf = vec![0u8; (size.0 * size.1 * 3) as usize];
    render_line_plot(plot, &mut buf, size).map_err(|e| Error::io(path, e))?;
    write_png(path, protected, &buf, size)
}

fn render_line_plot(plot: &LinePlot, buf: &mut [u8], size: (u32, u32)) -> std::io::Result<()> {
    let all = || plot.series.iter().flat_map(|s| s.points.iter());
    let (x0, x1) = padded(
        all().map(|p| p.0).fold(f64::INFINITY, f64::min),
        all().map(|p| p.0).fold(f64::NEG_INFINITY, f64::max),
    );
    let (y0, y1) = padded(
        all().map(|p| p.2.min(p.1)).fold(f64::INFINITY, f64::min),
        all()
            .map(|p| p.3.max(p.1))
            .fold(f64::NEG_INFINITY, f64::max),
    );
    let root = BitMapBackend::with_buffer(buf, size).into_drawing_area();
    root.fill(&WHITE).map_err(draw_err)?;
    let mut chart = ChartBuilder::on(&root)
        .caption(&plot.title, (FAMILY, 22))
        .margin(15)
        .x_label_area_size(55)
        .y_label_area_size(80)
        .build_cartesian_2d(x0..x1, y0..y1)
        .map_err(draw_err)?;
    chart
        .configure_mesh()
        .x_desc(plot.x_label.as_str())
        .y_desc(plot.y_label.as_str())
        .label_style((FAMILY, 15))
        .axis_desc_style((FAMILY, 17))
        .light_line_style(WHITE.mix(0.0))
        .draw()
        .map_err(draw_err)?;
    for (i, s) in plot.series.iter().enumerate() {
        let color = PALETTE[i % PALETTE.len()];
        let band: Vec<(f64, f64)> = s
            .points
            .iter()
            .map(|p| (p.0, p.3))
            .chain(s.points.iter().rev().map(|p| (p.0, p.2)))
            .collect();
        chart
            .draw_series(std::iter::once(Polygon::new(
                band,
                color.mix(0.18).filled(),
            )))
            .map_err(draw_err)?;
        chart
            .draw_series(LineSeries::new(
                s.points.iter().map(|p| (p.0, p.1)),
                color.stroke_width(2),
            ))
            .map_err(draw_err)?
            .label(s.label.as_str())
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 24, y)], color.stroke_width(2))
            });
        chart
            .draw_series(
                s.points
                    .iter()
                    .map(|p| Circle::new((p.0, p.1), 4, color.filled())),
            )
            .map_err(draw_err)?;
    }
    chart
        .configure_series_labels()
        .label_font((FAMILY, 15))
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .position(SeriesLabelPosition::UpperRight)
        .draw()
        .map_err(draw_err)?;
    root.present().map_err(draw_err)?;
    Ok(())
}

/// One panel of a bird's-eye figure.
#[derive(Clone, Debug)]
pub struct BirdsEyePanel {
    /// Title of the panel.
    pub title: String,
    /// Points: x, y in metres and class (-2 ground, -1 noise, k >= 0 cluster id).
    pub points: Vec<(f32, f32, i32)>,
}

/// Draws up to four panels in a 2 x 2 grid, each showing `-extent..extent` metres
/// around the sensor, clusters coloured, ground grey, unclustered points dark grey.
pub fn birdseye(
    title: &str,
    panels: &[BirdsEyePanel],
    extent_m: f64,
    path: &Path,
    protected: &[&Path],
) -> Result<()> {
    register_font()?;
    let size = (1400u32, 1440u32);
    let mut buf = vec![0u8; (size.0 * size.1 * 3) as usize];
    render_birdseye(title, panels, extent_m, &mut buf, size).map_err(|e| Error::io(path, e))?;
    write_png(path, protected, &buf, size)
}

fn render_birdseye(
    title: &str,
    panels: &[BirdsEyePanel],
    e: f64,
    buf: &mut [u8],
    size: (u32, u32),
) -> std::io::Result<()> {
    let root = BitMapBackend::with_buffer(buf, size).into_drawing_area();
    root.fill(&WHITE).map_err(draw_err)?;
    let root = root.titled(title, (FAMILY, 26)).map_err(draw_err)?;
    let ground = RGBColor(190, 190, 190);
    let noise = RGBColor(90, 90, 90);
    for (area, panel) in root.split_evenly((2, 2)).iter().zip(panels) {
        let mut chart = ChartBuilder::on(area)
            .caption(&panel.title, (FAMILY, 22))
            .margin(12)
            .x_label_area_size(45)
            .y_label_area_size(55)
            .build_cartesian_2d(-e..e, -e..e)
            .map_err(draw_err)?;
        chart
            .configure_mesh()
            .x_desc("x, forward (m)")
            .y_desc("y, left (m)")
            .label_style((FAMILY, 14))
            .axis_desc_style((FAMILY, 16))
            .light_line_style(WHITE.mix(0.0))
            .draw()
            .map_err(draw_err)?;
        let inside = |p: &&(f32, f32, i32)| f64::from(p.0).abs() < e && f64::from(p.1).abs() < e;
        chart
            .draw_series(
                panel
                    .points
                    .iter()
                    .filter(inside)
                    .filter(|p| p.2 < 0)
                    .map(|p| {
                        let c = if p.2 == -2 { ground } else { noise };
                        Pixel::new((f64::from(p.0), f64::from(p.1)), c)
                    }),
            )
            .map_err(draw_err)?;
        chart
            .draw_series(
                panel
                    .points
                    .iter()
                    .filter(inside)
                    .filter(|p| p.2 >= 0)
                    .map(|p| {
                        let c = PALETTE[p.2 as usize % PALETTE.len()];
                        Circle::new((f64::from(p.0), f64::from(p.1)), 1, c.filled())
                    }),
            )
            .map_err(draw_err)?;
    }
    root.present().map_err(draw_err)?;
    Ok(())
}
