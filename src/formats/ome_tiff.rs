//! OME-TIFF stacks and images, for the tools FLIM and imaging labs open
//! their data in (Fiji and Bio-Formats, napari, FLIMfit). One TIFF page
//! per time bin, in bin order; the OME-XML in the first page's
//! `ImageDescription` says the axes (`XYZCT`, the bins along T), the
//! physical pixel size and, as OME's `ModuloAlongT` annotation of type
//! `lifetime`, where each bin starts after time zero (ps): the annotation
//! FLIMfit reads a lifetime axis from. Photon counts are stored exactly in
//! the smallest unsigned integer type that holds them (16 or 32 bits);
//! anything else (expected counts, a reconstruction) as 32-bit floats.
//! Pages are deflate-compressed; files past 2 GiB are BigTIFF.

use std::io::{BufWriter, Seek, Write};
use std::path::Path;

use ndarray::{ArrayView2, ArrayView3, Axis};
use tiff::encoder::colortype::{ColorType, Gray16, Gray32, Gray32Float};
use tiff::encoder::{Compression, DeflateLevel, TiffEncoder, TiffKind, TiffValue};
use tiff::tags::Tag;

use crate::files::AtomicFile;
use crate::stack::{CountsView, Stack, StackError, StackMeta, Unstated, ValueKind};

/// The namespace of OME's modulo annotation (the 2011-09 additions).
const MODULO_NAMESPACE: &str = "http://www.openmicroscopy.org/Schemas/Additions/2011-09";

/// What one page holds, and how the OME-XML names it.
enum Samples {
    U16(Vec<Vec<u16>>),
    U32(Vec<Vec<u32>>),
    F32(Vec<Vec<f32>>),
}

impl Samples {
    fn ome_type(&self) -> &'static str {
        match self {
            Samples::U16(_) => "uint16",
            Samples::U32(_) => "uint32",
            Samples::F32(_) => "float",
        }
    }

    fn bytes(&self) -> u64 {
        let (planes, item) = match self {
            Samples::U16(p) => (p.iter().map(Vec::len).sum::<usize>(), 2),
            Samples::U32(p) => (p.iter().map(Vec::len).sum::<usize>(), 4),
            Samples::F32(p) => (p.iter().map(Vec::len).sum::<usize>(), 4),
        };
        planes as u64 * item
    }
}

/// The planes of `values` (bins first) as the smallest type that holds
/// them exactly when they are counts, else as floats.
fn samples(values: ArrayView3<f32>, exact: Option<ArrayView3<u32>>, counts: bool) -> Samples {
    let planes = |v: ArrayView3<f32>| -> Vec<Vec<f32>> {
        v.axis_iter(Axis(0))
            .map(|p| p.iter().copied().collect())
            .collect()
    };
    if let Some(exact) = exact {
        return Samples::U32(
            exact
                .axis_iter(Axis(0))
                .map(|p| p.iter().copied().collect())
                .collect(),
        );
    }
    let whole = counts
        && values
            .iter()
            .all(|&v| v >= 0.0 && v.fract() == 0.0 && v <= u32::MAX as f32);
    if !whole {
        return Samples::F32(planes(values));
    }
    let top = values.iter().fold(0.0f32, |m, &v| m.max(v));
    if top <= f32::from(u16::MAX) {
        Samples::U16(
            values
                .axis_iter(Axis(0))
                .map(|p| p.iter().map(|&v| v as u16).collect())
                .collect(),
        )
    } else {
        Samples::U32(
            values
                .axis_iter(Axis(0))
                .map(|p| p.iter().map(|&v| v as u32).collect())
                .collect(),
        )
    }
}

/// What the OME-XML says of an image.
struct Description<'a> {
    name: String,
    width: usize,
    height: usize,
    pixel_pitch_cm: Option<f64>,
    /// Start of each bin after time zero, ps, with the bin width (none for
    /// a single image).
    bins: Option<(&'a [f64], f64)>,
    /// Whether the bins count micro-time channels of an unknown unit
    /// instead of ps.
    channels: bool,
    /// Named channels, one page each (maps), instead of one channel.
    named: &'a [String],
}

/// `text` with XML's five special characters escaped.
fn escape(text: &str) -> String {
    text.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
        .replace('\'', "&apos;")
}

/// The `ModuloAlongT` element for bins starting at `starts` (ps, or
/// micro-time channels of an unknown unit when `channels`) of `width_ps`:
/// start, step and end when they follow one another, else one label per
/// bin.
fn modulo_along_t(starts: &[f64], width_ps: f64, channels: bool) -> String {
    let consecutive = starts
        .windows(2)
        .all(|w| ((w[1] - w[0]) - width_ps).abs() <= 1e-6 * width_ps);
    let head = if channels {
        // No Unit: the recording did not say what a channel is in time.
        "<ModuloAlongT Type=\"lifetime\" TypeDescription=\"TCSPC: micro-time channel of each bin; the recording does not state the time unit\""
    } else {
        "<ModuloAlongT Type=\"lifetime\" Unit=\"ps\" TypeDescription=\"TCSPC: start of each time bin after time zero\""
    };
    match (consecutive, starts.first(), starts.last()) {
        (true, Some(first), Some(last)) => {
            format!("{head} Start=\"{first}\" Step=\"{width_ps}\" End=\"{last}\"/>")
        }
        _ => {
            let labels: String = starts
                .iter()
                .map(|t| format!("<Label>{t}</Label>"))
                .collect();
            format!("{head}>{labels}</ModuloAlongT>")
        }
    }
}

/// The OME-XML of one image of `planes` pages of type `ome_type`.
fn ome_xml(d: &Description<'_>, planes: usize, ome_type: &str) -> String {
    let size = d.pixel_pitch_cm.map_or(String::new(), |cm| {
        // Micrometres, written as a character reference: the description
        // is an ASCII field.
        let um = cm * 1e4;
        format!(
            " PhysicalSizeX=\"{um}\" PhysicalSizeXUnit=\"&#181;m\" PhysicalSizeY=\"{um}\" PhysicalSizeYUnit=\"&#181;m\""
        )
    });
    let (annotation_ref, annotations) = match d.bins {
        Some((starts, width)) => (
            "<AnnotationRef ID=\"Annotation:Modulo:0\"/>".to_string(),
            format!(
                "<StructuredAnnotations><XMLAnnotation ID=\"Annotation:Modulo:0\" Namespace=\"openmicroscopy.org/omero/dimension/modulo\"><Value><Modulo namespace=\"{MODULO_NAMESPACE}\">{}</Modulo></Value></XMLAnnotation></StructuredAnnotations>",
                modulo_along_t(starts, width, d.channels)
            ),
        ),
        None => (String::new(), String::new()),
    };
    // Named channels are the pages (one time point); else one channel
    // whose pages are the time points.
    let (channels, size_c, size_t) = if d.named.is_empty() {
        (
            "<Channel ID=\"Channel:0:0\" SamplesPerPixel=\"1\"/>".to_string(),
            1,
            planes,
        )
    } else {
        let list = d
            .named
            .iter()
            .enumerate()
            .map(|(i, n)| {
                format!(
                    "<Channel ID=\"Channel:0:{i}\" Name=\"{}\" SamplesPerPixel=\"1\"/>",
                    escape(n)
                )
            })
            .collect();
        (list, d.named.len(), 1)
    };
    format!(
        concat!(
            "<?xml version=\"1.0\" encoding=\"UTF-8\"?>",
            "<OME xmlns=\"http://www.openmicroscopy.org/Schemas/OME/2016-06\" ",
            "xmlns:xsi=\"http://www.w3.org/2001/XMLSchema-instance\" ",
            "xsi:schemaLocation=\"http://www.openmicroscopy.org/Schemas/OME/2016-06 ",
            "http://www.openmicroscopy.org/Schemas/OME/2016-06/ome.xsd\" ",
            "Creator=\"scatterscope {version}\">",
            "<Image ID=\"Image:0\" Name=\"{name}\">{annotation_ref}",
            "<Pixels ID=\"Pixels:0\" DimensionOrder=\"XYZCT\" Type=\"{ome_type}\" ",
            "SizeX=\"{w}\" SizeY=\"{h}\" SizeZ=\"1\" SizeC=\"{c}\" SizeT=\"{st}\"{size} ",
            "BigEndian=\"false\" Interleaved=\"false\">",
            "{channels}",
            "<TiffData IFD=\"0\" PlaneCount=\"{t}\"/>",
            "</Pixels></Image>{annotations}</OME>"
        ),
        version = env!("CARGO_PKG_VERSION"),
        name = escape(&d.name),
        annotation_ref = annotation_ref,
        ome_type = ome_type,
        w = d.width,
        h = d.height,
        t = planes,
        c = size_c,
        st = size_t,
        channels = channels,
        size = size,
        annotations = annotations,
    )
}

/// Writes every page of `planes` as an image of type `C`, the description
/// on the first.
fn pages<W: Write + Seek, K: TiffKind, C: ColorType>(
    tiff: &mut TiffEncoder<W, K>,
    planes: &[Vec<C::Inner>],
    (width, height): (u32, u32),
    xml: &str,
) -> tiff::TiffResult<()>
where
    [C::Inner]: TiffValue,
{
    for (k, plane) in planes.iter().enumerate() {
        let mut page = tiff.new_image::<C>(width, height)?;
        if k == 0 {
            page.encoder().write_tag(Tag::ImageDescription, xml)?;
        }
        page.write_data(plane)?;
    }
    Ok(())
}

/// Writes `samples` with description `d` to `path`, whole or not at all.
fn write(samples: &Samples, d: &Description<'_>, path: &Path) -> Result<(), StackError> {
    let planes = match samples {
        Samples::U16(p) => p.len(),
        Samples::U32(p) => p.len(),
        Samples::F32(p) => p.len(),
    };
    let xml = ome_xml(d, planes, samples.ome_type());
    let size = (
        u32::try_from(d.width).map_err(|_| StackError::format(path, "wider than TIFF holds"))?,
        u32::try_from(d.height).map_err(|_| StackError::format(path, "taller than TIFF holds"))?,
    );
    let file = AtomicFile::create(path).map_err(|e| StackError::io(path, e))?;
    let mut out = BufWriter::new(file);
    let tiff_error = |e: tiff::TiffError| StackError::format(path, format!("writing TIFF: {e}"));
    let compression = Compression::Deflate(DeflateLevel::Fast);
    // Classic TIFF addresses 4 GiB; past half of it (with room for the
    // directories) the file is BigTIFF.
    if samples.bytes() < 1 << 31 {
        let mut tiff = TiffEncoder::new(&mut out)
            .map_err(tiff_error)?
            .with_compression(compression);
        all_pages(&mut tiff, samples, size, &xml).map_err(tiff_error)?;
    } else {
        let mut tiff = TiffEncoder::new_big(&mut out)
            .map_err(tiff_error)?
            .with_compression(compression);
        all_pages(&mut tiff, samples, size, &xml).map_err(tiff_error)?;
    }
    AtomicFile::commit_buffered(out).map_err(|e| StackError::io(path, e))?;
    Ok(())
}

fn all_pages<W: Write + Seek, K: TiffKind>(
    tiff: &mut TiffEncoder<W, K>,
    samples: &Samples,
    size: (u32, u32),
    xml: &str,
) -> tiff::TiffResult<()> {
    match samples {
        Samples::U16(p) => pages::<_, _, Gray16>(tiff, p, size, xml),
        Samples::U32(p) => pages::<_, _, Gray32>(tiff, p, size, xml),
        Samples::F32(p) => pages::<_, _, Gray32Float>(tiff, p, size, xml),
    }
}

/// Writes photon `counts` with `meta` as OME-TIFF, as [`write_stack`]
/// writes their stack (16-bit pages when every count fits, else 32-bit).
pub fn write_counts(counts: CountsView, meta: &StackMeta, path: &Path) -> Result<(), StackError> {
    fn pages<T: Copy, U>(c: ArrayView3<T>, f: impl Fn(T) -> U + Copy) -> Vec<Vec<U>> {
        c.axis_iter(Axis(0))
            .map(|p| p.iter().map(|&v| f(v)).collect())
            .collect()
    }
    let samples = match counts {
        CountsView::U16(c) => Samples::U16(pages(c, |v| v)),
        CountsView::U32(c) if counts.max() <= u32::from(u16::MAX) => {
            Samples::U16(pages(c, |v| v as u16))
        }
        CountsView::U32(c) => Samples::U32(pages(c, |v| v)),
    };
    let (_, h, w) = counts.dim();
    write(&samples, &describe(meta, w, h, path), path)
}

/// What the OME-XML says of a stack with `meta` of `w` x `h` pixels
/// written to `path`.
fn describe<'a>(meta: &'a StackMeta, w: usize, h: usize, path: &Path) -> Description<'a> {
    let name = path
        .file_name()
        .map_or("stack".into(), |n| n.to_string_lossy().into_owned());
    Description {
        name,
        width: w,
        height: h,
        // A pitch the recording did not state is left out, not written
        // as its placeholder.
        pixel_pitch_cm: (!meta.is_unstated(Unstated::PixelPitch)).then_some(meta.pixel_pitch_cm),
        bins: Some((&meta.bin_starts_ps, meta.bin_width_ps)),
        channels: meta.is_unstated(Unstated::TimeUnit),
        named: &[],
    }
}

/// Writes `stack` as OME-TIFF: one page per bin, the bins' starts as the
/// lifetime modulo of T, the pixel pitch as the physical size, counts
/// exactly as integers.
pub fn write_stack(stack: &Stack, path: &Path) -> Result<(), StackError> {
    let (_, h, w) = stack.data.dim();
    let counts = stack.meta.kind == ValueKind::Counts;
    let samples = samples(
        stack.data.view(),
        stack.exact_counts.as_ref().map(|c| c.view()),
        counts,
    );
    write(&samples, &describe(&stack.meta, w, h, path), path)
}

/// Writes one image (a reconstruction) as a one-page float OME-TIFF, with
/// its pixel pitch when known.
pub fn write_image(
    image: ArrayView2<f32>,
    pixel_pitch_cm: Option<f64>,
    path: &Path,
) -> Result<(), StackError> {
    let (h, w) = image.dim();
    let name = path
        .file_name()
        .map_or("image".into(), |n| n.to_string_lossy().into_owned());
    let d = Description {
        name,
        width: w,
        height: h,
        pixel_pitch_cm: pixel_pitch_cm.filter(|p| p.is_finite() && *p > 0.0),
        bins: None,
        channels: false,
        named: &[],
    };
    write(
        &Samples::F32(vec![image.iter().copied().collect()]),
        &d,
        path,
    )
}

/// Writes named images of one size (maps: each name says the quantity and
/// its unit) as a float32 OME-TIFF of one channel per image, each channel
/// named, with the pixel pitch when known.
pub fn write_named_images(
    images: &[(String, ArrayView2<f32>)],
    pixel_pitch_cm: Option<f64>,
    path: &Path,
) -> Result<(), StackError> {
    let (h, w) = images
        .first()
        .map(|(_, i)| i.dim())
        .ok_or_else(|| StackError::format(path, "no image to write"))?;
    if let Some((n, i)) = images.iter().find(|(_, i)| i.dim() != (h, w)) {
        return Err(StackError::format(
            path,
            format!("image `{n}` is {:?}, the first {:?}", i.dim(), (h, w)),
        ));
    }
    let named: Vec<String> = images.iter().map(|(n, _)| n.clone()).collect();
    let d = Description {
        name: path
            .file_name()
            .map_or("maps".into(), |n| n.to_string_lossy().into_owned()),
        width: w,
        height: h,
        pixel_pitch_cm: pixel_pitch_cm.filter(|p| p.is_finite() && *p > 0.0),
        bins: None,
        channels: false,
        named: &named,
    };
    let planes = images
        .iter()
        .map(|(_, i)| i.iter().copied().collect())
        .collect();
    write(&Samples::F32(planes), &d, path)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn consecutive_bins_are_a_range_and_others_are_labels() {
        let m = modulo_along_t(&[10.0, 14.0, 18.0], 4.0, false);
        assert!(m.contains("Start=\"10\" Step=\"4\" End=\"18\""), "{m}");
        let m = modulo_along_t(&[10.0, 14.0, 30.0], 4.0, false);
        assert!(
            m.contains("<Label>30</Label>") && !m.contains("Start="),
            "{m}"
        );
    }

    #[test]
    fn counts_take_the_smallest_exact_type() {
        let small = ndarray::Array3::from_elem((2, 2, 2), 7.0f32);
        assert!(matches!(samples(small.view(), None, true), Samples::U16(_)));
        assert!(matches!(
            samples(small.view(), None, false),
            Samples::F32(_)
        ));
        let big = ndarray::Array3::from_elem((2, 2, 2), 70_000.0f32);
        assert!(matches!(samples(big.view(), None, true), Samples::U32(_)));
        let half = ndarray::Array3::from_elem((2, 2, 2), 0.5f32);
        assert!(matches!(samples(half.view(), None, true), Samples::F32(_)));
    }

    #[test]
    fn the_name_is_escaped() {
        let d = Description {
            name: "a<b>&\"c\"".into(),
            width: 2,
            height: 3,
            pixel_pitch_cm: Some(0.01),
            bins: None,
            channels: false,
            named: &[],
        };
        let xml = ome_xml(&d, 1, "float");
        assert!(
            xml.contains("Name=\"a&lt;b&gt;&amp;&quot;c&quot;\""),
            "{xml}"
        );
        assert!(xml.contains("PhysicalSizeX=\"100\""), "{xml}");
        assert!(xml.is_ascii());
    }
}
