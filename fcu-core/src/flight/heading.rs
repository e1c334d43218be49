//! The heading (yaw): its estimate, integrated from the gyro every tick, and its target, which
//! the outer step moves with the yaw stick. Both restart at 0 whenever the throttle is low.

use super::block::OuterJob;
use super::derived::{OuterParams, TickParams};
use crate::control::YawRateShaper;

/// The tick's half: the gyro-integrated heading, and what the outer step must hear of the
/// throttle-low resets.
#[derive(Clone, Debug, Default)]
pub(super) struct HeadingEstimate {
    yaw_est_rad: f32,
    /// The throttle was low on some tick since the last job: the outer step restarts the
    /// heading target at 0.
    low_since_job: bool,
    /// The throttle was low on some tick since the last outer result: the heading target in
    /// force is 0, whatever that result says.
    low_since_result: bool,
}

impl HeadingEstimate {
    /// One tick of yaw rate, rad/s.
    #[inline(always)] // docs/performance.md, «inlined into the tick».
    pub(super) fn integrate(&mut self, yaw_rate_rad_s: f32, throttle_low: bool, p: &TickParams) {
        self.yaw_est_rad = match p.reference_dt_s() {
            // The reference integrates in double (its dt is a C double).
            Some(dt_s) => (f64::from(self.yaw_est_rad) + f64::from(yaw_rate_rad_s) * dt_s) as f32,
            None => self.yaw_est_rad + yaw_rate_rad_s * p.tick_dt_s,
        };
        if !self.yaw_est_rad.is_finite() {
            self.yaw_est_rad = 0.0;
        }
        if throttle_low {
            self.yaw_est_rad = 0.0;
            self.low_since_job = true;
            self.low_since_result = true;
        }
    }

    pub(super) fn yaw_est_rad(&self) -> f32 {
        self.yaw_est_rad
    }

    /// For a job: whether the heading target restarts at 0 (and the next job starts afresh).
    #[inline(always)] // docs/performance.md, «inlined into the tick».
    pub(super) fn take_target_reset(&mut self) -> bool {
        core::mem::take(&mut self.low_since_job)
    }

    /// An outer result arrived: its heading target is in force.
    pub(super) fn result_applied(&mut self) {
        self.low_since_result = false;
    }

    /// The heading target in force, from the last result's.
    pub(super) fn target_rad(&self, result_target_rad: f32) -> f32 {
        if self.low_since_result {
            0.0
        } else {
            result_target_rad
        }
    }
}

/// The outer step's half: the heading target, moved by the yaw stick at its rate or at its
/// shaped rate.
#[derive(Clone, Debug)]
pub(super) struct HeadingTarget {
    yaw_target_rad: f32,
    /// The stick's yaw rate shaped for the airframe (`None` without yaw shaping).
    shaper: Option<YawRateShaper>,
}

impl HeadingTarget {
    pub(super) fn new(shaper: Option<YawRateShaper>) -> HeadingTarget {
        HeadingTarget { yaw_target_rad: 0.0, shaper }
    }

    /// One outer step: the heading target, rad, and what the yaw rate demand adds to the
    /// heading loop's (the yaw feedforward: the stick's rate passed on; `None`: nothing, not even a zero).
    pub(super) fn step(&mut self, p: &OuterParams, job: &OuterJob) -> (f32, Option<f32>) {
        if job.yaw_target_reset {
            self.yaw_target_rad = 0.0;
        }
        let yaw_step = p.rc.yaw_step(&job.sticks, p.outer_hz);
        // The heading target moves at the stick's rate, or at its shaped rate, which
        // starts again from rest whenever the throttle has been low.
        let shaped = self.shaper.as_mut().map(|shaper| {
            if job.yaw_target_reset || job.throttle_low {
                shaper.reset();
            }
            // `RcConfig::yaw_rate_rad_s`, from the yaw step already worked out above.
            let stick_rate = if job.throttle_low { 0.0 } else { yaw_step * p.outer_hz };
            shaper.shape(stick_rate)
        });
        match shaped {
            Some(s) => self.yaw_target_rad += s.rate_rad_s / p.outer_hz,
            None if yaw_step != 0.0 => self.yaw_target_rad += yaw_step,
            None => {}
        }
        if job.throttle_low || !self.yaw_target_rad.is_finite() {
            self.yaw_target_rad = 0.0;
        }
        let ff = p.control.yaw_rate_feedforward;
        let feedforward = match shaped {
            _ if job.throttle_low => None,
            // The shaped rate and, ahead of it, what gets the torque its acceleration needs.
            Some(s) => Some(ff * s.rate_rad_s + s.lead_rad_s),
            // The heading loop keeps correcting what the rate loop misses; the stick's rate
            // itself goes to the rate loop now, not once a heading error has built up.
            None if ff != 0.0 => Some(ff * yaw_step * p.outer_hz),
            None => None,
        };
        (self.yaw_target_rad, feedforward)
    }
}
