//! Lengths as users write them, in flags, setting files and capture
//! labels alike: a number with a unit (`um`, `mm`, `cm`, `m`, `in`),
//! exponents allowed (`1e2cm`, `2.5e-1 in`). The one parser behind every
//! length the library reads.

/// The units of a length and their size in cm.
pub const UNITS: [(&str, f64); 5] = [
    ("um", 1e-4),
    ("mm", 0.1),
    ("cm", 1.0),
    ("m", 100.0),
    ("in", 2.54),
];

/// What a number written without a unit means.
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
    let t = text.trim();
    // A unit starts at the first letter that is not an exponent's `e`.
    let split = t
        .find(|c: char| c.is_ascii_alphabetic() && c != 'e' && c != 'E')
        .unwrap_or(t.len());
    let (number, unit) = (t[..split].trim(), t[split..].trim());
    let names = || UNITS.map(|(u, _)| u).join(", ");
    let value: f64 = number.parse().map_err(|_| {
        format!(
            "length `{text}`: `{number}` is not a number (write a number and a unit: {})",
            names()
        )
    })?;
    let scale = match (unit, bare) {
        ("", BareNumber::Cm) => 1.0,
        ("", BareNumber::Refused) => {
            return Err(format!("length `{text}` needs a unit: {}", names()));
        }
        (u, _) => UNITS
            .iter()
            .find(|(name, _)| *name == u)
            .map(|(_, cm)| *cm)
            .ok_or_else(|| format!("length `{text}`: unknown unit `{u}` (use {})", names()))?,
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

/// [`parse_cm`] with bare numbers in cm: the value parser of the physics
/// flags.
pub fn parse_cm_or_bare(text: &str) -> Result<f64, String> {
    parse_cm(text, BareNumber::Cm)
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
}
