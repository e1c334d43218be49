//! The safety layer through the whole pipeline, driven the way the firmware drives it: raw
//! LSM6DSL words and radio capture edges on the 15-bit TIM2 counter, one control tick at a time
//! (from the testkit's one PWM receiver and one level IMU, `fcu_testkit::safety`). Each test is
//! a rule of `docs/safety.md`; several show the reference's accident beside ours.

use fcu_core::flight::TickOutput;
use fcu_core::rc::{CaptureEdge, EdgeDecoder, StickCounts, CAPTURE_WRAP};
use fcu_core::supervisor::FlightState;
use fcu_core::{Config, FlightController};
use fcu_testkit::harness;
use fcu_testkit::safety::{ChannelLayout, LevelImu, PwmReceiver, RadioFrame, COUNTS_PER_FRAME, COUNTS_PER_TICK};

/// TIM2 counts (0.25 µs) per control tick at 800 Hz, and per 50 Hz radio frame.
const TICK_COUNTS: u64 = COUNTS_PER_TICK;
const FRAME_COUNTS: u64 = COUNTS_PER_FRAME;
const TICKS_PER_S: u32 = 800;

/// Stick positions as pulse widths in µs: [AIL, ELE, THR, RUD].
const NEUTRAL: [f64; 4] = [1465.5, 1537.75, 1000.0, 1599.25];
const ARM: [f64; 4] = [1100.0, 1100.0, 1000.0, 1950.0];
const DISARM: [f64; 4] = [1465.5, 1537.75, 1000.0, 1100.0];
const FLY: [f64; 4] = [1465.5, 1537.75, 1600.0, 1599.25];

/// A board on the bench: the testkit's level IMU and PWM receiver (its first frame at the
/// first tick's start, channel `k` rising `k × channel_spacing_counts` into each frame), the
/// core. The test changes the fields between ticks.
struct Bench {
    fc: FlightController,
    decoder: EdgeDecoder,
    radio: PwmReceiver,
    imu: LevelImu,
    sticks_us: [f64; 4],
    sending: bool,
    /// Delay between the channels' pulses in a frame (0: all rise together, as many receivers).
    channel_spacing_counts: u64,
    /// Edges for the next tick only: (channel, counts after the tick's start, level).
    extra_edges: Vec<(usize, u64, bool)>,
    stuck_imu: bool,
    last: Option<TickOutput>,
    /// Control ticks run, and the tick each channel's last falling edge was fed in.
    ticks: u32,
    last_fall_tick: [u32; 4],
    /// TIM2 counts at the start of the next tick.
    now_counts: u64,
}

impl Bench {
    fn new(cfg: Config) -> Bench {
        let fc = FlightController::new(&cfg).unwrap();
        let decoder = fc.edge_decoder();
        let spacing = 10_000;
        let mut imu = LevelImu::new(12_345);
        imu.noise_lsb = 1;
        Bench {
            fc,
            decoder,
            radio: PwmReceiver::with_layout(0, ChannelLayout::Spaced { offset_counts: spacing }, 1),
            imu,
            sticks_us: NEUTRAL,
            sending: true,
            channel_spacing_counts: spacing,
            extra_edges: Vec::new(),
            stuck_imu: false,
            last: None,
            ticks: 0,
            last_fall_tick: [0; 4],
            now_counts: 0,
        }
    }

    fn tick(&mut self) -> TickOutput {
        self.ticks += 1;
        self.radio.set_layout(ChannelLayout::Spaced { offset_counts: self.channel_spacing_counts });
        for (channel, offset, level) in self.extra_edges.drain(..) {
            self.radio.inject(channel, offset, level);
        }
        let frame =
            if self.sending { RadioFrame { width_counts: self.sticks_us.map(|w| (w * 4.0) as u16), link: true } } else { RadioFrame::OFF };
        let mut edges: Vec<CaptureEdge> = Vec::new();
        self.radio.tick(&frame, 0, &mut edges);
        for e in edges.iter().filter(|e| !e.level_high) {
            if let Some(t) = self.last_fall_tick.get_mut(e.channel) {
                *t = self.ticks;
            }
        }
        self.now_counts = self.radio.now_counts();
        self.imu.stuck = self.stuck_imu;
        let imu = self.imu.sample();
        let out = harness::tick(&mut self.fc, &mut self.decoder, imu, edges).out;
        self.last = Some(out);
        out
    }

    fn run(&mut self, sticks: [f64; 4], ticks: u32) -> TickOutput {
        self.sticks_us = sticks;
        let mut out = self.tick();
        for _ in 1..ticks {
            out = self.tick();
        }
        out
    }

    fn state(&self) -> FlightState {
        self.fc.status().state
    }

    /// Boot (settle + calibrate + 2 s boot blocker) with the sticks neutral.
    fn boot(&mut self) {
        self.run(NEUTRAL, 5 * TICKS_PER_S / 2);
        assert_eq!(self.state(), FlightState::Disarmed, "{:?}", self.fc.status().blockers);
    }

    fn arm(&mut self) {
        self.run(ARM, 5 * TICKS_PER_S / 4);
        self.run(NEUTRAL, 40);
        assert_eq!(self.state(), FlightState::Armed, "{:?}", self.fc.status().blockers);
    }
}

fn motors_off(out: &TickOutput) -> bool {
    out.compare == [0; 4]
}

#[test]
fn arming_takes_the_stick_gesture_and_nothing_else() {
    let mut b = Bench::new(Config::default());
    b.boot();
    assert!(motors_off(&b.run(FLY, TICKS_PER_S)), "throttle up while disarmed");
    b.run(NEUTRAL, 40);
    let out = b.run(ARM, 5 * TICKS_PER_S / 4);
    assert_eq!(b.state(), FlightState::Arming);
    assert!(motors_off(&out));
    b.run(NEUTRAL, 40);
    assert_eq!(b.state(), FlightState::Armed);
    let out = b.run(FLY, 100);
    assert!(out.compare.iter().all(|&c| c > 600), "{:?}", out.compare);
}

#[test]
fn disarm_gesture_stops_the_motors() {
    let mut b = Bench::new(Config::default());
    b.boot();
    b.arm();
    b.run(FLY, 200);
    // The rudder pulse of the next 20 ms frame starts the hold.
    b.run(DISARM, TICKS_PER_S - 20);
    assert_eq!(b.state(), FlightState::Armed, "released before a full second");
    b.run(DISARM, 40);
    assert_eq!(b.state(), FlightState::Disarmed);
    assert!(motors_off(&b.run(FLY, 100)));
}

#[test]
fn holding_the_arm_gesture_while_the_link_comes_up_does_not_arm() {
    let mut b = Bench::new(Config::default());
    b.sending = false;
    b.run(ARM, 3 * TICKS_PER_S);
    b.sending = true;
    b.run(ARM, 3 * TICKS_PER_S);
    b.run(NEUTRAL, 100);
    assert_eq!(b.state(), FlightState::Disarmed);
    assert!(motors_off(&b.run(FLY, 400)));
}

#[test]
fn reference_arms_by_accident_when_the_link_comes_back_with_the_rudder_held() {
    // After a link loss the reference clears its capture state; if the link comes back
    // in the middle of the pulses, the first edge of each channel is a falling one and reports
    // the reset width 0: aileron −5862, elevator −6151, throttle 0 for one update each. With
    // the rudder held left (its stick keeps the last value) that is the arm gesture, and the
    // reference latches "armed" although the pilot never made it.
    let rudder_left = [1465.5, 1537.75, 1600.0, 1950.0];
    let fly_after = |cfg: Config| -> Bench {
        let mut b = Bench::new(cfg);
        b.channel_spacing_counts = 0;
        b.run(rudder_left, 5 * TICKS_PER_S / 2);
        b.sending = false;
        // Lose the link for 0.2 s (ten frames: the next one starts with the next tick), and
        // come back just after that frame's pulses started: its rising edges are missed, the
        // first edge of each channel is its falling one.
        b.run(rudder_left, 160);
        b.extra_edges = rudder_left.iter().enumerate().map(|(ch, w)| (ch, (w * 4.0) as u64, false)).collect();
        b.run(rudder_left, 1);
        b.sending = true;
        b.run(rudder_left, 39);
        b.run(FLY, 400);
        b
    };
    let reference = fly_after(Config::reference());
    assert_eq!(reference.state(), FlightState::Armed);
    assert!(!motors_off(reference.last.as_ref().unwrap()));

    let ours = fly_after(Config::default());
    assert_eq!(ours.state(), FlightState::Disarmed);
    assert!(motors_off(ours.last.as_ref().unwrap()));
}

#[test]
fn a_single_glitch_pulse_does_not_change_any_stick() {
    let mut b = Bench::new(Config::default());
    b.boot();
    b.arm();
    b.run(FLY, 400);
    let before = b.fc.status().sticks;
    // A 20 µs spike on the throttle wire, a lone falling edge on aileron, and a capture with
    // fall == rise on rudder (a full-wrap "width" of 8.192 ms).
    b.extra_edges = vec![(2, 100, true), (2, 180, false), (0, 300, false), (3, 400, true), (3, 400 + 32_768, false)];
    b.tick();
    for _ in 0..40 {
        b.tick();
        assert_eq!(b.fc.status().sticks, before);
    }
    assert_eq!(b.state(), FlightState::Armed);
}

#[test]
fn reference_turns_a_full_wrap_glitch_into_95_percent_throttle() {
    // The reference has no pulse check: fall == rise gives a width of 32768 counts; gTHR ≈ 28000 and the clamp writes 1900.
    let mut b = Bench::new(Config::reference());
    b.run(NEUTRAL, 2 * TICKS_PER_S);
    b.run(ARM, 20);
    b.run(FLY, 200);
    // The throttle pulse of the next frame rises at frame + 20000 counts.
    let next_frame = (b.now_counts / FRAME_COUNTS + 1) * FRAME_COUNTS;
    let ticks_to_frame = ((next_frame - b.now_counts) / TICK_COUNTS) as u32;
    b.run(FLY, ticks_to_frame);
    b.sending = false;
    b.extra_edges = vec![(2, 10, true), (2, 10 + 32_768, false)];
    let out = b.tick();
    assert_eq!(i32::from(b.fc.status().sticks.thr), 32_768 - 4450);
    assert!(out.compare.contains(&1900), "{:?}", out.compare);
}

#[test]
fn a_receiver_that_stops_sending_always_ends_with_the_motors_off() {
    let mut b = Bench::new(Config::default());
    b.boot();
    b.arm();
    b.run(FLY, 400);
    b.sending = false;
    let mut stage1 = false;
    let mut off_at = None;
    for t in 0..2 * TICKS_PER_S {
        let out = b.tick();
        stage1 |= b.state() == FlightState::FailsafeLevel;
        if off_at.is_none() && motors_off(&out) {
            off_at = Some(t);
        }
        if let Some(t_off) = off_at {
            assert!(motors_off(&out), "motors restarted at tick {t} after stopping at {t_off}");
        }
    }
    assert!(stage1, "stage 1 (level, hold throttle) came first");
    let off_at = off_at.expect("motors never stopped");
    // 1.0 s after the last pulse: the last pulse is up to one 20 ms frame before the cut.
    assert!((TICKS_PER_S - 16..=TICKS_PER_S).contains(&off_at), "stopped after {off_at} ticks");
    assert_eq!(b.state(), FlightState::FailsafeOff);
    // The link coming back with the throttle up does not restart anything.
    b.sending = true;
    assert!(motors_off(&b.run(FLY, 2 * TICKS_PER_S)));
    assert_eq!(b.state(), FlightState::Disarmed);
}

#[test]
fn stage_1_levels_and_never_raises_the_throttle() {
    let mut b = Bench::new(Config::default());
    b.boot();
    b.arm();
    // The sticks the next outer job flies with (what the failsafe puts in force).
    let job_sticks = |b: &mut Bench| loop {
        if let Some(job) = b.tick().outer_job {
            break job.sticks;
        }
    };
    b.run([1300.0, 1700.0, 1600.0, 1800.0], 400);
    let before = b.fc.status();
    let flown = job_sticks(&mut b);
    b.sending = false;
    b.run(FLY, 100);
    let st = b.fc.status();
    assert_eq!(st.state, FlightState::FailsafeLevel);
    assert_eq!(st.target_rad[0], 0.0);
    assert_eq!(st.target_rad[1], 0.0);
    assert!(before.target_rad[0] != 0.0 && before.target_rad[1] != 0.0);
    let held = job_sticks(&mut b);
    assert_eq!((held.ail, held.ele, held.rud), (StickCounts::ZERO, StickCounts::ZERO, StickCounts::ZERO), "{held:?}");
    assert!(held.thr <= flown.thr && held.thr > StickCounts::ZERO, "{held:?} vs {flown:?}");
}

#[test]
fn a_short_link_loss_hands_control_back_to_the_sticks() {
    let mut b = Bench::new(Config::default());
    b.boot();
    b.arm();
    b.run(FLY, 400);
    b.sending = false;
    b.run(FLY, 300);
    assert_eq!(b.state(), FlightState::FailsafeLevel);
    b.sending = true;
    // Control returns once the link has been good for the recovery time (1.0 s).
    b.run(FLY, 900);
    assert_eq!(b.state(), FlightState::Armed);
    assert!(!motors_off(b.last.as_ref().unwrap()));
}

#[test]
fn failsafe_pulses_inside_the_valid_window_are_a_radio_setting() {
    // A receiver set to "hold" or to send its own failsafe pulses keeps the link good: the core
    // cannot tell them from a pilot. Configure the receiver's failsafe as "no pulses" (then the
    // rule above applies) or as throttle low: then the motors stop at once and the 5 s auto
    // disarm follows, as this test shows.
    let mut b = Bench::new(Config::default());
    b.boot();
    b.arm();
    b.run(FLY, 400);
    let out = b.run(NEUTRAL, 10);
    assert!(motors_off(&out));
    assert_eq!(b.state(), FlightState::Armed);
    b.run(NEUTRAL, 5 * TICKS_PER_S);
    assert_eq!(b.state(), FlightState::Disarmed);
}

#[test]
fn a_stuck_imu_in_flight_stops_the_motors_and_latches_a_fault() {
    let mut b = Bench::new(Config::default());
    b.boot();
    b.arm();
    b.run(FLY, 400);
    b.stuck_imu = true;
    let out = b.run(FLY, 100);
    assert_eq!(b.state(), FlightState::Fault);
    assert!(motors_off(&out));
    b.stuck_imu = false;
    b.run(NEUTRAL, 100);
    b.arm_attempt_expect_refused();
}

#[test]
fn a_single_failed_sensor_read_is_bridged_but_a_dead_bus_stops_the_motors() {
    let mut b = Bench::new(Config::default());
    b.boot();
    b.arm();
    b.run(FLY, 400);
    let pulses = b.decoder.take();
    for _ in 0..fcu_core::imu::MAX_MISSING_SAMPLES {
        let out = b.fc.tick_without_sample(&pulses);
        assert!(!motors_off(&out));
    }
    assert_eq!(b.state(), FlightState::Armed);
    b.run(FLY, 100);
    for _ in 0..=fcu_core::imu::MAX_MISSING_SAMPLES {
        b.fc.tick_without_sample(&pulses);
    }
    let out = b.run(FLY, 1);
    assert_eq!(b.state(), FlightState::Fault);
    assert_eq!(b.fc.status().fault, Some(fcu_core::imu::SensorFault::NoData));
    assert!(motors_off(&out));
}

impl Bench {
    fn arm_attempt_expect_refused(&mut self) {
        self.run(ARM, 5 * TICKS_PER_S / 4);
        self.run(NEUTRAL, 40);
        assert_ne!(self.state(), FlightState::Armed);
        assert!(motors_off(&self.run(FLY, 100)));
    }
}

#[test]
fn motors_stay_off_until_the_boot_calibration_passed() {
    let mut b = Bench::new(Config::default());
    for _ in 0..2 * TICKS_PER_S {
        b.sticks_us = ARM;
        let out = b.tick();
        assert!(motors_off(&out));
        assert_ne!(b.state(), FlightState::Armed);
    }
}

/// Runs `ticks` ticks and returns the first tick (counted from 1) in `state`, if any.
fn first_tick_in(b: &mut Bench, ticks: u32, state: FlightState) -> Option<u32> {
    let mut at = None;
    for t in 1..=ticks {
        b.tick();
        if at.is_none() && b.state() == state {
            at = Some(t);
        }
    }
    at
}

#[test]
fn stage_2_comes_one_second_after_the_last_pulse_of_the_first_channel_to_fall_silent() {
    // The channels pulse 2.5 ms apart in each frame, so the aileron's is the stalest pulse when
    // the receiver stops: stage 1 exactly 100 ms after it, stage 2 exactly 1.0 s after it.
    let mut b = Bench::new(Config::default());
    b.boot();
    b.arm();
    b.run(FLY, 400);
    b.sending = false;
    let stopped_at = b.ticks;
    let stage1 = first_tick_in(&mut b, 200, FlightState::FailsafeLevel).expect("stage 1");
    let stage2 = first_tick_in(&mut b, 1000, FlightState::FailsafeOff).expect("stage 2") + stopped_at + 200;
    let pulse = b.last_fall_tick[0];
    assert!(b.last_fall_tick[1..].iter().all(|&t| t >= pulse));
    assert_eq!(stopped_at + stage1 - pulse, TICKS_PER_S / 10, "stage 1");
    assert_eq!(stage2 - pulse, TICKS_PER_S, "stage 2");
}

/// Armed and flying at `thr_us`, then the receiver sends for `on_ms` and stops for `off_ms`,
/// over and over (the first gap first), for `seconds`. Returns the log of (tick, state,
/// compare) from the first gap on, and whether control was ever handed back after stage 1.
fn flap(off_ms: u32, on_ms: u32, thr_us: f64, seconds: u32) -> (Vec<(u32, FlightState, [u16; 4])>, bool) {
    let mut b = Bench::new(Config::default());
    b.boot();
    b.arm();
    let fly = [NEUTRAL[0], NEUTRAL[1], thr_us, NEUTRAL[3]];
    b.run(fly, 400);
    let (off, on) = (off_ms * TICKS_PER_S / 1000, on_ms * TICKS_PER_S / 1000);
    let mut log = Vec::new();
    for t in 0..seconds * TICKS_PER_S {
        b.sending = t % (off + on) >= off;
        let out = b.tick();
        log.push((t, b.state(), out.compare));
    }
    let stage1 = log.iter().position(|&(_, s, _)| s == FlightState::FailsafeLevel).unwrap_or(log.len());
    let handed_back = log[stage1..].iter().any(|&(_, s, _)| s == FlightState::Armed);
    (log, handed_back)
}

#[test]
fn a_flapping_link_cannot_keep_the_motors_running() {
    // Off 900 ms, on 40 ms (two frames): handing control back on each burst would keep the
    // motors running throughout.
    let (log, handed_back) = flap(900, 40, 1600.0, 20);
    assert!(!handed_back, "control handed back to a flapping link");
    let stage2 = log.iter().position(|&(_, s, _)| s == FlightState::FailsafeOff).expect("never reached stage 2");
    assert!(stage2 <= 3 * TICKS_PER_S as usize, "stage 2 after {stage2} ticks");
    assert!(log[stage2..].iter().all(|&(_, s, c)| c == [0; 4] && !s.motors_may_run()), "motors restarted after stage 2");
}

#[test]
fn a_link_that_delivers_less_than_half_of_its_frames_ends_in_stage_2_within_3_s() {
    // Gaps longer than the 100 ms channel timeout, bursts no longer than the gaps: each gap
    // counts from the last pulse before it, so the 1.0 s of lost time comes within 3 s of the
    // first loss, and the bursts (never 1.0 s of good link) never hand control back.
    for (off, on) in [(110, 100), (120, 100), (150, 40), (200, 180), (300, 60), (500, 450), (900, 40)] {
        let (log, handed_back) = flap(off, on, 1600.0, 6);
        assert!(!handed_back, "off {off} / on {on} ms: control handed back");
        let stage2 = log.iter().position(|&(_, s, _)| s == FlightState::FailsafeOff);
        let stage2 = stage2.unwrap_or_else(|| panic!("off {off} / on {on} ms: never reached stage 2"));
        eprintln!("off {off} / on {on}: stage 2 after {:.3} s", stage2 as f64 / 800.0);
        assert!(stage2 <= 3 * TICKS_PER_S as usize, "off {off} / on {on} ms: stage 2 after {stage2} ticks");
        assert!(log[stage2..].iter().all(|&(_, s, c)| c == [0; 4] && !s.motors_may_run()), "off {off} / on {on} ms: motors restarted");
    }
}

#[test]
fn a_single_short_loss_levels_holds_and_recovers_after_the_recovery_time() {
    // The link-short case: 0.5 s without pulses, then a good link. Stage 1 all along, and the
    // sticks back 1.0 s after the link.
    let mut b = Bench::new(Config::default());
    b.boot();
    b.arm();
    b.run(FLY, 400);
    b.sending = false;
    b.run(FLY, TICKS_PER_S / 2);
    assert_eq!(b.state(), FlightState::FailsafeLevel);
    b.sending = true;
    let back = first_tick_in(&mut b, 2 * TICKS_PER_S, FlightState::Armed).expect("control never came back");
    // Counted from the end of the gap: the link is good once the first frame after it has
    // reached all four channels (up to 20 ms to the frame, 9 ms to its last pulse).
    assert!((TICKS_PER_S..=TICKS_PER_S + 24).contains(&back), "control back {back} ticks after the gap");
}

#[test]
fn after_stage_2_only_a_full_arming_starts_the_motors() {
    let mut b = Bench::new(Config::default());
    b.boot();
    b.arm();
    b.run(FLY, 400);
    b.sending = false;
    b.run(FLY, 2 * TICKS_PER_S);
    assert_eq!(b.state(), FlightState::FailsafeOff);
    // Back with the throttle up, then down, then flapping: nothing starts.
    b.sending = true;
    assert!(motors_off(&b.run(FLY, TICKS_PER_S)));
    assert!(motors_off(&b.run(NEUTRAL, TICKS_PER_S)));
    for _ in 0..5 {
        b.sending = false;
        assert!(motors_off(&b.run(FLY, 200)));
        b.sending = true;
        assert!(motors_off(&b.run(FLY, 100)));
    }
    assert_eq!(b.state(), FlightState::Disarmed);
    b.run(NEUTRAL, 100);
    b.arm();
    assert!(!motors_off(&b.run(FLY, 100)));
}

/// The arm gesture's deflection with the throttle nudged off zero but still low (1140 µs: 110
/// counts above the bottom, MIN_THR is 200).
const ARM_NUDGED: [f64; 4] = [1100.0, 1100.0, 1140.0, 1950.0];

#[test]
fn a_throttle_nudge_with_the_sticks_deflected_does_not_arm() {
    let mut b = Bench::new(Config::default());
    b.boot();
    b.run(ARM, 5 * TICKS_PER_S / 4);
    // After a full hold only the throttle moves: no longer the arm gesture, but the aileron,
    // elevator and rudder are still deflected. Not armed, motors off.
    let out = b.run(ARM_NUDGED, TICKS_PER_S);
    assert_eq!(b.fc.status().sticks.thr, StickCounts(110));
    assert_eq!(b.state(), FlightState::Arming);
    assert!(motors_off(&out));
    // The rudder alone still over: waiting.
    b.run([NEUTRAL[0], NEUTRAL[1], 1140.0, 1950.0], 100);
    assert_eq!(b.state(), FlightState::Arming);
    // Every stick back in a safe place: armed.
    b.run([NEUTRAL[0], NEUTRAL[1], 1140.0, NEUTRAL[3]], 40);
    assert_eq!(b.state(), FlightState::Armed);
}

#[test]
fn the_yaw_target_does_not_move_while_the_throttle_is_low() {
    // Armed on the ground, throttle low but off zero, rudder full over for 2 s: the heading
    // target stays 0 in every tick and every outer step (the reference resets it the same way).
    for cfg in [Config::default(), Config::reference()] {
        let mut b = Bench::new(cfg);
        b.boot();
        if cfg.supervisor == fcu_core::supervisor::SupervisorConfig::Reference {
            b.run(ARM, 20);
            b.run(NEUTRAL, 40);
        } else {
            b.arm();
        }
        assert_eq!(b.state(), FlightState::Armed);
        for sticks in [[NEUTRAL[0], NEUTRAL[1], 1140.0, 2000.0], [NEUTRAL[0], NEUTRAL[1], 1140.0, 1100.0], NEUTRAL] {
            b.sticks_us = sticks;
            for _ in 0..TICKS_PER_S {
                let out = b.tick();
                assert_eq!(b.fc.status().target_rad[2], 0.0, "{sticks:?}");
                assert!(motors_off(&out));
            }
        }
        // With the throttle up the rudder turns the target again.
        b.run([NEUTRAL[0], NEUTRAL[1], 1600.0, 2000.0], 200);
        assert!(b.fc.status().target_rad[2] > 0.1);
    }
}

#[test]
fn pulses_longer_than_the_capture_wrap_never_make_a_link() {
    // 8.192 ms longer than the arm gesture's pulses: on the 15-bit capture clock their counts
    // read as the gesture. The reference arms on them; the default profile sees no pulse at all.
    let wrap_us = f64::from(CAPTURE_WRAP) / 4.0;
    let aliased_arm = ARM.map(|w| w + wrap_us);
    let aliased_fly = FLY.map(|w| w + wrap_us);
    let mut reference = Bench::new(Config::reference());
    reference.run(aliased_arm, 2 * TICKS_PER_S);
    assert_eq!(reference.state(), FlightState::Armed, "the reference reads the aliased widths");
    assert!(!motors_off(&reference.run(aliased_fly, 100)));

    let mut ours = Bench::new(Config::default());
    ours.run(NEUTRAL, 5 * TICKS_PER_S / 2);
    assert!(ours.fc.status().link);
    for _ in 0..3 * TICKS_PER_S {
        ours.sticks_us = aliased_arm;
        let out = ours.tick();
        assert!(motors_off(&out));
    }
    assert!(!ours.fc.status().link, "a link from pulses past the capture wrap");
    ours.run(NEUTRAL, 40);
    assert_eq!(ours.state(), FlightState::Disarmed);
    assert!(motors_off(&ours.run(aliased_fly, TICKS_PER_S)));
}
