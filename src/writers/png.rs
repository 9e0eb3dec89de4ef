//! Figures drawn with plotters, as PNG or SVG: line plots with interval bands and
//! bird's-eye panels.
//!
//! Text is rendered by plotters' ab_glyph backend from the DejaVu Sans font kept in
//! `assets/fonts/` and compiled into the binary, so no system font library is needed; in
//! SVG the text stays text (family `sans-serif`) and is laid out with the same font's
//! measures. Images are rendered into memory and written through
//! [`super::atomic::write_atomically`] (PNG encoded with the `png` crate).
//!
//! Series are told apart by colour, marker and line style together, so a figure reads
//! in grey print and with any colour vision: the colours are Okabe and Ito's palette
//! ("Color Universal Design", 2008), designed to stay distinct for the common forms of
//! colour blindness. Text that does not fit is wrapped onto more lines, never cut.

use crate::error::{Error, Result};
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};
use std::path::Path;
use std::sync::Once;

/// The font compiled into the binary (DejaVu Sans, Bitstream Vera licence).
pub const FONT: &[u8] = include_bytes!("../../assets/fonts/DejaVuSans.ttf");
/// Family name the font is registered under.
pub(crate) const FAMILY: &str = "sans-serif";

/// Categorical colours for lines and clusters: Okabe and Ito's colour-blind-safe
/// palette, ordered so the first lines get the most distinct colours, without its black
/// (the bird's-eye figure draws unclustered returns dark grey) and with its yellow last
/// (the least visible on white).
pub const PALETTE: [RGBColor; 7] = [
    RGBColor(0, 114, 178),   // blue
    RGBColor(213, 94, 0),    // vermillion
    RGBColor(0, 158, 115),   // bluish green
    RGBColor(204, 121, 167), // reddish purple
    RGBColor(230, 159, 0),   // orange
    RGBColor(86, 180, 233),  // sky blue
    RGBColor(240, 228, 66),  // yellow
];

/// Shape of the marker drawn at each point of a line.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Marker {
    /// Filled circle.
    Circle,
    /// Open square (outline).
    Square,
    /// Filled triangle pointing up.
    TriangleUp,
    /// Open diamond (outline).
    Diamond,
    /// Filled triangle pointing down.
    TriangleDown,
    /// Diagonal cross (two strokes).
    Cross,
    /// Upright plus (two strokes).
    Plus,
}

/// Markers in the order the lines get them.
pub const MARKERS: [Marker; 7] = [
    Marker::Circle,
    Marker::Square,
    Marker::TriangleUp,
    Marker::Diamond,
    Marker::TriangleDown,
    Marker::Cross,
    Marker::Plus,
];

/// Line styles in the order the lines get them: solid, or (dash, gap) in pixels.
pub const DASHES: [Option<(u32, u32)>; 4] = [None, Some((12, 6)), Some((3, 4)), Some((22, 5))];

/// How line `i` of a plot is drawn: colour, marker and line style.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SeriesStyle {
    /// Line and marker colour.
    pub color: RGBColor,
    /// Marker at each point.
    pub marker: Marker,
    /// `None`: solid; else (dash, gap) in pixels.
    pub dash: Option<(u32, u32)>,
}

/// The style of line `i`: colour, marker and dash cycle with different periods (7, 7
/// and 4), so the first seven lines differ in both colour and marker and the first
/// four in line style too; no two of the first 49 lines share colour and marker.
pub fn series_style(i: usize) -> SeriesStyle {
    SeriesStyle {
        color: PALETTE[i % PALETTE.len()],
        marker: MARKERS[(i + i / PALETTE.len()) % MARKERS.len()],
        dash: DASHES[i % DASHES.len()],
    }
}

/// File format of the figures (`--figure-format`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, clap::ValueEnum)]
pub enum FigureFormat {
    /// Raster PNG (what a web page or a slide needs).
    #[default]
    Png,
    /// Vector SVG (scales for print; convert to PDF with e.g. `rsvg-convert -f pdf`).
    Svg,
}

impl FigureFormat {
    /// The file extension, without the dot.
    pub fn extension(self) -> &'static str {
        match self {
            FigureFormat::Png => "png",
            FigureFormat::Svg => "svg",
        }
    }
}

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

/// Width of `text` in `style`, in pixels (0 when the font cannot lay it out).
fn text_width(text: &str, style: &TextStyle) -> u32 {
    style.font.box_size(text).map_or(0, |(w, _)| w)
}

/// Breaks `text` into lines no wider than `width` pixels in `style`, at spaces; a word
/// wider than a line on its own is broken between characters. Nothing is left out.
pub(crate) fn wrap_text(text: &str, style: &TextStyle, width: u32) -> Vec<String> {
    let fits = |t: &str| text_width(t, style) <= width;
    let mut lines: Vec<String> = Vec::new();
    let mut line = String::new();
    for word in text.split(' ').filter(|w| !w.is_empty()) {
        let joined = if line.is_empty() {
            word.to_string()
        } else {
            format!("{line} {word}")
        };
        if fits(&joined) {
            line = joined;
            continue;
        }
        if !line.is_empty() {
            lines.push(std::mem::take(&mut line));
        }
        // The word alone: split it where it must be.
        for c in word.chars() {
            let mut longer = line.clone();
            longer.push(c);
            if !line.is_empty() && !fits(&longer) {
                lines.push(std::mem::take(&mut line));
                line.push(c);
            } else {
                line = longer;
            }
        }
    }
    if !line.is_empty() || lines.is_empty() {
        lines.push(line);
    }
    lines
}

/// Writes `svg` (a document from plotters' SVG backend) to `path`, atomically, with the
/// figure's title and description as its `<title>` and `<desc>` (what a PNG keeps in its
/// text chunks).
pub(crate) fn write_svg(
    path: &Path,
    protected: &[&Path],
    svg: &str,
    title: &str,
    description: &str,
) -> Result<()> {
    let esc = super::html::escape;
    let mut meta = format!("\n<title>{}</title>", esc(title));
    if !description.is_empty() {
        meta.push_str(&format!("\n<desc>{}</desc>", esc(description)));
    }
    // After the opening <svg ...> tag.
    let at = svg
        .find("<svg")
        .and_then(|s| svg[s..].find('>').map(|e| s + e + 1));
    let out = match at {
        Some(i) => format!("{}{meta}{}", &svg[..i], &svg[i..]),
        None => svg.to_string(),
    };
    super::atomic::write_atomically(path, protected, |o| o.write_all(out.as_bytes()))
}

/// Renders a figure of `size` in `format` with `png` or `svg` (the same generic drawing
/// code, once per backend) and writes it to `path` with its title and description.
#[allow(clippy::too_many_arguments)]
pub(crate) fn write_figure(
    path: &Path,
    protected: &[&Path],
    format: FigureFormat,
    size: (u32, u32),
    title: &str,
    description: &str,
    png: impl FnOnce(DrawingArea<BitMapBackend, Shift>) -> std::io::Result<()>,
    svg: impl FnOnce(DrawingArea<SVGBackend, Shift>) -> std::io::Result<()>,
) -> Result<()> {
    match format {
        FigureFormat::Png => {
            let mut buf = vec![0u8; (size.0 * size.1 * 3) as usize];
            png(BitMapBackend::with_buffer(&mut buf, size).into_drawing_area())
                .map_err(|e| Error::io(path, e))?;
            write_png(path, protected, &buf, size, title, description)
        }
        FigureFormat::Svg => {
            let mut text = String::new();
            svg(SVGBackend::with_string(&mut text, size).into_drawing_area())
                .map_err(|e| Error::io(path, e))?;
            write_svg(path, protected, &text, title, description)
        }
    }
}

/// Draws marker `m` centred on pixel `at` of `area`.
fn draw_marker<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    m: Marker,
    (x, y): (i32, i32),
    color: RGBColor,
) -> std::result::Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    let fill = color.filled();
    // Strokes of the open markers are wider than the lines (3 px against 2), so the
    // marker reads as a marker where it sits on its line.
    let stroke = color.stroke_width(3);
    // Square and diamond are open (outlines, a little larger), so where two lines
    // coincide the filled circle or triangle of the other shows inside them.
    let outline = |p: Vec<(i32, i32)>| {
        let mut closed = p.clone();
        closed.push(p[0]);
        area.draw(&PathElement::new(closed, stroke))
    };
    match m {
        Marker::Circle => area.draw(&Circle::new((x, y), 5, fill)),
        Marker::Square => outline(vec![
            (x - 7, y - 7),
            (x + 7, y - 7),
            (x + 7, y + 7),
            (x - 7, y + 7),
        ]),
        Marker::TriangleUp => area.draw(&Polygon::new(
            vec![(x, y - 6), (x + 6, y + 4), (x - 6, y + 4)],
            fill,
        )),
        Marker::Diamond => outline(vec![(x, y - 9), (x + 9, y), (x, y + 9), (x - 9, y)]),
        Marker::TriangleDown => area.draw(&Polygon::new(
            vec![(x, y + 6), (x + 6, y - 4), (x - 6, y - 4)],
            fill,
        )),
        Marker::Cross => {
            area.draw(&PathElement::new(
                vec![(x - 5, y - 5), (x + 5, y + 5)],
                stroke,
            ))?;
            area.draw(&PathElement::new(
                vec![(x - 5, y + 5), (x + 5, y - 5)],
                stroke,
            ))
        }
        Marker::Plus => {
            area.draw(&PathElement::new(vec![(x - 6, y), (x + 6, y)], stroke))?;
            area.draw(&PathElement::new(vec![(x, y - 6), (x, y + 6)], stroke))
        }
    }
}

/// Draws a line through pixels `points` of `area` in line style `dash`.
fn draw_line<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    points: Vec<(i32, i32)>,
    dash: Option<(u32, u32)>,
    color: RGBColor,
) -> std::result::Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    let style = color.stroke_width(2);
    match dash {
        None => area.draw(&PathElement::new(points, style)),
        Some((on, off)) => area.draw(&plotters::element::DashedPathElement::new(
            points, on, off, style,
        )),
    }
}

/// Font size and line height of a line plot's title, and of its legend.
const TITLE_PX: (u32, u32) = (22, 28);
const LEGEND_PX: (u32, u32) = (15, 20);

/// Where the parts of a line plot go: image size, legend width, the title's and the
/// legend's lines (wrapped to fit).
struct LineLayout {
    size: (u32, u32),
    legend_w: u32,
    title: Vec<String>,
    legend_title: Vec<String>,
    labels: Vec<Vec<String>>,
}

impl LineLayout {
    fn title_h(&self) -> u32 {
        12 + TITLE_PX.1 * self.title.len() as u32
    }
}

fn line_layout(plot: &LinePlot) -> LineLayout {
    let legend_w = legend_width(plot);
    let w = PLOT_W + legend_w;
    let title = wrap_text(&plot.title, &text_style(TITLE_PX.0), w - 40);
    let style = text_style(LEGEND_PX.0);
    let (legend_title, labels) = if legend_w > 0 {
        (
            if plot.legend_title.is_empty() {
                Vec::new()
            } else {
                wrap_text(&plot.legend_title, &style, legend_w - 12)
            },
            plot.series
                .iter()
                .map(|s| wrap_text(&s.label, &style, legend_w - 56))
                .collect(),
        )
    } else {
        (Vec::new(), Vec::new())
    };
    let mut layout = LineLayout {
        size: (w, 0),
        legend_w,
        title,
        legend_title,
        labels,
    };
    let legend_h = legend_h(&layout);
    layout.size.1 = layout.title_h() + (PLOT_H - 40).max(legend_h + 20);
    layout
}

/// Height of the legend's lines.
fn legend_h(l: &LineLayout) -> u32 {
    let title = if l.legend_title.is_empty() {
        0
    } else {
        LEGEND_PX.1 * l.legend_title.len() as u32 + 8
    };
    20 + title
        + l.labels
            .iter()
            .map(|s| LEGEND_PX.1 * s.len() as u32 + 6)
            .sum::<u32>()
}

/// Draws `plot` to `path` (900 x 560, wider by the legend when there are several lines,
/// one line needing none, and taller when the title or the legend needs more lines).
pub fn line_plot(
    plot: &LinePlot,
    path: &Path,
    protected: &[&Path],
    format: FigureFormat,
) -> Result<()> {
    register_font()?;
    let layout = line_layout(plot);
    write_figure(
        path,
        protected,
        format,
        layout.size,
        &plot.title,
        "",
        |root| render_line_plot(plot, &layout, root),
        |root| render_line_plot(plot, &layout, root),
    )
}

fn legend_width(plot: &LinePlot) -> u32 {
    if plot.series.len() < 2 {
        return 0;
    }
    let style = text_style(LEGEND_PX.0);
    let widest = plot
        .series
        .iter()
        .map(|s| text_width(&s.label, &style) + 56)
        .chain(std::iter::once(text_width(&plot.legend_title, &style) + 12))
        .max()
        .unwrap_or(0);
    (widest + 14).min(LEGEND_MAX_W)
}

fn render_line_plot<DB: DrawingBackend>(
    plot: &LinePlot,
    layout: &LineLayout,
    root: DrawingArea<DB, Shift>,
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
    root.fill(&WHITE).map_err(draw_err)?;
    let (head, body) = root.split_vertically(layout.title_h());
    let title_style = text_style(TITLE_PX.0).pos(Pos::new(HPos::Center, VPos::Top));
    for (k, line) in layout.title.iter().enumerate() {
        head.draw(&Text::new(
            line.clone(),
            (
                layout.size.0 as i32 / 2,
                10 + (TITLE_PX.1 * k as u32) as i32,
            ),
            title_style.clone(),
        ))
        .map_err(draw_err)?;
    }
    let (left, right) = body.split_horizontally(PLOT_W);
    let mut chart = ChartBuilder::on(&left)
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
    // Bands first, then every line over them, then every marker over the lines: a line
    // hidden under another (the same values) still shows its markers.
    for (i, points) in clipped.iter().enumerate() {
        let band: Vec<(f64, f64)> = points
            .iter()
            .map(|p| (p.0, p.3))
            .chain(points.iter().rev().map(|p| (p.0, p.2)))
            .collect();
        chart
            .draw_series(std::iter::once(Polygon::new(
                band,
                series_style(i).color.mix(0.15).filled(),
            )))
            .map_err(draw_err)?;
    }
    let pixels = |points: &Vec<(f64, f64, f64, f64)>| -> Vec<(i32, i32)> {
        points
            .iter()
            .map(|p| chart.backend_coord(&(p.0, p.1)))
            .collect()
    };
    for (i, points) in clipped.iter().enumerate() {
        let st = series_style(i);
        draw_line(&root, pixels(points), st.dash, st.color).map_err(draw_err)?;
    }
    for (i, points) in clipped.iter().enumerate() {
        let st = series_style(i);
        for p in pixels(points) {
            draw_marker(&root, st.marker, p, st.color).map_err(draw_err)?;
        }
    }
    if layout.legend_w > 0 {
        // The legend sits right of the plot area, never over the data.
        let style = text_style(LEGEND_PX.0).pos(Pos::new(HPos::Left, VPos::Center));
        let (_, top) = right.get_base_pixel();
        let (left_x, _) = right.get_base_pixel();
        let at = |x: i32, y: i32| (left_x + x, top + y);
        let mut y = 30;
        for line in &layout.legend_title {
            root.draw(&Text::new(
                line.clone(),
                at(6, y),
                style.color(&RGBColor(70, 70, 70)),
            ))
            .map_err(draw_err)?;
            y += LEGEND_PX.1 as i32;
        }
        if !layout.legend_title.is_empty() {
            y += 8;
        }
        for (i, lines) in layout.labels.iter().enumerate() {
            let st = series_style(i);
            draw_line(&root, vec![at(4, y), at(44, y)], st.dash, st.color).map_err(draw_err)?;
            draw_marker(&root, st.marker, at(24, y), st.color).map_err(draw_err)?;
            for line in lines {
                root.draw(&Text::new(line.clone(), at(54, y), style.clone()))
                    .map_err(draw_err)?;
                y += LEGEND_PX.1 as i32;
            }
            y += 6;
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

/// Width of one bird's-eye panel and height of its plot (px), and the title and key
/// around the grid.
const PANEL_W: u32 = 700;
const PANEL_PLOT_H: u32 = 640;
const BIRDSEYE_TITLE_PX: (u32, u32) = (26, 32);
const BIRDSEYE_KEY_H: u32 = 90;
/// Font sizes and line heights of a panel's title and of its detail lines.
const PANEL_TITLE_PX: (u32, u32) = (21, 26);
const PANEL_DETAIL_PX: (u32, u32) = (14, 19);

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

/// Where the parts of a bird's-eye figure go: grid, panel height, the wrapped lines.
struct BirdsEyeLayout {
    rows: usize,
    cols: usize,
    title: Vec<String>,
    /// Per panel: its title's lines and its detail lines, wrapped.
    heads: Vec<(Vec<String>, Vec<String>)>,
    /// Height of the panels' heads, per grid row (the row's tallest head): a row of
    /// short titles does not leave room for another row's long stage lists.
    head_h: Vec<u32>,
    size: (u32, u32),
}

impl BirdsEyeLayout {
    fn title_h(&self) -> u32 {
        12 + BIRDSEYE_TITLE_PX.1 * self.title.len() as u32
    }
    /// Height of grid row `row`.
    fn panel_h(&self, row: usize) -> u32 {
        self.head_h[row] + PANEL_PLOT_H
    }
    /// Top of grid row `row`, below the figure's title.
    fn row_top(&self, row: usize) -> u32 {
        self.title_h() + (0..row).map(|r| self.panel_h(r)).sum::<u32>()
    }
}

fn birdseye_layout(title: &str, panels: &[BirdsEyePanel]) -> BirdsEyeLayout {
    let (rows, cols) = birdseye_grid(panels.len());
    let w = cols as u32 * PANEL_W;
    let heads: Vec<(Vec<String>, Vec<String>)> = panels
        .iter()
        .map(|p| {
            let t = wrap_text(&p.title, &text_style(PANEL_TITLE_PX.0), PANEL_W - 30);
            let d = p
                .details
                .iter()
                .flat_map(|l| wrap_text(l, &text_style(PANEL_DETAIL_PX.0), PANEL_W - 30))
                .collect();
            (t, d)
        })
        .collect();
    let head_h = (0..rows)
        .map(|r| {
            heads
                .iter()
                .skip(r * cols)
                .take(cols)
                .map(|(t, d)| {
                    8 + PANEL_TITLE_PX.1 * t.len() as u32 + PANEL_DETAIL_PX.1 * d.len() as u32
                })
                .max()
                .unwrap_or(0)
                + 6
        })
        .collect();
    let mut l = BirdsEyeLayout {
        rows,
        cols,
        title: wrap_text(title, &text_style(BIRDSEYE_TITLE_PX.0), w - 40),
        heads,
        head_h,
        size: (w, 0),
    };
    l.size.1 = l.row_top(rows) + BIRDSEYE_KEY_H;
    l
}

/// Draws every panel in a grid that grows with their number ([`birdseye_grid`]), each
/// showing `-extent..extent` metres around the sensor, clusters coloured, ground grey,
/// unclustered points dark grey, with a colour key under the panels. Titles and stage
/// lines that do not fit a panel's width are wrapped, never cut.
pub fn birdseye(
    title: &str,
    panels: &[BirdsEyePanel],
    extent_m: f64,
    path: &Path,
    protected: &[&Path],
    format: FigureFormat,
) -> Result<()> {
    register_font()?;
    let layout = birdseye_layout(title, panels);
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
    write_figure(
        path,
        protected,
        format,
        layout.size,
        title,
        &description.join("\n\n"),
        |root| render_birdseye(&layout, panels, extent_m, root),
        |root| render_birdseye(&layout, panels, extent_m, root),
    )
}

fn render_birdseye<DB: DrawingBackend>(
    layout: &BirdsEyeLayout,
    panels: &[BirdsEyePanel],
    e: f64,
    root: DrawingArea<DB, Shift>,
) -> std::io::Result<()> {
    root.fill(&WHITE).map_err(draw_err)?;
    let w = layout.size.0 as i32;
    let title_style = text_style(BIRDSEYE_TITLE_PX.0).pos(Pos::new(HPos::Center, VPos::Top));
    for (k, line) in layout.title.iter().enumerate() {
        root.draw(&Text::new(
            line.clone(),
            (w / 2, 8 + (BIRDSEYE_TITLE_PX.1 * k as u32) as i32),
            title_style.clone(),
        ))
        .map_err(draw_err)?;
    }
    let (_, rest) = root.split_vertically(layout.title_h());
    let (grid, key) = rest.split_vertically(layout.row_top(layout.rows) - layout.title_h());
    let axes = Axis {
        lo: -e,
        hi: e,
        labels: 9,
        decimals: decimals_for(&ticks(-e, e, 9)),
    };
    let d = axes.decimals;
    let fmt = move |v: &f64| format_number(*v, d);
    let head_title = text_style(PANEL_TITLE_PX.0).pos(Pos::new(HPos::Center, VPos::Top));
    let small = text_style(PANEL_DETAIL_PX.0)
        .color(&RGBColor(70, 70, 70))
        .pos(Pos::new(HPos::Center, VPos::Top));
    let xs: Vec<u32> = (1..layout.cols as u32).map(|c| c * PANEL_W).collect();
    let ys: Vec<u32> = (1..layout.rows)
        .map(|r| layout.row_top(r) - layout.title_h())
        .collect();
    for (k, ((area, panel), (t, details))) in grid
        .split_by_breakpoints(xs, ys)
        .iter()
        .zip(panels)
        .zip(&layout.heads)
        .enumerate()
    {
        let (head, body) = area.split_vertically(layout.head_h[k / layout.cols]);
        let cx = PANEL_W as i32 / 2;
        let mut y = 6;
        for line in t {
            head.draw(&Text::new(line.clone(), (cx, y), head_title.clone()))
                .map_err(draw_err)?;
            y += PANEL_TITLE_PX.1 as i32;
        }
        for line in details {
            head.draw(&Text::new(line.clone(), (cx, y), small.clone()))
                .map_err(draw_err)?;
            y += PANEL_DETAIL_PX.1 as i32;
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
    key: &DrawingArea<DB, Shift>,
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
            let layout = birdseye_layout("t", &panels);
            let size = layout.size;
            let mut buf = vec![0u8; (size.0 * size.1 * 3) as usize];
            render_birdseye(
                &layout,
                &panels,
                10.0,
                BitMapBackend::with_buffer(&mut buf, size).into_drawing_area(),
            )
            .unwrap();
            // The grid lies between the title and the key.
            let inked = |k: usize| {
                let (r, c) = (k / cols, (k % cols) as u32);
                let h = layout.panel_h(r);
                let (x0, y0) = (c * PANEL_W + 20, layout.row_top(r) + 20);
                (y0..y0 + h - 40).any(|y| {
                    (x0..x0 + PANEL_W - 40).any(|x| {
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

    /// A line plot rendered to SVG, parsed.
    fn svg_of(plot: &LinePlot) -> String {
        register_font().unwrap();
        let layout = line_layout(plot);
        let mut text = String::new();
        render_line_plot(
            plot,
            &layout,
            SVGBackend::with_string(&mut text, layout.size).into_drawing_area(),
        )
        .unwrap();
        text
    }

    fn hex(c: RGBColor) -> String {
        format!("#{:02X}{:02X}{:02X}", c.0, c.1, c.2)
    }

    /// What a series of colour `color` looks like in `svg`: its marker elements (shape
    /// and vertex count) and its line style (solid, or the length of its dashes).
    fn look(svg: &str, color: RGBColor) -> (Vec<String>, String) {
        let doc = roxmltree::Document::parse(svg).unwrap();
        let c = hex(color);
        let mut marks: Vec<String> = Vec::new();
        let mut lines: Vec<f64> = Vec::new();
        for n in doc.descendants().filter(|n| n.is_element()) {
            let attr = |a: &str| n.attribute(a).unwrap_or("");
            let points = || -> Vec<(f64, f64)> {
                attr("points")
                    .split_whitespace()
                    .filter_map(|p| p.split_once(','))
                    .map(|(x, y)| (x.parse().unwrap(), y.parse().unwrap()))
                    .collect()
            };
            let solid_fill = attr("fill") == c && attr("opacity") == "1";
            match n.tag_name().name() {
                "circle" | "rect" if solid_fill => marks.push(n.tag_name().name().into()),
                "polygon" if solid_fill => marks.push(format!("polygon{}", points().len())),
                "polyline" if attr("stroke") == c && attr("stroke-width") == "3" => {
                    let p = points();
                    let upright = p.windows(2).all(|w| w[0].0 == w[1].0 || w[0].1 == w[1].1);
                    marks.push(format!("stroke{} upright {upright}", p.len()))
                }
                "polyline" if attr("stroke") == c && attr("stroke-width") == "2" => {
                    let p = points();
                    lines.push(
                        p.windows(2)
                            .map(|w| (w[1].0 - w[0].0).hypot(w[1].1 - w[0].1))
                            .sum(),
                    );
                }
                _ => {}
            }
        }
        marks.sort();
        marks.dedup();
        // Solid: one path for the plot and one in the legend; dashed: many, most of
        // them one dash long.
        let style = if lines.len() <= 2 {
            "solid".to_string()
        } else {
            let mut rounded: Vec<i64> = lines.iter().map(|l| l.round() as i64).collect();
            rounded.sort_unstable();
            let mode = rounded
                .iter()
                .max_by_key(|&&v| rounded.iter().filter(|&&w| w == v).count())
                .copied()
                .unwrap_or(0);
            format!("dash {mode}")
        };
        (marks, style)
    }

    /// Lines differ by marker and line style as well as colour, and two lines with the
    /// same values both stay visible (in "Objects per frame" one line hid the other, and
    /// only colour told lines apart).
    #[test]
    fn lines_differ_by_marker_and_dash_not_only_colour() {
        let same = [
            (0.0, 0.9, 0.8, 1.0),
            (2.0, 0.7, 0.6, 0.8),
            (5.0, 0.5, 0.4, 0.6),
        ];
        let series: Vec<Series> = (0..4)
            .map(|i| Series {
                label: format!("occlusion {i}"),
                // The first two lines coincide.
                points: same
                    .iter()
                    .map(|p| (p.0, p.1 - 0.1 * (i / 2) as f64, p.2, p.3))
                    .collect(),
            })
            .collect();
        let plot = LinePlot {
            title: "Objects detected (share)".into(),
            x_label: "rain rate (mm/h)".into(),
            y_label: "share".into(),
            series,
            y_range: Some((0.0, 1.0)),
            legend_title: "other varied values".into(),
            ..LinePlot::default()
        };
        let svg = svg_of(&plot);
        let looks: Vec<(Vec<String>, String)> =
            (0..4).map(|i| look(&svg, series_style(i).color)).collect();
        for (i, (marks, style)) in looks.iter().enumerate() {
            assert!(!marks.is_empty(), "line {i} has no marker: {looks:?}");
            for (j, other) in looks.iter().enumerate().skip(i + 1) {
                assert_ne!(marks, &other.0, "lines {i} and {j}: same marker");
                assert_ne!(style, &other.1, "lines {i} and {j}: same line style");
            }
        }
        // The palette is Okabe-Ito's (colour-blind safe), and the first lines differ in
        // colour, marker and dash.
        assert_eq!(hex(series_style(0).color), "#0072B2");
        assert_eq!(hex(series_style(1).color), "#D55E00");
        for i in 0..7 {
            for j in i + 1..7 {
                let (a, b) = (series_style(i), series_style(j));
                assert!(a.color != b.color && a.marker != b.marker, "{i} {j}");
            }
        }
    }

    /// Every text element of an SVG: its content, x, anchor and font size.
    fn texts(svg: &str) -> Vec<(String, f64, String, f64)> {
        let doc = roxmltree::Document::parse(svg).unwrap();
        doc.descendants()
            // Rotated axis titles run along the height; their width is not the concern.
            .filter(|n| n.has_tag_name("text") && n.attribute("transform").is_none())
            .map(|n| {
                let a = |k: &str| n.attribute(k).unwrap_or("").to_string();
                (
                    n.text().unwrap_or("").trim().to_string(),
                    a("x").parse().unwrap_or(0.0),
                    a("text-anchor"),
                    a("font-size").parse().unwrap_or(0.0),
                )
            })
            .collect()
    }

    /// Long titles, panel subtitles and legend labels are wrapped onto more lines, every
    /// word kept, every line inside the image ("overlap 0.9..1…" was cut).
    #[test]
    fn long_text_is_wrapped_not_cut() {
        register_font().unwrap();
        let detail = "occlusion: lasers 1, 2, 3, 4, 5, 6, 7, 8 from azimuth 10 to 350 degrees, \
            overlap 0.9..1.0 of the beam, transmission 0.05, scattering 0.3 \
            (a dirty lens with a long list of settings)";
        let panels: Vec<BirdsEyePanel> = (0..3)
            .map(|i| BirdsEyePanel {
                title: format!(
                    "occlusion and rain together on a long capture name, seed {i}: 12 clusters"
                ),
                details: vec![detail.into(), "rain 3 mm/h".into()],
                points: vec![(1.0, 2.0, 0)],
            })
            .collect();
        let layout = birdseye_layout("monterey frame 1: base configuration, seed 1", &panels);
        let mut svg = String::new();
        render_birdseye(
            &layout,
            &panels,
            10.0,
            SVGBackend::with_string(&mut svg, layout.size).into_drawing_area(),
        )
        .unwrap();
        let label = "a legend label naming every other varied value: rain.rate_mm_h=10, \
            occlusion on, fog.visibility_m=200";
        let plot = LinePlot {
            title: "Objects detected by distance band (share) - a capture with a very long \
                name, so long that the title cannot fit the width of the plot"
                .into(),
            series: vec![
                Series {
                    label: label.into(),
                    points: vec![(0.0, 0.5, 0.4, 0.6), (1.0, 0.6, 0.5, 0.7)],
                },
                Series {
                    label: "short".into(),
                    points: vec![(0.0, 0.3, 0.2, 0.4), (1.0, 0.4, 0.3, 0.5)],
                },
            ],
            legend_title: "other varied values".into(),
            ..LinePlot::default()
        };
        let line_svg = svg_of(&plot);
        let plot_w = line_layout(&plot).size.0;
        for (svg, width, wanted) in [
            (&svg, layout.size.0, vec![detail, panels[0].title.as_str()]),
            (&line_svg, plot_w, vec![label, plot.title.as_str()]),
        ] {
            let all = texts(svg);
            let words: Vec<&str> = all.iter().flat_map(|t| t.0.split_whitespace()).collect();
            for w in wanted.iter().flat_map(|t| t.split_whitespace()) {
                assert!(words.contains(&w), "{w:?} missing from the figure's text");
            }
            for (t, x, anchor, size) in &all {
                assert!(!t.contains('…'), "cut: {t:?}");
                // plotters writes font-size as size / 1.24.
                let style = text_style((size * 1.24).round() as u32);
                let w = f64::from(text_width(t, &style));
                let (lo, hi) = match anchor.as_str() {
                    "middle" => (x - w / 2.0, x + w / 2.0),
                    "end" => (x - w, *x),
                    _ => (*x, x + w),
                };
                assert!(
                    lo >= -1.0 && hi <= f64::from(width) + 1.0,
                    "{t:?} spans {lo}..{hi} of 0..{width}"
                );
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
