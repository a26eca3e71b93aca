//! The project's convolution engine, for every network it runs (the
//! FFDNet prior, the learned reconstruction): zero-padded NHWC feature
//! maps, 3x3 convolutions by im2col and GEMM ([`conv`]) or, for wide
//! layers, Winograd F(4x4, 3x3) ([`winograd`]), and the few other layers
//! those networks use ([`layers`]). Each matches PyTorch's layer of the
//! same name on fixtures (`tests/ffdnet.rs`, `tests/learned.rs`).

pub mod conv;
pub mod layers;
pub mod winograd;

/// One 3x3 convolution ready for the engine (a BatchNorm before it folded
/// in, where the network had one).
#[derive(Debug, Clone)]
pub struct FoldedConv {
    /// Input channels.
    pub cin: usize,
    /// Output channels.
    pub cout: usize,
    /// GEMM right-hand side, `[(ky * 3 + kx) * cin + ci][co]`, row-major.
    pub matrix: Vec<f32>,
    /// Per-output-channel bias (the folded BatchNorm shift), if any.
    pub bias: Option<Vec<f32>>,
    /// Whether a ReLU follows.
    pub relu: bool,
}

impl FoldedConv {
    /// A layer from PyTorch's `Conv2d(cin, cout, 3, padding=1)` weight
    /// (`[cout, cin, 3, 3]`, row-major), each output channel's weights
    /// multiplied by `scale[co]` in f64 and rounded once (1 for a plain
    /// convolution; a folded BatchNorm's factor), with `bias` and an
    /// optional ReLU after it.
    pub fn from_torch(
        (cin, cout): (usize, usize),
        weight: &[f32],
        scale: &[f64],
        bias: Option<Vec<f32>>,
        relu: bool,
    ) -> Self {
        assert_eq!(weight.len(), cout * cin * 9, "a [cout, cin, 3, 3] weight");
        let mut matrix = vec![0f32; 9 * cin * cout];
        for co in 0..cout {
            for ci in 0..cin {
                for k in 0..9 {
                    let src = f64::from(weight[(co * cin + ci) * 9 + k]);
                    matrix[(k * cin + ci) * cout + co] = (src * scale[co]) as f32;
                }
            }
        }
        Self {
            cin,
            cout,
            matrix,
            bias,
            relu,
        }
    }
}

/// The `f32` values of a safetensors tensor, which must have `shape` and
/// hold only finite numbers; the error says what is wrong.
pub fn read_f32(
    view: &safetensors::tensor::TensorView<'_>,
    shape: &[usize],
) -> Result<Vec<f32>, String> {
    if view.dtype() != safetensors::Dtype::F32 {
        return Err(format!("has dtype {:?}, expected F32", view.dtype()));
    }
    if view.shape() != shape {
        return Err(format!(
            "has shape {:?}, expected {:?}",
            view.shape(),
            shape
        ));
    }
    let v: Vec<f32> = view
        .data()
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .collect();
    if let Some((i, x)) = v.iter().enumerate().find(|(_, x)| !x.is_finite()) {
        return Err(format!("element {i} is {x}; weights must be finite"));
    }
    Ok(v)
}
