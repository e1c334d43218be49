//! The tick's command stage: the radio, the supervisor and the decision in force, with the
//! sticks the pipeline flies that follow from it.

use super::derived::TickParams;
use super::gcs::{Gcs, TestOutput};
use super::in_force::InForce;
use super::sensors::Sensors;
use crate::althold::VerticalCommand;
use crate::gcs::GcsInput;
use crate::rc::{Gesture, PulseBatch, RadioState, Receiver, StickCounts, Sticks, CHANNELS};
use crate::supervisor::{Blockers, Decision, FlightState, Inputs, ReferenceLatch, SafetyConfig, Supervisor, SupervisorConfig};

/// The radio state given directly (golden replay): the reference's `rc_connection_flag`,
/// `rc_enable_motor` and `rc_cal_flag` instead of capture edges.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ForcedRadio {
    pub width_counts: [u16; CHANNELS],
    pub link: bool,
    pub armed: bool,
    pub cal_request: bool,
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

/// Which supervisor decides, with its configuration.
#[derive(Clone, Debug)]
enum Machine {
    Reference(ReferenceLatch),
    Safe { cfg: SafetyConfig, supervisor: Supervisor },
}

/// The radio, the supervisor that decides, and its decision in force.
#[derive(Clone, Debug)]
pub(super) struct Supervision {
    receiver: Receiver,
    machine: Machine,
    in_force: InForce,
    /// Ticks since boot, this one included: the supervisor's clock.
    ticks: u32,
    /// What the ground station asked (the safe supervisor's only).
    gcs: Gcs,
    /// The vertical half's last word: the throttle the hold flies, the failsafe descent's cap,
    /// a landing.
    vertical: VerticalCommand,
    /// Tests only: the supervisor decides every tick, the decision in force never stands.
    #[cfg(feature = "test-switches")]
    table_only: bool,
}

impl Supervision {
    pub(super) fn new(cfg: SupervisorConfig) -> Supervision {
        Supervision {
            receiver: Receiver::new(),
            machine: match cfg {
                SupervisorConfig::Reference => Machine::Reference(ReferenceLatch::default()),
                SupervisorConfig::Safe(cfg) => Machine::Safe { cfg, supervisor: Supervisor::new() },
            },
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
                command_thr: StickCounts::ZERO,
            },
            vertical: VerticalCommand::default(),
            ticks: 0,
            gcs: Gcs::default(),
            #[cfg(feature = "test-switches")]
            table_only: false,
        }
    }

    /// The safe supervisor's numbers in force (tests).
    #[cfg(test)]
    pub(super) fn safety(&self) -> Option<SafetyConfig> {
        match &self.machine {
            Machine::Safe { cfg, .. } => Some(*cfg),
            Machine::Reference(_) => None,
        }
    }

    /// The safe supervisor's new numbers, its state kept. `false` (nothing changed) when the
    /// kind of supervisor would change: only a new controller can do that.
    pub(super) fn set_config(&mut self, cfg: SupervisorConfig) -> bool {
        match (&mut self.machine, cfg) {
            (Machine::Safe { cfg: c, .. }, SupervisorConfig::Safe(new)) => {
                *c = new;
                true
            }
            (Machine::Reference(_), SupervisorConfig::Reference) => true,
            _ => false,
        }
    }

    /// One tick's capture pulses.
    #[inline(always)] // docs/performance.md, «inlined into the tick».
    pub(super) fn receive(&mut self, p: &TickParams, pulses: &PulseBatch) -> RadioFlags {
        let rc = &p.rc;
        match self.machine {
            Machine::Reference(_) => {
                // The reference evaluates its gestures after every single-channel update.
                let (mut arm, mut calibrate) = (false, false);
                self.receiver.update(rc, pulses, |s| {
                    let g = rc.gesture(s);
                    arm |= g == Some(Gesture::Arm);
                    calibrate |= g == Some(Gesture::Calibrate);
                });
                RadioFlags { set_armed: arm.then_some(true), calibrate }
            }
            Machine::Safe { .. } => {
                self.receiver.update(rc, pulses, |_| {});
                RadioFlags::default()
            }
        }
    }

    /// The radio state given directly (golden replay).
    pub(super) fn receive_forced(&mut self, p: &TickParams, forced: &ForcedRadio) -> RadioFlags {
        self.receiver.force(&p.rc, forced.width_counts, forced.link);
        RadioFlags { set_armed: Some(forced.armed), calibrate: forced.cal_request }
    }

    /// This tick's decision, now in force; whether it asks for a calibration.
    #[inline(always)] // docs/performance.md, «inlined into the tick».
    pub(super) fn decide(&mut self, p: &TickParams, sensors: &Sensors, tilt_rad: f32, flags: RadioFlags) -> bool {
        self.ticks = self.ticks.saturating_add(1);
        // In steady flight, with nothing new from the radio and no sensor fault, the decision
        // in force stands: the supervisor would decide it again, the same
        // (`Supervisor::steady`; docs/performance.md, «repeat steady flight»).
        if let Machine::Safe { supervisor, .. } = &self.machine {
            if supervisor.steady() && !self.receiver.changed() && sensors.fault().is_none() && self.repeats_allowed() {
                return false;
            }
        }
        self.decide_now(p, sensors, tilt_rad, flags)
    }

    /// The supervisor decides (a tick that [`decide`](Self::decide) does not find steady).
    #[inline(never)] // docs/performance.md, «repeat steady flight».
    fn decide_now(&mut self, p: &TickParams, sensors: &Sensors, tilt_rad: f32, flags: RadioFlags) -> bool {
        let radio = self.receiver.state();
        let decision = match &mut self.machine {
            Machine::Reference(latch) => latch.decide(radio.link, flags.set_armed, sensors.calibrating()),
            Machine::Safe { cfg, supervisor } => {
                let gcs = self.gcs.commands(self.ticks, &radio.sticks, &p.rc);
                // The throttle flown: the hold's while it flies one (its bottom is the landed
                // drone's, which the automatic disarm counts), else the stick's.
                let flown = Sticks { thr: self.vertical.throttle.unwrap_or(radio.sticks.thr), ..radio.sticks };
                let inputs = Inputs {
                    tick: self.ticks,
                    link: radio.link,
                    // Only read without a good link.
                    silence_ticks: if radio.link { 0 } else { self.receiver.silence_ticks(&p.rc) },
                    sticks: flown,
                    gesture: radio.gesture,
                    throttle_low: p.rc.throttle_low(&flown),
                    calibrated: sensors.calibrated(),
                    calibrating: sensors.calibrating(),
                    sensor_fault: sensors.fault(),
                    tilt_rad,
                    gcs,
                    descent_cap_ticks: self.vertical.descent_cap_ticks,
                    landed: self.vertical.landed,
                };
                let decision = supervisor.decide(cfg, &inputs);
                self.gcs.decided(decision.state);
                decision
            }
        };
        self.in_force.decided(decision, radio.sticks, p, self.vertical.throttle);
        decision.request_calibration
    }

    /// The vertical half's new word (from an outer step's result): the throttle the hold flies
    /// is in force at once; a change the supervisor must see (the throttle flown going low or
    /// coming up, a landing) ends steady flight so that it is decided.
    pub(super) fn set_vertical(&mut self, v: VerticalCommand, p: &TickParams) {
        if v == self.vertical {
            return;
        }
        let f = &mut self.in_force;
        f.sticks.thr = v.throttle.unwrap_or(f.command_thr);
        let low = p.rc.throttle_low(&f.sticks);
        let news = low != f.throttle_low || v.landed != self.vertical.landed;
        f.throttle_low = low;
        self.vertical = v;
        if let (true, Machine::Safe { supervisor, .. }) = (news, &mut self.machine) {
            supervisor.unsteady();
        }
    }

    /// A ground station's input, between ticks. The reference's supervisor takes none.
    pub(super) fn take_gcs(&mut self, input: &GcsInput, p: &TickParams) {
        if let Machine::Safe { supervisor, .. } = &mut self.machine {
            self.gcs.take(input, self.ticks, self.in_force.decision.state, p);
            if self.gcs.disarm_pending() {
                // Steady flight repeats the last decision without asking the supervisor.
                supervisor.unsteady();
            }
        }
    }

    /// The safe supervisor's last decision was steady flight (tests).
    #[cfg(test)]
    pub(super) fn steady(&self) -> bool {
        matches!(&self.machine, Machine::Safe { supervisor, .. } if supervisor.steady())
    }

    /// The motor test's output, while one runs.
    pub(super) fn test_output(&self) -> Option<TestOutput> {
        self.gcs.test_output()
    }

    /// A ground station's radio calibration runs.
    pub(super) fn radio_calibration(&self) -> bool {
        self.gcs.radio_calibration()
    }

    pub(super) fn in_force(&self) -> &InForce {
        &self.in_force
    }

    pub(super) fn radio(&self) -> RadioState {
        self.receiver.state()
    }

    #[cfg(feature = "test-switches")]
    pub(super) fn set_table_only(&mut self, table_only: bool) {
        self.table_only = table_only;
    }

    #[cfg(feature = "test-switches")]
    #[inline(always)] // docs/performance.md, «inlined into the tick».
    fn repeats_allowed(&self) -> bool {
        !self.table_only
    }

    #[cfg(not(feature = "test-switches"))]
    #[inline(always)] // docs/performance.md, «inlined into the tick».
    fn repeats_allowed(&self) -> bool {
        true
    }
}
