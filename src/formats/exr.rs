//! OpenEXR stack files.
//!
//! One layer named `stack`, one `f32` channel per bin named `t000`, `t001`,
//! ... (bin order; past 1000 bins every name has as many digits as the
//! last, `t0000` ... `t3124`, so that name order is time order),
//! compressed losslessly. Header attributes that any EXR
//! tool shows: `valueKind`, `binStartPs` (first bin), `binWidthPs`,
//! `pixelPitchCm` (each left out when the recording did not state it) and,
//! when known, `muAPerCm`, `muSPerCm`, `anisotropyG`,
//! `refractiveIndex`, `thicknessCm`. The complete metadata, including every
//! bin start and the dropped bins, is the JSON text attribute `scatterscope`;
//! it is what this reader trusts. Files from other tools need only the
//! channel names; without the attribute the caller supplies the metadata.

use std::path::Path;

use exr::block::{BlockIndex, UncompressedBlock};
use exr::image::write::channels::{ChannelsWriter, WritableChannels};
use exr::math::RoundingMode;
use exr::meta::attribute::{ChannelDescription, ChannelList, LevelMode, SampleType};
use exr::meta::header::Header;
use exr::prelude::{
    AnyChannel, AnyChannels, AttributeValue, Compression, Encoding, FlatSamples, Image, Layer,
    LayerAttributes, ReadChannels, ReadLayers, SmallVec, Text, WritableImage,
};
use ndarray::{Array3, ArrayView3, Axis};

use crate::files::ReadError;
use crate::memory::bytes_of;
use crate::stack::{
    CountsView, F32_EXACT_COUNT, Stack, StackError, StackFile, StackMeta, Unstated,
};

/// Most channels (bins) of a file written: OpenEXR's library (3.5) does
/// not open a file of 32768 channels (measured: 32767 opens).
pub const MAX_CHANNELS: usize = 32_767;

/// Name of the attribute holding the JSON metadata.
pub const META_ATTRIBUTE: &str = "scatterscope";

/// Name of channel `k` of `count` slices: `prefix` and the index, padded
/// to at least three digits and to the width of the largest index, so
/// that the names sort in slice order (EXR files list channels sorted by
/// name, and readers take them in that order: `t0999` before `t1000`,
/// where `t999` would sort after `t1000`).
pub fn channel_name(prefix: &str, k: usize, count: usize) -> String {
    let width = count.saturating_sub(1).to_string().len().max(3);
    format!("{prefix}{k:0width$}")
}

/// What the stack's channel names start with.
const STACK_CHANNEL_PREFIX: &str = "t";

/// `json` as EXR text: an EXR text attribute holds one byte per
/// character, so every character outside ASCII (a file name in another
/// script, a vendor's text field) is written as JSON's `\uXXXX` escape,
/// which any JSON reader turns back into the same character.
fn json_text(json: &str) -> Text {
    let mut ascii = String::with_capacity(json.len());
    for c in json.chars() {
        if c.is_ascii() {
            ascii.push(c);
        } else {
            let mut units = [0u16; 2];
            for u in c.encode_utf16(&mut units) {
                ascii.push_str(&format!("\\u{u:04x}"));
            }
        }
    }
    Text::new_or_none(ascii).expect("ASCII is EXR text")
}

/// Writes `stack` to `path`.
pub fn write(stack: &Stack, path: &Path) -> Result<(), StackError> {
    match &stack.exact_counts {
        // Counts above 2^24 go in 32-bit unsigned channels, exactly.
        Some(counts) => write_slices::<_, u32>(
            counts.view(),
            "stack",
            STACK_CHANNEL_PREFIX,
            volume_encoding(),
            || stack_attributes(&stack.meta),
            path,
        ),
        None => write_slices::<_, f32>(
            stack.data.view(),
            "stack",
            STACK_CHANNEL_PREFIX,
            volume_encoding(),
            || stack_attributes(&stack.meta),
            path,
        ),
    }
}

/// Writes photon `counts` with `meta` to `path` as [`write`] writes their
/// stack (float channels, 32-bit unsigned ones when a count passes 2^24),
/// each line converted as the encoder takes it: no float copy of the
/// whole stack is made.
pub fn write_counts(counts: CountsView, meta: &StackMeta, path: &Path) -> Result<(), StackError> {
    let attributes = || stack_attributes(meta);
    let (what, prefix, zip) = ("stack", STACK_CHANNEL_PREFIX, counts_encoding());
    match counts {
        CountsView::U16(c) => write_slices::<_, f32>(c, what, prefix, zip, attributes, path),
        CountsView::U32(c) if counts.max() > F32_EXACT_COUNT => {
            write_slices::<_, u32>(c, what, prefix, zip, attributes, path)
        }
        CountsView::U32(c) => write_slices::<_, f32>(c, what, prefix, zip, attributes, path),
    }
}

/// How binned recordings are stored: ZIP on 16 lines. On the two real
/// FLIM files in the shared samples (a 2 x 512 x 512 x 256 `.sdt`, a
/// 256 x 256 x 132 PTU image; `bin --no-preview`, medians of 5 on the
/// 2-core VM) it wrote as fast as PIZ (1.69 against 1.73 s, 0.12 against
/// 0.13 s) to 1.46 MB where PIZ took 2.47 MB on the large sparse image
/// (478 against 416 kB on the small one), with 20 % less memory
/// (BENCHMARKS.md).
fn counts_encoding() -> Encoding {
    Encoding {
        compression: Compression::ZIP16,
        ..Encoding::SMALL_LOSSLESS
    }
}

/// The header attributes of a stack with `meta`: its JSON and the values
/// other tools show.
fn stack_attributes(meta: &StackMeta) -> Result<LayerAttributes, StackError> {
    let json = serde_json::to_string(meta).expect("metadata serialises");
    let mut attrs = LayerAttributes::named("stack");
    let mut put = |name: &str, value: AttributeValue| {
        attrs.other.insert(Text::from(name), value);
    };
    put(META_ATTRIBUTE, AttributeValue::Text(json_text(&json)));
    put(
        "valueKind",
        AttributeValue::Text(Text::from(meta.kind.name())),
    );
    // What the recording left unstated is not written as a value (the
    // JSON says so).
    if !meta.is_unstated(Unstated::TimeUnit) {
        put("binStartPs", AttributeValue::F64(meta.bin_starts_ps[0]));
        put("binWidthPs", AttributeValue::F64(meta.bin_width_ps));
    }
    if !meta.is_unstated(Unstated::PixelPitch) {
        put("pixelPitchCm", AttributeValue::F64(meta.pixel_pitch_cm));
    }
    if let Some(setup) = &meta.setup {
        let m = &setup.medium;
        put("muAPerCm", AttributeValue::F64(m.mu_a_per_cm));
        put("muSPerCm", AttributeValue::F64(m.mu_s_per_cm));
        put("anisotropyG", AttributeValue::F64(m.g));
        put("refractiveIndex", AttributeValue::F64(m.refractive_index));
        put("thicknessCm", AttributeValue::F64(m.thickness_cm));
    }
    Ok(attrs)
}

/// A sample type an EXR channel holds.
trait ChannelSample: exr::io::Data + Copy + Sync + 'static {
    /// Its type in the file.
    const SAMPLE_TYPE: SampleType;
}

impl ChannelSample for f32 {
    const SAMPLE_TYPE: SampleType = SampleType::F32;
}

impl ChannelSample for u32 {
    const SAMPLE_TYPE: SampleType = SampleType::U32;
}

/// A volume element stored as a channel sample of type `T`.
trait AsSample<T>: Copy + Sync + bytemuck::Pod + 'static {
    /// Whether the element is the sample, bit for bit (a line is then
    /// copied whole).
    const SAME: bool;
    /// The sample.
    fn as_sample(self) -> T;
}

impl AsSample<f32> for f32 {
    const SAME: bool = true;
    fn as_sample(self) -> f32 {
        self
    }
}

impl AsSample<u32> for u32 {
    const SAME: bool = true;
    fn as_sample(self) -> u32 {
        self
    }
}

impl AsSample<f32> for u32 {
    const SAME: bool = false;
    /// Exact below 2^24, where counts are stored as floats.
    fn as_sample(self) -> f32 {
        self as f32
    }
}

impl AsSample<f32> for u16 {
    const SAME: bool = false;
    fn as_sample(self) -> f32 {
        f32::from(self)
    }
}

/// The slices of a volume along its first axis as EXR channels, named
/// `prefix` and the slice index, each line read from the volume when the
/// encoder asks for its block. The exr crate's own `AnyChannels` wants
/// every channel's samples in a `Vec` of its own: a copy of the whole
/// volume (64 MB for a 256 x 256 x 256 stack), whose fresh pages the
/// kernel zeroes, which was most of `bin`'s time on a large `.sdt` file on
/// our 2-core machine (BENCHMARKS.md); these bytes are the same.
struct SliceChannels<'a, S, T> {
    volume: ArrayView3<'a, S>,
    prefix: &'a str,
    sample: std::marker::PhantomData<T>,
}

impl<'s, S: AsSample<T>, T: ChannelSample + bytemuck::Pod> WritableChannels<'s>
    for SliceChannels<'_, S, T>
{
    fn infer_channel_list(&self) -> ChannelList {
        let count = self.volume.dim().0;
        // Names sort in slice order ([`channel_name`]), so the file's
        // sorted channel `k` is slice `k`.
        ChannelList::new(
            (0..count)
                .map(|k| {
                    ChannelDescription::named(
                        channel_name(self.prefix, k, count).as_str(),
                        T::SAMPLE_TYPE,
                    )
                })
                .collect(),
        )
    }

    fn infer_level_modes(&self) -> (LevelMode, RoundingMode) {
        (LevelMode::Singular, RoundingMode::Down)
    }

    type Writer = SliceWriter<'s, S, T>;

    fn create_writer(&'s self, _header: &Header) -> Self::Writer {
        SliceWriter {
            volume: self.volume.view(),
            sample: std::marker::PhantomData,
        }
    }
}

/// Lines of a volume's slices for the encoder.
struct SliceWriter<'a, S, T> {
    volume: ArrayView3<'a, S>,
    sample: std::marker::PhantomData<T>,
}

impl<S: AsSample<T>, T: ChannelSample + bytemuck::Pod> ChannelsWriter for SliceWriter<'_, S, T> {
    fn extract_uncompressed_block(&self, header: &Header, block: BlockIndex) -> Vec<u8> {
        UncompressedBlock::collect_block_data_from_lines(&header.channels, block, |line| {
            let at = line.location;
            let (x, y) = (at.position.x(), at.position.y());
            let row = self
                .volume
                .slice(ndarray::s![at.channel, y, x..x + at.sample_count]);
            let written = match row.as_slice() {
                Some(samples) if S::SAME => {
                    line.write_samples_from_slice(bytemuck::cast_slice::<S, T>(samples))
                }
                _ => line.write_samples(|i| row[i].as_sample()),
            };
            written.expect("a line's bytes hold its samples");
        })
    }
}

/// Writes a volume as one layer named `layer` with one `f32` channel per
/// slice along its first axis, named `prefix` and the slice index (`z000`,
/// ...), with `numbers` as `f64` header attributes and `json` as the text
/// attribute [`META_ATTRIBUTE`].
pub fn write_volume(
    volume: ndarray::ArrayView3<f32>,
    layer: &str,
    prefix: &str,
    numbers: &[(&str, f64)],
    json: &str,
    path: &Path,
) -> Result<(), StackError> {
    let attributes = || {
        let mut attrs = LayerAttributes::named(layer);
        let text = json_text(json);
        attrs
            .other
            .insert(Text::from(META_ATTRIBUTE), AttributeValue::Text(text));
        for (name, value) in numbers {
            attrs
                .other
                .insert(Text::from(*name), AttributeValue::F64(*value));
        }
        Ok(attrs)
    };
    write_slices::<_, f32>(volume, layer, prefix, volume_encoding(), attributes, path)
}

/// One layer whose channels are the slices of `volume` along its first
/// axis, named `prefix` and the slice index, stored with `encoding`, with
/// the attributes `attributes` makes once the volume is known not to be
/// empty (`what` names it then).
fn write_slices<S: AsSample<T>, T: ChannelSample + bytemuck::Pod>(
    volume: ArrayView3<S>,
    what: &str,
    prefix: &str,
    encoding: Encoding,
    attributes: impl FnOnce() -> Result<LayerAttributes, StackError>,
    path: &Path,
) -> Result<(), StackError> {
    let (k, h, w) = volume.dim();
    if k == 0 || h == 0 || w == 0 {
        return Err(StackError::format(
            path,
            format!("cannot write an empty {k} x {h} x {w} {what}"),
        ));
    }
    if k > MAX_CHANNELS {
        return Err(StackError::format(
            path,
            format!(
                "a {what} of {k} slices: an OpenEXR file of more than {MAX_CHANNELS} channels is one OpenEXR's own library (3.5) will not open; write it as .npy or OME-TIFF (bin --npy), or with fewer bins"
            ),
        ));
    }
    let layer = Layer::new(
        (w, h),
        attributes()?,
        encoding,
        SliceChannels {
            volume,
            prefix,
            sample: std::marker::PhantomData::<T>,
        },
    );
    write_layer(layer, path)
}

/// How volumes are stored: PIZ (wavelet and Huffman, lossless for every
/// sample type): on a 125 x 256 x 256 FLIM stack it wrote in 137 ms to
/// 1.15 MB where ZIP16 took 207 ms for 1.53 MB, and on the demo's 30 x
/// 256 x 256 stack 30 ms to 0.70 MB against 87 ms for 1.00 MB; it reads
/// back 20 to 25 ms slower, once per reconstruction (BENCHMARKS.md).
fn volume_encoding() -> Encoding {
    Encoding {
        compression: Compression::PIZ,
        ..Encoding::SMALL_LOSSLESS
    }
}

/// Encodes one layer and writes it to `path`, header attributes in name
/// order.
fn write_layer<C>(layer: Layer<C>, path: &Path) -> Result<(), StackError>
where
    C: for<'s> WritableChannels<'s>,
{
    let mut bytes = Vec::new();
    Image::from_layer(layer)
        .write()
        .to_buffered(std::io::Cursor::new(&mut bytes))
        .map_err(|e| exr_error(path, e))?;
    sort_header_attributes(&mut bytes);
    crate::files::write_atomic(path, bytes).map_err(|e| StackError::io(path, e))
}

/// Puts the header attributes of a single-part EXR file in name order, in
/// place, so that the same stack always gives the same bytes. The `exr`
/// crate writes custom attributes in hash-map order, which changes from
/// run to run; attribute order carries no meaning in OpenEXR and the
/// header keeps its length, so the offset table after it stays valid.
/// Leaves anything it does not recognise untouched.
fn sort_header_attributes(bytes: &mut [u8]) {
    const MAGIC: [u8; 4] = [0x76, 0x2f, 0x31, 0x01];
    const MULTIPART: u32 = 0x1000;
    let Some(flags) = bytes.get(4..8) else { return };
    let flags = u32::from_le_bytes(flags.try_into().expect("4 bytes"));
    if bytes[..4] != MAGIC || flags & MULTIPART != 0 {
        return;
    }
    let nul_after = |from: usize| {
        bytes
            .get(from..)?
            .iter()
            .position(|&b| b == 0)
            .map(|i| from + i)
    };
    let mut attributes: Vec<(usize, usize)> = Vec::new();
    let mut pos = 8;
    loop {
        match bytes.get(pos) {
            None => return,
            Some(0) => break,
            Some(_) => {}
        }
        let Some(name_end) = nul_after(pos) else {
            return;
        };
        let Some(type_end) = nul_after(name_end + 1) else {
            return;
        };
        let Some(size) = bytes.get(type_end + 1..type_end + 5) else {
            return;
        };
        let size = u32::from_le_bytes(size.try_into().expect("4 bytes")) as usize;
        let end = type_end + 5 + size;
        if end > bytes.len() {
            return;
        }
        attributes.push((pos, end));
        pos = end;
    }
    let name = |&(start, _): &(usize, usize)| {
        let end = nul_after(start).expect("checked above");
        &bytes[start..end]
    };
    attributes.sort_by(|a, b| name(a).cmp(name(b)));
    let sorted: Vec<u8> = attributes
        .iter()
        .flat_map(|&(start, end)| bytes[start..end].iter().copied())
        .collect();
    bytes[8..pos].copy_from_slice(&sorted);
}

/// Most decoded pixel bytes a file may declare per byte it holds. Lossless
/// EXR compression (ZIP's deflate tops out near 1032:1) cannot reach it, so
/// only headers that promise more pixels than the file could hold are
/// refused, before anything is allocated for them.
const MAX_EXPANSION: u64 = 4096;
/// Decoded bytes any file may declare, whatever its size.
const MIN_BUDGET: u64 = 64 << 20;

/// The first valid layer of an EXR file with all its channels and
/// attributes. Refused before decoding: a special file, a header that
/// declares more pixels than the file could hold, or more than the memory
/// budget (the samples, a float32 copy of each channel and the stack).
pub(crate) fn read_first_layer(path: &Path) -> Result<Layer<AnyChannels<FlatSamples>>, StackError> {
    let (_, file) = crate::files::open_input(path, "OpenEXR file")?;
    let size = file.len();
    let budget = size.saturating_mul(MAX_EXPANSION).max(MIN_BUDGET);
    let meta = exr::meta::MetaData::read_from_file(path, false).map_err(|e| exr_error(path, e))?;
    for header in meta.headers.iter() {
        let (w, h) = (header.layer_size.0 as u64, header.layer_size.1 as u64);
        let declared = w
            .saturating_mul(h)
            .saturating_mul(header.channels.bytes_per_pixel as u64)
            .saturating_add((header.chunk_count as u64).saturating_mul(8));
        if declared > budget {
            return Err(StackError::format(
                path,
                format!(
                    "OpenEXR: header declares {w} x {h} pixels of {} bytes ({declared} bytes decoded) in a file of {size} bytes",
                    header.channels.bytes_per_pixel
                ),
            ));
        }
        let channels = header.channels.list.len();
        crate::memory::check(bytes_of([w as usize, h as usize, channels], 12), || {
            format!("the {w} x {h} x {channels} image of {}", path.display())
        })
        .map_err(ReadError::from)?;
    }
    exr::prelude::read()
        .no_deep_data()
        .largest_resolution_level()
        .all_channels()
        .first_valid_layer()
        .all_attributes()
        .from_file(path)
        .map(|image| image.layer_data)
        .map_err(|e| exr_error(path, e))
}

/// Reads the first layer's time-bin channels (`t000`, `t001`, ...), as
/// [`write()`] or any other OpenEXR writer lays them out, and the metadata
/// attribute when there is one.
pub fn read(path: &Path) -> Result<StackFile, StackError> {
    let layer = read_first_layer(path)?;
    let meta = match layer.attributes.other.get(&Text::from(META_ATTRIBUTE)) {
        Some(AttributeValue::Text(t)) => Some(
            serde_json::from_str::<StackMeta>(&t.to_string()).map_err(|e| {
                StackError::format(path, format!("attribute `{META_ATTRIBUTE}`: {e}"))
            })?,
        ),
        Some(other) => {
            return Err(StackError::format(
                path,
                format!("attribute `{META_ATTRIBUTE}` is {other:?}, expected JSON text"),
            ));
        }
        None => None,
    };
    let mut bins: Vec<(usize, &FlatSamples)> = Vec::new();
    for ch in &layer.channel_data.list {
        let name = ch.name.to_string();
        let index = name
            .strip_prefix('t')
            .and_then(|n| n.parse::<usize>().ok())
            .ok_or_else(|| {
                StackError::format(path, format!("channel `{name}` is not a time bin (tNNN)"))
            })?;
        bins.push((index, &ch.sample_data));
    }
    bins.sort_by_key(|(i, _)| *i);
    for (expect, (got, _)) in bins.iter().enumerate() {
        if *got != expect {
            return Err(StackError::format(
                path,
                format!(
                    "time-bin channels are not contiguous: expected {}, found {}",
                    channel_name(STACK_CHANNEL_PREFIX, expect, bins.len()),
                    channel_name(STACK_CHANNEL_PREFIX, *got, bins.len())
                ),
            ));
        }
    }
    let (w, h) = (layer.size.0, layer.size.1);
    let mut data = Array3::<f32>::zeros((bins.len(), h, w));
    for (mut dst, (_, samples)) in data.axis_iter_mut(Axis(0)).zip(&bins) {
        match samples {
            FlatSamples::F32(v) => dst.iter_mut().zip(v).for_each(|(d, &v)| *d = v),
            other => dst
                .iter_mut()
                .zip(other.values_as_f32())
                .for_each(|(d, v)| *d = v),
        }
    }
    // 32-bit unsigned channels hold counts exactly; kept when f32 cannot.
    let big = |s: &FlatSamples| match s {
        FlatSamples::U32(v) => v.iter().any(|&c| c > F32_EXACT_COUNT),
        _ => false,
    };
    let exact_counts = if bins.iter().any(|(_, s)| big(s)) {
        let mut counts = Array3::<u32>::zeros((bins.len(), h, w));
        for (mut dst, (_, samples)) in counts.axis_iter_mut(Axis(0)).zip(&bins) {
            match samples {
                FlatSamples::U32(v) => dst.iter_mut().zip(v).for_each(|(d, &v)| *d = v),
                other => {
                    for (d, v) in dst.iter_mut().zip(other.values_as_f32()) {
                        if !(v >= 0.0 && v.fract() == 0.0 && v <= u32::MAX as f32) {
                            return Err(StackError::format(
                                path,
                                format!(
                                    "a bin of counts holds {v}, not a whole count, beside 32-bit count channels"
                                ),
                            ));
                        }
                        *d = v as u32;
                    }
                }
            }
        }
        Some(counts)
    } else {
        None
    };
    Ok(StackFile {
        data,
        meta,
        exact_counts,
    })
}

fn exr_error(path: &Path, e: exr::error::Error) -> StackError {
    match e {
        exr::error::Error::Io(io) => StackError::io(path, io),
        other => StackError::format(path, format!("OpenEXR: {other}")),
    }
}

/// Writes a single image as a one-channel (`Y`) EXR, e.g. a truth image;
/// `scatterscope simulate --scene FILE.exr` reads it back.
pub fn write_image(img: ndarray::ArrayView2<f32>, path: &Path) -> Result<(), StackError> {
    let (h, w) = img.dim();
    let channel = AnyChannel::new("Y", FlatSamples::F32(img.iter().copied().collect()));
    let layer = Layer::new(
        (w, h),
        LayerAttributes::named("image"),
        Encoding::SMALL_LOSSLESS,
        AnyChannels::sort(SmallVec::from_vec(vec![channel])),
    );
    write_layer(layer, path)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The file the exr crate's own channels (each slice copied into a
    /// `Vec`) make of `volume`.
    fn written_by_any_channels<T: ChannelSample>(
        volume: ArrayView3<T>,
        samples: fn(Vec<T>) -> FlatSamples,
        path: &Path,
    ) -> Vec<u8> {
        let count = volume.dim().0;
        let channels: SmallVec<[AnyChannel<FlatSamples>; 4]> = volume
            .axis_iter(Axis(0))
            .enumerate()
            .map(|(k, slice)| {
                AnyChannel::new(
                    channel_name("t", k, count).as_str(),
                    samples(slice.iter().copied().collect()),
                )
            })
            .collect();
        let (_, h, w) = volume.dim();
        let layer = Layer::new(
            (w, h),
            LayerAttributes::named("stack"),
            volume_encoding(),
            AnyChannels::sort(channels),
        );
        write_layer(layer, path).unwrap();
        std::fs::read(path).unwrap()
    }

    /// Lines read from the volume as the encoder asks give the same bytes
    /// as the crate's channels of copied slices: f32 and u32 samples, a
    /// size that is no multiple of PIZ's 32-line blocks, a volume not in
    /// standard layout, and more than 1000 slices (names of 4 digits).
    #[test]
    fn slices_read_in_place_write_the_bytes_the_crates_channels_write() {
        let dir = tempfile::tempdir().unwrap();
        let f32s = Array3::from_shape_fn((5, 37, 9), |(k, y, x)| (k * 1000 + y * 10 + x) as f32);
        let u32s = Array3::from_shape_fn((3, 40, 33), |(k, y, x)| (k << 30 | y << 8 | x) as u32);
        let many = Array3::from_shape_fn((1001, 2, 3), |(k, y, x)| (k + y + x) as f32);
        let transposed = f32s.view().permuted_axes([0, 2, 1]);
        let ours = |path: &Path, write: &dyn Fn(&Path)| {
            write(path);
            std::fs::read(path).unwrap()
        };
        let attributes = || Ok(LayerAttributes::named("stack"));
        for (i, volume) in [f32s.view(), many.view(), transposed]
            .into_iter()
            .enumerate()
        {
            let mine = ours(&dir.path().join(format!("f{i}.exr")), &|p| {
                write_slices::<_, f32>(volume, "stack", "t", volume_encoding(), attributes, p)
                    .unwrap()
            });
            let theirs = written_by_any_channels(
                volume,
                FlatSamples::F32,
                &dir.path().join(format!("g{i}.exr")),
            );
            assert_eq!(mine, theirs, "f32 volume {i}");
        }
        let mine = ours(&dir.path().join("u.exr"), &|p| {
            write_slices::<_, u32>(u32s.view(), "stack", "t", volume_encoding(), attributes, p)
                .unwrap()
        });
        let theirs =
            written_by_any_channels(u32s.view(), FlatSamples::U32, &dir.path().join("v.exr"));
        assert_eq!(mine, theirs, "u32 volume");
        // 16-bit counts become float samples line by line: the bytes of
        // the crate's channels of their float copies.
        let u16s = Array3::from_shape_fn((4, 35, 7), |(k, y, x)| (k * 9000 + y * 50 + x) as u16);
        let mine = ours(&dir.path().join("h.exr"), &|p| {
            write_slices::<_, f32>(u16s.view(), "stack", "t", volume_encoding(), attributes, p)
                .unwrap()
        });
        let theirs = written_by_any_channels(
            u16s.mapv(f32::from).view(),
            FlatSamples::F32,
            &dir.path().join("i.exr"),
        );
        assert_eq!(mine, theirs, "u16 volume");
    }
}
