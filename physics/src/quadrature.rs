//! Globally adaptive Gauss-Kronrod (G7/K15) quadrature for vector integrands.
//!
//! The ST-PSF kernel needs one set of time nodes per bin that integrates every
//! pixel accurately. We adapt the node set on a few scalar probes (the total
//! mass and the narrowest pixels) and then reuse the final nodes for the whole
//! image. Hand-written because the crates we looked at integrate one scalar
//! function and do not expose their final node set.

/// Positive Kronrod nodes of the 15-point rule on [-1, 1], outermost first.
const XGK: [f64; 8] = [
    0.991_455_371_120_812_6,
    0.949_107_912_342_758_5,
    0.864_864_423_359_769_1,
    0.741_531_185_599_394_4,
    0.586_087_235_467_691_1,
    0.405_845_151_377_397_2,
    0.207_784_955_007_898_5,
    0.0,
];
/// Kronrod weights matching [`XGK`].
const WGK: [f64; 8] = [
    0.022_935_322_010_529_22,
    0.063_092_092_629_978_55,
    0.104_790_010_322_250_2,
    0.140_653_259_715_525_9,
    0.169_004_726_639_267_9,
    0.190_350_578_064_785_4,
    0.204_432_940_075_298_9,
    0.209_482_141_084_727_8,
];
/// Gauss weights of the embedded 7-point rule (nodes XGK[1], XGK[3], XGK[5], XGK[7]).
const WG: [f64; 4] = [
    0.129_484_966_168_869_7,
    0.279_705_391_489_276_7,
    0.381_830_050_505_118_9,
    0.417_959_183_673_469_4,
];

/// One quadrature node: abscissa and weight.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Node {
    /// Abscissa in the integration variable.
    pub x: f64,
    /// Weight (already scaled by the panel half-width).
    pub w: f64,
}

/// Result of [`adaptive_nodes`].
#[derive(Debug, Clone)]
pub struct Adapted<const N: usize> {
    /// Kronrod nodes of every accepted panel.
    pub nodes: Vec<Node>,
    /// Integral estimate of each component.
    pub integral: [f64; N],
    /// Estimated absolute error of each component.
    pub error: [f64; N],
    /// Whether every component met the tolerance before the panel cap.
    pub converged: bool,
}

struct Panel<const N: usize> {
    a: f64,
    b: f64,
    kronrod: [f64; N],
    error: [f64; N],
}

fn panel<const N: usize>(a: f64, b: f64, f: &mut impl FnMut(f64) -> [f64; N]) -> Panel<N> {
    let half = 0.5 * (b - a);
    let mid = 0.5 * (a + b);
    let mut kronrod = [0.0; N];
    let mut gauss = [0.0; N];
    for (i, (&x, &wk)) in XGK.iter().zip(&WGK).enumerate() {
        let points: &[f64] = if x == 0.0 { &[0.0] } else { &[-x, x] };
        for &sx in points {
            let v = f(mid + half * sx);
            for c in 0..N {
                kronrod[c] += wk * v[c];
                if i % 2 == 1 {
                    gauss[c] += WG[i / 2] * v[c];
                }
            }
        }
    }
    let mut error = [0.0; N];
    for c in 0..N {
        kronrod[c] *= half;
        error[c] = (kronrod[c] - gauss[c] * half).abs();
    }
    Panel {
        a,
        b,
        kronrod,
        error,
    }
}

/// Integrates the vector function `f` over `[breaks[0], breaks[last]]`,
/// starting from the panels between consecutive `breaks` and bisecting the
/// panel with the largest relative error until every component's total error
/// is at most `rtol` times its integral, or `max_panels` panels exist.
///
/// Like every adaptive rule it can only refine features its nodes have seen:
/// callers put breakpoints where the integrand changes scale.
pub fn adaptive_nodes<const N: usize>(
    breaks: &[f64],
    rtol: f64,
    max_panels: usize,
    mut f: impl FnMut(f64) -> [f64; N],
) -> Adapted<N> {
    let mut panels: Vec<Panel<N>> = breaks
        .windows(2)
        .map(|w| panel(w[0], w[1], &mut f))
        .collect();
    loop {
        let mut integral = [0.0; N];
        let mut error = [0.0; N];
        for p in &panels {
            for c in 0..N {
                integral[c] += p.kronrod[c];
                error[c] += p.error[c];
            }
        }
        let scale = integral.map(|v| v.abs().max(f64::MIN_POSITIVE));
        let converged = (0..N).all(|c| error[c] <= rtol * scale[c]);
        if converged || panels.len() >= max_panels {
            let nodes = panels.iter().flat_map(panel_nodes).collect();
            return Adapted {
                nodes,
                integral,
                error,
                converged,
            };
        }
        let worst = (0..panels.len())
            .max_by(|&i, &j| {
                let ri: f64 = (0..N).map(|c| panels[i].error[c] / scale[c]).sum();
                let rj: f64 = (0..N).map(|c| panels[j].error[c] / scale[c]).sum();
                ri.total_cmp(&rj)
            })
            .expect("breaks span at least one panel");
        let old = panels.swap_remove(worst);
        let mid = 0.5 * (old.a + old.b);
        panels.push(panel(old.a, mid, &mut f));
        panels.push(panel(mid, old.b, &mut f));
    }
}

fn panel_nodes<const N: usize>(p: &Panel<N>) -> Vec<Node> {
    let half = 0.5 * (p.b - p.a);
    let mid = 0.5 * (p.a + p.b);
    let mut nodes = Vec::with_capacity(15);
    for (&x, &wk) in XGK.iter().zip(&WGK) {
        nodes.push(Node {
            x: mid - half * x,
            w: wk * half,
        });
        if x != 0.0 {
            nodes.push(Node {
                x: mid + half * x,
                w: wk * half,
            });
        }
    }
    nodes
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn polynomials_are_exact_on_one_panel() {
        // K15 integrates degree-22 polynomials exactly.
        let r = adaptive_nodes(&[0.0, 2.0], 1e-12, 1, |x| [x.powi(22), 1.0]);
        assert!((r.integral[0] - 2f64.powi(23) / 23.0).abs() < 1e-9);
        assert!((r.integral[1] - 2.0).abs() < 1e-14);
        assert_eq!(r.nodes.len(), 15);
        let wsum: f64 = r.nodes.iter().map(|n| n.w).sum();
        assert!((wsum - 2.0).abs() < 1e-14);
    }

    #[test]
    fn adapts_to_a_sharp_peak() {
        // Narrow Gaussian at an awkward place: exact value from erf.
        let s = 2e-2;
        let r = adaptive_nodes(&[0.0, 1.0], 1e-10, 200, |x| {
            [(-((x - 0.3217) / s).powi(2)).exp()]
        });
        let exact = 0.5
            * s
            * std::f64::consts::PI.sqrt()
            * (libm::erf((1.0 - 0.3217) / s) + libm::erf(0.3217 / s));
        assert!(r.converged);
        assert!(
            r.nodes.len() > 15,
            "a single panel cannot resolve this peak"
        );
        assert!(((r.integral[0] - exact) / exact).abs() < 1e-9);
    }
}
