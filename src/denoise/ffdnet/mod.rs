//! FFDNet (Zhang, Zuo, Zhang 2018), gray: a CNN denoiser that takes the
//! noise level as an input map, so one network serves every sigma that
//! PnP-ADMM asks for.
//!
//! Forward pass: pad odd sizes by reflection (bottom/right), 2x2
//! pixel-unshuffle into four sub-images (offsets (0,0), (0,1), (1,0), (1,1)),
//! prepend a constant noise-level map (channel 0), run the 3x3 convolutions
//! (ReLU after all but the last, BatchNorm folded in at load time), and
//! subtract the pixel-shuffled output (the predicted noise) from the padded
//! input. f32 throughout.

pub mod pth;
pub mod source;
pub mod weights;

use ndarray::{Array2, ArrayView2};

use self::weights::FfdnetWeights;
use super::Denoiser;
use crate::cnn::conv::{FeatureMap, conv3x3};
use crate::cnn::winograd::{WinogradWeights, conv3x3_winograd, transform_weights};

/// FFDNet with loaded weights.
#[derive(Debug, Clone)]
pub struct Ffdnet {
    weights: FfdnetWeights,
    /// Winograd-transformed weights of the layers wide enough to gain from
    /// it (both sides at least [`WINOGRAD_MIN_CHANNELS`]); `None` runs im2col.
    winograd: Vec<Option<WinogradWeights>>,
    label: String,
}

/// Narrower layers (the 5-channel input, the 4-channel output) run im2col:
/// their transforms would cost more than the multiplies they save.
const WINOGRAD_MIN_CHANNELS: usize = 16;

impl Ffdnet {
    /// Wraps validated weights; `label` says where they came from (it is
    /// part of [`Denoiser::name`], so traces name the prior used).
    pub fn new(weights: FfdnetWeights, label: impl Into<String>) -> Self {
        let winograd = weights
            .layers
            .iter()
            .map(|l| {
                (l.cin >= WINOGRAD_MIN_CHANNELS && l.cout >= WINOGRAD_MIN_CHANNELS)
                    .then(|| transform_weights(l))
            })
            .collect();
        Ffdnet {
            weights,
            winograd,
            label: label.into(),
        }
    }

    /// Loads and validates a weight file; `label` as in [`Ffdnet::new`].
    pub fn from_file(
        path: &std::path::Path,
        label: impl Into<String>,
    ) -> Result<Self, weights::WeightsError> {
        Ok(Self::new(FfdnetWeights::from_file(path)?, label))
    }

    /// The network in words: its name, architecture, trained sigma
    /// range, cost per 256 x 256 call, and its weights' metadata.
    pub fn describe(&self) -> Vec<String> {
        let a = &self.weights().arch;
        let mut lines = vec![
            format!("prior: {}", self.name()),
            format!(
                "{} layers, {} channels, sigma in [0, {:.4}], {:.2} GFLOP per 256x256 call",
                a.layers,
                a.channels,
                a.sigma_max,
                a.flops(256, 256) / 1e9
            ),
        ];
        lines.extend(
            self.weights()
                .metadata
                .iter()
                .map(|(k, v)| format!("  {k}: {v}")),
        );
        lines
    }

    /// The weights in use.
    pub fn weights(&self) -> &FfdnetWeights {
        &self.weights
    }

    /// Denoises an image on the [0, 1] scale. `sigma` is clamped to the
    /// weights' trained range `[0, sigma_max]` (see [`Denoiser::sigma_max`]).
    pub fn run(&self, img: ArrayView2<f32>, sigma: f32) -> Array2<f32> {
        let (h, w) = img.dim();
        if h == 0 || w == 0 {
            return img.to_owned();
        }
        let sigma = sigma.clamp(0.0, self.weights.arch.sigma_max as f32);
        let (h2, w2) = (h.div_ceil(2), w.div_ceil(2));
        // Reflection padding to even size: row h is row h - 2 (the edge row
        // itself is not repeated). A 1-pixel dimension has nothing to
        // reflect and repeats its only row/column.
        let src = |y: usize, x: usize| {
            let yy = if y < h { y } else { h.saturating_sub(2) };
            let xx = if x < w { x } else { w.saturating_sub(2) };
            img[[yy, xx]]
        };
        let mut map = FeatureMap::zeros(h2, w2, 5);
        for y in 0..h2 {
            for x in 0..w2 {
                let at = map.at(y, x);
                map.data[at] = sigma;
                map.data[at + 1] = src(2 * y, 2 * x);
                map.data[at + 2] = src(2 * y, 2 * x + 1);
                map.data[at + 3] = src(2 * y + 1, 2 * x);
                map.data[at + 4] = src(2 * y + 1, 2 * x + 1);
            }
        }
        let mut spare = FeatureMap::zeros(h2, w2, self.weights.arch.channels);
        for (layer, wino) in self.weights.layers.iter().zip(&self.winograd) {
            if spare.c != layer.cout {
                spare = FeatureMap::zeros(h2, w2, layer.cout);
            }
            match wino {
                Some(u) => conv3x3_winograd(layer, u, &map, &mut spare),
                None => conv3x3(layer, &map, &mut spare),
            }
            std::mem::swap(&mut map, &mut spare);
        }
        Array2::from_shape_fn((h, w), |(y, x)| {
            let at = map.at(y / 2, x / 2) + 2 * (y % 2) + x % 2;
            img[[y, x]] - map.data[at]
        })
    }
}

impl Denoiser for Ffdnet {
    fn name(&self) -> String {
        let a = &self.weights.arch;
        format!("ffdnet({}; {}x{})", self.label, a.layers, a.channels)
    }

    fn denoise_unit(&self, img: ArrayView2<f64>, sigma: f64) -> Array2<f64> {
        let x = img.mapv(|v| v as f32);
        self.run(x.view(), sigma as f32).mapv(f64::from)
    }

    fn sigma_max(&self) -> f64 {
        self.weights.arch.sigma_max
    }

    fn unshuffles(&self) -> bool {
        true
    }

    /// Two activations of `channels` on the half-resolution grid, the
    /// im2col or Winograd buffers (about 9 more), and the image's copies.
    fn working_bytes(&self, h: usize, w: usize) -> u64 {
        let half = (h / 2 + 1) * (w / 2 + 1);
        crate::memory::bytes_of([half, self.weights.arch.channels], 4 * 12)
            .saturating_add(crate::memory::bytes_of([h, w], 32))
    }

    /// The network does not become the identity at small sigma: PnP's
    /// primal residual reaches a minimum and rises again (BENCHMARKS.md).
    fn fades_to_identity(&self) -> bool {
        false
    }
}
