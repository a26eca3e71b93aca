//! The learned reconstruction's network and its weight file.
//!
//! Design (b), the counts in every stage (`training/unrolled_model.py`
//! defines it in PyTorch; [`super::stages`] runs it): a small U-Net of
//! two scales, shared by the stages, on the project's convolution engine
//! ([`crate::cnn`]): two 3x3 convolutions with ReLU at each of three
//! resolutions (channels `c0`, `c1`, `c2`), 2 x 2 average pooling down,
//! nearest-neighbour upsampling and concatenation with the encoder's maps
//! up, and a last 3x3 convolution whose output is a stage's correction.
//! Inputs are padded at the bottom and right by repeating their last row
//! and column to a multiple of 4, as the PyTorch module does, and the
//! output cropped back.
//!
//! A weight file is safetensors: `{block}.{0,2}.weight` (`[cout, cin, 3,
//! 3]`) and `.bias` for the blocks `enc0`, `enc1`, `mid`, `dec1`, `dec0`,
//! `out.weight`, `out.bias`, and `stage_weights` (one per stage); its
//! metadata names the format, the architecture, the stages and EM steps,
//! the inputs' checkpoints and the ranges it was trained on (JSON), and how
//! it was trained.

use std::collections::BTreeMap;

use ndarray::{Array2, Array3};
use safetensors::SafeTensors;
use serde::{Deserialize, Serialize};

use super::inputs::CHECKPOINTS;
use crate::cnn::FoldedConv;
use crate::cnn::conv::{FeatureMap, conv3x3};
use crate::cnn::layers::{avg_pool2, concat, upsample2};

/// The `format` value of the learned reconstruction's weight files.
pub const FORMAT: &str = "scatterscope-learned";
/// The `format_version` this build reads.
pub const FORMAT_VERSION: &str = "2";
/// The architecture this build runs.
pub const ARCHITECTURE: &str = "unrolled-em";
/// A stage's input channels: the estimate, the log of its EM ratio, the
/// 10th and 40th Richardson-Lucy iterates, the scaled counts, the light
/// level and the blur width.
pub const STAGE_INPUTS: usize = 7;
/// Most stages, and most EM steps a stage, a weight file may ask for.
const MOST_STEPS: usize = 16;

/// Why a weight file cannot be used.
#[derive(Debug, thiserror::Error)]
#[error("{origin}: {problem}")]
pub struct NetError {
    /// Where the weights came from.
    pub origin: String,
    /// What is wrong.
    pub problem: String,
}

/// What a stack may be and still be reconstructed by the network: the
/// ranges its training data spanned (the trainer writes them).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TrainedRanges {
    /// Mean summed counts per sensor pixel, lowest and highest.
    pub photons_per_pixel: [f64; 2],
    /// RMS radius of the time-summed kernel, pixels.
    pub kernel_width_px: [f64; 2],
    /// Background over mean counts, at most.
    pub background_share_max: f64,
}

/// The network with its weights.
#[derive(Debug, Clone)]
pub struct LearnedNet {
    /// Channels at the three scales.
    pub channels: [usize; 3],
    /// Stages: each a correction by the shared U-Net, then EM steps.
    pub stages: usize,
    /// Exact EM steps after each stage's correction.
    pub em_steps: usize,
    /// Each stage's weight on the U-Net's correction.
    pub stage_weights: Vec<f32>,
    blocks: [[FoldedConv; 2]; 5],
    out: FoldedConv,
    /// The ranges it was trained on.
    pub ranges: TrainedRanges,
    /// Every metadata entry of the file.
    pub metadata: BTreeMap<String, String>,
}

/// The encoder and decoder blocks, in file order.
const BLOCKS: [&str; 5] = ["enc0", "enc1", "mid", "dec1", "dec0"];

impl LearnedNet {
    /// Reads and checks a weight file's bytes (`origin` names them in
    /// errors).
    pub fn from_bytes(bytes: &[u8], origin: &str) -> Result<Self, NetError> {
        let fail = |problem: String| NetError {
            origin: origin.to_string(),
            problem,
        };
        let (_, header) = SafeTensors::read_metadata(bytes)
            .map_err(|e| fail(format!("not a safetensors file: {e}")))?;
        let metadata: BTreeMap<String, String> = header
            .metadata()
            .clone()
            .unwrap_or_default()
            .into_iter()
            .collect();
        let field = |name: &str| {
            metadata
                .get(name)
                .cloned()
                .ok_or_else(|| fail(format!("metadata field `{name}` is missing")))
        };
        for (name, want) in [
            ("format", FORMAT),
            ("format_version", FORMAT_VERSION),
            ("architecture", ARCHITECTURE),
        ] {
            let got = field(name)?;
            if got != want {
                return Err(fail(format!(
                    "metadata field `{name}` is `{got}`; this build reads `{want}`"
                )));
            }
        }
        let checkpoints = field("checkpoints")?;
        let want: Vec<String> = CHECKPOINTS.iter().map(|c| c.to_string()).collect();
        if checkpoints != want.join(",") {
            return Err(fail(format!(
                "trained on Richardson-Lucy iterates {checkpoints}; this build computes {}",
                want.join(",")
            )));
        }
        let channels: Vec<usize> = field("channels")?
            .split(',')
            .map(|c| c.trim().parse::<usize>())
            .collect::<Result<_, _>>()
            .map_err(|e| fail(format!("metadata field `channels`: {e}")))?;
        let [c0, c1, c2] = <[usize; 3]>::try_from(channels.as_slice())
            .ok()
            .filter(|c| c.iter().all(|&n| (1..=512).contains(&n)))
            .ok_or_else(|| {
                fail(format!(
                    "metadata field `channels` is {channels:?}: three counts from 1 to 512"
                ))
            })?;
        let count = |name: &str, least: usize| {
            field(name)?
                .trim()
                .parse::<usize>()
                .ok()
                .filter(|n| (least..=MOST_STEPS).contains(n))
                .ok_or_else(|| {
                    fail(format!(
                        "metadata field `{name}`: a count from {least} to {MOST_STEPS}"
                    ))
                })
        };
        let stages = count("stages", 1)?;
        let em_steps = count("em_steps", 0)?;
        let ranges: TrainedRanges = serde_json::from_str(&field("ranges")?)
            .map_err(|e| fail(format!("metadata field `ranges`: {e}")))?;
        let tensors = SafeTensors::deserialize(bytes)
            .map_err(|e| fail(format!("not a safetensors file: {e}")))?;
        let stage_weights = tensors
            .tensor("stage_weights")
            .map_err(|_| fail("tensor `stage_weights` is missing".into()))
            .and_then(|t| {
                crate::cnn::read_f32(&t, &[stages])
                    .map_err(|p| fail(format!("tensor `stage_weights` {p}")))
            })?;
        let shapes = [
            (STAGE_INPUTS, c0),
            (c0, c1),
            (c1, c2),
            (c2 + c1, c1),
            (c1 + c0, c0),
        ];
        let mut expected: Vec<String> = vec!["stage_weights".into()];
        let mut conv = |name: String, (cin, cout): (usize, usize), relu: bool| {
            let weight = tensors
                .tensor(&format!("{name}.weight"))
                .map_err(|_| fail(format!("tensor `{name}.weight` is missing")))?;
            let w = crate::cnn::read_f32(&weight, &[cout, cin, 3, 3])
                .map_err(|p| fail(format!("tensor `{name}.weight` {p}")))?;
            let bias = tensors
                .tensor(&format!("{name}.bias"))
                .map_err(|_| fail(format!("tensor `{name}.bias` is missing")))?;
            let b = crate::cnn::read_f32(&bias, &[cout])
                .map_err(|p| fail(format!("tensor `{name}.bias` {p}")))?;
            expected.extend([format!("{name}.weight"), format!("{name}.bias")]);
            Ok::<_, NetError>(FoldedConv::from_torch(
                (cin, cout),
                &w,
                &vec![1.0; cout],
                Some(b),
                relu,
            ))
        };
        let mut blocks = Vec::with_capacity(BLOCKS.len());
        for (block, (cin, cout)) in BLOCKS.iter().zip(shapes) {
            blocks.push([
                conv(format!("{block}.0"), (cin, cout), true)?,
                conv(format!("{block}.2"), (cout, cout), true)?,
            ]);
        }
        let out = conv("out".into(), (c0, 1), false)?;
        if let Some(extra) = tensors
            .names()
            .into_iter()
            .find(|n| !expected.iter().any(|e| e == *n))
        {
            return Err(fail(format!(
                "tensor `{extra}` is not part of the {ARCHITECTURE} network"
            )));
        }
        Ok(Self {
            channels: [c0, c1, c2],
            stages,
            em_steps,
            stage_weights,
            blocks: blocks.try_into().expect("five blocks"),
            out,
            ranges,
            metadata,
        })
    }

    /// The shared U-Net's correction for a stage's `features`
    /// (`STAGE_INPUTS x H x W`), `H x W`.
    pub fn correction(&self, features: &Array3<f32>) -> Array2<f32> {
        let (c, h, w) = features.dim();
        assert_eq!(c, STAGE_INPUTS, "a stage's input channels");
        // Replicate-padded to a multiple of 4 at the bottom and right.
        let (ph, pw) = (h.div_ceil(4) * 4, w.div_ceil(4) * 4);
        let mut x = FeatureMap::zeros(ph, pw, c);
        for y in 0..ph {
            for xx in 0..pw {
                let at = x.at(y, xx);
                for ch in 0..c {
                    x.data[at + ch] = features[[ch, y.min(h - 1), xx.min(w - 1)]];
                }
            }
        }
        let block = |b: &[FoldedConv; 2], input: &FeatureMap| {
            let mut mid = FeatureMap::zeros(input.h, input.w, b[0].cout);
            conv3x3(&b[0], input, &mut mid);
            let mut out = FeatureMap::zeros(input.h, input.w, b[1].cout);
            conv3x3(&b[1], &mid, &mut out);
            out
        };
        let [enc0, enc1, mid, dec1, dec0] = &self.blocks;
        let e0 = block(enc0, &x);
        let e1 = block(enc1, &avg_pool2(&e0));
        let m = block(mid, &avg_pool2(&e1));
        let d1 = block(dec1, &concat(&upsample2(&m, e1.h, e1.w), &e1));
        let d0 = block(dec0, &concat(&upsample2(&d1, e0.h, e0.w), &e0));
        let mut out = FeatureMap::zeros(ph, pw, 1);
        conv3x3(&self.out, &d0, &mut out);
        Array2::from_shape_fn((h, w), |(y, xx)| out.data[out.at(y, xx)])
    }

    /// The convolutions' scratch on a map `width` pixels wide: one band
    /// of the widest layer per thread ([`crate::cnn::conv::band_bytes`]).
    pub fn scratch_bytes(&self, width: usize) -> u64 {
        let widest = self
            .blocks
            .iter()
            .flatten()
            .chain([&self.out])
            .map(|l| crate::cnn::conv::band_bytes(l.cin, l.cout, width))
            .max()
            .unwrap_or(0);
        widest.saturating_mul(rayon::current_num_threads() as u64)
    }

    /// The file's metadata entry `name`, if any.
    pub fn meta(&self, name: &str) -> Option<&str> {
        self.metadata.get(name).map(String::as_str)
    }

    /// Its architecture, then every metadata entry (what it was trained
    /// on, how, and its ranges), a line each.
    pub fn describe(&self) -> Vec<String> {
        let mut lines = vec![format!(
            "learned network: {ARCHITECTURE}, {} stages of a shared CNN (channels {:?}) each followed by {} EM steps",
            self.stages, self.channels, self.em_steps
        )];
        lines.extend(self.metadata.iter().map(|(k, v)| format!("  {k}: {v}")));
        lines
    }

    /// Whether the file at `path` is a safetensors file of this format
    /// (read for its header only; `false` when it cannot be read).
    pub fn is_file_of_format(path: &std::path::Path) -> bool {
        std::fs::read(path).is_ok_and(|bytes| {
            SafeTensors::read_metadata(&bytes).is_ok_and(|(_, header)| {
                header
                    .metadata()
                    .as_ref()
                    .and_then(|m| m.get("format"))
                    .is_some_and(|f| f == FORMAT)
            })
        })
    }

    /// Why a stack of `photons_per_pixel`, `kernel_width_px` and
    /// `background_share` lies outside what the network was trained on
    /// (each bound widened by [`RANGE_SLACK`]), by name; `None` inside.
    pub fn outside(
        &self,
        photons_per_pixel: f64,
        kernel_width_px: f64,
        background_share: f64,
    ) -> Option<String> {
        let r = &self.ranges;
        let within = |v: f64, [lo, hi]: [f64; 2]| v >= lo / RANGE_SLACK && v <= hi * RANGE_SLACK;
        if !within(photons_per_pixel, r.photons_per_pixel) {
            return Some(format!(
                "{photons_per_pixel:.3} photons per pixel (trained on {:.3} to {:.3})",
                r.photons_per_pixel[0], r.photons_per_pixel[1]
            ));
        }
        if !within(kernel_width_px, r.kernel_width_px) {
            return Some(format!(
                "a blur of {kernel_width_px:.2} px RMS radius (trained on {:.2} to {:.2} px: another slab, or another pixel pitch)",
                r.kernel_width_px[0], r.kernel_width_px[1]
            ));
        }
        if background_share > r.background_share_max * RANGE_SLACK + 1e-9 {
            return Some(format!(
                "a background of {background_share:.3} of the mean counts (trained on at most {:.3})",
                r.background_share_max
            ));
        }
        None
    }
}

/// How far past its trained ranges a stack may lie (a factor on each
/// bound).
pub const RANGE_SLACK: f64 = 1.25;
