//! The simulated LPS22HB in the loop: stepped with the plant (its height, collective thrust
//! and the air's speed), read by the in-process core on every second outer step (80 Hz) as the
//! firmware reads it (a read clears the data-ready flag), and stuck by a scenario's fault.

use fcu_core::imu::RawImu;
use fcu_testkit::sim::baro_model::BaroModel;
use fcu_testkit::sim::radio_model::TimedEdge;
use fcu_testkit::sim::{self, scenario, ComputerView, FlightComputer, InProcess, RunOptions, SimError};
use fcu_testkit::Profile;

/// A fresh sample the core read, with the plant's height at that step.
#[derive(Clone, Copy, Debug)]
struct Read {
    t_s: f64,
    pressure_counts: i32,
    height_m: f64,
}

/// The in-process core; every fresh sample it takes from the part is recorded, seen on copies
/// of the part before and after its step (a fresh sample taken clears the flag).
struct Recorder {
    inner: InProcess,
    height_m: f64,
    reads: Vec<Read>,
}

impl FlightComputer for Recorder {
    fn tick_hz(&self) -> f64 {
        self.inner.tick_hz()
    }
    fn step(&mut self, _: f64, _: &[TimedEdge], _: RawImu, _: f64) -> Result<[u16; 4], SimError> {
        Err(SimError::Computer("the simulator must hand the barometer to an in-process core".into()))
    }
    fn step_with_baro(
        &mut self,
        t_end_s: f64,
        edges: &[TimedEdge],
        imu: RawImu,
        battery_v: f64,
        baro: &mut BaroModel,
    ) -> Result<[u16; 4], SimError> {
        let offered = baro.clone().read();
        let out = self.inner.step_with_baro(t_end_s, edges, imu, battery_v, baro)?;
        let left = baro.clone().read();
        if offered.pressure_fresh() && !left.pressure_fresh() {
            self.reads.push(Read { t_s: t_end_s, pressure_counts: offered.pressure_counts, height_m: self.height_m });
        }
        Ok(out)
    }
    fn air(&mut self, height_m: f64) -> Result<(), SimError> {
        self.height_m = height_m;
        Ok(())
    }
    fn view(&self) -> ComputerView {
        self.inner.view()
    }
}

fn fly(sc: &scenario::Scenario, seed: u64) -> (sim::FlightLog, Vec<Read>) {
    let cfg = sc.configure(Profile::Default.config()).unwrap_or_else(|e| panic!("{e}"));
    let mut rec = Recorder { inner: InProcess::new(cfg).unwrap_or_else(|e| panic!("{e}")), height_m: 0.0, reads: Vec::new() };
    let opts = RunOptions { seed, ..RunOptions::default() };
    let log = sim::run_with(&mut rec, sc, Profile::Default, &opts).unwrap_or_else(|e| panic!("{e}"));
    (log, rec.reads)
}

fn pa(counts: i32) -> f64 {
    f64::from(counts) * 100.0 / 4096.0
}

#[test]
fn the_core_reads_every_sample_of_the_part_and_its_pressure_follows_the_plants_height() {
    let sc = scenario::by_name("hover").unwrap_or_else(|| panic!("hover"));
    let (log, reads) = fly(&sc, 3);
    // 75 Hz from the first outer step (after the boot's calibration) to the end: every sample
    // reaches the core (80 reads a second).
    let (first_s, last_s) = (reads.first().map_or(0.0, |r| r.t_s), log.rows.last().map_or(0.0, |r| r.t_s));
    let rate_hz = reads.len() as f64 / (last_s - first_s);
    assert!((rate_hz - 75.0).abs() < 0.5, "{rate_hz} fresh samples a second");
    // Read on every second outer step (the firmware's 80 Hz): the reads are whole 12.5 ms apart
    // (read at 160 Hz, 6.25 ms steps, the part's 13.3 ms would leave 18.75 ms gaps).
    let off_grid = reads.windows(2).map(|w| (w[1].t_s - w[0].t_s) * 80.0).filter(|n| (n - n.round()).abs() > 0.05).count();
    assert_eq!(off_grid, 0, "reads off the 80 Hz grid");
    // The height the pressure says, from the mean on the floor before arming, against the
    // plant's: within the installation's errors (offset drift, prop wash up to 15 Pa at full
    // thrust, ground effect, noise: well under a metre) everywhere, and each sample apart.
    let floor: Vec<f64> = reads.iter().filter(|r| r.t_s < scenario::ARM_AT_S).map(|r| pa(r.pressure_counts)).collect();
    let p0 = floor.iter().sum::<f64>() / floor.len() as f64;
    let baro_height = |r: &Read| 44_330.77 * (1.0 - (pa(r.pressure_counts) / p0).powf(0.190_263));
    let worst = reads.iter().map(|r| (baro_height(r) - r.height_m).abs()).fold(0.0, f64::max);
    assert!(worst < 0.8, "barometric height off by {worst:.2} m");
    let hover: Vec<&Read> = reads.iter().filter(|r| (8.0..19.0).contains(&r.t_s)).collect();
    let mean_err = hover.iter().map(|r| baro_height(r) - r.height_m).sum::<f64>() / hover.len() as f64;
    assert!(mean_err.abs() < 0.6, "hover: barometric height off by {mean_err:.2} m on average");
    let distinct = hover.windows(2).filter(|w| w[0].pressure_counts != w[1].pressure_counts).count();
    assert!(distinct > hover.len() * 9 / 10, "a working part's words change with its noise");
}

#[test]
fn a_scenarios_fault_sticks_the_parts_words_and_it_still_flags_new_samples() {
    let mut sc = scenario::by_name("hover").unwrap_or_else(|| panic!("hover"));
    sc.baro_freeze_s = Some(10.0);
    let (_, reads) = fly(&sc, 1);
    let after: Vec<&Read> = reads.iter().filter(|r| r.t_s > 10.1).collect();
    assert!(after.len() as f64 > 75.0 * 10.0, "still flagged as new after the freeze: {}", after.len());
    assert!(after.iter().all(|r| r.pressure_counts == after[0].pressure_counts), "the words changed after the freeze");
    let before: Vec<&Read> = reads.iter().filter(|r| (9.0..10.0).contains(&r.t_s)).collect();
    assert!(before.windows(2).any(|w| w[0].pressure_counts != w[1].pressure_counts));
}

#[test]
fn the_log_carries_the_true_climb_rate_and_the_cores_vertical_report() {
    let sc = scenario::by_name("hover").unwrap_or_else(|| panic!("hover"));
    let log =
        sim::run(&sc, Profile::Default, &RunOptions { duration_s: Some(8.0), ..RunOptions::default() }).unwrap_or_else(|e| panic!("{e}"));
    // The climb rate is the derivative of the logged height.
    let dt = 1.0 / log.tick_hz;
    let worst = log
        .rows
        .windows(2)
        .filter(|w| w[0].alt_m > 0.05)
        .map(|w| ((w[1].alt_m - w[0].alt_m) / dt - 0.5 * (w[0].vertical.climb_m_s + w[1].vertical.climb_m_s)).abs())
        .fold(0.0, f64::max);
    assert!(worst < 0.01, "climb rate against the height's slope: {worst} m/s");
    assert!(log.rows.iter().any(|r| r.vertical.climb_m_s > 0.2), "it climbed");
    assert!(log.rows.iter().all(|r| r.vertical.mode.is_some() && r.vertical.est_alt_m.is_finite()), "the core's report in every row");
}
