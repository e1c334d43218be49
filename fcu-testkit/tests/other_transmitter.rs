//! A transmitter that is not the reference's Devo 7E, set up through parameters alone: its
//! channels in another order, the pitch channel reversed, every channel's endpoints at
//! 1000..2000 µs. The simulated pilot flies the usual scenarios; between the simulated
//! receiver and the flight core the pulses become what that transmitter would send. With the
//! parameter file the drone arms by gesture and flies the scenario's criteria; without it, it
//! does not.

use fcu_core::parameters;
use fcu_core::rc::{pulse_width, CaptureEdge, CAPTURE_WRAP, CHANNELS};
use fcu_core::Config;
use fcu_testkit::sim::radio_model::TimedEdge;
use fcu_testkit::sim::{self, metrics, scenario, ComputerView, FlightComputer, InProcess, Profile, RunOptions, SimError};

/// The other transmitter: which input each of the Devo's channels (AIL, ELE, THR, RUD) arrives
/// on, and which are reversed.
const INPUT_OF: [usize; CHANNELS] = [1, 2, 0, 3];
const REVERSED: [bool; CHANNELS] = [false, true, false, false];

/// Its setup, as a ground station would push it (MAVProxy `param load` format).
const PARAMS: &str = "\
# another transmitter: throttle on 1, roll on 2, pitch on 3 (reversed), yaw on 4
RCMAP_THROTTLE 1
RCMAP_ROLL 2
RCMAP_PITCH 3
RCMAP_YAW 4
RC1_MIN 1000
RC1_TRIM 1000
RC1_MAX 2000
RC2_MIN 1000
RC2_TRIM 1500
RC2_MAX 2000
RC3_MIN 1000
RC3_TRIM 1500
RC3_MAX 2000
RC3_REV -1
RC4_MIN 1000
RC4_TRIM 1500
RC4_MAX 2000
";

/// The Devo's width on channel `ch` (counts) as the other transmitter sends the same stick:
/// the stick's travel from the Devo's centre (or bottom), rescaled to 1000..2000 µs.
fn other_width(devo: &Config, ch: usize, w: u32) -> u32 {
    let e = devo.rc.inputs[ch];
    let w = i64::from(w);
    let out = if ch == fcu_core::rc::THR {
        4000 + (w - i64::from(e.min_counts)) * 4000 / 3600
    } else {
        let d = (w - i64::from(e.trim_counts)) * 2000 / 1800;
        if REVERSED[ch] {
            6000 - d
        } else {
            6000 + d
        }
    };
    out.clamp(1, i64::from(CAPTURE_WRAP) - 1) as u32
}

/// The flight core behind the other transmitter: each falling edge moved to give the other
/// transmitter's width, each edge moved to its input.
struct OtherTransmitter {
    inner: InProcess,
    devo: Config,
    rise: [u16; CHANNELS],
    edges: Vec<TimedEdge>,
}

impl FlightComputer for OtherTransmitter {
    fn tick_hz(&self) -> f64 {
        self.inner.tick_hz()
    }

    fn step(&mut self, t_end_s: f64, edges: &[TimedEdge], imu: fcu_core::imu::RawImu, battery_v: f64) -> Result<[u16; 4], SimError> {
        self.edges.clear();
        for e in edges {
            let ch = e.edge.channel;
            let mut capture = e.edge.capture_counts;
            if e.edge.level_high {
                self.rise[ch] = capture;
            } else {
                let w = other_width(&self.devo, ch, pulse_width(self.rise[ch], capture));
                capture = ((u32::from(self.rise[ch]) + w) % CAPTURE_WRAP) as u16;
            }
            self.edges.push(TimedEdge {
                t_s: e.t_s,
                edge: CaptureEdge { channel: INPUT_OF[ch], capture_counts: capture, level_high: e.edge.level_high },
            });
        }
        self.inner.step(t_end_s, &self.edges, imu, battery_v)
    }

    fn view(&self) -> ComputerView {
        self.inner.view()
    }
}

/// The scenario flown through the other transmitter: its log and the criteria it failed.
fn fly(name: &str, cfg: Config) -> (sim::FlightLog, Vec<String>) {
    let sc = scenario::by_name(name).unwrap_or_else(|| panic!("unknown scenario {name}"));
    let mut computer =
        OtherTransmitter { inner: InProcess::new(cfg).unwrap(), devo: Config::default(), rise: [0; CHANNELS], edges: Vec::new() };
    let log = sim::run_with(&mut computer, &sc, Profile::Default, &RunOptions::default()).unwrap_or_else(|e| panic!("{e}"));
    let failed =
        metrics::check_all(&log, &sc).into_iter().filter(|v| !v.passed).map(|v| format!("{} — {}", v.criterion, v.detail)).collect();
    (log, failed)
}

#[test]
fn another_transmitter_flies_once_set_up_by_parameters() {
    let cfg = parameters::apply_file(&Config::default(), PARAMS).unwrap_or_else(|e| panic!("{e:?}"));
    for name in ["hover", "steps", "yaw"] {
        let (log, failed) = fly(name, cfg);
        assert!(failed.is_empty(), "{name}: {failed:#?}");
        // The sticks read as the Devo's do: the roll and pitch targets of the same flight
        // with the Devo itself, to the rounding of a count or two (20° / 1800 a count).
        let sc = scenario::by_name(name).unwrap();
        let devo = sim::run(&sc, Profile::Default, &RunOptions::default()).unwrap();
        let worst = log
            .rows
            .iter()
            .zip(&devo.rows)
            .map(|(a, b)| (a.roll_target_deg - b.roll_target_deg).abs().max((a.pitch_target_deg - b.pitch_target_deg).abs()))
            .fold(0.0, f64::max);
        assert!(worst < 0.05, "{name}: targets differ by up to {worst}°");
    }
}

#[test]
fn without_its_parameters_the_same_transmitter_does_not_fly() {
    assert!(!fly("hover", Config::default()).1.is_empty());
}
