//! Test objects: built-in scenes generated in code, or an image file.
//!
//! A scene is a grayscale transmittance image in [0, 1], H x W, `f64`.

mod draw;
mod patterns;

pub use patterns::text;

use std::path::{Path, PathBuf};

use ndarray::Array2;

pub use crate::formats::image::ImageError;

/// Which object to image.
#[derive(Debug, Clone, PartialEq)]
pub enum Scene {
    /// USAF-1951-style resolution chart: bar triplets shrinking by 2^(1/6).
    Usaf,
    /// Siemens star: 36 bright and 36 dark wedges.
    Star,
    /// Text glyphs in the built-in 5 x 7 font.
    Text,
    /// Disks of several sizes and contrasts on a dim background.
    Disks,
    /// A PNG, JPEG or EXR image, converted to grayscale and resized.
    File(PathBuf),
}

impl Scene {
    /// Names of the built-in scenes.
    pub const BUILT_IN: [&'static str; 4] = ["usaf", "star", "text", "disks"];

    /// Parses a built-in name, or takes anything else as a file path.
    pub fn parse(s: &str) -> Self {
        match s {
            "usaf" => Scene::Usaf,
            "star" => Scene::Star,
            "text" => Scene::Text,
            "disks" => Scene::Disks,
            path => Scene::File(PathBuf::from(path)),
        }
    }

    /// Short name for metadata and file names.
    pub fn name(&self) -> String {
        match self {
            Scene::Usaf => "usaf".into(),
            Scene::Star => "star".into(),
            Scene::Text => "text".into(),
            Scene::Disks => "disks".into(),
            Scene::File(p) => p.display().to_string(),
        }
    }

    /// Renders the scene at `height` x `width`, values in [0, 1].
    pub fn render(&self, height: usize, width: usize) -> Result<Array2<f64>, ImageError> {
        Ok(match self {
            Scene::Usaf => patterns::usaf(height, width),
            Scene::Star => patterns::siemens_star(height, width, 36),
            Scene::Text => patterns::text(height, width, &["SCATTER", "SCOPE", "2026"]),
            Scene::Disks => patterns::disks(height, width),
            Scene::File(path) if !path.exists() => {
                return Err(ImageError::Content {
                    path: path.clone(),
                    reason: format!(
                        "no such file, and not a built-in scene ({})",
                        Self::BUILT_IN.join(", ")
                    ),
                });
            }
            Scene::File(path) => {
                crate::formats::image::read_grayscale(Path::new(path), height, width)?
            }
        })
    }
}
