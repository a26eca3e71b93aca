//! PNG charts and heatmaps (plotters, bitmap backend): the report's
//! figures and the calibrations' plots.
//!
//! plotters draws text only with a registered font; the DejaVu Sans font
//! ships inside the `dejavu` crate and is registered once, so no system
//! font library is needed.

use std::path::Path;
use std::sync::Once;

use plotters::prelude::*;
use plotters::style::FontStyle;

/// One named series of (x, y) points.
pub struct Series {
    /// Legend label.
    pub label: String,
    /// Points in x order.
    pub points: Vec<(f64, f64)>,
}

/// Writes a rendered RGB chart whole.
fn save_rgb(pixels: &[u8], width: u32, height: u32, path: &Path) -> Result<(), String> {
    crate::formats::png::write_png_bytes(
        pixels,
        width,
        height,
        image::ExtendedColorType::Rgb8,
        path,
    )
    .map_err(|e| e.to_string())
}

fn register_font() {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| {
        plotters::style::register_font("sans-serif", FontStyle::Normal, dejavu::sans::regular())
            .unwrap_or_else(|_| panic!("the embedded DejaVu Sans font is a valid TrueType file"));
    });
}

const COLORS: [RGBColor; 6] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
];

fn bounds(all: impl Iterator<Item = (f64, f64)>) -> ((f64, f64), (f64, f64)) {
    let mut xr = (f64::INFINITY, f64::NEG_INFINITY);
    let mut yr = (f64::INFINITY, f64::NEG_INFINITY);
    for (x, y) in all.filter(|(x, y)| x.is_finite() && y.is_finite()) {
        xr = (xr.0.min(x), xr.1.max(x));
        yr = (yr.0.min(y), yr.1.max(y));
    }
    if !xr.0.is_finite() {
        return ((0.0, 1.0), (0.0, 1.0));
    }
    let pad = |(lo, hi): (f64, f64), f: f64| {
        let span = (hi - lo).max(1e-9);
        (lo - f * span, hi + f * span)
    };
    (pad(xr, 0.02), pad(yr, 0.08))
}

/// Draws `points` series as markers and `lines` series as lines on one chart.
pub fn chart(
    path: &Path,
    title: &str,
    x_label: &str,
    y_label: &str,
    points: &[Series],
    lines: &[Series],
    log_x: bool,
) -> Result<(), String> {
    register_font();
    let all = points
        .iter()
        .chain(lines)
        .flat_map(|s| s.points.iter().copied());
    let ((x0, x1), (y0, y1)) = bounds(all);
    let (width, height) = (960u32, 600u32);
    let mut pixels = vec![0u8; (width * height * 3) as usize];
    let root = BitMapBackend::with_buffer(&mut pixels, (width, height)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| e.to_string())?;
    let mut builder = ChartBuilder::on(&root);
    builder
        .caption(title, ("sans-serif", 22))
        .margin(12)
        .x_label_area_size(44)
        .y_label_area_size(56);
    macro_rules! draw {
        ($chart:expr) => {{
            let mut chart = $chart;
            chart
                .configure_mesh()
                .x_desc(x_label)
                .y_desc(y_label)
                .label_style(("sans-serif", 14))
                .draw()
                .map_err(|e| e.to_string())?;
            for (i, s) in points.iter().enumerate() {
                let c = COLORS[i % COLORS.len()];
                chart
                    .draw_series(s.points.iter().map(|&p| Circle::new(p, 5, c.filled())))
                    .map_err(|e| e.to_string())?
                    .label(s.label.clone())
                    .legend(move |(x, y)| Circle::new((x + 10, y), 5, c.filled()));
            }
            for (i, s) in lines.iter().enumerate() {
                let c = COLORS[(i + points.len()) % COLORS.len()];
                chart
                    .draw_series(LineSeries::new(s.points.iter().copied(), c.stroke_width(2)))
                    .map_err(|e| e.to_string())?
                    .label(s.label.clone())
                    .legend(move |(x, y)| {
                        PathElement::new(vec![(x, y), (x + 20, y)], c.stroke_width(2))
                    });
            }
            chart
                .configure_series_labels()
                .label_font(("sans-serif", 14))
                .background_style(WHITE.mix(0.85))
                .border_style(BLACK)
                .position(SeriesLabelPosition::LowerRight)
                .draw()
                .map_err(|e| e.to_string())?;
        }};
    }
    if log_x {
        // Padded by a factor on the log axis, from the smallest positive x.
        let positive = points
            .iter()
            .chain(lines)
            .flat_map(|s| s.points.iter().map(|p| p.0))
            .filter(|x| *x > 0.0 && x.is_finite());
        let (lo, hi) = positive.fold((f64::INFINITY, 0.0f64), |(a, b), x| (a.min(x), b.max(x)));
        let (lo, hi) = if lo.is_finite() {
            (lo / 1.5, hi * 1.5)
        } else {
            (1e-3, 1.0)
        };
        draw!(
            builder
                .build_cartesian_2d((lo..hi.max(lo * 10.0)).log_scale(), y0..y1)
                .map_err(|e| e.to_string())?
        );
    } else {
        draw!(
            builder
                .build_cartesian_2d(x0..x1, y0..y1)
                .map_err(|e| e.to_string())?
        );
    }
    root.present().map_err(|e| e.to_string())?;
    drop(builder);
    drop(root);
    save_rgb(&pixels, width, height, path)
}

/// One image drawn as gray cells on metric axes.
pub struct Heatmap<'a> {
    /// Values, indexed (row, column); row 0 at the top.
    pub values: ndarray::ArrayView2<'a, f64>,
    /// Title above the plot.
    pub title: &'a str,
    /// Horizontal axis: label and the centres of the first and last column.
    pub x: (&'a str, f64, f64),
    /// Vertical axis: label and the centres of the first and last row.
    pub y: (&'a str, f64, f64),
}

/// Draws `map` as a PNG: black at 0 (or the minimum when negative), white
/// at the maximum, the cells centred on their coordinates.
pub fn heatmap(path: &Path, map: &Heatmap) -> Result<(), String> {
    register_font();
    let (rows, cols) = map.values.dim();
    let half = |(_, a, b): (&str, f64, f64), n: usize| {
        let step = if n > 1 { (b - a) / (n - 1) as f64 } else { 1.0 };
        (step, a - 0.5 * step, b + 0.5 * step)
    };
    let (xs, x0, x1) = half(map.x, cols);
    let (ys, y0, y1) = half(map.y, rows);
    let lo = map.values.iter().fold(0.0f64, |m, &v| m.min(v));
    let hi = map.values.iter().fold(lo, |m, &v| m.max(v));
    let span = if hi > lo { hi - lo } else { 1.0 };
    let aspect = ((y1 - y0) / (x1 - x0)).abs().clamp(0.25, 4.0);
    let width = 640u32;
    let height = ((width - 80) as f64 * aspect) as u32 + 90;
    let mut pixels = vec![0u8; (width * height * 3) as usize];
    let root = BitMapBackend::with_buffer(&mut pixels, (width, height)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| e.to_string())?;
    // The vertical axis runs downwards, as images are read.
    let mut chart = ChartBuilder::on(&root)
        .caption(map.title, ("sans-serif", 18))
        .margin(10)
        .x_label_area_size(40)
        .y_label_area_size(56)
        .build_cartesian_2d(x0.min(x1)..x0.max(x1), y1.max(y0)..y0.min(y1))
        .map_err(|e| e.to_string())?;
    chart
        .configure_mesh()
        .disable_mesh()
        .x_desc(map.x.0)
        .y_desc(map.y.0)
        .label_style(("sans-serif", 13))
        .draw()
        .map_err(|e| e.to_string())?;
    chart
        .draw_series(map.values.indexed_iter().map(|((r, c), &v)| {
            let g = (255.0 * ((v - lo) / span).clamp(0.0, 1.0)).round() as u8;
            let (cx, cy) = (map.x.1 + c as f64 * xs, map.y.1 + r as f64 * ys);
            Rectangle::new(
                [
                    (cx - 0.5 * xs, cy - 0.5 * ys),
                    (cx + 0.5 * xs, cy + 0.5 * ys),
                ],
                RGBColor(g, g, g).filled(),
            )
        }))
        .map_err(|e| e.to_string())?;
    root.present().map_err(|e| e.to_string())?;
    drop(chart);
    drop(root);
    save_rgb(&pixels, width, height, path)
}
