//! Flags renamed: the old spelling still works. The command line is
//! rewritten to the new names before it is parsed, with a note on stderr
//! for each old name given; one table for every command.

use std::ffi::OsString;

/// The renamed flags: the command each belongs to (`None`: every command
/// that has it), the old name, the new one, and what the note says after
/// the new name.
type Renamed = (
    Option<&'static str>,
    &'static str,
    &'static str,
    &'static str,
);

const RENAMED: &[Renamed] = &[
    (None, "--bin-ps", "--bin-width", ""),
    (None, "--irf-bin-ps", "--irf-bin-width", ""),
    (
        Some("hidden"),
        "--medium",
        "--material",
        " (the material file; --medium is the physics flags' diffusion model)",
    ),
    (
        Some("calibrate-slab"),
        "--mu-s",
        "--mu-s-reduced",
        " (the reduced scattering coefficient mu_s')",
    ),
    (
        Some("calibrate-slab"),
        "--offset-cm",
        "--detector-offset",
        " (the detector's distance from the axis, cm)",
    ),
    (Some("acquire"), "--raw", "--tags", ""),
    (
        Some("acquire"),
        "--offset",
        "--t3-offset",
        " (a PicoQuant device's T3 offset)",
    ),
    (
        Some("acquire"),
        "--replay",
        "--mock-replay",
        " (the mock's batches drawn once and replayed; --device replay:FILE plays a recording)",
    ),
    (
        Some("acquire"),
        "--resolution",
        "--micro-time-unit",
        " (our own devices' micro-time unit; --binning sets a PicoQuant device's)",
    ),
];

/// Global flags that take a value (the command is the first word that is
/// neither a flag nor such a value).
const GLOBAL_WITH_VALUE: &[&str] = &["--memory-limit"];

/// `args` (the program name first) with every old flag name of the
/// command given replaced by its new one, and the notes to print.
pub fn new_spellings(args: impl IntoIterator<Item = OsString>) -> (Vec<OsString>, Vec<String>) {
    let mut out: Vec<OsString> = Vec::new();
    let mut notes = Vec::new();
    let mut command: Option<String> = None;
    let mut after_global = false;
    let mut positional_only = false;
    for (i, arg) in args.into_iter().enumerate() {
        let Some(text) = arg.to_str().map(str::to_owned) else {
            out.push(arg);
            continue;
        };
        if i == 0 || positional_only {
            out.push(arg);
            continue;
        }
        if text == "--" {
            positional_only = true;
            out.push(arg);
            continue;
        }
        if command.is_none() {
            if !text.starts_with('-') && !after_global {
                command = Some(text.clone());
            }
            after_global = GLOBAL_WITH_VALUE.contains(&text.as_str());
            out.push(arg);
            continue;
        }
        let (flag, value) = match text.split_once('=') {
            Some((f, v)) => (f, Some(v)),
            None => (text.as_str(), None),
        };
        let renamed = RENAMED
            .iter()
            .find(|(of, old, ..)| *old == flag && of.is_none_or(|c| Some(c) == command.as_deref()));
        match renamed {
            Some(&(of, old, new, why)) => {
                let whose = of.map_or(String::new(), |c| format!("{c}'s "));
                let note =
                    format!("note: {whose}{old} is now {new}{why}; the old name still works");
                if !notes.contains(&note) {
                    notes.push(note);
                }
                out.push(match value {
                    Some(v) => format!("{new}={v}").into(),
                    None => new.into(),
                });
            }
            None => out.push(arg),
        }
    }
    (out, notes)
}
