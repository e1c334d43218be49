//! The tick's command stage: the radio, the supervisor and the decision in force, with the
//! sticks the pipeline flies that follow from it.

use super::params::TickParams;
use super::sensors::Sensors;
use super::ForcedRadio;
use crate::rc::{PulseBatch, RadioState, Receiver, StickCounts, Sticks};
use crate::supervisor::{Blockers, Decision, FlightState, Inputs, Supervisor, SupervisorConfig};

/// The supervisor's last decision and what follows from it and the sticks, kept until the
/// supervisor decides again.
#[derive(Clone, Copy, Debug)]
pub(super) struct InForce {
    pub(super) decision: Decision,
    /// The sticks the pipeline flies with: the radio's, or the failsafe's while it holds.
    pub(super) sticks: Sticks,
    /// Whether their throttle is low (motors stopped, integrators and yaw reset).
    pub(super) throttle_low: bool,
}

impl InForce {
    /// A new decision, and what follows from it and the radio's sticks: the one writer of all
    /// three. (Written in place: building a new value and moving it in cost 12 instructions
    /// on every tick the table runs; docs/performance.md, «in place».)
    #[inline(always)]
    fn decided(&mut self, decision: Decision, radio_sticks: Sticks, p: &TickParams) {
        self.decision = decision;
        self.sticks = decision.failsafe_throttle.map_or(radio_sticks, failsafe_sticks);
        self.throttle_low = p.rc.throttle_low(&self.sticks);
    }
}

/// The sticks the failsafe flies with: centred (level, no yaw) and the held throttle.
fn failsafe_sticks(throttle: StickCounts) -> Sticks {
    Sticks { thr: throttle, ..Sticks::default() }
}

/// What the radio said besides the sticks and the link: the reference's gestures as its
/// capture evaluates them, or the replay's flags.
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct RadioFlags {
    /// Set (or clear) the reference's arm latch.
    pub(super) set_armed: Option<bool>,
    /// A calibration is asked for.
    pub(super) calibrate: bool,
}

#[derive(Clone, Debug)]
pub(super) struct Supervision {
    kind: SupervisorConfig,
    receiver: Receiver,
    supervisor: Supervisor,
    in_force: InForce,
}

impl Supervision {
    pub(super) fn new(kind: SupervisorConfig) -> Supervision {
        Supervision {
            kind,
            receiver: Receiver::new(),
            supervisor: Supervisor::new(),
            in_force: InForce {
                decision: Decision {
                    state: FlightState::Calibrating,
                    motors_enabled: false,
                    failsafe_throttle: None,
                    request_calibration: false,
                    blockers: Blockers::default(),
                },
                sticks: Sticks::default(),
                throttle_low: true,
            },
        }
    }

    /// One tick's capture pulses.
    #[inline(always)]
    pub(super) fn receive(&mut self, p: &TickParams, pulses: &PulseBatch) -> RadioFlags {
        let rc = &p.rc;
        let mut cal_gesture = false;
        match self.kind {
            SupervisorConfig::Reference => {
                let supervisor = &mut self.supervisor;
                // The reference evaluates its gestures after every single-channel update.
                self.receiver.update(rc, pulses, |s| cal_gesture |= supervisor.reference_gesture(rc.gesture(s)))
            }
            SupervisorConfig::Safe(_) => self.receiver.update(rc, pulses, |_| {}),
        };
        RadioFlags { set_armed: None, calibrate: cal_gesture }
    }

    /// The radio state given directly (golden replay).
    pub(super) fn receive_forced(&mut self, p: &TickParams, forced: &ForcedRadio) -> RadioFlags {
        self.receiver.force(&p.rc, forced.width_counts, forced.link);
        RadioFlags { set_armed: Some(forced.armed), calibrate: forced.cal_request }
    }

    /// This tick's decision (or the last one, where it stands); whether it asks for a
    /// calibration.
    #[inline(always)]
    pub(super) fn decide(&mut self, p: &TickParams, sensors: &Sensors, tilt_rad: f32, flags: RadioFlags) -> bool {
        let radio = self.receiver.state();
        let (kind, receiver, fault) = (&self.kind, &self.receiver, sensors.fault());
        // Run only when the last decision cannot simply stand.
        let decide = |supervisor: &mut Supervisor| {
            let calibrating = sensors.calibrating();
            match kind {
                SupervisorConfig::Reference => supervisor.decide_reference(radio.link, flags.set_armed, calibrating),
                SupervisorConfig::Safe(safety) => {
                    let sticks = radio.sticks;
                    let inputs = Inputs {
                        link: radio.link,
                        // Only read without a good link.
                        silence_ticks: if radio.link { 0 } else { receiver.silence_ticks(&p.rc) },
                        sticks,
                        gesture: radio.gesture,
                        throttle_low: p.rc.throttle_low(&sticks),
                        calibrated: sensors.calibrated(),
                        calibrating,
                        sensor_fault: fault,
                        tilt_rad,
                    };
                    supervisor.decide_inline(safety, inputs)
                }
            }
        };
        match self.supervisor.decide_or_repeat(receiver.changed(), fault, decide) {
            Some(decision) => {
                self.in_force.decided(decision, radio.sticks, p);
                decision.request_calibration
            }
            None => false,
        }
    }

    pub(super) fn in_force(&self) -> &InForce {
        &self.in_force
    }

    pub(super) fn radio(&self) -> RadioState {
        self.receiver.state()
    }

    #[cfg(feature = "test-switches")]
    pub(super) fn set_table_only(&mut self, table_only: bool) {
        self.supervisor.set_table_only(table_only);
    }
}
