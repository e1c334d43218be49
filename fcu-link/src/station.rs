//! The flight controller behind the link: fcu-core's parameter table, configuration and status
//! as the link's [`Vehicle`], one implementation for the firmware and anything else that runs
//! fcu-core behind a ground station.
//!
//! The station holds the configuration in force and a copy of the latest status; its owner
//! (the firmware's link task) feeds it the status, hands the configuration changes it accepts
//! to the control loop ([`Station::take_change`]), hands the commands it accepts to the control
//! tick ([`Station::take_ground`]) and does the flash work it asks for ([`Station::save_due`],
//! [`Station::saved`]). It decides what a ground station may do, with the rules of fcu-core's
//! parameter table and of [`fcu_core::ground`] (which the control tick applies again with the
//! state it is in); the owner only moves bytes and words.
//!
//! A save first tells the control tick ([`GroundInput::saving`]), which refuses to arm from
//! then on, and starts only once two status snapshots taken after that show the refusal
//! ([`Blocker::GroundBusy`]) with the board disarmed: the first may predate the tick taking
//! the input. An erase stalls every instruction fetch, the control tick's included.

use fcu_core::flight::Status;
use fcu_core::ground::{self, Disarm, GroundInput, MotorTest, MotorTestChange};
use fcu_core::parameters::{self, snapshot, RULE_ARMED};
use fcu_core::rc::COUNTS_PER_US;
use fcu_core::supervisor::{Blocker, FlightState, SupervisorConfig};
use fcu_core::Config;

use crate::rates::Rates;
use crate::vehicle::{Attitude, Battery, Health, Param, ParamMask, Request, SystemStatus, Vehicle, VehicleState};

/// How long after the last parameter change a save waits, so that a ground station setting
/// twenty parameters in a row (a radio calibration) costs one erase, not twenty.
pub const SAVE_DEBOUNCE_MS: u32 = 2000;

// A set reports every parameter it changed in a mask: the table must fit in one.
const _: () = assert!(parameters::COUNT <= ParamMask::CAPACITY);

/// Status snapshots showing the save's arming refusal before the save starts (see the module
/// docs).
const SAVE_CONFIRMATIONS: u8 = 2;

pub struct Station {
    cfg: Config,
    defaults: &'static Config,
    status: Option<Status>,
    battery_mv: u16,
    /// Radio pulse widths, capture counts, by input (0: none yet).
    rc_widths_counts: [u16; 4],
    now_ms: u32,
    /// A configuration the control loop has not taken yet.
    change_pending: bool,
    /// When the parameters in RAM differ from flash: the time of the last change.
    unsaved_since_ms: Option<u32>,
    /// A save asked for by the ground station: at once, not after the debounce.
    save_asked: bool,
    reboot_asked: bool,
    /// The commands for the control tick not taken yet, and the save's level.
    ground: GroundInput,
    /// `ground` differs from what the control tick last took.
    ground_pending: bool,
    /// Snapshots since the save's level went out that show it in force (see the module docs).
    saving_confirmed: u8,
}

impl Station {
    /// `cfg` is the configuration the board booted with, `defaults` what a reset restores.
    pub fn new(cfg: Config, defaults: &'static Config) -> Station {
        Station {
            cfg,
            defaults,
            status: None,
            battery_mv: 0,
            rc_widths_counts: [0; 4],
            now_ms: 0,
            change_pending: false,
            unsaved_since_ms: None,
            save_asked: false,
            reboot_asked: false,
            ground: GroundInput::default(),
            ground_pending: false,
            saving_confirmed: 0,
        }
    }

    /// The latest status from the control loop, the battery and the radio's widths.
    pub fn observe(&mut self, status: &Status, battery_mv: u32, rc_widths_counts: [u16; 4], now_ms: u32) {
        self.status = Some(*status);
        self.battery_mv = battery_mv.min(u32::from(u16::MAX)) as u16;
        self.rc_widths_counts = rc_widths_counts;
        self.now_ms = now_ms;
        let refusing = !status.state.armed() && status.blockers.contains(Blocker::GroundBusy);
        self.saving_confirmed =
            if self.ground.saving && !self.ground_pending && refusing { self.saving_confirmed.saturating_add(1) } else { 0 };
    }

    /// The configuration in force.
    pub fn config(&self) -> &Config {
        &self.cfg
    }

    /// The link's telemetry rates in this configuration.
    pub fn rates(&self) -> Rates {
        let period = |hz: u8| (1000 / u16::from(hz.max(1))).max(1);
        Rates {
            attitude_ms: period(self.cfg.link.attitude_hz),
            rc_channels_ms: period(self.cfg.link.rc_hz),
            servo_output_ms: period(self.cfg.link.rc_hz),
            ..Rates::DEFAULT
        }
    }

    /// A changed configuration for the control loop, once: both halves must take it.
    pub fn take_change(&mut self) -> Option<Config> {
        core::mem::take(&mut self.change_pending).then_some(self.cfg)
    }

    /// What the control tick is to take ([`fcu_core::flight::ControlTick::take_ground`]): the
    /// commands accepted since the last call, and whether a save is wanted; `None` when nothing
    /// changed.
    pub fn take_ground(&mut self) -> Option<GroundInput> {
        let saving = self.save_wanted();
        if saving != self.ground.saving {
            self.ground.saving = saving;
            self.ground_pending = true;
        }
        if !core::mem::take(&mut self.ground_pending) {
            return None;
        }
        let input = self.ground;
        self.ground = GroundInput { saving, ..GroundInput::default() };
        Some(input)
    }

    /// Whether the parameters should be written to flash now: asked for, or changed and left
    /// alone for [`SAVE_DEBOUNCE_MS`]; never while armed; and only once the control tick
    /// refuses to arm for it (see the module docs). The reference's supervisor has no such
    /// refusal: only the armed state counts there.
    pub fn save_due(&self) -> bool {
        let confirmed = self.ground.saving && self.saving_confirmed >= SAVE_CONFIRMATIONS;
        self.save_wanted() && (confirmed || !self.safe_supervisor())
    }

    fn safe_supervisor(&self) -> bool {
        matches!(self.cfg.supervisor, SupervisorConfig::Safe(_))
    }

    fn save_wanted(&self) -> bool {
        if self.armed() {
            return false;
        }
        let settled = self.unsaved_since_ms.is_some_and(|t| self.now_ms.wrapping_sub(t) >= SAVE_DEBOUNCE_MS);
        self.save_asked || settled
    }

    /// The words to write for a save, given the sectors as they are.
    pub fn plan_save(&self, sectors: [&[u32]; 2]) -> snapshot::SavePlan {
        snapshot::plan_save(sectors, &parameters::values(&self.cfg))
    }

    /// The save was written (or failed: `ok` false keeps it due, for a later try).
    pub fn saved(&mut self, ok: bool) {
        if ok {
            self.unsaved_since_ms = None;
        }
        self.save_asked = false;
    }

    /// Whether a save is still to be made (a reboot waits for it).
    pub fn unsaved(&self) -> bool {
        self.unsaved_since_ms.is_some() || self.save_asked
    }

    /// A reboot was asked for (the link says when its acknowledgement is out).
    pub fn reboot_asked(&self) -> bool {
        self.reboot_asked
    }

    /// Out of line: most rules ask it.
    #[inline(never)]
    fn armed(&self) -> bool {
        self.status.is_some_and(|s| s.state.armed())
    }

    /// The supervisor's state as last seen (calibrating until the first status).
    fn flight_state(&self) -> FlightState {
        self.status.map_or(FlightState::Calibrating, |s| s.state)
    }

    /// The commands for the control tick, to add one to; the safe supervisor's only. Not
    /// generic over what is added (a closure each): one copy for every command.
    fn for_tick(&mut self) -> Result<&mut GroundInput, &'static str> {
        if !self.safe_supervisor() {
            return Err(ground::RULE_REFERENCE);
        }
        self.ground_pending = true;
        Ok(&mut self.ground)
    }

    fn changed(&mut self) {
        self.change_pending = true;
        self.unsaved_since_ms = Some(self.now_ms);
    }
}

impl Vehicle for Station {
    fn state(&self) -> VehicleState {
        let Some(s) = self.status else {
            return VehicleState {
                armed: false,
                in_air: false,
                throttle_low: true,
                status: SystemStatus::Boot,
                attitude: Attitude::default(),
                rc_widths_us: [0; 8],
                rc_channel_count: 0,
                motor_outputs_us: [1000; 4],
                battery: Battery { voltage_mv: self.battery_mv, current_ca: -1, remaining_pct: -1 },
                health: Health { imu: false, radio: false, estimator: false, battery: true, prearm: false },
                load_permille: 0,
            };
        };
        let armed = self.armed();
        let status = match s.state {
            FlightState::Calibrating => SystemStatus::Boot,
            FlightState::Disarmed => SystemStatus::Standby,
            FlightState::Arming | FlightState::Armed => SystemStatus::Active,
            FlightState::FailsafeLevel | FlightState::FailsafeOff | FlightState::Fault => SystemStatus::Critical,
        };
        let mut rc_widths_us = [0u16; 8];
        for (out, &w) in rc_widths_us.iter_mut().zip(self.rc_widths_counts.iter()) {
            *out = (u32::from(w) / COUNTS_PER_US) as u16;
        }
        let throttle_low = self.cfg.rc.throttle_low(&s.sticks);
        let arr = u32::from(self.cfg.mixer.timer_arr) + 1;
        let motor_outputs_us = s.compare.map(|c| (1000 + u32::from(c) * 1000 / arr).min(2000) as u16);
        VehicleState {
            armed,
            in_air: armed && !throttle_low,
            throttle_low,
            status,
            attitude: Attitude {
                roll_rad: s.tilt.roll_rad,
                pitch_rad: s.tilt.pitch_rad,
                // fcu-core's heading turns anticlockwise seen from above; MAVLink's clockwise.
                yaw_rad: -s.yaw_est_rad,
                roll_rate_rad_s: 0.0,
                pitch_rate_rad_s: 0.0,
                yaw_rate_rad_s: 0.0,
            },
            rc_widths_us,
            rc_channel_count: 4,
            motor_outputs_us,
            battery: Battery { voltage_mv: self.battery_mv, current_ca: -1, remaining_pct: -1 },
            health: Health {
                imu: s.fault.is_none(),
                radio: s.link,
                estimator: s.calibrated,
                battery: true,
                prearm: armed || (s.state == FlightState::Disarmed && s.blockers.is_empty()),
            },
            load_permille: 0,
        }
    }

    fn param_count(&self) -> u16 {
        parameters::count() as u16
    }

    fn param(&self, index: u16) -> Option<Param> {
        let i = usize::from(index);
        Some(Param { name: parameters::name(i)?, value: parameters::value(&self.cfg, i)? })
    }

    fn param_index(&self, name: &[u8]) -> Option<u16> {
        parameters::index_of(name).map(|i| i as u16)
    }

    fn set_param(&mut self, index: u16, value: f32) -> Result<ParamMask, &'static str> {
        let i = usize::from(index);
        // Compared by value: -0.0 for a 0.0 is no change (no save, and taken armed too), where
        // fcu-core's set, comparing bit patterns, would take it as a new value.
        if parameters::value(&self.cfg, i) == Some(value) {
            return Ok(ParamMask::EMPTY);
        }
        let armed = self.armed();
        let mut next = self.cfg;
        parameters::set(&mut next, i, value, armed).map_err(|r| r.rule)?;
        // Every parameter the set moved, whatever the reason (RCMAP_* form a permutation: one
        // set swaps the channel another had), so that the ground station hears of each.
        let mut others = ParamMask::EMPTY;
        let mut any = false;
        for j in 0..parameters::count() {
            if parameters::value(&self.cfg, j) != parameters::value(&next, j) {
                any = true;
                if j != i {
                    others.insert(j as u16);
                }
            }
        }
        if any {
            fcu_core::flight::check_change(&self.cfg, &next, armed).map_err(|e| e.rule())?;
            self.cfg = next;
            self.changed();
        }
        Ok(others)
    }

    fn request(&mut self, request: Request) -> Result<(), &'static str> {
        match request {
            Request::SaveParams if self.armed() => Err(RULE_ARMED),
            Request::SaveParams => {
                self.save_asked = true;
                Ok(())
            }
            Request::ResetParams if self.armed() => Err(RULE_ARMED),
            Request::ResetParams => {
                fcu_core::flight::check_change(&self.cfg, self.defaults, false).map_err(|e| e.rule())?;
                if !self.cfg.is_same_as(self.defaults) {
                    self.cfg = *self.defaults;
                    self.changed();
                }
                Ok(())
            }
            Request::Reboot if self.armed() => Err(RULE_ARMED),
            Request::Reboot => {
                self.reboot_asked = true;
                Ok(())
            }
            Request::Disarm { forced } => {
                let throttle_low = self.status.is_none_or(|s| self.cfg.rc.throttle_low(&s.sticks));
                ground::disarm_rule(self.flight_state(), throttle_low, forced)?;
                self.for_tick()?.disarm = Some(Disarm { forced });
                Ok(())
            }
            Request::CalibrateImu => {
                ground::ground_test_rule(self.flight_state())?;
                self.for_tick()?.calibrate_imu = true;
                Ok(())
            }
            Request::CalibrateRadio => {
                ground::ground_test_rule(self.flight_state())?;
                self.for_tick()?.radio_calibration = Some(true);
                Ok(())
            }
            Request::EndCalibration => {
                self.for_tick()?.radio_calibration = Some(false);
                Ok(())
            }
            Request::MotorTest { motor, throttle_pct, duration_ms } => {
                ground::ground_test_rule(self.flight_state())?;
                if motor >= ground::MOTORS {
                    return Err(ground::RULE_NO_SUCH_MOTOR);
                }
                let test = MotorTest { motor, duty_pct: ground::capped_duty_pct(throttle_pct), duration_ms: u32::from(duration_ms) };
                self.for_tick()?.motor_test = Some(MotorTestChange::Start(test));
                Ok(())
            }
            Request::StopMotorTest => {
                self.for_tick()?.motor_test = Some(MotorTestChange::Stop);
                Ok(())
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use fcu_core::flight::FlightController;
    use fcu_core::rc::Sticks;
    use fcu_core::supervisor::Blockers;

    fn status(state: FlightState, sticks: Sticks, blockers: Blockers) -> Status {
        let mut s = FlightController::new(Config::default()).unwrap().status();
        s.state = state;
        s.sticks = sticks;
        s.blockers = blockers;
        s
    }

    const REST: Sticks = Sticks::new(0, 0, 0, 0);
    const UP: Sticks = Sticks::new(0, 0, 1500, 0);

    fn station_in(state: FlightState, sticks: Sticks) -> Station {
        let mut st = Station::new(Config::default(), &Config::DEFAULT);
        st.observe(&status(state, sticks, Blockers::default()), 3900, [0; 4], 1000);
        st
    }

    fn motor_test(motor: u8, throttle_pct: f32) -> Request {
        Request::MotorTest { motor, throttle_pct, duration_ms: 2000 }
    }

    #[test]
    fn a_disarm_goes_to_the_tick_on_the_ground_and_in_the_air_only_forced() {
        let mut st = station_in(FlightState::Armed, REST);
        assert_eq!(st.request(Request::Disarm { forced: false }), Ok(()));
        assert_eq!(st.take_ground().and_then(|g| g.disarm), Some(Disarm { forced: false }));
        assert_eq!(st.take_ground(), None, "taken once");

        let mut st = station_in(FlightState::Armed, UP);
        assert_eq!(st.request(Request::Disarm { forced: false }), Err(ground::RULE_THROTTLE_NOT_LOW));
        assert_eq!(st.take_ground(), None, "a refusal sends nothing");
        assert_eq!(st.request(Request::Disarm { forced: true }), Ok(()));
        assert_eq!(st.take_ground().and_then(|g| g.disarm), Some(Disarm { forced: true }));

        let mut st = station_in(FlightState::FailsafeLevel, REST);
        assert_eq!(st.request(Request::Disarm { forced: false }), Err(ground::RULE_FAILSAFE_LEVEL));
    }

    #[test]
    fn a_motor_test_goes_to_the_tick_disarmed_only_capped() {
        let mut st = station_in(FlightState::Disarmed, REST);
        assert_eq!(st.request(motor_test(3, 90.0)), Ok(()));
        let test = MotorTest { motor: 3, duty_pct: ground::MOTOR_TEST_MAX_DUTY_PCT, duration_ms: 2000 };
        assert_eq!(st.take_ground().and_then(|g| g.motor_test), Some(MotorTestChange::Start(test)));
        assert_eq!(st.request(Request::StopMotorTest), Ok(()));
        assert_eq!(st.take_ground().and_then(|g| g.motor_test), Some(MotorTestChange::Stop));
        assert_eq!(st.request(motor_test(4, 5.0)), Err(ground::RULE_NO_SUCH_MOTOR));

        for state in [FlightState::Arming, FlightState::Armed, FlightState::FailsafeLevel] {
            let mut st = station_in(state, REST);
            assert_eq!(st.request(motor_test(0, 5.0)), Err(ground::RULE_DISARMED_ONLY), "{state:?}");
            assert_eq!(st.take_ground(), None);
        }
        assert_eq!(station_in(FlightState::Calibrating, REST).request(motor_test(0, 5.0)), Err(ground::RULE_CALIBRATING));
        // No status yet: the board is still booting.
        let mut st = Station::new(Config::default(), &Config::DEFAULT);
        assert_eq!(st.request(motor_test(0, 5.0)), Err(ground::RULE_CALIBRATING));
    }

    #[test]
    fn calibrations_go_to_the_tick_disarmed_only_and_an_end_always() {
        let mut st = station_in(FlightState::Disarmed, REST);
        assert_eq!(st.request(Request::CalibrateImu), Ok(()));
        assert_eq!(st.request(Request::CalibrateRadio), Ok(()));
        let g = st.take_ground().unwrap();
        assert!(g.calibrate_imu);
        assert_eq!(g.radio_calibration, Some(true));

        let mut st = station_in(FlightState::Armed, REST);
        assert_eq!(st.request(Request::CalibrateImu), Err(ground::RULE_DISARMED_ONLY));
        assert_eq!(st.request(Request::CalibrateRadio), Err(ground::RULE_DISARMED_ONLY));
        assert_eq!(st.take_ground(), None);
        assert_eq!(st.request(Request::EndCalibration), Ok(()));
        assert_eq!(st.take_ground().and_then(|g| g.radio_calibration), Some(false));
    }

    #[test]
    fn the_reference_supervisor_takes_no_command() {
        const CFG: Config = Config { supervisor: SupervisorConfig::Reference, ..Config::DEFAULT };
        let mut st = Station::new(CFG, &CFG);
        st.observe(&status(FlightState::Disarmed, REST, Blockers::default()), 3900, [0; 4], 0);
        assert_eq!(st.request(Request::CalibrateImu), Err(ground::RULE_REFERENCE));
        assert_eq!(st.request(motor_test(0, 5.0)), Err(ground::RULE_REFERENCE));
        assert_eq!(st.take_ground(), None);
        // A save has no arming refusal to wait for there.
        assert_eq!(st.request(Request::SaveParams), Ok(()));
        assert!(st.save_due());
    }

    #[test]
    fn the_pre_arm_check_is_healthy_disarmed_without_a_blocker_and_armed() {
        let mut busy = Blockers::default();
        busy.insert(Blocker::GroundBusy);
        for (state, blockers, ready) in [
            (FlightState::Disarmed, Blockers::default(), true),
            (FlightState::Disarmed, busy, false),
            (FlightState::Calibrating, Blockers::default(), false),
            (FlightState::Armed, Blockers::default(), true),
        ] {
            let mut st = Station::new(Config::default(), &Config::DEFAULT);
            st.observe(&status(state, REST, blockers), 3900, [0; 4], 0);
            assert_eq!(st.state().health.prearm, ready, "{state:?} {blockers:?}");
        }
    }

    #[test]
    fn a_save_waits_until_the_tick_refuses_to_arm_for_it() {
        let mut st = station_in(FlightState::Disarmed, REST);
        let idle = status(FlightState::Disarmed, REST, Blockers::default());
        let mut busy = idle;
        busy.blockers.insert(Blocker::GroundBusy);
        assert_eq!(st.request(Request::SaveParams), Ok(()));
        assert!(!st.save_due(), "the tick does not know yet");
        assert_eq!(st.take_ground().map(|g| g.saving), Some(true));
        // A snapshot that does not show the refusal, then one that may predate the tick's take.
        st.observe(&idle, 3900, [0; 4], 1005);
        st.observe(&busy, 3900, [0; 4], 1010);
        assert!(!st.save_due());
        st.observe(&busy, 3900, [0; 4], 1015);
        assert!(st.save_due());
        // Armed meanwhile (the refusal came too late): no save.
        let mut armed = busy;
        armed.state = FlightState::Armed;
        st.observe(&armed, 3900, [0; 4], 1020);
        assert!(!st.save_due());
        st.observe(&busy, 3900, [0; 4], 1025);
        st.observe(&busy, 3900, [0; 4], 1030);
        assert!(st.save_due());
        // Calibrating or faulted, the board cannot arm either: the refusal is what counts.
        let mut faulted = busy;
        faulted.state = FlightState::Fault;
        st.observe(&faulted, 3900, [0; 4], 1035);
        assert!(st.save_due());
        st.saved(true);
        assert!(!st.save_due());
        assert_eq!(st.take_ground().map(|g| g.saving), Some(false), "arming allowed again");
        assert_eq!(st.take_ground(), None);
    }

    fn index(name: &str) -> u16 {
        parameters::index_of(name.as_bytes()).unwrap() as u16
    }

    #[test]
    fn a_set_reports_every_other_parameter_it_changed() {
        let mut st = station_in(FlightState::Disarmed, REST);
        let changed = st.set_param(index("RCMAP_ROLL"), 3.0).unwrap();
        let mut expected = ParamMask::EMPTY;
        expected.insert(index("RCMAP_THROTTLE"));
        assert_eq!(changed, expected);
        assert_eq!(st.param(index("RCMAP_THROTTLE")).map(|p| p.value), Some(1.0));
        // A set that moves nothing else reports nothing else.
        assert_eq!(st.set_param(index("RC_TIMEOUT_MS"), 100.0), Ok(ParamMask::EMPTY));
    }

    /// The link in front of the station: what a ground station hears back of a set.
    fn echo(st: &mut Station, name: &str, value: f32) -> Vec<f32> {
        use crate::test_support::{drain, param_set, param_values, v2};
        let mut link: crate::Link<512> = crate::Link::default();
        link.receive(&v2(&param_set(name, value)), 0, st);
        param_values(&drain(&mut link)).into_iter().map(|p| p.1).collect()
    }

    #[test]
    fn minus_zero_is_not_taken_as_a_change() {
        let mut st = station_in(FlightState::Disarmed, REST);
        assert_eq!(parameters::value(st.config(), usize::from(index("RATE_YAW_I"))), Some(0.0));
        let echoed = echo(&mut st, "RATE_YAW_I", -0.0);
        assert_eq!(echoed.len(), 1);
        assert_eq!(echoed[0].to_bits(), 0.0f32.to_bits(), "the value in force is echoed, not the -0.0 sent");
        assert!(!st.unsaved(), "no save");
        assert_eq!(st.take_change(), None, "nothing for the control loop");

        // Armed, a parameter only changed disarmed takes the value it already has, -0.0 too.
        let mut st = station_in(FlightState::Disarmed, REST);
        assert_eq!(echo(&mut st, "YAW_DEADBAND_US", 0.0), [0.0]);
        st.saved(true);
        let _ = st.take_change();
        st.observe(&status(FlightState::Armed, REST, Blockers::default()), 3900, [0; 4], 1000);
        assert_eq!(st.set_param(index("YAW_DEADBAND_US"), -0.0), Ok(ParamMask::EMPTY));
        assert!(!st.unsaved());
        assert_eq!(st.take_change(), None);
    }
}
