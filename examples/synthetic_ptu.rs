//! Writes the synthetic PTU files the benchmarks and reader comparisons
//! use: `cargo run --release --example synthetic_ptu -- OUT.ptu [RECORDS]`
//! for the single-pixel Generic T3 file, `... -- --flim OUT.ptu [PHOTONS]`
//! for a 256 x 256 FLIM image file (two frames, about 3 MB at the default
//! 730 000 photons).

use std::path::Path;

use scatterscope::formats::picoquant::writer;

fn main() -> std::io::Result<()> {
    let mut args: Vec<String> = std::env::args().skip(1).collect();
    let flim = args.first().is_some_and(|a| a == "--flim");
    if flim {
        args.remove(0);
    }
    let path = args
        .first()
        .cloned()
        .unwrap_or_else(|| "synthetic.ptu".into());
    let count = |default: u64| {
        args.get(1)
            .map_or(default, |r| r.parse().expect("the count is a whole number"))
    };
    if flim {
        let photons = count(730_000);
        writer::write_synthetic_flim(Path::new(&path), 256, photons)?;
        println!("wrote a 256 x 256 FLIM image of about {photons} photons to {path}");
    } else {
        let records = count(20_000_000);
        writer::write_synthetic_t3(Path::new(&path), records)?;
        println!("wrote {records} records to {path}");
    }
    Ok(())
}
