//! `cargo bench`: the same hot-loop throughputs as `motionlab bench`, printed as a table.
//! Run in release mode (cargo bench does); timing never happens in tests.

fn main() {
    let seconds = std::env::var("MOTIONLAB_BENCH_SECONDS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(1.0);
    for m in motionlab::bench::metrics(seconds) {
        println!("{:<45} {:>14.1}", m.name, m.value);
    }
}
