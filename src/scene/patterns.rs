//! The built-in scenes, drawn in a resolution-independent way: sizes are
//! fractions of the shorter image side.

use ndarray::Array2;

use super::draw::{fill_rect, supersample};
use crate::font;

/// Background transmittance of the chart-like scenes.
const DARK: f64 = 0.05;

/// USAF-1951-style chart: elements of three vertical and three horizontal
/// bars (bar length 5 widths), each element 2^(1/6) smaller than the last,
/// laid out in rows from 3.9 % of the shorter side down to about one pixel at
/// 256 pixels.
pub fn usaf(h: usize, w: usize) -> Array2<f64> {
    let side = h.min(w) as f64;
    let mut img = Array2::from_elem((h, w), DARK);
    let margin = 0.05 * side;
    let (mut x, mut y, mut row_height) = (margin, margin, 0.0f64);
    let mut bar = 0.039 * side;
    while bar >= 0.9 {
        let element_w = 11.0 * bar;
        let element_h = 5.0 * bar;
        if x + element_w > w as f64 - margin {
            x = margin;
            y += row_height + 2.0 * bar.max(1.0);
            row_height = 0.0;
        }
        if y + element_h > h as f64 - margin {
            break;
        }
        for i in 0..3 {
            let off = 2.0 * i as f64 * bar;
            // Vertical bars (resolve horizontal detail) ...
            fill_rect(
                &mut img,
                x + off,
                y,
                x + off + bar,
                y + element_h,
                1.0 - DARK,
            );
            // ... and horizontal bars beside them.
            let hx = x + 6.0 * bar;
            fill_rect(
                &mut img,
                hx,
                y + off,
                hx + element_h,
                y + off + bar,
                1.0 - DARK,
            );
        }
        x += element_w + 2.0 * bar;
        row_height = row_height.max(element_h);
        bar /= 2f64.powf(1.0 / 6.0);
    }
    img
}

/// Siemens star: `sectors` bright and as many dark wedges inside 45 % of the
/// shorter side, dark outside.
pub fn siemens_star(h: usize, w: usize, sectors: usize) -> Array2<f64> {
    let radius = 0.45 * h.min(w) as f64;
    let (cy, cx) = (h as f64 / 2.0, w as f64 / 2.0);
    supersample(h, w, 4, |x, y| {
        let (dx, dy) = (x - cx, y - cy);
        let r = (dx * dx + dy * dy).sqrt();
        let bright = r <= radius && (sectors as f64 * dy.atan2(dx)).cos() > 0.0;
        if bright { 1.0 } else { DARK }
    })
}

/// Lines of text, centred, as bright glyphs on a dark background.
pub fn text(h: usize, w: usize, lines: &[&str]) -> Array2<f64> {
    let mut img = Array2::from_elem((h, w), DARK);
    let cols = lines.iter().map(|l| l.chars().count()).max().unwrap_or(0);
    if cols == 0 {
        return img;
    }
    // One font pixel = `cell` image pixels; glyphs 6 cells apart, lines 9.
    let cell_w = 0.9 * w as f64 / (6 * cols - 1) as f64;
    let cell_h = 0.9 * h as f64 / (9 * lines.len() - 2) as f64;
    let cell = cell_w.min(cell_h);
    let block_h = cell * (9 * lines.len() - 2) as f64;
    let top = 0.5 * (h as f64 - block_h);
    for (li, line) in lines.iter().enumerate() {
        let n = line.chars().count();
        let left = 0.5 * (w as f64 - cell * (6 * n - 1) as f64);
        let y0 = top + 9.0 * li as f64 * cell;
        for (ci, ch) in line.chars().enumerate() {
            let x0 = left + 6.0 * ci as f64 * cell;
            for row in 0..font::GLYPH_HEIGHT {
                for col in 0..font::GLYPH_WIDTH {
                    if font::pixel(ch, col, row) {
                        let (x, y) = (x0 + col as f64 * cell, y0 + row as f64 * cell);
                        fill_rect(&mut img, x, y, x + cell, y + cell, 1.0 - DARK);
                    }
                }
            }
        }
    }
    img
}

/// A 3 x 3 grid of disks: radius shrinks down the rows (12 %, 7 %, 3.5 % of
/// the shorter side), contrast above the 0.1 background shrinks across the
/// columns (0.9, 0.5, 0.2).
pub fn disks(h: usize, w: usize) -> Array2<f64> {
    const BACKGROUND: f64 = 0.1;
    let side = h.min(w) as f64;
    let radii = [0.12 * side, 0.07 * side, 0.035 * side];
    let contrasts = [0.9, 0.5, 0.2];
    supersample(h, w, 4, |x, y| {
        let (row, col) = ((3.0 * y / h as f64) as usize, (3.0 * x / w as f64) as usize);
        let (cy, cx) = (
            (row as f64 + 0.5) * h as f64 / 3.0,
            (col as f64 + 0.5) * w as f64 / 3.0,
        );
        let r = radii[row.min(2)];
        if (x - cx).powi(2) + (y - cy).powi(2) <= r * r {
            BACKGROUND + contrasts[col.min(2)]
        } else {
            BACKGROUND
        }
    })
}
