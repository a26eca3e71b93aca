//! Which format a file is in: its first bytes (the format's magic) first,
//! its extension second. The extension decides only when the bytes cannot:
//! a file too short or unreadable (its reader then says why in its own
//! words), a special file the readers refuse, or a file about to be
//! written. Every reader that accepts more than one format asks here.

use std::io::Read;
use std::path::Path;

/// A file format scatterscope reads.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Format {
    /// OpenEXR (`.exr`).
    Exr,
    /// NumPy `.npy`.
    Npy,
    /// MATLAB v7.3 (HDF5) `.mat`.
    Mat,
    /// PicoQuant PTU (`.ptu`).
    Ptu,
    /// PicoQuant's legacy HydraHarp and PicoHarp files (`.pt3`, `.ht3`,
    /// `.pt2`, `.ht2`).
    PicoQuantLegacy,
    /// The project's tag file (`.sstags`).
    TagFile,
    /// Becker & Hickl FIFO file (`.spc`; no magic: by extension).
    BeckerHicklFifo,
    /// Becker & Hickl histogram file (`.sdt`; no magic: by extension).
    BeckerHicklHistogram,
    /// PNG.
    Png,
    /// JPEG.
    Jpeg,
    /// TIFF (`.tif`, `.tiff`; written as OME-TIFF, not read).
    Tiff,
    /// None of these.
    Unknown,
}

/// Magic bytes and the format they open, longest first where one is a
/// prefix of another.
const MAGICS: [(&[u8], Format); 11] = [
    (&[0x76, 0x2f, 0x31, 0x01], Format::Exr),
    (b"\x93NUMPY", Format::Npy),
    // MATLAB's v7.3 files open with a text header before the HDF5 data;
    // HDF5 files written by other tools (h5py) open with its signature.
    (b"MATLAB ", Format::Mat),
    (b"\x89HDF\r\n\x1a\n", Format::Mat),
    (b"PQTTTR\0\0", Format::Ptu),
    (b"HydraHarp", Format::PicoQuantLegacy),
    (b"PicoHarp 300", Format::PicoQuantLegacy),
    (b"TimeHarp", Format::PicoQuantLegacy),
    (crate::formats::sstags::MAGIC, Format::TagFile),
    (b"\x89PNG\r\n\x1a\n", Format::Png),
    (&[0xFF, 0xD8, 0xFF], Format::Jpeg),
];

impl Format {
    /// The format of the file at `path`: by its first bytes, else by its
    /// extension.
    pub fn of_file(path: &Path) -> Self {
        Self::of_magic(path).unwrap_or_else(|| Self::of_extension(path))
    }

    /// The format the extension of `path` names (case ignored): for files
    /// to be written, and files whose bytes do not say.
    pub fn of_extension(path: &Path) -> Self {
        let ext = path
            .extension()
            .map(|e| e.to_string_lossy().to_ascii_lowercase())
            .unwrap_or_default();
        match ext.as_str() {
            "exr" => Self::Exr,
            "npy" => Self::Npy,
            "mat" => Self::Mat,
            "ptu" => Self::Ptu,
            "pt3" | "ht3" | "pt2" | "ht2" => Self::PicoQuantLegacy,
            "sstags" => Self::TagFile,
            "spc" => Self::BeckerHicklFifo,
            "sdt" => Self::BeckerHicklHistogram,
            "png" => Self::Png,
            "jpg" | "jpeg" => Self::Jpeg,
            "tif" | "tiff" => Self::Tiff,
            _ => Self::Unknown,
        }
    }

    /// The format the first bytes of a regular file at `path` open with;
    /// `None` for anything else (missing, special, short, unknown bytes).
    fn of_magic(path: &Path) -> Option<Self> {
        if !std::fs::metadata(path).ok()?.is_file() {
            return None;
        }
        let mut head = Vec::with_capacity(16);
        std::fs::File::open(path)
            .ok()?
            .take(16)
            .read_to_end(&mut head)
            .ok()?;
        MAGICS
            .iter()
            .find(|(magic, _)| head.starts_with(magic))
            .map(|&(_, format)| format)
    }
}

/// Whether `path` is one of the project's tag files (its magic, else its
/// `.sstags` extension).
pub fn is_tag_file(path: &Path) -> bool {
    Format::of_file(path) == Format::TagFile
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_bytes_decide_before_the_extension() {
        let dir = tempfile::tempdir().unwrap();
        let cases: [(&[u8], Format); 8] = [
            (&[0x76, 0x2f, 0x31, 0x01, 2, 0, 0, 0], Format::Exr),
            (b"\x93NUMPY\x01\x00", Format::Npy),
            (b"MATLAB 7.3 MAT-file, Platform", Format::Mat),
            (b"\x89HDF\r\n\x1a\n\0\0", Format::Mat),
            (b"PQTTTR\0\x001.0.00\0\0", Format::Ptu),
            (b"PicoHarp 300\0\0\0\0", Format::PicoQuantLegacy),
            (b"SSTAGS01", Format::TagFile),
            (b"\x89PNG\r\n\x1a\n", Format::Png),
        ];
        for (bytes, format) in cases {
            // A misleading extension: the bytes win.
            let path = dir.path().join("file.jpg");
            std::fs::write(&path, bytes).unwrap();
            assert_eq!(Format::of_file(&path), format, "{bytes:?}");
        }
    }

    #[test]
    fn the_extension_decides_when_the_bytes_cannot() {
        let dir = tempfile::tempdir().unwrap();
        let missing = dir.path().join("missing.NPY");
        assert_eq!(Format::of_file(&missing), Format::Npy);
        let short = dir.path().join("short.ht3");
        std::fs::write(&short, b"Hy").unwrap();
        assert_eq!(Format::of_file(&short), Format::PicoQuantLegacy);
        assert_eq!(Format::of_file(dir.path()), Format::Unknown);
        let other = dir.path().join("notes.txt");
        std::fs::write(&other, b"plain text, no magic").unwrap();
        assert_eq!(Format::of_file(&other), Format::Unknown);
        assert_eq!(Format::of_extension(Path::new("a.Exr")), Format::Exr);
    }
}
