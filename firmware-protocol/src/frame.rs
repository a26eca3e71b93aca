//! Framing: `SYNC(4) kind(1) length(2, LE) header-CRC-8(1) payload
//! CRC-32C(4, LE)`.
//!
//! The CRC-8 covers kind and length, so a damaged length is refused at once
//! instead of making the receiver wait for bytes that belong to later
//! frames; the CRC-32C covers kind, length, header check and payload. A
//! receiver that loses its place (dropped or corrupted bytes) scans for the
//! next sync word; a frame is accepted only if both checks match, so
//! garbage never becomes data.

use alloc::vec::Vec;

/// Sync word that starts every frame.
pub const SYNC: [u8; 4] = [0x53, 0x53, 0x46, 0xA5];
/// Bytes before the payload: sync, kind, length, header check.
pub const HEADER_LEN: usize = 8;
/// Bytes after the payload: the CRC.
pub const TRAILER_LEN: usize = 4;
/// Largest payload a frame can carry.
pub const MAX_PAYLOAD: usize = u16::MAX as usize;

/// CRC-32C (Castagnoli): better burst-error detection than CRC-32 at the
/// same cost, and in hardware on x86 (SSE4.2) and many microcontrollers.
/// The 16-entry slicing table keeps the host check well above the event
/// rates of any time tagger (see the host benchmarks).
pub const CRC: crc::Crc<u32, crc::Table<16>> =
    crc::Crc::<u32, crc::Table<16>>::new(&crc::CRC_32_ISCSI);

/// CRC-32C of `bytes`: the hardware instruction where the `hw-crc` feature
/// is on and the CPU has it (about 5x faster than the table on the host
/// benchmark, see BENCHMARKS.md), else the table above. Both give the same
/// value (tested).
#[inline]
pub fn crc32c(bytes: &[u8]) -> u32 {
    #[cfg(feature = "hw-crc")]
    {
        ::crc32c::crc32c(bytes)
    }
    #[cfg(not(feature = "hw-crc"))]
    {
        CRC.checksum(bytes)
    }
}

/// Header check over kind and length (CRC-8/SMBUS).
pub const HEADER_CRC: crc::Crc<u8> = crc::Crc::<u8>::new(&crc::CRC_8_SMBUS);

/// What a frame carries.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u8)]
pub enum FrameKind {
    /// Host -> device: a postcard-encoded [`crate::RequestFrame`].
    Request = 0x01,
    /// Device -> host: a postcard-encoded [`crate::ResponseFrame`].
    Response = 0x02,
    /// Device -> host: an event batch ([`crate::EventBatch`]).
    Events = 0x03,
}

impl FrameKind {
    /// The kind of a wire byte, if it names one.
    pub fn from_byte(b: u8) -> Option<Self> {
        match b {
            0x01 => Some(Self::Request),
            0x02 => Some(Self::Response),
            0x03 => Some(Self::Events),
            _ => None,
        }
    }
}

/// Errors of [`encode_frame`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FrameError {
    /// The payload is longer than [`MAX_PAYLOAD`].
    PayloadTooLong(usize),
}

impl core::fmt::Display for FrameError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            FrameError::PayloadTooLong(n) => {
                write!(f, "frame payload of {n} bytes exceeds {MAX_PAYLOAD}")
            }
        }
    }
}

/// Appends one frame to `out`.
pub fn encode_frame(kind: FrameKind, payload: &[u8], out: &mut Vec<u8>) -> Result<(), FrameError> {
    if payload.len() > MAX_PAYLOAD {
        return Err(FrameError::PayloadTooLong(payload.len()));
    }
    let start = out.len();
    out.extend_from_slice(&SYNC);
    let len = (payload.len() as u16).to_le_bytes();
    let head = [kind as u8, len[0], len[1]];
    out.extend_from_slice(&head);
    out.push(HEADER_CRC.checksum(&head));
    out.extend_from_slice(payload);
    let crc = crc32c(&out[start + SYNC.len()..]);
    out.extend_from_slice(&crc.to_le_bytes());
    Ok(())
}

/// One received frame, borrowed from the decoder's buffer.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Frame<'a> {
    /// What the payload is.
    pub kind: FrameKind,
    /// The payload, CRC already checked.
    pub payload: &'a [u8],
}

/// What a [`FrameDecoder`] has seen.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct FrameStats {
    /// Frames accepted.
    pub frames: u64,
    /// Bytes discarded while looking for a valid frame.
    pub bytes_skipped: u64,
    /// Candidate frames whose header check or CRC did not match.
    pub crc_errors: u64,
    /// Frames with a valid CRC but an unknown kind (skipped whole).
    pub unknown_kind: u64,
}

/// Incremental frame decoder: push bytes as they arrive, pull frames.
///
/// Never panics on any input; memory is bounded by one maximal frame plus
/// the bytes pushed since the last pull.
#[derive(Debug, Default)]
pub struct FrameDecoder {
    buf: Vec<u8>,
    /// First byte of `buf` not yet consumed.
    start: usize,
    stats: FrameStats,
    /// No more bytes will come: incomplete candidates are not frames.
    ended: bool,
}

impl FrameDecoder {
    /// An empty decoder.
    pub fn new() -> Self {
        Self::default()
    }

    /// Appends received bytes.
    pub fn push(&mut self, bytes: &[u8]) {
        if self.start > 0
            && (self.start >= self.buf.len() / 2
                || self.buf.len() + bytes.len() > self.buf.capacity())
        {
            self.buf.drain(..self.start);
            self.start = 0;
        }
        self.buf.extend_from_slice(bytes);
    }

    /// Counters so far.
    pub fn stats(&self) -> FrameStats {
        self.stats
    }

    /// Bytes held that do not yet form a complete frame.
    pub fn pending(&self) -> usize {
        self.buf.len() - self.start
    }

    /// Marks the end of the stream: later [`Self::next_frame`] calls treat
    /// an incomplete candidate as damage and look past it, and the final
    /// call counts what is left as skipped.
    pub fn end_stream(&mut self) {
        self.ended = true;
    }

    /// The next complete, CRC-checked frame, or `None` until more bytes
    /// arrive.
    pub fn next_frame(&mut self) -> Option<Frame<'_>> {
        let base = self.start;
        let (advance, found) = scan(&self.buf[base..], self.ended, &mut self.stats);
        self.start += advance;
        found.map(|(kind, payload)| Frame {
            kind,
            payload: &self.buf[base + payload.start..base + payload.end],
        })
    }

    /// Bytes the held candidate frame still lacks (0 if none is held).
    fn bytes_needed(&self) -> usize {
        let avail = &self.buf[self.start..];
        if avail.is_empty() {
            0
        } else if avail.len() < HEADER_LEN {
            HEADER_LEN - avail.len()
        } else {
            let len = usize::from(u16::from_le_bytes([avail[5], avail[6]]));
            (HEADER_LEN + len + TRAILER_LEN).saturating_sub(avail.len())
        }
    }

    /// Pushes `bytes` and hands every frame they complete to `on_frame`.
    ///
    /// Same frames as [`Self::push`] + [`Self::next_frame`], but frames that
    /// lie wholly inside `bytes` are read in place, without copying them
    /// into the decoder's buffer: only a frame split across calls is
    /// buffered (the host's receive path, see BENCHMARKS.md).
    pub fn push_with(&mut self, mut bytes: &[u8], mut on_frame: impl FnMut(Frame<'_>)) {
        loop {
            if self.pending() == 0 {
                self.buf.clear();
                self.start = 0;
                let mut pos = 0;
                loop {
                    let (advance, found) = scan(&bytes[pos..], self.ended, &mut self.stats);
                    let base = pos;
                    pos += advance;
                    let Some((kind, payload)) = found else { break };
                    on_frame(Frame {
                        kind,
                        payload: &bytes[base + payload.start..base + payload.end],
                    });
                }
                self.buf.extend_from_slice(&bytes[pos..]);
                return;
            }
            // Complete the held candidate with just the bytes it needs.
            let take = match self.bytes_needed() {
                0 => bytes.len(),
                need => need.min(bytes.len()),
            };
            self.push(&bytes[..take]);
            bytes = &bytes[take..];
            while let Some(f) = self.next_frame() {
                on_frame(f);
            }
            if bytes.is_empty() {
                return;
            }
        }
    }
}

/// Looks for the next frame in `avail`: returns how many bytes are used up
/// (skipped garbage plus the frame) and the frame's kind and payload range.
/// Without a complete frame, the bytes that may still start one are not
/// used up (unless the stream has `ended`).
fn scan(
    avail: &[u8],
    ended: bool,
    stats: &mut FrameStats,
) -> (usize, Option<(FrameKind, core::ops::Range<usize>)>) {
    let mut at = 0;
    loop {
        let rest = &avail[at..];
        let Some(pos) = find_sync(rest) else {
            // Keep a tail that may be the start of a sync word.
            let keep = if ended {
                0
            } else {
                rest.len().min(SYNC.len() - 1)
            };
            let drop = rest.len() - keep;
            stats.bytes_skipped += drop as u64;
            return (at + drop, None);
        };
        stats.bytes_skipped += pos as u64;
        at += pos;
        let rest = &avail[at..];
        if rest.len() < HEADER_LEN {
            if ended {
                stats.bytes_skipped += 1;
                at += 1;
                continue;
            }
            return (at, None);
        }
        if HEADER_CRC.checksum(&rest[4..7]) != rest[7] {
            stats.crc_errors += 1;
            stats.bytes_skipped += 1;
            at += 1;
            continue;
        }
        let len = usize::from(u16::from_le_bytes([rest[5], rest[6]]));
        let total = HEADER_LEN + len + TRAILER_LEN;
        if rest.len() < total {
            if ended {
                stats.bytes_skipped += 1;
                at += 1;
                continue;
            }
            return (at, None);
        }
        let crc = u32::from_le_bytes([
            rest[HEADER_LEN + len],
            rest[HEADER_LEN + len + 1],
            rest[HEADER_LEN + len + 2],
            rest[HEADER_LEN + len + 3],
        ]);
        if crc32c(&rest[SYNC.len()..HEADER_LEN + len]) != crc {
            // Not a frame (or a damaged one): resume one byte later.
            stats.crc_errors += 1;
            stats.bytes_skipped += 1;
            at += 1;
            continue;
        }
        let Some(kind) = FrameKind::from_byte(rest[4]) else {
            stats.unknown_kind += 1;
            stats.bytes_skipped += total as u64;
            at += total;
            continue;
        };
        stats.frames += 1;
        return (
            at + total,
            Some((kind, at + HEADER_LEN..at + HEADER_LEN + len)),
        );
    }
}

fn find_sync(bytes: &[u8]) -> Option<usize> {
    // Fast path: a well-behaved stream has the sync word right here.
    if bytes.starts_with(&SYNC) {
        return Some(0);
    }
    bytes.windows(SYNC.len()).position(|w| w == SYNC)
}
