//! Arbitrary bytes as Becker & Hickl files (first byte: 0-2 a `.spc` of
//! one module layout with a micro-time unit given, else an `.sdt`), read
//! and binned through `bin_file`, what `scatterscope bin` runs: no panic,
//! no hang, and the photon accounting balances.
#![no_main]
use libfuzzer_sys::fuzz_target;
use scatterscope::formats::becker_hickl::spc::{SpcModule, SpcOptions};
use scatterscope::named::Named;

#[path = "common/file.rs"]
mod file;

fuzz_target!(|data: &[u8]| {
    let Some((&pick, rest)) = data.split_first() else {
        return;
    };
    let spec = match SpcModule::ALL.get(usize::from(pick)) {
        Some(&module) => scatterscope::BinSpec {
            spc: SpcOptions {
                module: Some(module),
                micro_unit_ps: Some(10.0),
            },
            allow_truncated: true,
            ..scatterscope::BinSpec::default()
        },
        None => scatterscope::BinSpec::default(),
    };
    let name = if pick < 3 { "file.spc" } else { "file.sdt" };
    let path = file::write(name, rest);
    if let Ok(b) = scatterscope::bin_file(&path, &spec) {
        assert!(b.accounting.balances(), "{:?}", b.accounting);
    }
});
