//! Transport runs kept on disk (`transport_cache`): a kept run is the run
//! made anew, a damaged file is made again and replaced (and said), a file
//! of other physics is never taken, and a folder that cannot be written
//! costs only the keeping.

use scatterscope_physics::transport::{Grid, Run, Slab, Source, Transport, transport};
use scatterscope_physics::transport_cache::{CacheUse, transport_in};

fn slab() -> Slab {
    Slab {
        mu_a_per_cm: 0.5,
        mu_s_per_cm: 20.0,
        g: 0.8,
        n: 1.4,
        n_outside: 1.0,
        thickness_cm: 0.5,
    }
}

fn grid() -> Grid {
    Grid {
        t_start_ps: 0.0,
        bin_width_ps: 5.0,
        bins: 40,
        ring_width_cm: 0.1,
        rings: 20,
    }
}

fn run(seed: u64) -> Run {
    Run {
        photons: 50_000,
        seed,
        max_path_cm: 1e3,
    }
}

/// Every number of two runs, bit for bit.
fn same(a: &Transport, b: &Transport) -> bool {
    let bits = |t: &Transport| -> Vec<u64> {
        let mut v = vec![t.photons, t.specular.to_bits()];
        for e in [
            t.reflected,
            t.transmitted,
            t.absorbed,
            t.cut,
            t.outside_grid,
        ]
        .iter()
        .chain(&t.cells)
        .chain(&t.face)
        {
            v.extend([e.mean.to_bits(), e.error.to_bits()]);
        }
        v
    };
    bits(a) == bits(b) && a.grid == b.grid
}

#[test]
fn a_kept_run_is_the_run_and_damage_is_made_again() {
    let dir = tempfile::tempdir().unwrap();
    let fresh = transport(&slab(), Source::Lambertian, &grid(), &run(7)).unwrap();
    let (first, used) =
        transport_in(dir.path(), &slab(), Source::Lambertian, &grid(), &run(7)).unwrap();
    let CacheUse::Written(path) = used else {
        panic!("{used:?}")
    };
    assert!(same(&first, &fresh));
    let (second, used) =
        transport_in(dir.path(), &slab(), Source::Lambertian, &grid(), &run(7)).unwrap();
    assert_eq!(used, CacheUse::Read(path.clone()));
    assert!(same(&second, &fresh));
    // Only the kept file is left: no temporary beside it.
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);

    // Cut short: made again, said, replaced by a whole file.
    let bytes = std::fs::read(&path).unwrap();
    std::fs::write(&path, &bytes[..bytes.len() - 100]).unwrap();
    let (again, used) =
        transport_in(dir.path(), &slab(), Source::Lambertian, &grid(), &run(7)).unwrap();
    match &used {
        CacheUse::Replaced(p, why) => assert!(p == &path && why.contains("expected"), "{why}"),
        other => panic!("{other:?}"),
    }
    assert!(used.to_string().contains("did not read back"), "{used}");
    assert!(same(&again, &fresh));
    assert_eq!(std::fs::read(&path).unwrap(), bytes);

    // A number that is not finite: made again.
    let mut bad = bytes.clone();
    let n = bad.len();
    bad[n - 8..].copy_from_slice(&f64::NAN.to_le_bytes());
    std::fs::write(&path, &bad).unwrap();
    let (_, used) =
        transport_in(dir.path(), &slab(), Source::Lambertian, &grid(), &run(7)).unwrap();
    assert!(matches!(used, CacheUse::Replaced(..)), "{used:?}");
}

#[test]
fn other_physics_is_never_taken_from_the_cache() {
    let dir = tempfile::tempdir().unwrap();
    let (_, used) =
        transport_in(dir.path(), &slab(), Source::Lambertian, &grid(), &run(1)).unwrap();
    let CacheUse::Written(path) = used else {
        panic!("{used:?}")
    };
    // Another seed, index, source or grid: another file, made now.
    let mut thicker = slab();
    thicker.thickness_cm = 0.6;
    let mut finer = grid();
    finer.bin_width_ps = 4.0;
    for (s, src, g, r) in [
        (slab(), Source::Lambertian, grid(), run(2)),
        (thicker, Source::Lambertian, grid(), run(1)),
        (slab(), Source::Pencil, grid(), run(1)),
        (slab(), Source::Lambertian, finer, run(1)),
    ] {
        let (t, used) = transport_in(dir.path(), &s, src, &g, &r).unwrap();
        assert!(
            matches!(&used, CacheUse::Written(p) if p != &path),
            "{used:?}"
        );
        assert!(same(&t, &transport(&s, src, &g, &r).unwrap()));
    }
    // A file of other physics under this run's name is not taken: the
    // key inside decides.
    let other = std::fs::read(
        dir.path().join(
            std::fs::read_dir(dir.path())
                .unwrap()
                .map(|e| e.unwrap().file_name())
                .find(|n| dir.path().join(n) != path)
                .unwrap(),
        ),
    )
    .unwrap();
    std::fs::write(&path, other).unwrap();
    let (t, used) =
        transport_in(dir.path(), &slab(), Source::Lambertian, &grid(), &run(1)).unwrap();
    assert_eq!(used, CacheUse::Written(path));
    assert!(same(
        &t,
        &transport(&slab(), Source::Lambertian, &grid(), &run(1)).unwrap()
    ));
}

#[test]
fn a_folder_that_cannot_be_written_costs_only_the_keeping() {
    let dir = tempfile::tempdir().unwrap();
    let blocked = dir.path().join("a-file");
    std::fs::write(&blocked, b"not a folder").unwrap();
    let (t, used) = transport_in(&blocked, &slab(), Source::Lambertian, &grid(), &run(3)).unwrap();
    assert!(matches!(used, CacheUse::NotWritten(..)), "{used:?}");
    assert!(used.to_string().contains("not kept"), "{used}");
    assert!(same(
        &t,
        &transport(&slab(), Source::Lambertian, &grid(), &run(3)).unwrap()
    ));
    assert_eq!(std::fs::read(&blocked).unwrap(), b"not a folder");
    // Bad physics is refused whether or not a folder is set.
    let mut bad = slab();
    bad.g = 1.0;
    assert!(transport_in(dir.path(), &bad, Source::Lambertian, &grid(), &run(3)).is_err());
}
