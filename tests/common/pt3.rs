//! A PicoHarp PT3 file laid out byte by byte, independent of the project's
//! readers and writers.

use std::path::Path;

/// A PicoHarp 300 PT3 file (format 2.0) laid out field by field as in
/// PicoQuant's C file-access demo: text header, binary header, one board
/// header with router settings, TTTR header, image header, records.
pub fn write_pt3(path: &Path, mode: i32, img_ints: usize, records: &[u32], announced: i32) {
    let mut b = Vec::new();
    let text = |b: &mut Vec<u8>, s: &str, n: usize| {
        let mut f = s.as_bytes().to_vec();
        f.resize(n, 0);
        b.extend_from_slice(&f);
    };
    let int = |b: &mut Vec<u8>, v: i32| b.extend_from_slice(&v.to_le_bytes());
    text(&mut b, "PicoHarp 300", 16);
    text(&mut b, "2.0", 6);
    text(&mut b, "PicoHarp Software", 18);
    text(&mut b, "2.3.0.0", 12);
    text(&mut b, "22/11/26 10:00:00", 18);
    text(&mut b, "\r\n", 2);
    text(&mut b, "test file", 256);
    // Curves, BitsPerRecord, RoutingChannels, NumberOfBoards, ActiveCurve,
    // MeasMode, SubMode, RangeNo, Offset, Tacq, StopAt, StopOnOvfl,
    // Restart, DispLinLog, DispTimeFrom, DispTimeTo, DispCountFrom,
    // DispCountTo.
    for v in [0, 32, 4, 1, 0, mode, 0, 0, 0, 1000, 0, 0, 0, 0, 0, 0, 0, 0] {
        int(&mut b, v);
    }
    b.extend_from_slice(&[0u8; 64 + 36 + 16]); // DispCurves, Params, Repeat*
    text(&mut b, "", 20); // ScriptName
    text(&mut b, "PicoHarp 300", 16);
    text(&mut b, "2.0", 8);
    for v in [1_000_123, 8, 10, 50, 10, 50] {
        int(&mut b, v); // serial, SyncDivider, CFD settings
    }
    b.extend_from_slice(&0.016f32.to_le_bytes()); // Resolution, ns
    b.extend_from_slice(&[0u8; 26 * 4]); // router model, enabled, 4 x 6 channel ints
    for v in [
        0,
        0,
        0,
        40_000_000,
        1000,
        1000,
        0,
        announced,
        img_ints as i32,
    ] {
        int(&mut b, v); // ExtDevices .. Records, ImgHdrSize
    }
    b.extend(std::iter::repeat_n(0u8, 4 * img_ints));
    assert_eq!(
        b.len(),
        728 + 4 * img_ints,
        "the PT3 2.0 header is 728 bytes + image header"
    );
    for r in records {
        b.extend_from_slice(&r.to_le_bytes());
    }
    std::fs::write(path, b).unwrap();
}
