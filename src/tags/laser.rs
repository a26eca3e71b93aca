//! The laser's repetition rate: what a recording states of it, each
//! statement checked against the range pulsed lasers of time-correlated
//! photon counting have and against the file's other statements, and what
//! a user gives (`--frequency`, Python's `frequency_hz`), checked against
//! the same range. One validation for every format and entry point.

/// Repetition rates a pulsed laser of a TCSPC measurement has, lowest and
/// highest (Hz): 10 kHz to 10 GHz.
pub const PLAUSIBLE_HZ: [f64; 2] = [1e4, 1e10];

/// Two statements within this fraction of each other say the same rate
/// (a rate meter's reading against the period a file times its records
/// with).
const AGREE: f64 = 0.01;

/// A rate in words: Hz, kHz, MHz or GHz as fits.
pub fn hz_text(hz: f64) -> String {
    let a = hz.abs();
    if !hz.is_finite() || (a != 0.0 && !(1.0..1e12).contains(&a)) {
        format!("{hz:e} Hz")
    } else if a >= 1e9 {
        format!("{:.6} GHz", hz * 1e-9)
    } else if a >= 1e6 {
        format!("{:.6} MHz", hz * 1e-6)
    } else if a >= 1e3 {
        format!("{:.3} kHz", hz * 1e-3)
    } else {
        format!("{hz} Hz")
    }
}

/// Why `hz` is no laser's repetition rate, in words; `None` when it may be
/// one.
pub fn implausible(hz: f64) -> Option<String> {
    let [lo, hi] = PLAUSIBLE_HZ;
    if hz.is_finite() && (lo..=hi).contains(&hz) {
        return None;
    }
    let hint = if hz.is_finite() && hz > 0.0 && hz < lo && hz * 1e6 >= lo && hz * 1e6 <= hi {
        format!(" (frequencies are in Hz: {} is {hz}e6)", hz_text(hz * 1e6))
    } else {
        String::new()
    };
    Some(format!(
        "{} lies outside the repetition rates of pulsed lasers ({} to {}){hint}",
        hz_text(hz),
        hz_text(lo),
        hz_text(hi)
    ))
}

/// A laser frequency a user gives, checked: the frequency, or why not.
pub fn given(hz: f64) -> Result<f64, String> {
    match implausible(hz) {
        None => Ok(hz),
        Some(why) => Err(format!("laser frequency {why}")),
    }
}

/// What a recording states of its laser: the frequency it implies (Hz),
/// when one statement is plausible and agrees with the others, and what
/// was found, in words.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Stated {
    /// The frequency, or `None`: the file states none that can be used.
    pub hz: Option<f64>,
    /// The statements left out or overruled, and why.
    pub notes: Vec<String>,
}

/// The laser frequency from a file's `statements` (name, value in Hz),
/// most authoritative first: statements outside [`PLAUSIBLE_HZ`] are left
/// out (and said); of the rest the first is used, and a later one that
/// disagrees with it by more than 1 % is said.
pub fn stated(statements: &[(&str, Option<f64>)]) -> Stated {
    let mut notes = Vec::new();
    let mut plausible = Vec::new();
    for &(name, value) in statements {
        let Some(hz) = value else { continue };
        match implausible(hz) {
            None => plausible.push((name, hz)),
            Some(why) => notes.push(format!(
                "the file's {name}, {why}, is not the laser's rate: left out"
            )),
        }
    }
    let hz = plausible.first().map(|&(_, hz)| hz);
    if let Some(&(first, hz)) = plausible.first() {
        for &(name, other) in &plausible[1..] {
            if (other - hz).abs() > AGREE * hz {
                notes.push(format!(
                    "the file's {name} ({}) contradicts its {first} ({}): the latter used",
                    hz_text(other),
                    hz_text(hz)
                ));
            }
        }
    }
    Stated { hz, notes }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rates_outside_the_lasers_range_are_refused_by_value() {
        assert_eq!(given(80e6), Ok(80e6));
        for bad in [
            0.0,
            -1.0,
            1.0,
            1e300,
            1e-300,
            f64::NAN,
            f64::INFINITY,
            2f64.powi(62),
        ] {
            let e = given(bad).unwrap_err();
            assert!(e.contains("outside the repetition rates"), "{e}");
        }
        // 80 Hz was meant as 80 MHz.
        assert!(given(80.0).unwrap_err().contains("80.000000 MHz is 80e6"));
    }

    #[test]
    fn statements_are_checked_against_the_range_and_each_other() {
        // The period that times the records against a meter's nonsense.
        let s = stated(&[("period", Some(78.02e6)), ("meter", Some(1.0))]);
        assert_eq!(s.hz, Some(78.02e6));
        assert!(
            s.notes[0].contains("meter, 1 Hz lies outside"),
            "{:?}",
            s.notes
        );
        let s = stated(&[("period", Some(78.02e6)), ("meter", Some(40e6))]);
        assert_eq!(s.hz, Some(78.02e6));
        assert!(
            s.notes[0].contains("contradicts its period"),
            "{:?}",
            s.notes
        );
        assert!(
            stated(&[("period", Some(78.02e6)), ("meter", Some(78.0e6))])
                .notes
                .is_empty()
        );
        // Nothing plausible: no frequency, every statement said.
        let s = stated(&[("max", Some(3.9e-42)), ("min", Some(-1.16e7))]);
        assert_eq!(s.hz, None);
        assert_eq!(s.notes.len(), 2);
        assert_eq!(stated(&[("max", None)]), Stated::default());
    }
}
