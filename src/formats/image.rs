//! Single images in and out: PNG and JPEG (gray levels on a [0, 1]
//! scale), EXR (luminance, values as stored) and 2-D `.npy` (float32 or
//! float64), read as the file's first bytes say (else its extension) and
//! written as the extension says; scenes, truths, denoiser
//! inputs and outputs all go through here.

use std::path::{Path, PathBuf};

use exr::prelude::FlatSamples;
use image::imageops::{FilterType, resize};
use image::{ImageBuffer, Luma};
use ndarray::{Array2, ArrayView2};
use ndarray_npy::{ReadNpyExt, WriteNpyExt};

use super::detect::Format;

/// Why an image file cannot be read or written.
#[derive(Debug, thiserror::Error)]
pub enum ImageError {
    /// The file could not be opened or decoded.
    #[error("{path}: cannot read image: {reason}")]
    Decode {
        /// The file.
        path: PathBuf,
        /// Decoder message.
        reason: String,
    },
    /// The file decoded but its content is unusable.
    #[error("{path}: {reason}")]
    Content {
        /// The file.
        path: PathBuf,
        /// What is wrong, with the value.
        reason: String,
    },
    /// The image could not be written.
    #[error("{path}: {reason}")]
    Write {
        /// The file.
        path: PathBuf,
        /// Why.
        reason: String,
    },
}

/// An error's text without its leading `path: ` (the caller names it).
fn strip_path(path: &Path, text: String) -> String {
    text.strip_prefix(&format!("{}: ", path.display()))
        .map_or(text.clone(), str::to_string)
}

/// Writes `img` as the extension of `path` says: `.png` (8 bits, [0, 1]
/// to black and white, values outside clamped), `.exr` or `.npy` (float32,
/// values as they are).
pub fn write_image(img: ArrayView2<f64>, path: &Path) -> Result<(), ImageError> {
    let fail = |reason: String| ImageError::Write {
        path: path.to_owned(),
        reason,
    };
    match Format::of_extension(path) {
        Format::Png => {
            super::png::write_png(img.mapv(|v| v.clamp(0.0, 1.0)).view(), Some(1.0), path)
                .map_err(|e| fail(e.to_string()))
        }
        Format::Exr => super::exr::write_image(img.mapv(|v| v as f32).view(), path)
            .map_err(|e| fail(e.to_string())),
        Format::Npy => {
            let mut bytes = Vec::new();
            img.mapv(|v| v as f32)
                .write_npy(&mut bytes)
                .map_err(|e| fail(e.to_string()))?;
            crate::files::write_atomic(path, bytes).map_err(|e| fail(e.to_string()))
        }
        _ => Err(fail(format!(
            "unknown extension `{}` (use .png, .exr or .npy)",
            path.extension().unwrap_or_default().to_string_lossy()
        ))),
    }
}

/// A 2-D float32 or float64 `.npy` image, every value finite.
fn read_npy_image(path: &Path) -> Result<Array2<f64>, ImageError> {
    let decode = |reason: String| ImageError::Decode {
        path: path.to_owned(),
        reason,
    };
    crate::formats::npy::checked_header(path, 2)
        .map_err(|e| decode(strip_path(path, e.to_string())))?;
    let open = || std::fs::File::open(path).map_err(|e| decode(e.to_string()));
    let img = match Array2::<f32>::read_npy(open()?) {
        Ok(a) => a.mapv(f64::from),
        Err(_) => Array2::<f64>::read_npy(open()?)
            .map_err(|_| decode("expected a 2-D float32 or float64 .npy array".into()))?,
    };
    if let Some(((r, c), v)) = img.indexed_iter().find(|(_, v)| !v.is_finite()) {
        return Err(ImageError::Content {
            path: path.to_owned(),
            reason: format!("pixel (row {r}, column {c}) is {v}; images must be finite"),
        });
    }
    Ok(img)
}

/// Reads a PNG or JPEG file as grayscale in [0, 1], an EXR file's
/// luminance or a 2-D `.npy` array with its own values, at the file's size.
pub fn read_image(path: &Path) -> Result<Array2<f64>, ImageError> {
    let format = Format::of_file(path);
    let img = if format == Format::Npy {
        read_npy_image(path)?
    } else {
        read_decoded(path, format)?
    };
    if img.is_empty() {
        return Err(ImageError::Content {
            path: path.to_owned(),
            reason: "the image is empty".into(),
        });
    }
    Ok(img)
}

/// A PNG, JPEG or EXR file (`format`, as detected) at its size.
fn read_decoded(path: &Path, format: Format) -> Result<Array2<f64>, ImageError> {
    let gray = decode_luminance(path, format)?;
    let (w, h) = gray.dimensions();
    Ok(Array2::from_shape_fn((h as usize, w as usize), |(r, c)| {
        f64::from(gray.get_pixel(c as u32, r as u32).0[0])
    }))
}

/// The luminance of the file, in `format` (as detected), every value finite.
fn decode_luminance(
    path: &Path,
    format: Format,
) -> Result<ImageBuffer<Luma<f32>, Vec<f32>>, ImageError> {
    let decode = |reason: String| ImageError::Decode {
        path: path.to_owned(),
        reason,
    };
    let gray: ImageBuffer<Luma<f32>, Vec<f32>> = if format == Format::Exr {
        read_exr_luminance(path).map_err(decode)?
    } else {
        let budget = crate::memory::budget().map_err(|e| decode(e.to_string()))?;
        let bytes = crate::files::read_bounded(path, budget.bytes, "image")
            .map_err(|e| strip_path(path, e.to_string()))
            .map_err(decode)?;
        // JPEG decoders fill a cut file's missing blocks with grey and say
        // nothing; a JPEG must end with its EOI marker (FF D9), trailing
        // zero padding aside.
        if bytes.starts_with(&[0xFF, 0xD8]) {
            let end = bytes.iter().rposition(|&b| b != 0).map_or(0, |p| p + 1);
            if !bytes[..end].ends_with(&[0xFF, 0xD9]) {
                return Err(decode(format!(
                    "JPEG without its end marker (FF D9) after {} bytes: the file is cut",
                    bytes.len()
                )));
            }
        }
        let reader = || {
            image::ImageReader::new(std::io::Cursor::new(&bytes))
                .with_guessed_format()
                .map_err(|e| decode(e.to_string()))
        };
        let (w, h) = reader()?
            .into_dimensions()
            .map_err(|e| decode(e.to_string()))?;
        // The decoded pixels (up to 8 bytes each), their float32 gray and
        // the float64 image.
        crate::memory::check(
            crate::memory::bytes_of([w as usize, h as usize], 20),
            || format!("the {w} x {h} image of {}", path.display()),
        )
        .map_err(|e| decode(e.to_string()))?;
        let mut limits = image::Limits::default();
        limits.max_alloc = Some(budget.bytes);
        let mut reader = reader()?;
        reader.limits(limits);
        reader
            .decode()
            .map_err(|e| decode(e.to_string()))?
            .to_luma32f()
    };
    if let Some(bad) = gray.pixels().position(|p| !p.0[0].is_finite()) {
        let (w, _) = gray.dimensions();
        return Err(ImageError::Content {
            path: path.to_owned(),
            reason: format!(
                "pixel (row {}, column {}) is {}; images must be finite",
                bad as u32 / w,
                bad as u32 % w,
                gray.as_raw()[bad]
            ),
        });
    }
    Ok(gray)
}

/// Loads a PNG, JPEG or EXR file as grayscale in [0, 1], resized to
/// `height` x `width` (Lanczos-3, clamped after resampling). EXR data is
/// scaled by its maximum when that exceeds 1.
pub fn read_grayscale(path: &Path, height: usize, width: usize) -> Result<Array2<f64>, ImageError> {
    let mut gray = decode_luminance(path, Format::of_file(path))?;
    let max = gray.pixels().fold(0.0f32, |m, p| m.max(p.0[0]));
    if max > 1.0 {
        gray.pixels_mut().for_each(|p| p.0[0] /= max);
    }
    let resized = if gray.dimensions() == (width as u32, height as u32) {
        gray
    } else {
        resize(&gray, width as u32, height as u32, FilterType::Lanczos3)
    };
    Ok(Array2::from_shape_fn((height, width), |(r, c)| {
        f64::from(resized.get_pixel(c as u32, r as u32).0[0]).clamp(0.0, 1.0)
    }))
}

/// Luminance of the first layer of an EXR file: `Y`, Rec. 709 luminance of
/// `R`, `G`, `B`, or its only channel.
fn read_exr_luminance(path: &Path) -> Result<ImageBuffer<Luma<f32>, Vec<f32>>, String> {
    let layer = crate::formats::exr::read_first_layer(path).map_err(|e| e.to_string())?;
    let size = layer.size;
    let find = |name: &str| {
        layer
            .channel_data
            .list
            .iter()
            .find(|c| c.name == *name)
            .map(|c| samples_f32(&c.sample_data))
    };
    let values: Vec<f32> = if let Some(y) = find("Y") {
        y
    } else if let (Some(r), Some(g), Some(b)) = (find("R"), find("G"), find("B")) {
        r.iter()
            .zip(&g)
            .zip(&b)
            .map(|((r, g), b)| 0.2126 * r + 0.7152 * g + 0.0722 * b)
            .collect()
    } else if layer.channel_data.list.len() == 1 {
        samples_f32(&layer.channel_data.list[0].sample_data)
    } else {
        let names: Vec<String> = layer
            .channel_data
            .list
            .iter()
            .map(|c| c.name.to_string())
            .collect();
        return Err(format!(
            "no Y or R, G, B channel and more than one channel ({})",
            names.join(", ")
        ));
    };
    ImageBuffer::from_raw(size.0 as u32, size.1 as u32, values)
        .ok_or_else(|| "channel size does not match the layer size".to_string())
}

fn samples_f32(s: &FlatSamples) -> Vec<f32> {
    s.values_as_f32().collect()
}
