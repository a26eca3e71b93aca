//! The default method's per-stack choice (`--method auto`) on two of the
//! benchmark's tuning scenes at the paper preset's light (1x, sensor with
//! edges, seed 0): PnP on a piecewise-flat one, whole-stack
//! Richardson-Lucy on a textured one (run only after PnP is not
//! chosen), and the same output on a rerun.

use std::path::PathBuf;

use scatterscope::denoise::ffdnet::{Ffdnet, source};
use scatterscope::physics::Preset;
use scatterscope::reconstruct::Reconstruction;
use scatterscope::reconstruct::auto::{PNP_MISFIT_Z, chosen, deviance_z};
use scatterscope::reconstruct::method::{Method, MethodOptions, run_method};
use scatterscope::report::bench::{BenchImage, level_setup, simulate_case};

fn run_auto(name: &str, file: Option<PathBuf>) -> Reconstruction {
    let image = BenchImage {
        name: name.into(),
        file,
        source: "test".into(),
        category: "test".into(),
        split: "tuning".into(),
    };
    let setup = level_setup(&Preset::Paper.setup(), 1.0).unwrap();
    let case = simulate_case(&image, &setup, 384, 0).unwrap();
    let ffdnet = Ffdnet::new(source::embedded(), "embedded");
    run_method(
        &case.problem,
        Method::Auto,
        None,
        &ffdnet,
        &MethodOptions::default(),
        None,
        |_| {},
    )
    .unwrap()
}

#[test]
fn auto_picks_pnp_on_a_piecewise_flat_scene_and_repeats_itself() {
    let file = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data/bench/checkerboard.png");
    let first = run_auto("checkerboard", Some(file.clone()));
    assert_eq!(chosen(&first.trace), Some("pnp"), "{:?}", first.trace.notes);
    let z = deviance_z(&first.trace).expect("PnP reached its noise floor");
    assert!(z >= PNP_MISFIT_Z, "z = {z}");
    // PnP runs first; once it is chosen, rl-stack is not run.
    let notes = first.trace.notes.join("\n");
    assert!(notes.contains("auto: rl-stack not run"), "{notes}");
    assert!(!notes.contains("auto: rl-stack took"), "{notes}");
    let again = run_auto("checkerboard", Some(file));
    assert_eq!(chosen(&again.trace), Some("pnp"));
    assert_eq!(first.image, again.image, "same stack, same output");
}

#[test]
fn auto_picks_whole_stack_richardson_lucy_on_a_textured_scene() {
    let out = run_auto("text", None);
    assert_eq!(
        chosen(&out.trace),
        Some("rl-stack"),
        "{:?}",
        out.trace.notes
    );
    // Each candidate's time and PnP's score are in the notes.
    let notes = out.trace.notes.join("\n");
    assert!(notes.contains("auto: rl-stack took"), "{notes}");
    assert!(notes.contains("its output deviance z = "), "{notes}");
    // PnP ran first: the chosen rows are timed from the start of the
    // whole run, so its first row comes after PnP's seconds.
    let pnp_s: f64 = notes
        .split("auto: pnp took ")
        .nth(1)
        .and_then(|rest| rest.split(" s;").next())
        .and_then(|s| s.parse().ok())
        .expect("PnP's time in the notes");
    let first_row = out.trace.rows.first().unwrap().wall_s;
    assert!(first_row >= pnp_s - 0.01, "{first_row} < {pnp_s}");
    assert!(out.trace.wall_s >= first_row);
}

/// The z of PnP's output that an `auto` run's first note states.
fn stated_z(trace: &scatterscope::reconstruct::trace::Trace) -> String {
    let notes = trace.notes.join("\n");
    notes
        .split("its output deviance z = ")
        .nth(1)
        .and_then(|rest| rest.split(' ').next())
        .unwrap_or_else(|| panic!("no z in {notes}"))
        .to_string()
}

#[test]
fn auto_runs_pnp_with_the_solver_the_options_choose() {
    use scatterscope::denoise::tv::TotalVariation;
    use scatterscope::forward::poisson_counts;
    use scatterscope::reconstruct::method::{Acceleration, RlStop, Solver};
    use scatterscope::{
        Boundary, ForwardModel, KernelStack, Problem, Sampling, Scene, Stack, StackMeta, ValueKind,
    };
    // A small stack of the paper's slab: 32 x 32 pixels.
    let mut setup = Preset::Paper.setup();
    (setup.sensor.width_px, setup.sensor.height_px) = (32, 32);
    setup.sensor.fov_cm = 50.0 / 8.0;
    let kernels = KernelStack::build(&setup, Sampling::Integrated).unwrap();
    let model = ForwardModel::new(&kernels, Boundary::Sensor);
    let truth = Scene::parse("disks").render(32, 32).unwrap();
    let counts = poisson_counts(&model.expected_scene(truth.view()).counts, 7);
    let stack = Stack::new(
        counts.mapv(|c| c as f32),
        StackMeta::simulated(&kernels, ValueKind::Counts, "test".into()),
    );
    let problem = Problem::new(&stack, &setup, Sampling::Integrated, Boundary::Sensor).unwrap();
    let prior = TotalVariation::default();
    let run = |method, solver| {
        let mut opts = MethodOptions {
            solver,
            ..MethodOptions::default()
        };
        opts.split.max_iters = 8;
        opts.admm_lbfgs.max_iters = 8;
        opts.rl_stop = RlStop::CrossValidated {
            max_iters: 20,
            acceleration: Acceleration::None,
        };
        run_method(&problem, method, None, &prior, &opts, None, |_| {}).unwrap()
    };
    let z_of =
        |r: &Reconstruction| deviance_z(&r.trace).map_or("none".into(), |z| format!("{z:.1}"));
    for solver in [Solver::Split, Solver::AdmmLbfgs] {
        let pnp = run(Method::Pnp, solver);
        let auto = run(Method::Auto, solver);
        assert_eq!(stated_z(&auto.trace), z_of(&pnp), "{solver:?}");
    }
    // The two solvers' outputs differ, so the check above tells them apart.
    assert_ne!(
        z_of(&run(Method::Pnp, Solver::Split)),
        z_of(&run(Method::Pnp, Solver::AdmmLbfgs))
    );
}
