use scatterscope::denoise::prior::PriorSpec;
use scatterscope::reconstruct::input::{InputSpec, load};
use scatterscope::reconstruct::method::{Method, MethodOptions, run_method};
fn run() -> f64 {
    let input = load(
        std::path::Path::new("/tmp/pb/sim/counts.exr"),
        &InputSpec::default(),
    )
    .unwrap();
    let d = PriorSpec::default().build().unwrap();
    let t = std::time::Instant::now();
    run_method(
        &input.problem,
        Method::RlStack,
        None,
        d.as_ref(),
        &MethodOptions::default(),
        None,
        |_| {},
    )
    .unwrap();
    t.elapsed().as_secs_f64()
}
fn main() {
    println!("main thread {:.2}", run());
    println!(
        "spawned thread {:.2}",
        std::thread::spawn(run).join().unwrap()
    );
    println!(
        "spawned 8MB-stack thread {:.2}",
        std::thread::Builder::new()
            .stack_size(8 << 20)
            .spawn(run)
            .unwrap()
            .join()
            .unwrap()
    );
}
