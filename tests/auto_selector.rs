//! The default method (`--method auto`, rule R77b): the learned
//! reconstruction inside the ranges its network was trained on,
//! whole-stack Richardson-Lucy (`rl-stack`, cross-validated stop) outside
//! them, and nothing else run. Scenes of the benchmark's tuning split,
//! simulated as the benchmark does (sensor with edges, seed 0).

use scatterscope::Problem;
use scatterscope::denoise::ffdnet::{Ffdnet, source};
use scatterscope::physics::Preset;
use scatterscope::reconstruct::Reconstruction;
use scatterscope::reconstruct::auto::chosen;
use scatterscope::reconstruct::method::{Method, MethodOptions, run_method};
use scatterscope::report::bench::{BenchImage, level_setup, simulate_case};

/// The benchmark's simulation of scene `name` at `level` times the
/// paper's light, its pixels `pitch` times the paper's.
fn case(name: &str, level: f64, pitch: f64) -> Problem {
    let image = BenchImage {
        name: name.into(),
        file: None,
        source: "test".into(),
        category: "test".into(),
        split: "tuning".into(),
    };
    let mut setup = level_setup(&Preset::Paper.setup(), level).unwrap();
    setup.sensor.fov_cm *= pitch;
    simulate_case(&image, &setup, 384, 0).unwrap().problem
}

fn run(problem: &Problem, method: Method) -> Reconstruction {
    let ffdnet = Ffdnet::new(source::embedded(), "embedded");
    run_method(
        problem,
        method,
        None,
        &ffdnet,
        &MethodOptions::default(),
        None,
        |_| {},
    )
    .unwrap()
}

#[test]
fn auto_is_the_learned_reconstruction_inside_the_trained_ranges() {
    let problem = case("text", 1.0, 1.0);
    let auto = run(&problem, Method::Auto);
    assert_eq!(
        chosen(&auto.trace),
        Some("learned"),
        "{:?}",
        auto.trace.notes
    );
    let learned = run(&problem, Method::Learned);
    assert_eq!(auto.image, learned.image, "auto's output is learned's");
    let notes = auto.trace.notes.join("\n");
    assert!(notes.contains("learned: output deviance"), "{notes}");
    // Nothing it would throw away: neither PnP nor rl-stack ran.
    assert!(
        !notes.contains("pnp") && !notes.contains("rl-stack"),
        "{notes}"
    );
    assert_eq!(
        run(&problem, Method::Auto).image,
        auto.image,
        "same stack, same output"
    );
}

#[test]
fn auto_runs_whole_stack_richardson_lucy_outside_the_trained_ranges() {
    // Pixels 1.6 times the paper's: the blur is 5.1 px RMS, narrower
    // than any the network was trained on.
    let problem = case("text", 1.0, 1.6);
    let auto = run(&problem, Method::Auto);
    assert_eq!(
        chosen(&auto.trace),
        Some("rl-stack"),
        "{:?}",
        auto.trace.notes
    );
    let notes = auto.trace.notes.join("\n");
    assert!(
        notes.contains("outside what the network was trained on")
            && notes.contains("px RMS radius (trained on"),
        "{notes}"
    );
    let rl_stack = run(&problem, Method::RlStack);
    assert_eq!(auto.image, rl_stack.image, "auto's output is rl-stack's");
    // `--method learned` keeps its own stand-in, rl-sum.
    let learned = run(&problem, Method::Learned);
    assert!(
        learned
            .trace
            .notes
            .join("\n")
            .contains("reconstructed by rl-sum"),
        "{:?}",
        learned.trace.notes
    );
}
