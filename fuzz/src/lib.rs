//! Shared input decoding for the fuzz targets.
//!
//! An input is a start byte and a list of operations, decoded by hand (no `arbitrary`) so a
//! few bytes reach deep states:
//!
//! | byte | meaning |
//! |---|---|
//! | 0 | profile (`flight_controller` only: default, ESC, reference) and pre-run start point |
//! | `0x00..=0x7F` k, lo, hi | one capture edge: channel `k & 7` (4..7 do not exist), level high if `k & 8`, counts `lo | hi << 8` (all 16 bits; the core masks to 15) |
//! | `0x80..=0xBF` | `(k & 63) + 1` control ticks: injected edges first, then the receiver's |
//! | `0xC0..=0xDF` | the receiver now sends preset `k & 15` (neutral, arm, disarm, calibrate, fly, off, …) |
//! | `0xE0..=0xE7` + 8 bytes | the receiver now sends these four widths (u16 LE counts, 0 = no pulse) |
//! | `0xE8..=0xEF` | sensor mode `k & 7` (`flight_controller` only): level, stuck at the next 12 bytes, random words, words from the input (12 bytes per tick), extremes |
//! | `0xF0..=0xF7` | `((k & 7) + 1) · 32` control ticks |
//! | `0xF8..=0xFF` | glitches per frame = `k & 3` |
//!
//! At most [`MAX_TICKS`] ticks run per input.

use std::sync::OnceLock;

use fcu_core::config::Config;
use fcu_core::imu::RawImu;
use fcu_core::rc::{CaptureEdge, Sticks};
use fcu_core::supervisor::FlightState;
use fcu_testkit::safety::{sticks, RadioFrame, Rig, Violation};
use fcu_testkit::sim::rng::Rng;

/// Ticks per input (1.28 s of flight; the start points sit a few ticks before each
/// transition), to keep executions fast.
pub const MAX_TICKS: u32 = 1024;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Target {
    /// Default profile, level IMU, edges only.
    EdgesSupervisor,
    /// All profiles, edges and sensor words.
    FlightController,
}

fn must<T, E: std::fmt::Display>(r: Result<T, E>, what: &str) -> T {
    match r {
        Ok(v) => v,
        Err(e) => panic!("building the start point {what}: {e}"),
    }
}

/// The pre-run start points of one profile: each a few ticks away from a transition.
fn build_starts(cfg: Config) -> Vec<Rig> {
    let safe = cfg.supervisor != fcu_core::supervisor::SupervisorConfig::Reference;
    let mut out = Vec::new();
    // Mid-boot: 10 ticks before the start-up calibration completes.
    let mut boot = must(Rig::new(cfg, 11), "boot");
    let boot_ticks = cfg.calibration.settle_ticks + cfg.calibration.samples - 10;
    must(boot.sticks(sticks::NEUTRAL, boot_ticks), "boot");
    out.push(boot);

    let booted = must(Rig::booted(cfg, 11), "booted");
    out.push(booted.clone());
    let hold = match cfg.supervisor {
        fcu_core::supervisor::SupervisorConfig::Safe(s) => s,
        fcu_core::supervisor::SupervisorConfig::Reference => fcu_core::supervisor::SafetyConfig::DEFAULT,
    };
    // Arm gesture held until a few ticks before the hold is complete.
    let mut arming = booted.clone();
    must(arming.sticks(sticks::ARM, hold.arm_hold_ticks - 3), "arming");
    out.push(arming);
    // Just armed, throttle low.
    let mut armed = booted.clone();
    must(armed.arm(), "armed");
    out.push(armed.clone());
    // Flying level.
    let mut flying = armed.clone();
    must(flying.sticks(sticks::FLY, 400), "flying");
    out.push(flying.clone());
    if safe {
        // Armed, throttle low, 10 ticks before the automatic disarm.
        let mut idle = armed.clone();
        must(idle.sticks(sticks::NEUTRAL, hold.auto_disarm_ticks - 12), "idle");
        out.push(idle);
        // Stage 1, a few ticks before stage 2 (lost time counts from the last pulse, which
        // came up to a frame before the receiver went quiet).
        let mut stage1 = flying.clone();
        must(stage1.run(&RadioFrame::OFF, hold.failsafe_off_ticks - 20, 0), "stage 1");
        assert_eq!(stage1.state(), FlightState::FailsafeLevel);
        out.push(stage1.clone());
        // Stage 2.
        let mut stage2 = stage1;
        must(stage2.run(&RadioFrame::OFF, 40, 0), "stage 2");
        assert_eq!(stage2.state(), FlightState::FailsafeOff);
        out.push(stage2);
        // Flying, disarm gesture held until just before the hold completes.
        let mut disarming = flying.clone();
        must(disarming.sticks(sticks::DISARM, hold.disarm_hold_ticks - 3), "disarming");
        out.push(disarming);
        // Stage 1 on a flapping link (off 150 ms, on 40 ms), most of the lost time spent,
        // the link good again for now.
        let mut flapping = flying.clone();
        let fly = RadioFrame::from_sticks(&cfg.rc, sticks::FLY);
        for _ in 0..4 {
            must(flapping.run(&RadioFrame::OFF, 120, 0), "flapping");
            must(flapping.run(&fly, 32, 0), "flapping");
        }
        assert_eq!(flapping.state(), FlightState::FailsafeLevel);
        out.push(flapping);
    }
    out
}

fn starts(profile: usize) -> &'static [Rig] {
    static STARTS: OnceLock<[Vec<Rig>; 3]> = OnceLock::new();
    let all = STARTS.get_or_init(|| [build_starts(Config::default()), build_starts(Config::esc()), build_starts(Config::reference())]);
    all.get(profile).map_or(&[], |v| v.as_slice())
}

const PRESETS: [Option<Sticks>; 16] = [
    Some(sticks::NEUTRAL),
    Some(sticks::ARM),
    Some(sticks::DISARM),
    Some(sticks::CALIBRATE),
    Some(sticks::FLY),
    None,
    Some(Sticks::new(0, 0, 199, 0)),
    Some(Sticks::new(0, 0, 200, 0)),
    Some(Sticks::new(1800, -1800, 2500, 1800)),
    Some(Sticks::new(-1201, -1201, 0, 1201)),
    Some(Sticks::new(-1200, -1201, 0, 1201)),
    Some(Sticks::new(300, -300, 150, -1201)),
    Some(Sticks::new(-4000, 4000, 5000, -4000)),
    Some(Sticks::new(0, 0, 1, 0)),
    Some(Sticks::new(0, 0, 600, 0)),
    None,
];

#[derive(Clone, Copy)]
enum Sensor {
    Level,
    Stuck(RawImu),
    Random,
    FromInput,
    Extremes,
}

struct Bytes<'a> {
    data: &'a [u8],
    pos: usize,
}

impl Bytes<'_> {
    fn u8(&mut self) -> Option<u8> {
        let b = self.data.get(self.pos).copied();
        self.pos += 1;
        b
    }
    fn u16(&mut self) -> u16 {
        let lo = self.u8().unwrap_or(0);
        let hi = self.u8().unwrap_or(0);
        u16::from_le_bytes([lo, hi])
    }
    fn raw_imu(&mut self) -> RawImu {
        let mut w = || self.u16() as i16;
        RawImu { accel: [w(), w(), w()], gyro: [w(), w(), w()] }
    }
}

impl Sensor {
    /// The IMU's reading for the next tick.
    fn sample(&self, rig: &mut Rig, b: &mut Bytes, rng: &mut Rng) -> RawImu {
        match *self {
            Sensor::Level => rig.imu.sample(),
            Sensor::Stuck(raw) => raw,
            Sensor::Random => {
                let mut w = || rng.next_u64() as i16;
                RawImu { accel: [w(), w(), w()], gyro: [w(), w(), w()] }
            }
            Sensor::FromInput => {
                if b.pos + 12 <= b.data.len() {
                    b.raw_imu()
                } else {
                    rig.imu.sample()
                }
            }
            Sensor::Extremes => {
                const X: [i16; 5] = [i16::MIN, -1, 0, 1, i16::MAX];
                let mut w = || X[(rng.next_u64() % 5) as usize];
                RawImu { accel: [w(), w(), w()], gyro: [w(), w(), w()] }
            }
        }
    }
}

/// Run one input; a violated invariant is the error (a panic in the core propagates).
pub fn run(data: &[u8], target: Target) -> Result<(), Violation> {
    let mut b = Bytes { data, pos: 0 };
    let head = b.u8().unwrap_or(0);
    let profile = match target {
        Target::EdgesSupervisor => 0,
        Target::FlightController => usize::from(head >> 4) % 3,
    };
    let list = starts(profile);
    let Some(start) = list.get(usize::from(head & 15) % list.len().max(1)) else {
        return Ok(());
    };
    let mut rig = start.clone();
    let rc = rig.fc.config().rc;
    let mut frame = RadioFrame::from_sticks(&rc, sticks::NEUTRAL);
    let mut glitches = 0u8;
    let mut sensor = Sensor::Level;
    let mut rng = Rng::new(u64::from(head));
    let mut edges: Vec<CaptureEdge> = Vec::new();
    let mut ticks = 0u32;
    while let Some(k) = b.u8() {
        let n = match k {
            0x00..=0x7F => {
                let counts = b.u16();
                edges.push(CaptureEdge { channel: usize::from(k & 7), capture_counts: counts, level_high: k & 8 != 0 });
                0
            }
            0x80..=0xBF => u32::from(k & 63) + 1,
            0xC0..=0xDF => {
                frame = PRESETS[usize::from(k & 15)].map_or(RadioFrame::OFF, |s| RadioFrame::from_sticks(&rc, s));
                0
            }
            0xE0..=0xE7 => {
                frame = RadioFrame { width_counts: [b.u16(), b.u16(), b.u16(), b.u16()], link: true };
                0
            }
            0xE8..=0xEF => {
                if target == Target::FlightController {
                    sensor = match k & 7 {
                        1 => Sensor::Stuck(b.raw_imu()),
                        2 => Sensor::Random,
                        3 => Sensor::FromInput,
                        4 => Sensor::Extremes,
                        _ => Sensor::Level,
                    };
                }
                0
            }
            0xF0..=0xF7 => (u32::from(k & 7) + 1) * 32,
            0xF8..=0xFF => {
                glitches = k & 3;
                0
            }
        };
        for _ in 0..n {
            if ticks >= MAX_TICKS {
                return Ok(());
            }
            ticks += 1;
            let imu = sensor.sample(&mut rig, &mut b, &mut rng);
            rig.radio.tick(&frame, glitches, &mut edges);
            rig.tick_with(imu, &edges)?;
            edges.clear();
        }
    }
    Ok(())
}
