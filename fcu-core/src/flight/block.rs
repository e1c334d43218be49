//! The block of five ticks the outer step runs on: each tick's accelerometer words and the
//! running sum of the low-passed gyro, handed out as an [`OuterJob`] when the block is full.

use super::in_force::InForce;
use crate::filter::{accumulate, BLOCK};
use crate::imu::{Decoder, Offsets};
use crate::rc::{StickCounts, Sticks};
use crate::supervisor::FlightState;

/// The accelerometer words of a block, one per slot, aligned to 4 bytes (docs/performance.md,
/// «aligned words»).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[repr(C, align(4))]
pub struct AccelWords(pub [[i16; 3]; BLOCK]);

/// Add accelerometer words to a block sum, each converted and corrected as the tick would
/// have done it, in slot order.
pub(super) fn accumulate_accel_mg(sum: &mut [f32; 3], words: &[[i16; 3]], decoder: &Decoder, offsets: &Offsets) {
    for w in words {
        accumulate(sum, offsets.accel(decoder.accel_mg(*w)).map(|v| v as f32));
    }
}

/// The block being filled. The tick stores the accelerometer's raw words and the outer step
/// converts them (docs/performance.md, «accel words, not values»); the gyro is summed in slot
/// order, bit for bit the reference's sum of five stored slots.
#[derive(Clone, Debug, Default)]
pub(super) struct Block {
    /// Samples written so far.
    len: usize,
    accel_words: AccelWords,
    /// The slots before `first_raw_slot`, converted under the offsets they were taken with
    /// and summed (only a block that spans the end of a calibration has any).
    accel_sum_before_mg: [f32; 3],
    first_raw_slot: u8,
    gyro_sum_mdps: [f32; 3],
}

impl Block {
    /// One tick's sample; true when the block is full and its job is due.
    #[inline(always)] // docs/performance.md, «inlined into the tick».
    pub(super) fn add(&mut self, accel: [i16; 3], gyro_mdps: [f32; 3]) -> bool {
        if let Some(words) = self.accel_words.0.get_mut(self.len) {
            *words = accel;
        }
        accumulate(&mut self.gyro_sum_mdps, gyro_mdps);
        self.len += 1;
        self.len >= BLOCK
    }

    /// The offsets change from `old`: the words taken so far are converted under them now and
    /// join the sum before.
    pub(super) fn offsets_change(&mut self, old: &Offsets, decoder: &Decoder) {
        let taken = self.accel_words.0.get(usize::from(self.first_raw_slot)..self.len).unwrap_or(&[]);
        accumulate_accel_mg(&mut self.accel_sum_before_mg, taken, decoder, old);
        // `len` < BLOCK here (a job resets it), so the cast is exact.
        self.first_raw_slot = self.len.min(BLOCK) as u8;
    }

    /// The full block's job, with what the rest of the tick adds to it; the next block starts.
    #[inline(always)] // docs/performance.md, «inlined into the tick».
    pub(super) fn take_job(&mut self, offsets: Offsets, in_force: &InForce, yaw_est_rad: f32, yaw_target_reset: bool) -> OuterJob {
        let job = OuterJob {
            accel_words: self.accel_words,
            accel_offsets: offsets,
            accel_sum_before_mg: self.accel_sum_before_mg,
            first_raw_slot: self.first_raw_slot,
            gyro_sum_mdps: self.gyro_sum_mdps,
            sticks: in_force.sticks,
            throttle_low: in_force.throttle_low,
            yaw_est_rad,
            yaw_target_reset,
            command_throttle: in_force.command_thr,
            state: in_force.decision.state,
        };
        self.len = 0;
        self.accel_sum_before_mg = [0.0; 3];
        self.first_raw_slot = 0;
        self.gyro_sum_mdps = [0.0; 3];
        job
    }
}

/// What the outer step needs of the last five ticks: the accelerometer words and the summed
/// gyro, and what the sticks said.
///
/// The tick stores the accelerometer's raw words and the outer step converts them (mount,
/// sensitivity, offsets: the tick's integer arithmetic, done at 160 Hz); the gyro arrives as
/// the sum its block mean is made of, accumulated in slot order (bit for bit the reference's
/// sum of five stored slots). Why: docs/performance.md, «accel words, not values».
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OuterJob {
    /// Accelerometer words, sensor axes, of the slots `first_raw_slot..`.
    pub accel_words: AccelWords,
    /// The offsets in force for those words.
    pub accel_offsets: Offsets,
    /// The slots before `first_raw_slot`, converted and corrected with the offsets they were
    /// taken under and summed (only a block that spans the end of a calibration has any).
    pub accel_sum_before_mg: [f32; 3],
    pub first_raw_slot: u8,
    /// Low-passed gyro summed over the block, mdps, body axes.
    pub gyro_sum_mdps: [f32; 3],
    /// The sticks in force (the failsafe's level sticks while it holds), with the throttle
    /// flown (the altitude hold's while it flies one).
    pub sticks: Sticks,
    pub throttle_low: bool,
    /// The yaw estimate at the end of the tick, rad.
    pub yaw_est_rad: f32,
    /// The throttle was low on some tick since the last job: the yaw target restarts at 0.
    pub yaw_target_reset: bool,
    /// The throttle the sticks (or the failsafe) ask, before the altitude hold's.
    pub command_throttle: StickCounts,
    /// The supervisor's state (the vertical half re-zeroes the height at arming and lands in
    /// the failsafe).
    pub state: FlightState,
}

impl OuterJob {
    /// The block's summed accelerometer, corrected mg, body axes.
    pub fn accel_sum_mg(&self, decoder: &Decoder) -> [f32; 3] {
        let mut sum = self.accel_sum_before_mg;
        let raw = self.accel_words.0.get(usize::from(self.first_raw_slot)..).unwrap_or(&[]);
        accumulate_accel_mg(&mut sum, raw, decoder, &self.accel_offsets);
        sum
    }
}
