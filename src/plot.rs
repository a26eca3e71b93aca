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

/// The value at fraction `q` (0 to 1) of `values` sorted, the nearest
/// rank; `None` when empty.
pub fn quantile(mut values: Vec<f64>, q: f64) -> Option<f64> {
    values.sort_by(f64::total_cmp);
    (!values.is_empty()).then(|| values[((values.len() - 1) as f64 * q).round() as usize])
}

/// An image whose hue says one quantity and whose brightness another: a
/// lifetime image coloured by lifetime, weighted by intensity.
pub struct ColouredMap<'a> {
    /// The quantity coloured (NaN cells are black).
    pub values: ndarray::ArrayView2<'a, f64>,
    /// Brightness of each cell, 0 (black) to 1 (full colour).
    pub brightness: ndarray::ArrayView2<'a, f64>,
    /// The values at the colour bar's ends (viridis from the first to the
    /// second; values outside take the end's colour).
    pub range: (f64, f64),
    /// Title above the image.
    pub title: &'a str,
    /// The colour bar's label (the quantity and its unit).
    pub bar_label: &'a str,
}

/// Draws `map` as a PNG: the image, its cells square, with a viridis
/// colour bar on its right.
pub fn coloured_map(path: &Path, map: &ColouredMap) -> Result<(), String> {
    use plotters::style::colors::colormaps::{ColorMap, ViridisRGB};
    register_font();
    let (rows, cols) = map.values.dim();
    let (lo, hi) = map.range;
    let span = if hi > lo { hi - lo } else { 1.0 };
    let colour = |v: f64, b: f64| -> RGBColor {
        if !v.is_finite() || !b.is_finite() {
            return BLACK;
        }
        let t = ((v - lo) / span).clamp(0.0, 1.0);
        let RGBColor(r, g, bl) = ViridisRGB.get_color(t);
        let k = b.clamp(0.0, 1.0);
        let f = |c: u8| (f64::from(c) * k).round() as u8;
        RGBColor(f(r), f(g), f(bl))
    };
    // The image 512 px on its longer side, the bar 110 px to its right.
    let cell = (512.0 / rows.max(cols).max(1) as f64).max(1.0);
    let (iw, ih) = ((cols as f64 * cell) as u32, (rows as f64 * cell) as u32);
    let (width, height) = (iw + 150, ih + 60);
    let mut pixels = vec![0u8; (width * height * 3) as usize];
    // Everything drawing on the buffer lives in this block.
    {
        let root = BitMapBackend::with_buffer(&mut pixels, (width, height)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| e.to_string())?;
        let titled = root
            .titled(map.title, ("sans-serif", 18))
            .map_err(|e| e.to_string())?;
        let (image, bar) = titled.split_horizontally(iw + 20);
        let image = image.margin(10, 10, 10, 10);
        image
            .draw(&Rectangle::new(
                [(0, 0), (iw as i32, ih as i32)],
                BLACK.filled(),
            ))
            .map_err(|e| e.to_string())?;
        for ((r, c), &v) in map.values.indexed_iter() {
            let b = map.brightness[[r, c]];
            let (x0, y0) = ((c as f64 * cell) as i32, (r as f64 * cell) as i32);
            let (x1, y1) = (
                ((c + 1) as f64 * cell) as i32,
                ((r + 1) as f64 * cell) as i32,
            );
            image
                .draw(&Rectangle::new([(x0, y0), (x1, y1)], colour(v, b).filled()))
                .map_err(|e| e.to_string())?;
        }
        let mut chart = ChartBuilder::on(&bar)
            .margin_top(10)
            .margin_bottom(10)
            .margin_right(50)
            .y_label_area_size(0)
            .right_y_label_area_size(45)
            .build_cartesian_2d(0.0..1.0, lo..lo + span)
            .map_err(|e| e.to_string())?;
        chart
            .configure_mesh()
            .disable_mesh()
            .disable_x_axis()
            .y_desc(map.bar_label)
            .label_style(("sans-serif", 12))
            .draw()
            .map_err(|e| e.to_string())?;
        let steps = 128;
        chart
            .draw_series((0..steps).map(|i| {
                let (a, b) = (
                    lo + span * i as f64 / steps as f64,
                    lo + span * (i + 1) as f64 / steps as f64,
                );
                Rectangle::new([(0.0, a), (1.0, b)], colour(0.5 * (a + b), 1.0).filled())
            }))
            .map_err(|e| e.to_string())?;
        drop(chart);
        root.present().map_err(|e| e.to_string())?;
    }
    save_rgb(&pixels, width, height, path)
}

/// Points `(g, s)` of a phasor plot as a 2-D histogram.
pub struct PhasorHistogram<'a> {
    /// Each point's `g` and `s` (NaN points are left out).
    pub points: &'a [(f64, f64)],
    /// Title above the plot.
    pub title: &'a str,
    /// Lifetimes (ps) marked on the universal semicircle, with the
    /// angular frequency (rad/ps) that places them; none when the phasors
    /// are not calibrated.
    pub marks: Option<(&'a [f64], f64)>,
}

/// Draws `plot` as a PNG: counts per cell of a 2-D histogram on a
/// logarithmic grey-to-viridis scale, with the universal semicircle
/// (every single exponential) and its lifetime marks.
pub fn phasor_histogram(path: &Path, plot: &PhasorHistogram) -> Result<(), String> {
    use plotters::style::colors::colormaps::{ColorMap, ViridisRGB};
    register_font();
    // The semicircle's box, widened to hold 99.5 % of the points (within
    // the unit circle, where every phasor of counts lies).
    let inside: Vec<(f64, f64)> = plot
        .points
        .iter()
        .copied()
        .filter(|(g, s)| g.is_finite() && s.is_finite())
        .collect();
    let gs: Vec<f64> = inside.iter().map(|p| p.0).collect();
    let ss: Vec<f64> = inside.iter().map(|p| p.1).collect();
    let (g0, g1) = (
        quantile(gs.clone(), 0.0025)
            .map_or(0.0, |q| q.min(0.0))
            .max(-1.0),
        quantile(gs, 0.9975).map_or(1.0, |q| q.max(1.0)).min(1.0),
    );
    let (s0, s1) = (
        quantile(ss.clone(), 0.0025)
            .map_or(0.0, |q| q.min(0.0))
            .max(-1.0),
        quantile(ss, 0.9975).map_or(0.6, |q| q.max(0.6)).min(1.0),
    );
    let (g0, g1, s0, s1) = (g0 - 0.05, g1 + 0.05, s0 - 0.05, s1 + 0.05);
    let cells = 160usize;
    let step = (g1 - g0).max(s1 - s0) / cells as f64;
    let (nx, ny) = (
        ((g1 - g0) / step).ceil() as usize,
        ((s1 - s0) / step).ceil() as usize,
    );
    let mut counts = vec![0u32; nx * ny];
    for &(g, s) in &inside {
        let (i, j) = (((g - g0) / step).floor(), ((s - s0) / step).floor());
        if i >= 0.0 && j >= 0.0 && (i as usize) < nx && (j as usize) < ny {
            counts[j as usize * nx + i as usize] += 1;
        }
    }
    let top = f64::from(counts.iter().copied().max().unwrap_or(0).max(1));
    let width = 720u32;
    let height = ((f64::from(width - 80) * (s1 - s0) / (g1 - g0)) as u32 + 100).clamp(240, 900);
    let mut pixels = vec![0u8; (width * height * 3) as usize];
    let root = BitMapBackend::with_buffer(&mut pixels, (width, height)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| e.to_string())?;
    let mut chart = ChartBuilder::on(&root)
        .caption(plot.title, ("sans-serif", 18))
        .margin(10)
        .x_label_area_size(40)
        .y_label_area_size(50)
        .build_cartesian_2d(g0..g1, s0..s1)
        .map_err(|e| e.to_string())?;
    chart
        .configure_mesh()
        .disable_mesh()
        .x_desc("g")
        .y_desc("s")
        .label_style(("sans-serif", 13))
        .draw()
        .map_err(|e| e.to_string())?;
    chart
        .draw_series(
            counts
                .iter()
                .enumerate()
                .filter(|(_, n)| **n > 0)
                .map(|(k, &n)| {
                    let (i, j) = (k % nx, k / nx);
                    let (x, y) = (g0 + i as f64 * step, s0 + j as f64 * step);
                    let t = (f64::from(n).ln_1p() / top.ln_1p()).clamp(0.0, 1.0);
                    Rectangle::new(
                        [(x, y), (x + step, y + step)],
                        ViridisRGB.get_color(t).filled(),
                    )
                }),
        )
        .map_err(|e| e.to_string())?;
    chart
        .draw_series(LineSeries::new(
            (0..=180).map(|k| {
                let a = std::f64::consts::PI * f64::from(k) / 180.0;
                (0.5 + 0.5 * a.cos(), 0.5 * a.sin())
            }),
            BLACK.stroke_width(1),
        ))
        .map_err(|e| e.to_string())?;
    if let Some((lifetimes, omega)) = plot.marks {
        for &tau in lifetimes {
            let wt = omega * tau;
            let (g, s) = (1.0 / (1.0 + wt * wt), wt / (1.0 + wt * wt));
            chart
                .draw_series([
                    Circle::new((g, s), 3, BLACK.filled()).into_dyn(),
                    Text::new(
                        format!("{:.1} ns", tau / 1000.0),
                        (g, s + 0.02),
                        ("sans-serif", 12),
                    )
                    .into_dyn(),
                ])
                .map_err(|e| e.to_string())?;
        }
    }
    drop(chart);
    root.present().map_err(|e| e.to_string())?;
    drop(root);
    save_rgb(&pixels, width, height, path)
}

/// A decay with its fit: the counts, the fit and the IRF on a log scale
/// above, the weighted residuals below.
pub struct DecayFitPlot<'a> {
    /// The title.
    pub title: &'a str,
    /// Bin times, ns.
    pub times_ns: &'a [f64],
    /// Counts per bin.
    pub decay: &'a [f64],
    /// The fit per bin.
    pub fit: &'a [f64],
    /// The IRF per bin (empty: none).
    pub irf: &'a [f64],
    /// Lines of text written under the legend (the fitted values).
    pub values: &'a [String],
}

/// Draws a [`DecayFitPlot`].
pub fn decay_fit(path: &Path, plot: &DecayFitPlot) -> Result<(), String> {
    register_font();
    let (width, height) = (960u32, 720u32);
    let mut pixels = vec![0u8; (width * height * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut pixels, (width, height)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| e.to_string())?;
        let (upper, lower) = root.split_vertically(500);
        let t = plot.times_ns;
        let (t0, t1) = (
            t.first().copied().unwrap_or(0.0),
            t.last().copied().unwrap_or(1.0),
        );
        // Finite values only: an infinite one made the log axis's ticks
        // endless.
        let top = plot
            .decay
            .iter()
            .chain(plot.fit)
            .cloned()
            .filter(|v| v.is_finite())
            .fold(1.0f64, f64::max);
        let mut chart = ChartBuilder::on(&upper)
            .caption(plot.title, ("sans-serif", 20))
            .margin(12)
            .x_label_area_size(30)
            .y_label_area_size(64)
            .build_cartesian_2d(t0..t1.max(t0 + 1e-9), (0.5f64..top * 2.0).log_scale())
            .map_err(|e| e.to_string())?;
        chart
            .configure_mesh()
            .y_desc("photons per bin")
            .label_style(("sans-serif", 14))
            .draw()
            .map_err(|e| e.to_string())?;
        let points = |v: &[f64]| -> Vec<(f64, f64)> {
            t.iter()
                .zip(v)
                .filter(|(_, y)| **y > 0.5 && y.is_finite())
                .map(|(x, y)| (*x, *y))
                .collect()
        };
        let c = COLORS[0];
        chart
            .draw_series(
                points(plot.decay)
                    .into_iter()
                    .map(|p| Circle::new(p, 2, c.filled())),
            )
            .map_err(|e| e.to_string())?
            .label("summed decay")
            .legend(move |(x, y)| Circle::new((x + 10, y), 3, c.filled()));
        for (i, (name, v)) in [("fit", plot.fit), ("IRF (scaled)", plot.irf)]
            .into_iter()
            .enumerate()
        {
            if v.is_empty() {
                continue;
            }
            let c = COLORS[i + 1];
            chart
                .draw_series(LineSeries::new(points(v), c.stroke_width(2)))
                .map_err(|e| e.to_string())?
                .label(name)
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 20, y)], c.stroke_width(2))
                });
        }
        chart
            .configure_series_labels()
            .label_font(("sans-serif", 14))
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .position(SeriesLabelPosition::UpperRight)
            .draw()
            .map_err(|e| e.to_string())?;
        for (i, line) in plot.values.iter().enumerate() {
            upper
                .draw(&Text::new(
                    line.as_str(),
                    (width as i32 - 430, 130 + 18 * i as i32),
                    ("sans-serif", 14).into_font().color(&BLACK),
                ))
                .map_err(|e| e.to_string())?;
        }
        let residuals: Vec<(f64, f64)> = t
            .iter()
            .zip(plot.decay.iter().zip(plot.fit))
            .map(|(x, (y, m))| (*x, (y - m) / m.max(1.0).sqrt()))
            .filter(|(_, r)| r.is_finite())
            .collect();
        let r = residuals
            .iter()
            .map(|p| p.1.abs())
            .filter(|v| v.is_finite())
            .fold(1.0f64, f64::max);
        let mut res = ChartBuilder::on(&lower)
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(64)
            .build_cartesian_2d(t0..t1.max(t0 + 1e-9), -r..r)
            .map_err(|e| e.to_string())?;
        res.configure_mesh()
            .x_desc("time (ns)")
            .y_desc("weighted residual")
            .label_style(("sans-serif", 14))
            .draw()
            .map_err(|e| e.to_string())?;
        res.draw_series(LineSeries::new(residuals, COLORS[3].stroke_width(1)))
            .map_err(|e| e.to_string())?;
        root.present().map_err(|e| e.to_string())?;
    }
    save_rgb(&pixels, width, height, path)
}
