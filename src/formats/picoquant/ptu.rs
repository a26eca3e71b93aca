//! The PTU tagged header: `PQTTTR\0\0`, an 8-byte version, then tags of
//! 48 bytes (32-byte ident, i32 index, u32 type, 8-byte value), strings,
//! arrays and blobs followed by their payload, up to `Header_End`. All
//! little-endian. Payload lengths need not be multiples of 8.

use std::io::Read;

use super::TtrError;

/// A tag's value.
#[derive(Debug, Clone, PartialEq)]
pub enum TagValue {
    /// tyEmpty8.
    Empty,
    /// tyBool8.
    Bool(bool),
    /// tyInt8, tyBitSet64, tyColor8.
    Int(i64),
    /// tyFloat8.
    Float(f64),
    /// tyTDateTime (days since 1899-12-30).
    DateTime(f64),
    /// tyFloat8Array.
    FloatArray(Vec<f64>),
    /// tyAnsiString, tyWideString.
    Text(String),
    /// tyBinaryBlob (length only; the bytes are skipped).
    Blob(usize),
}

/// One header tag.
#[derive(Debug, Clone, PartialEq)]
pub struct HeaderTag {
    /// Tag name, e.g. `MeasDesc_Resolution`.
    pub ident: String,
    /// Index (-1 for scalars).
    pub index: i32,
    /// Value.
    pub value: TagValue,
    /// The tag exactly as the file holds it (its 48 bytes and payload),
    /// so that a writer can copy it at full precision.
    pub raw: Vec<u8>,
}

/// Tag type codes.
pub mod ty {
    /// Empty.
    pub const EMPTY8: u32 = 0xFFFF_0008;
    /// Boolean.
    pub const BOOL8: u32 = 0x0000_0008;
    /// Integer.
    pub const INT8: u32 = 0x1000_0008;
    /// Bit set.
    pub const BITSET64: u32 = 0x1100_0008;
    /// Colour.
    pub const COLOR8: u32 = 0x1200_0008;
    /// Double.
    pub const FLOAT8: u32 = 0x2000_0008;
    /// Date.
    pub const DATETIME: u32 = 0x2100_0008;
    /// Array of doubles.
    pub const FLOAT8_ARRAY: u32 = 0x2001_FFFF;
    /// 8-bit string.
    pub const ANSI_STRING: u32 = 0x4001_FFFF;
    /// UTF-16 string.
    pub const WIDE_STRING: u32 = 0x4002_FFFF;
    /// Blob.
    pub const BINARY_BLOB: u32 = 0xFFFF_FFFF;
}

/// Largest payload of one tag we accept (a corrupt length would otherwise
/// ask for gigabytes).
const MAX_PAYLOAD: u64 = 64 << 20;
/// Most tags we read before giving up on finding `Header_End`.
const MAX_TAGS: usize = 1 << 20;

/// The magic at the start of every PTU file.
pub const MAGIC: &[u8; 8] = b"PQTTTR\0\0";

/// Parses the tagged header after the 8-byte magic; returns the version,
/// the tags and the number of bytes consumed (magic included).
pub fn parse(r: &mut impl Read) -> Result<(String, Vec<HeaderTag>, u64), TtrError> {
    let mut head = [0u8; 16];
    read_exact(r, &mut head, 0, "magic and version")?;
    if &head[..8] != MAGIC {
        return Err(TtrError::header(
            0,
            format!(
                "magic is {:?}, expected \"PQTTTR\"",
                String::from_utf8_lossy(&head[..8])
            ),
        ));
    }
    let version = c_string(&head[8..]);
    let mut offset = 16u64;
    let mut tags = Vec::new();
    loop {
        if tags.len() >= MAX_TAGS {
            return Err(TtrError::header(offset, "no Header_End tag"));
        }
        let mut raw = [0u8; 48];
        read_exact(r, &mut raw, offset, "tag")?;
        let ident = c_string(&raw[..32]);
        let index = i32::from_le_bytes(raw[32..36].try_into().expect("4 bytes"));
        let typ = u32::from_le_bytes(raw[36..40].try_into().expect("4 bytes"));
        let bits: [u8; 8] = raw[40..48].try_into().expect("8 bytes");
        let tag_offset = offset;
        offset += 48;
        let int = i64::from_le_bytes(bits);
        let mut payload = Vec::new();
        let value = match typ {
            ty::EMPTY8 => TagValue::Empty,
            ty::BOOL8 => TagValue::Bool(int != 0),
            ty::INT8 | ty::BITSET64 | ty::COLOR8 => TagValue::Int(int),
            ty::FLOAT8 => TagValue::Float(f64::from_le_bytes(bits)),
            ty::DATETIME => TagValue::DateTime(f64::from_le_bytes(bits)),
            ty::FLOAT8_ARRAY | ty::ANSI_STRING | ty::WIDE_STRING | ty::BINARY_BLOB => {
                let len = u64::try_from(int)
                    .ok()
                    .filter(|&l| l <= MAX_PAYLOAD)
                    .ok_or_else(|| {
                        TtrError::header(
                            tag_offset,
                            format!("tag {ident}: payload length {int} is not plausible"),
                        )
                    })?;
                payload = vec![0u8; len as usize];
                read_exact(r, &mut payload, offset, &format!("payload of tag {ident}"))?;
                offset += len;
                match typ {
                    ty::FLOAT8_ARRAY => TagValue::FloatArray(
                        payload
                            .chunks_exact(8)
                            .map(|c| f64::from_le_bytes(c.try_into().expect("8 bytes")))
                            .collect(),
                    ),
                    ty::ANSI_STRING => TagValue::Text(c_string(&payload)),
                    ty::WIDE_STRING => {
                        let units: Vec<u16> = payload
                            .chunks_exact(2)
                            .map(|c| u16::from_le_bytes([c[0], c[1]]))
                            .take_while(|&u| u != 0)
                            .collect();
                        TagValue::Text(String::from_utf16_lossy(&units))
                    }
                    _ => TagValue::Blob(payload.len()),
                }
            }
            other => {
                return Err(TtrError::header(
                    tag_offset,
                    format!("tag {ident}: unknown type code 0x{other:08X}"),
                ));
            }
        };
        let end = ident == "Header_End";
        let mut bytes = raw.to_vec();
        bytes.extend_from_slice(&payload);
        tags.push(HeaderTag {
            ident,
            index,
            value,
            raw: bytes,
        });
        if end {
            return Ok((version, tags, offset));
        }
    }
}

fn read_exact(r: &mut impl Read, buf: &mut [u8], offset: u64, what: &str) -> Result<(), TtrError> {
    r.read_exact(buf).map_err(|e| {
        if e.kind() == std::io::ErrorKind::UnexpectedEof {
            TtrError::header(offset, format!("file ends inside the {what}"))
        } else {
            TtrError::Io(e)
        }
    })
}

fn c_string(bytes: &[u8]) -> String {
    let end = bytes.iter().position(|&b| b == 0).unwrap_or(bytes.len());
    bytes[..end].iter().map(|&b| b as char).collect()
}

/// Lookup helpers over a tag list.
pub trait TagLookup {
    /// The scalar tag `ident` (index -1 or 0).
    fn value(&self, ident: &str) -> Option<&TagValue>;
    /// An integer tag.
    fn int(&self, ident: &str) -> Option<i64> {
        match self.value(ident)? {
            TagValue::Int(v) => Some(*v),
            TagValue::Bool(b) => Some(i64::from(*b)),
            _ => None,
        }
    }
    /// A float tag.
    fn float(&self, ident: &str) -> Option<f64> {
        match self.value(ident)? {
            TagValue::Float(v) => Some(*v),
            TagValue::Int(v) => Some(*v as f64),
            _ => None,
        }
    }
    /// A text tag.
    fn text(&self, ident: &str) -> Option<&str> {
        match self.value(ident)? {
            TagValue::Text(s) => Some(s),
            _ => None,
        }
    }
}

impl TagLookup for [HeaderTag] {
    fn value(&self, ident: &str) -> Option<&TagValue> {
        self.iter()
            .find(|t| t.ident == ident && t.index <= 0)
            .map(|t| &t.value)
    }
}
