//! PicoQuant readers: real sample files (tests ignored unless run with the
//! shared data: they say what they need), files
//! written with known content for every record type, and malformed input.

#[path = "common/pt3.rs"]
mod pt3;
#[path = "common/pydeps.rs"]
mod pydeps;
#[path = "common/shared_data.rs"]
mod shared_data;

use std::path::{Path, PathBuf};

use pt3::write_pt3;

use scatterscope::events::Imaging;
use scatterscope::events::{ChunkDecoder, Tag, TagSink};
use scatterscope::formats::picoquant::records::{Decoder, RecordType};
use scatterscope::formats::picoquant::writer::write_synthetic_t3;
use scatterscope::formats::picoquant::writer::{PtuWriter, WriterHeader};
use scatterscope::formats::picoquant::{self, TtrError};
use scatterscope::tags::bin_file::{BinSpec, Pixels, bin_file};
use scatterscope::tags::binning::{Binner, FrameSelect, PixelMap, TimeWindow};
use scatterscope::tags::recorded::survey;
use scatterscope::tags::survey::Survey;

/// A PicoQuant sample file (`../shared/data/picoquant-sample-data/REL`).
fn sample(rel: &str) -> PathBuf {
    shared_data::shared_data(&format!("picoquant-sample-data/{rel}"))
}

/// Decodes every record; returns tags and the reader's final result.
fn decode_all(path: &Path) -> (picoquant::FileInfo, Vec<Tag>, Result<(), TtrError>) {
    let (info, mut reader) = picoquant::open(path).unwrap();
    let mut d = Decoder::new(info.record_type);
    let mut tags = Vec::new();
    let mut chunk = Vec::new();
    let end = loop {
        match reader.next_chunk(&mut chunk) {
            Ok(true) => tags.extend(chunk.iter().filter_map(|&r| d.decode(r))),
            Ok(false) => break Ok(()),
            Err(e) => break Err(e),
        }
    };
    (info, tags, end)
}

fn macro_time(t: &Tag) -> u64 {
    match *t {
        Tag::Photon { macro_time, .. }
        | Tag::Marker { macro_time, .. }
        | Tag::Sync { macro_time } => macro_time,
    }
}

#[test]
#[ignore = "needs ../shared/data/picoquant-sample-data"]
fn real_ptu_files_decode_completely_with_monotonic_times() {
    for (rel, rt) in [
        ("hydraharp/v10_t3.ptu", RecordType::HydraHarpV1T3),
        ("hydraharp/v20_t3.ptu", RecordType::HydraHarpV2T3),
        ("hydraharp/v20_t2.ptu", RecordType::HydraHarpV2T2),
        ("picoharp/v30_t2.ptu", RecordType::PicoHarpT2),
    ] {
        let path = sample(rel);
        let (info, tags, end) = decode_all(&path);
        end.unwrap();
        assert_eq!(info.record_type, rt, "{rel}");
        assert_eq!(info.records_present, info.records_announced, "{rel}");
        assert_eq!(info.trailing_bytes, 0);
        // Overflow-corrected times never go backwards (records are in time order).
        assert!(
            tags.windows(2)
                .all(|w| macro_time(&w[0]) <= macro_time(&w[1])),
            "{rel}: time went backwards"
        );
        // The last event lies just before the recorded stop time: overflow
        // handling is right over the whole file.
        let last = macro_time(tags.last().unwrap()) as f64 * info.macro_unit_s;
        let stop = info.stopped_after_s().unwrap();
        assert!(
            (last - stop).abs() < 0.01 * stop + 0.01 && last <= stop + 1e-3,
            "{rel}: last event {last} s, stopped after {stop} s"
        );
    }
}

#[test]
#[ignore = "needs ../shared/data/picoquant-sample-data"]
fn first_records_match_the_published_layout_by_hand() {
    let path = sample("hydraharp/v20_t3.ptu");
    let bytes = std::fs::read(&path).unwrap();
    let (info, tags, _) = decode_all(&path);
    let raw = |i: usize| {
        let o = info.data_offset as usize + 4 * i;
        u32::from_le_bytes(bytes[o..o + 4].try_into().unwrap())
    };
    // HydraHarp T3 by hand: bit 31 special, 30..25 channel, 24..10 dtime, 9..0 nsync.
    let mut overflow = 0u64;
    let mut expected = Vec::new();
    for i in 0..200 {
        let r = raw(i);
        let (special, channel, dtime, nsync) = (
            r >> 31,
            (r >> 25) & 63,
            (r >> 10) & 0x7FFF,
            u64::from(r & 1023),
        );
        if special == 1 && channel == 63 {
            overflow += 1024 * if nsync == 0 { 1 } else { nsync };
        } else if special == 0 {
            expected.push(Tag::Photon {
                channel: channel as u16,
                macro_time: overflow + nsync,
                micro_time: dtime,
            });
        }
    }
    let photons: Vec<Tag> = tags
        .into_iter()
        .filter(|t| matches!(t, Tag::Photon { .. }))
        .take(expected.len())
        .collect();
    assert_eq!(photons, expected);
    // Per-channel photon counts of the whole file.
    let (_, all, _) = decode_all(&path);
    let count = |c: u8| {
        all.iter()
            .filter(|t| matches!(t, Tag::Photon { channel, .. } if *channel == u16::from(c)))
            .count()
    };
    assert_eq!((count(0), count(1)), (45012, 32871));
}

#[test]
#[ignore = "needs ../shared/data/picoquant-sample-data"]
fn legacy_ht3_files_decode_and_cut_files_say_how_much_was_read() {
    {
        let path = sample("hydraharp/v20.ht3");
        let (info, tags, end) = decode_all(&path);
        end.unwrap();
        assert_eq!(info.record_type, RecordType::HydraHarpV2T3);
        assert_eq!(
            (info.records_announced, info.records_present),
            (53606, 53606)
        );
        assert!((info.resolution_s - 16e-12).abs() < 1e-18);
        assert!(
            tags.windows(2)
                .all(|w| macro_time(&w[0]) <= macro_time(&w[1]))
        );
    }
    {
        let path = sample("hydraharp/v10.ht3");
        // The sample is an excerpt of a longer measurement.
        let (info, tags, end) = decode_all(&path);
        assert_eq!(info.record_type, RecordType::HydraHarpV1T3);
        assert!(!tags.is_empty());
        let e = end.unwrap_err().to_string();
        assert!(e.contains("read 1050 of 72463591 records"), "{e}");
    }
}

fn header() -> WriterHeader {
    WriterHeader {
        resolution_s: 4e-12,
        sync_rate_hz: 80e6,
        device: "TestHarp".into(),
        imaging: None,
        extra: Vec::new(),
    }
}

fn write(path: &Path, rt: RecordType, h: &WriterHeader, tags: &[Tag]) -> u64 {
    let mut w = PtuWriter::create(path, rt, h).unwrap();
    for t in tags {
        w.write_tag(*t).unwrap();
    }
    w.finish().unwrap()
}

#[test]
fn every_record_type_round_trips_through_the_writer() {
    let dir = tempfile::tempdir().unwrap();
    for rt in RecordType::ALL {
        let pico = matches!(rt, RecordType::PicoHarpT3 | RecordType::PicoHarpT2);
        let max_micro = match rt {
            RecordType::PicoHarpT3 => 4095,
            t if t.is_t3() => 32767,
            _ => 0,
        };
        let mut tags = Vec::new();
        let mut t = 0u64;
        for i in 0..2000u64 {
            // Gaps from 0 to far beyond every wrap period, some exactly on it.
            t += match i % 7 {
                0 => 0,
                1 => 1,
                2 => 1023,
                3 => 1024,
                4 => 65_536,
                5 => 210_698_240,
                _ => 3 * 33_554_432 + 5,
            };
            let tag = match i % 5 {
                0 if !pico || rt.is_t3() => Tag::Marker {
                    bits: (i % 15 + 1) as u8,
                    macro_time: t,
                },
                1 if !rt.is_t3() && !pico => Tag::Sync { macro_time: t },
                _ => Tag::Photon {
                    channel: (i % match rt {
                        RecordType::PicoHarpT3 => 14,
                        RecordType::PicoHarpT2 => 15,
                        _ => 63,
                    }) as u16,
                    macro_time: t,
                    micro_time: (i * 37 % (max_micro + 1)) as u32,
                },
            };
            tags.push(tag);
        }
        // Overflow at the very end: the last record is an overflow.
        let path = dir.path().join(format!("{:08x}.ptu", rt.code()));
        let mut w = PtuWriter::create(&path, rt, &header()).unwrap();
        for tag in &tags {
            w.write_tag(*tag).unwrap();
        }
        let extra = if pico {
            15 << 28
        } else {
            (1 << 31) | (63 << 25) | 1
        };
        w.write_raw(extra).unwrap();
        let n = w.finish().unwrap();
        let (info, decoded, end) = decode_all(&path);
        end.unwrap();
        assert_eq!(info.record_type, rt);
        assert_eq!(info.records_announced, n);
        assert_eq!(decoded, tags, "{}", rt.name());
    }
}

#[test]
fn malformed_files_give_errors_with_offsets_not_panics() {
    let dir = tempfile::tempdir().unwrap();
    let good = dir.path().join("good.ptu");
    let tags: Vec<Tag> = (0..100)
        .map(|i| Tag::Photon {
            channel: 1,
            macro_time: i * 10,
            micro_time: 7,
        })
        .collect();
    write(&good, RecordType::GenericT3, &header(), &tags);
    let bytes = std::fs::read(&good).unwrap();
    let check = |name: &str, data: &[u8], needle: &str| {
        let p = dir.path().join(name);
        std::fs::write(&p, data).unwrap();
        let msg = match picoquant::open(&p) {
            Err(e) => e.to_string(),
            Ok(_) => {
                let (_, _, end) = decode_all(&p);
                end.expect_err(name).to_string()
            }
        };
        assert!(msg.contains(needle), "{name}: {msg}");
    };
    // Cut mid-record: says how many complete records were read.
    check(
        "cut.ptu",
        &bytes[..bytes.len() - 6],
        "read 98 of 100 records (2 trailing bytes",
    );
    check(
        "magic.ptu",
        b"PQXXXR\0\0 something else",
        "not a PicoQuant file",
    );
    check("header-cut.ptu", &bytes[..200], "file ends inside");
    // An absurd string length in the first tag (HW_Type payload length).
    let mut absurd = bytes.clone();
    absurd[16 + 40..16 + 48].copy_from_slice(&i64::MAX.to_le_bytes());
    check("absurd.ptu", &absurd, "payload length");
    let mut typ = bytes.clone();
    typ[16 + 36..16 + 40].copy_from_slice(&0x1234_5678u32.to_le_bytes());
    check("type.ptu", &typ, "unknown type code 0x12345678");
    // Random bytes after a valid magic never panic.
    for seed in 0..200u32 {
        let mut junk = [&b"PQTTTR\0\0"[..], b"1.0.00\0\0"].concat();
        junk.extend((0..300u32).map(|i| {
            (i.wrapping_mul(2_654_435_761)
                .wrapping_add(seed.wrapping_mul(40_503))
                >> 13) as u8
        }));
        let p = dir.path().join("junk.ptu");
        std::fs::write(&p, &junk).unwrap();
        let _ = picoquant::open(&p).map(|_| decode_all(&p));
    }
}

#[test]
fn a_recording_whose_writer_never_finished_is_flagged_and_binned_only_when_allowed() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("zero.ptu");
    let tags: Vec<Tag> = (0..10)
        .map(|i| Tag::Photon {
            channel: 0,
            macro_time: i,
            micro_time: 1,
        })
        .collect();
    let mut w = PtuWriter::create_recording(&p, RecordType::PicoHarpT3, &header()).unwrap();
    for t in &tags {
        w.write_tag(*t).unwrap();
    }
    drop(w); // never finished: the count stays 0, under the temporary name
    assert!(
        !p.exists(),
        "an unfinished recording never takes the final name"
    );
    let partial: Vec<PathBuf> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    assert_eq!(partial.len(), 1);
    assert!(scatterscope::files::output::is_partial_name(&partial[0]));
    let (info, decoded, end) = decode_all(&partial[0]);
    end.unwrap();
    assert!(info.count_missing && info.marked_incomplete());
    assert_eq!(info.records_announced, 10);
    assert_eq!(decoded, tags);
    let note = info.completeness_note().unwrap();
    assert!(
        note.contains("never finished") && note.contains("10 records"),
        "{note}"
    );
    let err = bin_file(&partial[0], &BinSpec::default())
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("no record count") && err.contains(".zero.ptu.partial-"),
        "{err}"
    );
    let allowed = BinSpec {
        allow_truncated: true,
        ..BinSpec::default()
    };
    let binned = bin_file(&partial[0], &allowed).unwrap();
    assert_eq!(binned.counts.photons, 10);
    assert!(
        binned
            .warnings()
            .iter()
            .any(|w| w.contains("never finished"))
    );
}

#[test]
fn an_interrupted_recording_is_whole_and_says_so() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("cut.ptu");
    let mut w = PtuWriter::create_recording(&p, RecordType::GenericT3, &header()).unwrap();
    w.write_records(&[5, 6, 7]).unwrap();
    w.finish_as(scatterscope::files::Completion::Interrupted)
        .unwrap();
    let (info, _, end) = decode_all(&p);
    end.unwrap();
    assert!(!info.count_missing && info.marked_incomplete());
    assert_eq!(info.records_announced, 3);
    assert!(info.completeness_note().unwrap().contains("interrupted"));
    let p2 = dir.path().join("whole.ptu");
    let mut w = PtuWriter::create_recording(&p2, RecordType::GenericT3, &header()).unwrap();
    w.write_records(&[5, 6, 7]).unwrap();
    w.finish().unwrap();
    let (info, _, _) = decode_all(&p2);
    assert!(!info.marked_incomplete() && info.completeness_note().is_none());
}

#[test]
fn scanned_images_bin_photons_into_their_pixels_and_keep_every_frame() {
    let img = Imaging {
        pixels_x: 4,
        pixels_y: 3,
        line_start: 1,
        line_stop: 2,
        frame: 4,
        bidirectional: true,
    };
    let mut tags = Vec::new();
    let mut t = 1000u64;
    let mut expected = ndarray::Array3::<u32>::zeros((2, 3, 4));
    for frame in 0..2 {
        for line in 0..3 {
            tags.push(Tag::Marker {
                bits: 1,
                macro_time: t,
            });
            for x in 0..4u64 {
                // frame + 1 photons in pixel x, 100 syncs per pixel.
                for _ in 0..=frame {
                    tags.push(Tag::Photon {
                        channel: 0,
                        macro_time: t + x * 100 + 50,
                        micro_time: 10,
                    });
                }
                let col = if line % 2 == 1 { 3 - x } else { x } as usize;
                expected[[frame, line, col]] += frame as u32 + 1;
            }
            // A marker coinciding with a photon time, and an empty gap.
            tags.push(Tag::Marker {
                bits: 2,
                macro_time: t + 400,
            });
            tags.push(Tag::Photon {
                channel: 0,
                macro_time: t + 450,
                micro_time: 10,
            }); // between lines
            t += 1000;
        }
        // SymPhoTime style: the frame marker follows the lines of its frame.
        tags.push(Tag::Marker {
            bits: 4,
            macro_time: t,
        });
        t += 10;
    }
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("img.ptu");
    let h = WriterHeader {
        imaging: Some(img),
        ..header()
    };
    write(&p, RecordType::PicoHarpT3, &h, &tags);
    let (info, decoded, _) = decode_all(&p);
    assert_eq!(info.imaging, Some(img));
    let window = TimeWindow {
        start: 0.0,
        width: 16.0,
        bins: 2,
    };
    let mut b = Binner::new(window, PixelMap::Scan(img), None, FrameSelect::All);
    for t in decoded {
        b.push(Some(t));
    }
    let (stacks, acc) = b.finish();
    assert_eq!(stacks.len(), 2, "both frames kept");
    assert_eq!(acc.frames, 2);
    for f in 0..2 {
        for r in 0..3 {
            for c in 0..4 {
                assert_eq!(
                    stacks[f][[0, r, c]],
                    expected[[f, r, c]],
                    "frame {f} row {r} col {c}"
                );
            }
        }
    }
    assert!(acc.balances(), "{acc:?}");
    assert_eq!(acc.outside_region, 6, "one photon between lines per line");
}

/// Frames kept apart: a last frame whose lines place no photon in the
/// image (none inside a line, one past its last pixel) makes no stack, as
/// a frame without photons never has; its photon counts outside.
#[test]
fn a_last_frame_without_a_placed_photon_makes_no_stack() {
    let img = Imaging {
        pixels_x: 2,
        pixels_y: 1,
        line_start: 1,
        line_stop: 2,
        frame: 4,
        bidirectional: false,
    };
    let window = TimeWindow {
        start: 0.0,
        width: 16.0,
        bins: 1,
    };
    let marker = |bits, macro_time| Tag::Marker { bits, macro_time };
    let photon = |macro_time| Tag::Photon {
        channel: 0,
        macro_time,
        micro_time: 3,
    };
    let tags = [
        // Frame 0: one line, one photon in each pixel.
        marker(1, 0),
        photon(10),
        photon(60),
        marker(2, 100),
        marker(4, 110),
        // Frame 1: an empty line, then a line whose only photon is
        // recorded with the stop marker's own time (past the last pixel).
        marker(1, 200),
        marker(2, 300),
        marker(1, 400),
        photon(500),
        marker(2, 500),
        marker(4, 510),
    ];
    let mut b = Binner::new(window, PixelMap::Scan(img), None, FrameSelect::All);
    for t in tags {
        b.push(Some(t));
    }
    let (stacks, acc) = b.finish();
    assert_eq!(acc.frames, 2);
    assert_eq!(stacks.len(), 1, "the photon-less frame has no stack");
    assert_eq!(stacks[0].iter().copied().collect::<Vec<_>>(), vec![1, 1]);
    assert_eq!((acc.binned, acc.outside_region), (2, 1), "{acc:?}");
    assert!(acc.balances(), "{acc:?}");
}

#[test]
fn legacy_pt3_files_decode_with_their_header_values() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("m.pt3");
    // PicoHarp T3 records: channel 4 bits, dtime 12, nsync 16; channel 15
    // with markers 0 is an overflow of 65536 syncs; photon channels count
    // from 1 (decoded from 0, as ptufile does).
    let rec = |ch: u32, dtime: u32, nsync: u32| (ch << 28) | (dtime << 16) | nsync;
    let records = [
        rec(1, 100, 5),
        rec(2, 4095, 65_535),
        rec(15, 0, 0),
        rec(1, 7, 3),
        rec(15, 2, 9),
    ];
    write_pt3(&path, 3, 2, &records, records.len() as i32);
    let (info, tags, end) = decode_all(&path);
    end.unwrap();
    assert_eq!(info.record_type, RecordType::PicoHarpT3);
    assert_eq!(info.data_offset, 736);
    assert_eq!(info.records_present, 5);
    assert!(
        (info.resolution_s - 16e-12).abs() < 1e-18,
        "{}",
        info.resolution_s
    );
    assert_eq!(info.sync_rate_hz, Some(40e6));
    assert_eq!(info.device, "PicoHarp 300");
    assert_eq!(
        tags,
        vec![
            Tag::Photon {
                channel: 0,
                macro_time: 5,
                micro_time: 100
            },
            Tag::Photon {
                channel: 1,
                macro_time: 65_535,
                micro_time: 4095
            },
            Tag::Photon {
                channel: 0,
                macro_time: 65_536 + 3,
                micro_time: 7
            },
            Tag::Marker {
                bits: 2,
                macro_time: 65_536 + 9
            },
        ]
    );

    // T2 mode, and a header that announces more records than present.
    let t2 = dir.path().join("m.pt2");
    write_pt3(&t2, 2, 0, &[(1 << 28) | 1234], 3);
    let (info, _, end) = decode_all(&t2);
    assert_eq!(info.record_type, RecordType::PicoHarpT2);
    assert!((info.macro_unit_s - 4e-12).abs() < 1e-20);
    assert!(
        matches!(
            end,
            Err(TtrError::Truncated {
                read: 1,
                expected: 3,
                ..
            })
        ),
        "{end:?}"
    );

    // Not time-tagging: a clear error naming the field and value.
    let hist = dir.path().join("h.pt3");
    write_pt3(&hist, 0, 0, &[], 0);
    let err = picoquant::open(&hist)
        .err()
        .expect("a histogram file is refused")
        .to_string();
    assert!(
        err.contains("h.pt3") && err.contains("MeasMode = 0"),
        "{err}"
    );

    // Every cut inside the header is an error naming the field, not a panic.
    let bytes = std::fs::read(&path).unwrap();
    for cut in (0..736).step_by(7) {
        let short = dir.path().join("cut.pt3");
        std::fs::write(&short, &bytes[..cut]).unwrap();
        if let Ok((info, _)) = picoquant::open(&short) {
            panic!("a header cut at {cut} bytes opened: {info:?}");
        }
    }
}

#[test]
fn bulk_binning_matches_record_by_record_binning() {
    // A mixed stream: photons on 5 channels (one beyond a 4-wide channel
    // map), micro times inside and outside the window and beyond the
    // lookup table, markers, overflows, syncs.
    let mut tags = Vec::new();
    let mut state = 0x2545_F491_4F6C_DD1Du64;
    for i in 0..50_000u64 {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        tags.push(match state % 11 {
            0 => None,
            1 => Some(Tag::Marker {
                bits: 1,
                macro_time: i,
            }),
            2 => Some(Tag::Sync { macro_time: i }),
            _ => Some(Tag::Photon {
                channel: (state >> 20) as u16 % 5,
                macro_time: i,
                micro_time: (state >> 30) as u32 % 40_000,
            }),
        });
    }
    // A window of 7-unit bins (the lookup table) and one of unit bins
    // from a whole unit (the subtraction).
    let windows = [
        TimeWindow {
            start: 100.0,
            width: 7.0,
            bins: 300,
        },
        TimeWindow {
            start: 100.0,
            width: 1.0,
            bins: 3000,
        },
    ];
    for window in windows {
        for (map, channel) in [
            (PixelMap::Single, None),
            (PixelMap::Single, Some(2)),
            (PixelMap::Channel { width: 4 }, None),
            (PixelMap::Channel { width: 4 }, Some(4)),
        ] {
            let mut one = Binner::new(window, map, channel, FrameSelect::Sum);
            for &t in &tags {
                one.push(t);
            }
            // Chunk by chunk, and in three parts binned apart and absorbed.
            let fresh = Binner::new(window, map, channel, FrameSelect::Sum);
            let mut bulk = fresh.clone();
            for chunk in tags.chunks(977) {
                bulk.bin_chunk(&mut Replay, chunk);
            }
            assert!(fresh.order_free());
            let mut parts = fresh.clone();
            for part in tags.chunks(tags.len() / 3 + 1) {
                let mut b = fresh.clone();
                b.bin_chunk(&mut Replay, part);
                parts.absorb(b);
            }
            for other in [bulk, parts] {
                let label = format!("{window:?} {map:?} {channel:?}");
                assert_eq!(one.past_window(), other.past_window(), "{label}");
                let (a, acc_a) = one.clone().finish();
                let (b, acc_b) = other.finish();
                assert_eq!(acc_a, acc_b, "{label}");
                assert!(
                    acc_a.balances()
                        && acc_a.outside_window > 0
                        && acc_a.binned + acc_a.outside_region > 0,
                    "{label}"
                );
                assert_eq!(a, b, "{label}");
            }
        }
    }
}

/// Tags already decoded, handed on as they are.
struct Replay;

impl ChunkDecoder for Replay {
    type Record = Option<Tag>;

    fn decode_chunk<S: TagSink>(&mut self, records: &[Option<Tag>], mut sink: S) -> S {
        for &t in records {
            sink.push(t);
        }
        sink
    }
}

#[test]
fn default_window_holds_micro_times_past_the_sync_period() {
    // PicoHarp T3 at 4 ps and 80 MHz: one sync period is 3125 steps.
    // Photons at and past it (a TAC range longer than the period) must not
    // be dropped by the default window.
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("flim.ptu");
    let micro = [0u32, 100, 3124, 3125, 3125, 3200];
    let tags: Vec<Tag> = micro
        .iter()
        .enumerate()
        .map(|(i, &m)| Tag::Photon {
            channel: 1,
            macro_time: i as u64 * 10,
            micro_time: m,
        })
        .collect();
    write(&path, RecordType::PicoHarpT3, &header(), &tags);
    let binned = bin_file(&path, &BinSpec::default()).unwrap();
    let acc = binned.counts;
    assert!(acc.balances());
    assert_eq!((acc.photons, acc.binned, acc.outside_window), (6, 6, 0));
    assert_eq!(
        binned.window.bins, 3201,
        "bins 0..=3200 hold every micro time"
    );
    let stack = &binned.stacks[0];
    assert_eq!(stack.total(), 6.0);
    assert_eq!(stack.data[[3125, 0, 0]], 2.0);
    assert_eq!(stack.data[[3200, 0, 0]], 1.0);
    assert_eq!(stack.meta.bin_starts_ps[3200], 12_800.0);
    assert_eq!(binned.notes.len(), 1);
    let note = &binned.notes[0];
    assert!(
        note.contains("3 photon(s)") && note.contains("widened to 3201 bins"),
        "{note}"
    );
    // A window the caller chose is kept, and the note says what it missed.
    let spec = BinSpec {
        bins: Some(3125),
        ..BinSpec::default()
    };
    let binned = bin_file(&path, &spec).unwrap();
    assert_eq!(binned.window.bins, 3125);
    assert_eq!((binned.counts.binned, binned.counts.outside_window), (3, 3));
    assert!(
        binned.notes[0].contains("3201 bins would hold them"),
        "{}",
        binned.notes[0]
    );
    // Nothing past the period: nothing widened, nothing said.
    write(&path, RecordType::PicoHarpT3, &header(), &tags[..3]);
    let binned = bin_file(&path, &BinSpec::default()).unwrap();
    assert_eq!(binned.window.bins, 3125);
    assert!(binned.notes.is_empty());
}

#[test]
fn bad_windows_and_record_types_are_refused_naming_the_field() {
    for (start, width, bins, field) in [
        (0.0, 0.0, 10, "bin_width = 0 ps"),
        (0.0, f64::NAN, 10, "bin_width = NaN ps"),
        (-4.0, 4.0, 10, "t_start = -4 ps"),
        (0.0, 4.0, 0, "bins = 0"),
        (0.0, 4.0, 65_537, "bins = 65537"),
    ] {
        let e = TimeWindow::from_ps(start, width, bins, 4.0)
            .unwrap_err()
            .to_string();
        assert!(e.contains(field), "{e}");
    }
    let w = TimeWindow::from_ps(8.0, 12.0, 5, 4.0).unwrap();
    assert_eq!((w.start, w.width, w.bins), (2.0, 3.0, 5));
    assert_eq!(w.bins_to_hold(2), 1);
    assert_eq!(w.bins_to_hold(16), 5);
    // A stack too large to allocate is refused before binning.
    use scatterscope::tags::binning::{PixelMap, Region};
    let sensor = |side: usize| PixelMap::Sensor {
        sensor_width: side,
        region: Region {
            x: 0,
            y: 0,
            width: side,
            height: side,
        },
    };
    let big = TimeWindow::from_ps(0.0, 4.0, 65_536, 4.0).unwrap();
    assert!(big.check_stack(&sensor(128)).is_ok(), "2^30 cells fit");
    let e = big.check_stack(&sensor(129)).unwrap_err().to_string();
    assert!(e.contains("bins = 65536 over 129 x 129 pixels"), "{e}");
    assert!(big.check_stack(&PixelMap::Single).is_ok());
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("t2.ptu");
    write(&path, RecordType::PicoHarpT2, &header(), &[]);
    let e = bin_file(&path, &BinSpec::default())
        .unwrap_err()
        .to_string();
    assert!(e.contains("t2.ptu") && e.contains("no micro time"), "{e}");
}

#[test]
fn survey_counts_every_record_kind_and_reports_a_cut() {
    use scatterscope::tags::survey::survey_picoquant;
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("s.ptu");
    // Macro times past the 10-bit PicoHarp T3 sync field force overflow
    // records between the events.
    let tags = [
        Tag::Photon {
            channel: 0,
            macro_time: 5,
            micro_time: 7,
        },
        Tag::Photon {
            channel: 2,
            macro_time: 70_000,
            micro_time: 9,
        },
        Tag::Marker {
            bits: 1,
            macro_time: 70_001,
        },
        Tag::Photon {
            channel: 2,
            macro_time: 200_000,
            micro_time: 1,
        },
    ];
    let records = write(&path, RecordType::PicoHarpT3, &header(), &tags);
    let (info, s) = survey_picoquant(&path).unwrap();
    assert_eq!(
        s.photons_per_channel.into_iter().collect::<Vec<_>>(),
        [(0, 1), (2, 2)]
    );
    assert_eq!((s.markers, s.syncs), (1, 0));
    assert_eq!(
        s.overflows,
        records - 4,
        "every other record is an overflow"
    );
    assert!(s.overflows > 0);
    assert!((s.last_event_s - 200_000.0 * info.macro_unit_s).abs() < 1e-15);
    assert!(s.cut.is_none());
    // Cut inside the records: counted up to the cut, which is reported.
    let bytes = std::fs::read(&path).unwrap();
    std::fs::write(&path, &bytes[..bytes.len() - 4]).unwrap();
    let (_, s) = survey_picoquant(&path).unwrap();
    assert!(s.cut.is_some());
    assert_eq!(s.photons_per_channel.values().sum::<u64>(), 2);
}

#[test]
fn a_duplicated_header_is_an_error_not_bogus_records() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("once.ptu");
    write_synthetic_t3(&path, 2_000).unwrap();
    let bytes = std::fs::read(&path).unwrap();
    let (info, _) = picoquant::open(&path).unwrap();
    let header = &bytes[..info.data_offset as usize];
    // The header written twice, then the records.
    let twice = dir.path().join("twice.ptu");
    let mut doubled = header.to_vec();
    doubled.extend_from_slice(&bytes);
    std::fs::write(&twice, doubled).unwrap();
    let e = bin_file(&twice, &BinSpec::default())
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("twice.ptu")
            && e.contains("second PTU header")
            && e.contains(&format!("byte {}", info.data_offset)),
        "{e}"
    );
}

#[test]
fn records_past_the_announced_count_are_said_not_ignored() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("count.ptu");
    write_synthetic_t3(&path, 2_000).unwrap();
    let mut bytes = std::fs::read(&path).unwrap();
    // TTResult_NumberOfRecords: 32-byte name, index, type, then the value.
    let name = b"TTResult_NumberOfRecords";
    let at = bytes.windows(name.len()).position(|w| w == name).unwrap() + 40;
    let announced = u64::from_le_bytes(bytes[at..at + 8].try_into().unwrap());
    bytes[at..at + 8].copy_from_slice(&(announced - 100).to_le_bytes());
    std::fs::write(&path, &bytes).unwrap();
    let binned = bin_file(&path, &BinSpec::default()).unwrap();
    assert_eq!(binned.counts.records, announced - 100);
    assert!(
        binned.notes.iter().any(|n| n.contains(&format!(
            "announces {} records (TTResult_NumberOfRecords) but the file holds {announced}: the 100 after them are not read",
            announced - 100
        ))),
        "{:?}",
        binned.notes
    );
    let Survey::PicoQuant(_, _) = survey(&path, &Default::default()).unwrap() else {
        panic!("a PTU file")
    };
    assert!(
        survey(&path, &Default::default())
            .unwrap()
            .lines()
            .iter()
            .any(|l| l.starts_with("warning: the header announces")),
    );
}

#[test]
fn binning_a_file_in_parts_equals_one_pass() {
    // Long enough for three parts of the parallel path, on channels 0-3
    // with micro times over one sync period.
    let dir = tempfile::tempdir().unwrap();
    let whole = dir.path().join("whole.ptu");
    write_synthetic_t3(&whole, 13_000_000).unwrap();
    // The same file cut 1000 and a half records short of its count.
    let bytes = std::fs::read(&whole).unwrap();
    let cut = dir.path().join("cut.ptu");
    std::fs::write(&cut, &bytes[..bytes.len() - 4002]).unwrap();

    // The part readers cover the records once, in order.
    let (info, mut reader) = picoquant::open(&whole).unwrap();
    let read = |r: &mut picoquant::RecordReader| {
        let (mut all, mut chunk) = (Vec::new(), Vec::new());
        while r.next_chunk(&mut chunk).unwrap() {
            all.extend_from_slice(&chunk);
        }
        all
    };
    let expected = read(&mut reader);
    let parts: Vec<u32> = info
        .split_records(3)
        .unwrap()
        .iter_mut()
        .flat_map(read)
        .collect();
    assert_eq!(parts, expected);

    let on = |threads: usize, path: &Path, spec: &BinSpec| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| bin_file(path, spec).unwrap())
    };
    let specs = [
        (&whole, BinSpec::default()),
        (
            &whole,
            BinSpec {
                channel: Some(2),
                pixels: Pixels::Channel,
                bin_width_ps: Some(12.0),
                ..BinSpec::default()
            },
        ),
        (
            &cut,
            BinSpec {
                allow_truncated: true,
                ..BinSpec::default()
            },
        ),
    ];
    for (path, spec) in &specs {
        let one = on(1, path, spec);
        let three = on(3, path, spec);
        let label = format!("{} {spec:?}", path.display());
        assert_eq!(one.counts, three.counts, "{label}");
        assert!(one.counts.balances() && one.counts.binned > 0, "{label}");
        assert_eq!(one.window, three.window, "{label}");
        assert_eq!(one.notes, three.notes, "{label}");
        assert_eq!(one.truncated, three.truncated, "{label}");
        assert_eq!(one.stacks.len(), three.stacks.len(), "{label}");
        for (a, b) in one.stacks.iter().zip(&three.stacks) {
            assert_eq!(a.data, b.data, "{label}");
        }
    }
    // The cut file says so, in parts as in one pass.
    let cut_binned = on(3, &cut, &specs[2].1);
    assert!(
        cut_binned
            .truncated
            .as_deref()
            .is_some_and(|t| t.contains(&format!(
                "read {} of {} records",
                expected.len() - 1001,
                expected.len()
            ))),
        "{:?}",
        cut_binned.truncated
    );
}

/// A synthetic FLIM image file bins, frame by frame and summed, into the
/// image histograms ptufile (an independent reader) decodes from it: the
/// same photons in the same pixel and bin.
#[test]
#[ignore = "needs ptufile under target/pydeps (scripts/fetch_python_deps.sh)"]
fn a_flim_image_bins_as_ptufile_decodes_it() {
    use ndarray::{Array3, Array5, Axis};
    use ndarray_npy::ReadNpyExt;
    let dir = tempfile::tempdir().unwrap();
    let ptu = dir.path().join("flim.ptu");
    scatterscope::formats::picoquant::writer::write_synthetic_flim(&ptu, 48, 60_000).unwrap();
    let script = r#"
import sys, numpy, ptufile
with ptufile.PtuFile(sys.argv[1]) as f:
    assert f.is_image, "ptufile does not read the file as an image"
    numpy.save(sys.argv[2], f.decode_image(dtype="uint32"))
"#;
    let npy = dir.path().join("ptufile.npy");
    pydeps::python(script, &[&ptu, &npy]);
    // T (frames), Y, X, C (channels), H (bins).
    let theirs = Array5::<u32>::read_npy(std::fs::File::open(&npy).unwrap()).unwrap();
    let (frames, h, w, channels, bins) = theirs.dim();
    assert_eq!((frames, h, w, channels), (2, 48, 48, 1));
    let frame = |t: usize| -> Array3<u32> {
        theirs
            .index_axis(Axis(0), t)
            .index_axis(Axis(2), 0)
            .permuted_axes([2, 0, 1])
            .to_owned()
    };
    let bin = |frames: FrameSelect| {
        let spec = BinSpec {
            frames,
            bins: Some(bins),
            ..BinSpec::default()
        };
        bin_file(&ptu, &spec).unwrap()
    };
    let summed = bin(FrameSelect::Sum);
    assert_eq!(summed.stacks.len(), 1);
    let ours = summed.stacks[0].data.mapv(|v| v as u32);
    assert_eq!(ours, frame(0) + frame(1));
    assert!(ours.sum() > 50_000, "{} photons", ours.sum());
    let each = bin(FrameSelect::All);
    assert_eq!(each.stacks.len(), 2);
    for (t, stack) in each.stacks.iter().enumerate() {
        assert_eq!(stack.data.mapv(|v| v as u32), frame(t), "frame {t}");
    }
}
