//! PNG figures drawn with plotters: line plots with interval bands and bird's-eye panels.
//!
//! Text is rendered by plotters' ab_glyph backend from the DejaVu Sans font kept in
//! `assets/fonts/` and compiled into the binary, so no system font library is needed.
//! Images are rendered into memory and encoded with the `png` crate through
//! [`super::atomic::write_atomically`].

use crate::error::{Error, Result};
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};
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

/// Encodes an RGB buffer as PNG to `path`, atomically, with the figure's title as the
/// PNG `Title` text and an optional `Description` (iTXt, UTF-8), so a reader or a test
/// can tell what a file shows without looking at it.
pub(crate) fn write_png(
    path: &Path,
    protected: &[&Path],
    buf: &[u8],
    (w, h): (u32, u32),
    title: &str,
    description: &str,
) -> Result<()> {
    super::atomic::write_atomically(path, protected, |out| {
        let mut enc = png::Encoder::new(out, w, h);
        enc.set_color(png::ColorType::Rgb);
        enc.set_depth(png::BitDepth::Eight);
        enc.add_itxt_chunk("Title".into(), title.into())
            .map_err(std::io::Error::other)?;
        if !description.is_empty() {
            enc.add_itxt_chunk("Description".into(), description.into())
                .map_err(std::io::Error::other)?;
        }
        let mut writer = enc.write_header().map_err(std::io::Error::other)?;
        writer
            .write_image_data(buf)
            .map_err(std::io::Error::other)?;
        writer.finish().map_err(std::io::Error::other)
    })
}

/// Formats `v` with `decimals` decimals, never as negative zero ("-0.0" reads as a
/// value below zero that is not there).
pub fn format_number(v: f64, decimals: usize) -> String {
    let s = format!("{v:.decimals$}");
    match s.strip_prefix('-') {
        Some(rest) if rest.chars().all(|c| c == '0' || c == '.') => rest.to_string(),
        _ => s,
    }
}

/// Fewest decimals (at most 6) that print every value of `values` exactly.
fn decimals_for(values: &[f64]) -> usize {
    (0..=6)
        .find(|&d| {
            let scale = 10f64.powi(d as i32);
            values
                .iter()
                .all(|v| ((v * scale).round() - v * scale).abs() < 1e-6)
        })
        .unwrap_or(6)
}

/// Tick layout of one axis: its range, how many labels to ask plotters for, and the
/// decimals every label gets (one format per axis).
#[derive(Clone, Copy, Debug, PartialEq)]
struct Axis {
    lo: f64,
    hi: f64,
    labels: usize,
    decimals: usize,
}

/// The ticks plotters draws for `lo..hi` when asked for `n` labels.
fn ticks(lo: f64, hi: f64, n: usize) -> Vec<f64> {
    use plotters::coord::ranged1d::Ranged;
    use plotters::coord::types::RangedCoordf64;
    RangedCoordf64::from(lo..hi).key_points(n)
}

/// Lays out an axis over `lo..hi`. An integer axis (counts, integer parameter values)
/// gets only integer ticks, printed without decimals: the number of labels is lowered
/// until plotters' ticks are whole numbers, and the range widened to whole numbers when
/// it is narrower than one.
fn axis(lo: f64, hi: f64, integer: bool) -> Axis {
    const WANT: usize = 8;
    if !integer {
        let t = ticks(lo, hi, WANT);
        return Axis {
            lo,
            hi,
            labels: WANT,
            decimals: decimals_for(&t),
        };
    }
    let whole = |t: &[f64]| t.len() >= 2 && t.iter().all(|v| (v - v.round()).abs() < 1e-9);
    for n in (2..=WANT).rev() {
        if whole(&ticks(lo, hi, n)) {
            return Axis {
                lo,
                hi,
                labels: n,
                decimals: 0,
            };
        }
    }
    // Narrower than one unit: show the whole numbers around it.
    let (mut a, mut b) = (lo.floor(), hi.ceil());
    if b - a < 1.0 {
        a -= 1.0;
        b += 1.0;
    }
    let (a, b) = (a - 0.05 * (b - a), b + 0.05 * (b - a));
    let labels = (2..=WANT)
        .rev()
        .find(|&n| whole(&ticks(a, b, n)))
        .unwrap_or(2);
    Axis {
        lo: a,
        hi: b,
        labels,
        decimals: 0,
    }
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
#[derive(Clone, Debug, Default)]
pub struct LinePlot {
    /// Title above the plot.
    pub title: String,
    /// X axis label with unit.
    pub x_label: String,
    /// Y axis label with unit.
    pub y_label: String,
    /// The lines.
    pub series: Vec<Series>,
    /// X values are whole numbers: integer tick labels.
    pub x_integer: bool,
    /// Y is a count: integer tick labels.
    pub y_integer: bool,
    /// Fixed y range (e.g. 0..1 for shares) widened to hold every point; `None`: the
    /// data's range.
    pub y_range: Option<(f64, f64)>,
    /// Bounds of the values the metric can take (e.g. 0..1 for a share, 0.. for a
    /// count): the interval bands are clipped to them, since a t interval can reach past
    /// them; `None`: not clipped.
    pub y_domain: Option<(f64, f64)>,
    /// Heading of the legend (what the lines are); empty for none.
    pub legend_title: String,
}

impl LinePlot {
    /// True when every mean and bound is zero (or there is no point): nothing to draw.
    pub fn all_zero(&self) -> bool {
        self.series
            .iter()
            .flat_map(|s| s.points.iter())
            .all(|p| p.1 == 0.0 && p.2 == 0.0 && p.3 == 0.0)
    }
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

/// Width of the plot area of a line plot; a legend is drawn to its right, outside the
/// data, and widens the image.
const PLOT_W: u32 = 900;
/// Height of a line plot.
const PLOT_H: u32 = 560;
/// Widest legend, in pixels.
const LEGEND_MAX_W: u32 = 380;

fn text_style(size: u32) -> TextStyle<'static> {
    TextStyle::from((FAMILY, size).into_font()).color(&BLACK)
}

/// Shortens `text` with an ellipsis until it fits `width` pixels in `style`.
fn fit_text<DB: DrawingBackend>(
    area: &DrawingArea<DB, plotters::coord::Shift>,
    text: &str,
    style: &TextStyle,
    width: u32,
) -> String {
    let fits = |t: &str| {
        area.estimate_text_size(t, style)
            .map_or(true, |(w, _)| w <= width)
    };
    if fits(text) {
        return text.to_string();
    }
    let chars: Vec<char> = text.chars().collect();
    for n in (1..chars.len()).rev() {
        let t: String = chars[..n].iter().collect::<String>() + "…";
        if fits(&t) {
            return t;
        }
    }
    "…".into()
}

/// Draws `plot` to `path` (PNG, 900 x 560, wider by the legend when there are several
/// lines; one line needs no legend).
pub fn line_plot(plot: &LinePlot, path: &Path, protected: &[&Path]) -> Result<()> {
    register_font()?;
    let legend_w = legend_width(plot);
    let size = (PLOT_W + legend_w, PLOT_H);
    let mut buf = vec![0u8; (size.0 * size.1 * 3) as usize];
    render_line_plot(plot, legend_w, &mut buf, size).map_err(|e| Error::io(path, e))?;
    write_png(path, protected, &buf, size, &plot.title, "")
}

fn legend_width(plot: &LinePlot) -> u32 {
    if plot.series.len() < 2 {
        return 0;
    }
    // Text width estimated from the font without a canvas: a 1x1 area measures text.
    let mut one = [0u8; 3];
    let area = BitMapBackend::with_buffer(&mut one, (1, 1)).into_drawing_area();
    let style = text_style(15);
    let widest = plot
        .series
        .iter()
        .map(|s| &s.label)
        .chain(std::iter::once(&plot.legend_title))
        .filter_map(|t| area.estimate_text_size(t, &style).ok())
        .map(|(w, _)| w)
        .max()
        .unwrap_or(0);
    (widest + 70).min(LEGEND_MAX_W)
}

fn render_line_plot(
    plot: &LinePlot,
    legend_w: u32,
    buf: &mut [u8],
    size: (u32, u32),
) -> std::io::Result<()> {
    let (dlo, dhi) = plot.y_domain.unwrap_or((f64::NEG_INFINITY, f64::INFINITY));
    let clipped: Vec<Vec<(f64, f64, f64, f64)>> = plot
        .series
        .iter()
        .map(|s| {
            s.points
                .iter()
                .map(|p| (p.0, p.1, p.2.clamp(dlo, dhi), p.3.clamp(dlo, dhi)))
                .collect()
        })
        .collect();
    let all = || clipped.iter().flat_map(|s| s.iter());
    let (x0, x1) = padded(
        all().map(|p| p.0).fold(f64::INFINITY, f64::min),
        all().map(|p| p.0).fold(f64::NEG_INFINITY, f64::max),
    );
    let (mut ylo, mut yhi) = (
        all().map(|p| p.2.min(p.1)).fold(f64::INFINITY, f64::min),
        all()
            .map(|p| p.3.max(p.1))
            .fold(f64::NEG_INFINITY, f64::max),
    );
    let (y0, y1) = match plot.y_range {
        Some((a, b)) => {
            ylo = ylo.min(a);
            yhi = yhi.max(b);
            let pad = (yhi - ylo) * 0.03;
            (ylo - pad, yhi + pad)
        }
        None => padded(ylo, yhi),
    };
    let xa = axis(x0, x1, plot.x_integer);
    let ya = axis(y0, y1, plot.y_integer);
    let root = BitMapBackend::with_buffer(buf, size).into_drawing_area();
    root.fill(&WHITE).map_err(draw_err)?;
    let (left, right) = root.split_horizontally(PLOT_W);
    let mut chart = ChartBuilder::on(&left)
        .caption(&plot.title, (FAMILY, 22))
        .margin(15)
        .x_label_area_size(55)
        .y_label_area_size(80)
        .build_cartesian_2d(xa.lo..xa.hi, ya.lo..ya.hi)
        .map_err(draw_err)?;
    let (xd, yd) = (xa.decimals, ya.decimals);
    let xf = move |v: &f64| format_number(*v, xd);
    let yf = move |v: &f64| format_number(*v, yd);
    chart
        .configure_mesh()
        .x_labels(xa.labels)
        .y_labels(ya.labels)
        .x_label_formatter(&xf)
        .y_label_formatter(&yf)
        .x_desc(plot.x_label.as_str())
        .y_desc(plot.y_label.as_str())
        .label_style((FAMILY, 15))
        .axis_desc_style((FAMILY, 17))
        .light_line_style(WHITE.mix(0.0))
        .draw()
        .map_err(draw_err)?;
    for (i, points) in clipped.iter().enumerate() {
        let color = PALETTE[i % PALETTE.len()];
        let band: Vec<(f64, f64)> = points
            .iter()
            .map(|p| (p.0, p.3))
            .chain(points.iter().rev().map(|p| (p.0, p.2)))
            .collect();
        chart
            .draw_series(std::iter::once(Polygon::new(
                band,
                color.mix(0.18).filled(),
            )))
            .map_err(draw_err)?;
        chart
            .draw_series(LineSeries::new(
                points.iter().map(|p| (p.0, p.1)),
                color.stroke_width(2),
            ))
            .map_err(draw_err)?;
        chart
            .draw_series(
                points
                    .iter()
                    .map(|p| Circle::new((p.0, p.1), 4, color.filled())),
            )
            .map_err(draw_err)?;
    }
    if legend_w > 0 {
        // The legend sits right of the plot area, never over the data.
        let style = text_style(15);
        let mut y = 62;
        if !plot.legend_title.is_empty() {
            let title = fit_text(&right, &plot.legend_title, &style, legend_w - 12);
            right
                .draw(&Text::new(
                    title,
                    (6, y),
                    style
                        .color(&RGBColor(70, 70, 70))
                        .pos(Pos::new(HPos::Left, VPos::Center)),
                ))
                .map_err(draw_err)?;
            y += 28;
        }
        for (i, s) in plot.series.iter().enumerate() {
            let color = PALETTE[i % PALETTE.len()];
            right
                .draw(&PathElement::new(
                    vec![(6, y), (34, y)],
                    color.stroke_width(2),
                ))
                .map_err(draw_err)?;
            right
                .draw(&Circle::new((20, y), 4, color.filled()))
                .map_err(draw_err)?;
            let label = fit_text(&right, &s.label, &style, legend_w.saturating_sub(56));
            right
                .draw(&Text::new(
                    label,
                    (44, y),
                    style.pos(Pos::new(HPos::Left, VPos::Center)),
                ))
                .map_err(draw_err)?;
            y += 26;
        }
    }
    root.present().map_err(draw_err)?;
    Ok(())
}

/// One panel of a bird's-eye figure.
#[derive(Clone, Debug)]
pub struct BirdsEyePanel {
    /// Title of the panel: what it shows (e.g. "rain only · seed 1 · 11 clusters").
    pub title: String,
    /// Smaller lines under the title: the noise stages applied and their settings.
    pub details: Vec<String>,
    /// Points: x, y in metres and class (-2 ground, -1 noise, k >= 0 cluster id).
    pub points: Vec<(f32, f32, i32)>,
}

/// Colour of ground returns in the bird's-eye figure.
const GROUND: RGBColor = RGBColor(190, 190, 190);
/// Colour of returns that are neither ground nor in a cluster.
const UNCLUSTERED: RGBColor = RGBColor(90, 90, 90);

/// Width and height of one bird's-eye panel (px), and the title and key around them.
const PANEL_PX: (u32, u32) = (700, 710);
const BIRDSEYE_FRAME_PX: u32 = 100;

/// Rows and columns of the bird's-eye grid for `n` panels: 2 columns up to four panels,
/// 3 up to nine, then 4, as many rows as needed.
pub fn birdseye_grid(n: usize) -> (usize, usize) {
    let cols = match n {
        0..=4 => 2,
        5..=9 => 3,
        _ => 4,
    };
    (n.div_ceil(cols).max(1), cols)
}

/// Draws every panel in a grid that grows with their number ([`birdseye_grid`]), each
/// showing `-extent..extent` metres around the sensor, clusters coloured, ground grey,
/// unclustered points dark grey, with a colour key under the panels.
pub fn birdseye(
    title: &str,
    panels: &[BirdsEyePanel],
    extent_m: f64,
    path: &Path,
    protected: &[&Path],
) -> Result<()> {
    register_font()?;
    let (rows, cols) = birdseye_grid(panels.len());
    let size = (
        cols as u32 * PANEL_PX.0,
        rows as u32 * PANEL_PX.1 + BIRDSEYE_FRAME_PX,
    );
    let mut buf = vec![0u8; (size.0 * size.1 * 3) as usize];
    render_birdseye(title, panels, extent_m, &mut buf, size).map_err(|e| Error::io(path, e))?;
    // The panels' titles and stage lines, one panel per paragraph.
    let description: Vec<String> = panels
        .iter()
        .map(|p| {
            std::iter::once(p.title.as_str())
                .chain(p.details.iter().map(String::as_str))
                .collect::<Vec<_>>()
                .join("\n")
        })
        .collect();
    write_png(
        path,
        protected,
        &buf,
        size,
        title,
        &description.join("\n\n"),
    )
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
    let (grid, key) = root.split_vertically(size.1 - 40 - 60);
    let lines = panels.iter().map(|p| p.details.len()).max().unwrap_or(0) as u32;
    let header = 34 + 20 * lines;
    let axes = Axis {
        lo: -e,
        hi: e,
        labels: 9,
        decimals: decimals_for(&ticks(-e, e, 9)),
    };
    let d = axes.decimals;
    let fmt = move |v: &f64| format_number(*v, d);
    for (area, panel) in grid
        .split_evenly(birdseye_grid(panels.len()))
        .iter()
        .zip(panels)
    {
        let (head, body) = area.split_vertically(header);
        let (w, _) = head.dim_in_pixel();
        head.draw(&Text::new(
            fit_text(&head, &panel.title, &text_style(21), w - 20),
            (w as i32 / 2, 16),
            text_style(21).pos(Pos::new(HPos::Center, VPos::Center)),
        ))
        .map_err(draw_err)?;
        let small = text_style(14).color(&RGBColor(70, 70, 70));
        for (i, line) in panel.details.iter().enumerate() {
            head.draw(&Text::new(
                fit_text(&head, line, &small, w - 30),
                (w as i32 / 2, 40 + 20 * i as i32),
                small.pos(Pos::new(HPos::Center, VPos::Center)),
            ))
            .map_err(draw_err)?;
        }
        let mut chart = ChartBuilder::on(&body)
            .margin(12)
            .x_label_area_size(45)
            .y_label_area_size(55)
            .build_cartesian_2d(-e..e, -e..e)
            .map_err(draw_err)?;
        chart
            .configure_mesh()
            .x_labels(axes.labels)
            .y_labels(axes.labels)
            .x_label_formatter(&fmt)
            .y_label_formatter(&fmt)
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
                        let c = if p.2 == -2 { GROUND } else { UNCLUSTERED };
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
    draw_birdseye_key(&key).map_err(draw_err)?;
    root.present().map_err(draw_err)?;
    Ok(())
}

/// The colour key of the bird's-eye figure: ground, unclustered returns, clusters.
fn draw_birdseye_key<DB: DrawingBackend>(
    key: &DrawingArea<DB, plotters::coord::Shift>,
) -> std::result::Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    let style = text_style(16).pos(Pos::new(HPos::Left, VPos::Center));
    let y = 30;
    let swatch = |x: i32, c: RGBColor| Rectangle::new([(x, y - 8), (x + 16, y + 8)], c.filled());
    let mut x = 60;
    key.draw(&Text::new("Colour key:", (x, y), style.clone()))?;
    x += 110;
    key.draw(&swatch(x, GROUND))?;
    key.draw(&Text::new("ground", (x + 24, y), style.clone()))?;
    x += 110;
    key.draw(&swatch(x, UNCLUSTERED))?;
    key.draw(&Text::new(
        "not ground, in no cluster (noise, small groups)",
        (x + 24, y),
        style.clone(),
    ))?;
    x += 420;
    for (i, c) in PALETTE.iter().enumerate() {
        key.draw(&swatch(x + 18 * i as i32, *c))?;
    }
    x += 18 * PALETTE.len() as i32 + 8;
    key.draw(&Text::new(
        "clusters (one colour each, repeating)",
        (x, y),
        style.clone(),
    ))?;
    key.draw(&Text::new(
        "Returns dropped by a noise stage or the detection filters are not drawn.",
        (60, y + 30),
        text_style(14)
            .color(&RGBColor(70, 70, 70))
            .pos(Pos::new(HPos::Left, VPos::Center)),
    ))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every panel gets a cell of the grid and is drawn (five and eleven panels were cut
    /// to the first four); cells beyond the panels stay blank.
    #[test]
    fn every_birdseye_panel_is_drawn_whatever_their_number() {
        register_font().unwrap();
        for n in [1, 2, 4, 5, 11] {
            let panels: Vec<BirdsEyePanel> = (0..n)
                .map(|i| BirdsEyePanel {
                    title: format!("panel {i}"),
                    details: vec!["rain 3 mm/h".into()],
                    points: vec![(1.0, 2.0, 0), (-3.0, 1.0, -2), (4.0, -4.0, -1)],
                })
                .collect();
            let (rows, cols) = birdseye_grid(n);
            assert!(
                rows * cols >= n && (rows - 1) * cols < n,
                "{n}: {rows} x {cols}"
            );
            let size = (
                cols as u32 * PANEL_PX.0,
                rows as u32 * PANEL_PX.1 + BIRDSEYE_FRAME_PX,
            );
            let mut buf = vec![0u8; (size.0 * size.1 * 3) as usize];
            render_birdseye("t", &panels, 10.0, &mut buf, size).unwrap();
            // The grid lies between the title (at most 40 px) and the key (100 px).
            let (top, bottom) = (40, size.1 - BIRDSEYE_FRAME_PX);
            let h = (bottom - top) / rows as u32;
            let inked = |k: usize| {
                let (r, c) = ((k / cols) as u32, (k % cols) as u32);
                let (x0, y0) = (c * PANEL_PX.0 + 20, top + r * h + 20);
                (y0..y0 + h - 40).any(|y| {
                    (x0..x0 + PANEL_PX.0 - 40).any(|x| {
                        let i = ((y * size.0 + x) * 3) as usize;
                        buf[i..i + 3] != [255, 255, 255]
                    })
                })
            };
            for k in 0..rows * cols {
                assert_eq!(inked(k), k < n, "{n} panels: cell {k}");
            }
        }
    }

    #[test]
    fn numbers_never_print_negative_zero() {
        assert_eq!(format_number(-0.0, 1), "0.0");
        assert_eq!(format_number(-0.0001, 3), "0.000");
        assert_eq!(format_number(-0.5, 1), "-0.5");
        assert_eq!(format_number(50000.0, 0), "50000");
    }

    #[test]
    fn integer_axes_get_integer_ticks() {
        for (lo, hi) in [
            (15.5, 16.5),
            (18_200.0, 18_950.0),
            (-0.35, 7.35),
            (0.0, 3.0),
            (49_990.2, 50_000.4),
        ] {
            let a = axis(lo, hi, true);
            let t = ticks(a.lo, a.hi, a.labels);
            assert!(t.len() >= 2, "{lo}..{hi}: {t:?}");
            assert!(t.iter().all(|v| v.fract() == 0.0), "{lo}..{hi}: {t:?}");
            assert_eq!(a.decimals, 0);
        }
    }

    #[test]
    fn real_axes_get_one_format() {
        let a = axis(-0.05, 1.05, false);
        let t = ticks(a.lo, a.hi, a.labels);
        let labels: Vec<String> = t.iter().map(|v| format_number(*v, a.decimals)).collect();
        assert!(labels.contains(&"0.0".to_string()), "{labels:?}");
        assert!(labels.iter().all(|l| !l.starts_with("-0")), "{labels:?}");
        assert!(
            labels.iter().all(|l| l.len() == labels[0].len()),
            "{labels:?}"
        );
    }
}
