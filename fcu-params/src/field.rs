//! What each parameter reads and writes in a [`Config`]: a [`Field`] per table entry, and one
//! getter and one setter matching on it.

use super::{
    gyro_cutoff_hz, ms_from_ticks, safety_ms, set_endpoint_us, set_gyro_cutoff, set_safety_ms, stick_from_us, stick_us, ticks_from_ms,
    us_from_counts, SetResult, RULE_NO_SAFETY, RULE_REV,
};
use fcu_core::althold::AltitudeSettings;
use fcu_core::altitude::AltMode;
use fcu_core::config::{Config, LinkProtocol};
use fcu_core::control::AxisGains;
use fcu_core::rc::COUNTS_PER_US;
use fcu_core::rc::{Function, RcInput};
use fcu_core::supervisor::SafetyConfig;

/// The setting a parameter is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Field {
    /// The input (1-4) carrying a function.
    RcMap(Function),
    /// An endpoint of a radio input (from 0), µs.
    RcEndpoint(u8, Endpoint),
    /// A radio input's sense (from 0): 1 or -1.
    RcReversed(u8),
    RcTimeoutMs,
    /// A stick threshold, µs.
    Stick(Stick),
    /// One of the safe supervisor's times, ms.
    Safety(SafetyTime),
    AngleMaxDeg,
    YawRateMaxDegS,
    /// A gain of one axis of the cascade.
    Gain(Axis, Gain),
    YawFeedforward,
    GyroCutoffHz,
    RateDFilterK,
    BatteryVoltMult,
    LinkProtocol,
    LinkAttitudeHz,
    LinkRcHz,
    /// An altitude setting.
    Alt(Alt),
}

/// The altitude settings ([`fcu_core::althold::AltitudeSettings`]); throttles in µs of stick
/// (four capture counts each: the conversion is exact).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Alt {
    Mode,
    ClimbRateMax,
    FsDescentRate,
    Deadband,
    PosP,
    VelP,
    VelI,
    Hover,
    EstimatorTau,
    ThrustScale,
}

/// The altitude settings in `cfg`, the default's for a profile without (the reference).
fn altitude(cfg: &Config) -> AltitudeSettings {
    cfg.altitude.unwrap_or(AltitudeSettings::DEFAULT)
}

fn alt_get(cfg: &Config, which: Alt) -> f32 {
    let a = altitude(cfg);
    let per_us = COUNTS_PER_US as f32;
    match which {
        Alt::Mode => match a.mode {
            AltMode::Manual => 0.0,
            AltMode::Hold => 1.0,
        },
        Alt::ClimbRateMax => a.hold.climb_rate_max_m_s,
        Alt::FsDescentRate => a.hold.fs_descent_rate_m_s,
        Alt::Deadband => stick_us(a.hold.deadband),
        Alt::PosP => a.hold.pos_p,
        Alt::VelP => a.hold.vel_p / per_us,
        Alt::VelI => a.hold.vel_i / per_us,
        Alt::Hover => stick_us(a.hold.hover_throttle),
        Alt::EstimatorTau => a.estimator.time_constant_s,
        Alt::ThrustScale => a.estimator.thrust_scale_pa,
    }
}

fn alt_set(cfg: &mut Config, which: Alt, v: f32) -> SetResult {
    let Some(a) = &mut cfg.altitude else {
        return Err(RULE_NO_SAFETY);
    };
    let per_us = COUNTS_PER_US as f32;
    match which {
        Alt::Mode => a.mode = if v == 0.0 { AltMode::Manual } else { AltMode::Hold },
        Alt::ClimbRateMax => a.hold.climb_rate_max_m_s = v,
        Alt::FsDescentRate => a.hold.fs_descent_rate_m_s = v,
        Alt::Deadband => a.hold.deadband = stick_from_us(v),
        Alt::PosP => a.hold.pos_p = v,
        Alt::VelP => a.hold.vel_p = v * per_us,
        Alt::VelI => a.hold.vel_i = v * per_us,
        Alt::Hover => a.hold.hover_throttle = stick_from_us(v),
        Alt::EstimatorTau => a.estimator.time_constant_s = v,
        Alt::ThrustScale => a.estimator.thrust_scale_pa = v,
    }
    Ok(())
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Endpoint {
    Min,
    Trim,
    Max,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Stick {
    GestureThreshold,
    MinThrottle,
    YawDeadband,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum SafetyTime {
    ArmHold,
    DisarmHold,
    AutoDisarm,
    FailsafeOff,
    Recovery,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Axis {
    Pitch,
    Roll,
    Yaw,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Gain {
    OuterP,
    InnerP,
    InnerI,
    InnerD,
}

/// The endpoint `which` of `e`, to write.
pub(super) fn endpoint_mut(e: &mut RcInput, which: Endpoint) -> &mut u16 {
    match which {
        Endpoint::Min => &mut e.min_counts,
        Endpoint::Trim => &mut e.trim_counts,
        Endpoint::Max => &mut e.max_counts,
    }
}

fn endpoint(e: &RcInput, which: Endpoint) -> u16 {
    match which {
        Endpoint::Min => e.min_counts,
        Endpoint::Trim => e.trim_counts,
        Endpoint::Max => e.max_counts,
    }
}

/// The time `which` of the safe supervisor in `s`, to write.
pub(super) fn safety_ticks_mut(s: &mut SafetyConfig, which: SafetyTime) -> &mut u32 {
    match which {
        SafetyTime::ArmHold => &mut s.arm_hold_ticks,
        SafetyTime::DisarmHold => &mut s.disarm_hold_ticks,
        SafetyTime::AutoDisarm => &mut s.auto_disarm_ticks,
        SafetyTime::FailsafeOff => &mut s.failsafe_off_ticks,
        SafetyTime::Recovery => &mut s.recovery_ticks,
    }
}

/// The time `which` of the safe supervisor in `s`.
pub(super) fn safety_ticks(s: &SafetyConfig, which: SafetyTime) -> u32 {
    match which {
        SafetyTime::ArmHold => s.arm_hold_ticks,
        SafetyTime::DisarmHold => s.disarm_hold_ticks,
        SafetyTime::AutoDisarm => s.auto_disarm_ticks,
        SafetyTime::FailsafeOff => s.failsafe_off_ticks,
        SafetyTime::Recovery => s.recovery_ticks,
    }
}

fn axis(cfg: &Config, axis: Axis) -> &AxisGains {
    match axis {
        Axis::Pitch => &cfg.control.pitch,
        Axis::Roll => &cfg.control.roll,
        Axis::Yaw => &cfg.control.yaw,
    }
}

fn gain(a: &AxisGains, which: Gain) -> f32 {
    match which {
        Gain::OuterP => a.outer_kp,
        Gain::InnerP => a.inner_kp,
        Gain::InnerI => a.inner_ki,
        Gain::InnerD => a.inner_kd,
    }
}

fn gain_mut(cfg: &mut Config, axis: Axis, which: Gain) -> &mut f32 {
    let a = match axis {
        Axis::Pitch => &mut cfg.control.pitch,
        Axis::Roll => &mut cfg.control.roll,
        Axis::Yaw => &mut cfg.control.yaw,
    };
    match which {
        Gain::OuterP => &mut a.outer_kp,
        Gain::InnerP => &mut a.inner_kp,
        Gain::InnerI => &mut a.inner_ki,
        Gain::InnerD => &mut a.inner_kd,
    }
}

impl Field {
    /// The value in `cfg`.
    pub(super) fn get(self, cfg: &Config) -> f32 {
        match self {
            Field::RcMap(f) => f32::from(cfg.rc.map.input(f)) + 1.0,
            Field::RcEndpoint(input, which) => cfg.rc.inputs.get(usize::from(input)).map_or(0.0, |e| us_from_counts(endpoint(e, which))),
            Field::RcReversed(input) => cfg.rc.inputs.get(usize::from(input)).map_or(0.0, |e| if e.reversed { -1.0 } else { 1.0 }),
            Field::RcTimeoutMs => ms_from_ticks(cfg, cfg.rc.link_timeout_ticks),
            Field::Stick(which) => stick_us(match which {
                Stick::GestureThreshold => cfg.rc.gesture_threshold,
                Stick::MinThrottle => cfg.rc.min_throttle,
                Stick::YawDeadband => cfg.rc.yaw_deadband,
            }),
            Field::Safety(which) => safety_ms(cfg, which),
            Field::AngleMaxDeg => cfg.rc.max_tilt_deg,
            Field::YawRateMaxDegS => cfg.rc.yaw_rate_max_deg_s,
            Field::Gain(a, which) => gain(axis(cfg, a), which),
            Field::YawFeedforward => cfg.control.yaw_rate_feedforward,
            Field::GyroCutoffHz => gyro_cutoff_hz(cfg),
            Field::RateDFilterK => cfg.control.d_filter_k,
            Field::BatteryVoltMult => cfg.battery_sense.volt_mult,
            Field::LinkProtocol => match cfg.link.protocol {
                LinkProtocol::TextLines => 0.0,
                LinkProtocol::Mavlink => 1.0,
            },
            Field::LinkAttitudeHz => f32::from(cfg.link.attitude_hz),
            Field::LinkRcHz => f32::from(cfg.link.rc_hz),
            Field::Alt(which) => alt_get(cfg, which),
        }
    }

    /// Set to `v` (within bounds and on the step) in `cfg`, or the setting's own refusal.
    pub(super) fn set(self, cfg: &mut Config, v: f32) -> SetResult {
        match self {
            Field::RcMap(f) => {
                cfg.rc.map.assign(f, (v as u8).saturating_sub(1));
            }
            Field::RcEndpoint(input, which) => return set_endpoint_us(cfg, usize::from(input), v, which),
            Field::RcReversed(input) => {
                if v == 0.0 {
                    return Err(RULE_REV);
                }
                if let Some(e) = cfg.rc.inputs.get_mut(usize::from(input)) {
                    e.reversed = v < 0.0;
                }
            }
            Field::RcTimeoutMs => cfg.rc.link_timeout_ticks = ticks_from_ms(cfg, v)?,
            Field::Stick(which) => {
                let s = stick_from_us(v);
                match which {
                    Stick::GestureThreshold => cfg.rc.gesture_threshold = s,
                    Stick::MinThrottle => cfg.rc.min_throttle = s,
                    Stick::YawDeadband => cfg.rc.yaw_deadband = s,
                }
            }
            Field::Safety(which) => return set_safety_ms(cfg, v, which),
            Field::AngleMaxDeg => cfg.rc.max_tilt_deg = v,
            Field::YawRateMaxDegS => cfg.rc.yaw_rate_max_deg_s = v,
            Field::Gain(axis, which) => *gain_mut(cfg, axis, which) = v,
            Field::YawFeedforward => cfg.control.yaw_rate_feedforward = v,
            Field::GyroCutoffHz => return set_gyro_cutoff(cfg, v),
            Field::RateDFilterK => cfg.control.d_filter_k = v,
            Field::BatteryVoltMult => cfg.battery_sense.volt_mult = v,
            Field::LinkProtocol => cfg.link.protocol = if v == 0.0 { LinkProtocol::TextLines } else { LinkProtocol::Mavlink },
            Field::LinkAttitudeHz => cfg.link.attitude_hz = v as u8,
            Field::LinkRcHz => cfg.link.rc_hz = v as u8,
            Field::Alt(which) => return alt_set(cfg, which, v),
        }
        Ok(())
    }
}
