//! The default method (`--method auto`, rules R77b and R82b): the learned
//! reconstruction inside the ranges its network was trained on, kept only
//! where it explains held-back counts as well as `rl-sum` with its
//! cross-validated stop (else that `rl-sum`), whole-stack Richardson-Lucy
//! (`rl-stack`, cross-validated stop) outside them, and nothing else run.
//! Scenes of the benchmark's tuning split, simulated as the benchmark does
//! (sensor with edges, seed 0).

use scatterscope::Problem;
use scatterscope::denoise::ffdnet::{Ffdnet, source};
use scatterscope::physics::Preset;
use scatterscope::reconstruct::Reconstruction;
use scatterscope::reconstruct::auto::chosen;
use scatterscope::reconstruct::method::{Method, MethodOptions, run_method};
use scatterscope::report::bench::{BenchImage, CaseSimulation, level_setup, simulate_case};

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
    simulate_case(&image, &setup, 384, 0, &CaseSimulation::default())
        .unwrap()
        .problem
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
fn inside_the_trained_ranges_auto_returns_the_network_or_rl_sum_as_its_check_says() {
    let problem = case("text", 1.0, 1.0);
    let auto = run(&problem, Method::Auto);
    let notes = auto.trace.notes.join("\n");
    assert!(
        notes.contains("held-back deviance of the network"),
        "{notes}"
    );
    // Whichever it chose, its output is that method's, bit for bit.
    let chose = chosen(&auto.trace).unwrap_or_else(|| panic!("{notes}"));
    let method = match chose {
        "learned" => Method::Learned,
        "rl-sum" => Method::RlSum,
        other => panic!("auto chose {other}: {notes}"),
    };
    assert_eq!(
        auto.image,
        run(&problem, method).image,
        "auto's output is {chose}'s"
    );
    // Nothing it would throw away but what the check needs: neither PnP
    // nor rl-stack ran.
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
fn a_network_that_explains_the_counts_badly_is_not_kept() {
    use scatterscope::reconstruct::Reconstructor;
    use scatterscope::reconstruct::auto::Auto;
    use scatterscope::reconstruct::learned::Learned;
    use scatterscope::reconstruct::learned::net::LearnedNet;
    use scatterscope::reconstruct::method::{Acceleration, RlStop};
    use scatterscope::reconstruct::rl_stack::RlStack;
    // Random weights (the engine's fixture), trained on 1-10 photons per
    // pixel: 0.15x the paper's light (about 9 per pixel) lies in that
    // range. Its exact EM steps keep it near Richardson-Lucy: at 0.05x
    // the check cannot tell them apart (z about +4); with three times the
    // photons it can.
    let random = LearnedNet::from_bytes(
        &std::fs::read(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/tests/fixtures/learned/small.safetensors"
        ))
        .unwrap(),
        "small.safetensors",
    )
    .unwrap();
    let problem = case("text", 0.15, 1.0);
    let auto = Auto {
        learned: Learned {
            net: &random,
            outside: Box::new(RlStack {
                stop: RlStop::CROSS_VALIDATED,
            }),
        },
        search: (RlStop::DEFAULT_MAX_ITERS, Acceleration::None),
        carried: None,
    };
    let bins = problem.all_bins();
    let data =
        scatterscope::reconstruct::Data::new(&problem.model, &problem.counts, &bins).unwrap();
    let out = auto.run(&data, None, &mut |_| {}).unwrap();
    let notes = out.trace.notes.join("\n");
    assert_eq!(chosen(&out.trace), Some("rl-sum"), "{notes}");
    assert!(
        notes.contains("worse than Richardson-Lucy with its cross-validated stop"),
        "{notes}"
    );
    assert_eq!(
        out.image,
        run(&problem, Method::RlSum).image,
        "auto's output is rl-sum's"
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

/// The photons of the two halves a carried search's note names: the new
/// halves, and the last snapshot's when it grew them.
fn halves_in(notes: &str) -> (Vec<f64>, Option<Vec<f64>>) {
    let numbers = |s: &str| -> Vec<f64> {
        s.split(' ')
            .filter_map(|w| w.trim_matches(|c| c == '(' || c == ')').parse().ok())
            .collect()
    };
    let line = notes
        .lines()
        .find(|l| l.contains("two halves of"))
        .unwrap_or_else(|| panic!("{notes}"));
    let after = line.split("two halves of ").nth(1).unwrap();
    let new = numbers(after.split(" photons").next().unwrap());
    let old = after
        .split("grown from the last snapshot's ")
        .nth(1)
        .map(|s| numbers(s.split(" by thinning").next().unwrap()));
    (new, old)
}

#[test]
fn a_growing_acquisitions_check_keeps_each_photon_in_its_half_and_carries_its_search_on() {
    use scatterscope::reconstruct::guard::CarriedSearch;
    use scatterscope::reconstruct::method::MethodPlan;
    let image = BenchImage {
        name: "text".into(),
        file: None,
        source: "test".into(),
        category: "test".into(),
        split: "tuning".into(),
    };
    let setup = level_setup(&Preset::Paper.setup(), 0.5).unwrap();
    let first = simulate_case(&image, &setup, 384, 0, &CaseSimulation::default()).unwrap();
    let later = simulate_case(&image, &setup, 384, 1, &CaseSimulation::default()).unwrap();
    let mut grown = simulate_case(&image, &setup, 384, 0, &CaseSimulation::default())
        .unwrap()
        .problem;
    grown.counts += &later.problem.counts;
    let carried = CarriedSearch::new(CarriedSearch::LIVE_STEPS);
    let opts = MethodOptions::default();
    let plan = MethodPlan::auto_carrying(&opts, &carried);
    let notes = |p: &Problem| {
        let r = plan.run_within_budget(p, None, &mut |_| {}).unwrap();
        assert!(r.image.iter().all(|v| v.is_finite()));
        r.trace.notes.join("\n")
    };
    // The first snapshot: thinned afresh, its search from the flat object
    // capped at the carried steps.
    let one = notes(&first.problem);
    let (halves, old) = halves_in(&one);
    assert_eq!(old, None, "{one}");
    assert_eq!(
        halves.iter().sum::<f64>(),
        first.problem.counts.sum(),
        "{one}"
    );
    assert!(one.contains("of at most 100)"), "{one}");
    // The next: the same halves and the photons since thinned between
    // them; every photon in one half, each half at least as full.
    let two = notes(&grown);
    let (halves, old) = halves_in(&two);
    let old = old.unwrap_or_else(|| panic!("{two}"));
    assert_eq!(halves.iter().sum::<f64>(), grown.counts.sum(), "{two}");
    assert_eq!(old.iter().sum::<f64>(), first.problem.counts.sum(), "{two}");
    assert!(halves[0] >= old[0] && halves[1] >= old[1], "{two}");
    let since = later.problem.counts.sum();
    for (new, old) in halves.iter().zip(&old) {
        // Binomial thinning of the photons since: within 6 sd of half.
        assert!(
            (new - old - since / 2.0).abs() < 6.0 * (since / 4.0).sqrt(),
            "{two}"
        );
    }
    assert!(two.contains("steps from the flat object"), "{two}");
    // Counts that are not the last snapshot's and more (a new run): thinned
    // afresh.
    let three = notes(&later.problem);
    assert_eq!(halves_in(&three).1, None, "{three}");
}
