//! The pipeline's steady-flight shortcut, tested where the pipeline takes it: two flight
//! controllers fly the same simulated drone on random stick timelines, one as shipped and one
//! with `set_table_only(true)` (the supervisor decides every tick: the decision in force never
//! stands). Their compare values, outer jobs and `Status`
//! must agree on every tick. The repeat is taken when the radio brought nothing new even
//! though other inputs (the tilt after each outer step, the calibration flags) have changed,
//! so this is the test of its rule, not only of the supervisor alone.

use fcu_core::flight::FlightController;
use fcu_core::imu::RawImu;
use fcu_core::rc::EdgeDecoder;
use fcu_core::supervisor::FlightState;
use fcu_testkit::harness;
use fcu_testkit::sim::radio_model::TimedEdge;
use fcu_testkit::sim::scenario::{self, StickRow, Throttle, Timeline, AIL_CENTRE_US, ELE_CENTRE_US, RUD_CENTRE_US};
use fcu_testkit::sim::{self, ComputerView, FlightComputer, RunOptions, SimError};
use fcu_testkit::Profile;
use proptest::prelude::*;

/// Two controllers in lockstep; the first disagreement stops the flight with its tick.
struct Lockstep {
    shipped: (FlightController, EdgeDecoder),
    table_only: (FlightController, EdgeDecoder),
    ticks: u64,
    /// Ticks flown armed with the motors under stick control (where the shortcuts live).
    armed_ticks: u64,
}

impl Lockstep {
    fn new(profile: Profile) -> Lockstep {
        let build = |table_only: bool| {
            let mut fc = FlightController::new(&profile.config()).unwrap_or_else(|e| panic!("{e}"));
            fc.set_table_only(table_only);
            let decoder = fc.edge_decoder();
            (fc, decoder)
        };
        Lockstep { shipped: build(false), table_only: build(true), ticks: 0, armed_ticks: 0 }
    }
}

impl FlightComputer for Lockstep {
    fn tick_hz(&self) -> f64 {
        f64::from(self.shipped.0.config().timing.tick_hz())
    }

    fn step(&mut self, _t_end_s: f64, edges: &[TimedEdge], imu: RawImu, _battery_v: f64) -> Result<[u16; 4], SimError> {
        let mut outs = Vec::with_capacity(2);
        for (fc, decoder) in [&mut self.shipped, &mut self.table_only] {
            let out = harness::tick(fc, decoder, imu, edges.iter().map(|e| e.edge)).out;
            outs.push((out, fc.status()));
        }
        self.ticks += 1;
        let [(a, sa), (b, sb)] = [outs[0], outs[1]];
        // Compare values, the outer job handed out (if any) and everything `Status` reports.
        if a != b || sa != sb {
            return Err(SimError::Computer(format!("tick {}: shipped {a:?} / {sa:?}, table only {b:?} / {sb:?}", self.ticks)));
        }
        self.armed_ticks += u64::from(sa.state == FlightState::Armed);
        Ok(a.compare)
    }

    fn view(&self) -> ComputerView {
        let st = self.shipped.0.status();
        ComputerView {
            state: st.state,
            armed: st.state.motors_may_run(),
            link: st.link,
            calibrated: st.calibrated,
            ..ComputerView::default()
        }
    }
}

/// A stretch of a random timeline.
#[derive(Clone, Copy, Debug)]
enum Stretch {
    Idle,
    ArmGesture,
    DisarmGesture,
    CalibrateGesture,
    /// Holding a height with the sticks deflected by this much, µs.
    Fly {
        roll_us: f64,
        pitch_us: f64,
        yaw_us: f64,
    },
    ThrottleUs(f64),
    LinkOff,
}

fn stretch() -> impl Strategy<Value = (Stretch, f64)> {
    let deflection = -300.0..300.0f64;
    let kind = prop_oneof![
        1 => Just(Stretch::Idle),
        2 => Just(Stretch::ArmGesture),
        1 => Just(Stretch::DisarmGesture),
        1 => Just(Stretch::CalibrateGesture),
        4 => (deflection.clone(), deflection.clone(), deflection).prop_map(|(roll_us, pitch_us, yaw_us)| Stretch::Fly { roll_us, pitch_us, yaw_us }),
        1 => (1000.0..1600.0f64).prop_map(Stretch::ThrottleUs),
        1 => Just(Stretch::LinkOff),
    ];
    (kind, 0.02..1.5f64)
}

fn row(t_s: f64, s: Stretch) -> StickRow {
    let idle = StickRow::idle(t_s);
    let gesture = |ail: f64, ele: f64, rud: f64| StickRow {
        ail_us: AIL_CENTRE_US + ail,
        ele_us: ELE_CENTRE_US + ele,
        rud_us: RUD_CENTRE_US + rud,
        ..StickRow::idle(t_s)
    };
    match s {
        Stretch::Idle => idle,
        Stretch::ArmGesture => gesture(-325.0, -325.0, 325.0),
        Stretch::DisarmGesture => gesture(0.0, 0.0, -325.0),
        Stretch::CalibrateGesture => gesture(325.0, -325.0, -325.0),
        Stretch::Fly { roll_us, pitch_us, yaw_us } => {
            StickRow { thr: Throttle::HoldAltitude { alt_m: 1.0 }, ..gesture(roll_us, pitch_us, yaw_us) }
        }
        Stretch::ThrottleUs(us) => StickRow { thr: Throttle::Us(us), ..idle },
        Stretch::LinkOff => StickRow { link: false, ..idle },
    }
}

/// Boot, arm and take off, then the random stretches.
fn fly(profile: Profile, stretches: &[(Stretch, f64)], seed: u64) -> Result<Lockstep, String> {
    let mut rows = vec![StickRow::idle(0.0), row(2.5, Stretch::ArmGesture), StickRow::idle(4.0)];
    rows.push(row(4.5, Stretch::Fly { roll_us: 0.0, pitch_us: 0.0, yaw_us: 0.0 }));
    let mut t = 6.0;
    for &(s, d) in stretches {
        rows.push(row(t, s));
        t += d;
    }
    let sc = scenario::from_timeline("lockstep", Timeline { rows }, t);
    let mut computer = Lockstep::new(profile);
    let opts = RunOptions { seed, duration_s: Some(t), substeps: 2, ..RunOptions::default() };
    sim::run_with(&mut computer, &sc, profile, &opts).map_err(|e| e.to_string())?;
    Ok(computer)
}

#[test]
fn a_take_off_and_hover_is_the_same_with_and_without_the_shortcuts() {
    let c =
        fly(Profile::Default, &[(Stretch::Fly { roll_us: 50.0, pitch_us: -80.0, yaw_us: 30.0 }, 3.0)], 1).unwrap_or_else(|e| panic!("{e}"));
    // Not vacuous: the shortcuts had thousands of ticks to differ in.
    assert!(c.armed_ticks > 3000, "armed only {} ticks", c.armed_ticks);
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 24, max_shrink_iters: 40, ..ProptestConfig::default() })]

    #[test]
    fn every_tick_is_the_same_with_and_without_the_shortcuts(
        stretches in prop::collection::vec(stretch(), 1..10),
        seed in 0u64..1000,
    ) {
        match fly(Profile::Default, &stretches, seed) {
            Ok(c) => prop_assert!(c.armed_ticks > 0, "never armed"),
            Err(e) => prop_assert!(false, "{e}"),
        }
    }
}
