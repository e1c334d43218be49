//! The supervisor: the one place that decides whether the motors may turn.
//!
//! Two kinds, chosen by [`SupervisorConfig`]:
//! - [`SupervisorConfig::Reference`]: the ST reference's behaviour (B8–B11, B16): the arm
//!   gesture latches "armed" for ever, motors run while armed and any edge arrived in the
//!   last 31 ms, no failsafe, calibration on the gesture at any time.
//! - [`SupervisorConfig::Safe`]: the product's safety layer (`docs/safety.md`), a state machine
//!   whose table is `Supervisor::decide_by_table` (entered through [`Supervisor::decide`]). Every number is a field of [`SafetyConfig`], in
//!   control ticks.

use crate::imu::SensorFault;
use crate::rc::{Gesture, StickCounts, Sticks};

/// Numbers of the safety layer, in control ticks (800 per second in the default profile).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SafetyConfig {
    /// The arm gesture must be held this long on a good link, then released (1.0 s).
    pub arm_hold_ticks: u32,
    /// The disarm gesture must be held this long (1.0 s).
    pub disarm_hold_ticks: u32,
    /// Armed with the throttle low this long disarms (5 s).
    pub auto_disarm_ticks: u32,
    /// Lost time, added up over the flight, at which stage 2 turns the motors off and disarms
    /// (1.0 s). Each loss counts from the last pulse of the channel that fell silent first
    /// ([`Inputs::silence_ticks`]), so a single loss reaches stage 2 exactly this long after
    /// that pulse; the link is declared lost (stage 1) after the radio's channel timeout.
    pub failsafe_off_ticks: u32,
    /// A good link must last this long before stage 1 hands control back (1.0 s): a link
    /// that delivers a couple of frames now and then never hands it back. A configuration
    /// must make it longer than the radio's channel timeout (`Config::validate`): one frame
    /// keeps the link good for that long.
    pub recovery_ticks: u32,
    /// Lost time is forgotten slowly, never reset by a recovery: one lost tick for every this
    /// many ticks flown under stick control after control was handed back (4: one second of
    /// loss takes four seconds of good flight to forget).
    pub loss_forget_ticks: u32,
    /// Arming is refused beyond this tilt from level, rad (25°).
    pub max_arm_tilt_rad: f32,
    /// Arming is refused during the first ticks after boot (2 s).
    pub boot_settle_ticks: u32,
}

impl SafetyConfig {
    pub const DEFAULT: SafetyConfig = SafetyConfig {
        arm_hold_ticks: 800,
        disarm_hold_ticks: 800,
        auto_disarm_ticks: 4000,
        failsafe_off_ticks: 800,
        recovery_ticks: 800,
        loss_forget_ticks: 4,
        max_arm_tilt_rad: 0.436_332_3,
        boot_settle_ticks: 1600,
    };

    /// Every number can work on its own; `Config::validate` adds the checks against the
    /// radio's channel timeout.
    pub fn is_valid(&self) -> bool {
        self.arm_hold_ticks > 0
            && self.disarm_hold_ticks > 0
            && self.auto_disarm_ticks > 0
            && self.failsafe_off_ticks > 0
            && self.recovery_ticks > 0
            && self.loss_forget_ticks > 0
            && self.max_arm_tilt_rad.is_finite()
            && self.max_arm_tilt_rad > 0.0
    }
}

/// Which supervisor runs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum SupervisorConfig {
    Reference,
    Safe(SafetyConfig),
}

/// The supervisor's state, reported by name in telemetry and the simulator's log.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FlightState {
    /// Motors off; arming possible once no blocker holds.
    Disarmed,
    /// The arm gesture is being held (or was held long enough and awaits release).
    Arming,
    /// Motors follow the sticks (and stop while the throttle is low).
    Armed,
    /// Link lost while armed: level, yaw rate 0, throttle held but never raised.
    FailsafeLevel,
    /// Link lost for 1 s in total: motors off, disarmed; the link must return and a full
    /// arming procedure follow.
    FailsafeOff,
    /// Averaging sensor offsets; motors off.
    Calibrating,
    /// A sensor fault was seen: motors off until reset.
    Fault,
}

impl FlightState {
    /// Every state, in declaration order.
    pub const ALL: [FlightState; 7] = [
        FlightState::Disarmed,
        FlightState::Arming,
        FlightState::Armed,
        FlightState::FailsafeLevel,
        FlightState::FailsafeOff,
        FlightState::Calibrating,
        FlightState::Fault,
    ];

    /// The state a [`FlightState::name`] names (telemetry and logs print states by name).
    pub fn from_name(name: &str) -> Option<FlightState> {
        FlightState::ALL.into_iter().find(|s| s.name() == name)
    }

    pub fn name(self) -> &'static str {
        match self {
            FlightState::Disarmed => "disarmed",
            FlightState::Arming => "arming",
            FlightState::Armed => "armed",
            FlightState::FailsafeLevel => "failsafe1",
            FlightState::FailsafeOff => "failsafe2",
            FlightState::Calibrating => "calibrating",
            FlightState::Fault => "fault",
        }
    }

    /// True in the states where the motors may turn (subject to the throttle-low cut).
    pub fn motors_may_run(self) -> bool {
        matches!(self, FlightState::Armed | FlightState::FailsafeLevel)
    }
}

/// A reason arming is refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u16)]
pub enum Blocker {
    NotCalibrated = 1 << 0,
    Calibrating = 1 << 1,
    LinkNotGood = 1 << 2,
    ThrottleNotLow = 1 << 3,
    NotLevel = 1 << 4,
    Failsafe = 1 << 5,
    SensorFault = 1 << 6,
    BootSettling = 1 << 7,
    GestureNotReleased = 1 << 8,
}

impl Blocker {
    pub const ALL: [Blocker; 9] = [
        Blocker::NotCalibrated,
        Blocker::Calibrating,
        Blocker::LinkNotGood,
        Blocker::ThrottleNotLow,
        Blocker::NotLevel,
        Blocker::Failsafe,
        Blocker::SensorFault,
        Blocker::BootSettling,
        Blocker::GestureNotReleased,
    ];

    pub fn name(self) -> &'static str {
        match self {
            Blocker::NotCalibrated => "not-calibrated",
            Blocker::Calibrating => "calibrating",
            Blocker::LinkNotGood => "link-not-good",
            Blocker::ThrottleNotLow => "throttle-not-low",
            Blocker::NotLevel => "not-level",
            Blocker::Failsafe => "failsafe",
            Blocker::SensorFault => "sensor-fault",
            Blocker::BootSettling => "boot-settling",
            Blocker::GestureNotReleased => "gesture-not-released",
        }
    }
}

/// A set of [`Blocker`]s.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Blockers(pub u16);

impl Blockers {
    pub fn insert(&mut self, b: Blocker) {
        self.0 |= b as u16;
    }

    pub fn contains(self, b: Blocker) -> bool {
        self.0 & (b as u16) != 0
    }

    pub fn is_empty(self) -> bool {
        self.0 == 0
    }

    pub fn iter(self) -> impl Iterator<Item = Blocker> {
        Blocker::ALL.into_iter().filter(move |b| self.contains(*b))
    }
}

/// What the supervisor sees each tick.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Inputs {
    pub link: bool,
    pub sticks: Sticks,
    /// The gesture the sticks make this tick (only meaningful with a good link).
    pub gesture: Option<Gesture>,
    pub throttle_low: bool,
    /// A calibration has passed since boot.
    pub calibrated: bool,
    /// A calibration (boot or requested) is averaging.
    pub calibrating: bool,
    pub sensor_fault: Option<SensorFault>,
    /// Tilt from level of the latest estimate, rad.
    pub tilt_rad: f32,
    /// Ticks since the last accepted pulse of the channel heard from longest ago (the link is
    /// good while it is below the channel timeout). Read only while the link is not good: lost
    /// time counts from that pulse.
    pub silence_ticks: u32,
}

impl Inputs {
    /// On the bench and ready: a good link, sticks centred with the throttle low, calibrated,
    /// level, no fault, no gesture.
    pub const READY: Inputs = Inputs {
        link: true,
        silence_ticks: 0,
        sticks: Sticks::new(0, 0, 0, 0),
        gesture: None,
        throttle_low: true,
        calibrated: true,
        calibrating: false,
        sensor_fault: None,
        tilt_rad: 0.0,
    };
}

/// What the supervisor decided for this tick.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Decision {
    pub state: FlightState,
    /// The motors may run this tick (the pipeline still cuts them while the throttle is low).
    pub motors_enabled: bool,
    /// Stage-1 failsafe: level targets, zero yaw rate and this throttle instead of the sticks.
    pub failsafe_throttle: Option<StickCounts>,
    /// Start a calibration now.
    pub request_calibration: bool,
    pub blockers: Blockers,
}

/// The supervisor's memory.
#[derive(Clone, Debug, PartialEq)]
pub struct Supervisor {
    state: FlightState,
    /// Ticks the current gesture (arm or disarm) has been held.
    hold_ticks: u32,
    /// The arm/disarm/calibrate gestures were let go since the last one acted (and since the
    /// link came up): a gesture held through a reconnect or an arm must not act again.
    released: bool,
    /// Lost time accumulated since the arming (see [`SafetyConfig::failsafe_off_ticks`] and
    /// [`loss_forget_ticks`](SafetyConfig::loss_forget_ticks)), as of `forgetting_since`.
    lost_ticks: u32,
    /// Boot tick from which the lost time is being forgotten (the arming or the last hand-back).
    forgetting_since: u32,
    /// Consecutive ticks with a good link, up to this one.
    good_ticks: u32,
    low_throttle_ticks: u32,
    boot_ticks: u32,
    last_good_throttle: StickCounts,
    fault: Option<SensorFault>,
    /// Reference latch (the reference has no disarm).
    reference_armed: bool,
    /// The last step was steady flight (see [`decide_in_flight`](Self::decide_in_flight)).
    steady: bool,
    /// Tests only: every step runs the full table (no steady-flight shortcut, no repeat).
    #[cfg(feature = "test-switches")]
    table_only: bool,
}

impl Default for Supervisor {
    fn default() -> Self {
        Supervisor::new()
    }
}

impl Supervisor {
    pub fn new() -> Self {
        Supervisor {
            state: FlightState::Calibrating,
            hold_ticks: 0,
            released: false,
            lost_ticks: 0,
            forgetting_since: 0,
            good_ticks: 0,
            low_throttle_ticks: 0,
            boot_ticks: 0,
            last_good_throttle: StickCounts::ZERO,
            fault: None,
            reference_armed: false,
            steady: false,
            #[cfg(feature = "test-switches")]
            table_only: false,
        }
    }

    pub fn state(&self) -> FlightState {
        self.state
    }

    /// The reference's arm latch, set by the arm gesture (after any single-channel update).
    pub fn reference_gesture(&mut self, g: Option<Gesture>) -> bool {
        if g == Some(Gesture::Arm) {
            self.reference_armed = true;
        }
        g == Some(Gesture::Calibrate)
    }

    /// The reference's supervisor: armed latch, motors while the link is up.
    pub fn decide_reference(&mut self, link: bool, armed_override: Option<bool>, calibrating: bool) -> Decision {
        self.steady = false;
        if let Some(a) = armed_override {
            self.reference_armed = a;
        }
        self.state = if calibrating && !self.reference_armed {
            FlightState::Calibrating
        } else if self.reference_armed {
            FlightState::Armed
        } else {
            FlightState::Disarmed
        };
        Decision {
            state: self.state,
            motors_enabled: link && self.reference_armed,
            failsafe_throttle: None,
            request_calibration: false,
            blockers: Blockers::default(),
        }
    }

    fn blockers(&self, cfg: &SafetyConfig, i: &Inputs) -> Blockers {
        let mut b = Blockers::default();
        if !i.calibrated {
            b.insert(Blocker::NotCalibrated);
        }
        if i.calibrating {
            b.insert(Blocker::Calibrating);
        }
        if !i.link {
            b.insert(Blocker::LinkNotGood);
        }
        if !i.throttle_low {
            b.insert(Blocker::ThrottleNotLow);
        }
        if !(i.tilt_rad.is_finite() && i.tilt_rad <= cfg.max_arm_tilt_rad) {
            b.insert(Blocker::NotLevel);
        }
        if matches!(self.state, FlightState::FailsafeLevel | FlightState::FailsafeOff) {
            b.insert(Blocker::Failsafe);
        }
        if self.fault.is_some() || i.sensor_fault.is_some() {
            b.insert(Blocker::SensorFault);
        }
        if self.boot_ticks < cfg.boot_settle_ticks {
            b.insert(Blocker::BootSettling);
        }
        if !self.released {
            b.insert(Blocker::GestureNotReleased);
        }
        b
    }

    /// One tick of the safety layer. The `match` is the state table; every arm has tests
    /// named after its rule in `tests::`.
    pub fn decide(&mut self, cfg: &SafetyConfig, i: &Inputs) -> Decision {
        self.decide_inline(cfg, *i)
    }

    /// Tests only: with `true`, every step runs the full state table — no steady-flight
    /// shortcut, no repeat — so that a test can fly two controllers, one without the
    /// shortcuts, and compare them tick by tick.
    #[cfg(feature = "test-switches")]
    pub fn set_table_only(&mut self, table_only: bool) {
        self.table_only = table_only;
    }

    #[cfg(feature = "test-switches")]
    #[inline(always)]
    fn shortcuts_allowed(&self) -> bool {
        !self.table_only
    }

    #[cfg(not(feature = "test-switches"))]
    #[inline(always)]
    fn shortcuts_allowed(&self) -> bool {
        true
    }

    /// [`decide`](Self::decide) with the inputs by value, for the 800 Hz path: inlined there, the
    /// steady-flight test reads the few inputs it needs where they are, and the full `Inputs`
    /// is only assembled in memory when the table has to run.
    #[inline(always)]
    pub fn decide_inline(&mut self, cfg: &SafetyConfig, i: Inputs) -> Decision {
        if self.state == FlightState::Armed
            && i.link
            && i.gesture.is_none()
            && !i.throttle_low
            && i.sensor_fault.is_none()
            && self.fault.is_none()
            && cfg.auto_disarm_ticks > 0
            && self.shortcuts_allowed()
        {
            return self.decide_in_flight(&i);
        }
        // By value: the caller assembles the inputs at this call, on the table's path only.
        self.decide_by_table(cfg, i)
    }

    /// The 800 Hz path's call: `None` when this tick's decision is the last one's (the caller
    /// keeps it and everything it derived from it), else the decision `decide` takes (the
    /// caller's [`decide_inline`](Self::decide_inline) or [`decide_reference`](Self::decide_reference),
    /// assembling the inputs only then).
    ///
    /// Why a repeat is exact: steady flight (`decide_in_flight`, the table's `Armed` line) reads
    /// only the link, the gesture, the throttle and the sensor fault among the inputs. When the
    /// last tick was steady flight, `radio_changed` is false (link, sticks and so gesture and
    /// throttle are the last tick's) and there is no sensor fault, this tick is steady flight
    /// too with the same decision; only the boot and good-link counters move. The other inputs
    /// (tilt, calibration flags, silence) may differ: steady flight does not read them. (The
    /// reference's supervisor never flies steady, so it never repeats.)
    /// `the_flight_shortcut_decides_exactly_as_the_table` checks this on random input
    /// sequences, and `fcu-testkit/tests/shortcuts.rs` on whole flights.
    #[inline(always)]
    pub fn decide_or_repeat(
        &mut self,
        radio_changed: bool,
        sensor_fault: Option<SensorFault>,
        decide: impl FnOnce(&mut Supervisor) -> Decision,
    ) -> Option<Decision> {
        if self.can_repeat(radio_changed, sensor_fault) {
            self.boot_ticks = self.boot_ticks.saturating_add(1);
            self.good_ticks = self.good_ticks.saturating_add(1);
            None
        } else {
            Some(decide(self))
        }
    }

    /// [`decide_by_table`](Self::decide_by_table) in the state the 800 Hz path is in almost every tick:
    /// armed on a good link, throttle up, no gesture, no fault. The table's every line for
    /// those inputs, and nothing else: the `Armed` arm without its branches (the throttle is
    /// up, so the auto-disarm count restarts and cannot reach its non-zero limit), no
    /// transition, the gesture released, the throttle remembered. The test
    /// `the_flight_shortcut_decides_exactly_as_the_table` compares the two on random input
    /// sequences.
    fn decide_in_flight(&mut self, i: &Inputs) -> Decision {
        self.boot_ticks = self.boot_ticks.saturating_add(1);
        self.good_ticks = self.good_ticks.saturating_add(1);
        self.low_throttle_ticks = 0;
        self.hold_ticks = 0;
        self.last_good_throttle = i.sticks.thr;
        self.released = true;
        self.steady = true;
        Decision {
            state: FlightState::Armed,
            motors_enabled: true,
            failsafe_throttle: None,
            request_calibration: false,
            blockers: Blockers::default(),
        }
    }

    /// Whether [`decide_or_repeat`](Self::decide_or_repeat) may repeat the last decision (no side
    /// effect).
    #[inline(always)]
    fn can_repeat(&self, radio_changed: bool, sensor_fault: Option<SensorFault>) -> bool {
        self.steady && !radio_changed && sensor_fault.is_none() && self.shortcuts_allowed()
    }

    /// The state table, for any state and inputs.
    #[inline(never)]
    fn decide_by_table(&mut self, cfg: &SafetyConfig, i: Inputs) -> Decision {
        let i = &i;
        self.steady = false;
        self.boot_ticks = self.boot_ticks.saturating_add(1);
        if let Some(f) = i.sensor_fault {
            // Latched until reset: motors off, disarmed.
            self.fault.get_or_insert(f);
        }
        // Lost time: a loss counts from the last pulse of the channel that fell silent first,
        // and every tick of that silence counts once. A tick without a good link adds the
        // silence up to it, except what an earlier tick without a good link already counted:
        // the first tick of a loss adds the channel timeout (or the good ticks since the last
        // loss, if fewer), each further tick one. It adds up over the flight and is forgotten
        // only slowly once control is back: a flapping link cannot keep the motors running.
        let mut lost_now = 0;
        if i.link {
            self.good_ticks = self.good_ticks.saturating_add(1);
        } else {
            lost_now = i.silence_ticks.min(self.good_ticks.saturating_add(1)).max(1);
            self.good_ticks = 0;
            if self.state == FlightState::FailsafeLevel {
                self.lost_ticks = self.lost_ticks.saturating_add(lost_now);
            }
        }
        let gesture = if i.link { i.gesture } else { None };
        let mut request_calibration = false;

        let next = match self.state {
            _ if self.fault.is_some() => FlightState::Fault,
            FlightState::Fault => FlightState::Fault,
            FlightState::Calibrating => {
                if i.calibrating {
                    FlightState::Calibrating
                } else {
                    FlightState::Disarmed
                }
            }
            FlightState::Disarmed => match gesture {
                Some(Gesture::Calibrate) if self.released => {
                    self.released = false;
                    request_calibration = true;
                    FlightState::Calibrating
                }
                Some(Gesture::Arm) if self.released && without(self.blockers(cfg, i), Blocker::GestureNotReleased).is_empty() => {
                    self.hold_ticks = 1;
                    FlightState::Arming
                }
                _ => FlightState::Disarmed,
            },
            FlightState::Arming => {
                let others = without(self.blockers(cfg, i), Blocker::GestureNotReleased);
                if gesture == Some(Gesture::Arm) {
                    self.hold_ticks = self.hold_ticks.saturating_add(1);
                    if others.is_empty() {
                        FlightState::Arming
                    } else {
                        // A blocker during the hold aborts it; the gesture must be let go.
                        self.released = false;
                        FlightState::Disarmed
                    }
                } else if self.hold_ticks >= cfg.arm_hold_ticks && others.is_empty() {
                    // Let go after a full hold, nothing against it: armed once every stick is
                    // back in a safe place (the throttle low is a blocker already). Until then
                    // keep waiting: arming with the sticks still deflected would take off
                    // rolled and yawing (a nudge of the throttle used to count as the release).
                    if i.sticks.attitude_sticks_centred() {
                        self.low_throttle_ticks = 0;
                        // A new flight starts with no lost time.
                        self.lost_ticks = 0;
                        self.forgetting_since = self.boot_ticks;
                        FlightState::Armed
                    } else {
                        FlightState::Arming
                    }
                } else {
                    FlightState::Disarmed
                }
            }
            FlightState::Armed => {
                self.low_throttle_ticks = if i.throttle_low { self.low_throttle_ticks.saturating_add(1) } else { 0 };
                if !i.link {
                    self.last_good_throttle = self.last_good_throttle.min(i.sticks.thr);
                    // What is left of earlier losses, plus this one so far. (Forgetting is
                    // counted here, from the ticks flown since the hand-back, not on every
                    // flying tick.)
                    let flown = self.boot_ticks.wrapping_sub(self.forgetting_since);
                    let forgotten = flown / cfg.loss_forget_ticks.max(1);
                    self.lost_ticks = self.lost_ticks.saturating_sub(forgotten).saturating_add(lost_now);
                    if self.lost_ticks >= cfg.failsafe_off_ticks {
                        FlightState::FailsafeOff
                    } else {
                        FlightState::FailsafeLevel
                    }
                } else if gesture == Some(Gesture::Disarm) {
                    self.hold_ticks = self.hold_ticks.saturating_add(1);
                    if self.hold_ticks >= cfg.disarm_hold_ticks {
                        FlightState::Disarmed
                    } else {
                        FlightState::Armed
                    }
                } else if self.low_throttle_ticks >= cfg.auto_disarm_ticks {
                    FlightState::Disarmed
                } else {
                    self.hold_ticks = 0;
                    FlightState::Armed
                }
            }
            FlightState::FailsafeLevel => {
                if i.link && self.good_ticks >= cfg.recovery_ticks {
                    self.low_throttle_ticks = 0;
                    self.forgetting_since = self.boot_ticks;
                    FlightState::Armed
                } else if self.lost_ticks >= cfg.failsafe_off_ticks {
                    FlightState::FailsafeOff
                } else {
                    FlightState::FailsafeLevel
                }
            }
            FlightState::FailsafeOff => {
                if i.link {
                    FlightState::Disarmed
                } else {
                    FlightState::FailsafeOff
                }
            }
        };
        if self.state.motors_may_run() && !next.motors_may_run() {
            // Every way out of flight (disarm gesture, automatic disarm, stage 2, fault): a
            // gesture held through it must be let go before it acts again. One rule here, not
            // one per branch: the automatic disarm once lacked it, and a gesture held through
            // it re-armed on release (found by the safety properties).
            self.released = false;
        }
        if next != self.state && next != FlightState::Arming {
            self.hold_ticks = 0;
        }
        if i.link && next == FlightState::Armed {
            self.last_good_throttle = i.sticks.thr;
        }
        // Let go of every gesture on a good link: a gesture only acts from a released start.
        if i.link && gesture.is_none() {
            self.released = true;
        }
        if !i.link {
            self.released = false;
        }
        self.state = next;
        Decision {
            state: next,
            motors_enabled: next.motors_may_run(),
            failsafe_throttle: (next == FlightState::FailsafeLevel).then_some(self.last_good_throttle),
            request_calibration,
            // Blockers say why arming is refused; armed, there is nothing to refuse
            // (docs/performance.md, «no blockers while armed»).
            blockers: if next == FlightState::Armed { Blockers::default() } else { self.blockers(cfg, i) },
        }
    }
}

fn without(b: Blockers, x: Blocker) -> Blockers {
    Blockers(b.0 & !(x as u16))
}

#[cfg(test)]
mod tests {
    //! One test per rule of `docs/safety.md`, named after it.
    use super::*;

    const CFG: SafetyConfig = SafetyConfig::DEFAULT;
    const ARM: Sticks = Sticks::new(-1500, -1500, 0, 1500);
    const DISARM: Sticks = Sticks::new(0, 0, 0, -1500);
    const CAL: Sticks = Sticks::new(1500, -1500, 0, -1500);
    const IDLE: Sticks = Sticks::new(0, 0, 0, 0);
    const FLY: Sticks = Sticks::new(0, 0, 1500, 0);
    /// The radio's channel timeout (100 ms): the first tick without a good link comes this
    /// long after the last pulse of the channel that fell silent.
    const TIMEOUT: u32 = 80;

    /// A supervisor driven tick by tick, with a good link, calibrated, level, no fault.
    struct Rig {
        s: Supervisor,
        i: Inputs,
        last: Decision,
    }

    impl Rig {
        fn new() -> Rig {
            let i = Inputs::READY;
            let mut r = Rig { s: Supervisor::new(), i, last: Supervisor::new().decide_reference(false, None, false) };
            r.run(IDLE, CFG.boot_settle_ticks);
            assert_eq!(r.last.state, FlightState::Disarmed);
            r
        }

        fn sticks(&mut self, s: Sticks) {
            self.i.sticks = s;
            self.i.throttle_low = s.thr < StickCounts(200);
            self.i.gesture = crate::rc::RcConfig::REFERENCE.gesture(&s);
        }

        fn run(&mut self, s: Sticks, ticks: u32) -> Decision {
            self.sticks(s);
            for _ in 0..ticks {
                self.last = self.s.decide(&CFG, &self.i);
            }
            self.last
        }

        fn arm(&mut self) {
            self.run(ARM, CFG.arm_hold_ticks);
            let d = self.run(IDLE, 1);
            assert_eq!(d.state, FlightState::Armed, "blockers {:?}", d.blockers);
        }

        /// `ticks` ticks without a good link, as a radio reports them: the link is declared lost
        /// [`TIMEOUT`] ticks after a channel's last pulse, so the silence starts there.
        fn lose_link(&mut self, ticks: u32) -> Decision {
            for _ in 0..ticks {
                self.i.silence_ticks = if self.i.link { TIMEOUT } else { self.i.silence_ticks + 1 };
                self.i.link = false;
                self.last = self.s.decide(&CFG, &self.i);
            }
            self.last
        }

        fn restore_link(&mut self, ticks: u32) -> Decision {
            self.i.link = true;
            self.i.silence_ticks = 0;
            for _ in 0..ticks {
                self.last = self.s.decide(&CFG, &self.i);
            }
            self.last
        }
    }

    #[test]
    fn boot_starts_calibrating_with_motors_off() {
        let mut s = Supervisor::new();
        let i = Inputs {
            link: true,
            silence_ticks: 0,
            sticks: IDLE,
            gesture: None,
            throttle_low: true,
            calibrated: false,
            calibrating: true,
            sensor_fault: None,
            tilt_rad: 0.0,
        };
        let d = s.decide(&CFG, &i);
        assert_eq!(d.state, FlightState::Calibrating);
        assert!(!d.motors_enabled);
        assert!(d.blockers.contains(Blocker::Calibrating) && d.blockers.contains(Blocker::NotCalibrated));
        assert!(d.blockers.contains(Blocker::BootSettling));
    }

    #[test]
    fn arm_requires_the_gesture_held_one_second() {
        let mut r = Rig::new();
        r.run(ARM, CFG.arm_hold_ticks - 1);
        assert_eq!(r.run(IDLE, 1).state, FlightState::Disarmed);
        let mut r = Rig::new();
        r.arm();
    }

    #[test]
    fn arm_happens_on_release_not_while_held() {
        let mut r = Rig::new();
        let d = r.run(ARM, 5 * CFG.arm_hold_ticks);
        assert_eq!(d.state, FlightState::Arming);
        assert!(!d.motors_enabled);
        assert_eq!(r.run(IDLE, 1).state, FlightState::Armed);
    }

    #[test]
    fn arming_completes_only_once_every_stick_is_back_in_a_safe_place() {
        // After a full hold, the throttle nudged off zero (still low) but aileron, elevator and
        // rudder still at the gesture's deflection: not armed yet, motors off.
        let mut r = Rig::new();
        r.run(ARM, CFG.arm_hold_ticks);
        let nudged = Sticks { thr: StickCounts(50), ..ARM };
        let d = r.run(nudged, 100);
        assert_eq!(d.state, FlightState::Arming);
        assert!(!d.motors_enabled);
        // Rudder still over: still waiting.
        let d = r.run(Sticks { rud: StickCounts(1300), ..IDLE }, 10);
        assert_eq!(d.state, FlightState::Arming);
        // Every stick centred, throttle low: armed.
        assert_eq!(r.run(IDLE, 1).state, FlightState::Armed);
    }

    #[test]
    fn arm_is_refused_until_a_calibration_passed() {
        let mut r = Rig::new();
        r.i.calibrated = false;
        let d = r.run(ARM, CFG.arm_hold_ticks);
        assert_eq!(d.state, FlightState::Disarmed);
        assert!(d.blockers.contains(Blocker::NotCalibrated));
        assert_eq!(r.run(IDLE, 1).state, FlightState::Disarmed);
    }

    #[test]
    fn arm_is_refused_while_calibrating() {
        let mut r = Rig::new();
        r.i.calibrating = true;
        r.run(ARM, CFG.arm_hold_ticks);
        let d = r.run(IDLE, 1);
        assert_ne!(d.state, FlightState::Armed);
        assert!(d.blockers.contains(Blocker::Calibrating));
    }

    #[test]
    fn arm_is_refused_without_a_good_link() {
        let mut r = Rig::new();
        r.i.link = false;
        let d = r.run(ARM, CFG.arm_hold_ticks);
        assert_eq!(d.state, FlightState::Disarmed);
        assert!(d.blockers.contains(Blocker::LinkNotGood));
    }

    #[test]
    fn arm_is_refused_if_the_throttle_is_up_at_release() {
        let mut r = Rig::new();
        r.run(ARM, CFG.arm_hold_ticks);
        let d = r.run(FLY, 1);
        assert_eq!(d.state, FlightState::Disarmed);
        assert!(d.blockers.contains(Blocker::ThrottleNotLow));
    }

    #[test]
    fn arm_is_refused_beyond_25_degrees_from_level() {
        let mut r = Rig::new();
        r.i.tilt_rad = 26f32.to_radians();
        r.run(ARM, CFG.arm_hold_ticks);
        let d = r.run(IDLE, 1);
        assert_eq!(d.state, FlightState::Disarmed);
        assert!(d.blockers.contains(Blocker::NotLevel));
        let mut r = Rig::new();
        r.i.tilt_rad = 24f32.to_radians();
        r.arm();
    }

    #[test]
    fn a_nan_attitude_counts_as_not_level() {
        let mut r = Rig::new();
        r.i.tilt_rad = f32::NAN;
        assert!(r.run(IDLE, 1).blockers.contains(Blocker::NotLevel));
    }

    #[test]
    fn arm_is_refused_during_the_first_two_seconds() {
        let mut s = Supervisor::new();
        let mut i = Rig::new().i;
        i.sticks = IDLE;
        s.decide(&CFG, &i);
        i.sticks = ARM;
        i.gesture = Some(Gesture::Arm);
        let mut d = s.decide(&CFG, &i);
        for _ in 0..CFG.arm_hold_ticks {
            d = s.decide(&CFG, &i);
        }
        assert!(d.blockers.contains(Blocker::BootSettling));
        i.sticks = IDLE;
        i.gesture = None;
        assert_eq!(s.decide(&CFG, &i).state, FlightState::Disarmed);
    }

    #[test]
    fn arm_is_refused_after_a_sensor_fault() {
        let mut r = Rig::new();
        r.i.sensor_fault = Some(SensorFault::Stuck);
        r.run(IDLE, 1);
        r.i.sensor_fault = None;
        r.run(ARM, CFG.arm_hold_ticks);
        let d = r.run(IDLE, 1);
        assert_eq!(d.state, FlightState::Fault);
        assert!(d.blockers.contains(Blocker::SensorFault));
    }

    #[test]
    fn holding_the_arm_gesture_while_the_link_comes_up_does_not_arm() {
        let mut r = Rig::new();
        r.lose_link(10);
        r.sticks(ARM);
        let d = r.restore_link(3 * CFG.arm_hold_ticks);
        assert_eq!(d.state, FlightState::Disarmed);
        assert!(d.blockers.contains(Blocker::GestureNotReleased));
        assert_eq!(r.run(IDLE, 1).state, FlightState::Disarmed);
        // Letting go and doing it properly then works.
        r.arm();
    }

    #[test]
    fn the_gesture_must_be_released_after_a_disarm_before_arming_again() {
        let mut r = Rig::new();
        r.arm();
        r.run(DISARM, CFG.disarm_hold_ticks);
        assert_eq!(r.last.state, FlightState::Disarmed);
        // Straight from the disarm gesture into the arm gesture, no neutral in between.
        let d = r.run(ARM, CFG.arm_hold_ticks);
        assert_eq!(d.state, FlightState::Disarmed);
        assert!(d.blockers.contains(Blocker::GestureNotReleased));
    }

    #[test]
    fn a_blocker_during_the_hold_aborts_arming() {
        let mut r = Rig::new();
        r.run(ARM, CFG.arm_hold_ticks / 2);
        r.i.tilt_rad = 1.0;
        r.run(ARM, 1);
        r.i.tilt_rad = 0.0;
        r.run(ARM, CFG.arm_hold_ticks);
        assert_eq!(r.run(IDLE, 1).state, FlightState::Disarmed);
    }

    #[test]
    fn disarm_gesture_held_one_second_disarms() {
        let mut r = Rig::new();
        r.arm();
        let d = r.run(DISARM, CFG.disarm_hold_ticks);
        assert_eq!(d.state, FlightState::Disarmed);
        assert!(!d.motors_enabled);
    }

    #[test]
    fn a_short_disarm_gesture_does_not_disarm() {
        let mut r = Rig::new();
        r.arm();
        r.run(DISARM, CFG.disarm_hold_ticks - 1);
        assert_eq!(r.run(FLY, 1).state, FlightState::Armed);
        // The hold starts again from zero.
        r.run(DISARM, CFG.disarm_hold_ticks - 1);
        assert_eq!(r.last.state, FlightState::Armed);
    }

    #[test]
    fn auto_disarm_after_five_seconds_armed_with_throttle_low() {
        let mut r = Rig::new();
        r.arm();
        assert_eq!(r.run(IDLE, CFG.auto_disarm_ticks - 2).state, FlightState::Armed);
        assert_eq!(r.run(IDLE, 2).state, FlightState::Disarmed);
    }

    #[test]
    fn holding_the_arm_gesture_through_the_automatic_disarm_does_not_rearm() {
        let mut r = Rig::new();
        r.arm();
        // The arm gesture has the throttle at 0: the motors stop and the auto disarm comes.
        assert_eq!(r.run(ARM, CFG.auto_disarm_ticks).state, FlightState::Disarmed);
        r.run(ARM, CFG.arm_hold_ticks);
        let d = r.run(IDLE, 1);
        assert_eq!(d.state, FlightState::Disarmed);
        // Let go, then the full procedure arms again.
        r.arm();
    }

    #[test]
    fn throttle_up_restarts_the_auto_disarm_timer() {
        let mut r = Rig::new();
        r.arm();
        r.run(IDLE, CFG.auto_disarm_ticks - 10);
        r.run(FLY, 1);
        assert_eq!(r.run(IDLE, CFG.auto_disarm_ticks - 10).state, FlightState::Armed);
    }

    #[test]
    fn link_loss_enters_failsafe_stage_1_holding_the_last_throttle() {
        let mut r = Rig::new();
        r.arm();
        r.run(FLY, 100);
        let d = r.lose_link(1);
        assert_eq!(d.state, FlightState::FailsafeLevel);
        assert!(d.motors_enabled);
        assert_eq!(d.failsafe_throttle, Some(FLY.thr));
        assert!(d.blockers.contains(Blocker::Failsafe));
    }

    #[test]
    fn failsafe_throttle_is_never_raised() {
        let mut r = Rig::new();
        r.arm();
        r.run(FLY, 100);
        // Stale sticks claiming more throttle while the link is down change nothing.
        r.i.sticks.thr = StickCounts(3000);
        let d = r.lose_link(50);
        assert_eq!(d.failsafe_throttle, Some(FLY.thr));
    }

    #[test]
    fn a_flapping_link_cannot_keep_the_motors_running() {
        // Off 900 ms / on 40 ms: silent 720 ticks from the last pulse of each burst (640 of them
        // without a good link), then two frames keep the link good for 112 ticks. Control is
        // never handed back, and lost time adds up to stage 2 in the second loss.
        let mut r = Rig::new();
        r.arm();
        r.run(FLY, 10);
        let mut t = 0;
        let stage2_at = loop {
            let d = r.lose_link(640);
            t += 640;
            if d.state == FlightState::FailsafeOff {
                break t;
            }
            r.restore_link(112);
            t += 112;
            assert_ne!(r.last.state, FlightState::Armed, "control handed back to a flapping link");
        };
        assert!(stage2_at <= 2 * (640 + 112), "stage 2 after {stage2_at} ticks");
    }

    #[test]
    fn brief_recoveries_do_not_restart_the_stage_2_clock() {
        // Off 150 ms / on 40 ms: about 21 % of the frames. Each silence is 120 ticks from the
        // last pulse, only 40 of them without a good link; the good 112 ticks after each burst
        // neither hand control back nor forget any of it. 800 / 120: stage 2 in the 7th loss.
        let mut r = Rig::new();
        r.arm();
        r.run(FLY, 10);
        let mut losses = 0;
        loop {
            losses += 1;
            if r.lose_link(40).state == FlightState::FailsafeOff {
                break;
            }
            assert_eq!(r.restore_link(112).state, FlightState::FailsafeLevel);
        }
        assert_eq!(losses, CFG.failsafe_off_ticks.div_ceil(TIMEOUT + 40 - 1));
    }

    #[test]
    fn lost_time_counts_from_the_last_pulse_not_from_the_link_timeout() {
        // Losses just past the channel timeout: 10 ticks without a good link each, 90 ticks of
        // silence. Counting only the ticks after the timeout, stage 2 would take 80 of them;
        // counted from the last pulse it takes 9.
        let mut r = Rig::new();
        r.arm();
        r.run(FLY, 10);
        for loss in 1..=9 {
            let d = r.lose_link(10);
            if loss < 9 {
                assert_eq!(d.state, FlightState::FailsafeLevel, "loss {loss}");
                r.restore_link(TIMEOUT + 20);
            } else {
                assert_eq!(d.state, FlightState::FailsafeOff, "loss {loss}");
            }
        }
    }

    #[test]
    fn silence_already_counted_is_not_counted_twice() {
        // Back for 5 ticks only (one channel's pulse made the link good; another goes silent
        // again): the new loss adds the 6 ticks since the last one, not the channel timeout.
        let mut r = Rig::new();
        r.arm();
        r.run(FLY, 10);
        r.lose_link(100); // 80 + 99 = 179 lost
        r.restore_link(5);
        r.i.link = false;
        r.i.silence_ticks = TIMEOUT + 200;
        let mut d = r.s.decide(&CFG, &r.i); // + 6 = 185
        assert_eq!(d.state, FlightState::FailsafeLevel);
        for _ in 0..CFG.failsafe_off_ticks - 185 - 1 {
            r.i.silence_ticks += 1;
            d = r.s.decide(&CFG, &r.i);
            assert_eq!(d.state, FlightState::FailsafeLevel);
        }
        r.i.silence_ticks += 1;
        assert_eq!(r.s.decide(&CFG, &r.i).state, FlightState::FailsafeOff);
    }

    #[test]
    fn lost_time_is_forgotten_slowly_after_control_is_back() {
        // 0.6 s lost (80 + 399 ticks), control back after the recovery time, then a second loss
        // right away: together they reach the 1.0 s budget, stage 2.
        let first = TIMEOUT + 399;
        let mut r = Rig::new();
        r.arm();
        r.run(FLY, 10);
        r.lose_link(400);
        assert_eq!(r.restore_link(CFG.recovery_ticks).state, FlightState::Armed);
        let rest = CFG.failsafe_off_ticks - first - TIMEOUT;
        assert_eq!(r.lose_link(rest).state, FlightState::FailsafeLevel);
        assert_eq!(r.lose_link(1).state, FlightState::FailsafeOff, "the earlier loss was forgotten too fast");
        // After flying four times as long as the loss on a good link, the same second loss
        // only levels: a second of loss at most.
        let mut r = Rig::new();
        r.arm();
        r.run(FLY, 10);
        r.lose_link(400);
        r.restore_link(CFG.recovery_ticks);
        r.run(FLY, first * CFG.loss_forget_ticks);
        assert_eq!(r.lose_link(CFG.failsafe_off_ticks - TIMEOUT).state, FlightState::FailsafeLevel);
    }

    #[test]
    fn link_back_within_stage_1_returns_control_after_the_recovery_time() {
        let mut r = Rig::new();
        r.arm();
        r.run(FLY, 10);
        r.lose_link(200);
        assert_eq!(r.restore_link(CFG.recovery_ticks - 1).state, FlightState::FailsafeLevel);
        assert_eq!(r.restore_link(1).state, FlightState::Armed);
    }

    #[test]
    fn link_lost_for_one_second_turns_the_motors_off_and_disarms() {
        // One second from the last pulse: the link was declared lost after TIMEOUT of it.
        let mut r = Rig::new();
        r.arm();
        r.run(FLY, 10);
        assert_eq!(r.lose_link(CFG.failsafe_off_ticks - TIMEOUT).state, FlightState::FailsafeLevel);
        assert_eq!(r.i.silence_ticks, CFG.failsafe_off_ticks - 1);
        let d = r.lose_link(1);
        assert_eq!(d.state, FlightState::FailsafeOff);
        assert!(!d.motors_enabled);
    }

    #[test]
    fn a_flickering_link_cannot_stretch_stage_1() {
        // Losses of 20 ticks (100 silent each), back for half the recovery time: stage 2 the
        // moment the silences add up to the budget.
        let mut r = Rig::new();
        r.arm();
        r.run(FLY, 10);
        let mut silent = 0;
        loop {
            silent += TIMEOUT + 20 - 1;
            if r.lose_link(20).state == FlightState::FailsafeOff {
                break;
            }
            assert!(silent < CFG.failsafe_off_ticks, "stage 1 outlasted its loss budget");
            assert_eq!(r.restore_link(CFG.recovery_ticks / 2).state, FlightState::FailsafeLevel);
        }
        assert!((CFG.failsafe_off_ticks..CFG.failsafe_off_ticks + TIMEOUT + 20).contains(&silent));
    }

    #[test]
    fn after_stage_2_the_link_returning_gives_disarmed_and_needs_a_full_arming() {
        let mut r = Rig::new();
        r.arm();
        r.run(FLY, 10);
        r.lose_link(CFG.failsafe_off_ticks + 10);
        let d = r.restore_link(1000);
        assert_eq!(d.state, FlightState::Disarmed);
        assert!(!d.motors_enabled);
        r.arm();
    }

    #[test]
    fn motors_never_restart_by_themselves_after_stage_2() {
        let mut r = Rig::new();
        r.arm();
        r.run(FLY, 10);
        r.lose_link(CFG.failsafe_off_ticks + 1);
        r.sticks(FLY);
        for _ in 0..10 {
            assert!(!r.restore_link(100).motors_enabled);
            assert!(!r.lose_link(5).motors_enabled);
        }
    }

    #[test]
    fn link_loss_while_disarmed_stays_disarmed() {
        let mut r = Rig::new();
        let d = r.lose_link(2000);
        assert_eq!(d.state, FlightState::Disarmed);
        assert!(d.blockers.contains(Blocker::LinkNotGood));
    }

    #[test]
    fn calibration_gesture_requests_a_calibration_while_disarmed() {
        let mut r = Rig::new();
        let d = r.run(CAL, 1);
        assert!(d.request_calibration);
        assert_eq!(d.state, FlightState::Calibrating);
        // Held on, it does not ask again.
        assert!(!r.run(CAL, 10).request_calibration);
    }

    #[test]
    fn calibration_gesture_is_ignored_while_armed() {
        let mut r = Rig::new();
        r.arm();
        let d = r.run(CAL, 100);
        assert!(!d.request_calibration);
        assert_eq!(d.state, FlightState::Armed);
    }

    #[test]
    fn a_sensor_fault_in_flight_stops_the_motors_and_latches() {
        let mut r = Rig::new();
        r.arm();
        r.run(FLY, 10);
        r.i.sensor_fault = Some(SensorFault::NotFinite);
        let d = r.run(FLY, 1);
        assert_eq!(d.state, FlightState::Fault);
        assert!(!d.motors_enabled);
        r.i.sensor_fault = None;
        assert_eq!(r.run(FLY, 10_000).state, FlightState::Fault);
    }

    #[test]
    fn motors_may_run_only_armed_or_in_stage_1() {
        for s in [FlightState::Disarmed, FlightState::Arming, FlightState::FailsafeOff, FlightState::Calibrating, FlightState::Fault] {
            assert!(!s.motors_may_run(), "{}", s.name());
        }
        assert!(FlightState::Armed.motors_may_run() && FlightState::FailsafeLevel.motors_may_run());
    }

    #[test]
    fn every_blocker_has_a_distinct_name() {
        let mut all = Blockers::default();
        for b in Blocker::ALL {
            all.insert(b);
        }
        let mut names = [""; 9];
        for (n, b) in names.iter_mut().zip(all.iter()) {
            *n = b.name();
        }
        assert!(names.iter().all(|n| !n.is_empty()));
        for (i, a) in names.iter().enumerate() {
            assert!(!names[i + 1..].contains(a), "{a}");
        }
    }

    #[test]
    fn reference_latch_never_disarms() {
        let mut s = Supervisor::new();
        s.reference_gesture(Some(Gesture::Arm));
        assert!(s.decide_reference(true, None, false).motors_enabled);
        s.reference_gesture(Some(Gesture::Disarm));
        assert!(s.decide_reference(true, None, false).motors_enabled);
        // Link loss stops the motors but keeps "armed": they resume when edges return (B8).
        assert!(!s.decide_reference(false, None, false).motors_enabled);
        assert!(s.decide_reference(true, None, false).motors_enabled);
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig::with_cases(200))]
        #[test]
        fn the_flight_shortcut_decides_exactly_as_the_table(
            // (sticks pattern, link, throttle up, fault, calibrating, tilted), 1 to 40 ticks each.
            seq in proptest::collection::vec(((0u8..5, proptest::bool::weighted(0.9), proptest::bool::weighted(0.2), proptest::bool::weighted(0.005), proptest::bool::weighted(0.01), proptest::bool::weighted(0.02)), 1u32..40), 1..60),
        ) {
            // Short counts so that random sequences arm, fly, fail over and disarm often.
            let cfg = SafetyConfig { arm_hold_ticks: 3, disarm_hold_ticks: 4, auto_disarm_ticks: 20, failsafe_off_ticks: 15, recovery_ticks: 5, boot_settle_ticks: 10, ..SafetyConfig::DEFAULT };
            let mut fast = Supervisor::new();
            let mut table = Supervisor::new();
            // Repeats steady flight whenever the inputs are those of the last tick.
            let mut lazy = Supervisor::new();
            let mut lazy_decision = None;
            let mut previous: Option<Inputs> = None;
            let mut shortcut_ticks = 0u32;
            let mut repeats = 0u32;
            // Every sequence starts by arming and flying (pattern, link, throttle up, fault,
            // calibrating, tilted), then goes its random way.
            let script = [((0, true, false, false, false, false), 12), ((1, true, false, false, false, false), 5), ((0, true, false, false, false, false), 1), ((4, true, true, false, false, false), 5)];
            let seq = script.into_iter().chain(seq);
            for ((pattern, link, throttle_up, fault, calibrating, tilted), ticks) in seq {
                let base = [IDLE, ARM, DISARM, CAL, FLY][usize::from(pattern)];
                let sticks = Sticks { thr: if throttle_up { StickCounts(1500) } else { base.thr }, ..base };
                let i = Inputs {
                    link,
                    // Any silence: the table and the shortcut must agree whatever the radio says.
                    silence_ticks: if link { 0 } else { ticks * 7 },
                    sticks,
                    gesture: crate::rc::RcConfig::REFERENCE.gesture(&sticks),
                    throttle_low: sticks.thr < StickCounts(200),
                    calibrated: true,
                    calibrating,
                    sensor_fault: fault.then_some(SensorFault::Stuck),
                    tilt_rad: if tilted { 1.0 } else { 0.0 },
                };
                for _ in 0..ticks {
                    let in_flight = fast.state == FlightState::Armed && i.link && i.gesture.is_none() && !i.throttle_low;
                    shortcut_ticks += u32::from(in_flight);
                    let a = fast.decide(&cfg, &i);
                    let b = table.decide_by_table(&cfg, i);
                    // The radio "changed" whenever link or sticks differ from the last tick's; the
                    // other inputs may differ on a repeat, as in the pipeline.
                    let radio_changed = previous.is_none_or(|p| p.link != i.link || p.sticks != i.sticks);
                    let c = match lazy.decide_or_repeat(radio_changed, i.sensor_fault, |s| s.decide(&cfg, &i)) {
                        Some(d) => d,
                        None => {
                            repeats += 1;
                            proptest::prop_assert!(lazy_decision.is_some(), "a repeat before any decision");
                            lazy_decision.unwrap_or(a)
                        }
                    };
                    lazy_decision = Some(c);
                    previous = Some(i);
                    proptest::prop_assert_eq!(a, b);
                    proptest::prop_assert_eq!(a, c);
                    // The same memory, whichever path ran (`steady` only says which one did).
                    proptest::prop_assert_eq!(&Supervisor { steady: fast.steady, ..table.clone() }, &fast);
                    proptest::prop_assert_eq!(&fast, &lazy);
                }
            }
            // Not a vacuous comparison: the shortcut ran.
            proptest::prop_assert!(shortcut_ticks >= 5);
            proptest::prop_assert!(repeats >= 3);
        }
    }

    #[test]
    fn the_flight_shortcut_is_taken_in_steady_flight() {
        let mut r = Rig::new();
        r.arm();
        r.run(FLY, 10);
        let before = r.s.clone();
        let d = r.s.decide_in_flight(&r.i);
        let mut table = before;
        assert_eq!(d, table.decide_by_table(&CFG, r.i));
        assert_eq!(r.s, Supervisor { steady: true, ..table });
    }
}
