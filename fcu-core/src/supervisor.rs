//! The supervisor: the one place that decides whether the motors may turn.
//!
//! Two kinds, chosen by [`SupervisorConfig`]:
//! - [`SupervisorConfig::Reference`]: the ST reference's behaviour, a
//!   [`ReferenceLatch`]: the arm gesture latches "armed" for ever, motors run while armed and
//!   any edge arrived in the last 31 ms, no failsafe, calibration on the gesture at any time.
//! - [`SupervisorConfig::Safe`]: the product's safety layer (`docs/safety.md`), the state machine
//!   [`Supervisor`]. Every number is a field of [`SafetyConfig`], in control ticks.
//!
//! The safety layer decides in three steps, each in one place ([`Supervisor::decide`]):
//! 1. the inputs and the supervisor's memory become a set of [`Conditions`] (the [`Blocker`]s
//!    and the holds, timeouts and budgets the memory counts);
//! 2. the next state is looked up in the state table, [`next_state`]: data
//!    ([`transitions`]), a pure function of the state and the conditions;
//! 3. the transition's actions (what starts or ends with a state) are applied, and the
//!    [`Decision`] follows from the new state.

use crate::gcs::GcsCommands;
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
            && crate::math::above(self.max_arm_tilt_rad, 0.0, f32::MAX)
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

    /// Changes are restricted: the motors may be running or about to (arming, armed, or the
    /// failsafe's level stage). Only in-flight parameters change then
    /// ([`ChangeKind::allowed`](crate::flight::ChangeKind::allowed)), and nothing is written to
    /// flash.
    pub fn changes_restricted(self) -> bool {
        matches!(self, FlightState::Arming | FlightState::Armed | FlightState::FailsafeLevel)
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
    /// A ground station's motor test runs, or a stick that ended one has not come back to rest
    /// ([`crate::gcs`]).
    MotorTest = 1 << 9,
    /// A ground station's radio calibration runs.
    RadioCalibration = 1 << 10,
    /// A flash save is due or runs: an erase stalls every instruction fetch.
    Saving = 1 << 11,
    /// A reboot a ground station asked for is pending.
    RebootPending = 1 << 12,
}

impl Blocker {
    pub const ALL: [Blocker; 13] = [
        Blocker::NotCalibrated,
        Blocker::Calibrating,
        Blocker::LinkNotGood,
        Blocker::ThrottleNotLow,
        Blocker::NotLevel,
        Blocker::Failsafe,
        Blocker::SensorFault,
        Blocker::BootSettling,
        Blocker::GestureNotReleased,
        Blocker::MotorTest,
        Blocker::RadioCalibration,
        Blocker::Saving,
        Blocker::RebootPending,
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
            Blocker::MotorTest => "motor-test",
            Blocker::RadioCalibration => "radio-calibration",
            Blocker::Saving => "saving",
            Blocker::RebootPending => "reboot-pending",
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
    /// This tick's number since boot, the first being 1. The supervisor times the boot
    /// settling, the good link and the forgetting of lost time from it, so a tick it is not
    /// asked about (a decision that stands, [`Supervisor::steady`]) loses it nothing.
    pub tick: u32,
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
    /// What the ground station asks this tick ([`crate::gcs`]).
    pub gcs: GcsCommands,
    /// The failsafe may land on the height estimate: the longest the descent from the present
    /// height may take, ticks (0: no healthy estimate, the failsafe levels and then stops the
    /// motors, as without a barometer). Latched at the loss of the link.
    pub descent_cap_ticks: u32,
    /// The altitude hold detected a landing and holds the motors at the bottom.
    pub landed: bool,
}

impl Inputs {
    /// On the bench and ready: a good link, sticks centred with the throttle low, calibrated,
    /// level, no fault, no gesture (at tick 1: a caller sets each tick's number).
    pub const READY: Inputs = Inputs {
        tick: 1,
        link: true,
        silence_ticks: 0,
        sticks: Sticks::new(0, 0, 0, 0),
        gesture: None,
        throttle_low: true,
        calibrated: true,
        calibrating: false,
        sensor_fault: None,
        tilt_rad: 0.0,
        gcs: GcsCommands::NONE,
        descent_cap_ticks: 0,
        landed: false,
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

/// A condition the state table reads besides the [`Blocker`]s: a gesture seen on a good link,
/// or a hold, timeout or budget the supervisor's memory has counted to its limit.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u32)]
pub enum Condition {
    ArmGesture = 1 << 16,
    DisarmGesture = 1 << 17,
    CalibrateGesture = 1 << 18,
    /// The arm gesture has been held [`SafetyConfig::arm_hold_ticks`].
    ArmHeld = 1 << 19,
    /// The disarm gesture has been held [`SafetyConfig::disarm_hold_ticks`].
    DisarmHeld = 1 << 20,
    /// Aileron, elevator and rudder are centred.
    SticksCentred = 1 << 21,
    /// Armed with the throttle low for [`SafetyConfig::auto_disarm_ticks`].
    ThrottleLowTooLong = 1 << 22,
    /// The lost time reached [`SafetyConfig::failsafe_off_ticks`].
    LossBudgetSpent = 1 << 23,
    /// The link has been good for [`SafetyConfig::recovery_ticks`].
    Recovered = 1 << 24,
    /// The ground station asked for a disarm, and [`crate::gcs::Disarm::checked`] lets it act.
    GcsDisarm = 1 << 25,
    /// The ground station asked for an IMU calibration.
    GcsCalibrate = 1 << 26,
    /// The altitude hold detected a landing ([`Inputs::landed`]).
    Landed = 1 << 27,
}

/// A set of conditions: the [`Blocker`]s on their own bits (the low 16) and the other
/// [`Condition`]s.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Conditions(pub u32);

impl Conditions {
    pub const NONE: Conditions = Conditions(0);

    /// The set of one blocker.
    pub const fn blocker(b: Blocker) -> Conditions {
        Conditions(b as u32)
    }

    /// The set of one condition.
    pub const fn of(c: Condition) -> Conditions {
        Conditions(c as u32)
    }

    pub const fn and(self, other: Conditions) -> Conditions {
        Conditions(self.0 | other.0)
    }

    pub const fn without(self, other: Conditions) -> Conditions {
        Conditions(self.0 & !other.0)
    }

    /// Every condition of `all` holds.
    pub const fn contains(self, all: Conditions) -> bool {
        self.0 & all.0 == all.0
    }

    /// Some condition of `any` holds.
    pub const fn intersects(self, any: Conditions) -> bool {
        self.0 & any.0 != 0
    }

    /// The blockers among them.
    pub const fn blockers(self) -> Blockers {
        Blockers(self.0 as u16)
    }

    fn set(&mut self, c: Condition, on: bool) {
        if on {
            self.0 |= c as u32;
        }
    }
}

/// One way out of a state: taken when every condition of `all` holds and none of `none`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Transition {
    pub to: FlightState,
    pub all: Conditions,
    pub none: Conditions,
}

impl Transition {
    pub const fn applies(&self, c: Conditions) -> bool {
        c.contains(self.all) && !c.intersects(self.none)
    }
}

const fn way(to: FlightState, all: Conditions, none: Conditions) -> Transition {
    Transition { to, all, none }
}

const NONE: Conditions = Conditions::NONE;
const FAULT: Conditions = Conditions::blocker(Blocker::SensorFault);
const NO_LINK: Conditions = Conditions::blocker(Blocker::LinkNotGood);
const CALIBRATING: Conditions = Conditions::blocker(Blocker::Calibrating);
const NOT_RELEASED: Conditions = Conditions::blocker(Blocker::GestureNotReleased);
/// Every reason to refuse arming: starting the hold needs none of them.
const ALL_BLOCKERS: Conditions = Conditions(0xFFFF);
/// Every reason to refuse arming but the release: they end the hold and refuse its end.
const HOLD_BLOCKERS: Conditions = ALL_BLOCKERS.without(NOT_RELEASED);
const ARM_GESTURE: Conditions = Conditions::of(Condition::ArmGesture);
const DISARM_GESTURE: Conditions = Conditions::of(Condition::DisarmGesture);
const CALIBRATE_GESTURE: Conditions = Conditions::of(Condition::CalibrateGesture);
const ARM_HELD: Conditions = Conditions::of(Condition::ArmHeld);
const DISARM_HELD: Conditions = Conditions::of(Condition::DisarmHeld);
const STICKS_CENTRED: Conditions = Conditions::of(Condition::SticksCentred);
const THROTTLE_LOW_TOO_LONG: Conditions = Conditions::of(Condition::ThrottleLowTooLong);
const LOSS_BUDGET_SPENT: Conditions = Conditions::of(Condition::LossBudgetSpent);
const RECOVERED: Conditions = Conditions::of(Condition::Recovered);
const GROUND_DISARM: Conditions = Conditions::of(Condition::GcsDisarm);
const GROUND_CALIBRATE: Conditions = Conditions::of(Condition::GcsCalibrate);
const LANDED: Conditions = Conditions::of(Condition::Landed);

/// The way out of every state, ahead of the state's own: a latched sensor fault ends
/// everything. (Fault has no other way out.)
pub const FROM_EVERY_STATE: [Transition; 1] = [way(FlightState::Fault, FAULT, NONE)];

const FROM_CALIBRATING: [Transition; 1] = [way(FlightState::Disarmed, NONE, CALIBRATING)];

const FROM_DISARMED: [Transition; 3] = [
    way(FlightState::Calibrating, CALIBRATE_GESTURE, NOT_RELEASED),
    way(FlightState::Calibrating, GROUND_CALIBRATE, NONE),
    way(FlightState::Arming, ARM_GESTURE, ALL_BLOCKERS),
];

const FROM_ARMING: [Transition; 6] = [
    // The ground station's disarm abandons the arming.
    way(FlightState::Disarmed, GROUND_DISARM, NONE),
    // Holding the gesture.
    way(FlightState::Arming, ARM_GESTURE, HOLD_BLOCKERS),
    // A blocker during the hold aborts it.
    way(FlightState::Disarmed, ARM_GESTURE, NONE),
    // Let go after a full hold, nothing against it: armed once every stick is back in a safe
    // place (the throttle low is a blocker already), and waiting until then: arming with the
    // sticks still deflected would take off rolled and yawing.
    way(FlightState::Armed, ARM_HELD.and(STICKS_CENTRED), HOLD_BLOCKERS),
    way(FlightState::Arming, ARM_HELD, HOLD_BLOCKERS),
    // Let go too early, or a blocker at the release.
    way(FlightState::Disarmed, NONE, NONE),
];

const FROM_ARMED: [Transition; 6] = [
    // Only with the throttle low or forced (`gcs::Disarm::checked`): the motors stop now.
    way(FlightState::Disarmed, GROUND_DISARM, NONE),
    way(FlightState::FailsafeOff, NO_LINK.and(LOSS_BUDGET_SPENT), NONE),
    way(FlightState::FailsafeLevel, NO_LINK, NONE),
    way(FlightState::Disarmed, DISARM_GESTURE.and(DISARM_HELD), NONE),
    // The disarm hold goes on: it is not the automatic disarm's to end.
    way(FlightState::Armed, DISARM_GESTURE, NONE),
    way(FlightState::Disarmed, THROTTLE_LOW_TOO_LONG, NONE),
];

const FROM_FAILSAFE_LEVEL: [Transition; 4] = [
    // Forced only: the stage-2 cut, at the ground station's word.
    way(FlightState::FailsafeOff, GROUND_DISARM, NONE),
    // The descent on the height estimate landed: motors off, disarmed.
    way(FlightState::FailsafeOff, LANDED, NONE),
    way(FlightState::Armed, RECOVERED, NO_LINK),
    way(FlightState::FailsafeOff, LOSS_BUDGET_SPENT, NONE),
];

const FROM_FAILSAFE_OFF: [Transition; 1] = [way(FlightState::Disarmed, NONE, NO_LINK)];

/// The state table: a state's own ways out, in order of precedence, after
/// [`FROM_EVERY_STATE`]. The first that applies is taken; with none, the state stays.
pub fn transitions(state: FlightState) -> &'static [Transition] {
    match state {
        FlightState::Calibrating => &FROM_CALIBRATING,
        FlightState::Disarmed => &FROM_DISARMED,
        FlightState::Arming => &FROM_ARMING,
        FlightState::Armed => &FROM_ARMED,
        FlightState::FailsafeLevel => &FROM_FAILSAFE_LEVEL,
        FlightState::FailsafeOff => &FROM_FAILSAFE_OFF,
        FlightState::Fault => &[],
    }
}

/// The next state, from the state table alone.
pub fn next_state(state: FlightState, c: Conditions) -> FlightState {
    FROM_EVERY_STATE.iter().chain(transitions(state)).find(|t| t.applies(c)).map_or(state, |t| t.to)
}

/// The safety layer's memory: what it counts, and the state.
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
    /// The tick from which the lost time is being forgotten (the arming or the last hand-back).
    forgetting_since: u32,
    /// The last tick without a good link (0: none yet): the link has been good since.
    last_lost_tick: u32,
    /// Consecutive ticks armed with the throttle low.
    low_throttle_ticks: u32,
    last_good_throttle: StickCounts,
    fault: Option<SensorFault>,
    /// The last decision was steady flight ([`steady`](Self::steady)).
    steady: bool,
    /// The failsafe descent's time cap, taken at the loss of the link (0: none, the manual
    /// failsafe's budget alone).
    descent_cap_ticks: u32,
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
            last_lost_tick: 0,
            low_throttle_ticks: 0,
            last_good_throttle: StickCounts::ZERO,
            fault: None,
            steady: false,
            descent_cap_ticks: 0,
        }
    }

    pub fn state(&self) -> FlightState {
        self.state
    }

    /// One tick of the safety layer: conditions, the state table, the transition's actions.
    pub fn decide(&mut self, cfg: &SafetyConfig, i: &Inputs) -> Decision {
        let c = self.conditions(cfg, i);
        let next = next_state(self.state, c);
        self.act(next, c, i)
    }

    /// The last decision was steady flight: armed, and staying armed, on a good link with the
    /// throttle up and no gesture. The state table's `Armed` line then reads nothing of the
    /// inputs but the link, the gestures, the throttle and the sensor fault, and leaves the
    /// memory as it found it (time is an input, not a count): a tick whose link and sticks are
    /// the last one's and that brings no sensor fault would be decided the same, with the same
    /// memory after it. A caller may keep the decision for such a tick instead of asking
    /// (docs/performance.md, «repeat steady flight»).
    pub fn steady(&self) -> bool {
        self.steady
    }

    /// The next tick must be decided, not repeated: something the steady rule does not read
    /// has come (a ground station's disarm).
    pub fn unsteady(&mut self) {
        self.steady = false;
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
        if self.fault.is_some() {
            b.insert(Blocker::SensorFault);
        }
        if i.tick < cfg.boot_settle_ticks {
            b.insert(Blocker::BootSettling);
        }
        if !self.released {
            b.insert(Blocker::GestureNotReleased);
        }
        let holds = i.gcs.holds;
        for (held, blocker) in [
            (holds.motor_test, Blocker::MotorTest),
            (holds.radio_calibration, Blocker::RadioCalibration),
            (holds.saving, Blocker::Saving),
            (holds.rebooting, Blocker::RebootPending),
        ] {
            if held {
                b.insert(blocker);
            }
        }
        b
    }

    /// Step 1: the conditions of this tick, after counting what the state counts (the holds,
    /// the throttle low while armed, the lost time).
    fn conditions(&mut self, cfg: &SafetyConfig, i: &Inputs) -> Conditions {
        if let Some(f) = i.sensor_fault {
            // Latched until reset: motors off, disarmed.
            self.fault.get_or_insert(f);
        }
        let gesture = if i.link { i.gesture } else { None };
        // Lost time: a loss counts from the last pulse of the channel that fell silent first,
        // and every tick of that silence counts once. A tick without a good link adds the
        // silence up to it, except what an earlier tick without a good link already counted:
        // the first tick of a loss adds the channel timeout (or the good ticks since the last
        // loss, if fewer), each further tick one. It adds up over the flight and is forgotten
        // only slowly once control is back: a flapping link cannot keep the motors running.
        let mut lost_now = 0;
        if !i.link {
            lost_now = i.silence_ticks.min(i.tick.saturating_sub(self.last_lost_tick)).max(1);
            self.last_lost_tick = i.tick;
        }
        // A latched fault ends every count: nothing leaves Fault.
        if self.fault.is_none() {
            match self.state {
                FlightState::Arming if gesture == Some(Gesture::Arm) => self.hold_ticks = self.hold_ticks.saturating_add(1),
                FlightState::Armed => {
                    self.low_throttle_ticks = if i.throttle_low { self.low_throttle_ticks.saturating_add(1) } else { 0 };
                    if !i.link {
                        // What is left of earlier losses, plus this one so far. (Forgetting is
                        // counted here, from the ticks flown since the hand-back, not on every
                        // flying tick.)
                        let flown = i.tick.wrapping_sub(self.forgetting_since);
                        let forgotten = flown / cfg.loss_forget_ticks.max(1);
                        self.lost_ticks = self.lost_ticks.saturating_sub(forgotten).saturating_add(lost_now);
                    } else if gesture == Some(Gesture::Disarm) {
                        self.hold_ticks = self.hold_ticks.saturating_add(1);
                    } else {
                        self.hold_ticks = 0;
                    }
                }
                FlightState::FailsafeLevel => self.lost_ticks = self.lost_ticks.saturating_add(lost_now),
                _ => {}
            }
        }
        let mut c = Conditions(u32::from(self.blockers(cfg, i).0));
        c.set(Condition::ArmGesture, gesture == Some(Gesture::Arm));
        c.set(Condition::DisarmGesture, gesture == Some(Gesture::Disarm));
        c.set(Condition::CalibrateGesture, gesture == Some(Gesture::Calibrate));
        c.set(Condition::ArmHeld, self.hold_ticks >= cfg.arm_hold_ticks);
        c.set(Condition::DisarmHeld, self.hold_ticks >= cfg.disarm_hold_ticks);
        c.set(Condition::SticksCentred, i.sticks.attitude_sticks_centred());
        c.set(Condition::ThrottleLowTooLong, self.low_throttle_ticks >= cfg.auto_disarm_ticks);
        c.set(Condition::LossBudgetSpent, self.lost_ticks >= self.loss_budget(cfg, i));
        c.set(Condition::Recovered, i.tick.saturating_sub(self.last_lost_tick) >= cfg.recovery_ticks);
        c.set(Condition::GcsDisarm, i.gcs.disarm.is_some_and(|d| d.checked(self.state, i.throttle_low).is_ok()));
        c.set(Condition::GcsCalibrate, i.gcs.calibrate);
        c.set(Condition::Landed, i.landed);
        c
    }

    /// The lost time that ends the flight: the manual failsafe's budget, or, while the height
    /// estimate stays healthy, the descent's time cap if longer (the one taken at the loss once
    /// the failsafe holds, the present one at the first tick of a loss). An estimate lost during
    /// the descent ends it as the manual failsafe would: a budget long spent stops the motors.
    fn loss_budget(&self, cfg: &SafetyConfig, i: &Inputs) -> u32 {
        if i.descent_cap_ticks == 0 {
            return cfg.failsafe_off_ticks;
        }
        let cap = if self.state == FlightState::FailsafeLevel { self.descent_cap_ticks } else { i.descent_cap_ticks };
        cfg.failsafe_off_ticks.max(cap)
    }

    /// Step 3: what starts or ends with the transition to `next`, and the decision.
    fn act(&mut self, next: FlightState, c: Conditions, i: &Inputs) -> Decision {
        let from = self.state;
        let link = !c.intersects(NO_LINK);
        let gesture = c.intersects(ARM_GESTURE.and(DISARM_GESTURE).and(CALIBRATE_GESTURE));
        match (from, next) {
            (FlightState::Disarmed, FlightState::Arming) => self.hold_ticks = 1,
            (FlightState::Arming, FlightState::Armed) => {
                self.low_throttle_ticks = 0;
                // A new flight starts with no lost time.
                self.lost_ticks = 0;
                self.forgetting_since = i.tick;
            }
            (FlightState::FailsafeLevel, FlightState::Armed) => {
                self.low_throttle_ticks = 0;
                self.forgetting_since = i.tick;
            }
            // The failsafe holds the last throttle flown on a good link, never more.
            (FlightState::Armed, FlightState::FailsafeLevel | FlightState::FailsafeOff) => {
                self.last_good_throttle = self.last_good_throttle.min(i.sticks.thr);
                self.descent_cap_ticks = i.descent_cap_ticks;
            }
            _ => {}
        }
        if next != from && next != FlightState::Arming {
            self.hold_ticks = 0;
        }
        if link && next == FlightState::Armed {
            self.last_good_throttle = i.sticks.thr;
        }
        // A gesture only acts from a released start: let go of every gesture on a good link.
        // One that acted (a calibration asked, an arming aborted) or was held through a way out
        // of flight (disarm gesture, automatic disarm, stage 2, fault) must be let go before it
        // acts again.
        let acted = matches!((from, next), (FlightState::Disarmed, FlightState::Calibrating))
            || (from == FlightState::Arming && next == FlightState::Disarmed && c.intersects(ARM_GESTURE))
            || (from.motors_may_run() && !next.motors_may_run());
        self.released = link && (!gesture || (self.released && !acted));
        self.steady = from == FlightState::Armed && next == FlightState::Armed && link && !gesture && !i.throttle_low;
        self.state = next;
        // Blockers say why arming is refused; armed, there is nothing to refuse.
        let blockers = if next == FlightState::Armed {
            Blockers::default()
        } else {
            let mut b = Blockers(c.blockers().0 & !(Blocker::Failsafe as u16 | Blocker::GestureNotReleased as u16));
            if matches!(next, FlightState::FailsafeLevel | FlightState::FailsafeOff) {
                b.insert(Blocker::Failsafe);
            }
            if !self.released {
                b.insert(Blocker::GestureNotReleased);
            }
            b
        };
        Decision {
            state: next,
            motors_enabled: next.motors_may_run(),
            failsafe_throttle: (next == FlightState::FailsafeLevel).then_some(self.last_good_throttle),
            request_calibration: from == FlightState::Disarmed && next == FlightState::Calibrating,
            blockers,
        }
    }
}

/// The reference's supervisor: an arm latch, the motors on while it is set and the link is up.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ReferenceLatch {
    armed: bool,
}

impl ReferenceLatch {
    /// One tick. `set_armed` sets (or, from a replay, clears) the latch: the arm gesture seen
    /// after any single-channel update, or the replay's flag. The reference has no disarm, and
    /// its calibration gesture acts directly, not through this decision.
    pub fn decide(&mut self, link: bool, set_armed: Option<bool>, calibrating: bool) -> Decision {
        if let Some(a) = set_armed {
            self.armed = a;
        }
        let state = if calibrating && !self.armed {
            FlightState::Calibrating
        } else if self.armed {
            FlightState::Armed
        } else {
            FlightState::Disarmed
        };
        Decision {
            state,
            motors_enabled: link && self.armed,
            failsafe_throttle: None,
            request_calibration: false,
            blockers: Blockers::default(),
        }
    }
}

#[cfg(test)]
mod tests {
    //! One test per rule of `docs/safety.md`, named after it; the state table has its own.
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
            let i = Inputs { tick: 0, ..Inputs::READY };
            let mut r = Rig { s: Supervisor::new(), i, last: ReferenceLatch::default().decide(false, None, false) };
            r.run(IDLE, CFG.boot_settle_ticks);
            assert_eq!(r.last.state, FlightState::Disarmed);
            r
        }

        fn sticks(&mut self, s: Sticks) {
            self.i.sticks = s;
            self.i.throttle_low = s.thr < StickCounts(200);
            self.i.gesture = crate::rc::RcConfig::REFERENCE.gesture(&s);
        }

        /// The next tick, with the inputs as they are.
        fn step(&mut self) -> Decision {
            self.i.tick += 1;
            self.last = self.s.decide(&CFG, &self.i);
            self.last
        }

        fn run(&mut self, s: Sticks, ticks: u32) -> Decision {
            self.sticks(s);
            for _ in 0..ticks {
                self.step();
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
                self.step();
            }
            self.last
        }

        fn restore_link(&mut self, ticks: u32) -> Decision {
            self.i.link = true;
            self.i.silence_ticks = 0;
            for _ in 0..ticks {
                self.step();
            }
            self.last
        }
    }

    #[test]
    fn boot_starts_calibrating_with_motors_off() {
        let mut s = Supervisor::new();
        let i = Inputs {
            tick: 1,
            link: true,
            silence_ticks: 0,
            sticks: IDLE,
            gesture: None,
            throttle_low: true,
            calibrated: false,
            calibrating: true,
            sensor_fault: None,
            tilt_rad: 0.0,
            gcs: GcsCommands::NONE,
            descent_cap_ticks: 0,
            landed: false,
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
        // A fresh supervisor, from tick 1.
        let mut r = Rig::new();
        r.s = Supervisor::new();
        r.i.tick = 0;
        r.run(IDLE, 1);
        let d = r.run(ARM, CFG.arm_hold_ticks + 1);
        assert!(d.blockers.contains(Blocker::BootSettling));
        assert_eq!(r.run(IDLE, 1).state, FlightState::Disarmed);
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
        let mut d = r.step(); // + 6 = 185
        assert_eq!(d.state, FlightState::FailsafeLevel);
        for _ in 0..CFG.failsafe_off_ticks - 185 - 1 {
            r.i.silence_ticks += 1;
            d = r.step();
            assert_eq!(d.state, FlightState::FailsafeLevel);
        }
        r.i.silence_ticks += 1;
        assert_eq!(r.step().state, FlightState::FailsafeOff);
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
    fn with_a_healthy_height_estimate_stage_1_lasts_until_the_descents_cap_taken_at_the_loss() {
        let mut r = Rig::new();
        r.arm();
        r.run(FLY, 10);
        // The height at the loss gives a 5 s cap (the vertical half works it out).
        r.i.descent_cap_ticks = 4000;
        let d = r.lose_link(CFG.failsafe_off_ticks);
        assert_eq!(d.state, FlightState::FailsafeLevel, "no stage-2 cut at 1 s");
        assert!(d.motors_enabled);
        // A cap worked out lower on the way down does not shorten the one taken at the loss.
        r.i.descent_cap_ticks = 900;
        assert_eq!(r.lose_link(4000 - TIMEOUT - CFG.failsafe_off_ticks).state, FlightState::FailsafeLevel);
        let d = r.lose_link(1);
        assert_eq!(d.state, FlightState::FailsafeOff, "the cap");
        assert!(!d.motors_enabled);
    }

    #[test]
    fn a_landing_detected_in_stage_1_turns_the_motors_off_and_disarms() {
        let mut r = Rig::new();
        r.arm();
        r.run(FLY, 10);
        r.i.descent_cap_ticks = 8000;
        assert_eq!(r.lose_link(2000).state, FlightState::FailsafeLevel);
        r.i.landed = true;
        let d = r.lose_link(1);
        assert_eq!(d.state, FlightState::FailsafeOff);
        assert!(!d.motors_enabled);
        // As after any stage 2: the link back gives disarmed, and a full arming is needed.
        r.i.landed = false;
        assert_eq!(r.restore_link(1).state, FlightState::Disarmed);
    }

    #[test]
    fn an_estimate_lost_in_stage_1_falls_back_to_the_manual_budget() {
        let mut r = Rig::new();
        r.arm();
        r.run(FLY, 10);
        r.i.descent_cap_ticks = 8000;
        assert_eq!(r.lose_link(2000).state, FlightState::FailsafeLevel);
        // The barometer fails: 2 s lost is long past the manual budget (1 s): off at once.
        r.i.descent_cap_ticks = 0;
        let d = r.lose_link(1);
        assert_eq!(d.state, FlightState::FailsafeOff);
        assert!(!d.motors_enabled);
    }

    #[test]
    fn without_a_height_estimate_a_landing_flag_while_armed_does_nothing_by_itself() {
        // Armed, the landed hold disarms through the automatic disarm (its throttle is low),
        // not through the flag: the flag acts only in stage 1.
        let mut r = Rig::new();
        r.arm();
        r.run(FLY, 10);
        r.i.landed = true;
        assert_eq!(r.run(FLY, 10).state, FlightState::Armed);
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
        let mut latch = ReferenceLatch::default();
        assert!(!latch.decide(true, None, false).motors_enabled);
        // The arm gesture seen: latched, and nothing but a replay's flag clears it.
        assert!(latch.decide(true, Some(true), false).motors_enabled);
        assert!(latch.decide(true, None, false).motors_enabled);
        // Link loss stops the motors but keeps "armed": they resume when edges return.
        assert!(!latch.decide(false, None, false).motors_enabled);
        assert!(latch.decide(true, None, false).motors_enabled);
        assert_eq!(latch.decide(true, None, true).state, FlightState::Armed);
        assert_eq!(latch.decide(true, Some(false), true).state, FlightState::Calibrating);
    }

    /// The inputs of a random step: (sticks pattern, link, throttle up, fault, calibrating,
    /// tilted) for 1 to 40 ticks.
    type Step = ((u8, bool, bool, bool, bool, bool), u32);

    fn steps() -> impl proptest::strategy::Strategy<Value = proptest::std_facade::Vec<Step>> {
        use proptest::bool::weighted;
        let step = (0u8..5, weighted(0.9), weighted(0.2), weighted(0.005), weighted(0.01), weighted(0.02));
        proptest::collection::vec((step, 1u32..40), 1..60)
    }

    fn inputs_of(((pattern, link, throttle_up, fault, calibrating, tilted), ticks): Step) -> Inputs {
        let base = [IDLE, ARM, DISARM, CAL, FLY][usize::from(pattern)];
        let sticks = Sticks { thr: if throttle_up { StickCounts(1500) } else { base.thr }, ..base };
        Inputs {
            tick: 0,
            link,
            // Any silence: a repeat must be exact whatever the radio says.
            silence_ticks: if link { 0 } else { ticks * 7 },
            sticks,
            gesture: crate::rc::RcConfig::REFERENCE.gesture(&sticks),
            throttle_low: sticks.thr < StickCounts(200),
            calibrated: true,
            calibrating,
            sensor_fault: fault.then_some(SensorFault::Stuck),
            tilt_rad: if tilted { 1.0 } else { 0.0 },
            gcs: GcsCommands::NONE,
            descent_cap_ticks: 0,
            landed: false,
        }
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig::with_cases(200))]
        #[test]
        fn a_steady_decision_kept_is_the_decision_the_supervisor_would_take(seq in steps()) {
            // Short counts so that random sequences arm, fly, fail over and disarm often.
            let cfg = SafetyConfig { arm_hold_ticks: 3, disarm_hold_ticks: 4, auto_disarm_ticks: 20, failsafe_off_ticks: 15, recovery_ticks: 5, boot_settle_ticks: 10, ..SafetyConfig::DEFAULT };
            // `every` decides every tick; `lazy` keeps its last decision whenever it was steady,
            // the link and the sticks are the last tick's and there is no sensor fault, as the
            // control tick does. The other inputs (tilt, calibration) may differ on a kept tick.
            let (mut every, mut lazy) = (Supervisor::new(), Supervisor::new());
            let mut kept: Option<Decision> = None;
            let mut previous: Option<Inputs> = None;
            let mut repeats = 0u32;
            // Every sequence starts by arming and flying, then goes its random way.
            let script: [Step; 4] = [((0, true, false, false, false, false), 12), ((1, true, false, false, false, false), 5), ((0, true, false, false, false, false), 1), ((4, true, true, false, false, false), 5)];
            let mut tick = 0;
            for step in script.into_iter().chain(seq) {
                let mut i = inputs_of(step);
                for _ in 0..step.1 {
                    tick += 1;
                    i.tick = tick;
                    let a = every.decide(&cfg, &i);
                    let radio_changed = previous.is_none_or(|p| p.link != i.link || p.sticks != i.sticks);
                    let b = match kept {
                        Some(d) if lazy.steady() && !radio_changed && i.sensor_fault.is_none() => {
                            repeats += 1;
                            d
                        }
                        _ => lazy.decide(&cfg, &i),
                    };
                    kept = Some(b);
                    previous = Some(i);
                    proptest::prop_assert_eq!(a, b);
                    proptest::prop_assert_eq!(&every, &lazy);
                }
            }
            // Not a vacuous comparison: decisions were kept.
            proptest::prop_assert!(repeats >= 3);
        }
    }

    #[test]
    fn steady_flight_is_steady_and_nothing_else_is() {
        let mut r = Rig::new();
        r.arm();
        assert!(!r.s.steady(), "the arming tick");
        r.run(FLY, 1);
        assert!(r.s.steady());
        r.run(IDLE, 1);
        assert!(!r.s.steady(), "throttle low: the automatic disarm counts");
        r.run(FLY, 1);
        assert!(r.s.steady());
        // A gesture with the throttle up (no stick makes one, but the inputs may say so).
        r.i.gesture = Some(Gesture::Disarm);
        r.step();
        assert!(!r.s.steady(), "a gesture");
        r.run(FLY, 1);
        r.lose_link(1);
        assert!(!r.s.steady(), "stage 1");
    }

    /// One tick with a ground station's commands, then none again.
    fn with_gcs(r: &mut Rig, gcs: GcsCommands) -> Decision {
        r.i.gcs = gcs;
        let d = r.step();
        r.i.gcs = GcsCommands::NONE;
        d
    }

    const DISARM_ASKED: GcsCommands = GcsCommands { disarm: Some(crate::gcs::Disarm { forced: false }), ..GcsCommands::NONE };
    const DISARM_FORCED: GcsCommands = GcsCommands { disarm: Some(crate::gcs::Disarm { forced: true }), ..GcsCommands::NONE };

    #[test]
    fn a_ground_disarm_acts_on_the_ground_and_in_the_air_only_forced() {
        let mut r = Rig::new();
        r.arm();
        // Throttle low: the motors are stopped, the disarm acts at once.
        assert_eq!(with_gcs(&mut r, DISARM_ASKED).state, FlightState::Disarmed);
        // Flying: refused without the force value, taken with it.
        let mut r = Rig::new();
        r.arm();
        r.run(FLY, 10);
        assert_eq!(with_gcs(&mut r, DISARM_ASKED).state, FlightState::Armed);
        assert_eq!(r.step().state, FlightState::Armed, "a refused disarm is not kept for later");
        r.sticks(IDLE);
        assert_eq!(r.step().state, FlightState::Armed, "a refused disarm is not kept for later");
        r.sticks(FLY);
        let d = with_gcs(&mut r, DISARM_FORCED);
        assert_eq!((d.state, d.motors_enabled), (FlightState::Disarmed, false));
    }

    #[test]
    fn a_ground_disarm_abandons_an_arming_and_ends_the_level_stage_only_forced() {
        let mut r = Rig::new();
        r.run(ARM, CFG.arm_hold_ticks / 2);
        assert_eq!(r.last.state, FlightState::Arming);
        assert_eq!(with_gcs(&mut r, DISARM_ASKED).state, FlightState::Disarmed);
        // The gesture still held must be let go before it arms again.
        r.run(ARM, CFG.arm_hold_ticks + 10);
        assert_eq!(r.last.state, FlightState::Disarmed);

        let mut r = Rig::new();
        r.arm();
        r.run(FLY, 10);
        assert_eq!(r.lose_link(1).state, FlightState::FailsafeLevel);
        r.i.gcs = DISARM_ASKED;
        assert_eq!(r.lose_link(1).state, FlightState::FailsafeLevel);
        r.i.gcs = DISARM_FORCED;
        let d = r.lose_link(1);
        assert_eq!((d.state, d.motors_enabled), (FlightState::FailsafeOff, false));
    }

    #[test]
    fn arming_waits_while_the_ground_holds_it_and_a_hold_ends_an_arming() {
        use crate::gcs::Holds;
        let each = [
            (Holds { motor_test: true, ..Holds::NONE }, Blocker::MotorTest, "motor-test"),
            (Holds { radio_calibration: true, ..Holds::NONE }, Blocker::RadioCalibration, "radio-calibration"),
            (Holds { saving: true, ..Holds::NONE }, Blocker::Saving, "saving"),
            (Holds { rebooting: true, ..Holds::NONE }, Blocker::RebootPending, "reboot-pending"),
        ];
        for (holds, blocker, name) in each {
            let mut r = Rig::new();
            r.i.gcs = GcsCommands { holds, ..GcsCommands::NONE };
            let d = r.run(ARM, CFG.arm_hold_ticks + 10);
            assert_eq!(d.state, FlightState::Disarmed, "{name}");
            assert_eq!(d.blockers.iter().collect::<std::vec::Vec<_>>(), [blocker], "{name}");
            assert_eq!(blocker.name(), name);
            // Held no more: a fresh gesture arms.
            r.i.gcs = GcsCommands::NONE;
            r.run(IDLE, 2);
            r.arm();

            let mut r = Rig::new();
            r.run(ARM, 10);
            assert_eq!(r.last.state, FlightState::Arming);
            r.i.gcs = GcsCommands { holds, ..GcsCommands::NONE };
            assert_eq!(r.step().state, FlightState::Disarmed, "{name}");
        }
    }

    #[test]
    fn a_ground_calibration_starts_disarmed_only() {
        let mut r = Rig::new();
        let d = with_gcs(&mut r, GcsCommands { calibrate: true, ..GcsCommands::NONE });
        assert_eq!(d.state, FlightState::Calibrating);
        assert!(d.request_calibration);
        let mut r = Rig::new();
        r.arm();
        r.run(FLY, 10);
        let d = with_gcs(&mut r, GcsCommands { calibrate: true, ..GcsCommands::NONE });
        assert_eq!((d.state, d.request_calibration), (FlightState::Armed, false));
    }

    #[test]
    fn a_ground_disarm_ends_steady_flight_once_unsteady_is_asked() {
        let mut r = Rig::new();
        r.arm();
        r.run(FLY, 10);
        assert!(r.s.steady());
        r.s.unsteady();
        assert!(!r.s.steady());
    }

    // The state table alone.

    /// Every set of conditions: the ten blockers and the eleven other conditions.
    fn every_conditions() -> impl Iterator<Item = Conditions> {
        (0u32..1 << 21).map(|m| Conditions((m & 0x3FF) | (m >> 10) << 16))
    }

    const STATES: [FlightState; 7] = [
        FlightState::Disarmed,
        FlightState::Arming,
        FlightState::Armed,
        FlightState::FailsafeLevel,
        FlightState::FailsafeOff,
        FlightState::Calibrating,
        FlightState::Fault,
    ];

    #[test]
    fn table_a_sensor_fault_leads_to_fault_from_every_state_and_nothing_leaves_it() {
        for c in every_conditions() {
            for s in STATES {
                let next = next_state(s, c);
                if c.contains(FAULT) || s == FlightState::Fault {
                    assert_eq!(next, FlightState::Fault, "{s:?} {c:?}");
                } else {
                    assert_ne!(next, FlightState::Fault, "{s:?} {c:?}");
                }
            }
        }
    }

    #[test]
    fn table_the_motors_come_under_the_sticks_only_by_a_full_arming_or_a_recovery() {
        for c in every_conditions() {
            for s in STATES {
                let next = next_state(s, c);
                if next == FlightState::Arming && s != FlightState::Arming {
                    assert!(s == FlightState::Disarmed && c.contains(ARM_GESTURE) && c.blockers().is_empty(), "{s:?} {c:?}");
                }
                if next == FlightState::Armed && s != FlightState::Armed {
                    let armed = s == FlightState::Arming
                        && c.contains(ARM_HELD.and(STICKS_CENTRED))
                        && !c.intersects(ARM_GESTURE.and(HOLD_BLOCKERS));
                    let recovered = s == FlightState::FailsafeLevel && c.contains(RECOVERED) && !c.intersects(NO_LINK);
                    assert!(armed || recovered, "{s:?} {c:?}");
                }
                if c.contains(NO_LINK) {
                    assert_ne!(next, FlightState::Armed, "{s:?} {c:?}");
                }
            }
        }
    }

    #[test]
    fn table_without_a_link_flight_goes_to_the_failsafe_and_stage_2_only_on_its_budget() {
        for c in every_conditions().filter(|c| !c.contains(FAULT)) {
            let from_armed = next_state(FlightState::Armed, c);
            // A ground station's disarm (the rule checked) comes first: the motors stop.
            if c.contains(GROUND_DISARM) {
                assert_eq!(from_armed, FlightState::Disarmed, "{c:?}");
            } else if c.contains(NO_LINK) {
                let stage = if c.contains(LOSS_BUDGET_SPENT) { FlightState::FailsafeOff } else { FlightState::FailsafeLevel };
                assert_eq!(from_armed, stage, "{c:?}");
            }
            for s in STATES {
                if next_state(s, c) == FlightState::FailsafeOff && s != FlightState::FailsafeOff {
                    let forced = s == FlightState::FailsafeLevel && c.contains(GROUND_DISARM);
                    assert!(c.contains(LOSS_BUDGET_SPENT) || forced, "{s:?} {c:?}");
                }
                if next_state(s, c) == FlightState::FailsafeLevel && s != FlightState::FailsafeLevel {
                    assert!(s == FlightState::Armed && c.contains(NO_LINK), "{s:?} {c:?}");
                }
            }
            // Stage 2 ends only with the link back, and then disarmed.
            let from_off = next_state(FlightState::FailsafeOff, c);
            assert_eq!(from_off, if c.contains(NO_LINK) { FlightState::FailsafeOff } else { FlightState::Disarmed }, "{c:?}");
        }
    }

    #[test]
    fn table_each_blocker_ends_a_hold_and_refuses_its_end() {
        let blockers = Blocker::ALL.into_iter().filter(|&b| b != Blocker::GestureNotReleased && b != Blocker::SensorFault);
        for b in blockers {
            let b = Conditions::blocker(b);
            assert_eq!(next_state(FlightState::Disarmed, ARM_GESTURE.and(b)), FlightState::Disarmed);
            assert_eq!(next_state(FlightState::Arming, ARM_GESTURE.and(b)), FlightState::Disarmed);
            assert_eq!(next_state(FlightState::Arming, ARM_HELD.and(STICKS_CENTRED).and(b)), FlightState::Disarmed);
        }
        assert_eq!(next_state(FlightState::Disarmed, ARM_GESTURE.and(NOT_RELEASED)), FlightState::Disarmed);
        assert_eq!(next_state(FlightState::Disarmed, ARM_GESTURE), FlightState::Arming);
        assert_eq!(next_state(FlightState::Arming, ARM_GESTURE), FlightState::Arming);
        assert_eq!(next_state(FlightState::Arming, ARM_HELD), FlightState::Arming, "waiting for the sticks");
        assert_eq!(next_state(FlightState::Arming, ARM_HELD.and(STICKS_CENTRED)), FlightState::Armed);
        assert_eq!(next_state(FlightState::Arming, STICKS_CENTRED), FlightState::Disarmed, "let go too early");
    }

    #[test]
    fn table_disarming_and_calibrating() {
        assert_eq!(next_state(FlightState::Armed, DISARM_GESTURE), FlightState::Armed);
        assert_eq!(next_state(FlightState::Armed, DISARM_GESTURE.and(DISARM_HELD)), FlightState::Disarmed);
        assert_eq!(next_state(FlightState::Armed, DISARM_GESTURE.and(THROTTLE_LOW_TOO_LONG)), FlightState::Armed);
        assert_eq!(next_state(FlightState::Armed, THROTTLE_LOW_TOO_LONG), FlightState::Disarmed);
        assert_eq!(next_state(FlightState::Armed, CALIBRATE_GESTURE), FlightState::Armed);
        assert_eq!(next_state(FlightState::Disarmed, CALIBRATE_GESTURE), FlightState::Calibrating);
        assert_eq!(next_state(FlightState::Disarmed, CALIBRATE_GESTURE.and(NOT_RELEASED)), FlightState::Disarmed);
        assert_eq!(next_state(FlightState::Calibrating, CALIBRATING), FlightState::Calibrating);
        assert_eq!(next_state(FlightState::Calibrating, NONE), FlightState::Disarmed);
        assert_eq!(next_state(FlightState::FailsafeLevel, RECOVERED.and(LOSS_BUDGET_SPENT)), FlightState::Armed);
        assert_eq!(next_state(FlightState::FailsafeLevel, RECOVERED.and(NO_LINK)), FlightState::FailsafeLevel);
    }
}
