//! Every tag of a PicoQuant file in order, read by the project's reader:
//! what tests compare a conversion or a recording against.

use std::path::Path;

use scatterscope::events::Tag;
use scatterscope::formats::picoquant::open;
use scatterscope::formats::picoquant::records::Decoder;

/// Every tag of the PicoQuant file at `path`, in order (overflows left out).
pub fn ptu_tags(path: &Path) -> Vec<Tag> {
    let (info, mut reader) = open(path).unwrap();
    let mut decoder = Decoder::new(info.record_type);
    let mut chunk = Vec::new();
    let mut tags = Vec::new();
    while reader.next_chunk(&mut chunk).unwrap() {
        tags.extend(chunk.iter().filter_map(|&r| decoder.decode(r)));
    }
    tags
}
