//! Photon time-tag events, below every module that produces or consumes
//! them: the file readers of [`crate::formats`], the devices of
//! [`crate::acquire`] and the binning of [`crate::tags`]. A decoder hands
//! each record's [`Tag`] to a [`TagSink`]; scanned images are described by
//! [`Imaging`].

/// One decoded event.
///
/// T3 files: `macro_time` counts sync (laser) periods and `micro_time` is
/// the delay after the sync in units of the file's TCSPC resolution.
/// T2 files: `macro_time` is the absolute time in units of the global
/// resolution and `micro_time` is 0.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Tag {
    /// A detected photon on input `channel` (numbered as in the record).
    Photon {
        /// Input channel as stored in the record.
        channel: u16,
        /// Overflow-corrected macro time.
        macro_time: u64,
        /// Micro time (T3) or 0 (T2).
        micro_time: u32,
    },
    /// External marker bits (bit 0 = marker 1), e.g. scanner line clocks.
    Marker {
        /// Marker bits set in this record.
        bits: u8,
        /// Overflow-corrected macro time.
        macro_time: u64,
    },
    /// A sync event, recorded as an event only in T2 files.
    Sync {
        /// Overflow-corrected macro time.
        macro_time: u64,
    },
}

impl Tag {
    /// The tag's overflow-corrected macro time.
    pub fn macro_time(&self) -> u64 {
        match *self {
            Tag::Photon { macro_time, .. }
            | Tag::Marker { macro_time, .. }
            | Tag::Sync { macro_time } => macro_time,
        }
    }

    /// A wire event of our devices as a tag: a photon (its sensor pixel
    /// as the channel) or a marker; `None` for a loss, which the ledger
    /// counts and no tag carries. The one conversion from the wire to
    /// tags, for the acquisition's PTU recording, `convert` and the tag
    /// table.
    pub fn from_wire(event: firmware_protocol::Event) -> Option<Tag> {
        match event {
            firmware_protocol::Event::Photon { pixel, micro, sync } => Some(Tag::Photon {
                channel: pixel,
                macro_time: sync,
                micro_time: micro,
            }),
            firmware_protocol::Event::Marker { bits, sync } => Some(Tag::Marker {
                bits,
                macro_time: sync,
            }),
            firmware_protocol::Event::Lost { .. } => None,
        }
    }
}

/// Scanned-image (FLIM) description from `ImgHdr_*` tags.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Imaging {
    /// Pixels per line.
    pub pixels_x: usize,
    /// Lines per frame.
    pub pixels_y: usize,
    /// Marker mask of the line start (1 << (bit - 1)).
    pub line_start: u8,
    /// Marker mask of the line stop.
    pub line_stop: u8,
    /// Marker mask of the frame clock (0 when absent).
    pub frame: u8,
    /// Lines alternate direction.
    pub bidirectional: bool,
}

/// Where a decoder puts each record's tag: any `FnMut(Option<Tag>)`, or
/// the binner's specialised sink, whose `push` is then inlined into the
/// decoder's per-layout loop.
pub trait TagSink {
    /// Takes one record's tag (`None` for records that carry no event,
    /// such as overflows).
    fn push(&mut self, tag: Option<Tag>);
}

/// A decoder of a record stream, chunk by chunk, carrying its state (the
/// overflow-corrected time base) from one chunk to the next.
pub trait ChunkDecoder {
    /// One record as stored.
    type Record;

    /// Decodes `records` in order, handing each record's tag to `sink`,
    /// and returns the sink: taken by value, so that its counters live in
    /// registers of the decoder's loop.
    fn decode_chunk<S: TagSink>(&mut self, records: &[Self::Record], sink: S) -> S;
}

impl<F: FnMut(Option<Tag>)> TagSink for F {
    #[inline(always)]
    fn push(&mut self, tag: Option<Tag>) {
        self(tag)
    }
}
