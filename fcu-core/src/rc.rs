//! Radio: capture edges → pulse widths → sticks → attitude targets, and stick gestures.
//!
//! Widths and sticks are in TIM2 counts of 0.25 µs (4000 = 1 ms). Inputs are the captured
//! pins, 0 = PA0 .. 3 = PA3; which stick each carries is the radio map ([`RcMap`], the
//! reference's wiring AIL, ELE, THR, RUD by default). Sticks are the reference's
//! `gAIL, gELE, gTHR, gRUD`: width minus the input's trim (throttle: minus its bottom, never
//! negative), scaled so that the input's endpoints are full deflections ([`RcInput`]); with the
//! reference's endpoints the scale is exactly one.

/// Number of radio channels.
pub const CHANNELS: usize = 4;
pub const AIL: usize = 0;
pub const ELE: usize = 1;
pub const THR: usize = 2;
pub const RUD: usize = 3;

/// The capture counter wraps every 32768 counts (8.192 ms): a 15-bit timer.
pub const CAPTURE_WRAP: u32 = 32_768;
/// Capture counts per microsecond.
pub const COUNTS_PER_US: u32 = 4;

/// One stick's value: its pulse width minus the channel's centre (the throttle's: minus its
/// bottom, never negative), in capture counts of 0.25 µs; the reference's `gAIL`.. `gRUD`.
///
/// Its own type because a throttle stick and a motor's compare value are both 16-bit counts
/// that the reference passes around as `int16`: the mixer turns one into the other
/// ([`MixerConfig::throttle_counts`](crate::mixer::MixerConfig::throttle_counts) gives a
/// [`CompareCounts`](crate::mixer::CompareCounts)), and nothing else may.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, PartialOrd, Ord, Hash)]
#[repr(transparent)]
pub struct StickCounts(pub i16);

impl StickCounts {
    pub const ZERO: StickCounts = StickCounts(0);

    pub fn get(self) -> i16 {
        self.0
    }
}

impl core::fmt::Display for StickCounts {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        self.0.fmt(f)
    }
}

impl From<StickCounts> for i32 {
    fn from(s: StickCounts) -> i32 {
        i32::from(s.0)
    }
}

/// The four sticks.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Sticks {
    pub ail: StickCounts,
    pub ele: StickCounts,
    pub thr: StickCounts,
    pub rud: StickCounts,
}

impl Sticks {
    /// Aileron, elevator, throttle and rudder, counts.
    pub const fn new(ail: i16, ele: i16, thr: i16, rud: i16) -> Sticks {
        Sticks { ail: StickCounts(ail), ele: StickCounts(ele), thr: StickCounts(thr), rud: StickCounts(rud) }
    }
}

/// How pulses are accepted (difference D9).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PulseRules {
    /// The reference: any falling edge reports the stored width, even when no rising edge
    /// of the same pulse was seen (B10), no range check (B11); the edge state is cleared
    /// when no edge arrived on any channel for `reset_after_ticks`.
    Reference { reset_after_ticks: u32 },
    /// A width counts only from a rising and the next falling edge of the same channel, only
    /// inside `[min_counts, max_counts]`, and only if the two edges arrived at most
    /// `max_pulse_ticks` control ticks apart: the 15-bit capture clock wraps every 8.192 ms,
    /// so a pulse of 9.3 ms would otherwise read as 1.1 ms; the tick count cannot alias.
    Validated { min_counts: u16, max_counts: u16, max_pulse_ticks: u16 },
}

/// Yaw stick behaviour (difference D8).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum YawStick {
    /// ±`max_step` per outer step beyond the dead band (reference).
    BangBang,
    /// Proportional beyond the dead band, reaching `max_step` at full scale.
    Proportional,
}

/// What the arm and calibrate gestures ask of the throttle (difference D18).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum GestureThrottle {
    /// At the bottom of its travel, exactly (reference). The Devo's throttle rests well below
    /// its calibrated bottom, so it reads 0; a transmitter calibrated to its own endpoints
    /// rests at its bottom, and a count of jitter above it breaks the gesture every few frames.
    AtBottom,
    /// Low, as every other throttle rule reads it: below `min_throttle` (`MIN_THR`).
    Low,
}

/// What a stick does: the four functions a captured input can carry.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Function {
    Roll,
    Pitch,
    Throttle,
    Yaw,
}

/// The radio map's rule: each function on its own input ([`RcConfig::problem`]).
pub const RULE_RCMAP: &str = "RCMAP: each input once";

/// Which captured input (0-based: 0 = PA0 .. 3 = PA3) carries each function. The parameters
/// `RCMAP_*` are these plus one. A valid map is a permutation of the inputs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RcMap {
    pub roll: u8,
    pub pitch: u8,
    pub throttle: u8,
    pub yaw: u8,
}

impl RcMap {
    /// The reference's wiring: AIL on PA0, ELE on PA1, THR on PA2, RUD on PA3.
    pub const IDENTITY: RcMap = RcMap { roll: AIL as u8, pitch: ELE as u8, throttle: THR as u8, yaw: RUD as u8 };

    /// The input carrying `f`.
    pub fn input(&self, f: Function) -> u8 {
        match f {
            Function::Roll => self.roll,
            Function::Pitch => self.pitch,
            Function::Throttle => self.throttle,
            Function::Yaw => self.yaw,
        }
    }

    /// The function input `input` carries (yaw for an input no other function names, which a
    /// valid map never leaves).
    #[inline(always)] // docs/performance.md, «inlined into the tick».
    pub fn function(&self, input: usize) -> Function {
        if input == usize::from(self.roll) {
            Function::Roll
        } else if input == usize::from(self.pitch) {
            Function::Pitch
        } else if input == usize::from(self.throttle) {
            Function::Throttle
        } else {
            Function::Yaw
        }
    }

    /// Every input carries exactly one function.
    pub fn is_permutation(&self) -> bool {
        let mut seen = [false; CHANNELS];
        for i in [self.roll, self.pitch, self.throttle, self.yaw] {
            match seen.get_mut(usize::from(i)) {
                Some(s) if !*s => *s = true,
                _ => return false,
            }
        }
        true
    }

    /// Give `f` to `input`; the function that had `input` takes `f`'s old input, so the map
    /// stays a permutation. Returns the function moved that way, if any. An input out of range
    /// is ignored (`None`, nothing moves).
    pub fn assign(&mut self, f: Function, input: u8) -> Option<Function> {
        if usize::from(input) >= CHANNELS {
            return None;
        }
        let old = self.input(f);
        if old == input {
            return None;
        }
        let other = self.function(usize::from(input));
        self.set(other, old);
        self.set(f, input);
        Some(other)
    }

    fn set(&mut self, f: Function, input: u8) {
        match f {
            Function::Roll => self.roll = input,
            Function::Pitch => self.pitch = input,
            Function::Throttle => self.throttle = input,
            Function::Yaw => self.yaw = input,
        }
    }
}

/// One captured input's endpoints and sense, capture counts (the parameters `RCn_MIN`,
/// `RCn_MAX`, `RCn_TRIM` are these in µs, `RCn_REV` the sense).
///
/// A centred function (roll, pitch, yaw) reads `width − trim`, scaled so that each endpoint
/// is a full deflection: by `full_scale / (max − trim)` above the trim and
/// `full_scale / (trim − min)` below it. The throttle reads `width − min` scaled by
/// `2·full_scale / (max − min)` (reversed: `max − width`), never negative; its trim is not
/// used. Integer arithmetic, so endpoints one full scale from the trim (the reference's fixed
/// mapping) give a scale of exactly one.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RcInput {
    pub min_counts: u16,
    pub trim_counts: u16,
    pub max_counts: u16,
    /// The stick moves the other way: a longer pulse is a smaller stick value.
    pub reversed: bool,
}

impl RcInput {
    /// A centred stick with `trim_counts` at its centre and one full scale each side
    /// (saturated at the counter's range).
    pub const fn centred(trim_counts: u16, full_scale: u16) -> RcInput {
        RcInput {
            min_counts: trim_counts.saturating_sub(full_scale),
            trim_counts,
            max_counts: trim_counts.saturating_add(full_scale),
            reversed: false,
        }
    }

    /// A throttle with its bottom at `min_counts` and two full scales of travel. The trim,
    /// which the throttle does not read, at the centre: the input can then be given to a
    /// centred function (`RCMAP_*`) with valid endpoints.
    pub const fn throttle(min_counts: u16, full_scale: u16) -> RcInput {
        RcInput {
            min_counts,
            trim_counts: min_counts.saturating_add(full_scale),
            max_counts: min_counts.saturating_add(full_scale).saturating_add(full_scale),
            reversed: false,
        }
    }
}

/// The shortest span from a centred input's trim to either endpoint, and the shortest
/// throttle travel, counts (100 µs): a stick scaled up by at most 4.5 (18× for the throttle's
/// travel), so a pulse of jitter stays a small stick move.
pub const MIN_ENDPOINT_SPAN_COUNTS: u16 = 400;

/// The largest stick full scale, counts: widths times twice this stay inside an `i32`.
pub const MAX_FULL_SCALE: StickCounts = StickCounts(8192);

/// The largest roll and pitch target at full stick, degrees (exclusive): short of the 90° at
/// which the Euler angles the cascade works in break down.
pub const MAX_TILT_LIMIT_DEG: f32 = 85.0;

/// Radio calibration and stick mapping.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RcConfig {
    /// Which input carries which function.
    pub map: RcMap,
    /// Each captured input's endpoints and sense, by input.
    pub inputs: [RcInput; CHANNELS],
    /// Stick full scale, counts (1800 = 450 µs): a centred stick at an endpoint.
    pub full_scale: StickCounts,
    /// Gesture threshold, counts (strict inequality, 1200).
    pub gesture_threshold: StickCounts,
    /// `MIN_THR`: below it the throttle is "low" (200 DC, 20 ESC).
    pub min_throttle: StickCounts,
    /// Roll and pitch target at full stick, degrees: the parameter `ANGLE_MAX` as set, so
    /// that what is set reads back, is saved and loads bit for bit. The targets use
    /// [`max_tilt_rad`](Self::max_tilt_rad) (20° gives the reference's 0.34906584 exactly).
    pub max_tilt_deg: f32,
    /// Yaw dead band, counts (600, inclusive).
    pub yaw_deadband: StickCounts,
    /// Yaw rate at full stick, degrees per second: the parameter `YAW_RATE_MAX` as set (see
    /// `max_tilt_deg`). The heading target moves by [`yaw_max_step_rad`](Self::yaw_max_step_rad)
    /// an outer step (120°/s at 160 Hz gives the reference's 0.01308997 exactly).
    pub yaw_rate_max_deg_s: f32,
    pub yaw_stick: YawStick,
    pub gesture_throttle: GestureThrottle,
    pub pulses: PulseRules,
    /// Link timeout, control ticks since the last edge (reference: 31 ms) or, with validated
    /// pulses, since the last accepted pulse of a channel (100 ms).
    pub link_timeout_ticks: u32,
}

impl RcConfig {
    /// The reference's R release: Walkera Devo 7E centres (AIL 5862, ELE 6151, RUD 6397, the
    /// throttle's bottom 4450) in its fixed channel order, unscaled.
    pub const REFERENCE: RcConfig = RcConfig {
        map: RcMap::IDENTITY,
        inputs: [RcInput::centred(5862, 1800), RcInput::centred(6151, 1800), RcInput::throttle(4450, 1800), RcInput::centred(6397, 1800)],
        full_scale: StickCounts(1800),
        gesture_threshold: StickCounts(1200),
        min_throttle: StickCounts(200),
        // (float)(3.141592654*20/180.0) and (float)(3.141592654*(120.0*0.00625)/180.0): the
        // radians derived from these degrees are those bits (config's tests check it).
        max_tilt_deg: 20.0,
        yaw_deadband: StickCounts(600),
        yaw_rate_max_deg_s: 120.0,
        yaw_stick: YawStick::BangBang,
        gesture_throttle: GestureThrottle::AtBottom,
        pulses: PulseRules::Reference { reset_after_ticks: 25 },
        link_timeout_ticks: 25,
    };

    pub fn is_valid(&self) -> bool {
        self.problem().is_none()
    }

    /// The first rule this configuration breaks, in words short enough for a ground station's
    /// status line (at most 32 characters), or `None`.
    pub fn problem(&self) -> Option<&'static str> {
        let pulses_ok = match self.pulses {
            PulseRules::Reference { .. } => true,
            PulseRules::Validated { min_counts, max_counts, max_pulse_ticks } => {
                min_counts < max_counts && u32::from(max_counts) < CAPTURE_WRAP && max_pulse_ticks > 0
            }
        };
        let broken = |ok: bool, rule: &'static str| (!ok).then_some(rule);
        broken(self.map.is_permutation(), RULE_RCMAP)
            .or_else(|| broken(self.full_scale > StickCounts::ZERO && self.full_scale <= MAX_FULL_SCALE, "stick full scale out of range"))
            .or_else(|| self.endpoints_problem())
            // A gesture is a stick beyond the threshold while the others are centred: it must
            // be reachable, and a centred stick must not make one.
            .or_else(|| broken(self.gesture_threshold > CENTRED_COUNTS && self.gesture_threshold < self.full_scale, "gesture: 76..449 us"))
            .or_else(|| {
                broken(
                    self.min_throttle >= StickCounts::ZERO && i32::from(self.min_throttle) < 2 * i32::from(self.full_scale),
                    "THR_MIN past the throttle travel",
                )
            })
            .or_else(|| broken(self.max_tilt_deg > 0.0 && self.max_tilt_deg < MAX_TILT_LIMIT_DEG, "max angle out of range"))
            .or_else(|| {
                broken(self.yaw_deadband >= StickCounts::ZERO && self.yaw_deadband < self.full_scale, "yaw dead band past full scale")
            })
            .or_else(|| broken(crate::math::within(self.yaw_rate_max_deg_s, 0.0, f32::MAX), "yaw rate out of range"))
            .or_else(|| broken(self.link_timeout_ticks > 0, "radio timeout is zero"))
            .or_else(|| broken(pulses_ok, "pulse limits invalid"))
    }

    /// The endpoints' rule broken: every input `min <= trim <= max` inside the capture wrap,
    /// then a centred function's input at least [`MIN_ENDPOINT_SPAN_COUNTS`] from its trim to
    /// either end and the throttle's that much travel. One pass over the inputs: an input out
    /// of order is reported before any too close, wherever it is.
    fn endpoints_problem(&self) -> Option<&'static str> {
        let span = i32::from(MIN_ENDPOINT_SPAN_COUNTS);
        let mut too_close = false;
        for (i, e) in self.inputs.iter().enumerate() {
            if !(e.min_counts <= e.trim_counts && e.trim_counts <= e.max_counts && u32::from(e.max_counts) < CAPTURE_WRAP) {
                return Some("RCn: need MIN <= TRIM <= MAX");
            }
            let (min, trim, max) = (i32::from(e.min_counts), i32::from(e.trim_counts), i32::from(e.max_counts));
            too_close |= match self.map.function(i) {
                Function::Throttle => max - min < span,
                _ => trim - min < span || max - trim < span,
            };
        }
        too_close.then_some("RCn: MIN/TRIM/MAX too close")
    }

    /// The endpoints of the input that carries `f` (a map naming no input, which
    /// [`is_valid`](Self::is_valid) refuses, reads as a centred stick at 1500 µs).
    pub fn input_for(&self, f: Function) -> RcInput {
        self.inputs.get(usize::from(self.map.input(f))).copied().unwrap_or(RcInput::centred(6000, 1800))
    }

    /// The reference's `update_rc_data` for one input: width → stick (int16), through the map
    /// and the input's endpoints. An input out of range is read as input 3.
    #[inline] // docs/performance.md, «inlined into the tick».
    pub fn stick_from_width(&self, input: usize, width_counts: u16) -> StickCounts {
        let f = self.map.function(input);
        let e = self.inputs.get(input).copied().unwrap_or_else(|| self.input_for(f));
        let w = i32::from(width_counts);
        let fs = i32::from(self.full_scale);
        let v = match f {
            Function::Throttle => {
                let travel = if e.reversed { i32::from(e.max_counts) - w } else { w - i32::from(e.min_counts) };
                if travel > 0 {
                    // In i32: at most 65 535 × 2 × MAX_FULL_SCALE.
                    travel * (2 * fs) / (i32::from(e.max_counts) - i32::from(e.min_counts)).max(1)
                } else {
                    0
                }
            }
            _ => {
                let d = w - i32::from(e.trim_counts);
                let span = if d > 0 {
                    i32::from(e.max_counts) - i32::from(e.trim_counts)
                } else {
                    i32::from(e.trim_counts) - i32::from(e.min_counts)
                };
                let scaled = d * fs / span.max(1);
                if e.reversed {
                    -scaled
                } else {
                    scaled
                }
            }
        };
        // Saturated, not wrapped: a width far past the centre stays a full deflection. (The
        // decoder's widths, below 32 768 counts, never reach either bound.)
        StickCounts(v.clamp(i32::from(i16::MIN), i32::from(i16::MAX)) as i16)
    }

    /// The width, counts, that input `input` must carry for the sticks `s`: the inverse of
    /// [`stick_from_width`](Self::stick_from_width), exact where the scale is one (a throttle
    /// of 0 is sent at the bottom of its travel). For the simulator's transmitters.
    pub fn width_for_sticks(&self, input: usize, s: &Sticks) -> u16 {
        let Some(e) = self.inputs.get(input) else { return 0 };
        let fs = i64::from(self.full_scale.0.max(1));
        let (min, trim, max) = (i64::from(e.min_counts), i64::from(e.trim_counts), i64::from(e.max_counts));
        let w = match self.map.function(input) {
            Function::Throttle => {
                let travel = i64::from(s.thr.0.max(0)) * (max - min) / (2 * fs);
                if e.reversed {
                    max - travel
                } else {
                    min + travel
                }
            }
            f => {
                let v = i64::from(match f {
                    Function::Roll => s.ail.0,
                    Function::Pitch => s.ele.0,
                    _ => s.rud.0,
                });
                let v = if e.reversed { -v } else { v };
                let span = if v > 0 { max - trim } else { trim - min };
                trim + v * span / fs
            }
        };
        w.clamp(1, i64::from(u16::MAX)) as u16
    }

    /// Store a width into the sticks (one input, the function the map gives it), as
    /// `update_rc_data`.
    #[inline(never)] // docs/performance.md, «channels written out».
    pub fn apply_width(&self, sticks: &mut Sticks, input: usize, width_counts: u16) {
        let v = self.stick_from_width(input, width_counts);
        match self.map.function(input) {
            Function::Roll => sticks.ail = v,
            Function::Pitch => sticks.ele = v,
            Function::Throttle => sticks.thr = v,
            Function::Yaw => sticks.rud = v,
        }
    }

    pub fn throttle_low(&self, sticks: &Sticks) -> bool {
        sticks.thr < self.min_throttle
    }

    fn saturate(&self, v: StickCounts) -> i32 {
        crate::math::limit(i32::from(v), -i32::from(self.full_scale), i32::from(self.full_scale))
    }

    /// Roll and pitch target at full stick, rad.
    pub fn max_tilt_rad(&self) -> f32 {
        self.max_tilt_deg.to_radians()
    }

    /// Yaw target change of one outer step at full stick, rad, at `outer_hz` outer steps a
    /// second.
    pub fn yaw_max_step_rad(&self, outer_hz: f32) -> f32 {
        self.yaw_rate_max_deg_s.to_radians() / outer_hz
    }

    /// Pitch and roll targets, rad: `(float)(−sat(stick))·max/full_scale` in f32, left to
    /// right, as `GetTargetEulerAngle`. Elevator forward (positive) is nose down.
    pub fn tilt_targets(&self, sticks: &Sticks) -> (f32, f32) {
        let fs = f32::from(self.full_scale.0);
        let max_tilt_rad = self.max_tilt_rad();
        let pitch = (-self.saturate(sticks.ele)) as f32 * max_tilt_rad / fs;
        let roll = (-self.saturate(sticks.ail)) as f32 * max_tilt_rad / fs;
        (pitch, roll)
    }

    /// The yaw rate the sticks ask for, rad/s: one outer step's heading change at `outer_hz`
    /// outer steps a second, none with the throttle low. What the core reports
    /// (`Status::yaw_rate_target_rad_s`) and what the host's simulator works out from the
    /// frames it sends, for its yaw metric.
    pub fn yaw_rate_rad_s(&self, sticks: &Sticks, outer_hz: f32) -> f32 {
        if self.throttle_low(sticks) {
            0.0
        } else {
            self.yaw_step(sticks, outer_hz) * outer_hz
        }
    }

    /// The yaw target change of one outer step, rad, at `outer_hz` outer steps a second.
    pub fn yaw_step(&self, sticks: &Sticks, outer_hz: f32) -> f32 {
        let max_step_rad = self.yaw_max_step_rad(outer_hz);
        let t = self.saturate(sticks.rud);
        let db = i32::from(self.yaw_deadband);
        match self.yaw_stick {
            YawStick::BangBang => {
                if t > db {
                    max_step_rad
                } else if t < -db {
                    -max_step_rad
                } else {
                    0.0
                }
            }
            YawStick::Proportional => {
                let span = (i32::from(self.full_scale) - db) as f32;
                let beyond = if t > db {
                    (t - db) as f32
                } else if t < -db {
                    (t + db) as f32
                } else {
                    0.0
                };
                max_step_rad * beyond / span
            }
        }
    }

    /// Which gesture the sticks make (strict comparisons, throttle exactly 0 for the
    /// reference's arm and calibration gestures).
    pub fn gesture(&self, s: &Sticks) -> Option<Gesture> {
        // i16 arithmetic: `-th` of a positive i16 cannot overflow.
        let th = self.gesture_threshold.0;
        let throttle_down = match self.gesture_throttle {
            GestureThrottle::AtBottom => s.thr == StickCounts::ZERO,
            GestureThrottle::Low => self.throttle_low(s),
        };
        if throttle_down && s.ele.0 < -th && s.ail.0 > th && s.rud.0 < -th {
            return Some(Gesture::Calibrate);
        }
        if throttle_down && s.ele.0 < -th && s.ail.0 < -th && s.rud.0 > th {
            return Some(Gesture::Arm);
        }
        // Ours (the reference has no disarm): throttle low, rudder hard over the other way,
        // elevator and aileron near centre.
        if self.throttle_low(s) && s.rud.0 < -th && centred(s.ele) && centred(s.ail) {
            return Some(Gesture::Disarm);
        }
        None
    }
}

/// A stick this close to its centre (counts) counts as centred: for the disarm gesture, and
/// for the release that must follow the arm gesture before the motors may run.
pub const CENTRED_COUNTS: StickCounts = StickCounts(300);

/// Whether a stick value is within [`CENTRED_COUNTS`] of centre.
pub fn centred(v: StickCounts) -> bool {
    i32::from(v).abs() <= i32::from(CENTRED_COUNTS)
}

impl Sticks {
    /// Aileron, elevator and rudder all centred: the attitude the drone would take off with is
    /// level and not turning.
    pub fn attitude_sticks_centred(&self) -> bool {
        centred(self.ail) && centred(self.ele) && centred(self.rud)
    }
}

/// A stick gesture.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Gesture {
    /// Throttle down, elevator down, aileron beyond −threshold, rudder beyond +threshold.
    Arm,
    /// Throttle low, rudder beyond −threshold, elevator and aileron centred (±300).
    Disarm,
    /// Throttle down, elevator down, aileron beyond +threshold, rudder beyond −threshold.
    Calibrate,
}

/// One capture event as the capture interrupt reads it: which channel, the captured counter
/// value and the pin level read in the interrupt. The firmware's capture interrupt makes them
/// from TIM2, the host's receivers from the frames they send; [`EdgeDecoder::on_edge`] takes
/// them.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct CaptureEdge {
    /// 0 = AIL .. 3 = RUD; the decoder ignores any other (a stray value cannot index past the
    /// channels).
    pub channel: usize,
    /// The captured counter value; only its low 15 bits count (the counter wraps at
    /// [`CAPTURE_WRAP`]).
    pub capture_counts: u16,
    /// The pin's level in the interrupt: high after a rising edge.
    pub level_high: bool,
}

impl CaptureEdge {
    pub const fn rising(channel: usize, capture_counts: u16) -> CaptureEdge {
        CaptureEdge { channel, capture_counts, level_high: true }
    }

    pub const fn falling(channel: usize, capture_counts: u16) -> CaptureEdge {
        CaptureEdge { channel, capture_counts, level_high: false }
    }
}

/// What the capture side saw since the last control tick.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct PulseBatch {
    /// The latest width each channel produced since the last tick (counts), if any.
    pub width_counts: [Option<u16>; CHANNELS],
    /// Whether any edge arrived on the channel since the last tick.
    pub edge_seen: [bool; CHANNELS],
}

#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
struct EdgeState {
    rise: u16,
    rise_pending: bool,
    /// The decoder's tick count when the rising edge came.
    rise_tick: u32,
    width: u16,
    edges: u8,
}

/// Turns capture timestamps into pulse widths. Owned by the capture interrupt in the
/// firmware; the control tick [`take`](EdgeDecoder::take)s what it produced.
#[derive(Clone, Debug)]
pub struct EdgeDecoder {
    rules: PulseRules,
    ch: [EdgeState; CHANNELS],
    batch: PulseBatch,
    idle_ticks: u32,
    /// Calls of `take`: the control ticks, for the pulse-duration check.
    ticks: u32,
}

/// Width between two capture timestamps on the 15-bit counter (`fall == rise` is a full
/// wrap, as the reference computes it).
pub fn pulse_width(rise_counts: u16, fall_counts: u16) -> u32 {
    let (r, f) = (u32::from(rise_counts) % CAPTURE_WRAP, u32::from(fall_counts) % CAPTURE_WRAP);
    if f > r {
        f - r
    } else {
        f + CAPTURE_WRAP - r
    }
}

impl EdgeDecoder {
    pub fn new(rules: PulseRules) -> Self {
        EdgeDecoder { rules, ch: [EdgeState::default(); CHANNELS], batch: PulseBatch::default(), idle_ticks: 0, ticks: 0 }
    }

    /// One capture event (see [`CaptureEdge`]). Out-of-range channels are ignored.
    pub fn on_edge(&mut self, edge: CaptureEdge) {
        let CaptureEdge { channel, capture_counts, level_high } = edge;
        let (Some(st), Some(seen), Some(out)) =
            (self.ch.get_mut(channel), self.batch.edge_seen.get_mut(channel), self.batch.width_counts.get_mut(channel))
        else {
            return;
        };
        *seen = true;
        let t = capture_counts & 0x7FFF;
        match self.rules {
            PulseRules::Reference { .. } => {
                st.edges = st.edges.saturating_add(1).min(2);
                if level_high {
                    st.rise = t;
                } else {
                    if st.edges >= 2 {
                        st.width = pulse_width(st.rise, t) as u16;
                    }
                    // B10: the stored width is reported even when it was not updated.
                    *out = Some(st.width);
                }
            }
            PulseRules::Validated { min_counts, max_counts, max_pulse_ticks } => {
                if level_high {
                    st.rise = t;
                    st.rise_pending = true;
                    st.rise_tick = self.ticks;
                } else if st.rise_pending {
                    st.rise_pending = false;
                    let w = pulse_width(st.rise, t);
                    let short_enough = self.ticks.wrapping_sub(st.rise_tick) <= u32::from(max_pulse_ticks);
                    if short_enough && (u32::from(min_counts)..=u32::from(max_counts)).contains(&w) {
                        *out = Some(w as u16);
                    }
                }
            }
        }
    }

    /// Hand over what arrived since the last call; called once per control tick.
    pub fn take(&mut self) -> PulseBatch {
        let b = self.batch;
        self.batch = PulseBatch::default();
        self.ticks = self.ticks.wrapping_add(1);
        if b.edge_seen.iter().any(|&e| e) {
            self.idle_ticks = 0;
        } else {
            self.idle_ticks = self.idle_ticks.saturating_add(1);
        }
        if let PulseRules::Reference { reset_after_ticks } = self.rules {
            // The reference's SysTick clears the whole capture state while disconnected.
            if self.idle_ticks > reset_after_ticks {
                self.ch = [EdgeState::default(); CHANNELS];
            }
        }
        b
    }
}

/// The control side of the radio: link state, per-channel validity and the sticks.
///
/// Ages are kept as the tick of each channel's last pulse against a tick counter, not as four
/// counters incremented every tick, and the link as the tick it expires, set when a pulse (or,
/// with the reference's rules, an edge) arrives: on the 800 Hz path, where most ticks carry no
/// pulse, the link test is one comparison.
#[derive(Clone, Debug)]
pub struct Receiver {
    sticks: Sticks,
    /// The gesture the sticks make, re-evaluated only when a width changes them.
    gesture: Option<Gesture>,
    /// Control ticks, starting at `u32::MAX` so that "never" (tick 0) is already older than
    /// any timeout; 64 bits never wrap (2^64 ticks at 800 Hz is 730 million years).
    now: u64,
    last_pulse_at: [u64; CHANNELS],
    /// The link is good while `now` is below this: the last edge (reference) or the stalest
    /// channel's last pulse (validated) plus the timeout, set when they change.
    link_until: u64,
    link: bool,
    /// The last update changed the sticks or the link.
    changed: bool,
}

/// One tick's view of the radio.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RadioState {
    pub sticks: Sticks,
    /// The link is good: reference, an edge within the timeout on any channel; validated,
    /// every channel had an accepted pulse within the timeout.
    pub link: bool,
    /// The gesture the sticks make (whatever the link; the supervisor decides what counts).
    pub gesture: Option<Gesture>,
}

impl RadioState {
    /// Nothing received yet.
    pub const NONE: RadioState = RadioState { sticks: Sticks::new(0, 0, 0, 0), link: false, gesture: None };
}

impl Default for Receiver {
    fn default() -> Self {
        Receiver::new()
    }
}

impl Receiver {
    pub fn new() -> Self {
        // Disconnected at boot, as the reference's `rc_timeout = 1000`.
        Receiver {
            sticks: Sticks::default(),
            gesture: None,
            now: u64::from(u32::MAX),
            last_pulse_at: [0; CHANNELS],
            link_until: 0,
            link: false,
            changed: true,
        }
    }

    pub fn sticks(&self) -> Sticks {
        self.sticks
    }

    /// Whether the last [`update`](Self::update) or [`force`](Self::force) changed the state:
    /// a width arrived (or was forced) or the link came or went. When it did not, everything
    /// that depends only on the radio state is what it was a tick ago.
    pub fn changed(&self) -> bool {
        self.changed
    }

    /// Ticks since the link's anchor: with validated pulses, the last accepted pulse of the
    /// channel heard from longest ago; with the reference's rules, the last edge (`u32::MAX`
    /// if there never was one). The link is good while this is below the timeout; the
    /// supervisor counts lost time from it.
    #[inline(never)] // docs/performance.md, «silence off the path».
    pub fn silence_ticks(&self, cfg: &RcConfig) -> u32 {
        // `link_until` is at most `now` + timeout (an anchor is never in the future), and `now`
        // never comes near `u64::MAX`: no wrap.
        let since_anchor = self.now + u64::from(cfg.link_timeout_ticks) - self.link_until;
        since_anchor.min(u64::from(u32::MAX)) as u32
    }

    /// The state the last [`update`](Self::update) or [`force`](Self::force) left.
    pub fn state(&self) -> RadioState {
        RadioState { sticks: self.sticks, link: self.link, gesture: self.gesture }
    }

    /// Take in one tick's pulses. `on_stick_update` runs after every single-channel update
    /// with the sticks as they are then (the reference evaluates its gestures there).
    pub fn update(&mut self, cfg: &RcConfig, batch: &PulseBatch, mut on_stick_update: impl FnMut(&Sticks)) -> RadioState {
        self.now += 1;
        let now = self.now;
        let [w0, w1, w2, w3] = batch.width_counts;
        let timeout = u64::from(cfg.link_timeout_ticks);
        let any_width = w0.is_some() | w1.is_some() | w2.is_some() | w3.is_some();
        // Most ticks bring no width: everything a width needs is behind this one test.
        if any_width {
            // Written out per channel, in channel order as the reference's gestures need
            // (docs/performance.md, «channels written out»).
            let [t0, t1, t2, t3] = &mut self.last_pulse_at;
            let sticks = &mut self.sticks;
            let mut channel = |at: &mut u64, width: Option<u16>, index: usize| {
                if let Some(w) = width {
                    *at = now;
                    cfg.apply_width(sticks, index, w);
                    on_stick_update(sticks);
                }
            };
            channel(t0, w0, AIL);
            channel(t1, w1, ELE);
            channel(t2, w2, THR);
            channel(t3, w3, RUD);
            if let PulseRules::Validated { .. } = cfg.pulses {
                self.link_until = (*t0).min(*t1).min(*t2).min(*t3) + timeout;
            }
            self.gesture = cfg.gesture(&self.sticks);
        }
        if let PulseRules::Reference { .. } = cfg.pulses {
            let [e0, e1, e2, e3] = batch.edge_seen;
            if e0 | e1 | e2 | e3 {
                self.link_until = now + timeout;
            }
        }
        let was = self.link;
        self.link = now < self.link_until;
        self.changed = any_width | (self.link != was);
        self.state()
    }

    /// Set the radio state directly (golden replay): with `link`, the four widths are
    /// applied in channel order as the reference's capture would; without it, the sticks keep
    /// their last values.
    pub fn force(&mut self, cfg: &RcConfig, widths: [u16; CHANNELS], link: bool) -> RadioState {
        if link {
            for (channel, w) in widths.into_iter().enumerate() {
                cfg.apply_width(&mut self.sticks, channel, w);
            }
            self.gesture = cfg.gesture(&self.sticks);
        }
        self.link = link;
        self.changed = true;
        self.state()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const REF: RcConfig = RcConfig::REFERENCE;
    const VALID: PulseRules = PulseRules::Validated { min_counts: 3200, max_counts: 8800, max_pulse_ticks: 3 };

    #[test]
    fn centred_widths_give_the_reference_sticks() {
        let mut s = Sticks::default();
        for ch in 0..CHANNELS {
            REF.apply_width(&mut s, ch, 6000);
        }
        assert_eq!(s, Sticks::new(138, -151, 1550, -397));
        REF.apply_width(&mut s, THR, 4450);
        assert_eq!(s.thr, StickCounts::ZERO);
    }

    /// Another transmitter: throttle on input 0, roll on 1, yaw on 2, pitch on 3; pitch
    /// reversed; endpoints 1000..2000 µs with the trims at 1500 (throttle 1000..2000).
    fn other_radio() -> RcConfig {
        let mut c = RcConfig { map: RcMap { roll: 1, pitch: 3, throttle: 0, yaw: 2 }, ..REF };
        let e = RcInput { min_counts: 4000, trim_counts: 6000, max_counts: 8000, reversed: false };
        c.inputs = [RcInput { trim_counts: 4000, ..e }, e, e, RcInput { reversed: true, ..e }];
        c
    }

    #[test]
    fn the_reference_endpoints_give_each_width_minus_its_centre_unscaled() {
        // Every width the 15-bit capture can produce, on every input: the fixed mapping.
        let centres = [5862, 6151, 4450, 6397];
        for (input, centre) in centres.into_iter().enumerate() {
            for w in 0..=u16::MAX {
                let d = i32::from(w) - centre;
                let want = if input == THR { d.max(0) } else { d }.clamp(-32768, 32767) as i16;
                assert_eq!(REF.stick_from_width(input, w), StickCounts(want), "input {input} width {w}");
            }
        }
    }

    #[test]
    fn another_transmitter_maps_orders_reverses_and_scales() {
        let c = other_radio();
        assert!(c.is_valid());
        let mut s = Sticks::default();
        // 2000 µs on the roll input (1): a full right roll, 500 µs = 1800 counts.
        c.apply_width(&mut s, 1, 8000);
        assert_eq!(s, Sticks::new(1800, 0, 0, 0));
        // Half way down on the reversed pitch input (3): pitch forward half.
        c.apply_width(&mut s, 3, 5000);
        assert_eq!(s.ele, StickCounts(900));
        // The throttle on input 0: 1000 µs is the bottom, 2000 µs full travel (3600).
        c.apply_width(&mut s, 0, 4000);
        assert_eq!(s.thr, StickCounts::ZERO);
        c.apply_width(&mut s, 0, 3900);
        assert_eq!(s.thr, StickCounts::ZERO);
        c.apply_width(&mut s, 0, 7000);
        assert_eq!(s.thr, StickCounts(2700));
        // Yaw on input 2, left half.
        c.apply_width(&mut s, 2, 5000);
        assert_eq!(s.rud, StickCounts(-900));
        // Asymmetric endpoints: each side is a full scale at its endpoint.
        let mut a = REF;
        a.inputs[AIL] = RcInput { min_counts: 5000, trim_counts: 6000, max_counts: 8000, reversed: false };
        assert_eq!(a.stick_from_width(AIL, 5000), StickCounts(-1800));
        assert_eq!(a.stick_from_width(AIL, 8000), StickCounts(1800));
        assert_eq!(a.stick_from_width(AIL, 7000), StickCounts(900));
        // A reversed throttle: the longest pulse is the bottom.
        let mut r = REF;
        r.inputs[THR].reversed = true;
        assert_eq!(r.stick_from_width(THR, 8050), StickCounts::ZERO);
        assert_eq!(r.stick_from_width(THR, 4450), StickCounts(3600));
    }

    #[test]
    fn widths_for_sticks_invert_the_mapping_where_the_scale_is_one_and_near_it_elsewhere() {
        for c in [REF, other_radio()] {
            for s in [
                Sticks::new(0, 0, 0, 0),
                Sticks::new(1800, -1800, 3600, 900),
                Sticks::new(-1300, -1300, 0, 1300),
                Sticks::new(7, -3, 101, -599),
            ] {
                let mut got = Sticks::default();
                for input in 0..CHANNELS {
                    c.apply_width(&mut got, input, c.width_for_sticks(input, &s));
                }
                let close = |a: StickCounts, b: StickCounts| (i32::from(a) - i32::from(b)).abs() <= 1;
                assert!(
                    close(got.ail, s.ail) && close(got.ele, s.ele) && close(got.thr, s.thr) && close(got.rud, s.rud),
                    "{s:?} -> {got:?}"
                );
                if c == REF {
                    assert_eq!(got, s);
                }
            }
        }
    }

    #[test]
    fn a_map_that_is_not_a_permutation_is_refused() {
        for map in [
            RcMap { roll: 0, pitch: 0, throttle: 2, yaw: 3 },
            RcMap { roll: 0, pitch: 1, throttle: 2, yaw: 4 },
            RcMap { roll: 3, pitch: 3, throttle: 3, yaw: 3 },
        ] {
            assert!(!map.is_permutation(), "{map:?}");
            assert!(!RcConfig { map, ..REF }.is_valid(), "{map:?}");
        }
        assert!(other_radio().map.is_permutation());
    }

    #[test]
    fn assigning_an_input_swaps_with_the_function_that_had_it() {
        let mut m = RcMap::IDENTITY;
        assert_eq!(m.assign(Function::Roll, 2), Some(Function::Throttle));
        assert_eq!(m, RcMap { roll: 2, pitch: 1, throttle: 0, yaw: 3 });
        assert_eq!(m.assign(Function::Roll, 2), None);
        assert_eq!(m.assign(Function::Yaw, 4), None);
        assert_eq!(m, RcMap { roll: 2, pitch: 1, throttle: 0, yaw: 3 });
        assert!(m.is_permutation());
    }

    #[test]
    fn endpoints_that_make_no_sense_are_refused() {
        let with = |input: usize, f: &dyn Fn(&mut RcInput)| {
            let mut c = REF;
            f(&mut c.inputs[input]);
            c.is_valid()
        };
        assert!(with(AIL, &|_| {}));
        // Trim outside min..max, min above max, a side shorter than 100 µs.
        assert!(!with(AIL, &|e| e.trim_counts = e.max_counts + 1));
        assert!(!with(AIL, &|e| e.trim_counts = e.min_counts - 1));
        assert!(!with(AIL, &|e| core::mem::swap(&mut e.min_counts, &mut e.max_counts)));
        assert!(!with(AIL, &|e| e.max_counts = e.trim_counts + MIN_ENDPOINT_SPAN_COUNTS - 1));
        assert!(with(AIL, &|e| e.max_counts = e.trim_counts + MIN_ENDPOINT_SPAN_COUNTS));
        assert!(!with(ELE, &|e| e.min_counts = e.trim_counts - MIN_ENDPOINT_SPAN_COUNTS + 1));
        // The throttle needs only travel: its trim may sit at the bottom, not its max.
        assert!(with(THR, &|e| e.trim_counts = e.min_counts));
        assert!(!with(THR, &|e| e.max_counts = e.min_counts + MIN_ENDPOINT_SPAN_COUNTS - 1));
        assert!(!with(THR, &|e| e.trim_counts = e.max_counts + 1));
        // Past the capture wrap no width can reach it.
        assert!(!with(RUD, &|e| e.max_counts = CAPTURE_WRAP as u16));
        // Endpoints that suit a throttle (trim at the bottom) do not suit a centred stick.
        let mut c = REF;
        c.inputs[THR].trim_counts = c.inputs[THR].min_counts;
        assert!(c.is_valid());
        c.map.assign(Function::Roll, THR as u8);
        assert!(!c.is_valid());
    }

    #[test]
    fn an_input_out_of_order_is_named_before_one_too_close_wherever_they_are() {
        let mut c = REF;
        c.inputs[AIL].max_counts = c.inputs[AIL].trim_counts + 1;
        assert_eq!(c.problem(), Some("RCn: MIN/TRIM/MAX too close"));
        c.inputs[RUD].trim_counts = c.inputs[RUD].max_counts + 1;
        assert_eq!(c.problem(), Some("RCn: need MIN <= TRIM <= MAX"));
    }

    #[test]
    fn gesture_thresholds_that_no_stick_can_reach_or_a_centred_one_makes_are_refused() {
        assert!(!RcConfig { gesture_threshold: StickCounts(1800), ..REF }.is_valid());
        assert!(!RcConfig { gesture_threshold: CENTRED_COUNTS, ..REF }.is_valid());
        assert!(RcConfig { gesture_threshold: StickCounts(1799), ..REF }.is_valid());
        assert!(!RcConfig { full_scale: StickCounts(MAX_FULL_SCALE.0 + 1), ..REF }.is_valid());
        assert!(!RcConfig { min_throttle: StickCounts(3600), ..REF }.is_valid());
    }

    #[test]
    fn pulse_width_handles_the_15_bit_wrap() {
        assert_eq!(pulse_width(1000, 7000), 6000);
        assert_eq!(pulse_width(32000, 1000), 1768);
        assert_eq!(pulse_width(5, 5), 32768);
    }

    #[test]
    fn gestures_use_strict_thresholds() {
        let g = |ele, ail, rud| REF.gesture(&Sticks::new(ail, ele, 0, rud));
        assert_eq!(g(-1300, 1300, -1300), Some(Gesture::Calibrate));
        assert_eq!(g(-1300, -1300, 1300), Some(Gesture::Arm));
        assert_eq!(g(-1200, -1300, 1300), None);
        assert_eq!(g(0, 0, -1300), Some(Gesture::Disarm));
        assert_eq!(g(0, 301, -1300), None);
    }

    #[test]
    fn targets_match_the_reference_examples() {
        let (p, _) = REF.tilt_targets(&Sticks { ele: StickCounts(900), ..Sticks::default() });
        assert!((p + 0.174_532_93).abs() < 1e-7);
        let (_, r) = REF.tilt_targets(&Sticks { ail: StickCounts(-2500), ..Sticks::default() });
        assert!((r - 0.349_065_87).abs() < 1e-7);
        assert_eq!(REF.yaw_step(&Sticks { rud: StickCounts(601), ..Sticks::default() }, 160.0), 0.013_089_97);
        assert_eq!(REF.yaw_step(&Sticks { rud: StickCounts(600), ..Sticks::default() }, 160.0), 0.0);
    }

    #[test]
    fn proportional_yaw_reaches_the_same_maximum() {
        let cfg = RcConfig { yaw_stick: YawStick::Proportional, ..REF };
        assert_eq!(cfg.yaw_step(&Sticks { rud: StickCounts(600), ..Sticks::default() }, 160.0), 0.0);
        assert!((cfg.yaw_step(&Sticks { rud: StickCounts(1800), ..Sticks::default() }, 160.0) - REF.yaw_max_step_rad(160.0)).abs() < 1e-9);
        assert!(
            (cfg.yaw_step(&Sticks { rud: StickCounts(-1200), ..Sticks::default() }, 160.0) + REF.yaw_max_step_rad(160.0) * 0.5).abs()
                < 1e-9
        );
    }

    #[test]
    fn reference_decoder_reports_a_bogus_width_on_the_first_falling_edge() {
        let mut d = EdgeDecoder::new(REF.pulses);
        d.on_edge(CaptureEdge::falling(AIL, 1000));
        assert_eq!(d.take().width_counts[AIL], Some(0));
    }

    #[test]
    fn validated_decoder_needs_both_edges_of_one_pulse() {
        let mut d = EdgeDecoder::new(VALID);
        d.on_edge(CaptureEdge::falling(AIL, 1000));
        assert_eq!(d.take().width_counts[AIL], None);
        d.on_edge(CaptureEdge::rising(AIL, 30000));
        d.on_edge(CaptureEdge::falling(AIL, 30000u16.wrapping_add(6000) % 32768));
        assert_eq!(d.take().width_counts[AIL], Some(6000));
    }

    #[test]
    fn validated_decoder_rejects_out_of_range_widths() {
        let mut d = EdgeDecoder::new(VALID);
        d.on_edge(CaptureEdge::rising(THR, 100));
        d.on_edge(CaptureEdge::falling(THR, 100)); // fall == rise: 32768 counts
        d.on_edge(CaptureEdge::rising(ELE, 100));
        d.on_edge(CaptureEdge::falling(ELE, 300)); // 50 µs glitch
        let b = d.take();
        assert_eq!(b.width_counts, [None; CHANNELS]);
        assert!(b.edge_seen[THR] && b.edge_seen[ELE]);
    }

    #[test]
    fn a_width_far_past_centre_saturates_instead_of_wrapping() {
        let mut s = Sticks::default();
        REF.apply_width(&mut s, AIL, u16::MAX);
        assert_eq!(s.ail, StickCounts(i16::MAX));
    }

    #[test]
    fn a_pulse_longer_than_the_capture_wrap_does_not_alias_into_a_valid_width() {
        // 9.5 ms high: the 15-bit clock wraps at 8.192 ms, so the edges' counts are 1.308 ms
        // apart, a valid-looking width. The rise came 7 control ticks before the fall.
        let mut d = EdgeDecoder::new(VALID);
        d.on_edge(CaptureEdge::rising(AIL, 1000));
        for _ in 0..7 {
            assert_eq!(d.take().width_counts[AIL], None);
        }
        d.on_edge(CaptureEdge::falling(AIL, (1000 + 38_000 - 32_768) as u16));
        assert_eq!(d.take().width_counts[AIL], None, "a 9.5 ms pulse must not read as 1.3 ms");
    }

    #[test]
    fn pulses_across_a_capture_wrap_and_a_tick_boundary_still_count() {
        // A 2.2 ms pulse straddling the wrap, its falling edge two ticks after its rising one.
        let mut d = EdgeDecoder::new(VALID);
        d.on_edge(CaptureEdge::rising(THR, 30_000));
        d.take();
        d.take();
        d.on_edge(CaptureEdge::falling(THR, (30_000 + 8800 - 32_768) as u16));
        assert_eq!(d.take().width_counts[THR], Some(8800));
    }

    /// One pulse on THR, rising at absolute capture count `rise_at` and `length` counts long,
    /// fed to the default decoder tick by tick (5000 counts per tick): the width it reports.
    fn decode_one_pulse(rise_at: u64, length: u64) -> Option<u16> {
        const TICK: u64 = 5000;
        let mut d = EdgeDecoder::new(VALID);
        let fall_at = rise_at + length;
        let mut width = None;
        for tick in rise_at / TICK..=fall_at / TICK {
            for (at, high) in [(rise_at, true), (fall_at, false)] {
                if at / TICK == tick {
                    d.on_edge(CaptureEdge { channel: THR, capture_counts: (at % u64::from(CAPTURE_WRAP)) as u16, level_high: high });
                }
            }
            width = width.or(d.take().width_counts[THR]);
        }
        width
    }

    #[test]
    fn receiver_link_needs_every_channel_with_validated_pulses() {
        let cfg = RcConfig { pulses: VALID, link_timeout_ticks: 80, ..REF };
        let mut r = Receiver::new();
        let mut b = PulseBatch { width_counts: [Some(6000), Some(6000), None, Some(6000)], ..PulseBatch::default() };
        assert!(!r.update(&cfg, &b, |_| {}).link);
        b.width_counts[THR] = Some(4400);
        assert!(r.update(&cfg, &b, |_| {}).link);
        let empty = PulseBatch::default();
        for _ in 0..79 {
            assert!(r.update(&cfg, &empty, |_| {}).link);
        }
        assert!(!r.update(&cfg, &empty, |_| {}).link);
    }

    #[test]
    fn receiver_link_with_reference_rules_follows_any_edge() {
        let cfg = RcConfig { link_timeout_ticks: 25, ..REF };
        let mut r = Receiver::new();
        let empty = PulseBatch::default();
        assert!(!r.update(&cfg, &empty, |_| {}).link);
        let edge = PulseBatch { edge_seen: [false, false, true, false], ..PulseBatch::default() };
        assert!(r.update(&cfg, &edge, |_| {}).link);
        for _ in 0..24 {
            assert!(r.update(&cfg, &empty, |_| {}).link);
        }
        assert!(!r.update(&cfg, &empty, |_| {}).link);
    }

    #[test]
    fn receiver_reports_the_gesture_of_the_latest_sticks() {
        let cfg = RcConfig { pulses: VALID, ..REF };
        let mut r = Receiver::new();
        // Arm: throttle at the bottom, elevator and aileron low, rudder high.
        let arm =
            PulseBatch { width_counts: [Some(5862 - 1500), Some(6151 - 1500), Some(4450), Some(6397 + 1500)], ..PulseBatch::default() };
        assert_eq!(r.update(&cfg, &arm, |_| {}).gesture, Some(Gesture::Arm));
        // It holds while no pulse changes the sticks, and goes with the first that does.
        assert_eq!(r.update(&cfg, &PulseBatch::default(), |_| {}).gesture, Some(Gesture::Arm));
        let centre_rudder = PulseBatch { width_counts: [None, None, None, Some(6397)], ..PulseBatch::default() };
        assert_eq!(r.update(&cfg, &centre_rudder, |_| {}).gesture, None);
    }

    proptest::proptest! {
        #[test]
        fn receiver_state_equals_per_tick_channel_ages(
            ticks in proptest::collection::vec((proptest::array::uniform4(proptest::option::weighted(0.2, 3200u16..8800)), proptest::array::uniform4(proptest::bool::weighted(0.3))), 0..400),
            timeout in 1u32..60,
            validated in proptest::bool::ANY,
        ) {
            // The model: what the receiver promises, counted tick by tick.
            let pulses = if validated { VALID } else { PulseRules::Reference { reset_after_ticks: 25 } };
            let cfg = RcConfig { pulses, link_timeout_ticks: timeout, ..REF };
            let mut r = Receiver::new();
            let mut ages = [u32::MAX; CHANNELS];
            let mut since_edge = u32::MAX;
            let mut sticks = Sticks::default();
            // Before the first update the receiver reports nothing received.
            let mut last = Some(RadioState::NONE);
            for (widths, edges) in ticks {
                let b = PulseBatch { width_counts: widths, edge_seen: edges };
                let got = r.update(&cfg, &b, |_| {});
                since_edge = if edges.iter().any(|&e| e) { 0 } else { since_edge.saturating_add(1) };
                for ((age, w), ch) in ages.iter_mut().zip(widths).zip(0..) {
                    match w {
                        Some(w) => { *age = 0; cfg.apply_width(&mut sticks, ch, w); }
                        None => *age = age.saturating_add(1),
                    }
                }
                let link = if validated { ages.iter().all(|&a| a < timeout) } else { since_edge < timeout };
                let want = RadioState { sticks, link, gesture: cfg.gesture(&sticks) };
                // Unchanged means: no width and the same state as a tick ago.
                if !r.changed() {
                    proptest::prop_assert!(widths.iter().all(Option::is_none));
                    proptest::prop_assert_eq!(Some(want), last);
                }
                last = Some(want);
                proptest::prop_assert_eq!(got, want);
                // Lost time counts from the stalest channel's last pulse (or the last edge).
                let silence = if validated { ages.iter().copied().max().unwrap_or(u32::MAX) } else { since_edge };
                proptest::prop_assert_eq!(r.silence_ticks(&cfg), silence);
            }
        }

        #[test]
        fn width_is_correct_across_the_wrap(rise in 0u32..32768, width in 1u32..32768) {
            let fall = (rise + width) % CAPTURE_WRAP;
            proptest::prop_assert_eq!(pulse_width(rise as u16, fall as u16), width);
        }

        #[test]
        fn a_stick_beyond_full_scale_saturates_at_the_configured_angle(ele in proptest::num::i16::ANY, ail in proptest::num::i16::ANY) {
            let (p, r) = REF.tilt_targets(&Sticks { ele: StickCounts(ele), ail: StickCounts(ail), ..Sticks::default() });
            // Full scale gives the configured angle to f32 rounding (the reference's own
            // arithmetic lands one ulp above it), and anything beyond gives exactly that.
            let full = REF.tilt_targets(&Sticks { ele: StickCounts(1800), ail: StickCounts(-1800), ..Sticks::default() });
            proptest::prop_assert!((full.1 - REF.max_tilt_rad()).abs() <= 1e-6 * REF.max_tilt_rad());
            proptest::prop_assert!(p.abs() <= full.1 && r.abs() <= full.1);
            if ele >= 1800 { proptest::prop_assert_eq!(p, full.0); }
            if ail <= -1800 { proptest::prop_assert_eq!(r, full.1); }
        }

        #[test]
        fn every_valid_width_is_accepted_wherever_it_falls_against_the_wrap_and_the_ticks(
            rise_at in 0u64..10_000_000,
            width in 3200u64..=8800,
        ) {
            // Fed as the firmware feeds it: each edge before the `take` of the tick it came in,
            // the counter wrapping every 32768 counts, 5000 counts per 800 Hz tick.
            proptest::prop_assert_eq!(decode_one_pulse(rise_at, width), Some(width as u16));
        }

        #[test]
        fn no_pulse_longer_than_the_capture_wrap_is_accepted(
            rise_at in 0u64..10_000_000,
            length in u64::from(CAPTURE_WRAP)..20 * u64::from(CAPTURE_WRAP),
        ) {
            proptest::prop_assert_eq!(decode_one_pulse(rise_at, length), None);
        }

        #[test]
        fn decoder_never_panics_and_validated_widths_are_in_range(
            edges in proptest::collection::vec((0usize..6, proptest::num::u16::ANY, proptest::bool::ANY), 0..200)
        ) {
            let mut d = EdgeDecoder::new(VALID);
            for (ch, t, lvl) in edges {
                d.on_edge(CaptureEdge { channel: ch, capture_counts: t, level_high: lvl });
            }
            for w in d.take().width_counts.into_iter().flatten() {
                proptest::prop_assert!((3200..=8800).contains(&w));
            }
        }
    }
}
