//! The vertical half of the outer step: the barometer's health, the height estimate, the
//! ground state (lift-off and landing detection) and altitude hold, with what it hands the
//! control tick (one collective throttle) and the supervisor (the failsafe descent's time cap
//! and the landing). `docs/altitude.md` has the numbers and the reasons.
//!
//! The hold is a cascade run at the outer rate (160 Hz): height error → climb rate (P) →
//! collective throttle (PI on the climb rate, with the hover throttle as feedforward). Its output
//! is in throttle stick counts ([`StickCounts`]), the unit the tick's throttle map already reads:
//! the tick flies it in place of the stick's throttle and does nothing else with it. A descent
//! the stick asks slows near the floor to the failsafe's rate ([`LAND_SLOW_M`]).
//!
//! Ground and air:
//! - armed before the take-off, or after a landing, the drone is on the ground: the estimator
//!   takes the floor as its height, and the hold keeps the throttle at the bottom (the tick's
//!   throttle cut stops the motors, and the supervisor's automatic disarm counts) until the stick
//!   asks for a climb, when it ramps the throttle up to the hover's;
//! - it is airborne once the collective reaches [`LIFTOFF_FRACTION`] of the hover throttle;
//! - it has landed when, descending, the collective has stayed below [`LAND_FRACTION`] of the
//!   hover throttle with the height estimate still ([`LAND_SPEED_M_S`]) and the accelerometer
//!   too ([`LAND_ACCEL_M_S2`]) for [`LAND_TIME_S`].

use crate::altitude::{vertical_accel_m_s2, AltMode, AltitudeConfig, AltitudeEstimate, AltitudeEstimator, AltitudeStatus};
use crate::baro::{BaroFault, BaroHealthConfig, BaroMonitor, RawBaro};
use crate::math::{limit, within, Quat, Vec3};
use crate::rc::StickCounts;

/// The hold's tunables (parameters `CLIMB_RATE_MAX`, `FS_DESCENT_RATE`, `ALT_*`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HoldConfig {
    /// Climb and descent rate at full stick, m/s.
    pub climb_rate_max_m_s: f32,
    /// The link-loss failsafe's descent, and the stick's fastest near the floor, m/s.
    pub fs_descent_rate_m_s: f32,
    /// Throttle stick travel either side of its centre that asks for no climb.
    pub deadband: StickCounts,
    /// Height error to climb rate, 1/s.
    pub pos_p: f32,
    /// Climb-rate error to throttle, stick counts per m/s.
    pub vel_p: f32,
    /// Its integral, stick counts per m.
    pub vel_i: f32,
    /// The throttle that hovers, stick counts: the feedforward of a take-off in hold, until the
    /// hold has learned the airframe's.
    pub hover_throttle: StickCounts,
}

impl HoldConfig {
    /// For the STEVAL-FCU001V1 on its 8520 motors (65 g, 4 × 0.33 N): it hovers at a duty of
    /// about 0.4, some 530 stick counts (132.5 µs of throttle) through the throttle map; a stick
    /// count is then 0.0036 m/s² of lift, so 1 m/s² is some 280 counts.
    /// - climb 1 m/s, failsafe descent 0.4 m/s (a room's height in some 6 s, and a touchdown
    ///   well under 0.5 m/s on an airframe 30 % off the nominal);
    /// - dead band ±360 counts (±90 µs, a tenth of the travel each side of centre);
    /// - height loop 1/s (at 1.5/s the barometer's noise through the height error shook the
    ///   throttle in the 1–5 Hz band more than a pilot's hand does); climb-rate loop 1100 counts
    ///   per m/s (some 4 rad/s, a decade under the attitude loops) with the integral's zero at
    ///   1 rad/s (1100 counts per m).
    pub const DEFAULT: HoldConfig = HoldConfig {
        climb_rate_max_m_s: 1.0,
        fs_descent_rate_m_s: 0.4,
        deadband: StickCounts(360),
        pos_p: 1.0,
        vel_p: 1100.0,
        vel_i: 1100.0,
        hover_throttle: StickCounts(530),
    };

    pub fn is_valid(&self) -> bool {
        within(self.climb_rate_max_m_s, 0.1, 5.0)
            && within(self.fs_descent_rate_m_s, 0.1, 3.0)
            && within(self.pos_p, 0.0, 10.0)
            && within(self.vel_p, 0.0, 10_000.0)
            && within(self.vel_i, 0.0, 10_000.0)
            && self.deadband >= StickCounts::ZERO
            && self.hover_throttle > StickCounts::ZERO
    }
}

/// Everything altitude: the mode, the estimator, the barometer's health check and the hold.
/// The reference profile has none (`Config::altitude` is `None`): its outer step never reads
/// the barometer and its tick flies the stick.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AltitudeSettings {
    pub mode: AltMode,
    pub estimator: AltitudeConfig,
    pub baro: BaroHealthConfig,
    pub hold: HoldConfig,
}

impl AltitudeSettings {
    /// Manual throttle by default: the reference's users fly the stick's throttle, and a hold
    /// engages only where the pilot asks for it (`ALT_MODE` 1, which may be set in flight).
    /// The failsafe descent needs no mode: it lands on the estimate whenever it is healthy.
    pub const DEFAULT: AltitudeSettings = AltitudeSettings {
        mode: AltMode::Manual,
        estimator: AltitudeConfig::DEFAULT,
        baro: BaroHealthConfig::DEFAULT,
        hold: HoldConfig::DEFAULT,
    };

    pub fn is_valid(&self) -> bool {
        let e = &self.estimator;
        self.hold.is_valid()
            && within(e.time_constant_s, 0.2, 10.0)
            && within(e.thrust_scale_pa, -100.0, 100.0)
            && within(e.step_dt_s, 1.0e-4, 0.1)
            && within(self.baro.check_hz, 1.0, 10_000.0)
    }
}

/// The collective must stay at this share of the hover throttle for a lift-off to be counted.
pub const LIFTOFF_FRACTION: f32 = 0.75;
/// The barometer this far above the take-off level counts as airborne, m.
pub const LIFTOFF_BARO_M: f32 = 1.0;
/// A landing: the collective below this share of the hover throttle…
pub const LAND_FRACTION: f32 = 0.75;
/// …with the estimated climb rate within this, m/s…
pub const LAND_SPEED_M_S: f32 = 0.2;
/// …for this long, s, within this of the take-off level, m: a drone that cannot sink on the
/// lowest throttle that keeps its motors turning (an airframe lighter than the throttle map's
/// floor) looks landed by the first three, anywhere. The margin is the estimate's drift over a
/// flight and the props' wash near the floor, twice over.
pub const LAND_TIME_S: f32 = 0.5;
/// …and with the vertical acceleration (the accelerometer's, its bias off, low-passed over
/// [`LAND_ACCEL_FILTER_S`]) within this, m/s²: on the floor nothing moves whatever the
/// throttle, while in the air a throttle under the hover's sinks the drone at once; a gust
/// that holds it still can fool the rule only for as long as it holds it exactly.
pub const LAND_ACCEL_M_S2: f32 = 0.5;
pub const LAND_ACCEL_FILTER_S: f32 = 0.1;
pub const LAND_HEIGHT_M: f32 = 0.75;
/// The stick's descent slows near the floor (the landing speed, ArduPilot's and PX4's
/// LAND_SPEED): at most the failsafe's descent rate below this height above the take-off level,
/// m, which a touchdown at the set rate stays within even with the estimate this far off…
pub const LAND_SLOW_M: f32 = 0.5;
/// …rising to the full rate over this much above it, m: the speed target follows the height, so
/// the throttle has no step (a 1 m/s descent brakes at 1.2 m/s², an eighth of the hover's thrust).
pub const LAND_SLOW_BAND_M: f32 = 0.5;
/// The failsafe holds the height this long before it descends, s (the level stage of the
/// manual failsafe, in which a brief loss comes back).
pub const FS_LEVEL_S: f32 = 1.0;
/// The failsafe descent's time cap: the level time, the descent at the set rate with this
/// margin on top (a head wind, a slower descent near the floor), the landing detection, and
/// [`FS_CAP_SPARE_S`].
pub const FS_CAP_MARGIN: f32 = 1.5;
pub const FS_CAP_SPARE_S: f32 = 3.0;
/// A barometer fault makes the estimate unhealthy until this long without one, s.
pub const BARO_RECOVERY_S: f32 = 1.0;
/// The take-off ramp: from the bottom to the hover throttle in this long, s.
pub const TAKEOFF_RAMP_S: f32 = 1.0;
/// The hold's throttle is averaged over this for a hand-over, s.
pub const CARRY_AVERAGE_S: f32 = 0.5;

/// What the control tick and the supervisor take from the vertical half.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct VerticalCommand {
    /// The throttle the tick flies instead of the sticks' (`None`: the sticks').
    pub throttle: Option<StickCounts>,
    /// The failsafe may land on the estimate: the longest the descent from here may take, in
    /// control ticks (0: no healthy estimate, the failsafe is the manual one).
    pub descent_cap_ticks: u32,
    /// The hold detected a landing and holds the motors at the bottom.
    pub landed: bool,
}

/// What the outer job tells the vertical half of the flight state.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VerticalInput {
    /// The motors may run (armed, or the failsafe's level stage).
    pub motors_enabled: bool,
    /// The link-loss failsafe holds.
    pub failsafe: bool,
    /// The throttle the sticks ask (or the failsafe's held throttle), stick counts.
    pub command: StickCounts,
    /// The throttle the tick flew (the hold's or the sticks'), stick counts.
    pub flown: StickCounts,
    /// The throttle's centre and bottom: the stick's full scale (its travel is twice that) and
    /// the low-throttle limit.
    pub full_scale: StickCounts,
    pub min_throttle: StickCounts,
}

/// The vertical half's state.
#[derive(Clone, Debug)]
pub struct Vertical {
    cfg: AltitudeSettings,
    monitor: BaroMonitor,
    estimator: AltitudeEstimator,
    dt_s: f32,
    /// Control ticks per second, for the failsafe's cap.
    tick_hz: f32,
    /// The throttle map, unscaled (compare = slope · stick + offset), and a full duty's compare,
    /// for the estimator's thrust share.
    throttle_slope: f32,
    throttle_offset: f32,
    period_counts: f32,
    /// The last step's motors-enabled, to see the arming.
    was_enabled: bool,
    airborne: bool,
    /// Steps the landing conditions have held.
    land_steps: u32,
    /// The vertical acceleration, low-passed, m/s² (for the landing).
    accel_filtered_m_s2: f32,
    /// Steps since the last barometer fault (saturating).
    since_fault_steps: u32,
    last_fault: Option<BaroFault>,
    pressure_pa: Option<f32>,
    temperature_c: f32,
    /// The hold runs: its target height, m.
    engaged: Option<f32>,
    /// The hover throttle: the feedforward, learned (stick counts).
    hover: f32,
    integral: f32,
    /// The hold's last throttle, stick counts.
    out: f32,
    /// Its average over the last [`CARRY_AVERAGE_S`]: the thrust it was giving, which a
    /// hand-over carries (the last output alone is a noisy sample of it).
    out_average: f32,
    /// Left the hold: the throttle it gave, kept until the stick crosses it (and from which
    /// side the stick started: below it, it takes over as soon as it reaches the carried
    /// throttle).
    carry: Option<(f32, bool)>,
    /// Steps in the failsafe.
    failsafe_steps: u32,
    /// Airborne since the arming.
    has_flown: bool,
    /// The stick has been in the dead band since the hold engaged in flight: until then it asks
    /// for no rate (the manual hover's stick, far below the centre, would ask for a descent).
    stick_centred: bool,
}

impl Vertical {
    pub fn new(cfg: AltitudeSettings, tick_hz: f32, mixer: &crate::mixer::MixerConfig) -> Vertical {
        Vertical {
            monitor: BaroMonitor::new(cfg.baro),
            estimator: AltitudeEstimator::new(cfg.estimator),
            dt_s: cfg.estimator.step_dt_s,
            tick_hz,
            throttle_slope: mixer.throttle_slope,
            throttle_offset: mixer.throttle_offset,
            period_counts: mixer.period_counts(),
            was_enabled: false,
            airborne: false,
            land_steps: 0,
            accel_filtered_m_s2: 0.0,
            since_fault_steps: 0,
            last_fault: None,
            pressure_pa: None,
            temperature_c: 0.0,
            engaged: None,
            hover: f32::from(cfg.hold.hover_throttle.0),
            integral: 0.0,
            out: 0.0,
            out_average: 0.0,
            carry: None,
            failsafe_steps: 0,
            stick_centred: false,
            has_flown: false,
            cfg,
        }
    }

    /// New settings (a parameter change): the estimator takes its new time constant and thrust
    /// scale with its state kept (those change only on the ground), the hold its new numbers; the
    /// health check's numbers are no parameter.
    pub fn set_config(&mut self, cfg: &AltitudeSettings) {
        self.estimator.set_config(&cfg.estimator);
        if !self.airborne {
            self.hover = f32::from(cfg.hold.hover_throttle.0);
        }
        self.cfg = *cfg;
    }

    /// The estimate may be flown on: referenced, and no barometer fault for
    /// [`BARO_RECOVERY_S`].
    fn healthy(&self) -> bool {
        self.estimator.estimate().referenced && self.since_fault_steps as f32 * self.dt_s >= BARO_RECOVERY_S
    }

    /// The throttle's share of full duty, for the estimator's thrust compensation.
    fn thrust_share(&self, throttle: StickCounts, min_throttle: StickCounts) -> f32 {
        if throttle < min_throttle {
            return 0.0;
        }
        limit((self.throttle_slope * f32::from(throttle.0) + self.throttle_offset) / self.period_counts, 0.0, 1.0)
    }

    /// One outer step: the burst read since the last (`baro`), the attitude and the block's mean
    /// accelerometer (body mg, offsets removed), and the flight state.
    pub fn step(&mut self, baro: Option<RawBaro>, quat: Quat, accel_mg: Vec3, i: &VerticalInput) -> (VerticalCommand, AltitudeStatus) {
        let pressure = self.take_baro(baro);
        let baro_fault = self.last_fault;
        let was_failsafe = self.follow_flight_state(i);
        let est = self.estimate(pressure, quat, accel_mg, i);
        let healthy = self.healthy();

        // The hold, or the stick (with what the hold gave carried until the stick crosses it).
        let hold_wanted = healthy && i.motors_enabled && (self.cfg.mode == AltMode::Hold || i.failsafe);
        let (throttle, landed) =
            if hold_wanted { self.held_throttle(&est, i) } else { (self.stick_throttle(was_failsafe, &est, i), false) };
        self.has_flown |= self.airborne;
        let throttle = throttle.map(|t| StickCounts(limit(t, 0.0, f32::from(i.full_scale.0) * 2.0) as i16));

        let descent_cap_ticks = if healthy && i.motors_enabled { self.descent_cap_ticks(est.height_m) } else { 0 };
        let status = AltitudeStatus {
            mode: self.cfg.mode,
            holding: hold_wanted,
            failsafe_descent: hold_wanted && i.failsafe,
            height_m: est.height_m,
            climb_m_s: est.vertical_speed_m_s,
            target_m: if hold_wanted { self.engaged } else { None },
            pressure_pa: self.pressure_pa,
            temperature_c: self.temperature_c,
            baro_fault,
            estimate_healthy: healthy,
        };
        (VerticalCommand { throttle, descent_cap_ticks, landed }, status)
    }

    /// The barometer's health, and its pressure if this step has a sample to use. A fault is
    /// reported until a healthy sample comes (the check names it only on the samples it
    /// judges); a spike is a sample not used, not a sick sensor: it does not make the estimate
    /// unhealthy.
    fn take_baro(&mut self, baro: Option<RawBaro>) -> Option<f32> {
        let pressure = match self.monitor.check(baro) {
            Ok(Some(s)) => {
                self.pressure_pa = Some(s.pressure_pa);
                self.temperature_c = s.temperature_c;
                self.last_fault = None;
                Some(s.pressure_pa)
            }
            Ok(None) => None,
            Err(f) => {
                self.last_fault = Some(f);
                if f != BaroFault::Spike {
                    self.since_fault_steps = 0;
                }
                None
            }
        };
        let sick = self.last_fault.is_some_and(|f| f != BaroFault::Spike);
        if !sick {
            self.since_fault_steps = self.since_fault_steps.saturating_add(1);
        }
        pressure
    }

    /// Arming makes the take-off point here; disarmed, nothing flies. Returns whether the last
    /// step was in the failsafe.
    fn follow_flight_state(&mut self, i: &VerticalInput) -> bool {
        if i.motors_enabled && !self.was_enabled {
            self.estimator.rezero();
            self.airborne = false;
            self.has_flown = false;
            self.land_steps = 0;
        }
        if !i.motors_enabled {
            self.airborne = false;
            self.engaged = None;
            self.carry = None;
            self.integral = 0.0;
            self.land_steps = 0;
        }
        self.was_enabled = i.motors_enabled;
        let was_failsafe = self.failsafe_steps > 0;
        self.failsafe_steps = if i.failsafe { self.failsafe_steps.saturating_add(1) } else { 0 };
        was_failsafe
    }

    /// The estimate, on the ground state of the last step and the throttle flown, and the
    /// vertical acceleration the landing check filters.
    fn estimate(&mut self, pressure: Option<f32>, quat: Quat, accel_mg: Vec3, i: &VerticalInput) -> AltitudeEstimate {
        let accel_up = vertical_accel_m_s2(quat, accel_mg);
        let thrust = self.thrust_share(i.flown, i.min_throttle);
        if let (Some(p), true) = (pressure, i.motors_enabled && !self.airborne) {
            // The barometer well above the take-off level: airborne, whatever the throttle said
            // (a hover throttle set too high would otherwise keep a flying drone "on the
            // ground", its height pinned at 0). The margin is twice the most the props' wash and
            // ground effect move the reading at the floor.
            let h = self.estimator.baro_height_m(p, thrust);
            if h > LIFTOFF_BARO_M {
                self.airborne = true;
                self.estimator.airborne_at(h);
            }
        }
        let on_ground = !i.motors_enabled || !self.airborne;
        let est = self.estimator.update(accel_up, pressure, thrust, on_ground);
        let accel = accel_up - est.accel_bias_m_s2;
        if accel.is_finite() {
            self.accel_filtered_m_s2 += self.dt_s / (LAND_ACCEL_FILTER_S + self.dt_s) * (accel - self.accel_filtered_m_s2);
        }
        est
    }

    /// The hold's throttle (the failsafe's descent included), and whether it has landed.
    fn held_throttle(&mut self, est: &AltitudeEstimate, i: &VerticalInput) -> (Option<f32>, bool) {
        if self.engaged.is_none() {
            // On the ground the stick takes off at once; in the air it must come to the
            // dead band first.
            self.stick_centred = !self.airborne;
        }
        let rate = self.rate_asked(i);
        if rate == 0.0 {
            self.stick_centred = true;
        }
        let rate = if self.stick_centred || i.failsafe { rate } else { 0.0 };
        let rate = rate.max(-self.descent_limit_m_s(est.height_m));
        let t = self.hold(rate, est.height_m, est.vertical_speed_m_s, i);
        self.out_average += self.dt_s / (CARRY_AVERAGE_S + self.dt_s) * (t - self.out_average);
        (Some(t), !self.airborne && rate <= 0.0)
    }

    /// Without the hold: the stick's throttle (`None`), or the hold's thrust carried until
    /// the stick crosses it, or idle on the ground in hold without an estimate.
    fn stick_throttle(&mut self, was_failsafe: bool, est: &AltitudeEstimate, i: &VerticalInput) -> Option<f32> {
        if self.engaged.take().is_some() {
            // The link back after the failsafe's descent: the stick the pilot holds is live
            // again, and a stick above the thrust carried (the pilot climbing) takes over at
            // once; below it, as it comes up to it. Otherwise (a mode change, a barometer
            // fault) from whichever side the live stick is.
            let c = self.out_average;
            let from_below = was_failsafe || f32::from(i.command.0) < c;
            self.carry = Some((c, from_below));
        }
        let carried = self.carry.and_then(|(c, from_below)| {
            let crossed = if from_below { f32::from(i.command.0) >= c } else { f32::from(i.command.0) <= c };
            (!crossed).then_some(c)
        });
        self.carry = carried.map(|c| (c, self.carry.is_some_and(|(_, b)| b)));
        // ALT_MODE 1 without a healthy estimate before the take-off: the stick means "hold"
        // (its centre is several times the hover), so it takes nothing off the ground; the
        // motors idle and the automatic disarm counts.
        let grounded = self.cfg.mode == AltMode::Hold && i.motors_enabled && !self.has_flown && carried.is_none();
        let flown = if grounded { 0.0 } else { carried.unwrap_or(f32::from(i.command.0)) };
        self.manual_ground_state(flown, est, i);
        if grounded {
            Some(0.0)
        } else {
            carried
        }
    }

    /// The climb rate asked, m/s: the failsafe's (hold, then descend), or the stick's beyond the
    /// dead band around its centre.
    fn rate_asked(&self, i: &VerticalInput) -> f32 {
        let h = &self.cfg.hold;
        if i.failsafe {
            return if self.failsafe_steps as f32 * self.dt_s < FS_LEVEL_S { 0.0 } else { -h.fs_descent_rate_m_s };
        }
        let centre = f32::from(i.full_scale.0);
        let db = f32::from(h.deadband.0);
        let span = (centre - db).max(1.0);
        let off = f32::from(i.command.0) - centre;
        let share = if off > db {
            (off - db) / span
        } else if off < -db {
            (off + db) / span
        } else {
            0.0
        };
        limit(share, -1.0, 1.0) * h.climb_rate_max_m_s
    }

    /// The hold's step: the throttle, stick counts.
    fn hold(&mut self, rate: f32, height_m: f32, climb_m_s: f32, i: &VerticalInput) -> f32 {
        let h = self.cfg.hold;
        let floor = f32::from(i.min_throttle.0) + 1.0;
        let top = f32::from(i.full_scale.0) * 2.0;
        let entering = self.engaged.is_none();
        if entering {
            self.engage(height_m, f32::from(i.flown.0), floor, top);
        }
        if !self.airborne {
            self.engaged = Some(height_m);
            return self.take_off(rate, climb_m_s, floor, top);
        }
        // Asked for a rate, the rate is flown and the target is where the drone is; centred, the
        // target stays where the stick came back and the height loop holds it.
        let speed_target = if rate != 0.0 {
            self.engaged = Some(height_m);
            rate
        } else {
            let target = self.engaged.filter(|t| t.is_finite()).unwrap_or(height_m);
            self.engaged = Some(target);
            let down = if i.failsafe { h.fs_descent_rate_m_s } else { h.climb_rate_max_m_s };
            limit(h.pos_p * (target - height_m), -down, h.climb_rate_max_m_s)
        };
        let error = speed_target - climb_m_s;
        if entering {
            // Bumpless: the loop starts from the throttle flown, whatever the climb rate now.
            self.integral = limit(-h.vel_p * error, -self.hover, top);
        }
        let unlimited = self.hover + self.integral + h.vel_p * error;
        // Integrate unless the throttle is pinned in that direction.
        if !((unlimited >= top && error > 0.0) || (unlimited <= floor && error < 0.0)) {
            self.integral = limit(self.integral + h.vel_i * error * self.dt_s, -self.hover, top);
        }
        let out = limit(self.hover + self.integral + h.vel_p * error, floor, top);
        self.out = if out.is_finite() { out } else { self.hover };
        if !self.integral.is_finite() {
            self.integral = 0.0;
        }
        self.detect_landing(rate, climb_m_s, height_m);
        self.out
    }

    /// Entering the hold: the height now is the target; in the air the throttle flown is the
    /// hover (no jump), on the ground the one learned or set.
    fn engage(&mut self, height_m: f32, flown: f32, floor: f32, top: f32) {
        self.engaged = Some(height_m);
        self.carry = None;
        self.integral = 0.0;
        // Motors turning above the throttle cut when the hold takes over (the failsafe, a
        // mode change): flying, or about to, whatever the ground state thought; the hold
        // never takes a drone it might be flying for one on the floor.
        if flown > floor {
            self.airborne = true;
            self.land_steps = 0;
        }
        if self.airborne {
            self.hover = limit(flown, floor, top);
            self.out = self.hover;
        } else {
            self.out = 0.0;
        }
        self.out_average = self.out;
    }

    /// On the ground: idle, or, asked up, the take-off's ramp from the bottom to the hover
    /// throttle, after which the loops fly.
    fn take_off(&mut self, rate: f32, climb_m_s: f32, floor: f32, top: f32) -> f32 {
        if rate > 0.0 {
            let step = self.hover.max(floor) * self.dt_s / TAKEOFF_RAMP_S;
            self.out = (self.out.max(floor) + step).min(top);
            if self.out >= LIFTOFF_FRACTION * self.hover {
                self.airborne = true;
                self.land_steps = 0;
                // Bumpless: the integral takes what the ramp reached.
                self.integral = self.out - self.hover - self.cfg.hold.vel_p * (rate - climb_m_s);
            }
        } else {
            self.out = 0.0;
        }
        self.out
    }

    /// Landed: asked down, the throttle well under the hover, the height still, for
    /// [`LAND_TIME_S`]. Then the motors idle.
    fn detect_landing(&mut self, rate: f32, climb_m_s: f32, height_m: f32) {
        let holding = self.hover + self.integral;
        if rate < 0.0 && self.out < LAND_FRACTION * holding.max(self.hover) && self.still(climb_m_s, height_m) {
            self.land_steps = self.land_steps.saturating_add(1);
        } else {
            self.land_steps = 0;
        }
        if self.land_steps as f32 * self.dt_s >= LAND_TIME_S {
            self.airborne = false;
            self.land_steps = 0;
            self.out = 0.0;
            self.integral = 0.0;
        }
    }

    /// Without the hold: airborne once the throttle flown reaches the lift-off share of the
    /// hover throttle, landed once it stays under the landing share with the height still.
    fn manual_ground_state(&mut self, flown: f32, est: &AltitudeEstimate, i: &VerticalInput) {
        let climb_m_s = est.vertical_speed_m_s;
        if !i.motors_enabled {
            return;
        }
        if !self.airborne {
            self.airborne = flown >= LIFTOFF_FRACTION * self.hover;
            self.land_steps = 0;
            return;
        }
        if flown < LAND_FRACTION * self.hover && self.still(climb_m_s, est.height_m) {
            self.land_steps = self.land_steps.saturating_add(1);
        } else {
            self.land_steps = 0;
        }
        if self.land_steps as f32 * self.dt_s >= LAND_TIME_S {
            self.airborne = false;
            self.land_steps = 0;
        }
    }

    /// Near the take-off level and not moving: the estimate's climb rate and the accelerometer.
    fn still(&self, climb_m_s: f32, height_m: f32) -> bool {
        climb_m_s.abs() < LAND_SPEED_M_S && self.accel_filtered_m_s2.abs() < LAND_ACCEL_M_S2 && height_m < LAND_HEIGHT_M
    }

    /// The fastest descent the stick may ask at `height_m`, m/s: the failsafe's rate near the
    /// floor, blended up to the full rate over [`LAND_SLOW_BAND_M`]. Never under the failsafe's
    /// (at least 0.1 m/s): an estimate that is off, or not a number, slows a landing but never
    /// stops it short of the floor, where the landing detector must see it.
    fn descent_limit_m_s(&self, height_m: f32) -> f32 {
        let h = &self.cfg.hold;
        let share = (height_m - LAND_SLOW_M) / LAND_SLOW_BAND_M;
        let share = if share.is_nan() { 0.0 } else { limit(share, 0.0, 1.0) };
        h.fs_descent_rate_m_s + (h.climb_rate_max_m_s - h.fs_descent_rate_m_s).max(0.0) * share
    }

    /// The failsafe descent's time cap from `height_m`, control ticks.
    fn descent_cap_ticks(&self, height_m: f32) -> u32 {
        let h = &self.cfg.hold;
        let descent_s = height_m.max(0.0) / h.fs_descent_rate_m_s * FS_CAP_MARGIN;
        let s = FS_LEVEL_S + descent_s + LAND_TIME_S + FS_CAP_SPARE_S;
        // f32 → u32 saturates; a NaN height gives the spare alone.
        let ticks = (s * self.tick_hz) as u32;
        ticks.max(1)
    }
}

#[cfg(test)]
#[path = "althold_tests.rs"]
mod tests;
