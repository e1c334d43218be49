//! The simulator hands a flight computer the drone's height before every step
//! ([`FlightComputer::air`]), so a computer with a barometer model (fcu-pil's) reads the air
//! the plant flies in.

use fcu_core::imu::RawImu;
use fcu_testkit::sim::radio_model::TimedEdge;
use fcu_testkit::sim::{self, scenario, ComputerView, FlightComputer, InProcess, RunOptions, SimError};
use fcu_testkit::Profile;

/// The in-process core, with the heights it was given, one per step.
struct Recorder {
    inner: InProcess,
    heights_m: Vec<f64>,
    pending: Option<f64>,
}

impl FlightComputer for Recorder {
    fn tick_hz(&self) -> f64 {
        self.inner.tick_hz()
    }
    fn step(&mut self, t_end_s: f64, edges: &[TimedEdge], imu: RawImu, battery_v: f64) -> Result<[u16; 4], SimError> {
        let h = self.pending.take().ok_or_else(|| SimError::Computer(format!("no height before the step at {t_end_s} s")))?;
        self.heights_m.push(h);
        self.inner.step(t_end_s, edges, imu, battery_v)
    }
    fn air(&mut self, height_m: f64) -> Result<(), SimError> {
        self.pending = Some(height_m);
        Ok(())
    }
    fn view(&self) -> ComputerView {
        self.inner.view()
    }
}

#[test]
fn every_step_is_given_the_plants_height_first() {
    let profile = Profile::Default;
    let mut rec = Recorder { inner: InProcess::new(profile.config()).unwrap(), heights_m: Vec::new(), pending: None };
    let sc = scenario::by_name("hover").unwrap();
    let opts = RunOptions { seed: 1, duration_s: Some(6.0), ..RunOptions::default() };
    let log = sim::run_with(&mut rec, &sc, profile, &opts).unwrap();
    let logged: Vec<f64> = log.rows.iter().map(|r| r.alt_m).collect();
    assert_eq!(rec.heights_m, logged, "the height given is the one logged for that tick");
    assert!(logged.iter().any(|&h| h > 0.3), "the drone took off");
}
