//! The end of the tick: the rate loop, the mixer and the guard that writes the compare values.

use super::derived::TickParams;
use super::gcs::TestOutput;
use crate::control::RateLoop;
use crate::mixer::Saturation;
use crate::rc::StickCounts;

/// What the supervisor lets through to the motors this tick.
#[derive(Clone, Copy, Debug)]
pub(super) struct MotorsAllowed {
    /// The supervisor lets the motors run.
    pub(super) enabled: bool,
    /// The throttle flown (the sticks' or the failsafe's) and whether it is low.
    pub(super) throttle: StickCounts,
    pub(super) throttle_low: bool,
    /// A sensor fault is latched.
    pub(super) fault: bool,
}

/// The rate loop's state and what the tick last wrote to the motors.
#[derive(Clone, Debug)]
pub(super) struct Output {
    rate_loop: RateLoop,
    /// What the mixer could not deliver on the last tick (for the anti-windup).
    saturation: Saturation,
    /// Motor commands before the compare clamp.
    motor_command: [f32; 4],
    compare: [u16; 4],
}

impl Output {
    pub(super) fn new() -> Output {
        Output { rate_loop: RateLoop::default(), saturation: Saturation::NONE, motor_command: [0.0; 4], compare: [0; 4] }
    }

    /// Rate loop and mixer while the supervisor lets the motors run, then the guard: last and
    /// unconditional. With the motors not allowed to run, a ground station's motor test
    /// (`test`, read only then) drives its one motor, unless a sensor fault is latched.
    #[inline(always)] // docs/performance.md, «inlined into the tick».
    pub(super) fn run(
        &mut self,
        p: &TickParams,
        demand_rad_s: [f32; 3],
        gyro_rad_s: [f32; 3],
        allowed: MotorsAllowed,
        test: impl FnOnce() -> Option<TestOutput>,
    ) -> [u16; 4] {
        if allowed.enabled {
            let rate_commands = self.rate_loop.commands(&p.rate_loop, demand_rad_s, gyro_rad_s, allowed.throttle_low, self.saturation);
            let (cmd, sat) = p.mixer.mix(p.mixer.throttle_counts(allowed.throttle), rate_commands);
            self.motor_command = cmd;
            self.saturation = sat;
        } else {
            self.motor_command = [0.0; 4];
        }
        if allowed.throttle_low {
            // The reference's only throttle cut: the motors stop with the stick at the bottom.
            self.motor_command = [0.0; 4];
        }
        let range = p.compare_range;
        self.compare = self.motor_command.map(|c| range.to_compare(c));
        if !allowed.enabled || allowed.fault {
            self.compare = [p.off_compare; 4];
            if let Some(t) = test().filter(|_| !allowed.fault) {
                if let Some(c) = self.compare.get_mut(usize::from(t.motor)) {
                    *c = t.compare;
                }
            }
        }
        self.compare
    }

    /// Motors off, for a tick that a calibration in progress ends early: the guard's one other
    /// writer of compare values.
    pub(super) fn off(&mut self, p: &TickParams) -> [u16; 4] {
        self.motor_command = [0.0; 4];
        self.compare = [p.off_compare; 4];
        self.compare
    }

    pub(super) fn motor_command(&self) -> [f32; 4] {
        self.motor_command
    }

    /// The rate loop's integrators (tests: what a run-time change keeps).
    #[cfg(test)]
    pub(super) fn rate_integrators(&self) -> [f32; 3] {
        self.rate_loop.integrators()
    }

    pub(super) fn compare(&self) -> [u16; 4] {
        self.compare
    }
}
