//! The bad-input matrix: every file type the command line reads, with
//! every defect a lab meets (empty, cut at several places, random bytes,
//! flipped bits, absurd sizes, wrong dtype, NaN/Inf), through the command
//! that reads it. Each run must end in one of two ways:
//! - refused: exit status 1, one `error:` line naming the file, no panic,
//!   and none of the command's final output files written;
//! - accepted (only where the defect leaves a valid file, e.g. a flipped
//!   bit inside photon data, or a raw tag file cut by a crash, which is
//!   read up to the cut and said so): exit status 0 and complete outputs.

#[path = "common/command.rs"]
mod command;
use command::run_isolated;
#[path = "common/npy.rs"]
mod npy;
#[path = "common/pt3.rs"]
mod pt3;

use std::path::Path;
use std::process::Output;

use npy::npy_bytes as npy;
use pt3::write_pt3;
use scatterscope::events::Tag;
use scatterscope::formats::picoquant::records::RecordType;
use scatterscope::formats::picoquant::writer::{PtuWriter, WriterHeader};

/// What a defect must lead to.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Expect {
    Refused,
    /// Refused, or accepted with complete outputs.
    Either,
}

/// A file kind: how to run the command that reads it and which files
/// that command writes when it succeeds.
struct Kind {
    name: &'static str,
    extension: &'static str,
    valid: Vec<u8>,
    /// The command line for (file, output directory, directory of the
    /// valid inputs).
    command: fn(&Path, &Path, &Path) -> Vec<String>,
    /// A JSON sidecar written next to every case (`.npy` stacks).
    sidecar: Option<Vec<u8>>,
    /// Outputs (relative to the output directory) that mean "complete".
    complete: &'static [&'static str],
    /// Expectation for an empty file (an empty TOML document is a valid
    /// config without overrides).
    empty: Expect,
    /// Expectation for a cut file.
    cut: Expect,
    /// Expectation for a file one byte short: image formats end with a
    /// trailer (PNG's IEND CRC, JPEG's EOI) after the last pixel, so their
    /// decoders may accept it with every pixel intact.
    short: Expect,
    /// Type-specific defects.
    extra: Vec<(&'static str, Vec<u8>, Expect)>,
}

impl Kind {
    /// A kind every defect of which must be refused, without a sidecar or
    /// cases of its own.
    fn new(
        name: &'static str,
        extension: &'static str,
        valid: Vec<u8>,
        command: fn(&Path, &Path, &Path) -> Vec<String>,
        complete: &'static [&'static str],
    ) -> Self {
        Kind {
            name,
            extension,
            valid,
            command,
            sidecar: None,
            complete,
            empty: Expect::Refused,
            cut: Expect::Refused,
            short: Expect::Refused,
            extra: Vec::new(),
        }
    }
}

fn strings(args: &[&str]) -> Vec<String> {
    args.iter().map(|s| s.to_string()).collect()
}

/// Small physics so that every run takes milliseconds.
const SMALL: [&str; 6] = ["--size", "8", "--fov", "2cm", "--bins", "30"];

fn bin_cmd(file: &Path, out: &Path, _: &Path) -> Vec<String> {
    strings(&[
        "bin",
        file.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ])
}

fn reconstruct_cmd(file: &Path, out: &Path, _: &Path) -> Vec<String> {
    let mut a = strings(&["reconstruct", file.to_str().unwrap(), "--max-iters", "2"]);
    a.extend(strings(&["--out", out.to_str().unwrap()]));
    a
}

fn simulate_scene_cmd(file: &Path, out: &Path, _: &Path) -> Vec<String> {
    let mut a = strings(&["simulate", "--scene", file.to_str().unwrap()]);
    a.extend(strings(&SMALL));
    a.extend(strings(&["--out", out.to_str().unwrap()]));
    a
}

fn simulate_config_cmd(file: &Path, out: &Path, _: &Path) -> Vec<String> {
    let mut a = strings(&["simulate", "--config", file.to_str().unwrap()]);
    a.extend(strings(&["--size", "8", "--fov", "2cm"]));
    a.extend(strings(&["--out", out.to_str().unwrap()]));
    a
}

fn denoise_weights_cmd(file: &Path, out: &Path, inputs: &Path) -> Vec<String> {
    let mut a = strings(&[
        "denoise",
        inputs.join("scene.png").to_str().unwrap(),
        "--sigma",
        "0.1",
    ]);
    a.extend(strings(&["--weights", file.to_str().unwrap()]));
    a.extend(strings(&[
        "--out",
        out.join("denoised.png").to_str().unwrap(),
    ]));
    a
}

fn import_pth_cmd(file: &Path, out: &Path, _: &Path) -> Vec<String> {
    strings(&[
        "weights",
        "import",
        file.to_str().unwrap(),
        "--out",
        out.join("imported.safetensors").to_str().unwrap(),
    ])
}

/// Deterministic pseudo-random bytes (xorshift).
fn random_bytes(n: usize, mut seed: u64) -> Vec<u8> {
    (0..n)
        .map(|_| {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 24) as u8
        })
        .collect()
}

fn flipped(valid: &[u8], seed: u64) -> Vec<u8> {
    let mut v = valid.to_vec();
    let r = random_bytes(16, seed);
    for pair in r.chunks(2) {
        let i = (usize::from(pair[0]) << 8 | usize::from(pair[1])) % v.len();
        v[i] ^= 1 << (pair[0] % 8);
    }
    v
}

/// A PicoHarp T3 PTU file with 200 photons.
fn valid_ptu(dir: &Path) -> Vec<u8> {
    let path = dir.join("base.ptu");
    let h = WriterHeader {
        resolution_s: 4e-12,
        sync_rate_hz: 80e6,
        device: "TestHarp".into(),
        imaging: None,
        extra: Vec::new(),
    };
    let mut w = PtuWriter::create(&path, RecordType::PicoHarpT3, &h).unwrap();
    for i in 0..200u64 {
        w.write_tag(Tag::Photon {
            channel: 1,
            macro_time: i * 3,
            micro_time: (i * 37 % 3000) as u32,
        })
        .unwrap();
    }
    w.finish().unwrap();
    std::fs::read(&path).unwrap()
}

fn valid_pt3(dir: &Path) -> Vec<u8> {
    let path = dir.join("base.pt3");
    let records: Vec<u32> = (0..200u32)
        .map(|i| (1 << 28) | ((i * 37 % 4000) << 16) | (i * 3))
        .collect();
    write_pt3(&path, 3, 0, &records, 200);
    std::fs::read(&path).unwrap()
}

fn check(kind: &Kind, defect: &str, file: &Path, out: &Path, o: &Output, expect: Expect) {
    let stderr = String::from_utf8_lossy(&o.stderr);
    let stdout = String::from_utf8_lossy(&o.stdout);
    let what = format!("{} / {defect}", kind.name);
    assert!(!stderr.contains("panicked"), "{what}: panic\n{stderr}");
    match o.status.code() {
        Some(0) => {
            assert_eq!(expect, Expect::Either, "{what}: accepted\n{stdout}{stderr}");
            for f in kind.complete {
                assert!(out.join(f).exists(), "{what}: accepted without {f}");
            }
        }
        Some(4) => {
            // Outputs written, with the warning that they come from an
            // incomplete input or are empty.
            assert_eq!(expect, Expect::Either, "{what}: accepted\n{stdout}{stderr}");
            assert!(
                stdout.lines().any(|l| l.starts_with("warning: ")),
                "{what}: exit status 4 without a warning line\n{stdout}{stderr}"
            );
            for f in kind.complete {
                assert!(out.join(f).exists(), "{what}: accepted without {f}");
            }
        }
        Some(1) => {
            let name = file.file_name().unwrap().to_str().unwrap();
            assert!(
                stderr
                    .lines()
                    .any(|l| l.starts_with("error: ") && l.contains(name)),
                "{what}: the error does not name {name}:\n{stderr}"
            );
            for f in kind.complete {
                assert!(
                    !out.join(f).exists(),
                    "{what}: refused but left {f} looking complete"
                );
            }
        }
        other => panic!("{what}: exit status {other:?}\n{stderr}"),
    }
}

fn run_matrix(kind: &Kind, dir: &Path) -> usize {
    let v = &kind.valid;
    let mut defects: Vec<(String, Vec<u8>, Expect)> = vec![
        ("valid".into(), v.clone(), Expect::Either),
        ("empty".into(), Vec::new(), kind.empty),
        (
            "random bytes".into(),
            random_bytes(4096, 7),
            Expect::Refused,
        ),
        (
            "random bytes, 16".into(),
            random_bytes(16, 11),
            Expect::Refused,
        ),
    ];
    for (num, den) in [(1, 16), (1, 4), (1, 2), (15, 16)] {
        let at = v.len() * num / den;
        defects.push((format!("cut at byte {at}"), v[..at].to_vec(), kind.cut));
    }
    defects.push((
        "cut one byte short".into(),
        v[..v.len() - 1].to_vec(),
        kind.short,
    ));
    for seed in 1..=3 {
        defects.push((
            format!("flipped bits ({seed})"),
            flipped(v, seed),
            Expect::Either,
        ));
    }
    for (name, bytes, expect) in &kind.extra {
        defects.push((name.to_string(), bytes.clone(), *expect));
    }
    for (i, (defect, bytes, expect)) in defects.iter().enumerate() {
        let file = dir.join(format!("{}_{i}.{}", kind.name, kind.extension));
        std::fs::write(&file, bytes).unwrap();
        if let Some(json) = &kind.sidecar {
            std::fs::write(file.with_extension("json"), json).unwrap();
        }
        let out = dir.join(format!("out_{}_{i}", kind.name));
        std::fs::create_dir_all(&out).unwrap();
        let o = run_isolated(&(kind.command)(&file, &out, dir));
        if defect == "valid" {
            assert_eq!(
                o.status.code(),
                Some(0),
                "{}: the valid base file fails: {}",
                kind.name,
                String::from_utf8_lossy(&o.stderr)
            );
        }
        check(kind, defect, &file, &out, &o, *expect);
    }
    defects.len()
}

#[test]
fn every_reader_refuses_bad_files_clearly() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // Valid stacks, scenes and tags from the project's own writers.
    let sim = d.join("sim");
    let mut args = strings(&["simulate", "--scene", "disks", "--npy", "--seed", "1"]);
    args.extend(strings(&SMALL));
    args.extend(strings(&["--out", sim.to_str().unwrap()]));
    assert!(run_isolated(&args).status.success());
    let acq = d.join("acq");
    let raw = d.join("tags.sstags");
    let o = run_isolated(&strings(&[
        "acquire",
        "--device",
        "mock",
        "--size",
        "8",
        "--fov",
        "2cm",
        "--max-photons",
        "3000",
        "--raw",
        raw.to_str().unwrap(),
        "--out",
        acq.to_str().unwrap(),
    ]));
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let scene = image::GrayImage::from_fn(16, 16, |x, y| image::Luma([((x * 16 + y) % 256) as u8]));
    let png_path = d.join("scene.png");
    scene.save(&png_path).unwrap();
    let jpg_path = d.join("scene.jpg");
    scene.save(&jpg_path).unwrap();
    let counts_npy = std::fs::read(sim.join("counts.npy")).unwrap();
    let counts_json = std::fs::read(sim.join("counts.json")).unwrap();
    let nan_f4 = {
        let mut p: Vec<u8> = (0..30 * 64)
            .flat_map(|i| (i as f32).to_le_bytes())
            .collect();
        p[40..44].copy_from_slice(&f32::NAN.to_le_bytes());
        p
    };
    let inf_f4 = {
        let mut p: Vec<u8> = (0..30 * 64)
            .flat_map(|i| (i as f32).to_le_bytes())
            .collect();
        p[400..404].copy_from_slice(&f32::INFINITY.to_le_bytes());
        p
    };
    let kinds = vec![
        Kind {
            extra: vec![(
                "absurd record count",
                {
                    let mut v = valid_ptu(d);
                    // TTResult_NumberOfRecords is an Int8 tag: make it 10^15.
                    let key = b"TTResult_NumberOfRecords";
                    let at = v.windows(key.len()).position(|w| w == key).unwrap() + 32 + 8;
                    v[at..at + 8].copy_from_slice(&1_000_000_000_000_000i64.to_le_bytes());
                    v
                },
                Expect::Refused,
            )],
            ..Kind::new("ptu", "ptu", valid_ptu(d), bin_cmd, &["stack.exr"])
        },
        Kind::new("pt3", "pt3", valid_pt3(d), bin_cmd, &["stack.exr"]),
        Kind {
            // A recording cut by a crash is read up to the cut, and said so.
            cut: Expect::Either,
            short: Expect::Either,
            extra: vec![(
                "absurd sensor size",
                {
                    // The JSON header claims a 65535 x 65535 sensor.
                    let v = std::fs::read(&raw).unwrap();
                    let n = u32::from_le_bytes(v[8..12].try_into().unwrap()) as usize;
                    let mut h: serde_json::Value = serde_json::from_slice(&v[12..12 + n]).unwrap();
                    h["pixels_x"] = 65535.into();
                    h["pixels_y"] = 65535.into();
                    let json = serde_json::to_vec(&h).unwrap();
                    let mut out = v[..8].to_vec();
                    out.extend((json.len() as u32).to_le_bytes());
                    out.extend(json);
                    out.extend(&v[12 + n..]);
                    out
                },
                Expect::Refused,
            )],
            ..Kind::new(
                "sstags",
                "sstags",
                std::fs::read(&raw).unwrap(),
                bin_cmd,
                &["stack.exr"],
            )
        },
        Kind {
            extra: vec![(
                "absurd declared size",
                std::fs::read(
                    Path::new(env!("CARGO_MANIFEST_DIR"))
                        .join("tests/data/fuzz/exr_huge_declared_size.exr"),
                )
                .unwrap(),
                Expect::Refused,
            )],
            ..Kind::new(
                "exr",
                "exr",
                std::fs::read(sim.join("counts.exr")).unwrap(),
                reconstruct_cmd,
                &["reconstruction.exr", "trace.csv"],
            )
        },
        Kind {
            // The metadata stays valid while the array is damaged.
            sidecar: Some(counts_json),
            extra: vec![
                (
                    "absurd shape",
                    npy("<f4", (1 << 20, 1 << 20, 1 << 20), &[0; 64]),
                    Expect::Refused,
                ),
                (
                    "wrong dtype i2",
                    npy("<i2", (30, 8, 8), &[0; 30 * 64 * 2]),
                    Expect::Refused,
                ),
                (
                    "wrong dtype complex",
                    npy("<c8", (30, 8, 8), &[0; 30 * 64 * 8]),
                    Expect::Refused,
                ),
                (
                    "wrong rank",
                    npy("<f4", (30, 64, 1), &[0; 30 * 64 * 4])[..].to_vec(),
                    Expect::Refused,
                ),
                (
                    "NaN value",
                    npy("<f4", (30, 8, 8), &nan_f4),
                    Expect::Refused,
                ),
                (
                    "Inf value",
                    npy("<f4", (30, 8, 8), &inf_f4),
                    Expect::Refused,
                ),
            ],
            ..Kind::new(
                "npy",
                "npy",
                counts_npy,
                reconstruct_cmd,
                &["reconstruction.exr", "trace.csv"],
            )
        },
        Kind {
            short: Expect::Either,
            extra: vec![(
                "absurd dimensions",
                {
                    // IHDR width and height set to 2^30 (CRC fixed up).
                    let mut v = std::fs::read(&png_path).unwrap();
                    v[16..24].copy_from_slice(&[0x40, 0, 0, 0, 0x40, 0, 0, 0]);
                    let crc = crc32(&v[12..29]);
                    v[29..33].copy_from_slice(&crc.to_be_bytes());
                    v
                },
                Expect::Refused,
            )],
            ..Kind::new(
                "png",
                "png",
                std::fs::read(&png_path).unwrap(),
                simulate_scene_cmd,
                &["counts.exr"],
            )
        },
        Kind {
            short: Expect::Either,
            ..Kind::new(
                "jpeg",
                "jpg",
                std::fs::read(&jpg_path).unwrap(),
                simulate_scene_cmd,
                &["counts.exr"],
            )
        },
        Kind {
            // An empty TOML document is a config without overrides, and a
            // cut at a line end leaves a valid, shorter config.
            empty: Expect::Either,
            cut: Expect::Either,
            short: Expect::Either,
            extra: vec![
                (
                    "absurd bins",
                    b"bins = 1000000000000\n".to_vec(),
                    Expect::Refused,
                ),
                ("NaN value", b"mu_a = nan\n".to_vec(), Expect::Refused),
                ("Inf value", b"mu_s = inf\n".to_vec(), Expect::Refused),
                ("wrong type", b"mu_a = \"lots\"\n".to_vec(), Expect::Refused),
                ("unknown key", b"mu_x = 1.0\n".to_vec(), Expect::Refused),
            ],
            ..Kind::new(
                "toml",
                "toml",
                b"preset = \"paper\"\nmu_a = 0.1\nbins = 30\n".to_vec(),
                simulate_config_cmd,
                &["counts.exr"],
            )
        },
        Kind {
            extra: vec![(
                "absurd header length",
                {
                    let mut v = 1u64.wrapping_shl(62).to_le_bytes().to_vec();
                    v.extend_from_slice(b"{}");
                    v
                },
                Expect::Refused,
            )],
            ..Kind::new(
                "safetensors",
                "safetensors",
                std::fs::read(
                    Path::new(env!("CARGO_MANIFEST_DIR"))
                        .join("weights/ffdnet-gray-small.safetensors"),
                )
                .unwrap(),
                denoise_weights_cmd,
                &["denoised.png"],
            )
        },
        // Not a valid .pth in the suite (the real one is downloaded by the
        // user): the defects below need none.
        Kind::new(
            "pth",
            "pth",
            Vec::new(),
            import_pth_cmd,
            &["imported.safetensors"],
        ),
    ];
    let mut runs = 0;
    for kind in &kinds {
        if kind.valid.is_empty() {
            for (i, (defect, bytes)) in [
                ("empty", Vec::new()),
                ("random bytes", random_bytes(4096, 3)),
                ("zip header only", b"PK\x03\x04rest".to_vec()),
            ]
            .into_iter()
            .enumerate()
            {
                let file = d.join(format!("{}_{i}.{}", kind.name, kind.extension));
                std::fs::write(&file, &bytes).unwrap();
                let out = d.join(format!("out_{}_{i}", kind.name));
                std::fs::create_dir_all(&out).unwrap();
                let o = run_isolated(&(kind.command)(&file, &out, d));
                check(kind, defect, &file, &out, &o, Expect::Refused);
                runs += 1;
            }
        } else {
            runs += run_matrix(kind, d);
        }
    }
    println!("{runs} bad-input runs checked");
    assert!(runs > 100);
}

/// CRC-32 (PNG chunks), bit by bit.
fn crc32(bytes: &[u8]) -> u32 {
    let mut c = 0xFFFF_FFFFu32;
    for &b in bytes {
        c ^= u32::from(b);
        for _ in 0..8 {
            c = if c & 1 != 0 {
                0xEDB8_8320 ^ (c >> 1)
            } else {
                c >> 1
            };
        }
    }
    !c
}
