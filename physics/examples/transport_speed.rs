//! Packets per second of Monte Carlo transport on van de Hulst's slab
//! (mu_a 10 /cm, mu_s 90 /cm, g 0.75, n 1, 0.02 cm), MCML's check case,
//! or on a slab in air given as MU_A MU_S G N THICKNESS_CM:
//!
//! `cargo run --release -p scatterscope-physics --example transport_speed -- [PACKETS] [ROUNDS] [MU_A MU_S G N THICKNESS_CM]`
//!
//! Prints each round's wall time, the process's CPU time, packets per
//! second and per CPU second, the specular reflection, and the diffuse
//! reflectance and transmittance with their standard errors
//! (`scripts/mcml_side_by_side.py` reads these lines).

use std::time::Instant;

use scatterscope_physics::transport::{Grid, Run, Slab, Source, transport};

/// The process's user and system CPU seconds so far.
fn cpu_seconds() -> f64 {
    let stat = std::fs::read_to_string("/proc/self/stat").unwrap_or_default();
    let fields: Vec<&str> = stat
        .rsplit_once(')')
        .map_or(Vec::new(), |(_, rest)| rest.split_whitespace().collect());
    let ticks = |i: usize| {
        fields
            .get(i)
            .and_then(|v| v.parse::<f64>().ok())
            .unwrap_or(0.0)
    };
    // utime and stime are fields 14 and 15 (from 1), 11 and 12 after the
    // name; clock ticks of 1/100 s on Linux.
    (ticks(11) + ticks(12)) / 100.0
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let packets: u64 = args
        .get(1)
        .and_then(|v| v.parse().ok())
        .unwrap_or(10_000_000);
    let rounds: usize = args.get(2).and_then(|v| v.parse().ok()).unwrap_or(3);
    let slab = match args.get(3..8) {
        Some(v) => {
            let v: Vec<f64> = v
                .iter()
                .map(|x| x.parse().expect("slab parameters are numbers"))
                .collect();
            Slab {
                mu_a_per_cm: v[0],
                mu_s_per_cm: v[1],
                g: v[2],
                n: v[3],
                n_outside: 1.0,
                thickness_cm: v[4],
            }
        }
        None => Slab::VAN_DE_HULST,
    };
    let grid = Grid {
        t_start_ps: 0.0,
        bin_width_ps: 0.1,
        bins: 100,
        ring_width_cm: 0.01,
        rings: 50,
    };
    for round in 0..rounds {
        let (wall, cpu) = (Instant::now(), cpu_seconds());
        let run = Run {
            photons: packets,
            seed: round as u64,
            max_path_cm: 1e4,
        };
        let t = transport(&slab, Source::Pencil, &grid, &run).expect("the slab is a valid medium");
        let (wall, cpu) = (wall.elapsed().as_secs_f64(), cpu_seconds() - cpu);
        println!(
            "round {}: {packets} packets in {wall:.2} s ({cpu:.2} CPU s): {:.2e} per s, {:.2e} per CPU s; specular {:.6}, R {:.6} +- {:.6}, T {:.6} +- {:.6}",
            round + 1,
            packets as f64 / wall,
            packets as f64 / cpu,
            t.specular,
            t.reflected.mean,
            t.reflected.error,
            t.transmitted.mean,
            t.transmitted.error
        );
    }
}
