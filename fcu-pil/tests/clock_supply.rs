//! The release image against the clock and supply faults of the F401's reference manual and
//! datasheet: a crystal that stops in flight (the clock security system), the LSI at either end
//! of its 17–47 kHz range (the watchdog's timeout), and VDD too low for a flash write (the PVD).
//! The ELF is `FCU_PIL_ELF` if set, else the release firmware built now.

use std::sync::OnceLock;

use fcu_pil::elf::Image;
use fcu_pil::firmware;
use fcu_pil::periph::iwdg::{LSI_MAX_HZ, LSI_MIN_HZ};
use fcu_pil::periph::time_from_s;
use fcu_pil::rig::{self, BoardSetup, EmulatedBoard};
use fcu_testkit::sim::{self, RunOptions};
use fcu_testkit::Profile;

fn elf() -> &'static std::path::Path {
    static ELF: OnceLock<std::path::PathBuf> = OnceLock::new();
    ELF.get_or_init(|| firmware::resolve_elf(None).unwrap_or_else(|e| panic!("{e}")))
}

fn image() -> Image {
    Image::load(elf()).unwrap_or_else(|e| panic!("{e}"))
}

/// Boots with `setup` and flies the hover scenario to `until_s`.
fn hover_to(setup: &BoardSetup, until_s: f64) -> (EmulatedBoard, sim::FlightLog) {
    let sc = fcu_testkit::sim::scenario::by_name("hover").expect("no hover scenario");
    let opts = RunOptions { seed: 1, duration_s: Some(until_s), ..RunOptions::default() };
    let mut b = EmulatedBoard::boot(image(), setup, rig::imu_at_rest(1)).unwrap_or_else(|e| panic!("boot: {e}"));
    let log = sim::run_with(&mut b, &sc, Profile::Default, &opts).unwrap_or_else(|e| panic!("{e}"));
    (b, log)
}

/// The HSE crystal stops in flight. The image arms the clock security system once it runs on
/// the crystal, so the chip switches to the HSI and takes the NMI, whose handler puts the four
/// compares at 0 at once and resets the board. Without it (the image before the fix) the core
/// stops with TIM4 holding the motors' duty until the watchdog's reset, 34 to 94 ms later.
#[test]
fn a_crystal_failure_in_flight_stops_the_motors_within_50_us_and_resets_the_board() {
    let (mut b, _log) = hover_to(&BoardSetup::default(), 8.0);
    let now = b.machine.now();
    assert!(b.machine.board_mut().motor_compares(now).iter().all(|&m| m > 0), "not flying at 8 s");
    assert!(b.machine.board().rcc.clocks().unwrap().sysclk_hz == 84_000_000);
    b.machine.board_mut().rcc.fail_hse(now);
    let limit = now + time_from_s(50e-6);
    b.machine.run_until(limit).unwrap_or_else(|e| panic!("{e}"));
    let later = b.machine.now();
    assert_eq!(b.machine.board_mut().motor_compares(later), [0; 4], "motors still running 50 µs after the crystal stopped");
    b.machine.run_until(now + time_from_s(0.005)).unwrap_or_else(|e| panic!("{e}"));
    let resets = &b.machine.state().resets;
    let (reset_at, why) = *resets.first().expect("the board did not reset after the crystal failed");
    assert_eq!(why, "software (SYSRESETREQ)");
    // The reset request is taken when the run loop next serves the board: within the millisecond.
    assert!(reset_at <= now + time_from_s(0.001), "reset {:.1} µs after the failure", (reset_at - now) as f64 / 336.0);
    assert!(!b.machine.board().rcc.nmi_line(), "CSSF left set");
}

/// The watchdog over the LSI's whole range (DS9716: 17–47 kHz). At 47 kHz its 200 counts of /8
/// last 34 ms: a flight of 10 s, fed every 1.25 ms, must never reset. At 17 kHz they last
/// 94.1 ms: a control task that hangs must still be reset within that (plus the tick it hung in).
#[test]
fn the_watchdog_holds_in_flight_at_47_khz_and_catches_a_stall_within_95_ms_at_17_khz() {
    let fast = BoardSetup { lsi_hz: Some(LSI_MAX_HZ), ..BoardSetup::default() };
    let (b, log) = hover_to(&fast, 10.0);
    assert!(b.machine.state().resets.is_empty(), "reset in flight at 47 kHz: {:?}", b.machine.state().resets);
    let timeout_s = b.machine.board().iwdg.timeout_s().expect("watchdog not started");
    assert!((timeout_s - 0.034).abs() < 0.0005, "{timeout_s}");
    assert!(log.rows.iter().filter(|r| r.t_s > 7.0).all(|r| r.motors.iter().all(|&m| m > 0)), "not flying at 47 kHz");

    let slow = BoardSetup { lsi_hz: Some(LSI_MIN_HZ), ..BoardSetup::default() };
    let (mut b, _log) = hover_to(&slow, 8.0);
    let timeout_s = b.machine.board().iwdg.timeout_s().expect("watchdog not started");
    assert!((timeout_s - 0.0941).abs() < 0.0005, "{timeout_s}");
    b.hang_control_task().unwrap();
    let stalled_at = b.machine.now();
    b.machine.run_until(stalled_at + time_from_s(0.2)).unwrap();
    let (reset_at, why) = *b.machine.state().resets.first().expect("no reset after a stall at 17 kHz");
    assert_eq!(why, "watchdog");
    let after_s = (reset_at - stalled_at) as f64 / 336e6;
    assert!(after_s <= 0.0941 + 1.0 / rig::TICK_HZ, "the watchdog reset {:.1} ms after the stall", after_s * 1e3);
}

/// The PVD watches VDD for the flash's x32 writes (RM0368 §3.5.1: 2.7 V at the least): the
/// image turns it on at level 6 at boot; PVDO, which the firmware reports to the ground link,
/// reads 0 on the board's 3.3 V and 1 once VDD sags to 2.6 V.
#[test]
fn the_image_watches_vdd_with_the_pvd_at_level_6() {
    let setup = BoardSetup { boot_timeout_s: Some(1.5), ..BoardSetup::default() };
    let mut b = EmulatedBoard::boot(image(), &setup, rig::imu_at_rest(1)).unwrap_or_else(|e| panic!("boot: {e}"));
    assert!(b.flying(), "{}", b.boot_stall());
    let pwr = &mut b.machine.board_mut().pwr;
    assert!(pwr.pvd_enabled(), "PVDE not set");
    assert_eq!(pwr.pvd_level(), 6);
    assert!(!pwr.pvdo(), "3.3 V reads as low");
    pwr.set_vdd_volts(2.6);
    assert!(pwr.pvdo());
    // The firmware does not act on it: it flies on (the ground link's save is what it gates).
    b.run_to(0.5).unwrap();
    assert!(b.machine.state().resets.is_empty());
}
