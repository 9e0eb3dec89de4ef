//! Line plots with interval bands, one series a style, and a legend beside the plot.

use super::axis::*;
use super::*;
use crate::error::Result;
use plotters::coord::Shift;
use std::path::Path;

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

pub(super) fn padded(lo: f64, hi: f64) -> (f64, f64) {
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
pub(super) const PLOT_W: u32 = 900;
/// Height of a line plot.
pub(super) const PLOT_H: u32 = 560;
/// Widest legend, in pixels.
pub(super) const LEGEND_MAX_W: u32 = 380;

/// Font size and line height of a line plot's title, and of its legend.
pub(super) const TITLE_PX: (u32, u32) = (22, 28);
pub(super) const LEGEND_PX: (u32, u32) = (15, 20);

/// Where the parts of a line plot go: image size, legend width, the title's and the
/// legend's lines (wrapped to fit).
pub(super) struct LineLayout {
    pub(super) size: (u32, u32),
    legend_w: u32,
    title: Vec<String>,
    legend_title: Vec<String>,
    labels: Vec<Vec<String>>,
}

impl LineLayout {
    pub(super) fn title_h(&self) -> u32 {
        12 + TITLE_PX.1 * self.title.len() as u32
    }
}

pub(super) fn line_layout(plot: &LinePlot) -> LineLayout {
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
pub(super) fn legend_h(l: &LineLayout) -> u32 {
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

pub(super) fn legend_width(plot: &LinePlot) -> u32 {
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

pub(super) fn render_line_plot<DB: DrawingBackend>(
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
