//! When a source's light (a pencil beam by default) leaves the far face of a slab, by Monte
//! Carlo transport: the transmitted fraction, its ballistic part, the
//! arrival-time quantiles and the light before a given time.
//!
//! `cargo run --release -p scatterscope-physics --example transport_arrivals -- MU_A MU_S G N THICKNESS_CM [PACKETS] [BEFORE_PS] [pencil|lambertian|hemisphere]`
//!
//! (coefficients in 1/cm; air outside both faces).

use scatterscope_physics::diffusion::light_speed_cm_per_ps;
use scatterscope_physics::transport::{Grid, Run, Slab, Source, transport};

fn main() {
    let words: Vec<String> = std::env::args().skip(1).collect();
    let source = match words.last().map(String::as_str) {
        Some("lambertian") => Source::Lambertian,
        Some("hemisphere") => Source::Hemisphere,
        _ => Source::Pencil,
    };
    let a: Vec<f64> = words.iter().filter_map(|v| v.parse().ok()).collect();
    assert!(
        a.len() >= 5,
        "give MU_A MU_S G N THICKNESS_CM [PACKETS] [BEFORE_PS]"
    );
    let slab = Slab {
        mu_a_per_cm: a[0],
        mu_s_per_cm: a[1],
        g: a[2],
        n: a[3],
        n_outside: 1.0,
        thickness_cm: a[4],
    };
    let packets = a.get(5).map_or(10_000_000, |v| *v as u64);
    let ballistic_ps = slab.thickness_cm / light_speed_cm_per_ps(slab.n);
    let grid = Grid {
        t_start_ps: ballistic_ps.floor() - 1.0,
        bin_width_ps: 0.5,
        bins: 4000,
        ring_width_cm: 0.05,
        rings: 100,
    };
    let run = Run {
        photons: packets,
        seed: 1,
        max_path_cm: 1e4,
    };
    let t = transport(&slab, source, &grid, &run).unwrap_or_else(|e| panic!("{e}"));
    let total: f64 = t.face.iter().map(|e| e.mean).sum();
    let quantile = |q: f64| {
        let mut acc = 0.0;
        for (k, e) in t.face.iter().enumerate() {
            acc += e.mean;
            if acc >= q * total {
                return grid.t_start_ps + (k as f64 + 0.5) * grid.bin_width_ps;
            }
        }
        f64::NAN
    };
    println!(
        "transmitted {:.4e} +- {:.1e} (ballistic exp(-(mu_a + mu_s) d) = {:.4e}); outside the {:.0}-{:.0} ps grid {:.2e}",
        t.transmitted.mean,
        t.transmitted.error,
        (-(slab.mu_a_per_cm + slab.mu_s_per_cm) * slab.thickness_cm).exp(),
        grid.t_start_ps,
        grid.t_start_ps + grid.bins as f64 * grid.bin_width_ps,
        t.outside_grid.mean
    );
    println!(
        "first light {ballistic_ps:.1} ps; arrival quantiles 1 % {:.1}, 10 % {:.1}, 50 % {:.1}, 90 % {:.1}, 99 % {:.1} ps",
        quantile(0.01),
        quantile(0.1),
        quantile(0.5),
        quantile(0.9),
        quantile(0.99)
    );
    if let Some(&before) = a.get(6) {
        let k = ((before - grid.t_start_ps) / grid.bin_width_ps)
            .floor()
            .max(0.0) as usize;
        let early: f64 = t.face.iter().take(k).map(|e| e.mean).sum();
        println!(
            "light before {before} ps: {:.3} % of the transmitted",
            if early > 0.0 {
                100.0 * early / total
            } else {
                0.0
            }
        );
    }
}
