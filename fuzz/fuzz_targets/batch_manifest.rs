//! Arbitrary text as a batch manifest: an error naming the manifest, or
//! jobs that each have a unique plain folder name, a runnable command, an
//! absolute input and a time limit that parses.
#![no_main]
use libfuzzer_sys::fuzz_target;
use scatterscope::batch::parse_manifest;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    let path = std::path::Path::new("/fuzz/manifest.toml");
    match parse_manifest(path, text) {
        Err(e) => assert!(e.to_string().contains("manifest.toml"), "{e}"),
        Ok(jobs) => {
            let mut names = std::collections::HashSet::new();
            for job in &jobs {
                assert!(names.insert(job.name.clone()), "unique names");
                assert!(!job.name.contains('/') && !job.name.starts_with('.'));
                assert!(!job.command.is_empty() && job.command != "batch");
                assert!(job.input.as_deref().is_none_or(|i| i.starts_with('/')));
                if let Some(t) = &job.timeout {
                    scatterscope::units::parse_duration(t).expect("a checked time limit");
                }
            }
        }
    }
});
