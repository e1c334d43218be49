//! The seam between the link and the flight controller: what the link may see and ask.
//!
//! The link owns no configuration and decides nothing about flight. The host application (the
//! firmware's station, fcu-pil's board, a test's mock) implements [`Vehicle`]: a snapshot of
//! the state for telemetry, the parameter table, and the requests the link passes on. The link
//! refuses only what it cannot decode (UNSUPPORTED, or DENIED for a malformed parameter); every
//! request it decodes goes to the vehicle, whose verdict is fcu-core's ([`Refused`], the rules
//! of [`fcu_core::gcs`]): the link answers it TEMPORARILY_REJECTED when the flight state of
//! the moment refuses it, DENIED otherwise, and names the rule in a STATUSTEXT.

pub use fcu_core::altitude::AltMode;
pub use fcu_core::gcs::Refused;
use fcu_core::supervisor::FlightState;

/// Attitude in MAVLink's convention (ATTITUDE): roll right side down positive, pitch nose up
/// positive, yaw clockwise seen from above positive; rates about the same axes.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Attitude {
    /// Roll, rad.
    pub roll_rad: f32,
    /// Pitch, rad.
    pub pitch_rad: f32,
    /// Yaw, rad.
    pub yaw_rad: f32,
    /// Roll rate, rad/s.
    pub roll_rate_rad_s: f32,
    /// Pitch rate, rad/s.
    pub pitch_rate_rad_s: f32,
    /// Yaw rate, rad/s.
    pub yaw_rate_rad_s: f32,
}

/// The battery as far as it is measured.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Battery {
    /// Voltage, mV.
    pub voltage_mv: u16,
    /// Current, cA (10 mA); -1 when not measured.
    pub current_ca: i16,
    /// Charge left, percent; -1 when not estimated.
    pub remaining_pct: i8,
}

/// Health of what SYS_STATUS reports (all present and enabled on this board).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Health {
    /// Gyro and accelerometer (the LSM6DSL) answering and not faulted.
    pub imu: bool,
    /// Radio receiver: a valid link.
    pub radio: bool,
    /// The attitude estimate is usable (boot calibration done).
    pub estimator: bool,
    /// Battery above its low threshold.
    pub battery: bool,
    /// Nothing refuses arming, or armed (SYS_STATUS' pre-arm check, which QGroundControl
    /// shows as "ready to arm").
    pub prearm: bool,
}

/// The vertical mode: what HEARTBEAT says ([`crate::heartbeat`]) and a ground station's set-mode
/// asks for ([`Request::SetMode`]). Its numbers are ArduCopter's flight modes of the same
/// meaning (the attitude is always self-levelling here): a quadrotor's mode names in MAVProxy
/// and pymavlink are ArduCopter's, so `mode ALT_HOLD` and `set_mode('STABILIZE')` send them.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum VerticalMode {
    /// The throttle stick sets the thrust (ArduCopter's STABILIZE, 0).
    #[default]
    Manual,
    /// Altitude hold (ArduCopter's ALT_HOLD, 2).
    AltitudeHold,
    /// The link-loss failsafe descends on the height estimate (ArduCopter's LAND, 9): shown,
    /// never asked for.
    FailsafeDescent,
}

impl VerticalMode {
    /// Every mode, for tests and tables.
    pub const ALL: [VerticalMode; 3] = [VerticalMode::Manual, VerticalMode::AltitudeHold, VerticalMode::FailsafeDescent];

    /// Its number (ArduCopter's mode of the same meaning).
    pub const fn number(self) -> u8 {
        match self {
            VerticalMode::Manual => 0,
            VerticalMode::AltitudeHold => 2,
            VerticalMode::FailsafeDescent => 9,
        }
    }

    /// The mode numbered `number`, if any.
    pub fn from_number(number: u32) -> Option<VerticalMode> {
        VerticalMode::ALL.into_iter().find(|m| u32::from(m.number()) == number)
    }

    /// A ground station's name for it.
    pub const fn name(self) -> &'static str {
        match self {
            VerticalMode::Manual => "manual throttle",
            VerticalMode::AltitudeHold => "altitude hold",
            VerticalMode::FailsafeDescent => "failsafe descent",
        }
    }

    /// The pilot's choice this mode is, if a ground station may ask for it.
    pub const fn alt_mode(self) -> Option<AltMode> {
        match self {
            VerticalMode::Manual => Some(AltMode::Manual),
            VerticalMode::AltitudeHold => Some(AltMode::Hold),
            VerticalMode::FailsafeDescent => None,
        }
    }
}

/// Height and pressure, as far as they are known.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Altitude {
    /// Above the take-off point, m; `None` while the estimate may not be flown on (no
    /// barometer sample yet, or the barometer faulted).
    pub height_m: Option<f32>,
    /// Upward, m/s (with the height: `None` together).
    pub climb_m_s: Option<f32>,
    /// The barometer's last healthy sample, Pa; `None` before the first.
    pub pressure_pa: Option<f32>,
    /// The barometer's temperature with that sample, °C.
    pub temperature_c: f32,
    /// The vertical mode in force.
    pub mode: VerticalMode,
}

/// A snapshot of the vehicle for one telemetry tick.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VehicleState {
    /// The supervisor's state (HEARTBEAT says it: [`crate::heartbeat`]).
    pub state: FlightState,
    /// For ATTITUDE.
    pub attitude: Attitude,
    /// Radio pulse widths, µs, in receiver channel order; 0 for a channel without pulses.
    pub rc_widths_us: [u16; 8],
    /// Channels the receiver delivers (RC_CHANNELS' `chancount`).
    pub rc_channel_count: u8,
    /// Motor outputs on the 1000–2000 scale of SERVO_OUTPUT_RAW (µs for an ESC, the
    /// equivalent of the duty cycle for the brushed motors).
    pub motor_outputs_us: [u16; 4],
    /// For SYS_STATUS and BATTERY_STATUS.
    pub battery: Battery,
    /// For SYS_STATUS.
    pub health: Health,
    /// Main loop load, per mille (SYS_STATUS' `load`).
    pub load_permille: u16,
    /// A motor test runs, as the flight controller reports it (it decides when one stops).
    pub motor_test: bool,
    /// For VFR_HUD, ALTITUDE, SCALED_PRESSURE and HEARTBEAT's vertical mode.
    pub altitude: Altitude,
}

/// One parameter: name (at most 16 characters, upper case) and value in force.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Param {
    /// Name as the ground station shows it.
    pub name: &'static str,
    /// Value in force (every parameter is a `MAV_PARAM_TYPE_REAL32`).
    pub value: f32,
}

/// A set of parameter indices below [`ParamMask::CAPACITY`]: the parameters a PARAM_SET changed
/// besides the one it set, or the PARAM_VALUEs the link still owes the ground station.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ParamMask {
    words: [u32; 4],
}

impl ParamMask {
    /// Indices a mask can hold: a table with more parameters cannot report the changes of the
    /// ones past it (fcu-gcs's station checks its table fits at compile time).
    pub const CAPACITY: usize = 128;

    /// No index.
    pub const EMPTY: Self = Self { words: [0; 4] };

    /// Adds `index` (nothing past [`ParamMask::CAPACITY`]).
    pub fn insert(&mut self, index: u16) {
        if let Some(word) = self.words.get_mut(usize::from(index / 32)) {
            *word |= 1 << (index % 32);
        }
    }

    /// Takes `index` out.
    pub fn remove(&mut self, index: u16) {
        if let Some(word) = self.words.get_mut(usize::from(index / 32)) {
            *word &= !(1 << (index % 32));
        }
    }

    /// Whether `index` is in.
    pub fn contains(&self, index: u16) -> bool {
        self.words.get(usize::from(index / 32)).is_some_and(|word| word & (1 << (index % 32)) != 0)
    }

    /// No index in.
    pub fn is_empty(&self) -> bool {
        self.words.iter().all(|&word| word == 0)
    }

    /// The lowest index in, if any.
    pub fn first(&self) -> Option<u16> {
        let (i, word) = self.words.iter().enumerate().find(|(_, &word)| word != 0)?;
        Some(i as u16 * 32 + word.trailing_zeros() as u16)
    }

    /// Every index of `self` or `other`.
    pub fn union(self, other: Self) -> Self {
        let mut words = self.words;
        for (word, &o) in words.iter_mut().zip(other.words.iter()) {
            *word |= o;
        }
        Self { words }
    }
}

/// What the link asks the vehicle to do, as decoded; the vehicle decides whether it may
/// ([`fcu_core::gcs`] names each rule).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Request {
    /// Arm (the vehicle refuses: arming is the stick gesture's).
    Arm,
    /// Disarm now. `forced` when the ground station sent MAVLink's force value (armed with the
    /// throttle up or in the failsafe's level stage, the vehicle disarms only forced).
    Disarm {
        /// Sent with the force value 21196.
        forced: bool,
    },
    /// Gyro/accelerometer calibration (the boot calibration); disarmed only.
    CalibrateImu,
    /// Radio calibration: the ground station reads the radio's widths (RC_CHANNELS) and writes
    /// the endpoints and trims as parameters; the vehicle refuses to arm meanwhile. Disarmed
    /// only.
    CalibrateRadio,
    /// End the radio calibration (PREFLIGHT_CALIBRATION with every parameter 0, the way PX4
    /// cancels one). Taken armed or not.
    EndCalibration,
    /// Save the parameters to flash; disarmed only.
    SaveParams,
    /// Reset the parameters to the defaults; disarmed only.
    ResetParams,
    /// Reboot once [`crate::Link::reboot_ready`] says the acknowledgement is out and any
    /// pending save is done; disarmed only.
    Reboot,
    /// Spin one motor for a motor test, as the ground station asked: the vehicle decides
    /// whether it may (disarmed, a motor it has), caps the throttle and the duration, and stops
    /// it at its deadline, on a stick move and on arming ([`crate::motor_test`]).
    MotorTest {
        /// Motor index, 0-based (any: the vehicle knows how many it has).
        motor: u8,
        /// Throttle, percent of full output, as asked (finite, not negative).
        throttle_pct: f32,
        /// How long, ms, as asked.
        duration_ms: u32,
    },
    /// Stop the motor test now (another command came, or the link fell silent).
    StopMotorTest,
    /// A set-mode (SET_MODE, or COMMAND_LONG/INT DO_SET_MODE) naming a mode a ground station
    /// may ask for ([`VerticalMode::Manual`] or [`VerticalMode::AltitudeHold`], the
    /// pilot's choices of [`AltMode`]). The vehicle carries it out as a parameter set, and
    /// answers with the parameters it set, for the link to send their PARAM_VALUEs.
    SetMode(AltMode),
}

/// The host application's side of the link (see the module docs).
pub trait Vehicle {
    /// The state now.
    fn state(&self) -> VehicleState;

    /// Number of parameters; indices run from 0 to `param_count() - 1`.
    fn param_count(&self) -> u16;

    /// Parameter `index`, or `None` past the end.
    fn param(&self, index: u16) -> Option<Param>;

    /// Index of the parameter called `name` (exact, upper case), if any. The name is the
    /// bytes a ground station sent, NUL padding taken off: any bytes, not only UTF-8 (a name
    /// that is not one of the table's has no index, whatever it holds).
    fn param_index(&self, name: &[u8]) -> Option<u16>;

    /// Sets parameter `index` to `value` (finite: the link refuses NaN and infinities before
    /// asking). `Ok` carries every other parameter whose value the set changed (a channel map
    /// swaps the channel another function had), compared by value (-0.0 is 0.0): the link
    /// echoes `index` with the value now in force ([`Vehicle::param`]), then each of these in
    /// index order, so that the ground station's copy of the table stays whole. `Err` is the
    /// rule that refused it (short, it goes into a STATUSTEXT after the parameter's name); on
    /// a refusal nothing may change.
    fn set_param(&mut self, index: u16, value: f32) -> Result<ParamMask, &'static str>;

    /// Carries out a request, or refuses it with fcu-core's verdict (the rule, and whether the
    /// flight state of the moment refuses it). `Ok` carries the parameters the request set
    /// (a set-mode's), whose values the link then sends as PARAM_VALUEs in index order: the
    /// ground station's copy of the table stays the board's.
    fn request(&mut self, request: Request) -> Result<ParamMask, Refused>;
}
