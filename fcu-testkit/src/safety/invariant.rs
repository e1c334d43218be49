//! The rules the monitors check, by name, and a broken one.

use core::fmt;

/// A rule the monitor checks.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Invariant {
    /// Armed (or flying) without a full arming procedure just before: the arm gesture for
    /// `arm_hold_ticks` on a good link with the throttle low, started from a released gesture,
    /// then released with no blocker holding (`docs/safety.md#arming`).
    ArmedWithoutProcedure,
    /// A compare value other than the off value in a state where the motors must not run, or
    /// while the throttle in force is low (`docs/safety.md#motors`).
    MotorsNotOff,
    /// A compare value outside `[min_compare, max_compare]` (`docs/safety.md#motors`).
    CompareOutOfRange,
    /// The motors may still run after the link was gone for more than 1.0 s in total
    /// (`docs/safety.md#failsafe`): the silences since the arming, each from the last pulse of
    /// the channel that fell silent first and counted once, less what flying under stick
    /// control has forgotten (one tick per `loss_forget_ticks`). A brief recovery forgets
    /// nothing.
    MotorsOnAfterLinkLoss,
    /// Armed (motors following the sticks) without a good link.
    ArmedWithoutLink,
    /// Failsafe stage 1 handed control back before `recovery_ticks` of good link.
    EarlyRecovery,
    /// Failsafe stage 1 flies with sticks that are not level, or a throttle above the last
    /// good one.
    FailsafeSticks,
    /// A sensor fault did not stop the motors, or was forgotten.
    FaultNotLatched,
    /// Identical raw words for longer than the stuck limit without a fault.
    StuckSensorMissed,
    /// `status()` disagrees with the accepted pulses (link = every channel had a pulse in the
    /// last 100 ms; sticks = width minus centre).
    RadioView,
    /// A width outside the accepted pulse range reached the controller.
    PulseOutOfRange,
    /// A width reached the controller that no rising edge and next falling edge of its channel
    /// made within the capture wrap plus the shortest valid width: a pulse longer than the
    /// 15-bit capture clock's wrap read as a valid width (or a width from nowhere).
    PulseAliased,
    /// The yaw (heading) target is not 0 while the throttle in force is low.
    YawTargetWithThrottleLow,
    /// A calibration started while the motors could run.
    CalibrationWhileFlying,
    /// (Supervisor alone) `motors_enabled` disagrees with the state, a calibration was
    /// requested outside Disarmed, or `failsafe_throttle` is set outside stage 1.
    DecisionInconsistent,
}

impl Invariant {
    pub fn name(self) -> &'static str {
        match self {
            Invariant::ArmedWithoutProcedure => "armed-without-procedure",
            Invariant::MotorsNotOff => "motors-not-off",
            Invariant::CompareOutOfRange => "compare-out-of-range",
            Invariant::MotorsOnAfterLinkLoss => "motors-on-after-link-loss",
            Invariant::ArmedWithoutLink => "armed-without-link",
            Invariant::EarlyRecovery => "early-failsafe-recovery",
            Invariant::FailsafeSticks => "failsafe-sticks",
            Invariant::FaultNotLatched => "fault-not-latched",
            Invariant::StuckSensorMissed => "stuck-sensor-missed",
            Invariant::RadioView => "radio-view",
            Invariant::PulseOutOfRange => "pulse-out-of-range",
            Invariant::PulseAliased => "pulse-aliased",
            Invariant::YawTargetWithThrottleLow => "yaw-target-with-throttle-low",
            Invariant::CalibrationWhileFlying => "calibration-while-flying",
            Invariant::DecisionInconsistent => "decision-inconsistent",
        }
    }
}

/// A broken rule: which, at which tick (1 = the first tick observed), and what was seen.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Violation {
    pub tick: u64,
    pub invariant: Invariant,
    pub detail: String,
}

impl fmt::Display for Violation {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "tick {}: {}: {}", self.tick, self.invariant.name(), self.detail)
    }
}

impl std::error::Error for Violation {}
