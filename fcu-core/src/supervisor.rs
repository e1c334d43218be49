//! The supervisor: the one place that decides whether the motors may turn.
//!
//! Two kinds, chosen by [`SupervisorConfig`]:
//! - [`SupervisorConfig::Reference`]: the ST reference's behaviour (B8–B11, B16): the arm
//!   gesture latches "armed" for ever, motors run while armed and any edge arrived in the
//!   last 31 ms, no failsafe, calibration on the gesture at any time.
//! - [`SupervisorConfig::Safe`]: the product's safety layer (product.md §4), a state machine
//!   whose table is [`Supervisor::step`]. Every number is a field of [`SafetyConfig`], in
//!   control ticks.

use crate::imu::SensorFault;
use crate::rc::{Gesture, Sticks};

/// Numbers of the safety layer, in control ticks (800 per second in the default profile).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SafetyConfig {
    /// The arm gesture must be held this long on a good link, then released (1.0 s).
    pub arm_hold_ticks: u32,
    /// The disarm gesture must be held this long (1.0 s).
    pub disarm_hold_ticks: u32,
    /// Armed with the throttle low this long disarms (5 s).
    pub auto_disarm_ticks: u32,
    /// Ticks of link loss (counted from when the link stops being good, which is itself
    /// 100 ms after the last pulse) until stage 2: motors off and disarmed (0.9 s, so
    /// stage 2 comes 1.0 s after the last pulse).
    pub failsafe_off_ticks: u32,
    /// A good link must last this long before stage 1 hands control back (100 ms).
    pub recovery_ticks: u32,
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
        failsafe_off_ticks: 720,
        recovery_ticks: 80,
        max_arm_tilt_rad: 0.436_332_3,
        boot_settle_ticks: 1600,
    };

    pub fn is_valid(&self) -> bool {
        self.arm_hold_ticks > 0
            && self.disarm_hold_ticks > 0
            && self.auto_disarm_ticks > 0
            && self.failsafe_off_ticks > 0
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
    /// Link lost for 1 s: motors off, disarmed; the link must return and a full arming
    /// procedure follow.
    FailsafeOff,
    /// Averaging sensor offsets; motors off.
    Calibrating,
    /// A sensor fault was seen: motors off until reset.
    Fault,
}

impl FlightState {
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
}

/// What the supervisor decided for this tick.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Decision {
    pub state: FlightState,
    /// The motors may run this tick (the pipeline still cuts them while the throttle is low).
    pub motors_enabled: bool,
    /// Stage-1 failsafe: level targets, zero yaw rate and this throttle instead of the sticks.
    pub failsafe_throttle: Option<i16>,
    /// Start a calibration now.
    pub request_calibration: bool,
    pub blockers: Blockers,
}

/// The supervisor's memory.
#[derive(Clone, Debug)]
pub struct Supervisor {
    state: FlightState,
    /// Ticks the current gesture (arm or disarm) has been held.
    hold_ticks: u32,
    /// The arm/disarm/calibrate gestures were let go since the last one acted (and since the
    /// link came up): a gesture held through a reconnect or an arm must not act again.
    released: bool,
    lost_ticks: u32,
    good_ticks: u32,
    low_throttle_ticks: u32,
    boot_ticks: u32,
    last_good_throttle: i16,
    fault: Option<SensorFault>,
    /// Reference latch (the reference has no disarm).
    reference_armed: bool,
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
            good_ticks: 0,
            low_throttle_ticks: 0,
            boot_ticks: 0,
            last_good_throttle: 0,
            fault: None,
            reference_armed: false,
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
    pub fn step_reference(&mut self, link: bool, armed_override: Option<bool>, calibrating: bool) -> Decision {
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
    pub fn step(&mut self, cfg: &SafetyConfig, i: &Inputs) -> Decision {
        self.boot_ticks = self.boot_ticks.saturating_add(1);
        if let Some(f) = i.sensor_fault {
            // Latched until reset: motors off, disarmed.
            self.fault.get_or_insert(f);
        }
        if i.link {
            self.good_ticks = self.good_ticks.saturating_add(1);
        } else {
            self.good_ticks = 0;
        }
        // Loss time counts every tick of stage 1 without a good link and only restarts once
        // control is handed back: a flickering link cannot stretch stage 1 for ever.
        if self.state == FlightState::FailsafeLevel && !i.link {
            self.lost_ticks = self.lost_ticks.saturating_add(1);
        }
        let gesture = if i.link { i.gesture } else { None };
        let blockers = self.blockers(cfg, i);
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
                Some(Gesture::Arm) if self.released && without(blockers, Blocker::GestureNotReleased).is_empty() => {
                    self.hold_ticks = 1;
                    FlightState::Arming
                }
                _ => FlightState::Disarmed,
            },
            FlightState::Arming => {
                let others = without(blockers, Blocker::GestureNotReleased);
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
                    // Released after a full hold, nothing against it: armed.
                    self.low_throttle_ticks = 0;
                    FlightState::Armed
                } else {
                    FlightState::Disarmed
                }
            }
            FlightState::Armed => {
                self.low_throttle_ticks = if i.throttle_low { self.low_throttle_ticks.saturating_add(1) } else { 0 };
                if !i.link {
                    self.last_good_throttle = self.last_good_throttle.min(i.sticks.thr);
                    self.lost_ticks = 0;
                    FlightState::FailsafeLevel
                } else if gesture == Some(Gesture::Disarm) {
                    self.hold_ticks = self.hold_ticks.saturating_add(1);
                    if self.hold_ticks >= cfg.disarm_hold_ticks {
                        self.released = false;
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
                    FlightState::Armed
                } else if self.lost_ticks >= cfg.failsafe_off_ticks {
                    self.released = false;
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
            blockers: self.blockers(cfg, i),
        }
    }
}

fn without(b: Blockers, x: Blocker) -> Blockers {
    Blockers(b.0 & !(x as u16))
}
