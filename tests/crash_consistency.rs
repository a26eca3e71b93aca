//! Crash consistency: `convert`, `bin`, `batch` and `acquire` (the mock
//! and the PicoQuant stand-in) killed with SIGKILL at random moments.
//! After every kill, each file in the output folder is either complete and
//! valid under its final name, or an unfinished temporary
//! (`.NAME.partial-PID-N`) that the project's readers refuse or flag, and
//! the inputs are byte for byte what they were. The PTU files are checked
//! with ptufile too (an ignored test, run in CI).

#[path = "common/command.rs"]
mod command;
use command::run;
#[path = "common/pydeps.rs"]
mod pydeps;
#[path = "common/standin.rs"]
mod standin;

use std::collections::hash_map::DefaultHasher;
use std::hash::{Hash, Hasher};
use std::path::{Path, PathBuf};
use std::process::Stdio;
use std::time::{Duration, Instant};

use scatterscope::files::output::is_partial_name;
use scatterscope::formats::image::read_image;
use scatterscope::formats::picoquant;
use scatterscope::formats::picoquant::writer::write_synthetic_t3;
use scatterscope::formats::sstags::TagFile;
use scatterscope::stack::Stack;

/// The inputs every command reads, made once.
struct Inputs {
    dir: tempfile::TempDir,
    ptu: PathBuf,
    tags: PathBuf,
    manifest: PathBuf,
}

impl Inputs {
    fn make() -> Self {
        let dir = tempfile::tempdir().unwrap();
        let ptu = dir.path().join("in.ptu");
        write_synthetic_t3(&ptu, 4_000_000).unwrap();
        let tags = dir.path().join("in.sstags");
        let o = run(&[
            "acquire",
            "--device",
            "mock",
            "--duration",
            "300ms",
            "--size",
            "6",
            "--tags",
            tags.to_str().unwrap(),
            "--out",
            dir.path().join("made").to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let manifest = dir.path().join("jobs.toml");
        let mut m = String::new();
        for i in 0..3 {
            m.push_str(&format!(
                "[[job]]\nname = \"sim-{i}\"\ncommand = \"simulate\"\nargs = [\"--scene\", \"disks\", \"--size\", \"48\", \"--seed\", \"{i}\"]\n\n"
            ));
        }
        m.push_str("[[job]]\nname = \"bin\"\ncommand = \"bin\"\ninput = \"in.ptu\"\n");
        std::fs::write(&manifest, m).unwrap();
        Self {
            dir,
            ptu,
            tags,
            manifest,
        }
    }

    fn files(&self) -> [&Path; 3] {
        [&self.ptu, &self.tags, &self.manifest]
    }
}

fn digest(path: &Path) -> u64 {
    let mut h = DefaultHasher::new();
    std::fs::read(path).unwrap().hash(&mut h);
    h.finish()
}

/// The commands, each writing into `out`.
fn commands(inputs: &Inputs, out: &Path) -> Vec<(&'static str, Vec<String>)> {
    std::fs::create_dir_all(out).unwrap();
    let s = |p: &Path| p.to_str().unwrap().to_string();
    let o = |name: &str| s(&out.join(name));
    let lib = standin::standin_library();
    vec![
        (
            "convert ptu",
            vec!["convert".into(), s(&inputs.ptu), "--out".into(), o("c.ptu")],
        ),
        (
            "convert tags",
            vec![
                "convert".into(),
                s(&inputs.tags),
                "--out".into(),
                o("t.ptu"),
            ],
        ),
        (
            "bin",
            vec!["bin".into(), s(&inputs.ptu), "--out".into(), s(out)],
        ),
        (
            "batch",
            vec![
                "batch".into(),
                s(&inputs.manifest),
                "--workers".into(),
                "2".into(),
                "--out".into(),
                s(out),
            ],
        ),
        (
            "acquire mock",
            vec![
                "acquire".into(),
                "--device".into(),
                "mock".into(),
                "--duration".into(),
                "400ms".into(),
                "--size".into(),
                "6".into(),
                "--tags".into(),
                o("rec.sstags"),
                "--out".into(),
                s(out),
            ],
        ),
        (
            "acquire picoquant",
            vec![
                "acquire".into(),
                "--device".into(),
                "picoquant:multiharp".into(),
                "--vendor-lib".into(),
                s(&lib),
                "--duration".into(),
                "400ms".into(),
                "--out".into(),
                s(out),
            ],
        ),
    ]
}

/// Why `path` would be taken for complete when it is not; `None` when it
/// is complete and valid, or unfinished and refused or flagged as such.
fn defect(path: &Path) -> Option<String> {
    let name = path.file_name()?.to_str()?.to_string();
    let partial = is_partial_name(path);
    let is = |ext: &str| {
        if partial {
            name.contains(&format!(
                ".{ext}{}",
                scatterscope::files::output::PARTIAL_MARKER
            ))
        } else {
            name.ends_with(&format!(".{ext}"))
        }
    };
    if is("ptu") {
        return match picoquant::open(path) {
            Err(e) if partial => {
                let _ = e; // refused
                None
            }
            Err(e) => Some(format!("a final PTU does not open: {e}")),
            Ok((info, mut reader)) => {
                if partial {
                    // Flagged, or whole: killed between its last byte and
                    // its rename, it holds everything its header says.
                    let whole =
                        info.records_present == info.records_announced && info.trailing_bytes == 0;
                    return (info.completeness_note().is_none() && !whole)
                        .then(|| "an unfinished PTU reads as complete".to_string());
                }
                if info.completeness_note().is_some() || info.trailing_bytes > 0 {
                    return Some(format!(
                        "a final PTU is not whole: {:?}",
                        info.completeness_note()
                    ));
                }
                let mut chunk = Vec::new();
                loop {
                    match reader.next_chunk(&mut chunk) {
                        Ok(true) => {}
                        Ok(false) => return None,
                        Err(e) => return Some(format!("a final PTU is cut: {e}")),
                    }
                }
            }
        };
    }
    if is("sstags") {
        return match TagFile::open(path).and_then(|f| f.read(|_| {})) {
            Err(_) if partial => None,
            Err(e) => Some(format!("a final tag file does not read: {e}")),
            // Cut (no end frame), or whole: killed between its end frame
            // and its rename, it holds every batch its totals count.
            Ok(s) if partial => s
                .totals
                .is_some_and(|t| u64::from(t.batches) != s.batches || s.bytes_skipped > 0)
                .then(|| {
                    "an unfinished tag file has an end frame that does not match it".to_string()
                }),
            Ok(s) => s
                .totals
                .is_none()
                .then(|| "a final tag file has no end frame".to_string()),
        };
    }
    if partial {
        // A derived output's temporary: its name says it is unfinished.
        return None;
    }
    if name.ends_with(".exr") || name.ends_with(".npy") {
        // A stack, or a single image (a truth).
        return match (Stack::read_file(path), read_image(path)) {
            (Err(e), Err(_)) => Some(format!("a final stack or image does not read: {e}")),
            _ => None,
        };
    }
    if name.ends_with(".json") {
        let bytes = std::fs::read(path).ok()?;
        return serde_json::from_slice::<serde_json::Value>(&bytes)
            .err()
            .map(|e| format!("a final JSON file does not parse: {e}"));
    }
    if name.ends_with(".png") {
        return image::open(path)
            .err()
            .map(|e| format!("a final PNG does not decode: {e}"));
    }
    None
}

fn walk(dir: &Path, found: &mut Vec<PathBuf>) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for e in entries.flatten() {
        let p = e.path();
        if p.is_dir() {
            walk(&p, found);
        } else {
            found.push(p);
        }
    }
}

/// xorshift: the same moments on every run.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        self.0
    }
}

/// What the kills left: every file found, and the PTUs by kind.
#[derive(Default)]
struct Outcome {
    kills: usize,
    by_command: std::collections::BTreeMap<&'static str, usize>,
    files: usize,
    partial: usize,
    defects: Vec<String>,
    final_ptus: Vec<PathBuf>,
    partial_ptus: Vec<PathBuf>,
}

/// Kills the commands named in `only` (all when empty) at random moments
/// until `kills` kills landed while the command still ran.
fn kill_at_random(inputs: &Inputs, work: &Path, kills: usize, only: &[&str], seed: u64) -> Outcome {
    let before: Vec<u64> = inputs.files().iter().map(|p| digest(p)).collect();
    // How long each command runs whole, and that it then succeeds.
    let mut full = std::collections::HashMap::new();
    for (name, args) in commands(inputs, &work.join("whole")) {
        let t = Instant::now();
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let o = run(&args);
        assert!(
            o.status.success(),
            "{name} whole: {}",
            String::from_utf8_lossy(&o.stderr)
        );
        full.insert(name, t.elapsed());
    }
    let mut rng = Rng(seed);
    let mut out = Outcome::default();
    let mut runs = 0usize;
    while out.kills < kills && runs < kills * 3 {
        runs += 1;
        let dir = work.join(format!("run-{runs:04}"));
        let cmds: Vec<_> = commands(inputs, &dir)
            .into_iter()
            .filter(|(n, _)| only.is_empty() || only.contains(n))
            .collect();
        let (name, args) = &cmds[rng.next() as usize % cmds.len()];
        let whole = full[name];
        let delay = whole.mul_f64((rng.next() % 1000) as f64 / 1000.0);
        let mut child = command::scatterscope()
            .args(args)
            .env_remove("SCATTERSCOPE_PQ_MOCK")
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .unwrap();
        std::thread::sleep(delay);
        let still_running = child.try_wait().unwrap().is_none();
        child.kill().unwrap();
        child.wait().unwrap();
        if still_running {
            out.kills += 1;
            *out.by_command.entry(name).or_default() += 1;
        }
        // A batch's jobs end with it (SIGTERM on the parent's death):
        // give them a moment before looking.
        if *name == "batch" {
            std::thread::sleep(Duration::from_millis(300));
        }
        let mut found = Vec::new();
        walk(&dir, &mut found);
        for f in found {
            out.files += 1;
            let partial = is_partial_name(&f);
            out.partial += usize::from(partial);
            if let Some(d) = defect(&f) {
                out.defects.push(format!(
                    "{name} killed after {delay:?}: {}: {d}",
                    f.display()
                ));
            }
            let n = f.file_name().unwrap().to_string_lossy().to_string();
            if n.ends_with(".ptu") {
                out.final_ptus.push(f);
            } else if partial && n.contains(".ptu.partial-") {
                out.partial_ptus.push(f);
            }
        }
        let now: Vec<u64> = inputs.files().iter().map(|p| digest(p)).collect();
        assert_eq!(now, before, "an input changed after {name} was killed");
    }
    out
}

/// Runs `convert` on the input PTU and kills it once its temporary output
/// holds records past the header; returns that temporary.
fn convert_killed_mid_write(inputs: &Inputs, out: &Path) -> PathBuf {
    std::fs::create_dir_all(out).unwrap();
    let mut child = command::scatterscope()
        .args(["convert", inputs.ptu.to_str().unwrap(), "--out"])
        .arg(out.join("c.ptu"))
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let start = Instant::now();
    let caught = loop {
        let mut found = Vec::new();
        walk(out, &mut found);
        let temp = found.into_iter().find(|p| {
            is_partial_name(p) && std::fs::metadata(p).is_ok_and(|m| m.len() > 64 * 1024)
        });
        if let Some(temp) = temp {
            break temp;
        }
        assert!(
            child.try_wait().unwrap().is_none() && start.elapsed() < Duration::from_secs(60),
            "convert ended before its temporary held records"
        );
        std::thread::sleep(Duration::from_micros(200));
    };
    child.kill().unwrap();
    child.wait().unwrap();
    assert!(defect(&caught).is_none(), "{:?}", defect(&caught));
    caught
}

#[test]
fn killed_commands_leave_only_whole_files_or_flagged_temporaries_and_their_inputs_intact() {
    let inputs = Inputs::make();
    let work = inputs.dir.path().join("work");
    let out = kill_at_random(&inputs, &work, 200, &[], 0x5EED_CAFE);
    eprintln!(
        "{} kills ({:?}), {} files after them, {} unfinished temporaries",
        out.kills, out.by_command, out.files, out.partial
    );
    assert!(out.kills >= 200, "only {} kills landed mid-run", out.kills);
    assert!(out.by_command.len() == 6, "{:?}", out.by_command);
    assert!(out.defects.is_empty(), "{:#?}", out.defects);
    assert!(
        out.partial > 0,
        "some kill should have caught a file mid-write"
    );
}

#[test]
#[ignore = "needs ptufile under target/pydeps (scripts/fetch_python_deps.sh)"]
fn ptufile_reads_every_whole_ptu_and_flags_every_unfinished_one() {
    let inputs = Inputs::make();
    let work = inputs.dir.path().join("work");
    let only = ["convert ptu", "convert tags", "acquire picoquant"];
    let mut out = kill_at_random(&inputs, &work, 40, &only, 0xF00D);
    // Random moments may miss either kind on a slow or fast machine: the
    // uninterrupted runs give the whole PTUs, and one conversion killed as
    // soon as its temporary holds records gives an unfinished one.
    let mut whole_runs = Vec::new();
    walk(&work.join("whole"), &mut whole_runs);
    out.final_ptus.extend(
        whole_runs
            .into_iter()
            .filter(|p| p.extension().is_some_and(|e| e == "ptu")),
    );
    out.partial_ptus
        .push(convert_killed_mid_write(&inputs, &work.join("caught")));
    assert!(out.final_ptus.len() >= 3, "{:?}", out.final_ptus);
    let list = |v: &[PathBuf]| {
        v.iter()
            .map(|p| p.to_str().unwrap().to_string())
            .collect::<Vec<_>>()
            .join("\n")
    };
    let whole = work.join("whole.txt");
    let partial = work.join("partial.txt");
    std::fs::write(&whole, list(&out.final_ptus)).unwrap();
    std::fs::write(&partial, list(&out.partial_ptus)).unwrap();
    // Whole files decode without a warning; each unfinished one is warned
    // about (its record count is 0 with records after it) or refused, or
    // holds nothing to misread: no record yet, or every record its patched
    // count says (killed between the patch and the rename).
    let script = pydeps::PTUFILE_WARNINGS.to_string()
        + r#"
bad = []
for path in open(sys.argv[1]).read().split():
    warned.clear()
    try:
        with ptufile.PtuFile(path) as f:
            f.decode_records()
    except Exception as e:
        bad.append(f"whole {path}: {e}")
    if warned:
        bad.append(f"whole {path}: warned {warned}")
flagged = 0
for path in open(sys.argv[2]).read().split():
    warned.clear()
    try:
        with ptufile.PtuFile(path) as f:
            f.decode_records()
    except Exception:
        flagged += 1
        continue
    if warned:
        flagged += 1
        continue
    with ptufile.PtuFile(path) as f:
        announced = int(f.tags.get("TTResult_NumberOfRecords", 0))
        held = f.number_records
    if held == 0 or announced == held:
        continue
    bad.append(f"unfinished {path} read without a warning: {announced} announced, {held} read")
print(flagged)
if bad:
    sys.exit("\n".join(bad))
"#;
    pydeps::python(&script, &[&whole, &partial]);
}
