//! PNG previews: single images and contact sheets of all bins.

use std::path::Path;

use image::{GrayImage, ImageEncoder, Luma};
use ndarray::{ArrayView2, ArrayView3, Axis};

use crate::font;
use crate::named::named;
use crate::stack::{CountsView, Stack, StackError, StackMeta, Unstated};

/// How contact-sheet tiles are scaled to 8 bits.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SheetScale {
    /// One scale for all bins: brightness compares across time.
    Shared,
    /// Each bin scaled to its own maximum: structure of dim bins is visible.
    PerBin,
}

named!(SheetScale {
    Shared => "shared",
    PerBin => "per-bin",
});

const GAP: u32 = 2;
const LABEL_H: u32 = font::GLYPH_HEIGHT as u32 + 3;

/// Writes one image as an 8-bit PNG, scaled so that `max` is white
/// (the image's own maximum when `max` is `None`).
pub fn write_png(img: ArrayView2<f64>, max: Option<f64>, path: &Path) -> Result<(), StackError> {
    let (h, w) = img.dim();
    let top = max.unwrap_or_else(|| img.iter().fold(0.0f64, |m, &v| m.max(v)));
    let mut out = GrayImage::new(w as u32, h as u32);
    for ((r, c), &v) in img.indexed_iter() {
        out.put_pixel(c as u32, r as u32, Luma([to_u8(v, top)]));
    }
    save(&out, path)
}

/// Encodes an 8-bit image (`L8` gray or `Rgb8`, rows of `width` pixels)
/// as PNG and writes it whole ([`crate::files::write_atomic`]).
pub fn write_png_bytes(
    pixels: &[u8],
    width: u32,
    height: u32,
    color: image::ExtendedColorType,
    path: &Path,
) -> Result<(), StackError> {
    let mut bytes = Vec::new();
    image::codecs::png::PngEncoder::new(&mut bytes)
        .write_image(pixels, width, height, color)
        .map_err(|e| StackError::format(path, format!("writing PNG: {e}")))?;
    crate::files::write_atomic(path, bytes).map_err(|e| StackError::io(path, e))
}

fn save(img: &GrayImage, path: &Path) -> Result<(), StackError> {
    write_png_bytes(
        img.as_raw(),
        img.width(),
        img.height(),
        image::ExtendedColorType::L8,
        path,
    )
}

/// Writes all bins of `stack` as a grid of labelled tiles (label: bin start in ps).
pub fn write_contact_sheet(
    stack: &Stack,
    scale: SheetScale,
    path: &Path,
) -> Result<(), StackError> {
    sheet(stack.data.view(), &stack.meta, scale, path)
}

/// [`write_contact_sheet`] of photon `counts` with `meta`, read in the
/// width they are held in.
pub fn write_counts_sheet(
    counts: CountsView,
    meta: &StackMeta,
    scale: SheetScale,
    path: &Path,
) -> Result<(), StackError> {
    match counts {
        CountsView::U16(c) => sheet(c, meta, scale, path),
        CountsView::U32(c) => sheet(c, meta, scale, path),
    }
}

fn sheet<T: Copy + Into<f64>>(
    values: ArrayView3<T>,
    meta: &StackMeta,
    scale: SheetScale,
    path: &Path,
) -> Result<(), StackError> {
    let (k, h, w) = values.dim();
    let cols = (k as f64).sqrt().ceil().max(1.0) as u32;
    let rows = (k as u32).div_ceil(cols).max(1);
    let tile_w = w as u32 + GAP;
    let tile_h = h as u32 + LABEL_H + GAP;
    let mut sheet = GrayImage::from_pixel(cols * tile_w + GAP, rows * tile_h + GAP, Luma([40]));
    let top_of = |v: ArrayView3<T>| v.iter().fold(0.0f64, |m, &v| m.max(v.into()));
    let global = top_of(values);
    let unit = if meta.is_unstated(Unstated::TimeUnit) {
        "CH"
    } else {
        "PS"
    };
    for (i, img) in values.axis_iter(Axis(0)).enumerate() {
        let top = match scale {
            SheetScale::Shared => global,
            SheetScale::PerBin => img.iter().fold(0.0f64, |m, &v| m.max(v.into())),
        };
        let (x0, y0) = (
            GAP + (i as u32 % cols) * tile_w,
            GAP + (i as u32 / cols) * tile_h,
        );
        let label = format!("{:.0}{unit}", meta.bin_starts_ps[i]);
        draw_label(&mut sheet, x0, y0 + 1, &label);
        for ((r, c), &v) in img.indexed_iter() {
            let px = to_u8(v.into(), top);
            sheet.put_pixel(x0 + c as u32, y0 + LABEL_H + r as u32, Luma([px]));
        }
    }
    save(&sheet, path)
}

fn to_u8(v: f64, top: f64) -> u8 {
    if top > 0.0 && v.is_finite() {
        (v / top * 255.0).round().clamp(0.0, 255.0) as u8
    } else {
        0
    }
}

fn draw_label(img: &mut GrayImage, x0: u32, y0: u32, text: &str) {
    for (i, ch) in text.chars().enumerate() {
        for row in 0..font::GLYPH_HEIGHT {
            for col in 0..font::GLYPH_WIDTH {
                let (x, y) = (x0 + (i * 6 + col) as u32, y0 + row as u32);
                if font::pixel(ch, col, row) && x < img.width() && y < img.height() {
                    img.put_pixel(x, y, Luma([255]));
                }
            }
        }
    }
}
