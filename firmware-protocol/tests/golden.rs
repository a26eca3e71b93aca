//! Golden wire frames: one literal byte frame per message kind and an
//! event batch with every record kind, the same hex as in PROTOCOL.md
//! ("Golden frames"). Encoder and decoder are each checked against the
//! literal bytes, so a change that alters the wire format fails here even
//! when encoder and decoder change together.

use firmware_protocol::*;

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

fn unhex(s: &str) -> Vec<u8> {
    let s: String = s.split_whitespace().collect();
    (0..s.len())
        .step_by(2)
        .map(|i| u8::from_str_radix(&s[i..i + 2], 16).unwrap())
        .collect()
}

fn frame(kind: FrameKind, payload: &[u8]) -> Vec<u8> {
    let mut out = Vec::new();
    encode_frame(kind, payload, &mut out).unwrap();
    out
}

fn decode_one(bytes: &[u8]) -> (FrameKind, Vec<u8>) {
    let mut dec = FrameDecoder::new();
    dec.push(bytes);
    dec.end_stream();
    let f = dec.next_frame().expect("one frame");
    let out = (f.kind, f.payload.to_vec());
    assert!(dec.next_frame().is_none());
    assert_eq!(dec.stats().bytes_skipped, 0);
    out
}

fn config() -> Config {
    Config {
        sync_divider: 1,
        resolution_fs: 1000,
        time_window: 12_500,
        roi: Some(Roi {
            x: 8,
            y: 8,
            width: 48,
            height: 48,
        }),
        exposure_ms: 2000,
    }
}

fn totals() -> Totals {
    Totals {
        batches: 3,
        photons_sent: 20_000,
        photons_lost: 5,
    }
}

fn requests() -> Vec<(&'static str, RequestFrame)> {
    vec![
        (
            "identify",
            RequestFrame {
                id: 1,
                request: Request::Identify,
            },
        ),
        (
            "configure",
            RequestFrame {
                id: 2,
                request: Request::Configure(config()),
            },
        ),
        (
            "start",
            RequestFrame {
                id: 3,
                request: Request::Start,
            },
        ),
        (
            "stop",
            RequestFrame {
                id: 4,
                request: Request::Stop,
            },
        ),
        (
            "status",
            RequestFrame {
                id: 5,
                request: Request::Status,
            },
        ),
    ]
}

fn responses() -> Vec<(&'static str, ResponseFrame)> {
    vec![
        (
            "identity",
            ResponseFrame {
                id: 1,
                response: Response::Identity(Identity {
                    model: "TT".into(),
                    serial: "S1".into(),
                    firmware: [1, 2, 3],
                    protocol_version: PROTOCOL_VERSION,
                    pixels_x: 64,
                    pixels_y: 64,
                    channels: 1,
                    tdc_resolution_fs: 1000,
                    sync_period_fs: 12_500_000,
                }),
            },
        ),
        (
            "configured",
            ResponseFrame {
                id: 2,
                response: Response::Configured(config()),
            },
        ),
        (
            "started",
            ResponseFrame {
                id: 3,
                response: Response::Started,
            },
        ),
        (
            "stopped",
            ResponseFrame {
                id: 4,
                response: Response::Stopped(totals()),
            },
        ),
        (
            "status",
            ResponseFrame {
                id: 5,
                response: Response::Status(Status {
                    running: true,
                    totals: totals(),
                    fifo_fill: 7,
                    fifo_capacity: 1024,
                    request_errors: 0,
                }),
            },
        ),
        (
            "error busy",
            ResponseFrame {
                id: 6,
                response: Response::Error(DeviceError::Busy),
            },
        ),
        (
            "error invalid config",
            ResponseFrame {
                id: 0xFFFF,
                response: Response::Error(DeviceError::InvalidConfig {
                    field: "roi".into(),
                    reason: "off".into(),
                }),
            },
        ),
    ]
}

/// Batch 2 of a stream, 40 photons before it, sync base 2^24: a photon, a
/// wrap, a marker, a lost record, a photon.
fn batch_events() -> Vec<Event> {
    vec![
        Event::Photon {
            pixel: 0x0102,
            micro: 0x0304,
            sync: (1 << 24) + 5,
        },
        Event::Marker {
            bits: 0b101,
            sync: (1 << 25) + 7,
        },
        Event::Lost { count: 9 },
        Event::Photon {
            pixel: 4095,
            micro: 12_499,
            sync: (1 << 25) + 8,
        },
    ]
}

fn batch_payload() -> Vec<u8> {
    let mut enc = BatchEncoder::new();
    let mut scratch = Vec::new();
    // Batches 0 and 1: 20 photons each.
    for b in 0..2u64 {
        for i in 0..20u64 {
            enc.push(Event::Photon {
                pixel: 0,
                micro: 0,
                sync: b * 100 + i,
            })
            .unwrap();
        }
        scratch.clear();
        enc.finish_batch(&mut scratch);
    }
    for e in batch_events() {
        enc.push(e).unwrap();
    }
    let mut payload = Vec::new();
    enc.finish_batch(&mut payload);
    payload
}

/// The frames, as in PROTOCOL.md: sync word, kind, payload length, header
/// CRC-8, payload, CRC-32C.
const GOLDEN: [(&str, &str); 13] = [
    ("request identify", "535346a5 01 0200 41 0100 1b42beb9"),
    (
        "request configure",
        "535346a5 01 0e00 bd 0201 01e807d461 01 08083030 d00f a1f3396a",
    ),
    ("request start", "535346a5 01 0200 41 0302 0202c07f"),
    ("request stop", "535346a5 01 0200 41 0403 4448c6f7"),
    ("request status", "535346a5 01 0200 41 0504 d8b4ae30"),
    (
        "response identity",
        "535346a5 02 1500 c0 0100 025454 025331 010203 01 40 40 01 e807 a0f8fa05 e9a0297d",
    ),
    (
        "response configured",
        "535346a5 02 0e00 00 0201 01e807d461 01 08083030 d00f ca791032",
    ),
    ("response started", "535346a5 02 0200 fc 0302 a4307352"),
    (
        "response stopped",
        "535346a5 02 0700 bd 0403 03a09c0105 fdde7b4a",
    ),
    (
        "response status",
        "535346a5 02 0c00 2a 0504 01 03a09c0105 07 8008 00 1fb1191d",
    ),
    (
        "response error busy",
        "535346a5 02 0300 e9 0605 01 953f5424",
    ),
    (
        "response error invalid config",
        "535346a5 02 0d00 3f ffff03 05 02 03726f69 036f6666 c73217c1",
    ),
    (
        "events",
        "535346a5 03 4400 b2 02000000 2800000000000000 0000000000000000 \
         0100000000000010 0500000403201000 0100000000000010 0700000000005020 \
         0900000000000030 080000d330f0ff00 e60d7c91",
    ),
];

fn golden(name: &str) -> Vec<u8> {
    let (_, h) = GOLDEN
        .iter()
        .find(|(n, _)| *n == name)
        .expect("a golden frame");
    unhex(h)
}

/// Each message encodes to its golden frame, and the golden frame decodes
/// to the message.
fn check_messages<T>(kind: FrameKind, prefix: &str, messages: Vec<(&str, T)>)
where
    T: serde::Serialize + serde::de::DeserializeOwned + PartialEq + std::fmt::Debug,
{
    for (name, m) in messages {
        let name = format!("{prefix} {name}");
        let want = golden(&name);
        assert_eq!(
            hex(&frame(kind, &to_payload(&m).unwrap())),
            hex(&want),
            "{name}: the encoder changed the wire"
        );
        let (got_kind, payload) = decode_one(&want);
        assert_eq!(got_kind, kind, "{name}");
        assert_eq!(from_payload::<T>(&payload).unwrap(), m, "{name}");
    }
}

#[test]
fn requests_match_their_golden_bytes_both_ways() {
    check_messages(FrameKind::Request, "request", requests());
}

#[test]
fn responses_match_their_golden_bytes_both_ways() {
    check_messages(FrameKind::Response, "response", responses());
}

#[test]
fn an_event_batch_with_every_record_kind_matches_its_golden_bytes() {
    let want = golden("events");
    assert_eq!(
        hex(&frame(FrameKind::Events, &batch_payload())),
        hex(&want),
        "the batch encoder changed the wire"
    );
    let (kind, payload) = decode_one(&want);
    assert_eq!(kind, FrameKind::Events);
    let batch = EventBatch::parse(&payload).unwrap();
    assert_eq!(batch.header.seq, 2);
    assert_eq!(batch.header.photon_offset, 40);
    assert_eq!(batch.header.sync_base, 0);
    // Two wrap records move the base; they are not events.
    assert_eq!(batch.len(), 6);
    let events: Vec<Event> = batch.events().collect::<Result<_, _>>().unwrap();
    assert_eq!(events, batch_events());
}

#[test]
fn protocol_md_shows_the_same_golden_frames() {
    let doc = include_str!("../PROTOCOL.md");
    for (name, h) in GOLDEN {
        let flat: String = h.split_whitespace().collect();
        let doc_flat: String = doc.split_whitespace().collect();
        assert!(
            doc_flat.contains(&flat),
            "PROTOCOL.md lacks the golden frame `{name}`: {h}"
        );
    }
}
