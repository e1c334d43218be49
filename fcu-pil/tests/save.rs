//! Parameter saves over the ground link, at DS9716's maximum flash times: what a save costs
//! the control loop and the clock. The ELF is `FCU_PIL_ELF` if set, else the release firmware
//! built now.

use std::sync::OnceLock;

use fcu_pil::elf::Image;
use fcu_pil::firmware;
use fcu_pil::periph::flash::FlashTiming;
use fcu_pil::periph::iwdg::{LSI_MAX_HZ, LSI_MIN_HZ};
use fcu_pil::periph::{Time, TIME_HZ};
use fcu_pil::rig::{self, BoardSetup, EmulatedBoard};
use mavlink::dialects::common::{MavCmd, COMMAND_LONG_DATA, HEARTBEAT_DATA, PARAM_SET_DATA};
use mavlink::{MAVLinkV2MessageRaw, MavHeader, MessageData};

fn elf() -> &'static std::path::Path {
    static ELF: OnceLock<std::path::PathBuf> = OnceLock::new();
    ELF.get_or_init(|| firmware::resolve_elf(None).unwrap_or_else(|e| panic!("{e}")))
}

/// The control tick's period, in emulated time units (800 Hz).
const TICK: Time = TIME_HZ / 800;
/// The parameter sectors (1 and 2) in the flash model's memory.
const PARAM_SECTORS: std::ops::Range<usize> = 0x4000..0xC000;

/// The board, booted at `timing` on `flash` (blank if `None`), its UART left
/// unparsed (it speaks MAVLink).
fn boot(flash: Option<Vec<u8>>, timing: FlashTiming) -> EmulatedBoard {
    boot_with_lsi(flash, timing, None)
}

/// [`boot`] with the LSI at `lsi_hz` (`None`: its nominal 32 kHz).
fn boot_with_lsi(flash: Option<Vec<u8>>, timing: FlashTiming, lsi_hz: Option<u64>) -> EmulatedBoard {
    let image = Image::load(elf()).unwrap_or_else(|e| panic!("{e}"));
    let setup = BoardSetup { flash_contents: flash, lsi_hz, mavlink_from_boot: true, ..BoardSetup::default() };
    let mut b = EmulatedBoard::boot(image, &setup, rig::imu_at_rest(1)).unwrap_or_else(|e| panic!("boot: {e}"));
    assert!(b.flying(), "{}", b.boot_stall());
    b.raw_uart = true;
    b.machine.board_mut().flash.set_timing(timing);
    b
}

/// Both parameter sectors hold words that are neither a snapshot nor erased: the first save
/// erases a sector.
fn flash_needing_an_erase() -> Vec<u8> {
    let mut flash = vec![0xFF; 256 * 1024];
    flash[PARAM_SECTORS].fill(0);
    flash
}

/// A MAVLink 2 frame from a ground station (system 255, component 190).
fn frame<D: MessageData>(data: &D) -> Vec<u8> {
    let mut raw = MAVLinkV2MessageRaw::new();
    raw.serialize_message_data(MavHeader { system_id: 255, component_id: 190, sequence: 0 }, data);
    raw.raw_bytes().to_vec()
}

fn send(b: &mut EmulatedBoard, bytes: &[u8]) {
    let now = b.machine.now();
    b.machine.board_mut().push_uart_rx(bytes, now);
}

fn heartbeat() -> Vec<u8> {
    frame(&HEARTBEAT_DATA { mavtype: mavlink::dialects::common::MavType::MAV_TYPE_GCS, ..HEARTBEAT_DATA::default() })
}

fn param_set(name: &str, value: f32) -> Vec<u8> {
    let mut id = [0u8; 16];
    id[..name.len()].copy_from_slice(name.as_bytes());
    frame(&PARAM_SET_DATA {
        param_value: value,
        target_system: 1,
        target_component: 1,
        param_id: id.into(),
        param_type: mavlink::dialects::common::MavParamType::MAV_PARAM_TYPE_REAL32,
    })
}

fn save_command() -> Vec<u8> {
    frame(&COMMAND_LONG_DATA {
        param1: 1.0,
        command: MavCmd::MAV_CMD_PREFLIGHT_STORAGE,
        target_system: 1,
        target_component: 1,
        ..COMMAND_LONG_DATA::default()
    })
}

/// Everything the UART sent from byte `from` on.
fn uart_from(b: &EmulatedBoard, from: usize) -> Vec<u8> {
    b.machine.board().records.uart.get(from..).unwrap_or_default().iter().map(|&(_, byte)| byte).collect()
}

fn contains(haystack: &[u8], needle: &[u8]) -> bool {
    haystack.windows(needle.len()).any(|w| w == needle)
}

/// A counter of the control task's, read from the firmware's RAM (an RTIC local, found by its
/// symbol).
fn control_counter(b: &EmulatedBoard, name: &str) -> u32 {
    let part = format!("__rtic_internal_local_control_{name}");
    let at = b.machine.image().symbol_containing(&part).unwrap_or_else(|| panic!("no symbol {part} in the image"));
    let bytes = b.machine.read_memory(at, 4).unwrap();
    u32::from_le_bytes(bytes.try_into().unwrap())
}

/// Failed IMU bursts: what the sensor bus model saw go wrong (overruns, a clock stopped too
/// early or too late), and the ticks the firmware ran without a sample (its `bus_errors`).
fn failed_bursts(b: &EmulatedBoard) -> [u32; 2] {
    let spi = &b.machine.board().spi2;
    [spi.overruns() + spi.early_stops() + spi.cut_frames(), control_counter(b, "bus_errors")]
}

/// Asks for a save of a changed gain and runs until the board says it saved (at most 2 s);
/// returns the instant the save began (its unlock of the flash).
fn save(b: &mut EmulatedBoard, value: f32) -> Time {
    let uart_mark = b.machine.board().records.uart.len();
    let unlocks_before = b.machine.board().flash.unlocks().len();
    send(b, &heartbeat());
    send(b, &param_set("RATE_PIT_P", value));
    send(b, &save_command());
    let start = b.scenario_s(b.machine.now());
    let mut t = start;
    while !contains(&uart_from(b, uart_mark), b"parameters saved") {
        assert!(!contains(&uart_from(b, uart_mark), b"NOT saved"), "the save failed");
        assert!(t < start + 2.0, "no \"parameters saved\" within 2 s");
        t += 0.01;
        b.run_to(t).unwrap();
    }
    let unlocks = b.machine.board().flash.unlocks();
    assert!(unlocks.len() > unlocks_before, "the save never unlocked the flash");
    unlocks[unlocks_before]
}

/// The phase of an instant in the control tick, in µs after the tick (TIM9's update).
fn tick_phase_us(b: &EmulatedBoard, at: Time) -> u64 {
    let since_t0 = at - b.time_of(0.0);
    (since_t0 % TICK) * 1_000_000 / TIME_HZ
}

/// Finding: a save programs ~56 words, each stalling every fetch from flash (the vector table
/// and the IMU's end-of-read handler included) for up to 100 µs; one that landed on a burst
/// cost its sample, and three in a row once. No save may cost one: at DS9716's maximum word
/// time, saves begun at several phases of the tick leave the sensor bus clean.
#[test]
fn saves_at_the_maximum_flash_times_cost_no_imu_sample_at_any_phase_of_the_tick() {
    let mut b = boot(None, FlashTiming::Maximum);
    b.run_to(0.5).unwrap();
    let (failed_before, reads_before) = (failed_bursts(&b), b.machine.board().spi2.sensors().lsm6dsl.reads());
    let mut phases = Vec::new();
    for k in 0..8 {
        // The link task waits its 5 ms after each period's work, so the work moves its phase
        // against the tick's: a different number of ground-station heartbeats before each
        // save (read at the line's rate, a few per period) moves where the next save begins.
        for _ in 0..k * 40 {
            send(&mut b, &heartbeat());
        }
        while b.machine.board().uart_rx_pending() > 0 {
            let t = b.scenario_s(b.machine.now());
            b.run_to(t + 0.01).unwrap();
        }
        let began = save(&mut b, 60.0 + k as f32);
        phases.push(tick_phase_us(&b, began));
        assert_eq!(failed_bursts(&b), failed_before, "IMU bursts failed by save {} (begun {} µs after a tick)", k + 1, phases[k]);
    }
    let t = b.scenario_s(b.machine.now());
    b.run_to(t + 0.1).unwrap();
    let mut distinct = phases.clone();
    distinct.sort_unstable();
    distinct.dedup_by(|a, b| a.abs_diff(*b) < 50);
    assert!(distinct.len() >= 3, "the saves began at too few phases of the tick to show anything: {phases:?} µs");
    let reads = b.machine.board().spi2.sensors().lsm6dsl.reads() - reads_before;
    let ticks = (b.scenario_s(b.machine.now()) - 0.5) * 800.0;
    assert!(reads as f64 >= ticks - 2.0, "{reads} IMU bursts in {ticks:.0} ticks: a burst was skipped");
}

/// The same with the erase a save makes when both sectors are full or hold no snapshot: the
/// CPU stalls for the erase (up to 500 ms), and no burst may be cut by it.
#[test]
fn a_save_that_erases_at_the_maximum_flash_times_costs_no_imu_sample() {
    let mut b = boot(Some(flash_needing_an_erase()), FlashTiming::Maximum);
    b.run_to(0.5).unwrap();
    let failed_before = failed_bursts(&b);
    let began = save(&mut b, 70.0);
    let t = b.scenario_s(b.machine.now());
    b.run_to(t + 0.1).unwrap();
    assert!(b.machine.board().flash.memory()[PARAM_SECTORS].contains(&0xFF), "no sector was erased");
    assert_eq!(failed_bursts(&b), failed_before, "IMU bursts failed by the save (begun {} µs after a tick)", tick_phase_us(&b, began));
}

/// Each ATTITUDE frame the board sent: (emulated instant its last byte left, its `time_boot_ms`).
fn attitude_times(b: &EmulatedBoard) -> Vec<(Time, u32)> {
    const ATTITUDE: u32 = 30;
    let uart = &b.machine.board().records.uart;
    let bytes: Vec<u8> = uart.iter().map(|&(_, byte)| byte).collect();
    let mut out = Vec::new();
    let mut i = 0;
    while i + 12 <= bytes.len() {
        let len = usize::from(bytes[i + 1]);
        let end = i + 10 + len + 2;
        if bytes[i] != 0xFD || end > bytes.len() {
            i += 1;
            continue;
        }
        let id = u32::from_le_bytes([bytes[i + 7], bytes[i + 8], bytes[i + 9], 0]);
        let crc = mavlink::calculate_crc(&bytes[i + 1..end - 2], mavlink::dialects::common::ATTITUDE_DATA::EXTRA_CRC);
        if id == ATTITUDE && crc.to_le_bytes() == bytes[end - 2..end] {
            let mut field = [0u8; 4];
            let payload = &bytes[i + 10..i + 10 + len];
            field[..payload.len().min(4)].copy_from_slice(&payload[..payload.len().min(4)]);
            out.push((uart[end - 1].0, u32::from_le_bytes(field)));
            i = end;
        } else {
            i += 1;
        }
    }
    out
}

/// Finding: the monotonic counted SysTick's interrupts, and an erase stalls every one of them
/// but the first: `time_boot_ms` fell 268 ms behind after one erase. The board's clock must
/// run through the stall: across a save that erases (500 ms at DS9716's maximum), the time the
/// board stamps its telemetry with keeps pace with the emulator's clock.
#[test]
fn time_boot_ms_keeps_pace_with_the_clock_across_an_erase() {
    let mut b = boot(Some(flash_needing_an_erase()), FlashTiming::Maximum);
    b.run_to(0.5).unwrap();
    send(&mut b, &heartbeat());
    b.run_to(1.0).unwrap();
    save(&mut b, 70.0);
    let t = b.scenario_s(b.machine.now());
    b.run_to(t + 0.5).unwrap();
    let (erase_start, erase_end) = b.machine.board().flash.erases().first().copied().expect("no erase");
    assert!(erase_end - erase_start >= TIME_HZ / 2 - 1, "the erase took {} ms", (erase_end - erase_start) * 1000 / TIME_HZ);
    let stamps = attitude_times(&b);
    let lag_ms = |&(at, boot_ms): &(Time, u32)| (at * 1000 / TIME_HZ) as i64 - i64::from(boot_ms);
    let before: Vec<i64> = stamps.iter().filter(|s| s.0 < erase_start).map(lag_ms).collect();
    let after: Vec<i64> = stamps.iter().filter(|s| s.0 > erase_end).map(lag_ms).collect();
    assert!(before.len() >= 5 && after.len() >= 5, "ATTITUDE frames: {} before the erase, {} after", before.len(), after.len());
    let (lo, hi) = (before.iter().min().unwrap(), before.iter().max().unwrap());
    for lag in &after {
        assert!(
            *lag >= lo - 10 && *lag <= hi + 10,
            "the emulator's clock minus time_boot_ms: {lo}..{hi} ms before the erase, {lag} ms after"
        );
    }
}

/// What the flash model's parameter sectors hold: the set fcu-core loads from them at boot.
fn saved_set(b: &EmulatedBoard) -> (fcu_core::Config, fcu_params::snapshot::Source) {
    let memory = b.machine.board().flash.memory();
    let words = |range: std::ops::Range<usize>| -> Vec<u32> {
        memory[range].chunks(4).map(|c| u32::from_le_bytes(c.try_into().unwrap())).collect()
    };
    let (a, b) = (words(0x4000..0x8000), words(0x8000..0xC000));
    fcu_params::snapshot::load_config([&a, &b], &fcu_core::Config::default())
}

/// Finding: the flash's data cache keeps the words it read before a program or erase; the
/// firmware empties it (DCRST) after each operation. Without that, the second save plans from
/// the first one's stale view of the sector (still erased) and programs over its words. Two
/// saves in a row leave the second set in flash (the flash model keeps a cached range stale
/// until DCRST).
#[test]
fn two_saves_in_a_row_leave_the_second_set_in_flash() {
    let mut b = boot(None, FlashTiming::Typical);
    b.run_to(0.5).unwrap();
    save(&mut b, 61.0);
    save(&mut b, 62.0);
    let (cfg, source) = saved_set(&b);
    assert!(matches!(source, fcu_params::snapshot::Source::Snapshot { .. }), "{source:?}");
    let index = fcu_params::index_of(b"RATE_PIT_P").unwrap();
    assert_eq!(fcu_params::value(&cfg, index), Some(62.0));
    assert!(b.machine.board().flash.stale_ranges().is_empty(), "the data cache was left holding old words");
}

/// An erase's length is the chip's (DS9716 bounds it, 500 ms at most, and no more), so it can
/// end anywhere in a tick: here 30 µs before one, after the burst for it was due (CC1, 60 µs
/// before the tick). Both TIM9 events are then pending together, one of them from a period the
/// stall swallowed; the tick that follows must still have its sample.
#[test]
fn an_erase_that_ends_between_a_burst_start_and_its_tick_costs_no_imu_sample() {
    let mut b = boot(Some(flash_needing_an_erase()), FlashTiming::Maximum);
    b.run_to(0.5).unwrap();
    let failed_before = failed_bursts(&b);
    send(&mut b, &heartbeat());
    send(&mut b, &param_set("RATE_PIT_P", 70.0));
    send(&mut b, &save_command());
    let mut t = 0.5;
    while b.machine.board().flash.erases().is_empty() {
        assert!(t < 2.5, "no erase within 2 s");
        t += 0.001;
        b.run_to(t).unwrap();
    }
    let (start, _) = b.machine.board().flash.erases()[0];
    // 30 µs before the first tick at least 300 ms after the erase's start.
    let ticks = (start + TIME_HZ * 3 / 10 - b.time_of(0.0)).div_ceil(TICK);
    let end = b.time_of(0.0) + ticks * TICK - TIME_HZ * 30 / 1_000_000;
    b.machine.board_mut().flash.retime_operation(end);
    let mut t = b.scenario_s(b.machine.now());
    let uart_mark = b.machine.board().records.uart.len();
    while !contains(&uart_from(&b, uart_mark), b"parameters saved") {
        assert!(t < 4.0, "no \"parameters saved\"");
        t += 0.01;
        b.run_to(t).unwrap();
    }
    b.run_to(t + 0.1).unwrap();
    assert_eq!(b.machine.board().flash.erases()[0].1, end);
    assert_eq!(failed_bursts(&b), failed_before, "IMU bursts failed around the erase's end");
}

/// The watchdog over a save at both ends of the LSI's range (DS9716: 17–47 kHz, as `cargo pil
/// serve --lsi-hz` sets it): a save that erases, at the maximum flash times, with the
/// watchdog's timeout at its shortest (47 kHz) and longest (17 kHz), saves and never resets the
/// board.
#[test]
fn a_save_over_the_link_at_an_lsi_of_17_and_47_khz_resets_nothing() {
    for hz in [LSI_MIN_HZ, LSI_MAX_HZ] {
        let mut b = boot_with_lsi(Some(flash_needing_an_erase()), FlashTiming::Maximum, Some(hz));
        b.run_to(0.5).unwrap();
        save(&mut b, 63.0);
        save(&mut b, 64.0);
        let t = b.scenario_s(b.machine.now());
        b.run_to(t + 0.2).unwrap();
        let resets = &b.machine.state().resets;
        assert!(resets.is_empty(), "LSI {hz} Hz: the board was reset: {resets:?}");
        assert!(b.machine.board().flash.erases().len() == 1, "LSI {hz} Hz: the first save did not erase");
        let (cfg, _) = saved_set(&b);
        let index = fcu_params::index_of(b"RATE_PIT_P").unwrap();
        assert_eq!(fcu_params::value(&cfg, index), Some(64.0), "LSI {hz} Hz");
    }
}
