//! The setup text Becker & Hickl's SPCM software writes into `.set` files
//! (saved beside every `.spc` FIFO file) and into the setup section of
//! `.sdt` files: one parameter per entry, `#SP [SP_TAC_R,F,5.0e-08]`
//! (name, type letter, value), per B&H's `SPC_data_file_structure.h`
//! ("Setup": ASCII between `*SETUP` and `*END`, then a binary part after
//! `BIN_PARA_BEGIN:`). Only the ASCII entries are read.

use std::path::Path;

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

    /// The setup text of the file at `path`.
    pub fn read(path: &Path) -> std::io::Result<Self> {
        Ok(Self::parse(&std::fs::read(path)?))
    }

    /// The value of the first entry called `name`, as a finite number.
    pub fn number(&self, name: &str) -> Option<f64> {
        self.entries
            .iter()
            .find(|(n, _)| n == name)
            .and_then(|(_, v)| v.parse::<f64>().ok())
            .filter(|v| v.is_finite())
    }

    /// The TAC's time per ADC channel (s) for records of `channels` ADC
    /// channels: `SP_TAC_R / SP_TAC_G / channels`, and the words that say
    /// where it came from; `None` when the range or gain is missing or not
    /// positive.
    pub fn micro_unit_s(&self, channels: u32) -> Option<(f64, String)> {
        let range = self.number("SP_TAC_R").filter(|v| *v > 0.0)?;
        let gain = self.number("SP_TAC_G").filter(|v| *v > 0.0)?;
        Some((
            range / gain / f64::from(channels),
            format!(
                "SP_TAC_R {:.6} ns / SP_TAC_G {gain} / {channels} ADC channels",
                range * 1e9
            ),
        ))
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
        assert_eq!(s.number("SP_TAC_R"), Some(5.0e-8));
        assert_eq!(s.number("SP_TAC_G"), Some(4.0));
        assert_eq!(s.number("PR_PDEV"), None, "only SP_ entries");
        let (unit, words) = s.micro_unit_s(4096).unwrap();
        assert!((unit - 5.0e-8 / 4.0 / 4096.0).abs() < 1e-20);
        assert!(words.contains("50.000000 ns"), "{words}");
        assert_eq!(
            SetupText::parse(b"#SP [SP_TAC_R,F,nan]").micro_unit_s(4096),
            None
        );
    }
}
