//! The board on a bench: the link task, the control loop and the parameter flash composed as
//! the firmware composes them, deterministic to the tick, for the invariants that live where
//! they meet (`tests/boundaries.rs`, the `boundaries` fuzz target).
//!
//! - [`flash`]: two sectors of 4096 words, erase (250–500 ms of stalled CPU) and word
//!   programming that only clears bits, and a power cut at any word;
//! - [`gcs`]: the ground station's MAVLink frames (any parameter name and value, any command
//!   number and parameters) and the board's answers read back;
//! - [`board`]: [`Bench`], the board at 800 Hz with the firmware's link task
//!   ([`fcu_gcs::Service`]) every 4 ticks, the UART at
//!   115200 baud both ways, a level still IMU, the pilot's transmitter;
//! - [`check`]: the invariants, each a named [`Invariant`], checked as the bench runs.
//!
//! A [`Scenario`] is a flash history (snapshots an older firmware saved, some of which today's
//! rules may refuse), a seed and the operations; [`Scenario::from_bytes`] makes one of any bytes
//! for the fuzzer.

pub mod board;
pub mod check;
pub mod flash;
pub mod gcs;

pub use board::{Bench, Counts, Op, Pilot};
pub use check::{Invariant, Violation};
pub use flash::{Flash, PowerCut};
pub use gcs::{cmd, name16, GcsFrame};

use std::collections::HashMap;
use std::sync::OnceLock;

use fcu_core::Config;
use fcu_params::{self as parameters, snapshot, COUNT};

/// How long the board needs after power-on to calibrate and settle before it may arm, ms
/// (with a margin); every scenario starts with it.
pub const BOOT_MS: u32 = 3000;

/// A snapshot an older firmware saved: its sequence number and values (defaults with some
/// values replaced, whatever today's rules say of them).
#[derive(Clone, Debug, PartialEq)]
pub struct Planted {
    pub sequence: u32,
    pub changes: Vec<(usize, f32)>,
}

impl Planted {
    pub fn values(&self, defaults: &Config) -> [f32; COUNT] {
        let mut v = parameters::values(defaults);
        for &(i, x) in &self.changes {
            if let Some(slot) = v.get_mut(i) {
                *slot = x;
            }
        }
        v
    }
}

/// Writes `values` as a snapshot with sequence `sequence` where a save would put it.
pub fn plant(flash: &mut Flash, sequence: u32, values: &[f32; COUNT]) {
    let plan = snapshot::plan_save(flash.sectors(), values);
    let words = snapshot::encode(sequence, values);
    if let Some(sector) = plan.erase {
        let _whole = flash.erase(sector);
    }
    let _whole = flash.program(plan.sector, plan.first_word, &words);
}

/// Where [`plant`] puts the k-th of consecutively numbered snapshots planted on an erased
/// flash: (the sector it erases first, the sector, the first word), for as many as a fuzz
/// input's history holds. The place depends only on which slots hold a whole snapshot and
/// which is newest, not on the values (every planted snapshot is whole, and the newest is
/// the last one planted), so one planting of default sets finds it for every history; a
/// history plants its snapshots without planning each save anew (130-odd plans, each
/// checking the CRC of every snapshot in both sectors, for one that fills both).
pub fn planting_order() -> &'static [(Option<usize>, usize, usize)] {
    static ORDER: OnceLock<Vec<(Option<usize>, usize, usize)>> = OnceLock::new();
    ORDER.get_or_init(|| {
        let values = parameters::values(&Config::DEFAULT);
        let mut flash = Flash::new();
        (0..3 + 2 * snapshot::SLOTS as u32)
            .map(|k| {
                let plan = snapshot::plan_save(flash.sectors(), &values);
                plant(&mut flash, 1 + k, &values);
                (plan.erase, plan.sector, plan.first_word)
            })
            .collect()
    })
}

/// Everything one bench run is made of.
#[derive(Clone, Debug, PartialEq)]
pub struct Scenario {
    pub history: Vec<Planted>,
    pub seed: u64,
    pub ops: Vec<Op>,
}

impl Scenario {
    /// The flash with the history written, oldest first, each where a save would put it
    /// ([`plant`]). The places are taken from [`planting_order`] (the same erases and
    /// programs; `the_planting_order_puts_snapshots_where_a_save_would` shows the flash is
    /// word for word what [`plant`] makes).
    pub fn flash(&self, defaults: &Config) -> Flash {
        let mut flash = Flash::new();
        let order = planting_order();
        // The order holds while every snapshot so far was numbered one after the one before.
        let mut in_order = true;
        for (k, p) in self.history.iter().enumerate() {
            let values = p.values(defaults);
            in_order = in_order && (k == 0 || self.history[k - 1].sequence.checked_add(1) == Some(p.sequence));
            match order.get(k) {
                Some(&(erase, sector, first_word)) if in_order => {
                    if let Some(e) = erase {
                        let _whole = flash.erase(e);
                    }
                    let _whole = flash.program(sector, first_word, &snapshot::encode(p.sequence, &values));
                }
                _ => plant(&mut flash, p.sequence, &values),
            }
        }
        flash
    }

    /// Boots the board on the scenario's flash, lets it settle ([`BOOT_MS`]) and runs the
    /// operations.
    pub fn run(&self, defaults: &'static Config) -> Bench {
        let mut bench = Scenario::booted(self.flash(defaults), defaults, self.seed);
        bench.run(&self.ops);
        bench
    }

    /// As [`Scenario::run`], the board booted taken from `cache` when a scenario with the
    /// same history and seed booted it before.
    pub fn run_cached(&self, cache: &mut BootCache) -> Bench {
        let mut bench = cache.booted(self);
        bench.run(&self.ops);
        bench
    }

    /// The board switched on with `flash` and settled for [`BOOT_MS`], before any operation.
    fn booted(flash: Flash, defaults: &'static Config, seed: u64) -> Bench {
        let mut bench = Bench::new(flash, defaults, seed);
        bench.run_ms(BOOT_MS);
        bench
    }

    /// A scenario from any bytes (the fuzzer's input), at most [`MAX_FUZZ_MS`] of operations:
    ///
    /// | byte | meaning |
    /// |---|---|
    /// | 0 | the seed |
    /// | 1 | `h`: a history of `h & 3` snapshots, sequence numbers starting at `u32::MAX - (h >> 2 & 31)` when `h & 0x80` (at most up to `u32::MAX`, no wrap), at 1 otherwise; each snapshot then takes a byte `n` and `n & 3` (index, value) changes of 2 bytes (see below); with `h & 0x40` the last of them fills both sectors (the next save erases) |
    /// | then `k`, by range | |
    /// | `0x00..=0x3F` | wait `(k + 1) · 20` ms |
    /// | `0x40..=0x44` | the pilot: neutral, arm, fly, disarm, transmitter off |
    /// | `0x45` / `0x46` | the arm / disarm gesture: held 1.1 s, then neutral 0.1 s |
    /// | `0x47..=0x5F` | a heartbeat |
    /// | `0x60..=0x6F` + 2 bytes | PARAM_SET: parameter `b0 % (COUNT + 1)` (`COUNT`: an unknown name), value [`value_for`]`(b1)` |
    /// | `0x70..=0x7F` + 2 bytes | a command ([`command_for`]): COMMAND_INT when `k & 1` |
    /// | `0x80..=0x8F` + 1 byte | PARAM_REQUEST_READ of that index (`0xFF`: by name, of parameter 0) |
    /// | `0x90..=0x97` | PARAM_REQUEST_LIST |
    /// | `0x98..=0x9F` | a flood of `((k & 7) + 1) · 200` ms |
    /// | `0xA0..=0xAF` + 3 bytes | a power cut at word `b0 | b1 << 8` (scaled by `k & 15` sectors' words), partial bits from `b2` |
    /// | `0xB0..=0xB7` | a power cut now |
    /// | `0xB8..=0xBF` | erases take `250 + (k & 7) · 35` ms |
    /// | `0xC0..=0xFF` | wait `(k & 63) + 1` ms |
    pub fn from_bytes(data: &[u8]) -> Scenario {
        Scenario::from_bytes_marked(data).0
    }

    /// [`Scenario::from_bytes`], with where each operation byte's operations end: a
    /// [`Mark`] for every one whose bytes are all in `data` (one byte at least follows it).
    /// Decoding reads forward only, so the operations up to a mark, and the board's state
    /// after them, depend on `data[..mark.bytes]` alone.
    pub fn from_bytes_marked(data: &[u8]) -> (Scenario, Vec<Mark>) {
        let mut it = data.iter().copied();
        let seed = u64::from(it.next().unwrap_or(0));
        let history = Scenario::history_from(&mut it);
        let mut ops = Vec::new();
        let mut marks = Vec::new();
        let mut ms = 0u32;
        while let Some(k) = it.next() {
            if ms >= MAX_FUZZ_MS {
                break;
            }
            ms += Scenario::push_op(k, &mut it, &mut ops);
            if it.len() > 0 {
                marks.push(Mark { bytes: data.len() - it.len(), ops: ops.len() });
            }
        }
        (Scenario { history, seed, ops }, marks)
    }

    /// The flash history a scenario starts from: its header byte and the entries it takes
    /// (see [`Scenario::from_bytes`]).
    fn history_from(it: &mut impl Iterator<Item = u8>) -> Vec<Planted> {
        let mut next = || it.next().unwrap_or(0);
        let h = next();
        // A history a board could have left: one sequence number after another, no wrap.
        let start = if h & 0x80 != 0 { u32::MAX - u32::from((h >> 2) & 0x1F) } else { 1 };
        let start = start.min(u32::MAX - u32::from(h & 3).saturating_sub(1));
        let mut history = Vec::new();
        for k in 0..u32::from(h & 3) {
            let n = next();
            let changes = (0..n & 3)
                .map(|_| {
                    let i = usize::from(next()) % COUNT;
                    (i, value_for(i, next()))
                })
                .collect();
            history.push(Planted { sequence: start + k, changes });
        }
        if h & 0x40 != 0 {
            if let Some(last) = history.last().cloned() {
                let room = u32::MAX - last.sequence;
                for k in 1..=(2 * snapshot::SLOTS as u32).min(room) {
                    history.push(Planted { sequence: last.sequence + k, changes: last.changes.clone() });
                }
            }
        }
        history
    }

    /// Appends what op byte `k` makes (with the bytes it takes from `it`, see
    /// [`Scenario::from_bytes`]); the board time it waits, ms.
    fn push_op(k: u8, it: &mut impl Iterator<Item = u8>, ops: &mut Vec<Op>) -> u32 {
        let mut byte = || it.next().unwrap_or(0);
        match k {
            0x00..=0x3F => {
                let w = (u32::from(k) + 1) * 20;
                ops.push(Op::Wait { ms: w });
                return w;
            }
            0x40..=0x44 => ops.push(Op::Pilot([Pilot::Neutral, Pilot::Arm, Pilot::Fly, Pilot::Disarm, Pilot::Off][usize::from(k - 0x40)])),
            0x45 | 0x46 => {
                ops.extend(gesture(if k == 0x45 { Pilot::Arm } else { Pilot::Disarm }));
                return 1200;
            }
            0x47..=0x5F => ops.push(Op::Send(GcsFrame::Heartbeat)),
            0x60..=0x6F => {
                let i = usize::from(byte()) % (COUNT + 1);
                let sel = byte();
                ops.push(Op::Send(param_set(i, value_for(i, sel))));
            }
            0x70..=0x7F => {
                let (c, p) = (byte(), byte());
                ops.push(Op::Send(command_for(c, p, k & 1 != 0)));
            }
            0x80..=0x8F => {
                let i = byte();
                let frame = if i == 0xFF {
                    GcsFrame::ParamRead { index: -1, name: name16(parameters::name(0).unwrap_or("")) }
                } else {
                    GcsFrame::ParamRead { index: i16::from(i), name: [0; 16] }
                };
                ops.push(Op::Send(frame));
            }
            0x90..=0x97 => ops.push(Op::Send(GcsFrame::ParamList)),
            0x98..=0x9F => {
                let w = (u32::from(k & 7) + 1) * 200;
                ops.push(Op::Flood { ms: w });
                return w;
            }
            0xA0..=0xAF => {
                let (lo, hi, partial) = (byte(), byte(), byte());
                let at_word = u32::from(k & 15) * snapshot::SECTOR_WORDS as u32 / 4 + u32::from(u16::from_le_bytes([lo, hi]) % 2048);
                ops.push(Op::CutAtWord(PowerCut { at_word, partial_bits: u32::from(partial).wrapping_mul(0x0101_0101) }));
            }
            0xB0..=0xB7 => ops.push(Op::CutNow),
            0xB8..=0xBF => ops.push(Op::EraseMs(250 + u32::from(k & 7) * 35)),
            0xC0..=0xFF => {
                let w = u32::from(k & 63) + 1;
                ops.push(Op::Wait { ms: w });
                return w;
            }
        }
        0
    }
}

/// Where the operations of one operation byte end: `data[..bytes]` decodes to the first
/// `ops` operations (see [`Scenario::from_bytes_marked`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Mark {
    pub bytes: usize,
    pub ops: usize,
}

/// A history as a key: the values by their bits (a NaN is a value like any other).
type HistoryKey = Vec<(u32, Vec<(usize, u32)>)>;

fn history_key(history: &[Planted]) -> HistoryKey {
    history.iter().map(|p| (p.sequence, p.changes.iter().map(|&(i, v)| (i, v.to_bits())).collect())).collect()
}

/// Booted benches by flash history and seed, planted flashes by history, and benches part
/// way through a fuzz input's operations by the input's bytes up to there, for a run of many
/// scenarios (the fuzzer's). The bench is deterministic and a clone a deep copy, so a
/// scenario run from a cached state runs exactly as from its own boot (shown by
/// `a_cached_boot_runs_on_as_a_fresh_boot` and
/// `an_input_run_from_a_cached_prefix_runs_as_from_its_boot`); what it saves is the boot
/// (2,400 ticks and 600 link periods), planting a history (a history that fills both sectors
/// plans 130-odd saves, each scanning both sectors), and the operations an input shares with
/// one run before (a fuzzer's mutation keeps the bytes ahead of it). Bounded: a map that
/// reaches [`BootCache::CAPACITY`] entries is emptied.
pub struct BootCache {
    defaults: &'static Config,
    booted: HashMap<(HistoryKey, u64), Bench>,
    flashes: HashMap<HistoryKey, Flash>,
    prefixes: HashMap<Vec<u8>, Bench>,
    /// Boots taken from the cache, and boots run.
    pub hits: u64,
    pub misses: u64,
    /// Inputs run on from a cached prefix of their operations.
    pub prefix_hits: u64,
}

impl BootCache {
    /// Entries each map holds at most (a bench is some 50 KiB, a flash 32 KiB).
    pub const CAPACITY: usize = 1024;

    pub fn new(defaults: &'static Config) -> BootCache {
        BootCache {
            defaults,
            booted: HashMap::new(),
            flashes: HashMap::new(),
            prefixes: HashMap::new(),
            hits: 0,
            misses: 0,
            prefix_hits: 0,
        }
    }

    /// Bench time between two prefixes kept, ms: a clone costs about what a few ms of bench
    /// time do.
    pub const PREFIX_EVERY_MS: u64 = 500;

    /// [`Scenario::from_bytes`]`(data)` run (as [`Scenario::run`]), from the longest prefix of
    /// its operations a run before kept, or from a cached boot; keeps its own prefixes.
    pub fn run_bytes(&mut self, data: &[u8]) -> Bench {
        let (scenario, marks) = Scenario::from_bytes_marked(data);
        let found = marks.iter().rev().find_map(|m| self.prefixes.get(&data[..m.bytes]).map(|b| (*m, b.clone())));
        let (mut bench, mut done) = match found {
            Some((m, bench)) => {
                self.prefix_hits += 1;
                (bench, m.ops)
            }
            None => (self.booted(&scenario), 0),
        };
        let mut kept_ms = bench.time_ms();
        let from = done;
        for m in marks.iter().filter(|m| m.ops > from) {
            bench.run(&scenario.ops[done..m.ops]);
            done = m.ops;
            if bench.time_ms() >= kept_ms + Self::PREFIX_EVERY_MS {
                kept_ms = bench.time_ms();
                if self.prefixes.len() >= Self::CAPACITY {
                    self.prefixes.clear();
                }
                self.prefixes.entry(data[..m.bytes].to_vec()).or_insert_with(|| bench.clone());
            }
        }
        bench.run(&scenario.ops[done..]);
        bench
    }

    /// A copy of the board `scenario` boots (its history, its seed), settled for [`BOOT_MS`].
    pub fn booted(&mut self, scenario: &Scenario) -> Bench {
        let history = history_key(&scenario.history);
        let key = (history, scenario.seed);
        if let Some(bench) = self.booted.get(&key) {
            self.hits += 1;
            return bench.clone();
        }
        self.misses += 1;
        let flash = match self.flashes.get(&key.0) {
            Some(flash) => flash.clone(),
            None => {
                let flash = scenario.flash(self.defaults);
                if self.flashes.len() >= Self::CAPACITY {
                    self.flashes.clear();
                }
                self.flashes.insert(key.0.clone(), flash.clone());
                flash
            }
        };
        let bench = Scenario::booted(flash, self.defaults, scenario.seed);
        if self.booted.len() >= Self::CAPACITY {
            self.booted.clear();
        }
        self.booted.insert(key, bench.clone());
        bench
    }
}

/// The most time a fuzz input's operations may take, ms (a case stays some tens of ms of CPU).
pub const MAX_FUZZ_MS: u32 = 20_000;

/// The pilot's gesture: `hold` for 1.1 s (more than the default 1 s hold), then the sticks
/// released for 0.1 s.
pub fn gesture(hold: Pilot) -> [Op; 4] {
    [Op::Pilot(hold), Op::Wait { ms: 1100 }, Op::Pilot(Pilot::Neutral), Op::Wait { ms: 100 }]
}

/// A PARAM_SET of parameter `i` (an unknown name past the table).
pub fn param_set(i: usize, value: f32) -> GcsFrame {
    GcsFrame::ParamSet { name: name16(parameters::name(i).unwrap_or("NO_SUCH_PARAM")), value }
}

/// A value for parameter `i` from a selector: its default, bounds, the middle and a step past
/// them, whole numbers, and values from the selector's bits.
pub fn value_for(i: usize, sel: u8) -> f32 {
    let (min, max, default) = match parameters::param(i) {
        Some(p) => (p.min, p.max, parameters::value(&Config::DEFAULT, i).unwrap_or(0.0)),
        None => (0.0, 1.0, 0.0),
    };
    match sel {
        0 => default,
        1 => min,
        2 => max,
        3 => ((min + max) * 0.5).round(),
        4 => max + 1.0,
        5 => min - 1.0,
        6 => f32::NAN,
        7..=39 => f32::from(sel - 7),
        40..=127 => min + (max - min) * f32::from(sel - 40) / 87.0,
        _ => (min + (max - min) * f32::from(sel - 128) / 127.0).round(),
    }
}

/// A command from two selector bytes: `c` picks the command (reboot, storage, calibration,
/// motor test, arm/disarm, home position, or an unlisted number), `p` its parameters.
pub fn command_for(c: u8, p: u8, int: bool) -> GcsFrame {
    let command = match c % 8 {
        0 => cmd::PREFLIGHT_REBOOT_SHUTDOWN,
        1 => cmd::PREFLIGHT_STORAGE,
        2 => cmd::PREFLIGHT_CALIBRATION,
        3 => cmd::DO_MOTOR_TEST,
        4 => cmd::COMPONENT_ARM_DISARM,
        5 => cmd::GET_HOME_POSITION,
        _ => u16::from(c) * 7,
    };
    let first = [0.0, 1.0, 2.0, 3.0, 4.0, 21196.0, -1.0, 0.5][usize::from(p & 7)];
    let mut params = [first, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0];
    match command {
        // Motor `first`, throttle in percent, `p >> 3`% for 2 s, one motor.
        cmd::DO_MOTOR_TEST => params = [first, 0.0, f32::from(p >> 3), 2.0, 1.0, 0.0, 0.0],
        // Gyro, radio or accelerometer by the upper bits.
        cmd::PREFLIGHT_CALIBRATION => match p >> 3 & 3 {
            1 => params[3] = 1.0,
            2 => params[4] = 1.0,
            _ => {}
        },
        // Arm or disarm, forced by the upper bits.
        cmd::COMPONENT_ARM_DISARM if p & 0x80 != 0 => params[1] = 21196.0,
        _ => {}
    }
    GcsFrame::Command { command, params, int }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_history_from_bytes_numbers_its_snapshots_one_after_another_without_a_wrap() {
        for h in [0x83u8, 0x87, 0xC3, 0xFF, 0x43] {
            let s = Scenario::from_bytes(&[0, h, 1, 0, 0, 1, 0, 0, 1, 0, 0]);
            assert!(!s.history.is_empty(), "{h:#x}");
            for pair in s.history.windows(2) {
                assert_eq!(pair[0].sequence.checked_add(1), Some(pair[1].sequence), "{h:#x}");
            }
        }
    }

    /// What a bench shows from outside: the status, the flash, what it sent, what it counted
    /// and what the checks found.
    fn seen(b: &Bench) -> (String, Vec<u32>, u64, Counts, u64, Vec<Violation>) {
        let flash = b.flash.sectors().iter().flat_map(|s| s.iter().copied()).collect();
        (format!("{:?}", b.status()), flash, b.downlink_hash(), b.counts, b.time_ms(), b.checker.violations().to_vec())
    }

    #[test]
    fn the_planting_order_puts_snapshots_where_a_save_would() {
        static DEFAULTS: Config = Config::DEFAULT;
        // Headers: no history, three snapshots, both sectors filled from 1 and from near the
        // top of the sequence numbers, with changed (some refused) values.
        for header in [
            &[0u8, 0][..],
            &[0, 3, 1, 4, 9, 2, 1, 3, 3, 5, 7, 0, 1, 2, 3],
            &[0, 0x43, 1, 3, 4, 2, 6, 6, 1, 2, 1],
            &[0, 0xC3, 2, 1, 2, 3, 4],
            &[0, 0xFE, 1, 2, 6],
        ] {
            let scenario = Scenario::from_bytes(header);
            let mut planted = Flash::new();
            for p in &scenario.history {
                plant(&mut planted, p.sequence, &p.values(&DEFAULTS));
            }
            let fast = scenario.flash(&DEFAULTS);
            assert_eq!(fast.sectors(), planted.sectors(), "{header:?}");
            // The erase and program counts too.
            assert_eq!(format!("{fast:?}"), format!("{planted:?}"), "{header:?}");
        }
    }

    #[test]
    fn a_cached_boot_runs_on_as_a_fresh_boot() {
        static DEFAULTS: Config = Config::DEFAULT;
        // Histories (none, one refused value, both sectors full), seeds, and operations that
        // set, save, reboot, arm, fly and cut the power.
        let ops: &[u8] =
            &[0x60, 5, 2, 0x70, 1, 1, 0x45, 0x42, 0x20, 0x43, 0x70, 0, 1, 0x3F, 0xA3, 9, 0, 0x55, 0x70, 1, 1, 0x3F, 0x90, 0x9A, 0xB0, 0x10];
        let mut cache = BootCache::new(&DEFAULTS);
        for header in [&[7u8, 0][..], &[7, 0x81, 1, 3, 4], &[200, 0xC2, 1, 0, 0, 2, 5, 1, 9, 130], &[3, 0x43, 2, 1, 2, 3, 4]] {
            let input = [header, ops].concat();
            let scenario = Scenario::from_bytes(&input);
            let fresh = scenario.run(&DEFAULTS);
            let first = scenario.run_cached(&mut cache);
            let again = scenario.run_cached(&mut cache);
            assert_eq!(seen(&first), seen(&fresh), "{header:?}");
            assert_eq!(seen(&again), seen(&fresh), "{header:?}");
            assert!(fresh.counts.saves > 0 && fresh.counts.reboots + fresh.counts.power_cuts > 0, "{header:?}: {:?}", fresh.counts);
        }
        assert_eq!((cache.hits, cache.misses), (4, 4));
    }

    #[test]
    fn an_input_run_from_a_cached_prefix_runs_as_from_its_boot() {
        static DEFAULTS: Config = Config::DEFAULT;
        let base: &[u8] = &[
            9, 0x41, 1, 4, 7, 0x60, 5, 2, 0x3F, 0x70, 1, 1, 0x3F, 0x45, 0x42, 0x30, 0x43, 0x98, 0x70, 0, 1, 0x3F, 0xA3, 9, 0, 0x55, 0x3F,
            0x70, 1, 1, 0x3F, 0x3F, 0xB0, 0x10,
        ];
        let mut cache = BootCache::new(&DEFAULTS);
        let first = cache.run_bytes(base);
        assert_eq!(seen(&first), seen(&Scenario::from_bytes(base).run(&DEFAULTS)));
        // The fuzzer's mutations: a byte changed, cut short, bytes appended, an op's bytes
        // cut in the middle, the same input again.
        let mut changed = base.to_vec();
        changed[25] = 0x70;
        let mut longer = base.to_vec();
        longer.extend([0x70, 0, 1, 0x3F, 0x60, 200, 7, 0x20]);
        for input in [&changed[..], &base[..20], &longer, &base[..23], base] {
            let ran = cache.run_bytes(input);
            assert_eq!(seen(&ran), seen(&Scenario::from_bytes(input).run(&DEFAULTS)), "{input:?}");
        }
        assert!(cache.prefix_hits >= 4, "{}", cache.prefix_hits);
    }
}
