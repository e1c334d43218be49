//! Host speed (`docs/performance.md`): one 10 s simulated flight, and one `FlightController::tick`.
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

/// A controller armed by the stick gesture and flying, with a noisy level IMU: the tick then
/// runs the whole pipeline (radio, supervisor, filters, rate loop, mixer, guard).
struct Flying {
    fc: FlightController,
    noise: u32,
}

impl Flying {
    fn new(cfg: Config) -> Flying {
        let mut f = Flying { fc: FlightController::new(&cfg).unwrap_or_else(|e| panic!("{e}")), noise: 1 };
        let neutral = [5862, 6151, 4000, 6397];
        let arm = [4400, 4400, 4000, 7800];
        let fly = [5862, 6151, 6400, 6397];
        for (widths, ticks) in [(neutral, 2000), (arm, 1000), (neutral, 40), (fly, 400)] {
            for _ in 0..ticks {
                let (imu, pulses) = f.inputs(widths);
                f.fc.tick_and_run_outer(imu, &pulses);
            }
        }
        assert!(f.fc.status().state.motors_may_run(), "the benchmark must measure a flying tick");
        f
    }

    fn inputs(&mut self, widths: [u16; 4]) -> (RawImu, PulseBatch) {
        self.noise = self.noise.wrapping_mul(1_103_515_245).wrapping_add(12_345);
        let d = |shift: u32| ((self.noise >> shift) % 5) as i16 - 2;
        let imu = RawImu { accel: [12 + d(3), -30 + d(7), 8197 + d(11)], gyro: [3 + d(15), -2 + d(19), 1 + d(23)] };
        (imu, PulseBatch { width_counts: widths.map(Some), edge_seen: [true; 4] })
    }
}

fn config(profile: &str) -> Config {
    if profile == "reference" {
        Config::reference()
    } else {
        Config::default()
    }
}

#[divan::bench(args = ["default", "reference"])]
fn one_tick(bencher: divan::Bencher, profile: &str) {
    let mut f = Flying::new(config(profile));
    bencher.bench_local(|| {
        let (imu, pulses) = f.inputs([5862, 6151, 6400, 6397]);
        let out = f.fc.tick(divan::black_box(imu), divan::black_box(&pulses));
        divan::black_box(out.compare)
    });
}

#[divan::bench(args = ["default", "reference"])]
fn one_outer_step(bencher: divan::Bencher, profile: &str) {
    let mut f = Flying::new(config(profile));
    let job = loop {
        let (imu, pulses) = f.inputs([5862, 6151, 6400, 6397]);
        if let Some(job) = f.fc.tick(imu, &pulses).outer_job {
            break job;
        }
    };
    bencher.bench_local(|| f.fc.run_outer(divan::black_box(&job)));
}
