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

mod axis;
mod birdseye;
pub mod heatmap;
mod line;

pub use birdseye::{birdseye, birdseye_grid, BirdsEyePanel};
pub use line::{line_plot, LinePlot, Series};

/// The font compiled into the binary (DejaVu Sans, Bitstream Vera licence).
pub const FONT: &[u8] = include_bytes!("../../../assets/fonts/DejaVuSans.ttf");
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
pub(super) fn decimals_for(values: &[f64]) -> usize {
    (0..=6)
        .find(|&d| {
            let scale = 10f64.powi(d as i32);
            values
                .iter()
                .all(|v| ((v * scale).round() - v * scale).abs() < 1e-6)
        })
        .unwrap_or(6)
}

pub(super) fn text_style(size: u32) -> TextStyle<'static> {
    TextStyle::from((FAMILY, size).into_font()).color(&BLACK)
}

/// Width of `text` in `style`, in pixels (0 when the font cannot lay it out).
pub(super) fn text_width(text: &str, style: &TextStyle) -> u32 {
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
pub(super) fn draw_marker<DB: DrawingBackend>(
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
pub(super) fn draw_line<DB: DrawingBackend>(
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

#[cfg(test)]
mod tests {
    use super::axis::*;
    use super::birdseye::*;
    use super::line::*;
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
