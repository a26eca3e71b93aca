//! FFDNet weight files: the project's safetensors format, its validation,
//! and BatchNorm folding into the convolutions.
//!
//! A file holds `conv.{i}.weight` (`[out, in, 3, 3]`, f32) for every layer
//! `i` and, for the inner layers `1..layers-1`, the BatchNorm tensors
//! `bn.{i}.weight`, `bn.{i}.bias`, `bn.{i}.running_mean` and
//! `bn.{i}.running_var` (`[channels]`, f32). The header's metadata names the
//! architecture; see [`Architecture`]. Nothing else is accepted: a missing,
//! extra or misshapen tensor is an error that names it.

use crate::cnn::FoldedConv;
use std::collections::{BTreeMap, HashMap};
use std::path::Path;

use safetensors::SafeTensors;
use safetensors::tensor::{Dtype, TensorView};

/// The `format` value of the project's FFDNet files.
pub const FORMAT: &str = "scatterscope-ffdnet";
/// The `format_version` this build reads and writes.
pub const FORMAT_VERSION: &str = "1";

/// Errors from reading or validating FFDNet weights.
#[derive(Debug, thiserror::Error)]
pub enum WeightsError {
    /// The file could not be read.
    #[error("{path}: {source}")]
    Io {
        /// File that failed.
        path: String,
        /// Underlying error.
        source: std::io::Error,
    },
    /// The file cannot be read whole (a special file, or too large).
    #[error("{0}")]
    Read(String),
    /// The bytes are not a safetensors file.
    #[error("{origin}: not a safetensors file: {reason}")]
    NotSafetensors {
        /// Where the weights came from.
        origin: String,
        /// What the parser said.
        reason: String,
    },
    /// A metadata field is missing or has a value this build refuses.
    #[error("{origin}: metadata field `{field}` {problem}")]
    Metadata {
        /// Where the weights came from.
        origin: String,
        /// The field.
        field: String,
        /// What is wrong with it.
        problem: String,
    },
    /// A tensor is missing, extra, of the wrong type or shape, or not finite.
    #[error("{origin}: tensor `{tensor}` {problem}")]
    Tensor {
        /// Where the weights came from.
        origin: String,
        /// The tensor's name.
        tensor: String,
        /// What is wrong with it.
        problem: String,
    },
}

/// The network's shape, as named in a weight file's metadata.
#[derive(Debug, Clone, PartialEq)]
pub struct Architecture {
    /// Number of 3x3 convolutions (the original gray FFDNet has 15).
    pub layers: usize,
    /// Feature channels of the inner layers (64 in the original).
    pub channels: usize,
    /// Largest noise sigma (on the [0, 1] scale) the weights were trained
    /// for; larger requests are clamped to it.
    pub sigma_max: f64,
    /// BatchNorm epsilon used when folding.
    pub batchnorm_eps: f64,
}

impl Architecture {
    /// The original gray FFDNet (Zhang, Zuo, Zhang 2018).
    pub fn original() -> Self {
        Architecture {
            layers: 15,
            channels: 64,
            sigma_max: 75.0 / 255.0,
            batchnorm_eps: 1e-5,
        }
    }

    /// The shape in words: layers, channels, the largest sigma.
    pub fn describe(&self) -> String {
        format!(
            "{} layers, {} channels, sigma up to {:.4}",
            self.layers, self.channels, self.sigma_max
        )
    }

    /// Multiply-adds x 2 of one call on an `h` x `w` image.
    pub fn flops(&self, h: usize, w: usize) -> f64 {
        let pixels = h.div_ceil(2) * w.div_ceil(2);
        let c = self.channels;
        let macs = 9 * pixels * (5 * c + (self.layers - 2) * c * c + c * 4);
        2.0 * macs as f64
    }

    /// Input and output channels of layer `i`.
    fn channels_of(&self, i: usize) -> (usize, usize) {
        let cin = if i == 0 { 5 } else { self.channels };
        let cout = if i + 1 == self.layers {
            4
        } else {
            self.channels
        };
        (cin, cout)
    }

    /// The metadata block that describes this architecture.
    pub fn metadata(&self) -> BTreeMap<String, String> {
        [
            ("format", FORMAT.to_string()),
            ("format_version", FORMAT_VERSION.to_string()),
            ("layers", self.layers.to_string()),
            ("channels", self.channels.to_string()),
            ("input_channels", "5".to_string()),
            ("output_channels", "4".to_string()),
            ("sigma_min", "0".to_string()),
            ("sigma_max", format!("{:?}", self.sigma_max)),
            ("padding", "reflect".to_string()),
            ("batchnorm_eps", format!("{:?}", self.batchnorm_eps)),
        ]
        .into_iter()
        .map(|(k, v)| (k.to_string(), v))
        .collect()
    }

    fn from_metadata(origin: &str, meta: &HashMap<String, String>) -> Result<Self, WeightsError> {
        let err = |field: &str, problem: String| WeightsError::Metadata {
            origin: origin.to_string(),
            field: field.to_string(),
            problem,
        };
        let get = |field: &str| {
            meta.get(field)
                .map(String::as_str)
                .ok_or_else(|| err(field, "is missing".into()))
        };
        let expect = |field: &str, want: &str| {
            let v = get(field)?;
            if v == want {
                Ok(())
            } else {
                Err(err(field, format!("is `{v}`, expected `{want}`")))
            }
        };
        expect("format", FORMAT)?;
        expect("format_version", FORMAT_VERSION)?;
        expect("input_channels", "5")?;
        expect("output_channels", "4")?;
        expect("padding", "reflect")?;
        expect("sigma_min", "0")?;
        let int = |field: &str, lo: usize, hi: usize| {
            let v = get(field)?;
            match v.parse::<usize>() {
                Ok(n) if (lo..=hi).contains(&n) => Ok(n),
                _ => Err(err(
                    field,
                    format!("is `{v}`, expected an integer in {lo}..={hi}"),
                )),
            }
        };
        let real = |field: &str, lo: f64, hi: f64| {
            let v = get(field)?;
            match v.parse::<f64>() {
                Ok(x) if x > lo && x <= hi => Ok(x),
                _ => Err(err(
                    field,
                    format!("is `{v}`, expected a number in ({lo}, {hi}]"),
                )),
            }
        };
        Ok(Architecture {
            layers: int("layers", 3, 64)?,
            channels: int("channels", 1, 1024)?,
            sigma_max: real("sigma_max", 0.0, 1.0)?,
            batchnorm_eps: real("batchnorm_eps", 0.0, 1.0)?,
        })
    }

    /// The tensors a file of this architecture holds, with their shapes.
    pub fn tensor_shapes(&self) -> Vec<(String, Vec<usize>)> {
        let mut out = Vec::new();
        for i in 0..self.layers {
            let (cin, cout) = self.channels_of(i);
            out.push((format!("conv.{i}.weight"), vec![cout, cin, 3, 3]));
            if i > 0 && i + 1 < self.layers {
                for p in ["weight", "bias", "running_mean", "running_var"] {
                    out.push((format!("bn.{i}.{p}"), vec![cout]));
                }
            }
        }
        out
    }

    /// Deterministic tensors of this architecture's shapes, not a trained
    /// network: the work of a call does not depend on the values, so a
    /// benchmark of an architecture, or a test of the file format and the
    /// BatchNorm folding, needs no download. Running variances are
    /// positive and vary by channel.
    pub fn stand_in_tensors(&self) -> BTreeMap<String, Vec<f32>> {
        self.tensor_shapes()
            .into_iter()
            .map(|(name, shape)| {
                let n: usize = shape.iter().product();
                let v = (0..n)
                    .map(|i| {
                        if name.ends_with("running_var") {
                            1.0 + (i % 3) as f32
                        } else {
                            ((i * 7919 % 101) as f32 / 101.0 - 0.5) * 0.2
                        }
                    })
                    .collect();
                (name, v)
            })
            .collect()
    }
}

/// Validated FFDNet weights: the architecture, the folded layers, and the
/// file's metadata (kept to name the prior in traces).
#[derive(Debug, Clone)]
pub struct FfdnetWeights {
    /// The architecture from the metadata.
    pub arch: Architecture,
    /// Layers with BatchNorm folded into the convolutions.
    pub layers: Vec<FoldedConv>,
    /// Every metadata entry of the file.
    pub metadata: BTreeMap<String, String>,
}

/// Largest weight file read (the original FFDNet's is 2 MB).
pub const MAX_WEIGHT_FILE: u64 = 256 << 20;

impl FfdnetWeights {
    /// Reads and validates a weight file.
    pub fn from_file(path: &Path) -> Result<Self, WeightsError> {
        let bytes = crate::files::read_bounded(path, MAX_WEIGHT_FILE, "weight file")
            .map_err(|e| WeightsError::Read(e.to_string()))?;
        Self::from_bytes(&bytes, &path.display().to_string())
    }

    /// Validates the bytes of a safetensors file; `origin` names it in errors.
    pub fn from_bytes(bytes: &[u8], origin: &str) -> Result<Self, WeightsError> {
        let not_st = |e: safetensors::SafeTensorError| WeightsError::NotSafetensors {
            origin: origin.to_string(),
            reason: e.to_string(),
        };
        let (_, header) = SafeTensors::read_metadata(bytes).map_err(not_st)?;
        let meta = header.metadata().clone().unwrap_or_default();
        let arch = Architecture::from_metadata(origin, &meta)?;
        let tensors = SafeTensors::deserialize(bytes).map_err(not_st)?;
        let expected = arch.tensor_shapes();
        let terr = |tensor: &str, problem: String| WeightsError::Tensor {
            origin: origin.to_string(),
            tensor: tensor.to_string(),
            problem,
        };
        for name in tensors.names() {
            if !expected.iter().any(|(n, _)| n == name) {
                return Err(terr(
                    name,
                    format!(
                        "is not part of a {}-layer, {}-channel FFDNet",
                        arch.layers, arch.channels
                    ),
                ));
            }
        }
        let mut values: HashMap<String, Vec<f32>> = HashMap::new();
        for (name, shape) in &expected {
            let view = tensors
                .tensor(name)
                .map_err(|_| terr(name, "is missing".into()))?;
            values.insert(name.clone(), read_f32(&view, shape, |p| terr(name, p))?);
        }
        let layers = fold(&arch, &values);
        Ok(FfdnetWeights {
            arch,
            layers,
            metadata: meta.into_iter().collect(),
        })
    }
}

fn read_f32(
    view: &TensorView<'_>,
    shape: &[usize],
    err: impl Fn(String) -> WeightsError,
) -> Result<Vec<f32>, WeightsError> {
    crate::cnn::read_f32(view, shape).map_err(err)
}

/// Folds each inner layer's BatchNorm (inference mode) into its convolution:
/// `gamma * (conv - mean) / sqrt(var + eps) + beta` becomes a convolution
/// with weights scaled by `gamma / sqrt(var + eps)` plus a bias. Computed in
/// f64 and rounded once.
fn fold(arch: &Architecture, t: &HashMap<String, Vec<f32>>) -> Vec<FoldedConv> {
    (0..arch.layers)
        .map(|i| {
            let (cin, cout) = arch.channels_of(i);
            let w = &t[&format!("conv.{i}.weight")];
            let inner = i > 0 && i + 1 < arch.layers;
            let (scale, shift): (Vec<f64>, Option<Vec<f32>>) = if inner {
                let g = &t[&format!("bn.{i}.weight")];
                let b = &t[&format!("bn.{i}.bias")];
                let m = &t[&format!("bn.{i}.running_mean")];
                let v = &t[&format!("bn.{i}.running_var")];
                let scale: Vec<f64> = (0..cout)
                    .map(|c| f64::from(g[c]) / (f64::from(v[c]) + arch.batchnorm_eps).sqrt())
                    .collect();
                let shift = (0..cout)
                    .map(|c| (f64::from(b[c]) - f64::from(m[c]) * scale[c]) as f32)
                    .collect();
                (scale, Some(shift))
            } else {
                (vec![1.0; cout], None)
            };
            FoldedConv::from_torch((cin, cout), w, &scale, shift, i + 1 < arch.layers)
        })
        .collect()
}

/// Serialises unfolded weights (`tensors` in the layout above) with the
/// architecture's metadata plus `extra` entries, validating them first by
/// reading the result back.
pub fn to_safetensors(
    arch: &Architecture,
    tensors: &BTreeMap<String, Vec<f32>>,
    extra: &BTreeMap<String, String>,
    origin: &str,
) -> Result<Vec<u8>, WeightsError> {
    let shapes: HashMap<String, Vec<usize>> = arch.tensor_shapes().into_iter().collect();
    let bytes: Vec<(String, Vec<u8>, Vec<usize>)> = tensors
        .iter()
        .map(|(name, v)| {
            let shape = shapes.get(name).cloned().unwrap_or_else(|| vec![v.len()]);
            (name.clone(), bytemuck::cast_slice(v).to_vec(), shape)
        })
        .collect();
    let views = bytes
        .iter()
        .map(|(name, b, shape)| {
            TensorView::new(Dtype::F32, shape.clone(), b)
                .map(|v| (name.clone(), v))
                .map_err(|e| WeightsError::Tensor {
                    origin: origin.to_string(),
                    tensor: name.clone(),
                    problem: format!(
                        "has {} elements, expected shape {shape:?} ({e})",
                        b.len() / 4
                    ),
                })
        })
        .collect::<Result<Vec<_>, _>>()?;
    let mut meta: HashMap<String, String> = arch.metadata().into_iter().collect();
    meta.extend(extra.clone());
    let out =
        safetensors::serialize(views, Some(meta)).map_err(|e| WeightsError::NotSafetensors {
            origin: origin.to_string(),
            reason: e.to_string(),
        })?;
    FfdnetWeights::from_bytes(&out, origin)?;
    Ok(out)
}
