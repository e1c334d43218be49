//! The ground station's commands through the whole controller (flight/gcs.rs's rules).

use crate::flight::{FlightController, ForcedRadio};
use crate::gcs::{Disarm, GcsInput, MotorTest, MotorTestChange, MOTOR_TEST_MAX_DUTY_PCT, RADIO_CALIBRATION_MAX_MS};
use crate::imu::RawImu;
use crate::supervisor::{Blocker, FlightState};
use crate::Config;

/// Level and still, a little noise.
fn still(k: u32) -> RawImu {
    let n = (k % 3) as i16 - 1;
    RawImu { accel: [n, -n, 8197 + n], gyro: [n, -n, n] }
}

/// The bench's radio (the reference transmitter's centres, the throttle low).
const REST: ForcedRadio = ForcedRadio { width_counts: [5862, 6151, 4400, 6397], link: true, armed: false, cal_request: false };
const ARM: ForcedRadio = ForcedRadio { width_counts: [5862 - 1500, 6151 - 1500, 4400, 6397 + 1500], ..REST };
const FLY: ForcedRadio = ForcedRadio { width_counts: [5862, 6151, 6000, 6397], ..REST };

struct Bench {
    fc: FlightController,
    k: u32,
}

impl Bench {
    /// Booted, calibrated, past the boot settling: disarmed with nothing against arming.
    fn new() -> Bench {
        let mut b = Bench { fc: FlightController::new(&Config::default()).unwrap(), k: 0 };
        b.run(&REST, 2400);
        let st = b.fc.status();
        assert_eq!((st.state, st.blockers.is_empty()), (FlightState::Disarmed, true), "{:?}", st.blockers);
        assert!(st.sticks.thr < Config::default().rc.min_throttle && st.sticks.attitude_sticks_centred(), "{:?}", st.sticks);
        b
    }

    fn run(&mut self, radio: &ForcedRadio, ticks: u32) -> [u16; 4] {
        let mut compare = [0; 4];
        for _ in 0..ticks {
            // Every channel's pulse on every tick: the supervisor decides each tick.
            let pulses = crate::rc::PulseBatch { width_counts: radio.width_counts.map(Some), edge_seen: [true; 4] };
            compare = self.fc.tick(still(self.k), &pulses).compare;
            self.k += 1;
        }
        compare
    }

    fn arm(&mut self) {
        self.run(&ARM, 900);
        self.run(&REST, 2);
        assert_eq!(self.fc.status().state, FlightState::Armed, "{:?}", self.fc.status().blockers);
    }
}

fn start(motor: u8, duty_pct: f32, duration_ms: u32) -> GcsInput {
    GcsInput { motor_test: Some(MotorTestChange::Start(MotorTest { motor, duty_pct, duration_ms })), ..GcsInput::default() }
}

/// The compare value of a duty on the default's range.
fn compare_of(duty_pct: f32) -> u16 {
    let m = Config::default().mixer;
    (m.min_compare + (m.max_compare - m.min_compare) * duty_pct * 0.01) as u16
}

#[test]
fn a_motor_test_spins_only_its_motor_capped_and_stops_at_its_deadline() {
    let mut b = Bench::new();
    let off = b.run(&REST, 1);
    assert_eq!(off, [0; 4]);
    b.fc.take_gcs(&start(2, 80.0, 1000));
    let on = b.run(&REST, 1);
    assert_eq!(on, [0, 0, compare_of(MOTOR_TEST_MAX_DUTY_PCT), 0]);
    assert!(on[2] > 0);
    let st = b.fc.status();
    assert_eq!(st.state, FlightState::Disarmed);
    assert!(st.blockers.contains(Blocker::MotorTest));
    assert_eq!(st.compare, on, "telemetry sees the test's output");
    // 1000 ms is 800 ticks: on until then, off after.
    assert_eq!(b.run(&REST, 797), on);
    assert_eq!(b.run(&REST, 3), [0; 4]);
    assert!(!b.fc.status().blockers.contains(Blocker::MotorTest));
}

#[test]
fn a_motor_test_lasts_at_most_three_seconds() {
    let mut b = Bench::new();
    b.fc.take_gcs(&start(0, 5.0, 60_000));
    assert_eq!(b.run(&REST, 2399)[0], compare_of(5.0));
    assert_eq!(b.run(&REST, 2), [0; 4]);
}

#[test]
fn a_motor_test_stops_on_request_and_on_a_stick_move() {
    let mut b = Bench::new();
    b.fc.take_gcs(&start(1, 10.0, 3000));
    assert_eq!(b.run(&REST, 10)[1], compare_of(10.0));
    b.fc.take_gcs(&GcsInput { motor_test: Some(MotorTestChange::Stop), ..GcsInput::default() });
    assert_eq!(b.run(&REST, 1), [0; 4]);

    for moved in [0, 1, 2, 3] {
        let mut radio = REST;
        if let Some(w) = radio.width_counts.get_mut(moved) {
            *w += 400;
        }
        b.fc.take_gcs(&start(3, 10.0, 3000));
        assert_eq!(b.run(&REST, 10)[3], compare_of(10.0));
        assert_eq!(b.run(&radio, 1), [0; 4], "channel {moved} moved");
        assert_eq!(b.run(&REST, 10), [0; 4], "a stopped test stays stopped");
    }
}

#[test]
fn arming_is_refused_while_a_motor_test_runs_and_a_test_is_refused_armed() {
    let mut b = Bench::new();
    b.fc.take_gcs(&start(0, 10.0, 3000));
    b.run(&REST, 1);
    assert!(b.fc.status().blockers.contains(Blocker::MotorTest));
    // The gesture's sticks leave their rest: the test stops at once, and the gesture begun
    // during it never arms, held as long as it may be.
    assert_eq!(b.run(&ARM, 1), [0; 4]);
    b.run(&ARM, 1500);
    assert_eq!(b.fc.status().state, FlightState::Disarmed);
    assert!(b.fc.status().blockers.contains(Blocker::MotorTest));
    b.run(&REST, 2);
    assert_eq!(b.fc.status().state, FlightState::Disarmed);
    // Back at rest, the blocker is gone and a fresh gesture arms.
    assert!(!b.fc.status().blockers.contains(Blocker::MotorTest), "{:?}", b.fc.status().blockers);
    b.arm();

    let mut b = Bench::new();
    b.arm();
    b.fc.take_gcs(&start(0, 10.0, 3000));
    assert_eq!(b.run(&REST, 5), [0; 4], "armed, throttle low: no test");
    b.run(&FLY, 5);
    b.fc.take_gcs(&start(0, 10.0, 3000));
    let flying = b.run(&FLY, 1);
    assert!(flying.iter().all(|&c| c > 0), "the mixer's output, not a test: {flying:?}");
}

#[test]
fn a_save_blocks_arming_until_it_is_done() {
    let mut b = Bench::new();
    b.fc.take_gcs(&GcsInput { saving: true, ..GcsInput::default() });
    b.run(&ARM, 900);
    b.run(&REST, 2);
    assert_eq!(b.fc.status().state, FlightState::Disarmed);
    assert!(b.fc.status().blockers.contains(Blocker::Saving));
    b.fc.take_gcs(&GcsInput::default());
    b.run(&REST, 2);
    assert!(b.fc.status().blockers.is_empty(), "{:?}", b.fc.status().blockers);
    b.arm();
}

#[test]
fn a_pending_reboot_blocks_arming_by_name_until_dropped() {
    let mut b = Bench::new();
    b.fc.take_gcs(&GcsInput { rebooting: true, ..GcsInput::default() });
    b.run(&ARM, 900);
    b.run(&REST, 2);
    assert_eq!(b.fc.status().state, FlightState::Disarmed);
    assert!(b.fc.status().blockers.contains(Blocker::RebootPending), "{:?}", b.fc.status().blockers);
    assert_eq!(Blocker::RebootPending.name(), "reboot-pending");
    b.fc.take_gcs(&GcsInput::default());
    b.run(&REST, 2);
    assert!(b.fc.status().blockers.is_empty(), "{:?}", b.fc.status().blockers);
    b.arm();
}

#[test]
fn a_save_stops_a_motor_test_and_refuses_a_new_one() {
    let mut b = Bench::new();
    b.fc.take_gcs(&start(1, 10.0, 3000));
    assert_eq!(b.run(&REST, 10)[1], compare_of(10.0));
    b.fc.take_gcs(&GcsInput { saving: true, ..GcsInput::default() });
    assert_eq!(b.run(&REST, 1), [0; 4], "the motor must not keep its duty through an erase");
    b.fc.take_gcs(&GcsInput { saving: true, ..start(1, 10.0, 3000) });
    assert_eq!(b.run(&REST, 10), [0; 4], "no test starts while a save is pending");
    b.fc.take_gcs(&GcsInput::default());
    b.fc.take_gcs(&start(1, 10.0, 3000));
    assert_eq!(b.run(&REST, 1)[1], compare_of(10.0), "after the save, a test starts again");
}

#[test]
fn a_ground_disarm_reaches_steady_flight() {
    let mut b = Bench::new();
    b.arm();
    b.run(&FLY, 400);
    b.fc.take_gcs(&GcsInput { disarm: Some(Disarm { forced: false }), ..GcsInput::default() });
    b.run(&FLY, 2);
    assert_eq!(b.fc.status().state, FlightState::Armed, "throttle up: not without the force value");
    b.run(&FLY, 2);
    // Ticks that bring no pulse repeat the steady decision without asking the supervisor:
    // the disarm must reach it all the same.
    let quiet = crate::rc::PulseBatch::default();
    b.fc.tick(still(0), &quiet);
    assert!(b.fc.control_tick.supervision.steady(), "steady flight: {:?}", b.fc.status());
    b.fc.take_gcs(&GcsInput { disarm: Some(Disarm { forced: true }), ..GcsInput::default() });
    let out = b.fc.tick(still(1), &quiet).compare;
    assert_eq!((b.fc.status().state, out), (FlightState::Disarmed, [0; 4]));
}

#[test]
fn an_imu_calibration_runs_again_disarmed_only() {
    let mut b = Bench::new();
    b.fc.take_gcs(&GcsInput { calibrate_imu: true, ..GcsInput::default() });
    b.run(&REST, 1);
    assert_eq!(b.fc.status().state, FlightState::Calibrating);
    b.run(&REST, 2000);
    assert_eq!(b.fc.status().state, FlightState::Disarmed);
    assert!(b.fc.status().calibrated);

    let mut b = Bench::new();
    b.arm();
    b.fc.take_gcs(&GcsInput { calibrate_imu: true, ..GcsInput::default() });
    b.run(&FLY, 5);
    assert_eq!(b.fc.status().state, FlightState::Armed);
    b.run(&REST, 5);
    assert_eq!(b.fc.status().state, FlightState::Armed, "the request was dropped, not kept for later");
}

#[test]
fn a_radio_calibration_blocks_arming_until_ended_or_timed_out() {
    let mut b = Bench::new();
    b.fc.take_gcs(&GcsInput { radio_calibration: Some(true), ..GcsInput::default() });
    // The sticks go through their ranges meanwhile: nothing stops it but an end.
    b.run(&ARM, 900);
    b.run(&FLY, 100);
    b.run(&REST, 2);
    assert!(b.fc.radio_calibration());
    assert_eq!(b.fc.status().state, FlightState::Disarmed);
    assert!(b.fc.status().blockers.contains(Blocker::RadioCalibration));
    b.fc.take_gcs(&GcsInput { radio_calibration: Some(false), ..GcsInput::default() });
    b.run(&REST, 1);
    assert!(!b.fc.radio_calibration() && b.fc.status().blockers.is_empty());

    b.fc.take_gcs(&GcsInput { radio_calibration: Some(true), ..GcsInput::default() });
    let ticks = RADIO_CALIBRATION_MAX_MS * 8 / 10;
    b.run(&REST, ticks - 2);
    assert!(b.fc.radio_calibration());
    b.run(&REST, 3);
    assert!(!b.fc.radio_calibration(), "timed out");
    b.arm();
}

impl FlightController {
    /// A ground station's radio calibration runs (tests).
    fn radio_calibration(&self) -> bool {
        self.control_tick.radio_calibration()
    }
}
