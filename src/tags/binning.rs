//! Tags -> transient stack: histogram photons by micro time into K bins per
//! pixel, where the pixel is fixed (single-pixel files), the input channel
//! (SPAD arrays), or the scan position between line markers (FLIM images).
//!
//! Every photon is accounted for: binned, outside the time window, on
//! another channel, outside the image (before the first line, beyond the
//! last line or pixel), and the counts balance.

use ndarray::Array3;

use super::counts::Counts;
use crate::events::{ChunkDecoder, Imaging, Tag, TagSink};

/// How photons map to pixels.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum PixelMap {
    /// Every photon in one pixel (1 x 1 image).
    Single,
    /// The input channel is the pixel index of a `width`-wide row of pixels.
    Channel {
        /// Number of pixels (channels 0..width).
        width: usize,
    },
    /// Scanned image from line/frame markers.
    Scan(Imaging),
    /// The channel is a row-major pixel index on a sensor `sensor_width`
    /// pixels wide (live SPAD-array data); only the region `region` is kept.
    Sensor {
        /// Columns of the whole sensor.
        sensor_width: usize,
        /// The region binned.
        region: Region,
    },
}

impl PixelMap {
    /// Rows and columns of the image this map bins into.
    pub fn image_size(&self) -> (usize, usize) {
        match *self {
            PixelMap::Single => (1, 1),
            PixelMap::Channel { width } => (1, width),
            PixelMap::Scan(img) => (img.pixels_y, img.pixels_x),
            PixelMap::Sensor { region, .. } => (region.height, region.width),
        }
    }
}

/// Most cells (bins x pixels) one binned stack may hold: 2^30 counts, 4 GiB
/// as `u32`. A header's absurd sensor size fails here with a clear error
/// instead of an allocation the machine cannot make.
pub const MAX_STACK_CELLS: usize = 1 << 30;

/// A rectangle of pixels that the host bins (a region of interest). The
/// device-side region of the wire protocol is `firmware_protocol::Roi`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct Region {
    /// First column.
    pub x: usize,
    /// First row.
    pub y: usize,
    /// Columns.
    pub width: usize,
    /// Rows.
    pub height: usize,
}

impl std::str::FromStr for Region {
    type Err = String;

    /// `X,Y,WIDTH,HEIGHT` in whole pixels, with a non-empty size.
    fn from_str(s: &str) -> Result<Self, String> {
        let v: Vec<usize> = s
            .split(',')
            .map(|p| p.trim().parse::<usize>())
            .collect::<Result<_, _>>()
            .map_err(|_| format!("`{s}`: expected X,Y,WIDTH,HEIGHT as whole pixels"))?;
        match v[..] {
            [x, y, width, height] if width > 0 && height > 0 => Ok(Region {
                x,
                y,
                width,
                height,
            }),
            _ => Err(format!(
                "`{s}`: expected X,Y,WIDTH,HEIGHT with a non-empty size"
            )),
        }
    }
}

/// Which frames of a scanned image to keep.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FrameSelect {
    /// Sum all frames into one stack.
    Sum,
    /// Keep every frame as its own stack.
    All,
    /// Keep only frame `n` (0-based).
    One(usize),
}

impl std::str::FromStr for FrameSelect {
    type Err = String;

    /// `sum`, `all` or a frame number.
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "sum" => Ok(Self::Sum),
            "all" => Ok(Self::All),
            n => n
                .parse()
                .map(Self::One)
                .map_err(|_| format!("`{n}`: use sum, all or a frame number")),
        }
    }
}

/// Micro-time binning: `bins` bins of `width` micro-time units from `start`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TimeWindow {
    /// First bin start (micro-time units, may be fractional).
    pub start: f64,
    /// Bin width (micro-time units).
    pub width: f64,
    /// Number of bins.
    pub bins: usize,
}

/// Photons whose micro time fell at or past the end of the window (a
/// subset of [`Counts::outside_window`]): how many, and the largest such
/// micro time, so that a caller can widen a default window to hold them.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct PastWindow {
    /// Photons past the window's end.
    pub photons: u64,
    /// Largest micro time among them (0 when there are none).
    pub max_micro: u32,
}

impl PastWindow {
    #[inline]
    fn note(&mut self, window: &TimeWindow, micro: u32) {
        if f64::from(micro) >= window.start + window.width * window.bins as f64 {
            self.photons += 1;
            self.max_micro = self.max_micro.max(micro);
        }
    }
}

impl TimeWindow {
    /// The window from picoseconds: `start_ps` after the sync, bins of
    /// `width_ps`, on a micro-time unit of `resolution_ps`; every value
    /// checked (finite, start >= 0, width > 0, 1 to [`MAX_BINS`] bins), the
    /// error naming the field and value.
    pub fn from_ps(
        start_ps: f64,
        width_ps: f64,
        bins: usize,
        resolution_ps: f64,
    ) -> Result<Self, WindowError> {
        let bad = |field: &'static str, value: String, reason: &'static str| {
            Err(WindowError {
                field,
                value,
                reason,
            })
        };
        if !(resolution_ps > 0.0 && resolution_ps.is_finite()) {
            return bad(
                "resolution",
                format!("{resolution_ps} ps"),
                "must be positive",
            );
        }
        if !(start_ps >= 0.0 && start_ps.is_finite()) {
            return bad(
                "t_start",
                format!("{start_ps} ps"),
                "must be a finite time >= 0 after the sync",
            );
        }
        if !(width_ps > 0.0 && width_ps.is_finite()) {
            return bad("bin_width", format!("{width_ps} ps"), "must be positive");
        }
        if !(1..=MAX_BINS).contains(&bins) {
            return bad("bins", bins.to_string(), "must lie in 1..=65536");
        }
        Ok(TimeWindow {
            start: start_ps / resolution_ps,
            width: width_ps / resolution_ps,
            bins,
        })
    }

    /// The window, if every bin holds the same whole number of micro-time
    /// steps (device data: bins of unequal step counts would hold unequal
    /// light).
    pub fn whole_steps(self, resolution_ps: f64) -> Result<Self, WindowError> {
        let steps = self.width.round();
        if (self.width - steps).abs() > 1e-6 || steps < 1.0 {
            return Err(WindowError {
                field: "bin_width",
                value: format!("{} ps", self.width * resolution_ps),
                reason: "is not a whole number of micro-time steps",
            });
        }
        Ok(TimeWindow {
            width: steps,
            ..self
        })
    }

    /// Start of the first bin (ps) on a micro-time unit of `resolution_ps`.
    pub fn start_ps(&self, resolution_ps: f64) -> f64 {
        self.start * resolution_ps
    }

    /// Bin width (ps) on a micro-time unit of `resolution_ps`.
    pub fn width_ps(&self, resolution_ps: f64) -> f64 {
        self.width * resolution_ps
    }

    /// Bins of `width_ps` from `start_ps` that cover one sync period of
    /// `period_ps` (at least 1): the default window of recorded tags.
    pub fn period_bins(period_ps: f64, start_ps: f64, width_ps: f64) -> usize {
        ((period_ps - start_ps) / width_ps).ceil().max(1.0) as usize
    }

    /// Checks that this window's bins over `map`'s image stay within
    /// [`MAX_STACK_CELLS`].
    pub fn check_stack(&self, map: &PixelMap) -> Result<(), WindowError> {
        let (h, w) = map.image_size();
        let cells = self.bins.checked_mul(h).and_then(|c| c.checked_mul(w));
        match cells {
            Some(c) if c <= MAX_STACK_CELLS => Ok(()),
            _ => Err(WindowError {
                field: "bins",
                value: format!("{} over {h} x {w} pixels", self.bins),
                reason: "makes a stack of more than 2^30 counts (4 GiB); bin fewer or wider bins, or fewer pixels",
            }),
        }
    }

    /// Bins needed from this window's start to hold micro time `micro`.
    pub fn bins_to_hold(&self, micro: u32) -> usize {
        ((f64::from(micro) - self.start) / self.width)
            .floor()
            .max(0.0) as usize
            + 1
    }
}

/// Most bins a window may have.
pub const MAX_BINS: usize = 65_536;

/// A time window that cannot be binned: the field, its value and why.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("time window: {field} = {value} {reason}")]
pub struct WindowError {
    /// The field (`t_start`, `bin_width`, `bins`, `resolution`).
    pub field: &'static str,
    /// Its value, with unit.
    pub value: String,
    /// What is wrong.
    pub reason: &'static str,
}

/// Micro times covered by the lookup table: every T3 format's range (15 bits).
const MICRO_LUT_LEN: usize = 1 << 15;
/// Lookup-table entry of a micro time outside the window.
const OUTSIDE: u16 = u16::MAX;

/// Builds stacks from a stream of tags.
#[derive(Clone)]
pub struct Binner {
    window: TimeWindow,
    /// Bin of every possible micro time; a table lookup instead of a
    /// floating-point division per photon (the decode + bin loop is the
    /// throughput-critical path, see BENCHMARKS.md).
    micro_lut: Vec<u16>,
    map: PixelMap,
    channel: Option<u16>,
    frames: FrameSelect,
    /// (bins, rows, columns) of every stack.
    shape: (usize, usize, usize),
    /// Flat row-major counts of each kept frame (one when summing).
    stacks: Vec<Vec<u32>>,
    counts: Counts,
    scan: ScanState,
    /// For [`PixelMap::Sensor`]: flat stack pixel of every sensor pixel,
    /// or [`OUTSIDE_REGION`]; one table lookup per photon instead of a
    /// division and four comparisons (see BENCHMARKS.md, acquisition).
    pixel_lut: Vec<u32>,
    /// Scratch space of [`Binner::push_sensor_photons`].
    offsets: Vec<u32>,
    /// Photons past the window's end, from [`Binner::push`] and
    /// [`Binner::bin_chunk`].
    past: PastWindow,
    /// The most stacks kept at once: frames kept apart past it are counted,
    /// not binned (the memory budget; at least one).
    max_stacks: usize,
}

/// Pixel-table entry of a sensor pixel outside the region of interest.
const OUTSIDE_REGION: u32 = u32::MAX;

#[derive(Clone, Default)]
struct ScanState {
    frame: usize,
    line: usize,
    lines_in_frame: usize,
    line_start: Option<u64>,
    /// (macro time, micro bin) of photons of the open line.
    pending: Vec<(u64, usize)>,
}

impl Binner {
    /// A binner with the given window, pixel map, optional channel filter
    /// and frame selection.
    pub fn new(
        window: TimeWindow,
        map: PixelMap,
        channel: Option<u16>,
        frames: FrameSelect,
    ) -> Self {
        // More bins than a u16 can name: no table, the division path runs.
        // The table ends with the window: later micro times take the
        // division path of `lookup_bin`, with the same result (building the
        // whole 2^15 table was a tenth of binning a 0.1 M-record file).
        let lut_len = if window.bins < usize::from(OUTSIDE) {
            let end = window.start + window.width * window.bins as f64;
            (end.ceil() as usize).saturating_add(1).min(MICRO_LUT_LEN)
        } else {
            0
        };
        let micro_lut = (0..lut_len)
            .map(|m| {
                let x = (m as f64 - window.start) / window.width;
                if x >= 0.0 && x < window.bins as f64 {
                    x as u16
                } else {
                    OUTSIDE
                }
            })
            .collect();
        let shape = {
            let (h, w) = map.image_size();
            (window.bins, h, w)
        };
        let pixel_lut = match map {
            PixelMap::Sensor {
                sensor_width,
                region,
            } if sensor_width > 0 => (0..1usize << 16)
                .map(|p| {
                    let (x, y) = (p % sensor_width, p / sensor_width);
                    if x >= region.x
                        && y >= region.y
                        && x - region.x < region.width
                        && y - region.y < region.height
                    {
                        ((y - region.y) * region.width + (x - region.x)) as u32
                    } else {
                        OUTSIDE_REGION
                    }
                })
                .collect(),
            _ => Vec::new(),
        };
        Self {
            window,
            micro_lut,
            map,
            channel,
            frames,
            shape,
            stacks: Vec::new(),
            counts: Counts::default(),
            scan: ScanState::default(),
            pixel_lut,
            offsets: Vec::new(),
            past: PastWindow::default(),
            max_stacks: {
                // Each count, and its float32 copy in the finished stack.
                let per_stack = crate::memory::bytes_of([shape.0, shape.1, shape.2], 8).max(1);
                let budget =
                    crate::memory::budget().map_or(crate::memory::FALLBACK_BYTES, |b| b.bytes);
                usize::try_from(budget / per_stack)
                    .unwrap_or(usize::MAX)
                    .max(1)
            },
        }
    }

    /// The most frames kept apart at once under the memory budget.
    pub fn max_stacks(&self) -> usize {
        self.max_stacks
    }

    /// Photons so far whose micro time fell at or past the window's end
    /// (tags from [`Binner::push`] and [`Binner::bin_chunk`]).
    pub fn past_window(&self) -> PastWindow {
        self.past
    }

    #[inline(always)]
    fn stack_for_frame(&mut self, frame: usize) -> Option<&mut Vec<u32>> {
        let index = match self.frames {
            FrameSelect::Sum => 0,
            FrameSelect::All => frame,
            FrameSelect::One(n) if n == frame => 0,
            FrameSelect::One(_) => return None,
        };
        if index >= self.max_stacks {
            return None;
        }
        if index >= self.stacks.len() {
            let (k, h, w) = self.shape;
            self.stacks.resize_with(index + 1, || vec![0; k * h * w]);
        }
        Some(&mut self.stacks[index])
    }

    #[inline(always)]
    fn micro_bin(&self, micro: u32) -> Option<usize> {
        lookup_bin(&self.micro_lut, &self.window, micro)
    }

    /// Decodes `records` with `decoder` and bins their tags like
    /// [`Binner::push`]. Single-pixel, channel and sensor maps summed into
    /// frame 0 take a sink specialised to the map, passed by value so that
    /// the decoder's loop keeps its counters in registers (the decode + bin
    /// hot path of recorded files, see BENCHMARKS.md); scanned images and
    /// frame selections that exclude frame 0 go through `push`.
    pub fn bin_chunk<D: ChunkDecoder>(&mut self, decoder: &mut D, records: &[D::Record]) {
        if !self.order_free() || self.stack_for_frame(0).is_none() {
            let _ = decoder.decode_chunk(records, |tag| self.push(tag));
            return;
        }
        match self.channel {
            None => self.bin_map::<false, D>(decoder, records),
            Some(_) => self.bin_map::<true, D>(decoder, records),
        }
    }

    /// The window's first micro time when its bins are single micro-time
    /// units from a whole unit (the default window of `bin`): then a bin is
    /// a subtraction, not a table lookup (a quarter of the loop's time).
    fn unit_start(&self) -> Option<u32> {
        let w = &self.window;
        (w.width == 1.0
            && w.start.fract() == 0.0
            && w.start >= 0.0
            && w.start <= f64::from(u32::MAX))
        .then_some(w.start as u32)
    }

    /// [`Binner::bin_chunk`]'s fast path for this map, with or without a
    /// channel filter (`FILTER`): each a loop of its own, the fewer
    /// instructions per record the faster (measured, BENCHMARKS.md).
    #[inline(always)]
    fn bin_map<const FILTER: bool, D: ChunkDecoder>(
        &mut self,
        decoder: &mut D,
        records: &[D::Record],
    ) {
        match self.map {
            PixelMap::Single => self.bin_fast::<FILTER, D>(decoder, records, |_, bin| Some(bin)),
            PixelMap::Channel { width } => {
                self.bin_fast::<FILTER, D>(decoder, records, move |c: u16, bin| {
                    let c = usize::from(c);
                    (c < width).then_some(bin * width + c)
                })
            }
            PixelMap::Sensor { region, .. } => {
                let plane = region.width * region.height;
                let lut = std::mem::take(&mut self.pixel_lut);
                self.bin_fast::<FILTER, D>(decoder, records, |c: u16, bin| {
                    match lut.get(usize::from(c)) {
                        Some(&p) if p != OUTSIDE_REGION => Some(bin * plane + p as usize),
                        _ => None,
                    }
                });
                self.pixel_lut = lut;
            }
            PixelMap::Scan(_) => unreachable!("scanned images take the path of `push`"),
        }
    }

    /// [`Binner::bin_chunk`] through a [`FastSink`] whose stack offset of
    /// a photon of a channel in a bin is `place` (`None`: outside the
    /// image), with the micro time's bin by subtraction or table.
    #[inline(always)]
    fn bin_fast<const FILTER: bool, D: ChunkDecoder>(
        &mut self,
        decoder: &mut D,
        records: &[D::Record],
        place: impl Fn(u16, usize) -> Option<usize>,
    ) {
        match self.unit_start() {
            Some(start) => {
                let bins = self.window.bins;
                self.bin_with::<FILTER, D>(decoder, records, place, move |micro: u32| {
                    let bin = micro.wrapping_sub(start) as usize;
                    (bin < bins).then_some(bin)
                })
            }
            None => {
                let (lut, window) = (std::mem::take(&mut self.micro_lut), self.window);
                self.bin_with::<FILTER, D>(decoder, records, place, |micro| {
                    lookup_bin(&lut, &window, micro)
                });
                self.micro_lut = lut;
            }
        }
    }

    /// [`Binner::bin_fast`] with the micro time's bin from `bin_of`.
    #[inline(always)]
    fn bin_with<const FILTER: bool, D: ChunkDecoder>(
        &mut self,
        decoder: &mut D,
        records: &[D::Record],
        place: impl Fn(u16, usize) -> Option<usize>,
        bin_of: impl Fn(u32) -> Option<usize>,
    ) {
        let sink = FastSink::<_, _, FILTER> {
            window: self.window,
            bin_of,
            place,
            channel: self.channel.unwrap_or(0),
            stack: &mut self.stacks[0],
            markers: 0,
            other_records: 0,
            other_channel: 0,
            outside_window: 0,
            outside_region: 0,
            past: self.past,
        };
        let f = decoder.decode_chunk(records, sink);
        // The loop counts the exceptions only; photons and binned photons
        // follow from them.
        let photons = records.len() as u64 - f.markers - f.other_records;
        let acc = &mut self.counts;
        acc.records += records.len() as u64;
        acc.photons += photons;
        acc.markers += f.markers;
        acc.other_channel += f.other_channel;
        acc.outside_window += f.outside_window;
        acc.outside_region += f.outside_region;
        acc.binned += photons - f.other_channel - f.outside_window - f.outside_region;
        self.past = f.past;
    }

    /// Whether no photon's place depends on the records before it: true
    /// for every map but a scanned image's, whose pixel follows the line
    /// markers. Parts of such a stream can be binned apart and
    /// [`Binner::absorb`]ed.
    pub fn order_free(&self) -> bool {
        !matches!(self.map, PixelMap::Scan(_))
    }

    /// Adds the counts of `other`, a clone of this binner's fresh state
    /// that binned another part of the same stream (see
    /// [`Binner::order_free`]).
    pub fn absorb(&mut self, other: Binner) {
        debug_assert!(self.order_free() && self.shape == other.shape);
        for (i, stack) in other.stacks.into_iter().enumerate() {
            match self.stacks.get_mut(i) {
                Some(mine) => mine.iter_mut().zip(stack).for_each(|(a, b)| *a += b),
                None => self.stacks.push(stack),
            }
        }
        self.counts += other.counts;
        self.past.photons += other.past.photons;
        self.past.max_micro = self.past.max_micro.max(other.past.max_micro);
    }

    /// Feeds one decoded record's tag (`None` for overflow records).
    #[inline]
    pub fn push(&mut self, tag: Option<Tag>) {
        self.counts.records += 1;
        match tag {
            None | Some(Tag::Sync { .. }) => {}
            Some(Tag::Photon {
                channel,
                macro_time,
                micro_time,
            }) => {
                self.counts.photons += 1;
                if self.channel.is_some_and(|c| c != channel) {
                    self.counts.other_channel += 1;
                    return;
                }
                let Some(bin) = self.micro_bin(micro_time) else {
                    self.counts.outside_window += 1;
                    self.past.note(&self.window, micro_time);
                    return;
                };
                match self.map {
                    PixelMap::Single => self.bin_at(0, bin, 0, 0),
                    PixelMap::Channel { width } => {
                        if usize::from(channel) < width {
                            self.bin_at(0, bin, 0, usize::from(channel));
                        } else {
                            self.counts.outside_region += 1;
                        }
                    }
                    PixelMap::Sensor { .. } => self.bin_sensor_pixel(bin, channel),
                    PixelMap::Scan(_) => {
                        if self.scan.line_start.is_some() {
                            self.scan.pending.push((macro_time, bin));
                        } else {
                            self.counts.outside_region += 1;
                        }
                    }
                }
            }
            Some(Tag::Marker { bits, macro_time }) => {
                self.counts.markers += 1;
                if let PixelMap::Scan(img) = self.map {
                    self.scan_marker(img, bits, macro_time);
                }
            }
        }
    }

    /// Whether this is a [`PixelMap::Sensor`] binner without a channel
    /// filter, for which [`Binner::push_sensor_photons`] applies.
    pub fn is_sensor(&self) -> bool {
        matches!(self.map, PixelMap::Sensor { .. })
            && self.channel.is_none()
            && !self.pixel_lut.is_empty()
    }

    /// Bins `(pixel, micro time)` photons of a [`PixelMap::Sensor`] map
    /// (the live-acquisition hot path). All photons are first turned into
    /// stack offsets (table lookups, cache-resident), then the stack is
    /// incremented in one tight loop: with little work between the random
    /// increments the CPU keeps many cache misses in flight. Measured 15x
    /// faster than binning photon by photon (see BENCHMARKS.md).
    pub fn push_sensor_photons(&mut self, photons: impl Iterator<Item = (u16, u32)>) {
        debug_assert!(self.is_sensor());
        let (k, h, w) = self.shape;
        let plane = h * w;
        let mut offsets = std::mem::take(&mut self.offsets);
        offsets.clear();
        let (mut n, mut outside_window, mut outside_region) = (0u64, 0u64, 0u64);
        for (pixel, micro) in photons {
            n += 1;
            let Some(bin) = self.micro_bin(micro) else {
                outside_window += 1;
                continue;
            };
            let flat = self.pixel_lut[usize::from(pixel)];
            if flat == OUTSIDE_REGION {
                outside_region += 1;
                continue;
            }
            offsets.push((bin * plane) as u32 + flat);
        }
        if self.stacks.is_empty() {
            self.stacks.push(vec![0; k * plane]);
        }
        let stack = &mut self.stacks[0];
        for &o in offsets.iter() {
            stack[o as usize] += 1;
        }
        self.counts.records += n;
        self.counts.photons += n;
        self.counts.binned += offsets.len() as u64;
        self.counts.outside_window += outside_window;
        self.counts.outside_region += outside_region;
        self.offsets = offsets;
    }

    /// Adds the counts of records that place no photon (overflows, losses,
    /// records that do not decode), read by the caller.
    pub fn count_other_records(&mut self, other: Counts) {
        debug_assert_eq!(other.photons + other.markers, 0);
        self.counts += other;
    }

    /// Counts marker records that need no other handling (sensor maps).
    pub fn count_markers(&mut self, n: u64) {
        self.counts.records += n;
        self.counts.markers += n;
    }

    /// Bins a photon of a [`PixelMap::Sensor`] map.
    #[inline]
    fn bin_sensor_pixel(&mut self, bin: usize, pixel: u16) {
        let flat = self
            .pixel_lut
            .get(usize::from(pixel))
            .copied()
            .unwrap_or(OUTSIDE_REGION);
        if flat == OUTSIDE_REGION {
            self.counts.outside_region += 1;
            return;
        }
        let (_, h, w) = self.shape;
        if self.stacks.is_empty() {
            self.stacks.push(vec![0; self.shape.0 * h * w]);
        }
        self.stacks[0][bin * h * w + flat as usize] += 1;
        self.counts.binned += 1;
    }

    // Always inlined: as a call it cost half the decode + bin time of
    // `scatterscope bin` (perf, BENCHMARKS.md).
    #[inline(always)]
    fn bin_at(&mut self, frame: usize, bin: usize, row: usize, col: usize) {
        let (_, h, w) = self.shape;
        let all = self.frames == FrameSelect::All;
        match self.stack_for_frame(frame) {
            Some(stack) => {
                stack[(bin * h + row) * w + col] += 1;
                self.counts.binned += 1;
            }
            None if all => self.counts.over_budget += 1,
            None => self.counts.outside_region += 1,
        }
    }

    /// Bins the photons of the line from `start` to `stop` (macro time)
    /// into the current row. Their stack offsets are computed first and
    /// the counts incremented in one tight loop after: a line's photons
    /// land on every bin plane of a stack larger than the cache, and
    /// with nothing between the increments the CPU keeps many of those
    /// misses in flight (the per-photon loop was 62 % of binning a FLIM
    /// image, perf, BENCHMARKS.md).
    fn flush_line(&mut self, img: Imaging, start: u64, stop: u64) {
        let mut pending = std::mem::take(&mut self.scan.pending);
        let mut offsets = std::mem::take(&mut self.offsets);
        offsets.clear();
        let row = self.scan.line;
        if row < img.pixels_y {
            let (_, h, w) = self.shape;
            let duration = stop.saturating_sub(start).max(1) as f64;
            let reverse = img.bidirectional && row % 2 == 1;
            offsets.extend(pending.iter().filter_map(|&(pt, bin)| {
                let x = (pt.saturating_sub(start) as f64 / duration * img.pixels_x as f64) as usize;
                (x < img.pixels_x).then(|| {
                    let col = if reverse { img.pixels_x - 1 - x } else { x };
                    // Below 2^30: `TimeWindow::check_stack`.
                    ((bin * h + row) * w + col) as u32
                })
            }));
        }
        let placed = offsets.len() as u64;
        self.counts.outside_region += pending.len() as u64 - placed;
        let all = self.frames == FrameSelect::All;
        // A line with no photon placed makes no stack (a frame's first
        // stack is made by its first photon, as everywhere).
        let stack = if placed > 0 {
            self.stack_for_frame(self.scan.frame)
        } else {
            None
        };
        match stack {
            Some(stack) => {
                for &o in &offsets {
                    stack[o as usize] += 1;
                }
                self.counts.binned += placed;
            }
            None if all => self.counts.over_budget += placed,
            None => self.counts.outside_region += placed,
        }
        pending.clear();
        self.scan.pending = pending;
        self.offsets = offsets;
    }

    fn scan_marker(&mut self, img: Imaging, bits: u8, t: u64) {
        if bits & img.line_start != 0 {
            // A start without a stop: photons of the unfinished line are lost.
            self.counts.outside_region += self.scan.pending.len() as u64;
            self.scan.pending.clear();
            self.scan.line_start = Some(t);
        }
        if bits & img.line_stop != 0
            && let Some(start) = self.scan.line_start.take()
        {
            self.flush_line(img, start, t);
            self.scan.line += 1;
            self.scan.lines_in_frame += 1;
        }
        if img.frame != 0 && bits & img.frame != 0 {
            // Frame markers precede their lines in some software and follow
            // them in other (SymPhoTime): a frame ends at a frame marker only
            // if it has lines, so neither convention loses or splits a frame.
            if self.scan.lines_in_frame > 0 {
                self.scan.frame += 1;
                self.counts.frames += 1;
            }
            self.scan.line = 0;
            self.scan.lines_in_frame = 0;
        }
    }

    /// The counts binned so far into the latest stack (`None` before the
    /// first photon), for a live view.
    pub fn counts_so_far(&self) -> Option<ndarray::ArrayView3<'_, u32>> {
        self.stacks.last().map(|s| {
            ndarray::ArrayView3::from_shape(self.shape, s).expect("stack length matches its shape")
        })
    }

    /// Counts so far.
    pub fn counts(&self) -> Counts {
        self.counts
    }

    /// Ends the stream: photons of an unfinished line count as outside the
    /// image; a last frame with lines counts as a frame.
    pub fn finish(mut self) -> (Vec<Array3<u32>>, Counts) {
        self.counts.outside_region += self.scan.pending.len() as u64;
        if self.scan.lines_in_frame > 0 {
            self.counts.frames += 1;
        }
        if self.stacks.is_empty() {
            let (k, h, w) = self.shape;
            self.stacks.push(vec![0; k * h * w]);
        }
        let stacks = self
            .stacks
            .into_iter()
            .map(|s| Array3::from_shape_vec(self.shape, s).expect("stack length matches its shape"))
            .collect();
        (stacks, self.counts)
    }
}

/// The bin of a micro time: from the lookup table, or by division beyond it.
#[inline(always)]
fn lookup_bin(micro_lut: &[u16], window: &TimeWindow, micro: u32) -> Option<usize> {
    match micro_lut.get(micro as usize) {
        Some(&OUTSIDE) => None,
        Some(&b) => Some(usize::from(b)),
        None => bin_past_lut(window, micro),
    }
}

/// The bin of a micro time past the lookup table. Kept out of line: its
/// floating-point registers, inlined, pushed the hot loop's pointers onto
/// the stack (perf, BENCHMARKS.md).
#[cold]
#[inline(never)]
fn bin_past_lut(window: &TimeWindow, micro: u32) -> Option<usize> {
    let x = (f64::from(micro) - window.start) / window.width;
    (x >= 0.0 && x < window.bins as f64).then_some(x as usize)
}

/// The sink of [`Binner::bin_chunk`]'s fast path: a photon goes to the
/// stack offset `place` gives its channel and its micro time's bin
/// (`bin_of`); with `FILTER`, only photons of `channel` are binned.
struct FastSink<'a, P, B, const FILTER: bool> {
    window: TimeWindow,
    bin_of: B,
    place: P,
    channel: u16,
    stack: &'a mut [u32],
    markers: u64,
    /// Records that are neither photons nor markers (overflows, syncs).
    other_records: u64,
    other_channel: u64,
    outside_window: u64,
    outside_region: u64,
    past: PastWindow,
}

impl<P, B, const FILTER: bool> TagSink for FastSink<'_, P, B, FILTER>
where
    P: Fn(u16, usize) -> Option<usize>,
    B: Fn(u32) -> Option<usize>,
{
    #[inline(always)]
    fn push(&mut self, tag: Option<Tag>) {
        match tag {
            None | Some(Tag::Sync { .. }) => self.other_records += 1,
            Some(Tag::Marker { .. }) => self.markers += 1,
            Some(Tag::Photon {
                channel,
                micro_time,
                ..
            }) => {
                if FILTER && channel != self.channel {
                    self.other_channel += 1;
                    return;
                }
                let Some(bin) = (self.bin_of)(micro_time) else {
                    self.outside_window += 1;
                    self.past.note(&self.window, micro_time);
                    return;
                };
                match (self.place)(channel, bin).and_then(|o| self.stack.get_mut(o)) {
                    Some(count) => *count += 1,
                    None => self.outside_region += 1,
                }
            }
        }
    }
}
