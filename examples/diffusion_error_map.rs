//! How far diffusion's transmittance is from light as it travels, over
//! media: the infinite medium (the paper's Eq. 6) and the slab with
//! extrapolated boundaries against Monte Carlo transport, for a point of
//! the object emitting by Lambert's law into a slab in air.
//!
//! `cargo run --release --example diffusion_error_map -- [PACKETS] [FIGURE.png]`
//!
//! mu_s' 10 /cm (g 0: diffusion depends on mu_s' alone), mu_s'/mu_a 1,
//! 10, 100, thickness 2, 5, 10, 20 transport lengths, n 1 and 1.4. For
//! each, over the time profile of the light through the whole far face
//! (2,000 bins from 0 to the ballistic time plus eight diffusion times
//! `3 mu_s' d^2 n / (pi^2 c)`): the shape error (half the L1 distance of
//! the two profiles, each scaled to unit sum: 0 equal, 1 disjoint) and the
//! median arrival's error; for the slab model also the ratio of its
//! transmitted light to the Monte Carlo's. With FIGURE, the shape errors
//! against thickness are drawn there: lines for the slab model, markers
//! for the infinite medium, one per mu_s'/mu_a and n.

use scatterscope::physics::diffusion::Diffusion;
use scatterscope::physics::diffusion::light_speed_cm_per_ps;
use scatterscope::physics::diffusion_error::shape_error;
use scatterscope::physics::params::{Medium, MediumModel};
use scatterscope::physics::transport::{Grid, Run, Slab, Source, transport};
use scatterscope::plot::{Series, chart};

const BINS: usize = 2000;

fn median(p: &[f64], width: f64) -> f64 {
    let total: f64 = p.iter().sum();
    let mut acc = 0.0;
    for (k, v) in p.iter().enumerate() {
        acc += v;
        if acc >= total / 2.0 {
            return (k as f64 + 0.5) * width;
        }
    }
    f64::NAN
}

fn main() {
    let packets: u64 = std::env::args()
        .nth(1)
        .and_then(|v| v.parse().ok())
        .unwrap_or(200_000);
    let figure = std::env::args().nth(2);
    let (mut slab_lines, mut infinite_points) = (Vec::new(), Vec::new());
    let mu_s_reduced = 10.0;
    println!(
        "| n | mu_s'/mu_a | mu_s' d | infinite: shape, median | slab: shape, median, light | MC light (+- SE) |"
    );
    println!("| --- | --- | --- | --- | --- | --- |");
    for n in [1.0, 1.4] {
        for ratio in [1.0, 10.0, 100.0] {
            let label = format!("mu_s'/mu_a {ratio}, n {n}");
            let mut slab_series = Series {
                label: format!("slab, {label}"),
                points: Vec::new(),
            };
            let mut infinite_series = Series {
                label: format!("infinite (Eq. 6), {label}"),
                points: Vec::new(),
            };
            for lengths in [2.0, 5.0, 10.0, 20.0] {
                let mu_a = mu_s_reduced / ratio;
                let d = lengths / mu_s_reduced;
                let speed = light_speed_cm_per_ps(n);
                let ballistic = d / speed;
                let t_diff = 3.0 * mu_s_reduced * d * d / (std::f64::consts::PI.powi(2) * speed);
                let width = (ballistic + 8.0 * t_diff) / BINS as f64;
                let slab = Slab {
                    mu_a_per_cm: mu_a,
                    mu_s_per_cm: mu_s_reduced,
                    g: 0.0,
                    n,
                    n_outside: 1.0,
                    thickness_cm: d,
                };
                let grid = Grid {
                    t_start_ps: 0.0,
                    bin_width_ps: width,
                    bins: BINS,
                    ring_width_cm: d,
                    rings: 1,
                };
                let run = Run {
                    photons: packets,
                    seed: 1,
                    max_path_cm: (BINS as f64 + 1.0) * width * speed,
                };
                let t = transport(&slab, Source::Lambertian, &grid, &run).expect("valid media");
                let mc: Vec<f64> = t.face.iter().map(|e| e.mean).collect();
                if mc.iter().sum::<f64>() <= 0.0 {
                    println!("| {n} | {ratio} | {lengths} | - | - | no packet crossed |");
                    continue;
                }
                let profile = |model: MediumModel| -> Option<Vec<f64>> {
                    let medium = Medium {
                        mu_a_per_cm: mu_a,
                        mu_s_per_cm: mu_s_reduced,
                        g: 0.0,
                        refractive_index: n,
                        thickness_cm: d,
                        model,
                    };
                    let diff = Diffusion::new(&medium).ok()?;
                    Some(
                        (0..BINS)
                            .map(|k| {
                                (0..8)
                                    .map(|j| {
                                        let s = (k as f64 + (j as f64 + 0.5) / 8.0) * width;
                                        diff.log_temporal_density(s).exp()
                                    })
                                    .sum::<f64>()
                                    * width
                                    / 8.0
                            })
                            .collect(),
                    )
                };
                let m_mc = median(&mc, width);
                let cell = |p: Option<Vec<f64>>, light: bool| match p {
                    None => "refused".to_string(),
                    Some(p) => {
                        let m = median(&p, width);
                        let mut s = format!(
                            "{:.3}, {:+.0} %",
                            shape_error(&mc, &p),
                            100.0 * (m - m_mc) / m_mc
                        );
                        if light {
                            let total: f64 = p.iter().sum();
                            s.push_str(&format!(", {:.2}", total / t.transmitted.mean));
                        }
                        s
                    }
                };
                let (infinite, slab_model) =
                    (profile(MediumModel::Infinite), profile(MediumModel::Slab));
                if let Some(p) = &infinite {
                    infinite_series.points.push((lengths, shape_error(&mc, p)));
                }
                if let Some(p) = &slab_model {
                    slab_series.points.push((lengths, shape_error(&mc, p)));
                }
                println!(
                    "| {n} | {ratio} | {lengths} | {} | {} | {:.3e} (+- {:.1e}) |",
                    cell(infinite, false),
                    cell(slab_model, true),
                    t.transmitted.mean,
                    t.transmitted.error
                );
            }
            slab_lines.push(slab_series);
            infinite_points.push(infinite_series);
        }
    }
    if let Some(path) = figure {
        chart(
            std::path::Path::new(&path),
            "Diffusion's shape error against Monte Carlo transport (Lambertian point, slab in air)",
            "slab thickness (transport lengths, mu_s' d)",
            "shape error (half the L1 distance of the time profiles)",
            &infinite_points,
            &slab_lines,
            true,
        )
        .expect("the figure is written");
        println!("wrote {path}");
    }
}
