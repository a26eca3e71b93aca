//! Checks shared by the protocol targets: a frame payload of each kind
//! parses or is refused without a panic, and what parses survives a
//! re-encoding unchanged.
use firmware_protocol::{
    BatchEncoder, EventBatch, FrameKind, RequestFrame, ResponseFrame, from_payload, to_payload,
};

pub fn check(kind: FrameKind, payload: &[u8]) {
    match kind {
        FrameKind::Events => {
            let Ok(batch) = EventBatch::parse(payload) else { return };
            let events: Vec<_> = batch.events().filter_map(Result::ok).collect();
            assert!(events.len() <= batch.len());
            let mut enc = BatchEncoder::new();
            let mut kept = 0;
            for e in &events {
                if !enc.has_room(1) || enc.push(*e).is_err() {
                    break;
                }
                kept += 1;
            }
            let mut out = Vec::new();
            enc.finish_batch(&mut out);
            let again = EventBatch::parse(&out).expect("an encoded batch parses");
            let back: Vec<_> = again.events().collect::<Result<_, _>>().expect("encoded events decode");
            assert_eq!(&back[..], &events[..kept]);
        }
        FrameKind::Request => {
            if let Ok(m) = from_payload::<RequestFrame>(payload) {
                let bytes = to_payload(&m).expect("decoded messages encode");
                assert_eq!(from_payload::<RequestFrame>(&bytes).expect("round trip"), m);
            }
        }
        FrameKind::Response => {
            if let Ok(m) = from_payload::<ResponseFrame>(payload) {
                let bytes = to_payload(&m).expect("decoded messages encode");
                assert_eq!(from_payload::<ResponseFrame>(&bytes).expect("round trip"), m);
            }
        }
    }
}
