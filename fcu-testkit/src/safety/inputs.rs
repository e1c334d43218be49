//! Deterministic inputs for the rules checked to the tick: a PWM receiver and its TIM2 capture
//! in exact counts, and a level, still IMU.

use fcu_core::imu::RawImu;
use fcu_core::rc::{CaptureEdge, RcConfig, Sticks, CAPTURE_WRAP, CHANNELS};

use crate::sim::rng::Rng;

/// TIM2 counts per control tick (1.25 ms at 4 MHz).
pub const COUNTS_PER_TICK: u64 = 5_000;
/// TIM2 counts per receiver frame (20 ms, 50 Hz).
pub const COUNTS_PER_FRAME: u64 = 80_000;

/// What the transmitter sends for a while: a pulse width per channel, TIM2 counts
/// (0 = that channel stays low), or nothing at all.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RadioFrame {
    pub width_counts: [u16; CHANNELS],
    pub link: bool,
}

impl RadioFrame {
    /// No signal.
    pub const OFF: RadioFrame = RadioFrame { width_counts: [0; CHANNELS], link: false };

    /// The widths that decode to `s` (throttle 0 is sent at the bottom of the range).
    pub fn from_sticks(rc: &RcConfig, s: Sticks) -> RadioFrame {
        RadioFrame { width_counts: core::array::from_fn(|input| rc.width_for_sticks(input, &s)), link: true }
    }
}

/// Stick positions of the gestures, reference counts.
pub mod sticks {
    use fcu_core::rc::Sticks;

    pub const NEUTRAL: Sticks = Sticks::new(0, 0, 0, 0);
    pub const ARM: Sticks = Sticks::new(-1500, -1500, 0, 1500);
    pub const DISARM: Sticks = Sticks::new(0, 0, 0, -1500);
    pub const CALIBRATE: Sticks = Sticks::new(1500, -1500, 0, -1500);
    /// Level flight at a mid throttle.
    pub const FLY: Sticks = Sticks::new(0, 0, 1500, 0);
}

/// How a receiver lays the four channels' pulses out in a frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ChannelLayout {
    /// One after the other: each channel rises when the previous one falls (most PPM-derived
    /// receivers).
    Sequential,
    /// Channel `k` rises `k × offset_counts` after the frame starts, whatever the widths (0: all
    /// four together, as some receivers do).
    Spaced { offset_counts: u64 },
}

/// The one PWM receiver of the tests, and the TIM2 capture behind it, in integer counts: every
/// 20 ms frame the four channels pulse ([`ChannelLayout`]), and every edge is timestamped on the
/// 15-bit 0.25 µs counter. Optional glitches: spikes of 2–30 µs on a random channel at a random
/// time of the frame; and edges injected by hand ([`PwmReceiver::inject`]). (The simulator's
/// `sim::radio_model` is the physical receiver, with jitter, for flights; this one is exact, for
/// rules checked to the tick.)
#[derive(Clone, Debug)]
pub struct PwmReceiver {
    now: u64,
    next_frame: u64,
    layout: ChannelLayout,
    /// Scheduled edges at their absolute time in counts (their capture value is set when they
    /// are delivered), in time order.
    pending: Vec<(u64, CaptureEdge)>,
    /// Edges for the next tick only, at their offset from its start.
    injected: Vec<(u64, CaptureEdge)>,
    rng: Rng,
}

impl PwmReceiver {
    /// `seed` sets the frame phase against the control ticks and the glitches; sequential
    /// channels.
    pub fn new(seed: u64) -> Self {
        let mut rng = Rng::fork(seed, 0x0050_574D);
        let next_frame = rng.next_u64() % COUNTS_PER_FRAME;
        PwmReceiver { now: 0, next_frame, layout: ChannelLayout::Sequential, pending: Vec::new(), injected: Vec::new(), rng }
    }

    /// A receiver whose first frame starts `first_frame_counts` after the first tick starts.
    pub fn with_layout(first_frame_counts: u64, layout: ChannelLayout, seed: u64) -> Self {
        PwmReceiver { next_frame: first_frame_counts, layout, ..PwmReceiver::new(seed) }
    }

    /// Frames from now on are laid out this way.
    pub fn set_layout(&mut self, layout: ChannelLayout) {
        self.layout = layout;
    }

    /// Absolute time, TIM2 counts since the receiver started.
    pub fn now_counts(&self) -> u64 {
        self.now
    }

    /// An edge delivered with the next tick, timestamped `offset_counts` after its start (an
    /// offset past the tick's end still comes with it, stamped as the counter would show it:
    /// 32 768 counts later reads the same, which is how a glitch as long as the wrap looks).
    pub fn inject(&mut self, channel: usize, offset_counts: u64, level_high: bool) {
        self.injected.push((offset_counts, CaptureEdge { channel, capture_counts: 0, level_high }));
    }

    /// Whether a frame starts during the next control tick: the transmitter sends the sticks
    /// as they are at a frame's start, and a stick movement that no frame start falls in
    /// never reaches the receiver's output.
    pub fn frame_starts_next_tick(&self) -> bool {
        self.next_frame < self.now + COUNTS_PER_TICK
    }

    /// The edges of the next control tick, appended to `out` oldest first. `frame` is what
    /// frames starting during this tick carry; `glitches` spikes are added to each of them.
    pub fn tick(&mut self, frame: &RadioFrame, glitches: u8, out: &mut Vec<CaptureEdge>) {
        let end = self.now + COUNTS_PER_TICK;
        while self.next_frame < end {
            let start = self.next_frame;
            self.next_frame += COUNTS_PER_FRAME;
            if frame.link {
                let mut t = start;
                for (channel, &w) in frame.width_counts.iter().enumerate() {
                    if let ChannelLayout::Spaced { offset_counts } = self.layout {
                        t = start + channel as u64 * offset_counts;
                    }
                    if w > 0 {
                        self.pending.push((t, CaptureEdge::rising(channel, 0)));
                        self.pending.push((t + u64::from(w), CaptureEdge::falling(channel, 0)));
                        t += u64::from(w);
                    }
                }
            }
            for _ in 0..glitches {
                let channel = (self.rng.next_u64() % CHANNELS as u64) as usize;
                let at = start + self.rng.next_u64() % COUNTS_PER_FRAME;
                let len = 8 + self.rng.next_u64() % 113;
                self.pending.push((at, CaptureEdge::rising(channel, 0)));
                self.pending.push((at + len, CaptureEdge::falling(channel, 0)));
            }
            self.pending.sort_by_key(|&(t, _)| t);
        }
        let due = self.pending.iter().take_while(|&&(t, _)| t < end).count();
        let mut now: Vec<(u64, CaptureEdge)> = self.pending.drain(..due).collect();
        now.extend(self.injected.drain(..).map(|(offset, e)| (self.now + offset, e)));
        now.sort_by_key(|&(t, _)| t);
        for (t, e) in now {
            out.push(CaptureEdge { capture_counts: (t % u64::from(CAPTURE_WRAP)) as u16, ..e });
        }
        self.now = end;
    }
}

/// The one level, still LSM6DSL of the tests: raw words in sensor axes, accel z = 8197 LSB
/// (1 g at 0.122 mg/LSB), ±`noise_lsb` on every word, never two identical samples in a row,
/// unless `stuck` (then every sample is the last one: a sensor that stopped converting). (The
/// simulator's `sim::imu_model` is the physical sensor on a flying airframe.)
#[derive(Clone, Debug)]
pub struct LevelImu {
    rng: Rng,
    last: RawImu,
    pub noise_lsb: i16,
    pub stuck: bool,
}

impl LevelImu {
    pub fn new(seed: u64) -> Self {
        LevelImu { rng: Rng::fork(seed, 0x0049_4D55), last: RawImu::default(), noise_lsb: 2, stuck: false }
    }

    pub fn sample(&mut self) -> RawImu {
        if self.stuck && self.last != RawImu::default() {
            return self.last;
        }
        let span = (2 * i64::from(self.noise_lsb.clamp(0, 100)) + 1) as u64;
        let mut n = || (self.rng.next_u64() % span) as i16 - self.noise_lsb.clamp(0, 100);
        let mut s = RawImu { accel: [n(), n(), 8197 + n()], gyro: [n(), n(), n()] };
        if s == self.last {
            s.accel[0] = if s.accel[0] > 0 { s.accel[0] - 1 } else { s.accel[0] + 1 };
        }
        self.last = s;
        s
    }
}
