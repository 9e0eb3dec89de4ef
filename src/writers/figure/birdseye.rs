//! Bird's-eye panels of frames: points coloured by cluster on a grid of panels.

use super::axis::*;
use super::*;
use crate::error::Result;
use plotters::coord::Shift;
use std::path::Path;

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
pub(super) const GROUND: RGBColor = RGBColor(190, 190, 190);
/// Colour of returns that are neither ground nor in a cluster.
pub(super) const UNCLUSTERED: RGBColor = RGBColor(90, 90, 90);

/// Width of one bird's-eye panel and height of its plot (px), and the title and key
/// around the grid.
pub(super) const PANEL_W: u32 = 700;
pub(super) const PANEL_PLOT_H: u32 = 640;
pub(super) const BIRDSEYE_TITLE_PX: (u32, u32) = (26, 32);
pub(super) const BIRDSEYE_KEY_H: u32 = 90;
/// Font sizes and line heights of a panel's title and of its detail lines.
pub(super) const PANEL_TITLE_PX: (u32, u32) = (21, 26);
pub(super) const PANEL_DETAIL_PX: (u32, u32) = (14, 19);

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
pub(super) struct BirdsEyeLayout {
    rows: usize,
    cols: usize,
    title: Vec<String>,
    /// Per panel: its title's lines and its detail lines, wrapped.
    heads: Vec<(Vec<String>, Vec<String>)>,
    /// Height of the panels' heads, per grid row (the row's tallest head): a row of
    /// short titles does not leave room for another row's long stage lists.
    head_h: Vec<u32>,
    pub(super) size: (u32, u32),
}

impl BirdsEyeLayout {
    pub(super) fn title_h(&self) -> u32 {
        12 + BIRDSEYE_TITLE_PX.1 * self.title.len() as u32
    }
    /// Height of grid row `row`.
    pub(super) fn panel_h(&self, row: usize) -> u32 {
        self.head_h[row] + PANEL_PLOT_H
    }
    /// Top of grid row `row`, below the figure's title.
    pub(super) fn row_top(&self, row: usize) -> u32 {
        self.title_h() + (0..row).map(|r| self.panel_h(r)).sum::<u32>()
    }
}

pub(super) fn birdseye_layout(title: &str, panels: &[BirdsEyePanel]) -> BirdsEyeLayout {
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

pub(super) fn render_birdseye<DB: DrawingBackend>(
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
pub(super) fn draw_birdseye_key<DB: DrawingBackend>(
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
