//! The setup text Becker & Hickl's SPCM software writes into `.set` files
//! (saved beside every `.spc` FIFO file) and into the setup section of
//! `.sdt` files: one parameter per entry, `#SP [SP_TAC_R,F,5.0e-08]`
//! (name, type letter, value), per B&H's `SPC_data_file_structure.h`
//! ("Setup": ASCII between `*SETUP` and `*END`, then a binary part after
//! `BIN_PARA_BEGIN:`). Only the ASCII entries are read.

use std::io::Read;
use std::path::Path;

/// Largest setup file read: SPCM's are tens of kilobytes (the ASCII
/// entries, then the binary panel settings); a larger file is not one.
pub const MAX_SETUP_BYTES: u64 = 16 << 20;

/// Micro-time units (ps) a time tagger can have: from 1 fs (no TCSPC card
/// resolves less) to 1 ms (a TAC range of seconds per channel is no
/// setting); anything outside is a damaged or mistyped value.
pub const MICRO_UNIT_PS: (f64, f64) = (1e-3, 1e9);

/// Refuses a micro-time unit of `ps` outside [`MICRO_UNIT_PS`], saying
/// where it came from (`from`).
pub fn check_micro_unit_ps(ps: f64, from: &str) -> Result<f64, String> {
    let (lo, hi) = MICRO_UNIT_PS;
    if ps.is_finite() && (lo..=hi).contains(&ps) {
        Ok(ps)
    } else {
        Err(format!(
            "micro-time unit {ps} ps ({from}) is not a time tagger's: give {lo} ps to {hi} ps"
        ))
    }
}

/// The `[NAME,TYPE,VALUE]` entries of a setup text, in file order.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SetupText {
    entries: Vec<(String, String)>,
}

impl SetupText {
    /// The entries of `bytes` up to the binary part (`BIN_PARA_BEGIN`), if
    /// any; bytes that are not entries are skipped.
    pub fn parse(bytes: &[u8]) -> Self {
        let end = find(bytes, b"BIN_PARA_BEGIN").unwrap_or(bytes.len());
        let text = String::from_utf8_lossy(&bytes[..end]);
        let entries = text
            .split('[')
            .skip(1)
            .filter_map(|chunk| {
                let inner = chunk.split(']').next()?;
                let mut fields = inner.splitn(3, ',');
                let (name, kind, value) = (fields.next()?, fields.next()?, fields.next()?);
                let name = name.trim();
                (name.starts_with("SP_") && kind.trim().len() == 1)
                    .then(|| (name.to_string(), value.trim().to_string()))
            })
            .collect();
        Self { entries }
    }

    /// The setup text of the file at `path`, which must be a regular file
    /// of at most [`MAX_SETUP_BYTES`] (read only that far).
    pub fn read(path: &Path) -> std::io::Result<Self> {
        let (file, meta) = crate::files::open_regular(path, "setup file")?;
        if meta.len() > MAX_SETUP_BYTES {
            return Err(std::io::Error::new(
                std::io::ErrorKind::InvalidData,
                format!(
                    "a setup file of {} bytes: SPCM's setup files are tens of kilobytes, so this is not one (read up to {MAX_SETUP_BYTES} bytes)",
                    meta.len()
                ),
            ));
        }
        let mut bytes = Vec::new();
        file.take(MAX_SETUP_BYTES).read_to_end(&mut bytes)?;
        Ok(Self::parse(&bytes))
    }

    /// The value of the entry called `name`, as a finite number; an entry
    /// given twice with different values is an error that names both.
    pub fn number(&self, name: &str) -> Result<Option<f64>, String> {
        let mut values = self
            .entries
            .iter()
            .filter(|(n, _)| n == name)
            .map(|(_, v)| v);
        let Some(first) = values.next() else {
            return Ok(None);
        };
        if let Some(other) = values.find(|v| v != &first) {
            return Err(format!(
                "{name} is given twice, as {first} and as {other}: which one the card ran with is unknown"
            ));
        }
        Ok(first.parse::<f64>().ok().filter(|v| v.is_finite()))
    }

    /// The TAC's time per ADC channel (s) for records of `channels` ADC
    /// channels: `SP_TAC_R / SP_TAC_G / channels`, and the words that say
    /// where it came from; `None` when the range or gain is missing or not
    /// positive; an error for an entry given twice or a unit no time tagger
    /// has.
    pub fn micro_unit_s(&self, channels: u32) -> Result<Option<(f64, String)>, String> {
        let range = self.number("SP_TAC_R")?.filter(|v| *v > 0.0);
        let gain = self.number("SP_TAC_G")?.filter(|v| *v > 0.0);
        let (Some(range), Some(gain)) = (range, gain) else {
            return Ok(None);
        };
        let words = format!(
            "SP_TAC_R {:.6} ns / SP_TAC_G {gain} / {channels} ADC channels",
            range * 1e9
        );
        let ps = check_micro_unit_ps(range / gain / f64::from(channels) * 1e12, &words)?;
        Ok(Some((ps * 1e-12, words)))
    }
}

/// Where `needle` first starts in `haystack`.
pub(crate) fn find(haystack: &[u8], needle: &[u8]) -> Option<usize> {
    haystack.windows(needle.len()).position(|w| w == needle)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn entries_are_read_up_to_the_binary_part() {
        let text = b"*SETUP\r\nSYS_PARA_BEGIN:\r\n#SP [SP_TAC_R,F,5.0e-08]\r\n#SP [SP_TAC_G,I,4]\r\n#SP [SP_ADC_RE,I,256]\r\n#PR [PR_PDEV,I,18]\r\nBIN_PARA_BEGIN:\0[SP_TAC_G,I,9]";
        let s = SetupText::parse(text);
        assert_eq!(s.number("SP_TAC_R"), Ok(Some(5.0e-8)));
        assert_eq!(s.number("SP_TAC_G"), Ok(Some(4.0)));
        assert_eq!(s.number("PR_PDEV"), Ok(None), "only SP_ entries");
        let (unit, words) = s.micro_unit_s(4096).unwrap().unwrap();
        assert!((unit - 5.0e-8 / 4.0 / 4096.0).abs() < 1e-20);
        assert!(words.contains("50.000000 ns"), "{words}");
        assert_eq!(
            SetupText::parse(b"#SP [SP_TAC_R,F,nan]").micro_unit_s(4096),
            Ok(None)
        );
    }

    #[test]
    fn a_field_twice_and_an_implausible_unit_are_refused_by_name() {
        let twice = SetupText::parse(b"[SP_TAC_R,F,5e-8] [SP_TAC_G,I,4] [SP_TAC_G,I,8]");
        let e = twice.micro_unit_s(4096).unwrap_err();
        assert!(e.contains("SP_TAC_G is given twice, as 4 and as 8"), "{e}");
        // The same value twice is one setting.
        let same = SetupText::parse(b"[SP_TAC_R,F,5e-8] [SP_TAC_G,I,4] [SP_TAC_G,I,4]");
        assert!(same.micro_unit_s(4096).unwrap().is_some());
        let huge = SetupText::parse(b"[SP_TAC_R,F,1e300] [SP_TAC_G,I,1]");
        let e = huge.micro_unit_s(4096).unwrap_err();
        assert!(
            e.contains("is not a time tagger's") && e.contains("SP_TAC_R"),
            "{e}"
        );
        let tiny = SetupText::parse(b"[SP_TAC_R,F,1e-300] [SP_TAC_G,I,1]");
        assert!(tiny.micro_unit_s(4096).is_err());
    }
}
