//! Table heatmaps (PNG or SVG): labelled rows and columns of coloured cells with text,
//! and a key. Each cell names its verdict in words, so the colour is never the only cue.
//!
//! Used for the interaction table of `sweep --interactions` (stage pairs x distance
//! bands). Drawn with plotters' primitives rather than a chart: the axes are categories.

use super::{draw_err, register_font, wrap_text, write_figure, FigureFormat, FAMILY};
use crate::error::{Error, Result};
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};
use std::path::Path;

/// One cell: its fill colour and up to three short lines of text.
#[derive(Clone, Debug)]
pub struct HeatCell {
    /// Fill colour.
    pub color: RGBColor,
    /// Lines of text, centred.
    pub lines: Vec<String>,
}

/// A labelled grid of cells with a colour key.
#[derive(Clone, Debug)]
pub struct Heatmap {
    /// Title above the grid.
    pub title: String,
    /// One label per row.
    pub rows: Vec<String>,
    /// One label per column.
    pub columns: Vec<String>,
    /// `cells[row][column]`.
    pub cells: Vec<Vec<HeatCell>>,
    /// Colour key below the grid: (colour, meaning).
    pub key: Vec<(RGBColor, String)>,
    /// Notes printed under the key, one line each.
    pub notes: Vec<String>,
}

const ROW_LABEL_W: u32 = 260;
const CELL_W: u32 = 170;
const CELL_H: u32 = 64;
const TOP: u32 = 90;
const MARGIN: u32 = 20;

/// Draws `map` to `path` in `format` (size from the grid).
pub fn heatmap(
    map: &Heatmap,
    path: &Path,
    protected: &[&Path],
    format: FigureFormat,
) -> Result<()> {
    register_font()?;
    if map.cells.len() != map.rows.len() || map.cells.iter().any(|r| r.len() != map.columns.len()) {
        return Err(Error::Invalid(format!(
            "{}: heatmap cells do not match its rows and columns",
            path.display()
        )));
    }
    let w = MARGIN * 2 + ROW_LABEL_W + CELL_W * map.columns.len().max(1) as u32;
    let key_h = 34 * map.key.len().div_ceil(3) as u32 + 22 * map.notes.len() as u32;
    let h = TOP + CELL_H * map.rows.len() as u32 + 30 + key_h + MARGIN;
    write_figure(
        path,
        protected,
        format,
        (w, h),
        &map.title,
        "",
        |root| render(map, root),
        |root| render(map, root),
    )
}

fn render<DB: DrawingBackend>(map: &Heatmap, root: DrawingArea<DB, Shift>) -> std::io::Result<()> {
    root.fill(&WHITE).map_err(draw_err)?;
    let style = |px: u32, h: HPos, v: VPos| {
        TextStyle::from((FAMILY, px).into_font())
            .color(&BLACK)
            .pos(Pos::new(h, v))
    };
    let centred = |px: u32| style(px, HPos::Center, VPos::Center);
    let left = |px: u32| style(px, HPos::Left, VPos::Center);
    let i = |v: u32| v as i32;
    root.draw(&Text::new(
        map.title.clone(),
        (i(MARGIN), i(MARGIN)),
        style(22, HPos::Left, VPos::Top),
    ))
    .map_err(draw_err)?;
    let x0 = MARGIN + ROW_LABEL_W;
    for (c, label) in map.columns.iter().enumerate() {
        let cx = x0 + CELL_W * c as u32 + CELL_W / 2;
        // Wrapped to the cell's width, the last line just above the grid.
        let lines = wrap_text(label, &centred(16), CELL_W - 8);
        for (k, line) in lines.iter().enumerate() {
            let up = 18 * (lines.len() - 1 - k) as u32;
            root.draw(&Text::new(
                line.clone(),
                (i(cx), i(TOP - 18 - up)),
                centred(16),
            ))
            .map_err(draw_err)?;
        }
    }
    for (r, label) in map.rows.iter().enumerate() {
        let y = TOP + CELL_H * r as u32;
        let lines = wrap_text(label, &left(16), ROW_LABEL_W - 10);
        let n = lines.len() as u32;
        for (k, line) in lines.iter().enumerate() {
            let ly = y + CELL_H / 2 + 19 * k as u32;
            root.draw(&Text::new(
                line.clone(),
                (i(MARGIN), i(ly - 19 * (n - 1) / 2)),
                left(16),
            ))
            .map_err(draw_err)?;
        }
        for (c, cell) in map.cells[r].iter().enumerate() {
            let x = x0 + CELL_W * c as u32;
            root.draw(&Rectangle::new(
                [(i(x), i(y)), (i(x + CELL_W), i(y + CELL_H))],
                cell.color.filled(),
            ))
            .map_err(draw_err)?;
            root.draw(&Rectangle::new(
                [(i(x), i(y)), (i(x + CELL_W), i(y + CELL_H))],
                WHITE.stroke_width(2),
            ))
            .map_err(draw_err)?;
            let n = cell.lines.len().max(1) as u32;
            for (k, line) in cell.lines.iter().enumerate() {
                let ly = y + CELL_H * (2 * k as u32 + 1) / (2 * n);
                root.draw(&Text::new(
                    line.clone(),
                    (i(x + CELL_W / 2), i(ly)),
                    centred(14),
                ))
                .map_err(draw_err)?;
            }
        }
    }
    let ky = TOP + CELL_H * map.rows.len() as u32 + 30;
    for (k, (color, meaning)) in map.key.iter().enumerate() {
        let x = MARGIN + (k % 3) as u32 * 300;
        let y = ky + 34 * (k / 3) as u32;
        root.draw(&Rectangle::new(
            [(i(x), i(y)), (i(x + 22), i(y + 22))],
            color.filled(),
        ))
        .map_err(draw_err)?;
        // The border keeps a white swatch ("no objects") visible.
        root.draw(&Rectangle::new(
            [(i(x), i(y)), (i(x + 22), i(y + 22))],
            RGBColor(120, 120, 120),
        ))
        .map_err(draw_err)?;
        root.draw(&Text::new(
            meaning.clone(),
            (i(x + 30), i(y + 11)),
            left(15),
        ))
        .map_err(draw_err)?;
    }
    let ny = ky + 34 * map.key.len().div_ceil(3) as u32;
    for (k, note) in map.notes.iter().enumerate() {
        root.draw(&Text::new(
            note.clone(),
            (i(MARGIN), i(ny + 22 * k as u32 + 8)),
            left(14),
        ))
        .map_err(draw_err)?;
    }
    root.present().map_err(draw_err)?;
    Ok(())
}
