//! Instructions per control tick and per outer step of the real `fcu_core::FlightController`,
//! on a Cortex-M4 under QEMU (`docs/performance.md#budgets`).
//!
//! QEMU with `-icount shift=N` advances virtual time by exactly 2^N ns per executed instruction,
//! and SysTick (core clock) counts virtual time, so a SysTick difference is an instruction count
//! times a fixed factor. The factor is not assumed: it is calibrated at start-up with a loop of a
//! known number of instructions, so the bench gives instructions on any machine and shift.
//!
//! Each build measures one profile, compiled as it runs: the default (the budgets) as the firmware
//! builds fcu-core, without its `reference` feature; with `--features reference`, the reference.
//! Both fly the same deterministic recording: level IMU with noise, radio pulses on all
//! four channels once per 20 ms frame (as a receiver sends them), the LPS22HB's burst before every
//! outer step (a new sample on 75 of 160, a noisy slow climb), boot settling and calibration, the
//! arm gesture held then released, then armed flight with the throttle up and small stick motions. The statistics cover only the
//! armed flight window; the earlier phases are printed separately for information.
#![no_std]
#![no_main]

use core::hint::black_box;
use core::sync::atomic::{compiler_fence, Ordering};

use cortex_m::peripheral::{syst::SystClkSource, SYST};
use cortex_m_rt::entry;
use cortex_m_semihosting::{debug, hprintln};
use fcu_core::althold::{AltitudeSettings, Vertical, VerticalCommand, VerticalInput};
use fcu_core::altitude::{self, AltMode, AltitudeConfig, AltitudeEstimate, AltitudeEstimator, AltitudeStatus};
use fcu_core::baro::{self, BaroFault, BaroHealthConfig, BaroMonitor, BaroSample, RawBaro};
use fcu_core::flight::{FlightController, OuterJob, TickOutput};
use fcu_core::imu::RawImu;
use fcu_core::math::{Quat, Vec3};
use fcu_core::mixer::MixerConfig;
use fcu_core::rc::PulseBatch;
use fcu_core::rc::StickCounts;
use fcu_core::supervisor::FlightState;
use fcu_core::Config;

/// SysTick is a 24-bit down-counter.
const SYST_MASK: u32 = 0x00FF_FFFF;

/// The recording, in control ticks (800 per second in the default profile).
const TICKS: usize = 7000;
/// Boot settling (800 ticks) and the start-up calibration (800 samples) are over by tick 1601,
/// and the safe supervisor's boot settling (1600 ticks) too, so the gesture starts after both.
const ARM_START: usize = 1800;
/// The arm gesture is held 1000 ticks (the safe supervisor wants 800), then released.
const ARM_END: usize = 2800;
/// Throttle up: the motors run from here.
const FLY_START: usize = 3000;
/// The statistics start a quarter second after throttle-up, once the rate loop's integrators
/// and the D low-pass have left the throttle step behind: steady flight is what the budget is for.
const MEASURE_START: usize = 3200;
/// Every fifth tick hands out an outer job.
const OUTER_MAX: usize = TICKS / 5 + 1;

/// Radio widths, TIM2 counts of 0.25 µs (rc.rs: RcConfig::REFERENCE centres).
const AIL_CENTER: i32 = 5862;
const ELE_CENTER: i32 = 6151;
const RUD_CENTER: i32 = 6397;
/// At or below the throttle bottom (4450) the stick reads 0: "throttle low" and the gestures.
const THR_LOW: i32 = 4400;
/// 1550 counts above the bottom: mid throttle, far from both the cut and saturation.
const THR_FLY: i32 = 6000;
/// Beyond the gesture threshold (1200) with margin, still a valid pulse (3200..=8800).
const GESTURE_DEFLECTION: i32 = 1500;

/// Level board at rest: +1 g on sensor Z at 0.122 mg/LSB.
const ONE_G_LSB: i16 = 8197;

/// A tiny deterministic noise source (Numerical Recipes LCG): the same inputs on every run.
struct Lcg(u32);

impl Lcg {
    fn next(&mut self) -> u32 {
        self.0 = self.0.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
        self.0
    }

    /// Uniform in `-amp..=amp` (from the high bits, the LCG's good ones).
    fn noise(&mut self, amp: i16) -> i16 {
        let span = u32::from(amp.unsigned_abs()) * 2 + 1;
        ((self.next() >> 16) % span) as i16 - amp
    }
}

/// The IMU sample of one tick: level and still, a few LSB of noise and a small gyro bias, so the
/// stuck-sensor check never fires and the filters see realistic, changing values.
fn imu_sample(lcg: &mut Lcg) -> RawImu {
    let bias = [3, -2, 1];
    RawImu {
        accel: [lcg.noise(20), lcg.noise(20), ONE_G_LSB + lcg.noise(20)],
        gyro: [bias[0] + lcg.noise(4), bias[1] + lcg.noise(4), bias[2] + lcg.noise(4)],
    }
}

/// A triangle wave in `-amp..=amp` with the given period in ticks.
fn triangle(k: usize, period: usize, amp: i32) -> i32 {
    let p = period.max(2);
    let phase = (k % p) as i32;
    let half = (p / 2) as i32;
    let up = if phase < half { phase } else { 2 * half - phase };
    amp * (2 * up - half) / half.max(1)
}

/// The four widths of tick `k` (AIL, ELE, THR, RUD): centred with the throttle low, then the
/// arm gesture, then released, then flying with slow stick motions (the yaw one reaching past
/// the 600-count dead band, so the proportional yaw path runs too).
fn widths(k: usize) -> [u16; 4] {
    let w = if k < ARM_START {
        [AIL_CENTER, ELE_CENTER, THR_LOW, RUD_CENTER]
    } else if k < ARM_END {
        [AIL_CENTER - GESTURE_DEFLECTION, ELE_CENTER - GESTURE_DEFLECTION, THR_LOW, RUD_CENTER + GESTURE_DEFLECTION]
    } else if k < FLY_START {
        [AIL_CENTER, ELE_CENTER, THR_LOW, RUD_CENTER]
    } else {
        [
            AIL_CENTER + triangle(k, 1200, 150),
            ELE_CENTER + triangle(k, 1600, 150),
            THR_FLY + triangle(k, 2000, 100),
            RUD_CENTER + triangle(k, 2400, 700),
        ]
    };
    // Every width above is inside 3200..=8800 by construction; the clamp only keeps the cast
    // honest if a constant is ever edited.
    w.map(|v| v.clamp(3200, 8800) as u16)
}

/// What a 50 Hz PWM receiver delivers in tick `k`: each channel's pulse once per 20 ms frame
/// (16 ticks), rising one tick and falling the next, the four channels two ticks apart as a
/// receiver sends them one after the other. Most ticks therefore carry no pulse at all.
fn pulses(k: usize) -> PulseBatch {
    let w = widths(k);
    let phase = k % 16;
    let mut b = PulseBatch::default();
    for (c, ((width, out), seen)) in w.iter().zip(b.width_counts.iter_mut()).zip(b.edge_seen.iter_mut()).enumerate() {
        let rise = 2 * c;
        if phase == rise + 1 {
            *out = Some(*width);
        }
        *seen = phase == rise || phase == rise + 1;
    }
    b
}

/// Counts to instructions: the calibrated factor and the harness's own cost.
#[derive(Clone, Copy)]
struct Calibration {
    instr_per_count: f32,
    /// Instructions the measurement itself adds (CVR reads, an empty indirect call).
    overhead_instr: f32,
}

impl Calibration {
    fn instructions(&self, counts: u32) -> u32 {
        let i = counts as f32 * self.instr_per_count - self.overhead_instr;
        if i > 0.0 {
            (i + 0.5) as u32
        } else {
            0
        }
    }
}

/// SysTick counts spent in `f`. The fences keep the compiler from moving memory accesses across
/// the CVR reads; `f` is always reached through an opaque function pointer, so nothing of the
/// measured code can be scheduled outside the window either.
#[inline(always)]
fn counts<R>(f: impl FnOnce() -> R) -> (R, u32) {
    compiler_fence(Ordering::SeqCst);
    let t0 = SYST::get_current();
    compiler_fence(Ordering::SeqCst);
    let r = f();
    compiler_fence(Ordering::SeqCst);
    let t1 = SYST::get_current();
    compiler_fence(Ordering::SeqCst);
    // A down-counter: start minus end, modulo the 24-bit wrap (one wrap is ~100 M instructions
    // at shift=0, far more than any call here).
    (r, t0.wrapping_sub(t1) & SYST_MASK)
}

#[inline(never)]
fn empty() {}

/// `cortex_m::asm::delay(n)` runs exactly `n + 1` iterations of `subs; bne`: 2(n + 1)
/// instructions. Two lengths cancel the fixed cost; the difference is 2 (n2 − n1) instructions.
fn calibrate() -> Option<Calibration> {
    let delay: fn(u32) = black_box(cortex_m::asm::delay);
    let (n1, n2) = (100_000u32, 1_100_000u32);
    let ((), c1) = counts(|| delay(n1));
    let ((), c2) = counts(|| delay(n2));
    let dc = c2.checked_sub(c1).filter(|&d| d > 0)?;
    let instr_per_count = (2 * (n2 - n1)) as f32 / dc as f32;

    // The harness's cost: the same window around an empty indirect call, averaged because one
    // reading is below the counter's resolution at shift=0.
    let e: fn() = black_box(empty);
    let runs = 256u32;
    let mut total = 0u32;
    for _ in 0..runs {
        total = total.saturating_add(counts(e).1);
    }
    let overhead_instr = total as f32 / runs as f32 * instr_per_count;
    Some(Calibration { instr_per_count, overhead_instr })
}

/// Median and maximum of a slice (sorted in place).
fn median_max(v: &mut [u32]) -> (u32, u32) {
    v.sort_unstable();
    let median = v.get(v.len() / 2).copied().unwrap_or(0);
    let max = v.last().copied().unwrap_or(0);
    (median, max)
}

struct Stats {
    tick: (u32, u32),
    outer: (u32, u32),
    /// Median and maximum per tick of the phases outside the window (for information).
    boot: (u32, u32),
    disarmed: (u32, u32),
    outer_steps: usize,
    window_ticks: usize,
}

type TickFn = fn(&mut FlightController, RawImu, &PulseBatch) -> TickOutput;
type OuterFn = fn(&mut FlightController, &OuterJob);

/// Fly the recording with one profile; `Err` says what went wrong (motors not running, no outer
/// steps, not armed).
fn run_profile(cfg: Config, cal: &Calibration, needs_armed_state: bool) -> Result<Stats, &'static str> {
    let mut fc = FlightController::new(&cfg).map_err(|e| e.field())?;
    // Reached through opaque pointers: the measured code is the real, whole call, never
    // interleaved by the optimiser with this loop's input generation.
    let tick: TickFn = black_box(FlightController::tick);
    let run_outer: OuterFn = black_box(FlightController::run_outer);

    let mut lcg = Lcg(0x2545_F491);
    let mut tick_instr = [0u32; TICKS];
    let mut outer_instr = [0u32; OUTER_MAX];
    let mut n_outer = 0usize;
    let mut motors_off_in_window = 0usize;
    let mut not_armed_in_window = 0usize;

    for (k, slot) in tick_instr.iter_mut().enumerate() {
        let imu = imu_sample(&mut lcg);
        let pulses = pulses(k);
        let (out, c) = counts(|| tick(&mut fc, black_box(imu), black_box(&pulses)));
        *slot = cal.instructions(c);

        if k >= MEASURE_START {
            if out.compare.contains(&0) {
                motors_off_in_window += 1;
            }
            if needs_armed_state && fc.status().state != FlightState::Armed {
                not_armed_in_window += 1;
            }
        }
        if let Some(job) = out.outer_job {
            // The burst the firmware reads before the step (not measured: it is the bus's).
            fc.set_baro(Some(baro::decode_burst(&baro_burst(k / 5, &mut lcg))));
            let ((), c) = counts(|| run_outer(&mut fc, black_box(&job)));
            if k >= MEASURE_START {
                if let Some(o) = outer_instr.get_mut(n_outer) {
                    *o = cal.instructions(c);
                    n_outer += 1;
                }
            }
        }
    }

    if motors_off_in_window > 0 {
        return Err("a motor compare value was 0 in the measured window: the motors did not run");
    }
    if not_armed_in_window > 0 {
        return Err("the supervisor was not armed throughout the measured window");
    }
    let window_ticks = TICKS - MEASURE_START;
    if n_outer < window_ticks / 5 {
        return Err("fewer outer steps than one per five ticks in the measured window");
    }
    let phase = |from: usize, to: usize| -> (u32, u32) {
        let mut scratch = [0u32; TICKS];
        let n = to.saturating_sub(from).min(TICKS);
        match (scratch.get_mut(..n), tick_instr.get(from..to)) {
            (Some(dst), Some(src)) => {
                dst.copy_from_slice(src);
                median_max(dst)
            }
            _ => (0, 0),
        }
    };
    Ok(Stats {
        tick: phase(MEASURE_START, TICKS),
        outer: median_max(outer_instr.get_mut(..n_outer).unwrap_or(&mut [])),
        boot: phase(0, ARM_START),
        disarmed: phase(ARM_START, FLY_START),
        outer_steps: n_outer,
        window_ticks,
    })
}

/// The LPS22HB's burst before outer step `n`: a new sample on 75 of 160 steps (the part's ODR),
/// 1013.25 hPa less 0.1 m/s of climb (1.2 Pa/s), ±53 counts of noise (±1.3 Pa, the datasheet's
/// 0.75 Pa RMS), 25 °C.
fn baro_burst(n: usize, lcg: &mut Lcg) -> [u8; baro::registers::BURST_LEN] {
    let due = (n * 75) / 160 != ((n + 1) * 75) / 160;
    let counts_now = 4_150_272 - (n as i32 * 4096 * 12 / 1000 / 160) + i32::from(lcg.noise(53));
    let [_, h, l, xl] = counts_now.to_be_bytes();
    [u8::from(due), xl, l, h, 0xC4, 0x09]
}

/// Outer steps of the altitude estimator's recording: 10 s at 160 Hz.
const ALT_STEPS: usize = 1600;

type AltitudeFn = fn(&mut AltitudeEstimator, f32, Option<f32>, f32, bool) -> AltitudeEstimate;
type VerticalFn = fn(Quat, Vec3) -> f32;
type BaroCheckFn = fn(&mut BaroMonitor, &[u8; baro::registers::BURST_LEN]) -> Result<Option<BaroSample>, BaroFault>;
type VerticalStepFn = fn(&mut Vertical, Option<RawBaro>, Quat, Vec3, &VerticalInput) -> (VerticalCommand, AltitudeStatus);

/// What the outer step will do with the LPS22HB's burst: decode it and check it.
fn decode_and_check(monitor: &mut BaroMonitor, burst: &[u8; baro::registers::BURST_LEN]) -> Result<Option<BaroSample>, BaroFault> {
    monitor.check(Some(baro::decode_burst(burst)))
}

/// The outer step's altitude work apart (a breakdown of the outer step, which has it all): the
/// estimator's update with a barometer sample on 75 of 160 steps (the LPS22HB at 75 Hz) and
/// without on the others, the rotation of the accelerometer to the earth's vertical, decoding and
/// checking the burst, and the whole vertical half (`althold::Vertical::step`: check, estimate,
/// ground state and the altitude hold engaged in flight). The recording: a noisy barometer
/// (±1.3 Pa, the datasheet's 0.75 Pa RMS) over a slow climb, a slightly tilted, noisy
/// accelerometer, hover thrust. Medians and maxima of each kind.
struct AltitudeStats {
    baro_check: (u32, u32),
    with_baro: (u32, u32),
    without_baro: (u32, u32),
    vertical: (u32, u32),
    hold: (u32, u32),
}

fn run_altitude(cal: &Calibration) -> AltitudeStats {
    let update: AltitudeFn = black_box(AltitudeEstimator::update);
    let vertical: VerticalFn = black_box(altitude::vertical_accel_m_s2);
    let check: BaroCheckFn = black_box(decode_and_check);
    let mut monitor = BaroMonitor::new(BaroHealthConfig::DEFAULT);
    let mut check_instr = [0u32; ALT_STEPS];
    let mut est = AltitudeEstimator::new(AltitudeConfig::DEFAULT);
    let mut lcg = Lcg(0x1234_5678);
    let q = Quat::from_axis_angle(Vec3::new(0.6, 0.8, 0.0), 0.05);
    let mut with_baro = [0u32; ALT_STEPS];
    let mut without_baro = [0u32; ALT_STEPS];
    let mut vertical_instr = [0u32; ALT_STEPS];
    let (mut n_with, mut n_without) = (0usize, 0usize);
    for (k, v_slot) in vertical_instr.iter_mut().enumerate() {
        let accel_mg = Vec3::new(f32::from(lcg.noise(20)), f32::from(lcg.noise(20)), 1000.0 + f32::from(lcg.noise(20)));
        let (accel_up, c) = counts(|| vertical(black_box(q), black_box(accel_mg)));
        *v_slot = cal.instructions(c);
        let baro_due = (k * 75) / 160 != ((k + 1) * 75) / 160;
        // 1013.25 hPa, 0.1 m/s of climb (1.2 Pa/s), ±53 counts of noise (±1.3 Pa), 25 °C.
        let counts_now = 4_150_272 - (k as i32 * 4096 * 12 / 1000 / 160) + i32::from(lcg.noise(53));
        let [_, h, l, xl] = counts_now.to_be_bytes();
        let burst = [u8::from(baro_due), xl, l, h, 0xC4, 0x09];
        let (checked, c) = counts(|| check(&mut monitor, black_box(&burst)));
        if let Some(slot) = check_instr.get_mut(k) {
            *slot = cal.instructions(c);
        }
        let pressure = checked.ok().flatten().map(|s| s.pressure_pa);
        let (_, c) = counts(|| update(&mut est, black_box(accel_up), black_box(pressure), black_box(0.4), black_box(false)));
        // The first second sets the reference; the statistics are of the steady filter.
        if k >= 160 {
            let slot = if pressure.is_some() { with_baro.get_mut(n_with) } else { without_baro.get_mut(n_without) };
            if let Some(slot) = slot {
                *slot = cal.instructions(c);
            }
            if pressure.is_some() {
                n_with += 1;
            } else {
                n_without += 1;
            }
        }
    }
    // The vertical half with the hold engaged: airborne on a manual hover's throttle for a
    // second, then ALT_MODE 1 with the stick centred.
    let step: VerticalStepFn = black_box(Vertical::step);
    let manual = AltitudeSettings::DEFAULT;
    let mut v = Vertical::new(manual, 800.0, &MixerConfig::REFERENCE_DC);
    let mut hold_instr = [0u32; ALT_STEPS];
    let mut flown = StickCounts(540);
    for (k, slot) in hold_instr.iter_mut().enumerate() {
        if k == 160 {
            v.set_config(&AltitudeSettings { mode: AltMode::Hold, ..manual });
        }
        let input = VerticalInput {
            motors_enabled: true,
            failsafe: false,
            command: StickCounts(if k < 160 { 540 } else { 1800 }),
            flown,
            full_scale: StickCounts(1800),
            min_throttle: StickCounts(200),
        };
        let burst = baro::decode_burst(&baro_burst(k, &mut lcg));
        let accel_mg = Vec3::new(f32::from(lcg.noise(20)), f32::from(lcg.noise(20)), 1000.0 + f32::from(lcg.noise(20)));
        let ((cmd, _), c) = counts(|| step(&mut v, black_box(Some(burst)), black_box(q), black_box(accel_mg), black_box(&input)));
        flown = cmd.throttle.unwrap_or(input.command);
        *slot = cal.instructions(c);
    }
    AltitudeStats {
        hold: median_max(hold_instr.get_mut(320..).unwrap_or(&mut [])),
        baro_check: median_max(check_instr.get_mut(160..).unwrap_or(&mut [])),
        with_baro: median_max(with_baro.get_mut(..n_with).unwrap_or(&mut [])),
        without_baro: median_max(without_baro.get_mut(..n_without).unwrap_or(&mut [])),
        vertical: median_max(vertical_instr.get_mut(160..).unwrap_or(&mut [])),
    }
}

#[entry]
fn main() -> ! {
    let code = match bench() {
        Ok(()) => debug::EXIT_SUCCESS,
        Err(msg) => {
            hprintln!("bench-m4: error: {}", msg);
            debug::EXIT_FAILURE
        }
    };
    loop {
        debug::exit(code);
    }
}

fn bench() -> Result<(), &'static str> {
    let mut p = cortex_m::Peripherals::take().ok_or("core peripherals already taken")?;
    // Free-running, no interrupt: nothing but the measured code runs between two reads.
    p.SYST.disable_interrupt();
    p.SYST.set_clock_source(SystClkSource::Core);
    p.SYST.set_reload(SYST_MASK);
    p.SYST.clear_current();
    p.SYST.enable_counter();

    let cal = calibrate().ok_or("SysTick does not count (is QEMU run with -icount?)")?;
    hprintln!("bench-m4 built with opt-level {}", env!("BENCH_OPT_LEVEL"));
    hprintln!(
        "calibration: {:.4} instructions per SysTick count (delay loop of 2,000,000 instructions); harness overhead {:.1} instructions, subtracted",
        cal.instr_per_count,
        cal.overhead_instr
    );

    // One profile per build, each compiled as it runs: the default as the firmware builds
    // fcu-core (without its `reference` feature), the reference with `--features reference`.
    #[cfg(not(feature = "reference"))]
    let (name, cfg, needs_armed_state) = ("default", Config::default(), true);
    #[cfg(feature = "reference")]
    let (name, cfg, needs_armed_state) = ("reference", Config::reference(), false);
    let s = run_profile(cfg, &cal, needs_armed_state)?;

    print_profile(name, &s);
    print_altitude(&run_altitude(&cal));
    if cfg!(feature = "reference") {
        return Ok(());
    }
    // The budgets of `docs/performance.md#budgets` (default profile, medians of the armed window).
    // A run over budget fails: CI runs this binary, and a regression must stop it.
    let tick_ok = s.tick.0 <= TICK_BUDGET;
    let outer_ok = s.outer.0 <= OUTER_BUDGET;
    hprintln!(
        "budget (default, median): tick <= {} {}, outer step <= {} {}",
        TICK_BUDGET,
        if tick_ok { "ok" } else { "OVER" },
        OUTER_BUDGET,
        if outer_ok { "ok" } else { "OVER" }
    );
    if tick_ok && outer_ok {
        Ok(())
    } else {
        Err("over budget")
    }
}

/// The profile's table: the armed window's medians and maxima, and the ticks outside it.
fn print_profile(name: &str, s: &Stats) {
    hprintln!(
        "window: ticks {}..{} of {} (armed, throttle up since tick {}): {} ticks, {} outer steps",
        MEASURE_START,
        TICKS,
        TICKS,
        FLY_START,
        s.window_ticks,
        s.outer_steps
    );
    hprintln!("profile    tick median  tick max  outer median  outer max");
    hprintln!("{:<9} {:>12} {:>9} {:>13} {:>10}", name, s.tick.0, s.tick.1, s.outer.0, s.outer.1);
    hprintln!("outside the window (per tick, median / max):");
    hprintln!(
        "{:<9} boot+calibration (ticks 0..{}) {} / {}; disarmed, arming (ticks {}..{}) {} / {}",
        name,
        ARM_START,
        s.boot.0,
        s.boot.1,
        ARM_START,
        FLY_START,
        s.disarmed.0,
        s.disarmed.1
    );
}

/// The altitude half of the outer step, part by part.
fn print_altitude(alt: &AltitudeStats) {
    hprintln!(
        "altitude in the outer step, a breakdown (median / max): the vertical half with the hold engaged {} / {}; of it the estimator's update with a barometer sample {} / {}, without {} / {}; vertical acceleration {} / {}; barometer burst decoded and checked {} / {}",
        alt.hold.0,
        alt.hold.1,
        alt.with_baro.0,
        alt.with_baro.1,
        alt.without_baro.0,
        alt.without_baro.1,
        alt.vertical.0,
        alt.vertical.1,
        alt.baro_check.0,
        alt.baro_check.1
    );
}

/// Median instructions per control tick allowed in the default profile.
const TICK_BUDGET: u32 = 600;
/// Median instructions per outer step allowed in the default profile.
const OUTER_BUDGET: u32 = 5000;

#[panic_handler]
fn panic(_: &core::panic::PanicInfo) -> ! {
    // Nothing here panics by design; if something does, fail the run rather than hang QEMU.
    loop {
        debug::exit(debug::EXIT_FAILURE);
    }
}
