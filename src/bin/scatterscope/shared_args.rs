//! What several commands share: the physics flags resolved, named
//! choices, progress lines, flags as given.

use indicatif::{ProgressBar, ProgressStyle};
use scatterscope::config::PhysicsOverrides;
use scatterscope::physics::Setup;

pub use scatterscope::named::choice;

/// The setup the physics flags give, printing what resolving them noted
/// (a reference recording's instrument response).
pub fn resolve(physics: &PhysicsOverrides) -> anyhow::Result<Setup> {
    let (setup, notes) = physics.resolve_noted(None)?;
    for note in notes {
        println!("{note}");
    }
    Ok(setup)
}

/// A progress display: a bar over `millis` when the end is known, else a
/// spinner; `{msg}` is the caller's.
pub fn progress(millis: Option<u128>) -> ProgressBar {
    let (bar, template) = match millis {
        Some(ms) => (
            ProgressBar::new(ms as u64),
            "{bar:30} {elapsed}/{duration} {msg}",
        ),
        None => (ProgressBar::new_spinner(), "{spinner} {elapsed} {msg}"),
    };
    bar.with_style(ProgressStyle::with_template(template).expect("template"))
}

/// The flags given on the command line to `command` (as parsed: new
/// spellings, one `--flag=value` per value), leaving out the arguments
/// whose ids `skip` names and the positional ones.
pub fn given_flags(
    matches: &clap::ArgMatches,
    command: &clap::Command,
    skip: &[&str],
) -> Vec<String> {
    let mut out = Vec::new();
    for arg in command.get_arguments() {
        let id = arg.get_id().as_str();
        let given = matches.value_source(id) == Some(clap::parser::ValueSource::CommandLine);
        let Some(long) = arg.get_long().filter(|_| given && !skip.contains(&id)) else {
            continue;
        };
        match arg.get_action().takes_values() {
            true => out.extend(
                matches
                    .get_raw(id)
                    .into_iter()
                    .flatten()
                    .map(|v| format!("--{long}={}", v.to_string_lossy())),
            ),
            false => out.push(format!("--{long}")),
        }
    }
    out
}

/// Says on stderr which of `names`, given to `flag`, are old spellings of
/// a fitted parameter, and the new ones (the old still work).
pub fn note_renamed_parameters(flag: &str, names: &[String]) {
    for (old, new) in scatterscope::calibrate::renamed_in(names) {
        eprintln!("note: {flag} `{old}` is now `{new}`; the old name still works");
    }
}
