//! Flags renamed: the old spelling still works. The command line is
//! rewritten to the new names before it is parsed, with a note on stderr
//! for each old name given; one table for every command.

use std::ffi::OsString;

/// One renamed flag.
struct Renamed {
    /// The command it belongs to (`None`: every command that has it).
    command: Option<&'static str>,
    old: &'static str,
    new: &'static str,
    /// Said after the new name in the note.
    why: &'static str,
}

const fn any(old: &'static str, new: &'static str) -> Renamed {
    Renamed {
        command: None,
        old,
        new,
        why: "",
    }
}

const fn of(
    command: &'static str,
    old: &'static str,
    new: &'static str,
    why: &'static str,
) -> Renamed {
    Renamed {
        command: Some(command),
        old,
        new,
        why,
    }
}

const RENAMED: &[Renamed] = &[
    any("--bin-ps", "--bin-width"),
    any("--irf-bin-ps", "--irf-bin-width"),
    of(
        "hidden",
        "--medium",
        "--material",
        " (the material file; --medium is the physics flags' diffusion model)",
    ),
    of(
        "calibrate-slab",
        "--mu-s",
        "--mu-s-reduced",
        " (the reduced scattering coefficient mu_s')",
    ),
    of(
        "calibrate-slab",
        "--offset-cm",
        "--detector-offset",
        " (the detector's distance from the axis, cm)",
    ),
    of("acquire", "--raw", "--tags", ""),
    of(
        "acquire",
        "--offset",
        "--t3-offset",
        " (a PicoQuant device's T3 offset)",
    ),
    of(
        "acquire",
        "--replay",
        "--mock-replay",
        " (the mock's batches drawn once and replayed; --device replay:FILE plays a recording)",
    ),
    of(
        "acquire",
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
            .find(|r| r.old == flag && r.command.is_none_or(|c| Some(c) == command.as_deref()));
        match renamed {
            Some(r) => {
                let whose = r.command.map_or(String::new(), |c| format!("{c}'s "));
                let note = format!(
                    "note: {whose}{} is now {}{}; the old name still works",
                    r.old, r.new, r.why
                );
                if !notes.contains(&note) {
                    notes.push(note);
                }
                out.push(match value {
                    Some(v) => format!("{}={v}", r.new).into(),
                    None => r.new.into(),
                });
            }
            None => out.push(arg),
        }
    }
    (out, notes)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn spell(args: &[&str]) -> (Vec<String>, Vec<String>) {
        let (out, notes) = new_spellings(args.iter().map(OsString::from));
        let out = out.into_iter().map(|a| a.into_string().unwrap()).collect();
        (out, notes)
    }

    #[test]
    fn old_names_of_the_command_given_are_rewritten_with_a_note() {
        let (out, notes) = spell(&[
            "scatterscope",
            "--memory-limit",
            "1GiB",
            "acquire",
            "--offset=10ns",
            "--replay",
            "3",
            "--bin-ps",
            "16",
        ]);
        assert_eq!(
            out,
            [
                "scatterscope",
                "--memory-limit",
                "1GiB",
                "acquire",
                "--t3-offset=10ns",
                "--mock-replay",
                "3",
                "--bin-width",
                "16"
            ]
        );
        assert_eq!(notes.len(), 3, "{notes:?}");
        assert!(notes[0].starts_with("note: acquire's --offset is now --t3-offset"));
        assert!(notes[2].starts_with("note: --bin-ps is now --bin-width"));
    }

    #[test]
    fn another_commands_flag_of_that_name_and_values_are_left_alone() {
        // --medium is the physics flags' diffusion model outside `hidden`.
        let args = [
            "scatterscope",
            "simulate",
            "--medium",
            "slab",
            "--out",
            "--offset",
        ];
        let (out, notes) = spell(&args);
        assert_eq!(out, args);
        assert!(notes.is_empty());
        let (out, _) = spell(&["scatterscope", "hidden", "--", "--medium"]);
        assert_eq!(out.last().unwrap(), "--medium", "after --, a positional");
    }
}
