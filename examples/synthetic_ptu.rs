//! Writes the synthetic Generic T3 file the tag benchmarks use, for
//! comparing readers: `cargo run --release --example synthetic_ptu -- OUT.ptu [RECORDS]`.

fn main() -> std::io::Result<()> {
    let mut args = std::env::args().skip(1);
    let path = args.next().unwrap_or_else(|| "synthetic.ptu".into());
    let records = args.next().map_or(20_000_000, |r| {
        r.parse().expect("RECORDS is a whole number")
    });
    scatterscope::formats::picoquant::writer::write_synthetic_t3(
        std::path::Path::new(&path),
        records,
    )?;
    println!("wrote {records} records to {path}");
    Ok(())
}
