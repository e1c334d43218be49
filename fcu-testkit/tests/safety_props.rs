//! Property tests of the safety layer (`docs/safety.md`) with the invariant monitor of
//! `fcu_testkit::safety`: arbitrary stick timelines, raw capture-edge streams and sensor
//! words through the whole default `FlightController`, and arbitrary input sequences through
//! the bare `Supervisor`. Every case starts from a controller that has already booted (or
//! armed), cloned, with the monitor that watched it boot.

use std::sync::OnceLock;

use fcu_core::config::Config;
use fcu_core::flight::{Status, TickOutput};
use fcu_core::imu::{RawImu, SensorFault};
use fcu_core::rc::{CaptureEdge, Gesture, PulseBatch, RcConfig, StickCounts, Sticks};
use fcu_core::supervisor::{Decision, FlightState, Inputs, SafetyConfig, Supervisor};
use fcu_testkit::safety::*;
use fcu_testkit::sim::rng::Rng;
use proptest::prelude::*;
use proptest::strategy::ValueTree;

// ---------------------------------------------------------------------------------------
// Starting points
// ---------------------------------------------------------------------------------------

/// Which pre-run controller a case starts from.
#[derive(Clone, Copy, Debug)]
enum Start {
    /// Default profile, booted, calibrated, disarmed, neutral sticks on a good link.
    Booted,
    /// Default profile, armed and flying level at mid throttle.
    Flying,
    /// ESC build (idle compare 850), booted.
    EscBooted,
    /// ESC build, armed and flying.
    EscFlying,
}

fn make_start(cfg: Config, fly: bool) -> Rig {
    let mut rig = Rig::booted(cfg, 7).unwrap_or_else(|e| panic!("{e}"));
    if fly {
        rig.arm().unwrap_or_else(|e| panic!("{e}"));
        rig.sticks(sticks::FLY, 400).unwrap_or_else(|v| panic!("{v}"));
        assert_eq!(rig.state(), FlightState::Armed);
        assert!(rig.fc.status().compare.iter().all(|&c| c > rig.fc.config().mixer.off_compare()));
    } else {
        assert_eq!(rig.state(), FlightState::Disarmed);
    }
    rig
}

fn start(which: Start) -> Rig {
    static RIGS: OnceLock<[Rig; 4]> = OnceLock::new();
    let rigs = RIGS.get_or_init(|| {
        [
            make_start(Config::default(), false),
            make_start(Config::default(), true),
            make_start(Config::esc(), false),
            make_start(Config::esc(), true),
        ]
    });
    rigs[which as usize].clone()
}

fn start_strategy() -> impl Strategy<Value = Start> {
    prop_oneof![4 => Just(Start::Booted), 4 => Just(Start::Flying), 1 => Just(Start::EscBooted), 1 => Just(Start::EscFlying)]
}

// ---------------------------------------------------------------------------------------
// (a) Stick timelines
// ---------------------------------------------------------------------------------------

/// What the transmitter does during a segment.
#[derive(Clone, Copy, Debug)]
enum Pattern {
    Sticks(Sticks),
    /// Raw widths per channel, counts (0: no pulse; anything outside 3200..=8800 is rejected).
    Widths([u16; 4]),
    /// Only the channels in the mask send (the others stay low).
    Partial(Sticks, u8),
    Off,
}

#[derive(Clone, Copy, Debug)]
struct Segment {
    pattern: Pattern,
    ticks: u32,
    glitches: u8,
}

impl Segment {
    fn frame(&self, rc: &RcConfig) -> RadioFrame {
        match self.pattern {
            Pattern::Sticks(s) => RadioFrame::from_sticks(rc, s),
            Pattern::Widths(w) => RadioFrame { width_counts: w, link: true },
            Pattern::Partial(s, mask) => {
                let mut f = RadioFrame::from_sticks(rc, s);
                for (ch, w) in f.width_counts.iter_mut().enumerate() {
                    if mask & (1 << ch) == 0 {
                        *w = 0;
                    }
                }
                f
            }
            Pattern::Off => RadioFrame::OFF,
        }
    }
}

fn arm_sticks() -> impl Strategy<Value = Sticks> {
    prop_oneof![
        3 => Just(sticks::ARM),
        1 => (-1800i16..=-1201, -1800i16..=-1201, 1201i16..=1800).prop_map(|(ail, ele, rud)| Sticks::new(ail, ele, 0, rud)),
    ]
}

fn disarm_sticks() -> impl Strategy<Value = Sticks> {
    prop_oneof![
        2 => Just(sticks::DISARM),
        1 => (-300i16..=300, -300i16..=300, 0i16..200, -1800i16..=-1201).prop_map(|(ail, ele, thr, rud)| Sticks::new(ail, ele, thr, rud)),
    ]
}

fn fly_sticks() -> impl Strategy<Value = Sticks> {
    prop_oneof![
        1 => Just(sticks::FLY),
        3 => (-1800i16..=1800, -1800i16..=1800, 0i16..2500, -1800i16..=1800).prop_map(|(ail, ele, thr, rud)| Sticks::new(ail, ele, thr, rud)),
    ]
}

fn pattern_strategy() -> impl Strategy<Value = Pattern> {
    prop_oneof![
        2 => Just(Pattern::Sticks(sticks::NEUTRAL)),
        3 => arm_sticks().prop_map(Pattern::Sticks),
        1 => disarm_sticks().prop_map(Pattern::Sticks),
        1 => Just(Pattern::Sticks(sticks::CALIBRATE)),
        3 => fly_sticks().prop_map(Pattern::Sticks),
        1 => prop::array::uniform4(prop_oneof![Just(0u16), 3000u16..9000, any::<u16>()]).prop_map(Pattern::Widths),
        1 => (fly_sticks(), 0u8..15).prop_map(|(s, m)| Pattern::Partial(s, m)),
        2 => Just(Pattern::Off),
    ]
}

fn segment_strategy() -> impl Strategy<Value = Segment> {
    let ticks = prop_oneof![2 => 1u32..120, 2 => 600u32..=1200, 1 => 120u32..600];
    let glitches = prop_oneof![6 => Just(0u8), 1 => 1u8..4];
    (pattern_strategy(), ticks, glitches).prop_map(|(pattern, ticks, glitches)| Segment { pattern, ticks, glitches })
}

fn run_timeline(rig: &mut Rig, timeline: &[Segment]) -> Result<(), Violation> {
    let rc = rig.fc.config().rc;
    for seg in timeline {
        rig.run(&seg.frame(&rc), seg.ticks, seg.glitches)?;
    }
    Ok(())
}

// ---------------------------------------------------------------------------------------
// (b) Raw edge streams
// ---------------------------------------------------------------------------------------

#[derive(Clone, Copy, Debug)]
enum EdgeOp {
    /// One capture event; channels ≥ 4 do not exist and must be ignored.
    Edge(usize, u16, bool),
    /// This many control ticks pass (with the background frame, if any).
    Ticks(u8),
}

fn edge_op_strategy() -> impl Strategy<Value = EdgeOp> {
    prop_oneof![
        6 => (0usize..6, any::<u16>(), any::<bool>()).prop_map(|(c, t, l)| EdgeOp::Edge(c, t, l)),
        2 => (1u8..=40).prop_map(EdgeOp::Ticks),
        1 => (100u8..=255).prop_map(EdgeOp::Ticks),
    ]
}

fn background_strategy() -> impl Strategy<Value = Option<Sticks>> {
    prop_oneof![2 => Just(None), 1 => Just(Some(sticks::NEUTRAL)), 2 => fly_sticks().prop_map(Some), 1 => arm_sticks().prop_map(Some)]
}

fn run_edges(rig: &mut Rig, background: Option<Sticks>, ops: &[EdgeOp]) -> Result<(), Violation> {
    let rc = rig.fc.config().rc;
    let frame = background.map_or(RadioFrame::OFF, |s| RadioFrame::from_sticks(&rc, s));
    let mut edges: Vec<CaptureEdge> = Vec::new();
    for op in ops {
        match *op {
            EdgeOp::Edge(channel, capture_counts, level_high) => edges.push(CaptureEdge { channel, capture_counts, level_high }),
            EdgeOp::Ticks(n) => {
                for _ in 0..n {
                    // The receiver's edges of this tick after the injected ones.
                    rig.radio.tick(&frame, 0, &mut edges);
                    let imu = rig.imu.sample();
                    rig.tick_with(imu, &edges)?;
                    edges.clear();
                }
            }
        }
    }
    Ok(())
}

// ---------------------------------------------------------------------------------------
// (c) Sensor words
// ---------------------------------------------------------------------------------------

#[derive(Clone, Copy, Debug)]
enum ImuPattern {
    Level,
    /// Uniformly random words every tick (from this seed).
    Random(u64),
    /// One word repeated: a stuck sensor (possibly at an extreme).
    Constant(RawImu),
    /// Random extremes (i16::MIN, −1, 0, 1, i16::MAX per word) every tick.
    Extremes(u64),
    /// The last sample repeated.
    Freeze,
}

fn word() -> impl Strategy<Value = i16> {
    prop_oneof![Just(i16::MIN), Just(i16::MAX), Just(0i16), Just(-1i16), Just(8197i16), any::<i16>()]
}

fn imu_pattern_strategy() -> impl Strategy<Value = ImuPattern> {
    prop_oneof![
        3 => Just(ImuPattern::Level),
        2 => any::<u64>().prop_map(ImuPattern::Random),
        2 => (prop::array::uniform3(word()), prop::array::uniform3(word())).prop_map(|(accel, gyro)| ImuPattern::Constant(RawImu { accel, gyro })),
        2 => any::<u64>().prop_map(ImuPattern::Extremes),
        1 => Just(ImuPattern::Freeze),
    ]
}

fn run_sensor_timeline(rig: &mut Rig, segments: &[(ImuPattern, Sticks, u32)]) -> Result<(), Violation> {
    let rc = rig.fc.config().rc;
    let stuck_limit = rig.fc.config().health.map_or(u32::MAX, |h| h.stuck_ticks);
    // The sample before the case is the level IMU's (never equal to what Freeze repeats first).
    let mut last: Option<RawImu> = None;
    let mut same = 0u32;
    for &(pattern, s, ticks) in segments {
        let frame = RadioFrame::from_sticks(&rc, s);
        let mut rng = Rng::new(match pattern {
            ImuPattern::Random(seed) | ImuPattern::Extremes(seed) => seed,
            _ => 0,
        });
        for _ in 0..ticks {
            let imu = match pattern {
                ImuPattern::Level => rig.imu.sample(),
                ImuPattern::Random(_) => {
                    let mut w = || rng.next_u64() as i16;
                    RawImu { accel: [w(), w(), w()], gyro: [w(), w(), w()] }
                }
                ImuPattern::Constant(raw) => raw,
                ImuPattern::Extremes(_) => {
                    const X: [i16; 5] = [i16::MIN, -1, 0, 1, i16::MAX];
                    let mut w = || X[(rng.next_u64() % 5) as usize];
                    RawImu { accel: [w(), w(), w()], gyro: [w(), w(), w()] }
                }
                ImuPattern::Freeze => last.unwrap_or_default(),
            };
            same = if Some(imu) == last { same + 1 } else { 0 };
            last = Some(imu);
            let out = rig.tick_frame_imu(&frame, 0, imu)?;
            let st = rig.fc.status();
            // Stated again here, independently of the monitor: a stuck sensor is a fault
            // within 100 ms, and a fault means motors off for good.
            if same >= stuck_limit {
                assert!(st.fault.is_some(), "stuck {same} ticks without a fault");
            }
            if st.fault.is_some() {
                let off = rig.fc.config().mixer.off_compare();
                assert!(out.compare.iter().all(|&c| c == off), "fault {:?} with compare {:?}", st.fault, out.compare);
                assert_eq!(st.state, FlightState::Fault);
            }
        }
    }
    Ok(())
}

// ---------------------------------------------------------------------------------------
// Supervisor alone
// ---------------------------------------------------------------------------------------

fn gesture_strategy() -> impl Strategy<Value = Option<Gesture>> {
    prop_oneof![
        3 => Just(None),
        3 => Just(Some(Gesture::Arm)),
        1 => Just(Some(Gesture::Disarm)),
        1 => Just(Some(Gesture::Calibrate)),
    ]
}

fn inputs_strategy() -> impl Strategy<Value = Inputs> {
    let link = prop::bool::weighted(0.85);
    let thr = prop_oneof![3 => Just(0i16), 1 => 0i16..200, 2 => 200i16..3000, 1 => any::<i16>()];
    let fault = prop_oneof![60 => Just(None), 1 => Just(Some(SensorFault::Stuck)), 1 => Just(Some(SensorFault::NotFinite))];
    let tilt = prop_oneof![6 => Just(0.0f32), 2 => 0.0f32..0.6, 1 => Just(f32::NAN), 1 => Just(f32::INFINITY)];
    // What a radio reports (the channel timeout, or more) and anything else.
    let silence = prop_oneof![4 => Just(80u32), 2 => 80u32..1200, 1 => Just(0u32), 1 => any::<u32>()];
    let flags = (prop::bool::weighted(0.75), prop::bool::weighted(0.9), prop::bool::weighted(0.1));
    (link, silence, gesture_strategy(), thr, flags, fault, tilt).prop_map(
        |(link, silence_ticks, gesture, thr, (throttle_low, calibrated, calibrating), sensor_fault, tilt_rad)| Inputs {
            // Set by `run_supervisor`.
            tick: 0,
            link,
            silence_ticks,
            sticks: Sticks::new(0, 0, thr, 0),
            gesture,
            throttle_low,
            calibrated,
            calibrating,
            sensor_fault,
            tilt_rad,
            gcs: fcu_core::gcs::GcsCommands::NONE,
            // No height estimate: the manual failsafe these properties state.
            descent_cap_ticks: 0,
            landed: false,
        },
    )
}

/// Each step's tick is the one after the monitor's last (the supervisor and its monitor see
/// every step together).
fn run_supervisor(cfg: &SafetyConfig, s: &mut Supervisor, m: &mut SupervisorMonitor, segs: &[(Inputs, u32)]) -> Result<(), Violation> {
    for (i, n) in segs {
        let mut i = *i;
        for _ in 0..*n {
            i.tick = u32::try_from(m.ticks() + 1).unwrap_or(u32::MAX);
            let d: Decision = s.decide(cfg, &i);
            m.observe(&i, &d)?;
            // The silence grows while the link stays lost, as a radio reports it.
            i.silence_ticks = i.silence_ticks.saturating_add(1);
        }
    }
    Ok(())
}

/// A supervisor and its monitor after `boot_settle_ticks` of calibrated idle with a good link.
fn settled_supervisor(cfg: &SafetyConfig) -> (Supervisor, SupervisorMonitor) {
    let idle = Inputs::READY;
    let mut s = Supervisor::new();
    let mut m = SupervisorMonitor::new(*cfg);
    run_supervisor(cfg, &mut s, &mut m, &[(idle, cfg.boot_settle_ticks + 1)]).unwrap_or_else(|v| panic!("{v}"));
    (s, m)
}

fn safety_config_strategy() -> impl Strategy<Value = SafetyConfig> {
    (1u32..24, 1u32..24, 1u32..60, 1u32..40, 1u32..12, 0.05f32..1.0, 0u32..30).prop_map(
        |(
            arm_hold_ticks,
            disarm_hold_ticks,
            auto_disarm_ticks,
            failsafe_off_ticks,
            recovery_ticks,
            max_arm_tilt_rad,
            boot_settle_ticks,
        )| {
            SafetyConfig {
                arm_hold_ticks,
                disarm_hold_ticks,
                auto_disarm_ticks,
                failsafe_off_ticks,
                recovery_ticks,
                loss_forget_ticks: 1 + recovery_ticks % 7,
                max_arm_tilt_rad,
                boot_settle_ticks,
            }
        },
    )
}

// ---------------------------------------------------------------------------------------
// The properties
// ---------------------------------------------------------------------------------------

proptest! {
    #![proptest_config(ProptestConfig { cases: 6000, max_shrink_iters: 2000, ..ProptestConfig::default() })]

    /// (a) Arbitrary stick timelines (neutral, gestures, flying, raw widths, partial and
    /// lost links, glitches): every invariant holds on every tick, nothing panics.
    #[test]
    fn stick_timelines_keep_every_safety_invariant(
        which in start_strategy(),
        timeline in prop::collection::vec(segment_strategy(), 1..10),
    ) {
        let mut rig = start(which);
        if let Err(v) = run_timeline(&mut rig, &timeline) {
            prop_assert!(false, "{v}");
        }
    }

    /// (b) Arbitrary raw capture edges (any channel including nonexistent ones, any counts,
    /// any level), alone or mixed into a valid receiver stream.
    #[test]
    fn raw_edge_streams_keep_every_safety_invariant(
        which in start_strategy(),
        background in background_strategy(),
        ops in prop::collection::vec(edge_op_strategy(), 1..300),
    ) {
        let mut rig = start(which);
        if let Err(v) = run_edges(&mut rig, background, &ops) {
            prop_assert!(false, "{v}");
        }
    }

    /// (c) Arbitrary sensor words (random, extreme, stuck, frozen) while armed and flying:
    /// compare values in range, a stuck sensor faults within 100 ms, motors off after a fault.
    #[test]
    fn sensor_words_while_flying_keep_every_safety_invariant(
        esc in prop::bool::weighted(0.2),
        segments in prop::collection::vec((imu_pattern_strategy(), fly_sticks(), 1u32..200), 1..8),
    ) {
        let mut rig = start(if esc { Start::EscFlying } else { Start::Flying });
        if let Err(v) = run_sensor_timeline(&mut rig, &segments) {
            prop_assert!(false, "{v}");
        }
    }
}

/// Flying with `sticks`, the receiver goes quiet for `off` ticks and sends for `on` ticks, for
/// each cycle in turn and then repeating, for `ticks` ticks in all. Returns the tick (from the
/// first gap) of stage 2, and whether control came back to the sticks after stage 1.
fn flap(rig: &mut Rig, sticks: Sticks, cycles: &[(u32, u32)], ticks: u32) -> Result<(Option<u32>, bool), Violation> {
    let rc = rig.fc.config().rc;
    let frame = RadioFrame::from_sticks(&rc, sticks);
    let (mut stage1, mut stage2, mut handed_back) = (false, None, false);
    let mut t = 0;
    for &(off, on) in cycles.iter().cycle() {
        for (f, n) in [(&RadioFrame::OFF, off), (&frame, on)] {
            for _ in 0..n {
                if t >= ticks {
                    return Ok((stage2, handed_back));
                }
                rig.tick_frame(f, 0)?;
                match rig.state() {
                    FlightState::FailsafeLevel => stage1 = true,
                    FlightState::Armed => handed_back |= stage1,
                    FlightState::FailsafeOff => stage2 = stage2.or(Some(t)),
                    _ => {}
                }
                t += 1;
            }
        }
    }
    Ok((stage2, handed_back))
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 300, max_shrink_iters: 500, ..ProptestConfig::default() })]

    /// A link that loses more than it delivers (gaps past the 100 ms channel timeout, each
    /// burst no longer than the gap before it and shorter than the recovery time) never gets
    /// control back, and ends in stage 2 within 3 s of the first gap, whatever the pattern;
    /// the monitor checks every tick (lost time, never restarted motors).
    #[test]
    fn a_link_that_loses_more_than_it_delivers_ends_in_stage_2_within_3_s(
        esc in prop::bool::weighted(0.2),
        cycles in prop::collection::vec((100u32..=800).prop_flat_map(|off| (Just(off), 1..=off.min(600))), 1..6),
        thr in 200i16..2500,
    ) {
        let mut rig = start(if esc { Start::EscFlying } else { Start::Flying });
        let sticks = Sticks { thr: StickCounts(thr), ..sticks::FLY };
        match flap(&mut rig, sticks, &cycles, 3 * 800 + 400) {
            Err(v) => prop_assert!(false, "{v}"),
            Ok((stage2, handed_back)) => {
                prop_assert!(!handed_back, "control handed back");
                let at = stage2.unwrap_or(u32::MAX);
                prop_assert!(at <= 3 * 800, "stage 2 at tick {at} of the flapping");
            }
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 40_000, max_shrink_iters: 4000, ..ProptestConfig::default() })]

    /// The bare supervisor, default numbers, from boot or from a settled start: armed only
    /// after ≥ arm_hold_ticks of the arm gesture on a good link then a release with no
    /// blocker; motors disabled in every non-flying state; faults latched; stage 2 on time.
    #[test]
    fn supervisor_default_config_arms_only_after_the_full_procedure(
        settled in prop::bool::weighted(0.7),
        segs in prop::collection::vec((inputs_strategy(), prop_oneof![3 => 1u32..40, 2 => 700u32..1000, 1 => 40u32..700]), 1..12),
    ) {
        let cfg = SafetyConfig::DEFAULT;
        let (mut s, mut m) = if settled { settled_supervisor(&cfg) } else { (Supervisor::new(), SupervisorMonitor::new(cfg)) };
        if let Err(v) = run_supervisor(&cfg, &mut s, &mut m, &segs) {
            prop_assert!(false, "{v}");
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 60_000, max_shrink_iters: 4000, ..ProptestConfig::default() })]

    /// The same rules for arbitrary valid safety numbers (short holds and timeouts, so every
    /// path is reached within a few dozen steps).
    #[test]
    fn supervisor_any_config_arms_only_after_the_full_procedure(
        cfg in safety_config_strategy(),
        segs in prop::collection::vec((inputs_strategy(), 1u32..30), 1..24),
    ) {
        prop_assume!(cfg.is_valid());
        let mut s = Supervisor::new();
        let mut m = SupervisorMonitor::new(cfg);
        if let Err(v) = run_supervisor(&cfg, &mut s, &mut m, &segs) {
            prop_assert!(false, "{v}");
        }
    }
}

// ---------------------------------------------------------------------------------------
// The monitor and the generators themselves
// ---------------------------------------------------------------------------------------

/// A realistic flight through the generators: boot, arm, fly, lose the link for good.
#[test]
fn generators_fly_a_whole_flight_and_fail_safe() {
    let mut rig = start(Start::Booted);
    rig.arm().unwrap_or_else(|e| panic!("{e}"));
    rig.sticks(sticks::FLY, 800).unwrap_or_else(|v| panic!("{v}"));
    assert!(rig.fc.status().compare.iter().all(|&c| c > 0));
    // 0.5 s without signal: stage 1, motors still running level.
    rig.run(&RadioFrame::OFF, 400, 0).unwrap_or_else(|v| panic!("{v}"));
    assert_eq!(rig.state(), FlightState::FailsafeLevel);
    assert!(rig.fc.status().compare.iter().all(|&c| c > 0));
    // At 1.0 s from the last pulse: stage 2.
    rig.run(&RadioFrame::OFF, 400, 0).unwrap_or_else(|v| panic!("{v}"));
    assert_eq!(rig.state(), FlightState::FailsafeOff);
    assert_eq!(rig.fc.status().compare, [0; 4]);
    // The link returning with the sticks up does not restart the motors.
    rig.sticks(sticks::FLY, 2000).unwrap_or_else(|v| panic!("{v}"));
    assert_eq!(rig.state(), FlightState::Disarmed);
    assert_eq!(rig.fc.status().compare, [0; 4]);
}

#[test]
fn receiver_generator_sends_50_hz_frames_that_decode_to_the_sticks() {
    let rc = Config::default().rc;
    let s = Sticks::new(-1234, 567, 890, 1700);
    let frame = RadioFrame::from_sticks(&rc, s);
    let mut radio = PwmReceiver::new(3);
    let mut decoder = fcu_core::rc::EdgeDecoder::new(rc.pulses);
    let mut receiver = fcu_core::rc::Receiver::new();
    let mut widths = 0;
    let mut edges = Vec::new();
    for _ in 0..800 {
        edges.clear();
        radio.tick(&frame, 0, &mut edges);
        for e in &edges {
            decoder.on_edge(*e);
        }
        let b = decoder.take();
        widths += b.width_counts.iter().flatten().count();
        receiver.update(&rc, &b, |_| {});
    }
    // One second: 50 frames of 4 pulses (±1 frame for the phase).
    assert!((49 * 4..=51 * 4).contains(&widths), "{widths} widths");
    assert_eq!(receiver.sticks(), s);
}

#[test]
fn level_imu_is_level_noisy_and_never_repeats() {
    let mut imu = LevelImu::new(5);
    let mut last = imu.sample();
    for _ in 0..10_000 {
        let s = imu.sample();
        assert_ne!(s, last);
        assert!((8195..=8199).contains(&s.accel[2]) && s.gyro.iter().all(|g| g.abs() <= 2), "{s:?}");
        last = s;
    }
}

/// A good observation to tamper with: the booted rig's next tick.
fn next_tick(rig: &mut Rig) -> (TickOutput, Status) {
    let out = rig.tick_frame(&RadioFrame::from_sticks(&Config::default().rc, sticks::NEUTRAL), 0).unwrap_or_else(|v| panic!("{v}"));
    (out, rig.fc.status())
}

fn tampered(f: impl FnOnce(&mut TickOutput, &mut Status)) -> Violation {
    let mut rig = start(Start::Booted);
    let (mut out, mut st) = next_tick(&mut rig);
    f(&mut out, &mut st);
    st.compare = out.compare;
    let mut m = rig.monitor.clone();
    m.observe(&Observation { imu: None, batch: None, edges: None, out: &out, status: &st }).expect_err("the monitor must object")
}

#[test]
fn monitor_rejects_armed_without_the_gesture() {
    let v = tampered(|_, st| st.state = FlightState::Armed);
    assert_eq!(v.invariant, Invariant::ArmedWithoutProcedure, "{v}");
    assert!(v.detail.contains("arm gesture held 0 ticks"), "{v}");
    // Named with the tick: boot, one good tick, then the tampered one.
    assert!(v.to_string().starts_with(&format!("tick {}: armed-without-procedure", start(Start::Booted).monitor.ticks() + 2)), "{v}");
    let v = tampered(|_, st| st.state = FlightState::FailsafeLevel);
    assert_eq!(v.invariant, Invariant::ArmedWithoutProcedure, "{v}");
}

#[test]
fn monitor_rejects_running_motors_while_disarmed_and_out_of_range_compares() {
    assert_eq!(tampered(|out, _| out.compare[2] = 1).invariant, Invariant::MotorsNotOff);
    assert_eq!(tampered(|out, _| out.compare[0] = 1901).invariant, Invariant::CompareOutOfRange);
}

#[test]
fn monitor_rejects_motors_with_the_throttle_low_while_armed() {
    let mut rig = start(Start::Flying);
    // The receiver needs a few ticks for all four channels to read the low throttle.
    rig.sticks(sticks::NEUTRAL, 41).unwrap_or_else(|v| panic!("{v}"));
    let (mut out, mut st) = next_tick(&mut rig);
    assert_eq!(st.state, FlightState::Armed);
    // Untouched, the core has the motors off: only the tampering below runs them.
    let off = Config::default().mixer.off_compare();
    assert_eq!(out.compare, [off; 4], "the core itself runs the motors with the throttle low");
    out.compare = [700; 4];
    st.compare = out.compare;
    let v = rig.monitor.observe(&Observation { imu: None, batch: None, edges: None, out: &out, status: &st }).expect_err("must object");
    assert_eq!(v.invariant, Invariant::MotorsNotOff, "{v}");
}

#[test]
fn monitor_rejects_a_stuck_sensor_without_a_fault_and_a_forgotten_fault() {
    let mut rig = start(Start::Booted);
    let (out, st) = next_tick(&mut rig);
    let raw = RawImu { accel: [1, 2, 8197], gyro: [3, 4, 5] };
    let mut m = rig.monitor.clone();
    let stuck = Config::default().health.map_or(0, |h| h.stuck_ticks);
    let mut result = Ok(());
    for _ in 0..=stuck {
        result = m.observe(&Observation { imu: Some(raw), batch: None, edges: None, out: &out, status: &st });
        if result.is_err() {
            break;
        }
    }
    assert_eq!(result.expect_err("must object").invariant, Invariant::StuckSensorMissed);

    let mut m = rig.monitor.clone();
    let mut faulted = st;
    faulted.fault = Some(SensorFault::Stuck);
    faulted.state = FlightState::Fault;
    m.observe(&Observation { imu: None, batch: None, edges: None, out: &out, status: &faulted }).unwrap_or_else(|v| panic!("{v}"));
    let v = m.observe(&Observation { imu: None, batch: None, edges: None, out: &out, status: &st }).expect_err("must object");
    assert_eq!(v.invariant, Invariant::FaultNotLatched);
}

#[test]
fn monitor_rejects_motors_after_a_long_link_loss() {
    // Stage 1 (FailsafeLevel) reported for ever without a link: stage 2 is late.
    let mut rig = start(Start::Flying);
    let (_, _) = next_tick(&mut rig);
    let mut m = rig.monitor.clone();
    let mut st = rig.fc.status();
    st.state = FlightState::FailsafeLevel;
    st.link = false;
    let out = TickOutput { compare: st.compare, outer_job: None };
    let mut first = None;
    for _ in 0..2000 {
        if let Err(v) = m.observe(&Observation { imu: None, batch: None, edges: None, out: &out, status: &st }) {
            first = Some(v);
            break;
        }
    }
    let v = first.expect("must object");
    assert_eq!(v.invariant, Invariant::MotorsOnAfterLinkLoss, "{v}");
    // Past 1.0 s + 10 ms from the last pulse; without the radio model the monitor takes the
    // link as declared lost 100 ms after it, at the first tampered tick.
    let ticks_after_start = v.tick - rig.monitor.ticks();
    assert_eq!(ticks_after_start, 800 + 8 - 80 + 2, "{v}");
}

#[test]
fn monitor_adds_up_lost_time_across_a_brief_recovery() {
    // Stage 1 reported throughout: 500 ticks without a link (80 + 499 of silence), 100 with,
    // then without again: the 1.0 s + 10 ms (808 ticks) are past at the 151st tick of the
    // second loss (579 + 80 + 150 = 809), not 729 ticks into it as a reset would make it.
    let mut rig = start(Start::Flying);
    let _ = next_tick(&mut rig);
    let mut m = rig.monitor.clone();
    let mut st = rig.fc.status();
    st.state = FlightState::FailsafeLevel;
    let out = TickOutput { compare: st.compare, outer_job: None };
    let mut observe = |link: bool, n: u32| -> Result<(), (u32, Violation)> {
        let st = Status { link, ..st };
        for k in 1..=n {
            m.observe(&Observation { imu: None, batch: None, edges: None, out: &out, status: &st }).map_err(|v| (k, v))?;
        }
        Ok(())
    };
    observe(false, 500).unwrap_or_else(|(_, v)| panic!("{v}"));
    observe(true, 100).unwrap_or_else(|(_, v)| panic!("{v}"));
    let (k, v) = observe(false, 1000).expect_err("must object");
    assert_eq!(v.invariant, Invariant::MotorsOnAfterLinkLoss, "{v}");
    assert_eq!(k, 151, "{v}");
}

#[test]
fn monitor_rejects_a_width_from_a_pulse_longer_than_the_capture_wrap() {
    // A 9.5 ms pulse on the aileron: its edges are 1.308 ms apart on the 15-bit clock, a valid
    // width, but they came 7 ticks apart. A decoder that handed it over is caught.
    let mut rig = start(Start::Booted);
    let (out, st) = next_tick(&mut rig);
    let mut m = rig.monitor.clone();
    let empty = PulseBatch::default();
    let rise = [CaptureEdge::rising(0, 1000)];
    let mut seen = |edges: &[CaptureEdge], batch: &PulseBatch| {
        m.observe(&Observation { imu: None, batch: Some(batch), edges: Some(edges), out: &out, status: &st })
    };
    seen(&rise, &empty).unwrap_or_else(|v| panic!("{v}"));
    for _ in 0..6 {
        seen(&[], &empty).unwrap_or_else(|v| panic!("{v}"));
    }
    let fall = [CaptureEdge::falling(0, (1000 + 38_000 - 32_768) as u16)];
    let aliased = PulseBatch { width_counts: [Some(38_000 - 32_768), None, None, None], ..PulseBatch::default() };
    let v = seen(&fall, &aliased).expect_err("must object");
    assert_eq!(v.invariant, Invariant::PulseAliased, "{v}");

    // The same width from a pulse whose edges came 2 ticks apart is fine.
    let mut m = rig.monitor.clone();
    let mut seen = |edges: &[CaptureEdge], batch: &PulseBatch| {
        m.observe(&Observation { imu: None, batch: Some(batch), edges: Some(edges), out: &out, status: &st })
    };
    seen(&rise, &empty).unwrap_or_else(|v| panic!("{v}"));
    seen(&[], &empty).unwrap_or_else(|v| panic!("{v}"));
    let fall = [CaptureEdge::falling(0, 1000 + 5232)];
    seen(&fall, &aliased).unwrap_or_else(|v| panic!("{v}"));
}

#[test]
fn monitor_rejects_a_yaw_target_with_the_throttle_low() {
    let mut rig = start(Start::Flying);
    rig.sticks(sticks::NEUTRAL, 40).unwrap_or_else(|v| panic!("{v}"));
    let (out, mut st) = next_tick(&mut rig);
    assert_eq!(st.state, FlightState::Armed);
    st.target_rad[2] = 0.3;
    let v = rig.monitor.observe(&Observation { imu: None, batch: None, edges: None, out: &out, status: &st }).expect_err("must object");
    assert_eq!(v.invariant, Invariant::YawTargetWithThrottleLow, "{v}");
}

#[test]
fn supervisor_monitor_rejects_an_early_arm() {
    let cfg = SafetyConfig::DEFAULT;
    let (_, mut m) = settled_supervisor(&cfg);
    let i = Inputs::READY;
    let arm = Inputs { gesture: Some(Gesture::Arm), ..i };
    let fake = |state| Decision {
        state,
        motors_enabled: state.motors_may_run(),
        failsafe_throttle: None,
        request_calibration: false,
        blockers: Default::default(),
    };
    for _ in 0..cfg.arm_hold_ticks - 1 {
        m.observe(&arm, &fake(FlightState::Arming)).unwrap_or_else(|v| panic!("{v}"));
    }
    let v = m.observe(&i, &fake(FlightState::Armed)).expect_err("799 ticks is too short");
    assert_eq!(v.invariant, Invariant::ArmedWithoutProcedure, "{v}");
}

/// The timeline generator reaches the states the invariants are about (so the properties
/// are not vacuous): armed, failsafe stages 1 and 2, disarmed by the gesture, calibrating.
#[test]
fn timeline_generator_reaches_every_safety_state() {
    let mut runner = proptest::test_runner::TestRunner::deterministic();
    let strategy = (start_strategy(), prop::collection::vec(segment_strategy(), 1..10));
    let mut seen = std::collections::BTreeSet::new();
    let mut armings = 0;
    for _ in 0..300 {
        let (which, timeline) = strategy.new_tree(&mut runner).map(|t| t.current()).unwrap_or_else(|e| panic!("{e}"));
        let mut rig = start(which);
        let rc = rig.fc.config().rc;
        let mut prev = rig.state();
        for seg in &timeline {
            for _ in 0..seg.ticks {
                rig.tick_frame(&seg.frame(&rc), seg.glitches).unwrap_or_else(|v| panic!("{v}"));
                let s = rig.state();
                if s == FlightState::Armed && prev == FlightState::Arming {
                    armings += 1;
                }
                seen.insert(format!("{prev:?}->{s:?}"));
                prev = s;
            }
        }
    }
    for t in [
        "Arming->Armed",
        "Armed->FailsafeLevel",
        "FailsafeLevel->Armed",
        "FailsafeLevel->FailsafeOff",
        "Armed->Disarmed",
        "Disarmed->Calibrating",
    ] {
        assert!(seen.contains(t), "{t} never happened: {seen:?}");
    }
    assert!(armings >= 10, "only {armings} armings");
}

// ---------------------------------------------------------------------------------------
// Cases the properties reach only by chance, pinned
// ---------------------------------------------------------------------------------------

/// Armed, the pilot holds the arm gesture (throttle at 0, so the motors are stopped and the
/// drone looks disarmed); after 5 s the automatic disarm fires; the gesture is still held for
/// 1 s more and let go: the supervisor must not arm again, because `docs/safety.md#disarming`
/// blocks arming until the gesture has been released since the last disarm, and the automatic
/// disarm is one (`Supervisor::decide` clears `released` on it, as on the gesture disarm and
/// on stage 2).
#[test]
fn arm_gesture_held_through_the_automatic_disarm_does_not_rearm() {
    let mut rig = Rig::booted(Config::default(), 7).unwrap_or_else(|e| panic!("{e}"));
    rig.arm().unwrap_or_else(|e| panic!("{e}"));
    // Hold the arm gesture while armed until the automatic disarm (4000 ticks), then 1 s more.
    rig.sticks(sticks::ARM, 4000 + 800 + 16).unwrap_or_else(|v| panic!("{v}"));
    let r = rig.sticks(sticks::NEUTRAL, 40);
    assert_eq!(r, Ok(()), "the monitor objects");
    assert_ne!(rig.state(), FlightState::Armed, "re-armed by a gesture held through the automatic disarm");

    // The bare supervisor, short numbers: the smallest case of it.
    let cfg = SafetyConfig { arm_hold_ticks: 1, auto_disarm_ticks: 3, boot_settle_ticks: 0, ..SafetyConfig::DEFAULT };
    let idle = Inputs::READY;
    let arm = Inputs { gesture: Some(Gesture::Arm), ..idle };
    let mut s = Supervisor::new();
    let mut m = SupervisorMonitor::new(cfg);
    let r = run_supervisor(&cfg, &mut s, &mut m, &[(idle, 1), (arm, 1), (idle, 1), (arm, 4), (idle, 1)]);
    assert_eq!(r, Ok(()));
}
