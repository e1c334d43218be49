//! The link task ([`fcu_gcs::Service`]) in front of the real control loop: a reboot or a save
//! asked for under a flood of requests, while the pilot makes the arm gesture.

#[path = "../../fcu-link/tests/support/mod.rs"]
mod support;

use fcu_core::flight::FlightController;
use fcu_core::imu::RawImu;
use fcu_core::rc::PulseBatch;
use fcu_core::supervisor::{Blocker, FlightState};
use fcu_core::Config;
use fcu_gcs::{Due, Observed, Service};
use fcu_link::LinkConfig;
use mavlink::dialects::common::{self, MavCmd, MavResult};
use support::*;

/// Control ticks per 5 ms link period, at 800 Hz.
const TICKS_PER_PERIOD: u32 = 4;
const PERIOD_MS: u32 = 5;
/// What 115200 baud sends in a period (11.52 bytes per ms).
const UART_BYTES_PER_PERIOD: usize = 57;
/// The firmware's UART queue.
const UART_QUEUE_BYTES: usize = 1024;

/// The bench's radio (the reference transmitter's centres), at rest with the throttle low, and
/// the arm gesture (yaw right, throttle low, roll and pitch to their corners).
const REST: [u16; 4] = [5862, 6151, 4400, 6397];
const ARM: [u16; 4] = [5862 - 1500, 6151 - 1500, 4400, 6397 + 1500];

struct Board {
    fc: FlightController,
    service: Service<512>,
    now_ms: u32,
    ticks: u32,
    uart_queue: usize,
    sent: Vec<u8>,
}

impl Board {
    fn new() -> Board {
        let cfg = Config::default();
        Board {
            fc: FlightController::new(&cfg).unwrap(),
            service: Service::new(cfg, &Config::DEFAULT, fcu_params::snapshot::Source::NoSnapshot, LinkConfig::DEFAULT),
            now_ms: 0,
            ticks: 0,
            uart_queue: 0,
            sent: Vec::new(),
        }
    }

    /// One link period: the control loop's ticks with `radio`, then the link task as the
    /// firmware runs it. Returns what was due.
    fn period(&mut self, radio: [u16; 4], rx: &[u8]) -> Due {
        for _ in 0..TICKS_PER_PERIOD {
            let n = (self.ticks % 3) as i16 - 1;
            let imu = RawImu { accel: [n, -n, 8197 + n], gyro: [n, -n, n] };
            let pulses = PulseBatch { width_counts: radio.map(Some), edge_seen: [true; 4] };
            self.fc.tick_and_run_outer(imu, &pulses);
            self.ticks += 1;
        }
        self.now_ms += PERIOD_MS;
        let observed = Observed { status: self.fc.status(), battery_mv: 3900, rc_widths_counts: radio };
        self.service.observe(self.now_ms, &observed);
        self.service.receive(self.now_ms, rx);
        let to = self.service.period(self.now_ms);
        if let Some(change) = to.config {
            self.fc.take_change(&change).unwrap();
        }
        if let Some(input) = to.gcs {
            self.fc.take_gcs(&input);
        }
        // The UART sends what a period allows; the link fills what room it has.
        let sending = self.uart_queue.min(UART_BYTES_PER_PERIOD);
        self.uart_queue -= sending;
        let mut out = [0u8; 128];
        let room = (UART_QUEUE_BYTES - self.uart_queue).min(out.len());
        let n = self.service.poll_tx(&mut out[..room]);
        self.sent.extend_from_slice(&out[..n]);
        self.uart_queue += n;
        self.service.due(self.now_ms, self.uart_queue == 0, true)
    }

    fn state(&self) -> FlightState {
        self.fc.status().state
    }

    /// What the UART sent, the frames it finished (the last may be half-way).
    fn sent(&self) -> Vec<Sent> {
        let mut end = 0;
        while let Some(&len) = self.sent.get(end + 1) {
            let next = end + 12 + usize::from(len);
            if next > self.sent.len() {
                break;
            }
            end = next;
        }
        decode_all(&self.sent[..end])
    }
}

/// About 60 PARAM_REQUEST_READs every 100 ms: three a period.
fn flood() -> Vec<u8> {
    let mut bytes = Vec::new();
    for index in 0..3 {
        bytes.extend(v2(&common::PARAM_REQUEST_READ_DATA {
            param_index: index,
            target_system: 1,
            target_component: 1,
            param_id: name16(""),
        }));
    }
    bytes
}

fn reboot() -> Vec<u8> {
    v2(&command_long(MavCmd::MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN, [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]))
}

/// Boots and waits past the calibration and the boot settling (2.2 s of board time).
fn booted() -> Board {
    let mut b = Board::new();
    while b.now_ms < 2200 {
        assert_eq!(b.period(REST, &flood()), Due::Nothing);
    }
    assert_eq!(b.state(), FlightState::Disarmed);
    b
}

#[test]
fn a_reboot_asked_under_a_flood_while_the_pilot_arms_resets_the_board_disarmed_and_soon() {
    let mut b = booted();
    let mut rx = flood();
    rx.extend(reboot());
    let mut due = b.period(REST, &rx);
    let mut rebooted_at = None;
    // The pilot starts the arm gesture right after and holds it; the ground station keeps
    // flooding.
    for _ in 0..400 {
        if due == Due::Reboot {
            rebooted_at = Some(b.now_ms);
            break;
        }
        assert_ne!(b.state(), FlightState::Armed, "armed at {} ms with a reboot pending", b.now_ms);
        if std::env::var("DEBUG_SERVICE").is_ok() {
            eprintln!(
                "{} {:?} {:?} asked={} q={}",
                b.now_ms,
                b.state(),
                b.fc.status().blockers,
                b.service.station().reboot_asked(),
                b.uart_queue
            );
        }
        due = b.period(ARM, &flood());
    }
    let at = rebooted_at.expect("the reboot was carried out");
    assert!(at < 2200 + 500, "rebooted at {at} ms: a flood must not hold it off");
    assert_eq!(b.state(), FlightState::Disarmed);
    assert!(b.fc.status().blockers.contains(Blocker::RebootPending), "{:?}", b.fc.status().blockers);
    // Its acknowledgement left before the reset.
    let sent = b.sent();
    assert!(acks(&sent).contains(&(246, MavResult::MAV_RESULT_ACCEPTED)), "{:?}", acks(&sent));
}

#[test]
fn a_reboot_asked_while_armed_is_refused_and_never_carried_out() {
    let mut b = booted();
    for _ in 0..300 {
        b.period(ARM, &flood());
    }
    for _ in 0..2 {
        b.period(REST, &flood());
    }
    assert_eq!(b.state(), FlightState::Armed);
    let mut rx = flood();
    rx.extend(reboot());
    let mut dues = vec![b.period(REST, &rx)];
    for _ in 0..2000 {
        dues.push(b.period(REST, &flood()));
    }
    assert!(dues.iter().all(|&d| d == Due::Nothing));
    let sent = b.sent();
    assert!(acks(&sent).contains(&(246, MavResult::MAV_RESULT_TEMPORARILY_REJECTED)), "{:?}", acks(&sent));
}

#[test]
fn a_save_asked_under_a_flood_is_written_disarmed_after_its_ack() {
    let mut b = booted();
    let mut rx = flood();
    rx.extend(v2(&param_set("ANGLE_MAX", 25.0)));
    rx.extend(v2(&command_long(MavCmd::MAV_CMD_PREFLIGHT_STORAGE, [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0])));
    let mut due = b.period(REST, &rx);
    let mut saved_at = None;
    for _ in 0..200 {
        if due == Due::Save {
            saved_at = Some(b.now_ms);
            assert_eq!(b.state(), FlightState::Disarmed);
            let sent = b.sent();
            assert!(acks(&sent).contains(&(245, MavResult::MAV_RESULT_ACCEPTED)), "the ACK is out first: {:?}", b.service.link().stats());
            b.service.saved(true);
            break;
        }
        due = b.period(REST, &flood());
    }
    let at = saved_at.expect("the save was carried out");
    assert!(at < 2200 + 500, "saved at {at} ms: a flood must not hold it off");
    // Then the link speaks again, and arming is allowed.
    for _ in 0..40 {
        assert_eq!(b.period(REST, &flood()), Due::Nothing);
    }
    assert!(texts(&b.sent()).iter().any(|t| t == "parameters saved"));
    assert!(b.fc.status().blockers.is_empty(), "{:?}", b.fc.status().blockers);
}

#[test]
fn the_link_alone_cannot_keep_a_motor_spinning_past_the_ticks_deadline() {
    let mut b = booted();
    // A minute asked, the ground station's heartbeat every second: nothing on the link's side
    // ends the test, so only the tick's deadline can.
    let start = v2(&command_long(MavCmd::MAV_CMD_DO_MOTOR_TEST, [2.0, 0.0, 10.0, 60.0, 0.0, 0.0, 0.0]));
    b.period(REST, &start);
    let started_ms = b.now_ms;
    let heartbeat = v2(&common::HEARTBEAT_DATA::DEFAULT);
    let mut last_spinning_ms = None;
    while b.now_ms < started_ms + 10_000 {
        let rx = if b.now_ms.is_multiple_of(1000) { heartbeat.clone() } else { Vec::new() };
        b.period(REST, &rx);
        let compare = b.fc.status().compare;
        assert_eq!((compare[0], compare[2], compare[3]), (0, 0, 0), "only motor 2");
        if compare[1] > 0 {
            last_spinning_ms = Some(b.now_ms);
        }
    }
    assert!(texts(&b.sent()).iter().all(|t| !t.starts_with("Motor test stopped")), "the link asked no stop");
    let ran_ms = last_spinning_ms.expect("the motor spun") - started_ms;
    let deadline_ms = fcu_core::gcs::MOTOR_TEST_MAX_MS;
    assert!((deadline_ms - 2 * PERIOD_MS..=deadline_ms + PERIOD_MS).contains(&ran_ms), "spun for {ran_ms} ms");
}
