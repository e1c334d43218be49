//! The vertical half flown on a small vertical plant written here, with the real supervisor
//! deciding at the tick rate: the hold, the landing and its disarm, the mode changes, the
//! failsafe descent, and garbage from the barometer.

use super::*;
use crate::baro::registers::status;
use crate::baro::PA_PER_COUNT;
use crate::gcs::GcsCommands;
use crate::mixer::MixerConfig;
use crate::rc::{RcConfig, Sticks};
use crate::supervisor::{Decision, FlightState, Inputs, SafetyConfig, Supervisor};

const TICK_HZ: f32 = 800.0;
const STEP_S: f32 = 1.0 / 160.0;
const P0: f32 = 101_325.0;
const FULL_SCALE: StickCounts = StickCounts(1800);
const MIN_THROTTLE: StickCounts = StickCounts(200);
const CENTRE: i16 = 1800;
const ARM: Sticks = Sticks::new(-1500, -1500, 0, 1500);
const IDLE: Sticks = Sticks::new(0, 0, 0, 0);
const SAFETY: SafetyConfig = SafetyConfig::DEFAULT;

/// The airframe of the simulator's nominal plant, vertically: 65 g, four motors of 0.33 N at
/// full duty with its thrust curve, a 50 ms motor lag, linear drag, a rigid floor.
struct Plant {
    mass_kg: f32,
    z_m: f32,
    v_m_s: f32,
    thrust_n: f32,
    /// The specific force along the vertical (the accelerometer), m/s².
    specific_force: f32,
    /// An updraught's push, N.
    updraught_n: f32,
}

impl Plant {
    const NOMINAL_KG: f32 = 0.065;
    const DRAG_N_PER_M_S: f32 = 0.02;
    const G: f32 = 9.80665;

    /// The thrust the tick's throttle gives once the motors have settled: the reference's DC
    /// throttle map to a duty, the motors' thrust curve; nothing below the throttle-low cut.
    fn thrust_for(throttle: f32, running: bool) -> f32 {
        if !running || throttle < f32::from(MIN_THROTTLE.0) {
            return 0.0;
        }
        let d = limit((0.33333 * throttle + 633.333) / 2000.0, 0.0, 1.0);
        4.0 * 0.33 * (-0.33 * d * d + 1.32 * d).max(0.0)
    }

    fn step(&mut self, throttle: f32, running: bool, dt: f32) {
        self.thrust_n += (Self::thrust_for(throttle, running) - self.thrust_n) * dt / 0.05;
        let force = self.thrust_n + self.updraught_n - Self::DRAG_N_PER_M_S * self.v_m_s;
        let mut a = force / self.mass_kg - Self::G;
        if self.z_m <= 0.0 && a <= 0.0 && self.v_m_s <= 0.0 {
            // On the floor: it pushes back.
            a = 0.0;
            self.v_m_s = 0.0;
            self.z_m = 0.0;
        }
        self.z_m += (self.v_m_s + 0.5 * a * dt) * dt;
        self.v_m_s += a * dt;
        if self.z_m < 0.0 {
            // The touch-down: the floor stops it within the step, as the accelerometer feels.
            a = -self.v_m_s / dt;
            self.z_m = 0.0;
            self.v_m_s = 0.0;
        }
        self.specific_force = a + Self::G;
    }
}

/// Deterministic noise, uniform in ±amp.
struct Noise(u32);
impl Noise {
    fn next(&mut self, amp: f32) -> f32 {
        self.0 = self.0.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
        ((self.0 >> 8) as f32 / (1u32 << 24) as f32 * 2.0 - 1.0) * amp
    }
}

/// What the barometer does in a run.
#[derive(Clone, Copy, PartialEq)]
enum Baro {
    Working,
    /// The words stop changing (a frozen part): `Stuck` after 15 samples.
    Frozen(i32),
    /// No burst at all.
    Silent,
}

/// The vertical half, the supervisor at the tick rate, the tick's throttle choice and the plant.
struct Rig {
    v: Vertical,
    s: Supervisor,
    decision: Decision,
    cmd: VerticalCommand,
    status: AltitudeStatus,
    plant: Plant,
    noise: Noise,
    tick: u32,
    steps: u32,
    sticks: Sticks,
    link: bool,
    silence: u32,
    baro: Baro,
    /// Added to the barometer's pressure (an estimate off the true height), Pa.
    baro_offset_pa: f32,
    last_counts: i32,
}

impl Rig {
    fn new(mode: AltMode) -> Rig {
        let cfg = AltitudeSettings { mode, ..AltitudeSettings::DEFAULT };
        let mut r = Rig {
            v: Vertical::new(cfg, TICK_HZ, &MixerConfig::REFERENCE_DC),
            s: Supervisor::new(),
            decision: crate::supervisor::ReferenceLatch::default().decide(false, None, false),
            cmd: VerticalCommand::default(),
            status: AltitudeStatus::default(),
            plant: Plant { mass_kg: Plant::NOMINAL_KG, z_m: 0.0, v_m_s: 0.0, thrust_n: 0.0, specific_force: Plant::G, updraught_n: 0.0 },
            noise: Noise(11),
            tick: 0,
            steps: 0,
            sticks: IDLE,
            link: true,
            silence: 0,
            baro: Baro::Working,
            baro_offset_pa: 0.0,
            last_counts: 0,
        };
        // Boot settling, then arm (hold the gesture, let go).
        r.run(IDLE, 2.1);
        r.run(ARM, 1.05);
        r.run(IDLE, 0.1);
        assert_eq!(r.decision.state, FlightState::Armed);
        r
    }

    fn set_mode(&mut self, mode: AltMode) {
        let cfg = AltitudeSettings { mode, ..AltitudeSettings::DEFAULT };
        self.v.set_config(&cfg);
    }

    /// The throttle the tick flies: the hold's, or the sticks' (the failsafe's held one).
    fn flown(&self) -> StickCounts {
        self.cmd.throttle.unwrap_or(self.command())
    }

    fn command(&self) -> StickCounts {
        self.decision.failsafe_throttle.unwrap_or(self.sticks.thr)
    }

    /// One outer step: five supervisor ticks with the plant, then the vertical half.
    fn step(&mut self) {
        let mut force_sum = 0.0;
        for _ in 0..5 {
            self.tick += 1;
            self.silence = if self.link {
                0
            } else if self.silence == 0 {
                80
            } else {
                self.silence + 1
            };
            let flown = Sticks { thr: self.flown(), ..self.sticks };
            let i = Inputs {
                tick: self.tick,
                link: self.link,
                silence_ticks: self.silence,
                sticks: flown,
                gesture: if self.link { RcConfig::REFERENCE.gesture(&self.sticks) } else { None },
                throttle_low: flown.thr < MIN_THROTTLE,
                calibrated: true,
                calibrating: false,
                sensor_fault: None,
                tilt_rad: 0.0,
                gcs: GcsCommands::NONE,
                descent_cap_ticks: self.cmd.descent_cap_ticks,
                landed: self.cmd.landed,
            };
            self.decision = self.s.decide(&SAFETY, &i);
            let running = self.decision.motors_enabled;
            let thr = f32::from(self.flown().0);
            self.plant.step(thr, running, 1.0 / TICK_HZ);
            force_sum += self.plant.specific_force;
        }
        let k = self.steps as usize;
        self.steps += 1;
        let due = (k * 75) / 160 != ((k + 1) * 75) / 160;
        let pressure = P0 - 12.01 * self.plant.z_m + self.baro_offset_pa + self.noise.next(1.3);
        let counts = (pressure / PA_PER_COUNT) as i32;
        let burst = match self.baro {
            Baro::Working => due.then_some(RawBaro { status: status::P_DA, pressure_counts: counts, temperature_counts: 2500 }),
            Baro::Frozen(c) => due.then_some(RawBaro { status: status::P_DA, pressure_counts: c, temperature_counts: 2500 }),
            Baro::Silent => None,
        };
        if due {
            self.last_counts = counts;
        }
        // The block's mean, as the outer step gets it.
        let accel_mg = Vec3::new(0.0, 0.0, force_sum / 5.0 / Plant::G * 1000.0 + self.noise.next(15.0));
        let input = VerticalInput {
            motors_enabled: self.decision.motors_enabled,
            failsafe: self.decision.state == FlightState::FailsafeLevel,
            command: self.command(),
            flown: self.flown(),
            full_scale: FULL_SCALE,
            min_throttle: MIN_THROTTLE,
        };
        let (cmd, status) = self.v.step(burst, Quat::IDENTITY, accel_mg, &input);
        self.cmd = cmd;
        self.status = status;
    }

    fn run(&mut self, sticks: Sticks, seconds: f32) {
        self.sticks = sticks;
        for _ in 0..(seconds / STEP_S) as u32 {
            self.step();
        }
    }

    /// Runs `seconds`, calling `each` after every step.
    fn watch(&mut self, sticks: Sticks, seconds: f32, mut each: impl FnMut(&Rig)) {
        self.sticks = sticks;
        for _ in 0..(seconds / STEP_S) as u32 {
            self.step();
            each(self);
        }
    }

    fn thr(t: i16) -> Sticks {
        Sticks { thr: StickCounts(t), ..IDLE }
    }

    /// In hold: take off with the stick up and settle at about `height_m` with it centred.
    fn take_off_to(&mut self, height_m: f32) {
        self.run(Rig::thr(3600), 0.1);
        let mut t = 0.0;
        while self.plant.z_m < height_m - 0.2 {
            self.run(Rig::thr(3600), 0.1);
            t += 0.1;
            assert!(t < 10.0, "no climb: {:?} at {} m", self.status, self.plant.z_m);
        }
        self.run(Rig::thr(CENTRE), 8.0);
    }
}

#[test]
fn on_the_ground_the_hold_idles_and_the_stick_up_takes_off() {
    let mut r = Rig::new(AltMode::Hold);
    r.run(Rig::thr(CENTRE), 2.0);
    assert_eq!(r.cmd.throttle, Some(StickCounts(0)), "centred on the ground: idle");
    assert!(r.plant.z_m == 0.0 && r.status.holding);
    r.take_off_to(1.0);
    assert!(r.plant.z_m > 0.7, "{}", r.plant.z_m);
}

#[test]
fn in_hold_without_a_healthy_estimate_the_stick_takes_nothing_off_the_ground() {
    let mut r = Rig::new(AltMode::Hold);
    r.baro = Baro::Silent;
    r.run(Rig::thr(CENTRE), 2.0);
    assert!(!r.status.estimate_healthy && !r.status.holding);
    assert_eq!(r.cmd.throttle, Some(StickCounts(0)), "centred means hold: idle, not half throttle");
    assert_eq!(r.plant.z_m, 0.0);
    // The automatic disarm counts the idle.
    r.run(Rig::thr(CENTRE), 3.5);
    assert_eq!(r.decision.state, FlightState::Disarmed);
}

#[test]
fn the_hold_holds_a_height_with_a_noisy_barometer() {
    let mut r = Rig::new(AltMode::Hold);
    r.take_off_to(1.0);
    let target = r.status.target_m.expect("holding");
    let start = r.plant.z_m;
    let (mut lo, mut hi) = (f32::MAX, f32::MIN);
    r.watch(Rig::thr(CENTRE + 200), 20.0, |r| {
        lo = lo.min(r.plant.z_m);
        hi = hi.max(r.plant.z_m);
    });
    // Within a dead band's stick offset: the height stays where it was, the estimate on it.
    assert!(hi - lo < 0.25, "height wandered {lo}..{hi} (start {start}, target {target})");
    assert!((r.status.height_m - r.plant.z_m).abs() < 0.15, "estimate {} true {}", r.status.height_m, r.plant.z_m);
    assert!((r.plant.z_m - target).abs() < 0.2, "{} vs target {target}", r.plant.z_m);
}

#[test]
fn the_stick_climbs_and_descends_at_the_rate_it_asks() {
    let cfg = HoldConfig::DEFAULT;
    let mut r = Rig::new(AltMode::Hold);
    r.take_off_to(1.0);
    let rate_over = |r: &mut Rig, stick: i16| {
        r.run(Rig::thr(stick), 1.5);
        let z0 = r.plant.z_m;
        r.run(Rig::thr(stick), 2.0);
        (r.plant.z_m - z0) / 2.0
    };
    let full = rate_over(&mut r, 3600);
    assert!((full - cfg.climb_rate_max_m_s).abs() < 0.15 * cfg.climb_rate_max_m_s, "full stick: {full} m/s");
    // Half-way between the dead band's top and full: half the rate.
    let half = CENTRE + cfg.deadband.0 + (CENTRE - cfg.deadband.0) / 2;
    let climb = rate_over(&mut r, half);
    assert!((climb - 0.5 * cfg.climb_rate_max_m_s).abs() < 0.1, "half stick: {climb} m/s");
    let down = CENTRE - cfg.deadband.0 - (CENTRE - cfg.deadband.0) / 2;
    let sink = rate_over(&mut r, down);
    assert!((sink + 0.5 * cfg.climb_rate_max_m_s).abs() < 0.1, "half stick down: {sink} m/s");
}

#[test]
fn the_stick_at_the_bottom_lands_idles_and_the_supervisor_disarms() {
    let mut r = Rig::new(AltMode::Hold);
    r.take_off_to(1.5);
    let mut landed_at = None;
    let mut idle_at = None;
    let mut t = 0.0;
    r.watch(Rig::thr(0), 15.0, |r| {
        t += STEP_S;
        if landed_at.is_none() && r.plant.z_m == 0.0 {
            landed_at = Some(t);
        }
        if idle_at.is_none() && r.cmd.throttle == Some(StickCounts(0)) {
            idle_at = Some(t);
        }
    });
    let (landed_at, idle_at) = (landed_at.expect("touched down"), idle_at.expect("idled"));
    // Down at the full rate to 1 m, slowing to the failsafe's rate at 0.5 m (some 2.9 s from
    // 1.5 m), then the landing's half second.
    assert!(landed_at < 3.5, "touched down after {landed_at} s");
    assert!(idle_at > landed_at + LAND_TIME_S - 0.1 && idle_at < landed_at + 1.0, "idle {idle_at} s, down {landed_at} s");
    // Throttle low since the landing: the automatic disarm (5 s) has acted.
    assert_eq!(r.decision.state, FlightState::Disarmed, "{:?}", r.status);
    assert!(!r.decision.motors_enabled);
}

/// The pilot changes their mind on the floor: the stick raised after the touchdown, before the
/// landing is detected or after it (the motors idling, the automatic disarm counting), takes the
/// drone off again, still armed.
#[test]
fn the_stick_raised_after_a_landing_takes_off_again_before_the_disarm() {
    for wait_s in [0.2, 1.0, 3.0] {
        let mut r = Rig::new(AltMode::Hold);
        r.take_off_to(1.5);
        let mut down_for = 0.0;
        let mut t = 0.0;
        while down_for < wait_s {
            r.run(Rig::thr(0), STEP_S);
            t += STEP_S;
            assert!(t < 10.0, "no touchdown: {} m", r.plant.z_m);
            if r.plant.z_m == 0.0 {
                down_for += STEP_S;
            }
        }
        if wait_s >= 1.0 {
            assert_eq!(r.cmd.throttle, Some(StickCounts(0)), "{wait_s} s after the touchdown: not idling");
        }
        assert_eq!(r.decision.state, FlightState::Armed, "{wait_s} s after the touchdown");
        let mut peak = 0.0f32;
        r.watch(Rig::thr(3600), 3.0, |r| peak = peak.max(r.plant.z_m));
        assert!(peak > 0.8, "{wait_s} s after the touchdown the stick up climbed to {peak} m only");
        assert_eq!(r.decision.state, FlightState::Armed);
        assert!(!r.cmd.landed, "climbing, still landed");
    }
}

/// Landing by stick (issue 28's goal for the failsafe, 0.5 m/s at the touchdown, now for the
/// stick too): the stick at the bottom descends at the full rate high up, slows to the failsafe's
/// rate near the floor without a throttle step, on the nominal airframe, a light one and one 30 %
/// heavier (0.7 × hovers under the throttle map's floor: it cannot sink in any mode).
#[test]
fn the_stick_at_the_bottom_slows_near_the_floor_and_touches_down_gently() {
    let cfg = HoldConfig::DEFAULT;
    for mass in [1.0, 0.9, 1.3] {
        let mut r = Rig::new(AltMode::Hold);
        r.plant.mass_kg = Plant::NOMINAL_KG * mass;
        r.take_off_to(2.5);
        let (mut fastest_high, mut touchdown, mut last_v) = (0.0f32, None, 0.0);
        let (mut last_thr, mut biggest_step) = (None::<i16>, 0i16);
        r.watch(Rig::thr(0), 15.0, |r| {
            let z = r.plant.z_m;
            if z > LAND_SLOW_M + LAND_SLOW_BAND_M + 0.2 {
                fastest_high = fastest_high.max(-r.plant.v_m_s);
            }
            if touchdown.is_none() && z == 0.0 {
                touchdown = Some(-last_v);
            }
            last_v = r.plant.v_m_s;
            if let (Some(StickCounts(t)), true) = (r.cmd.throttle, z > 0.0) {
                biggest_step = biggest_step.max(last_thr.map_or(0, |l| (t - l).abs()));
                last_thr = Some(t);
            }
        });
        let touchdown = touchdown.unwrap_or_else(|| panic!("mass {mass}: never touched down"));
        // (The light one sinks at some 0.6 m/s on the throttle map's floor.)
        if mass >= 1.0 {
            assert!(fastest_high > 0.85 * cfg.climb_rate_max_m_s, "mass {mass}: {fastest_high} m/s high up");
        }
        assert!(touchdown <= 0.5, "mass {mass}: touchdown at {touchdown} m/s");
        assert!(biggest_step < 40, "mass {mass}: the throttle stepped {biggest_step} counts");
        assert_eq!(r.decision.state, FlightState::Disarmed, "mass {mass}: {:?}", r.status);
    }
}

/// The slow-down never stops a descent: an estimate that reads low (or is not a number) asks
/// the failsafe's rate, still down to the floor, where the landing is seen.
#[test]
fn an_estimate_reading_low_slows_the_stick_landing_but_never_stops_it() {
    let mut r = Rig::new(AltMode::Hold);
    let cfg = HoldConfig::DEFAULT;
    for h in [f32::NAN, f32::NEG_INFINITY, -3.0, 0.0, LAND_SLOW_M] {
        assert_eq!(r.v.descent_limit_m_s(h), cfg.fs_descent_rate_m_s, "at {h} m");
    }
    assert_eq!(r.v.descent_limit_m_s(f32::INFINITY), cfg.climb_rate_max_m_s);
    r.take_off_to(1.0);
    // The barometer some 1.5 m low (12 Pa per metre): the estimate follows it within its time
    // constant while the hold keeps the estimated height, so the drone climbs.
    r.baro_offset_pa = 18.0;
    r.run(Rig::thr(CENTRE), 15.0);
    assert!(r.plant.z_m - r.status.height_m > 1.0, "estimate {} true {}", r.status.height_m, r.plant.z_m);
    let mut touchdown = None;
    let mut t = 0.0;
    r.watch(Rig::thr(0), 20.0, |r| {
        t += STEP_S;
        if touchdown.is_none() && r.plant.z_m == 0.0 {
            touchdown = Some(t);
        }
    });
    assert!(touchdown.is_some(), "never reached the floor: {:?}", r.status);
    assert_eq!(r.decision.state, FlightState::Disarmed, "{:?}", r.status);
}

#[test]
fn leaving_hold_in_flight_keeps_the_thrust_until_the_stick_crosses_it() {
    let mut r = Rig::new(AltMode::Hold);
    r.take_off_to(1.0);
    let before = StickCounts(mean_flown(&mut r, CENTRE, 1.0) as i16);
    let z = r.plant.z_m;
    // ALT_MODE to 0 with the stick centred (far above the hover): the thrust the hold was
    // giving (its last half second's) stays.
    r.set_mode(AltMode::Manual);
    r.run(Rig::thr(CENTRE), STEP_S);
    let carried = r.flown();
    let mut worst = 0i16;
    r.watch(Rig::thr(CENTRE), 1.0, |r| worst = worst.max((r.flown().0 - carried.0).abs()));
    assert!(!r.status.holding);
    // Within the hold's own wander on this noisy barometer (some ±40 counts at about 1 Hz).
    assert!((carried.0 - before.0).abs() <= 30, "{carried:?} vs {before:?}");
    assert!(worst == 0 && (r.plant.z_m - z).abs() < 0.15, "step {worst}, height {z} -> {}", r.plant.z_m);
    // The stick comes down through the thrust: from then on it flies.
    let mut stick = CENTRE;
    while r.cmd.throttle.is_some() {
        stick -= 20;
        r.run(Rig::thr(stick), 0.05);
        assert!(stick > 0, "never handed back");
    }
    assert!((stick - before.0).abs() < 60, "handed back at {stick}, hold gave {before:?}");
    assert_eq!(r.flown(), StickCounts(stick));
}

#[test]
fn a_barometer_fault_in_hold_leaves_it_without_a_drop_and_is_reported() {
    let mut r = Rig::new(AltMode::Hold);
    r.take_off_to(1.0);
    let before = mean_flown(&mut r, CENTRE, 1.0);
    let z = r.plant.z_m;
    r.baro = Baro::Frozen(r.last_counts);
    r.run(Rig::thr(CENTRE), 0.5);
    assert_eq!(r.status.baro_fault, Some(BaroFault::Stuck));
    assert!(!r.status.estimate_healthy && !r.status.holding);
    // The thrust the hold was giving, not one noisy step of it.
    assert!(r.cmd.throttle.is_some_and(|t| (f32::from(t.0) - before).abs() < 30.0), "{:?} vs {before}", r.cmd.throttle);
    assert!(r.plant.z_m > z - 0.15, "dropped {z} -> {}", r.plant.z_m);
    r.run(Rig::thr(CENTRE), 2.0);
    assert!(r.plant.z_m > z - 0.15, "sank {z} -> {} on the carried thrust", r.plant.z_m);
    r.baro = Baro::Silent;
    r.run(Rig::thr(CENTRE), 0.2);
    assert_eq!(r.status.baro_fault, Some(BaroFault::NoData));
}

#[test]
fn entering_hold_in_flight_takes_the_height_and_the_thrust_flown() {
    let mut r = Rig::new(AltMode::Manual);
    // Manual: climb on a little more than the hover, then hover near it.
    r.run(Rig::thr(620), 1.2);
    r.run(Rig::thr(545), 3.0);
    assert!(r.plant.z_m > 0.2, "{}", r.plant.z_m);
    assert_eq!(r.cmd.throttle, None);
    let z = r.status.height_m;
    // ALT_MODE to 1 with the stick where it hovers (far below the centre).
    r.set_mode(AltMode::Hold);
    r.run(Rig::thr(545), STEP_S);
    assert!((r.status.target_m.unwrap_or(f32::NAN) - z).abs() < 0.05, "{:?} vs {z}", r.status.target_m);
    assert!(r.cmd.throttle.is_some_and(|t| (t.0 - 545).abs() < 40), "{:?}", r.cmd.throttle);
    // The stick asks for no descent until it has been centred once: the height holds.
    let z_true = r.plant.z_m;
    r.run(Rig::thr(545), 5.0);
    assert!((r.plant.z_m - z_true).abs() < 0.2, "{z_true} -> {}", r.plant.z_m);
    r.run(Rig::thr(CENTRE), 5.0);
    assert!((r.plant.z_m - z_true).abs() < 0.3, "{z_true} -> {}", r.plant.z_m);
    // From then on the stick's rates: below the dead band, down.
    r.run(Rig::thr(545), 1.0);
    assert!(r.status.climb_m_s < -0.3, "{:?}", r.status);
}

/// The mean throttle flown over `seconds`.
fn mean_flown(r: &mut Rig, stick: i16, seconds: f32) -> f32 {
    let (mut sum, mut n) = (0.0, 0.0);
    r.watch(Rig::thr(stick), seconds, |r| {
        sum += f32::from(r.flown().0);
        n += 1.0;
    });
    sum / n
}

/// Manual flight at about `height_m`.
fn hovering_manually_at(height_m: f32) -> Rig {
    let mut r = Rig::new(AltMode::Manual);
    r.run(Rig::thr(700), 0.3);
    while r.plant.z_m < height_m {
        r.run(Rig::thr(650), 0.05);
    }
    r.run(Rig::thr(535), 1.0);
    r
}

#[test]
fn link_lost_at_height_with_a_healthy_estimate_descends_lands_and_disarms() {
    let mut r = hovering_manually_at(2.0);
    assert!(r.status.estimate_healthy);
    let z_loss = r.plant.z_m;
    r.link = false;
    let mut t = 0.0;
    let (mut level_min, mut z_at_2_5_s, mut z_at_4_s) = (f32::MAX, 0.0, 0.0);
    let mut off_at = None;
    r.watch(Rig::thr(535), 20.0, |r| {
        t += STEP_S;
        if t < super::FS_LEVEL_S {
            level_min = level_min.min(r.plant.z_m);
        }
        if (t - 2.5).abs() < STEP_S / 2.0 {
            z_at_2_5_s = r.plant.z_m;
        }
        if (t - 4.0).abs() < STEP_S / 2.0 {
            z_at_4_s = r.plant.z_m;
        }
        if off_at.is_none() && r.decision.state == FlightState::FailsafeOff {
            off_at = Some((t, r.plant.z_m));
        }
    });
    // Level and holding first (no manual stage-2 cut at 1 s), then down at FS_DESCENT_RATE.
    assert!(level_min > z_loss - 0.3, "{level_min} vs {z_loss}");
    let rate = (z_at_2_5_s - z_at_4_s) / 1.5;
    let asked = HoldConfig::DEFAULT.fs_descent_rate_m_s;
    assert!((rate - asked).abs() < 0.05, "descent {rate} m/s");
    let (off_t, off_z) = off_at.expect("landed and disarmed");
    assert_eq!(off_z, 0.0, "motors off only on the floor");
    assert!(off_t < 1.0 + z_loss / asked + 3.0, "{off_t} s");
    assert!(!r.decision.motors_enabled);
}

#[test]
fn link_lost_without_a_healthy_estimate_levels_then_stops_as_before() {
    let mut r = hovering_manually_at(1.5);
    r.baro = Baro::Silent;
    r.run(Rig::thr(535), 0.3);
    assert!(!r.status.estimate_healthy && r.cmd.descent_cap_ticks == 0);
    r.link = false;
    let mut t = 0.0;
    let mut off_at = None;
    r.watch(Rig::thr(535), 2.0, |r| {
        t += STEP_S;
        if off_at.is_none() && r.decision.state == FlightState::FailsafeOff {
            off_at = Some(t);
        }
        assert_eq!(r.cmd.throttle, None, "the failsafe's held throttle");
    });
    // Stage 2 one second after the last pulse: the link is declared lost 0.1 s after it.
    let off_t = off_at.expect("stage 2");
    assert!((off_t - 0.9).abs() < 0.02, "{off_t}");
}

#[test]
fn a_barometer_fault_during_the_descent_ends_it_with_the_motors_off() {
    let mut r = hovering_manually_at(2.0);
    r.link = false;
    r.run(Rig::thr(535), 2.0);
    assert_eq!(r.decision.state, FlightState::FailsafeLevel);
    assert!(r.status.failsafe_descent && r.plant.z_m > 0.5);
    r.baro = Baro::Silent;
    r.run(Rig::thr(535), 0.2);
    // No estimate: the manual failsafe's budget, long spent: motors off.
    assert_eq!(r.decision.state, FlightState::FailsafeOff);
    assert!(!r.decision.motors_enabled);
}

#[test]
fn the_link_back_during_the_descent_hands_control_back_after_the_recovery_time() {
    let mut r = hovering_manually_at(2.0);
    r.link = false;
    r.run(Rig::thr(535), 2.5);
    assert!(r.status.failsafe_descent);
    r.link = true;
    r.run(Rig::thr(535), 0.9);
    assert_eq!(r.decision.state, FlightState::FailsafeLevel, "recovery takes 1 s");
    r.run(Rig::thr(535), 0.2);
    assert_eq!(r.decision.state, FlightState::Armed);
    // Manual mode: leaving the descent carries its thrust until the stick crosses it.
    assert!(!r.status.holding);
    assert!(r.plant.z_m > 0.3, "{}", r.plant.z_m);
}

/// The link back after the failsafe's descent in manual mode: the stick the pilot holds is
/// live again. Above the thrust the descent was giving (the pilot climbing), it flies at once;
/// below it, the thrust is carried until the stick comes up to it.
#[test]
fn the_link_back_hands_the_throttle_to_a_stick_above_the_carried_at_once() {
    let link_back = |stick: i16| {
        let mut r = hovering_manually_at(2.0);
        r.link = false;
        r.run(Rig::thr(535), 2.5);
        assert!(r.status.failsafe_descent);
        r.link = true;
        r.run(Rig::thr(stick), 1.2);
        assert_eq!(r.decision.state, FlightState::Armed);
        r
    };
    let mut up = link_back(1200);
    assert_eq!(up.cmd.throttle, None, "the stick above the carried thrust flies");
    let z = up.plant.z_m;
    up.run(Rig::thr(1200), 1.0);
    assert!(up.plant.z_m > z + 0.3, "climbs on the stick: {z} -> {}", up.plant.z_m);

    let mut low = link_back(300);
    let carried = low.cmd.throttle.expect("a stick below the carried thrust waits");
    assert!(carried.0 > 400, "{carried:?}");
    let mut stick = 300;
    while low.cmd.throttle.is_some() {
        stick += 20;
        low.run(Rig::thr(stick), 0.05);
        assert!(stick < 3600, "never handed back");
    }
    assert!((stick - carried.0).abs() <= 20, "handed back at {stick}, carried {carried:?}");
}

#[test]
fn the_descent_cap_grows_with_the_height_at_the_loss() {
    let mut low = hovering_manually_at(0.6);
    let mut high = hovering_manually_at(2.5);
    low.run(Rig::thr(535), STEP_S);
    high.run(Rig::thr(535), STEP_S);
    let (l, h) = (low.cmd.descent_cap_ticks, high.cmd.descent_cap_ticks);
    // 1 s level + 1.5 × the descent at 0.4 m/s + the landing's 0.5 s + 3 s spare.
    let rate = HoldConfig::DEFAULT.fs_descent_rate_m_s;
    let expected = |z: f32| ((FS_LEVEL_S + z / rate * FS_CAP_MARGIN + LAND_TIME_S + FS_CAP_SPARE_S) * TICK_HZ) as i64;
    assert!((i64::from(l) - expected(low.status.height_m)).abs() < 10, "{l}");
    assert!((i64::from(h) - expected(high.status.height_m)).abs() < 10, "{h}");
    assert!(h > l + 4000, "{l} {h}");
}

proptest::proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig::with_cases(64))]

    /// Whatever the bus delivers as a barometer burst (any status, any word, stuck or wild),
    /// the throttle handed to the tick stays a throttle, and everything reported is a number.
    #[test]
    fn no_barometer_input_makes_the_throttle_or_the_report_non_finite(
        bursts in proptest::collection::vec(
            proptest::option::of((proptest::num::u8::ANY, proptest::num::i32::ANY, proptest::num::i16::ANY)),
            1..400,
        ),
        scale in proptest::prop_oneof![proptest::strategy::Just(0.0f32), -100.0f32..100.0],
    ) {
        let mut r = Rig::new(AltMode::Hold);
        r.take_off_to(0.8);
        let cfg = AltitudeSettings {
            mode: AltMode::Hold,
            estimator: AltitudeConfig { thrust_scale_pa: scale, ..AltitudeConfig::DEFAULT },
            ..AltitudeSettings::DEFAULT
        };
        r.v.set_config(&cfg);
        for b in &bursts {
            let burst = b.map(|(st, p, t)| RawBaro { status: st, pressure_counts: p >> 8, temperature_counts: t });
            let input = VerticalInput {
                motors_enabled: true,
                failsafe: false,
                command: StickCounts(CENTRE),
                flown: r.flown(),
                full_scale: FULL_SCALE,
                min_throttle: MIN_THROTTLE,
            };
            let accel = Vec3::new(0.0, 0.0, 1000.0);
            let (cmd, s) = r.v.step(burst, Quat::IDENTITY, accel, &input);
            r.cmd = cmd;
            if let Some(t) = cmd.throttle {
                proptest::prop_assert!((0..=3600).contains(&t.0), "{t:?}");
                proptest::prop_assert!(t.0 == 0 || t > MIN_THROTTLE, "{t:?}");
            }
            proptest::prop_assert!(s.height_m.is_finite() && s.climb_m_s.is_finite(), "{s:?}");
            proptest::prop_assert!(s.target_m.is_none_or(f32::is_finite), "{s:?}");
            proptest::prop_assert!(s.pressure_pa.is_none_or(f32::is_finite) && s.temperature_c.is_finite(), "{s:?}");
        }
    }
}

#[test]
fn non_finite_estimates_never_reach_the_throttle() {
    // The hold's own guard: a NaN or infinite height or climb rate (which the estimator never
    // gives, and a fault elsewhere might) holds the hover, never a NaN cast to a throttle.
    let mut r = Rig::new(AltMode::Hold);
    r.take_off_to(0.8);
    let input = VerticalInput {
        motors_enabled: true,
        failsafe: false,
        command: StickCounts(CENTRE),
        flown: r.flown(),
        full_scale: FULL_SCALE,
        min_throttle: MIN_THROTTLE,
    };
    for (h, v) in [(f32::NAN, 0.0), (0.5, f32::NAN), (f32::INFINITY, f32::NEG_INFINITY), (1e30, -1e30)] {
        let t = r.v.hold(0.0, h, v, &input);
        assert!(t.is_finite() && (f32::from(MIN_THROTTLE.0)..=3600.0).contains(&t), "{h} {v}: {t}");
    }
}

/// An airframe `mass` times the nominal, in manual flight near `height_m` on a throttle found
/// by a pilot: a little above its hover to climb, then its hover.
fn flying_manually(mass: f32, height_m: f32) -> Rig {
    let mut r = Rig::new(AltMode::Manual);
    r.plant.mass_kg = Plant::NOMINAL_KG * mass;
    let hover = (0..3600).find(|&t| Plant::thrust_for(f32::from(t as i16), true) > r.plant.mass_kg * Plant::G).unwrap_or(3600) as i16;
    while r.plant.z_m < height_m {
        r.run(Rig::thr(hover + 60), 0.05);
    }
    r.run(Rig::thr(hover), 1.0);
    r
}

#[test]
fn an_airframe_lighter_than_the_hover_setting_is_seen_airborne_and_its_failsafe_lands() {
    // 0.9 × the nominal mass hovers at about 270 stick counts, under 75 % of ALT_HOVER_US's
    // 530: the throttle alone never says airborne. Above 1 m the barometer does; below it the
    // failsafe's hold takes running motors for flight.
    for (height, loss_at) in [(2.0, "2 m"), (0.6, "0.6 m")] {
        let mut r = flying_manually(0.9, height);
        if height > 1.5 {
            assert!((r.status.height_m - r.plant.z_m).abs() < 0.3, "{loss_at}: estimate {} true {}", r.status.height_m, r.plant.z_m);
        }
        let z = r.plant.z_m;
        r.link = false;
        let mut off = None;
        let mut lowest_running = f32::MAX;
        let mut t = 0.0;
        r.watch(Rig::thr(0), 20.0, |r| {
            t += STEP_S;
            if off.is_none() && r.decision.state == FlightState::FailsafeOff {
                off = Some((t, r.plant.z_m));
            }
            if r.decision.motors_enabled {
                lowest_running = lowest_running.min(r.plant.z_m);
            }
        });
        let (t_off, z_off) = off.unwrap_or_else(|| panic!("{loss_at}: never stage 2"));
        assert_eq!(z_off, 0.0, "{loss_at}: motors off at {z_off} m after {t_off} s (lost at {z} m)");
    }
}

#[test]
fn an_airframe_heavier_than_the_hover_setting_takes_off_holds_and_lands_in_hold() {
    let mut r = Rig::new(AltMode::Hold);
    r.plant.mass_kg = Plant::NOMINAL_KG * 1.2;
    r.take_off_to(1.0);
    let z = r.plant.z_m;
    r.run(Rig::thr(CENTRE), 10.0);
    assert!((r.plant.z_m - z).abs() < 0.2, "{z} -> {}", r.plant.z_m);
    r.run(Rig::thr(0), 12.0);
    assert_eq!(r.plant.z_m, 0.0);
    assert_eq!(r.decision.state, FlightState::Disarmed);
}

/// The landing is seen in half a second of stillness with the throttle low while asked down:
/// an updraught that holds the failsafe's descent still near the floor for less than that is
/// no landing (the motors would stop in the air), on the nominal airframe and on a light one
/// that hovers under three quarters of the hover setting.
#[test]
fn a_gust_that_stops_the_descent_near_the_floor_is_no_landing() {
    for mass in [1.0, 0.9] {
        let mut r = flying_manually(mass, 1.2);
        r.link = false;
        r.sticks = Rig::thr(0);
        let (mut t, mut gust_at, mut still_s) = (0.0, None::<f32>, 0.0);
        let (mut landed_above, mut off_at) = (None, None);
        for _ in 0..(15.0 / STEP_S) as u32 {
            t += STEP_S;
            if gust_at.is_none() && r.status.failsafe_descent && r.plant.z_m < 0.4 {
                gust_at = Some(t);
            }
            let gust = gust_at.is_some_and(|g| t - g < 0.4);
            // Whatever stops the descent within some 50 ms and holds it still, whatever the
            // thrust: the hold's throttle goes low, asked down, the height still.
            let p = &r.plant;
            let push = p.mass_kg * Plant::G - p.thrust_n + Plant::DRAG_N_PER_M_S * p.v_m_s - p.mass_kg * p.v_m_s / 0.05;
            r.plant.updraught_n = if gust { push } else { 0.0 };
            r.step();
            if gust && r.plant.v_m_s.abs() < 0.1 {
                still_s += STEP_S;
            }
            if r.cmd.landed && r.plant.z_m > 0.02 && landed_above.is_none() {
                landed_above = Some(r.plant.z_m);
            }
            if off_at.is_none() && !r.decision.motors_enabled {
                off_at = Some(r.plant.z_m);
            }
        }
        assert!(gust_at.is_some() && still_s > 0.2, "mass {mass}: the gust held it still {still_s} s");
        assert_eq!(landed_above, None, "mass {mass}: landed at {landed_above:?} m");
        assert_eq!(off_at, Some(0.0), "mass {mass}: motors off at {off_at:?} m");
    }
}
