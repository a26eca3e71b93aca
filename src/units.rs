//! Quantities as users write them, in flags, setting files and capture
//! labels alike: a number and a unit, exponents allowed (`1e2cm`,
//! `2.5e-1 in`, `0.004 ns`, `500ms`, `4GiB`). One reading for every kind:
//! the unit starts at the first letter that is not an exponent's `e`, and
//! its size comes from the kind's table. Lengths come out in cm (the
//! physics' unit), times in ps, durations as [`Duration`], sizes in bytes.

use std::time::Duration;

/// Centimetres in a metre: the one factor between the physics' lengths
/// (cm) and the scans' and volumes' ([`crate::confocal`], m).
pub const CM_PER_M: f64 = 100.0;

/// The units of a length and their size in cm.
pub const LENGTH_UNITS: [(&str, f64); 5] = [
    ("um", 1e-4),
    ("mm", 0.1),
    ("cm", 1.0),
    ("m", CM_PER_M),
    ("in", 2.54),
];

/// The units of a time and their size in ps.
pub const TIME_UNITS: [(&str, f64); 4] = [("fs", 1e-3), ("ps", 1.0), ("ns", 1e3), ("us", 1e6)];

/// The units of a duration and their size in s.
const DURATION_UNITS: [(&str, f64); 4] = [("ms", 1e-3), ("s", 1.0), ("m", 60.0), ("h", 3600.0)];

/// The units of a size (matched in lower case) and their size in bytes:
/// decimal `k`, `M`, `G`, `T` (with or without `B`) and binary `KiB` to
/// `TiB`.
const SIZE_UNITS: [(&str, f64); 13] = [
    ("b", 1.0),
    ("k", 1e3),
    ("kb", 1e3),
    ("m", 1e6),
    ("mb", 1e6),
    ("g", 1e9),
    ("gb", 1e9),
    ("t", 1e12),
    ("tb", 1e12),
    ("kib", 1024.0),
    ("mib", 1048576.0),
    ("gib", 1073741824.0),
    ("tib", 1099511627776.0),
];

/// What is wrong with a quantity as written.
enum Fault<'a> {
    /// The part before the unit is not a number.
    NotANumber(&'a str),
    /// The unit is not in the kind's table.
    UnknownUnit(&'a str),
}

/// `text` read against `table`: its number and, when it names one, the
/// size of its unit.
fn read<'a>(text: &'a str, table: &[(&str, f64)]) -> Result<(f64, Option<f64>), Fault<'a>> {
    let t = text.trim();
    let split = t
        .find(|c: char| c.is_ascii_alphabetic() && c != 'e' && c != 'E')
        .unwrap_or(t.len());
    let (number, unit) = (t[..split].trim(), t[split..].trim());
    let value: f64 = number.parse().map_err(|_| Fault::NotANumber(number))?;
    if unit.is_empty() {
        return Ok((value, None));
    }
    table
        .iter()
        .find(|(name, _)| *name == unit)
        .map(|(_, size)| (value, Some(*size)))
        .ok_or(Fault::UnknownUnit(unit))
}

/// What a length written without a unit means.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BareNumber {
    /// Centimetres (the physics settings' unit).
    Cm,
    /// Refused: the text must name its unit (a capture's thickness, a
    /// scan's size, where a bare number is a guess).
    Refused,
}

/// The length `text` gives, in cm; the error names the text and what is
/// wrong with it.
pub fn parse_cm(text: &str, bare: BareNumber) -> Result<f64, String> {
    let names = || LENGTH_UNITS.map(|(u, _)| u).join(", ");
    let (value, scale) = read(text, &LENGTH_UNITS).map_err(|fault| match fault {
        Fault::NotANumber(number) => format!(
            "length `{text}`: `{number}` is not a number (write a number and a unit: {})",
            names()
        ),
        Fault::UnknownUnit(u) => format!("length `{text}`: unknown unit `{u}` (use {})", names()),
    })?;
    let scale = match (scale, bare) {
        (Some(scale), _) => scale,
        (None, BareNumber::Cm) => 1.0,
        (None, BareNumber::Refused) => {
            return Err(format!("length `{text}` needs a unit: {}", names()));
        }
    };
    let cm = value * scale;
    if !cm.is_finite() {
        return Err(format!("length `{text}` is not finite"));
    }
    Ok(cm)
}

/// A length of something real (a slab, a scan, a depth): a unit named,
/// and more than zero.
pub fn parse_positive_cm(text: &str) -> Result<f64, String> {
    let cm = parse_cm(text, BareNumber::Refused)?;
    if cm > 0.0 {
        Ok(cm)
    } else {
        Err(format!("length `{text}` must be more than zero"))
    }
}

/// [`parse_positive_cm`] in metres, the unit of the hidden-volume methods
/// ([`crate::confocal`]).
pub fn parse_positive_m(text: &str) -> Result<f64, String> {
    parse_positive_cm(text).map(|cm| cm / CM_PER_M)
}

/// [`parse_cm`] with bare numbers in cm: the value parser of the physics
/// flags.
pub fn parse_cm_or_bare(text: &str) -> Result<f64, String> {
    parse_cm(text, BareNumber::Cm)
}

/// A time with an optional unit (`fs`, `ps`, `ns`, `us`), in ps; plain
/// numbers are ps.
pub fn parse_ps(s: &str) -> Result<f64, String> {
    let (value, scale) = read(s, &TIME_UNITS).map_err(|fault| match fault {
        Fault::NotANumber(_) => format!("`{s}` is not a number with an optional unit"),
        Fault::UnknownUnit(unit) => format!(
            "unknown unit `{unit}` in `{s}` (use {}; default ps)",
            TIME_UNITS.map(|(u, _)| u).join(", ")
        ),
    })?;
    Ok(value * scale.unwrap_or(1.0))
}

/// A duration with its unit: `ms`, `s` (default), `m` or `h`; finite and
/// not negative.
pub fn parse_duration(s: &str) -> Result<Duration, String> {
    let (v, scale) = read(s, &DURATION_UNITS)
        .map_err(|_| format!("`{s}` is not a duration (e.g. 10s, 500ms, 2m)"))?;
    if !(v >= 0.0 && v.is_finite()) {
        return Err(format!("`{s}`: a duration must be finite and not negative"));
    }
    Duration::try_from_secs_f64(v * scale.unwrap_or(1.0))
        .map_err(|_| format!("`{s}`: longer than any clock counts"))
}

/// A size: a number of bytes, or with a unit (`k`/`kB`, `M`/`MB`,
/// `G`/`GB`, `T`/`TB` decimal; `KiB`, `MiB`, `GiB`, `TiB` binary; any
/// case); at least one byte.
pub fn parse_size(s: &str) -> Result<u64, String> {
    let lower = s.to_ascii_lowercase();
    let (v, scale) = read(&lower, &SIZE_UNITS).map_err(|fault| match fault {
        Fault::NotANumber(number) => format!("`{number}` is not a number of bytes"),
        Fault::UnknownUnit(other) => {
            format!("unknown unit `{other}` (use B, MB, GB, MiB, GiB, ...)")
        }
    })?;
    let bytes = v * scale.unwrap_or(1.0);
    if bytes.is_finite() && bytes >= 1.0 && bytes < u64::MAX as f64 {
        Ok(bytes as u64)
    } else {
        Err("a memory limit must be at least one byte".into())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_unit_exponents_and_spaces() {
        let close = |a: f64, b: f64| (a - b).abs() <= 1e-12 * b.abs().max(1.0);
        for (text, cm) in [
            ("1in", 2.54),
            ("25.4mm", 2.54),
            ("0.5 m", 50.0),
            ("1e2cm", 100.0),
            ("2.5e-1 in", 0.635),
            ("300um", 0.03),
            ("30mm", 3.0),
            ("-2cm", -2.0),
        ] {
            assert!(
                close(parse_cm(text, BareNumber::Refused).unwrap(), cm),
                "{text}"
            );
        }
        assert_eq!(parse_cm("3", BareNumber::Cm), Ok(3.0));
        assert_eq!(parse_cm("1E1", BareNumber::Cm), Ok(10.0));
    }

    #[test]
    fn errors_name_the_text_and_the_fault() {
        let err = |t: &str, bare| parse_cm(t, bare).unwrap_err();
        assert!(err("3", BareNumber::Refused).contains("`3` needs a unit: um, mm, cm, m, in"));
        assert!(err("3ft", BareNumber::Cm).contains("unknown unit `ft`"));
        assert!(
            err("abc", BareNumber::Cm).contains("`abc`")
                && err("abc", BareNumber::Cm).contains("not a number")
        );
        assert!(err("1e400cm", BareNumber::Cm).contains("not finite"));
        for bad in ["-1cm", "0in"] {
            assert!(
                parse_positive_cm(bad)
                    .unwrap_err()
                    .contains("more than zero"),
                "{bad}"
            );
        }
        for bad in ["nan", "inf", "xcm", ""] {
            assert!(parse_cm(bad, BareNumber::Cm).is_err(), "{bad} accepted");
        }
    }

    #[test]
    fn times_take_their_units_and_plain_numbers_are_ps() {
        assert_eq!(parse_ps("4"), Ok(4.0));
        assert_eq!(parse_ps("4ps"), Ok(4.0));
        assert_eq!(parse_ps("0.004 ns"), Ok(4.0));
        assert_eq!(parse_ps("1e-3ns"), Ok(1.0));
        assert!(
            parse_ps("4 parsecs")
                .unwrap_err()
                .contains("unknown unit `parsecs`")
        );
    }

    #[test]
    fn sizes_parse_with_their_units_and_bad_ones_are_named() {
        assert_eq!(parse_size("4GiB"), Ok(4 << 30));
        assert_eq!(parse_size("500MB"), Ok(500_000_000));
        assert_eq!(parse_size("1.5k"), Ok(1500));
        assert_eq!(parse_size("123"), Ok(123));
        assert!(parse_size("4 parsecs").unwrap_err().contains("parsecs"));
        assert!(parse_size("0").is_err());
        assert!(parse_size("NaN GB").is_err());
        assert!(parse_size("1e30 TB").is_err());
    }

    #[test]
    fn durations_take_their_units_and_refuse_the_rest() {
        assert_eq!(parse_duration("10s"), Ok(Duration::from_secs(10)));
        assert_eq!(parse_duration("500ms"), Ok(Duration::from_millis(500)));
        assert_eq!(parse_duration("2m"), Ok(Duration::from_secs(120)));
        assert_eq!(parse_duration("1e3ms"), Ok(Duration::from_secs(1)));
        assert_eq!(parse_duration(" 3 "), Ok(Duration::from_secs(3)));
        assert!(parse_duration("5x").unwrap_err().contains("not a duration"));
        assert!(parse_duration("-1s").unwrap_err().contains("not negative"));
    }
}
