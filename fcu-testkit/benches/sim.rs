//! Host speed (product.md §8): one 10 s simulated flight, and one `FlightController::tick`.
//! Run: `cargo bench -p fcu-testkit --bench sim`.

use fcu_core::imu::RawImu;
use fcu_core::rc::PulseBatch;
use fcu_core::{Config, FlightController};
use fcu_testkit::sim::{self, scenario, Profile, RunOptions};

fn main() {
    divan::main();
}

#[divan::bench(args = ["default", "reference"])]
fn flight_10_s_hover(profile: &str) {
    let p = Profile::parse(profile).unwrap_or(Profile::Default);
    let sc = scenario::by_name("hover").unwrap_or_else(|| panic!("hover"));
    let opts = RunOptions { duration_s: Some(10.0), ..RunOptions::default() };
    let log = sim::run(divan::black_box(&sc), p, &opts);
    divan::black_box(log.ok());
}

#[divan::bench(args = ["default", "reference"])]
fn one_tick(bencher: divan::Bencher, profile: &str) {
    let cfg = if profile == "reference" { Config::reference() } else { Config::default() };
    let mut fc = FlightController::new(cfg).unwrap_or_else(|e| panic!("{e}"));
    let imu = RawImu { accel: [12, -30, 8197], gyro: [3, -2, 1] };
    let pulses = PulseBatch::default();
    // Past boot settling and calibration, so the tick runs the whole pipeline.
    for _ in 0..2000 {
        fc.step(imu, &pulses);
    }
    bencher.bench_local(|| {
        let out = fc.tick(divan::black_box(imu), divan::black_box(&pulses));
        divan::black_box(out.compare)
    });
}
