//! `lifetime`'s fast lifetime against SymPhoTime 64's own export of
//! PicoQuant's example (the numbers in `tests/data/symphotime`, read by
//! ptufile and tifffile): the time zero, the bins kept (the sync period's
//! cut last bin left out) and every kept pixel within 5 ps.

use ndarray::Array3;
use scatterscope::decay::{DecayOptions, decay_maps, rising_flank_zero};
use scatterscope::stack::{CountsView, RecordedBins};
use serde_json::Value;

fn example() -> Value {
    let text = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/data/symphotime/example.json"
    ))
    .unwrap();
    serde_json::from_str(&text).unwrap()
}

fn numbers(v: &Value) -> Vec<f64> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect()
}

#[test]
fn fast_lifetime_equals_symphotime_export_within_5_ps() {
    let e = example();
    let width = e["bin_width_ps"].as_f64().unwrap();
    let period = e["sync_period_ps"].as_f64().unwrap();
    let bins = e["bins"].as_u64().unwrap() as usize;
    let starts: Vec<f64> = (0..bins).map(|k| k as f64 * width).collect();
    // The sync period cuts the last bin to a fifth of its width: it is
    // not recorded whole, and SymPhoTime leaves it out.
    let recorded = RecordedBins::within(&starts, width, (0.0, period), "test".into()).unwrap();
    assert_eq!((recorded.first, recorded.end), (0, bins - 1));
    let end = recorded.end;
    let pixels = e["pixels"].as_array().unwrap();
    // One column per chosen pixel, and one more holding the rest of the
    // image, so that the stack's summed decay is the image's.
    let total = numbers(&e["image_summed_decay"]);
    let mut counts = Array3::<u32>::zeros((end, 1, pixels.len() + 1));
    let mut rest = total.clone();
    for (i, p) in pixels.iter().enumerate() {
        for (k, c) in numbers(&p["counts"]).iter().enumerate() {
            rest[k] -= c;
            if k < end {
                counts[[k, 0, i]] = *c as u32;
            }
        }
    }
    for k in 0..end {
        counts[[k, 0, pixels.len()]] = rest[k] as u32;
    }
    // The time zero of the image's decay: the export is each pixel's
    // mean arrival time (photons at their bins' starts) less 1316.69 ps.
    let zero = rising_flank_zero(&total[..end], &starts[..end], width).unwrap();
    assert!((zero - 1316.69).abs() < 1.0, "time zero {zero} ps");
    let options = DecayOptions {
        min_photons: 1.0,
        ..DecayOptions::default()
    };
    let maps = decay_maps(
        CountsView::U32(counts.view()),
        &starts[..end],
        width,
        1e12 / period,
        &options,
    )
    .unwrap();
    for (i, p) in pixels.iter().enumerate() {
        let theirs = p["symphotime_fast_lifetime_ns"].as_f64().unwrap() * 1e3;
        let ours = maps.fast_lifetime_ps[[0, i]];
        assert!(
            (ours - theirs).abs() < 5.0,
            "pixel ({}, {}): {ours:.2} ps here, {theirs:.2} ps in SymPhoTime's export",
            p["row"],
            p["column"]
        );
        assert_eq!(
            maps.intensity[[0, i]],
            p["symphotime_photons"].as_f64().unwrap()
        );
    }
}
