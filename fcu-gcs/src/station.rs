//! The flight controller behind the link: fcu-core's parameter table, configuration and status
//! as the link's [`Vehicle`], one implementation for the firmware and anything else that runs
//! fcu-core behind a ground station.
//!
//! The station holds the configuration in force and a copy of the latest status; its owner
//! (the firmware's link task) feeds it the status, hands the configuration changes it accepts
//! to the control loop ([`Station::take_change`]), hands the commands it accepts to the control
//! tick ([`Station::take_gcs`]) and does the flash work it asks for ([`Station::save_due`],
//! [`Station::saved`]). It answers a ground station with the verdicts of fcu-core's parameter
//! table and of [`fcu_core::gcs`] (which the control tick applies again with the state it is
//! in), adding only the rules of its own work (a save or reboot pending, the reference
//! supervisor); the link maps the verdict to MAVLink's answer, and the owner only moves bytes
//! and words.
//!
//! # Deferred actions
//!
//! A save and a reboot are not carried out when they are asked for: a save waits for the
//! changes to settle, both wait for the acknowledgement to leave. Each first tells the control
//! tick ([`GcsInput::saving`], [`GcsInput::rebooting`]), which refuses to arm from then on
//! with a blocker of its own ([`Blocker::Saving`], [`Blocker::RebootPending`]), and is due only
//! once two status snapshots taken after that show the refusal with the board disarmed (the
//! first may predate the tick taking the input). [`Station::due`] asks again at the instant the
//! owner acts. An asked-for save or reboot that cannot be carried out within
//! [`ACTION_TIMEOUT_MS`], or that finds the board armed (it armed before the refusal reached the
//! tick), is dropped with a text saying so ([`Station::take_notice`]). An erase stalls every
//! instruction fetch, the control tick's included; a reset stops the motors.
//!
//! A motor test or a calibration is refused while a save or a reboot is pending.
//!
//! # Set-mode
//!
//! A ground station's set-mode (manual throttle or altitude hold) is carried out as a set of
//! the parameter [`ALT_MODE`], found in fcu-params' table by name: the same checks as a
//! PARAM_SET of it (its range, whether it may change armed, the configuration's validation),
//! the same save after the debounce, and the link echoes its PARAM_VALUE. A table without the
//! parameter refuses it ([`gcs::RULE_NO_ALTITUDE_HOLD`]); a set the table refuses is refused
//! with the table's rule (for now when it is the armed one).

use fcu_core::altitude::{AltMode, AltitudeStatus};
use fcu_core::flight::{ChangeKind, ConfigChange, Status};
use fcu_core::gcs::{self, Disarm, GcsInput, MotorTest, MotorTestChange, Refused};
use fcu_core::rc::COUNTS_PER_US;
use fcu_core::supervisor::{Blocker, FlightState, SupervisorConfig};
use fcu_core::Config;
use fcu_params::{self as parameters, snapshot};

use fcu_link::{Altitude, Attitude, Battery, Health, Param, ParamMask, Rates, Request, Vehicle, VehicleState, VerticalMode};

/// The parameter a set-mode sets: the pilot's vertical mode (0 manual, 1 altitude hold).
pub const ALT_MODE: &[u8] = b"ALT_MODE";

/// How long after the last parameter change a save waits, so that a ground station setting
/// twenty parameters in a row (a radio calibration) costs one erase, not twenty.
pub const SAVE_DEBOUNCE_MS: u32 = 2000;

// A set reports every parameter it changed in a mask: the table must fit in one.
const _: () = assert!(parameters::COUNT <= ParamMask::CAPACITY);

/// Status snapshots showing the arming refusal before a save or a reboot is due (see the module
/// docs).
const HOLD_CONFIRMATIONS: u8 = 2;

/// How long an asked-for save or reboot may wait for the arming refusal to show before it is
/// dropped: the refusal takes a tick and a status snapshot (milliseconds); the wait is for a
/// control loop that has stopped reporting, or a flood that keeps the link from going quiet.
pub const ACTION_TIMEOUT_MS: u32 = 5000;

/// Rule: nothing new starts while a save is pending.
pub const RULE_SAVING: &str = "save pending";
/// Rule: nothing new starts while a reboot is pending.
pub const RULE_REBOOTING: &str = "reboot pending";

/// Flash or reset work the owner is to carry out now ([`Station::due`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Due {
    Nothing,
    /// Write the parameters ([`Station::plan_save`]), then report with [`Station::saved`].
    Save,
    /// Reset the board.
    Reboot,
}

#[derive(Clone)]
pub struct Station {
    cfg: Config,
    defaults: &'static Config,
    status: Option<Status>,
    battery_mv: u16,
    /// Radio pulse widths, capture counts, by input (0: none yet).
    rc_widths_counts: [u16; 4],
    now_ms: u32,
    /// A configuration the control loop has not taken yet: what all the changes since the last
    /// one it took reach, together.
    change_pending: Option<ChangeKind>,
    /// When the parameters in RAM differ from flash: the time of the last change.
    unsaved_since_ms: Option<u32>,
    /// A save asked for by the ground station (at once, not after the debounce): when.
    save_asked_ms: Option<u32>,
    /// A reboot asked for: when.
    reboot_asked_ms: Option<u32>,
    /// The commands for the control tick not taken yet, and the levels of the save and the
    /// reboot.
    gcs: GcsInput,
    /// `gcs` differs from what the control tick last took.
    gcs_pending: bool,
    /// Snapshots since the levels went out that show them in force (see the module docs).
    hold_confirmed: u8,
    /// A dropped action's text, for the ground station.
    notice: Option<&'static [u8]>,
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
            change_pending: None,
            unsaved_since_ms: None,
            save_asked_ms: None,
            reboot_asked_ms: None,
            gcs: GcsInput::default(),
            gcs_pending: false,
            hold_confirmed: 0,
            notice: None,
        }
    }

    /// The latest status from the control loop, the battery and the radio's widths.
    pub fn observe(&mut self, status: &Status, battery_mv: u32, rc_widths_counts: [u16; 4], now_ms: u32) {
        self.status = Some(*status);
        self.battery_mv = battery_mv.min(u32::from(u16::MAX)) as u16;
        self.rc_widths_counts = rc_widths_counts;
        self.now_ms = now_ms;
        let held = self.gcs.saving || self.gcs.rebooting;
        let shows = |level: bool, blocker: Blocker| !level || status.blockers.contains(blocker);
        let refusing = !status.state.changes_restricted()
            && shows(self.gcs.saving, Blocker::Saving)
            && shows(self.gcs.rebooting, Blocker::RebootPending);
        self.hold_confirmed = if held && !self.gcs_pending && refusing { self.hold_confirmed.saturating_add(1) } else { 0 };
        if matches!(status.state, FlightState::Armed | FlightState::FailsafeLevel) {
            // Armed before the refusal reached the tick: what was asked cannot be done now,
            // and is not to be done by surprise later. (An arming gesture under way is ended
            // by the refusal: the action waits for it.)
            if self.reboot_asked_ms.take().is_some() {
                self.notice = Some(b"reboot dropped: the board armed");
            }
            if self.save_asked_ms.take().is_some() {
                self.notice = Some(if self.unsaved_since_ms.is_some() {
                    b"save dropped: the board armed (the changes are saved after the disarm)"
                } else {
                    b"save dropped: the board armed"
                });
            }
        }
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
    pub fn take_change(&mut self) -> Option<ConfigChange> {
        self.change_pending.take().map(|kind| ConfigChange { cfg: self.cfg, kind })
    }

    /// What the control tick is to take ([`fcu_core::flight::ControlTick::take_gcs`]): the
    /// commands accepted since the last call, and whether a save is wanted; `None` when nothing
    /// changed.
    pub fn take_gcs(&mut self) -> Option<GcsInput> {
        let saving = self.save_wanted();
        let rebooting = self.reboot_asked_ms.is_some();
        if (saving, rebooting) != (self.gcs.saving, self.gcs.rebooting) {
            self.gcs.saving = saving;
            self.gcs.rebooting = rebooting;
            self.gcs_pending = true;
        }
        if !core::mem::take(&mut self.gcs_pending) {
            return None;
        }
        let input = self.gcs;
        self.gcs = GcsInput { saving, rebooting, ..GcsInput::default() };
        Some(input)
    }

    /// The flash or reset work to carry out now, asked at the instant the owner would act: a
    /// save ([`Station::save_due`]) first, then a reboot once nothing is left unsaved; an
    /// asked-for action past [`ACTION_TIMEOUT_MS`] is dropped instead
    /// ([`Station::take_notice`]). The owner acts on the answer at once, with nothing in
    /// between that could let the board arm.
    pub fn due(&mut self) -> Due {
        let late = |asked: Option<u32>| asked.is_some_and(|t| self.now_ms.wrapping_sub(t) >= ACTION_TIMEOUT_MS);
        if late(self.save_asked_ms) {
            self.save_asked_ms = None;
            self.notice = Some(b"save dropped: arming refusal not confirmed in 5 s");
        }
        if late(self.reboot_asked_ms) {
            self.reboot_asked_ms = None;
            self.notice = Some(b"reboot dropped: arming refusal not confirmed in 5 s");
        }
        if self.save_due() {
            Due::Save
        } else if self.reboot_due() {
            Due::Reboot
        } else {
            Due::Nothing
        }
    }

    /// Whether a save or a reboot waits only for the link to go quiet: the owner stops
    /// feeding the UART, so that the acknowledgement is out and no byte is mid-way when the
    /// CPU stalls or resets.
    pub fn action_imminent(&self) -> bool {
        self.save_due() || self.reboot_due()
    }

    /// A text for the ground station about an action dropped (see [`Station::due`]), once.
    pub fn take_notice(&mut self) -> Option<&'static [u8]> {
        self.notice.take()
    }

    /// Whether the parameters should be written to flash now: asked for, or changed and left
    /// alone for [`SAVE_DEBOUNCE_MS`]; never while armed; and only once the control tick
    /// refuses to arm for it (see the module docs). The reference's supervisor has no such
    /// refusal: only the armed state counts there.
    pub fn save_due(&self) -> bool {
        self.save_wanted() && self.held(self.gcs.saving)
    }

    /// Whether the board should reset now: asked for, nothing left to save, and the control
    /// tick refuses to arm for it.
    fn reboot_due(&self) -> bool {
        self.reboot_asked_ms.is_some() && !self.unsaved() && self.held(self.gcs.rebooting)
    }

    /// The control tick shows the refusal `level` asks for (always, for the reference's
    /// supervisor, which has none).
    fn held(&self, level: bool) -> bool {
        let confirmed = level && !self.gcs_pending && self.hold_confirmed >= HOLD_CONFIRMATIONS;
        !self.armed() && (confirmed || !self.safe_supervisor())
    }

    fn safe_supervisor(&self) -> bool {
        matches!(self.cfg.supervisor, SupervisorConfig::Safe(_))
    }

    /// A save is wanted: asked for, settled after a change, or before an asked-for reboot;
    /// never while armed or while a motor test runs.
    fn save_wanted(&self) -> bool {
        if self.armed() || self.motor_test_running() {
            return false;
        }
        let settled = self.unsaved_since_ms.is_some_and(|t| self.now_ms.wrapping_sub(t) >= SAVE_DEBOUNCE_MS);
        let before_reboot = self.reboot_asked_ms.is_some() && self.unsaved_since_ms.is_some();
        self.save_asked_ms.is_some() || settled || before_reboot
    }

    /// The last status shows a motor test running (or a stick it stopped not yet back).
    fn motor_test_running(&self) -> bool {
        self.status.is_some_and(|s| s.blockers.contains(Blocker::MotorTest))
    }

    /// The words to write for a save, given the sectors as they are.
    pub fn plan_save(&self, sectors: [&[u32]; 2]) -> snapshot::SavePlan {
        snapshot::plan_save(sectors, &parameters::values(&self.cfg))
    }

    /// The save was written (or failed: `ok` false keeps it due, for a later try).
    pub fn saved(&mut self, ok: bool) {
        if ok {
            self.unsaved_since_ms = None;
        } else {
            self.save_failed();
        }
        self.save_asked_ms = None;
    }

    /// A save was due but the supply is too low for the flash's writes (under 2.7 V): not
    /// attempted, said, and tried again after [`SAVE_DEBOUNCE_MS`] if the changes are still
    /// unsaved.
    pub fn supply_low(&mut self) {
        self.save_failed();
        self.save_asked_ms = None;
        self.notice = Some(b"parameters NOT saved: supply below 2.7 V");
    }

    /// A save failed or was not attempted: a reboot waiting for it is dropped (it would lose
    /// the changes: the ground station decides again), and the changes wait a debounce before
    /// the next try, not one link period.
    fn save_failed(&mut self) {
        if self.reboot_asked_ms.take().is_some() {
            self.notice = Some(b"reboot dropped: the save before it failed");
        }
        if self.unsaved_since_ms.is_some() {
            self.unsaved_since_ms = Some(self.now_ms);
        }
    }

    /// Whether a save is still to be made (a reboot waits for it).
    pub fn unsaved(&self) -> bool {
        self.unsaved_since_ms.is_some() || self.save_asked_ms.is_some()
    }

    /// A reboot was asked for and is pending.
    pub fn reboot_asked(&self) -> bool {
        self.reboot_asked_ms.is_some()
    }

    /// Why a new motor test or calibration may not start now: a save or a reboot is pending.
    fn pending_rule(&self) -> Result<(), Refused> {
        if self.reboot_asked_ms.is_some() {
            Err(Refused::denied(RULE_REBOOTING))
        } else if self.save_wanted() || self.gcs.saving {
            Err(Refused::denied(RULE_SAVING))
        } else {
            Ok(())
        }
    }

    /// Changes are restricted ([`FlightState::changes_restricted`]), as the last status shows.
    fn armed(&self) -> bool {
        self.status.is_some_and(|s| s.state.changes_restricted())
    }

    /// The supervisor's state as last seen (calibrating until the first status).
    fn flight_state(&self) -> FlightState {
        self.status.map_or(FlightState::Calibrating, |s| s.state)
    }

    /// The commands for the control tick, to add one to; the safe supervisor's only. Not
    /// generic over what is added (a closure each): one copy for every command.
    fn for_tick(&mut self) -> Result<&mut GcsInput, Refused> {
        if !self.safe_supervisor() {
            return Err(Refused::denied(gcs::RULE_REFERENCE));
        }
        self.gcs_pending = true;
        Ok(&mut self.gcs)
    }

    fn changed(&mut self, kind: ChangeKind) {
        self.change_pending = self.change_pending.max(Some(kind));
        self.unsaved_since_ms = Some(self.now_ms);
    }
}

/// What the link says before the first status (the board boots: calibrating, nothing measured
/// but the battery), and the fields no status changes. One constant the state starts from, in
/// flash, rather than a second list of stores.
const BOOTING: VehicleState = VehicleState {
    state: FlightState::Calibrating,
    attitude: Attitude { roll_rad: 0.0, pitch_rad: 0.0, yaw_rad: 0.0, roll_rate_rad_s: 0.0, pitch_rate_rad_s: 0.0, yaw_rate_rad_s: 0.0 },
    rc_widths_us: [0; 8],
    rc_channel_count: 0,
    motor_outputs_us: [1000; 4],
    battery: Battery { voltage_mv: 0, current_ca: -1, remaining_pct: -1 },
    health: Health { imu: false, radio: false, estimator: false, battery: true, prearm: false },
    load_permille: 0,
    motor_test: false,
    altitude: Altitude { height_m: None, climb_m_s: None, pressure_pa: None, temperature_c: 0.0, mode: VerticalMode::Manual },
};

/// The vertical half's report as the link says it: the height only while the estimate may be
/// flown on, the failsafe's descent over the pilot's mode.
fn altitude(a: &AltitudeStatus) -> Altitude {
    let mode = match a.mode {
        _ if a.failsafe_descent => VerticalMode::FailsafeDescent,
        AltMode::Manual => VerticalMode::Manual,
        AltMode::Hold => VerticalMode::AltitudeHold,
    };
    let known = a.estimate_healthy;
    Altitude {
        height_m: known.then_some(a.height_m),
        climb_m_s: known.then_some(a.climb_m_s),
        pressure_pa: a.pressure_pa,
        temperature_c: a.temperature_c,
        mode,
    }
}

/// Whether any parameter of `a` differs from `b`'s, bit for bit. The station's configurations
/// differ in parameters only (each comes from the one before through the table's setters),
/// and comparing the table's values reuses its getters where the derived `Config: PartialEq`,
/// built with fcu-core at opt-level 3 and inlined, cost 1.5 KB (2 KB with altitude hold).
fn differs(a: &Config, b: &Config) -> bool {
    (0..parameters::count()).any(|i| parameters::value(a, i).map(f32::to_bits) != parameters::value(b, i).map(f32::to_bits))
}

impl Vehicle for Station {
    fn state(&self) -> VehicleState {
        let mut said = BOOTING;
        said.battery.voltage_mv = self.battery_mv;
        let Some(s) = self.status else {
            return said;
        };
        let armed = self.armed();
        for (out, &w) in said.rc_widths_us.iter_mut().zip(self.rc_widths_counts.iter()) {
            *out = (u32::from(w) / COUNTS_PER_US) as u16;
        }
        said.rc_channel_count = 4;
        let arr = u32::from(self.cfg.mixer.timer_arr) + 1;
        said.motor_outputs_us = s.compare.map(|c| (1000 + u32::from(c) * 1000 / arr).min(2000) as u16);
        said.state = s.state;
        said.attitude.roll_rad = s.tilt.roll_rad;
        said.attitude.pitch_rad = s.tilt.pitch_rad;
        // fcu-core's heading turns anticlockwise seen from above; MAVLink's clockwise.
        said.attitude.yaw_rad = -s.yaw_est_rad;
        said.health = Health {
            imu: s.fault.is_none(),
            radio: s.link,
            estimator: s.calibrated,
            battery: true,
            prearm: armed || (s.state == FlightState::Disarmed && s.blockers.is_empty()),
        };
        said.motor_test = self.motor_test_running();
        said.altitude = altitude(&s.altitude);
        said
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
            // `next` comes from the configuration in force through the table's setter, which
            // validated it: what it reaches is the table's to say, and a set that moved a
            // parameter not changeable in flight (a radio map's partner) waits for the disarm.
            let kind = parameters::change_kind(&self.cfg, &next);
            if !kind.allowed(armed) {
                return Err(parameters::ApplyError::Armed.rule());
            }
            self.cfg = next;
            self.changed(kind);
        }
        Ok(others)
    }

    fn request(&mut self, request: Request) -> Result<ParamMask, Refused> {
        if let Request::SetMode(mode) = request {
            return self.set_mode(mode);
        }
        self.command(request).map(|()| ParamMask::EMPTY)
    }
}

impl Station {
    /// A set-mode: the parameter [`ALT_MODE`]'s set (see the module docs). `Ok` carries it
    /// and any other parameter the set changed.
    fn set_mode(&mut self, mode: AltMode) -> Result<ParamMask, Refused> {
        let Some(index) = parameters::index_of(ALT_MODE) else {
            return Err(Refused::denied(gcs::RULE_NO_ALTITUDE_HOLD));
        };
        let index = index as u16;
        let mut set =
            self.set_param(index, f32::from(mode as u8)).map_err(|rule| Refused { rule, for_now: rule == parameters::RULE_ARMED })?;
        set.insert(index);
        Ok(set)
    }

    /// Every request but a set-mode.
    fn command(&mut self, request: Request) -> Result<(), Refused> {
        let state = self.flight_state();
        match request {
            Request::SetMode(mode) => self.set_mode(mode).map(|_| ()),
            Request::Arm => gcs::arm_rule(),
            Request::SaveParams => {
                gcs::save_rule(state, self.motor_test_running())?;
                self.save_asked_ms = Some(self.now_ms);
                Ok(())
            }
            Request::ResetParams => {
                gcs::disarmed_rule(state)?;
                // Every parameter to its default, through the table's setters and checked as a
                // whole (as a snapshot loaded at boot is).
                let next = parameters::with_values(&self.cfg, &parameters::values(self.defaults)).map_err(Refused::denied)?;
                if differs(&self.cfg, &next) {
                    let kind = parameters::change_kind(&self.cfg, &next);
                    self.cfg = next;
                    self.changed(kind);
                }
                Ok(())
            }
            Request::Reboot => {
                gcs::disarmed_rule(state)?;
                self.reboot_asked_ms = Some(self.now_ms);
                Ok(())
            }
            Request::Disarm { forced } => {
                let throttle_low = self.status.is_none_or(|s| self.cfg.rc.throttle_low(&s.sticks));
                Disarm { forced }.checked(state, throttle_low)?;
                self.for_tick()?.disarm = Some(Disarm { forced });
                Ok(())
            }
            Request::CalibrateImu => {
                gcs::test_or_calibration_rule(state)?;
                self.pending_rule()?;
                self.for_tick()?.calibrate_imu = true;
                Ok(())
            }
            Request::CalibrateRadio => {
                gcs::test_or_calibration_rule(state)?;
                self.pending_rule()?;
                self.for_tick()?.radio_calibration = Some(true);
                Ok(())
            }
            Request::EndCalibration => {
                self.for_tick()?.radio_calibration = Some(false);
                Ok(())
            }
            Request::MotorTest { motor, throttle_pct, duration_ms } => {
                let test = MotorTest { motor, duty_pct: throttle_pct, duration_ms }.checked(state)?;
                self.pending_rule()?;
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
        let mut s = FlightController::new(&Config::default()).unwrap().status();
        s.state = state;
        s.sticks = sticks;
        s.blockers = blockers;
        s
    }

    /// The rule of a request's verdict (whether it is refused for now, the rules' own tests
    /// in fcu-core show).
    trait Asked {
        fn asked(&mut self, request: Request) -> Result<(), &'static str>;
    }

    impl Asked for Station {
        fn asked(&mut self, request: Request) -> Result<(), &'static str> {
            self.request(request).map(|_| ()).map_err(|refused| refused.rule)
        }
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
        assert_eq!(st.asked(Request::Disarm { forced: false }), Ok(()));
        assert_eq!(st.take_gcs().and_then(|g| g.disarm), Some(Disarm { forced: false }));
        assert_eq!(st.take_gcs(), None, "taken once");

        let mut st = station_in(FlightState::Armed, UP);
        assert_eq!(st.asked(Request::Disarm { forced: false }), Err(gcs::RULE_THROTTLE_NOT_LOW));
        assert_eq!(st.take_gcs(), None, "a refusal sends nothing");
        assert_eq!(st.asked(Request::Disarm { forced: true }), Ok(()));
        assert_eq!(st.take_gcs().and_then(|g| g.disarm), Some(Disarm { forced: true }));

        let mut st = station_in(FlightState::FailsafeLevel, REST);
        assert_eq!(st.asked(Request::Disarm { forced: false }), Err(gcs::RULE_FAILSAFE_LEVEL));
    }

    #[test]
    fn a_motor_test_goes_to_the_tick_disarmed_only_capped() {
        let mut st = station_in(FlightState::Disarmed, REST);
        assert_eq!(st.asked(motor_test(3, 90.0)), Ok(()));
        let test = MotorTest { motor: 3, duty_pct: gcs::MOTOR_TEST_MAX_DUTY_PCT, duration_ms: 2000 };
        assert_eq!(st.take_gcs().and_then(|g| g.motor_test), Some(MotorTestChange::Start(test)));
        assert_eq!(st.asked(Request::StopMotorTest), Ok(()));
        assert_eq!(st.take_gcs().and_then(|g| g.motor_test), Some(MotorTestChange::Stop));
        assert_eq!(st.asked(motor_test(4, 5.0)), Err(gcs::RULE_NO_SUCH_MOTOR));

        for state in [FlightState::Arming, FlightState::Armed, FlightState::FailsafeLevel] {
            let mut st = station_in(state, REST);
            assert_eq!(st.asked(motor_test(0, 5.0)), Err(gcs::RULE_DISARMED_ONLY), "{state:?}");
            assert_eq!(st.take_gcs(), None);
        }
        assert_eq!(station_in(FlightState::Calibrating, REST).asked(motor_test(0, 5.0)), Err(gcs::RULE_CALIBRATING));
        // No status yet: the board is still booting.
        let mut st = Station::new(Config::default(), &Config::DEFAULT);
        assert_eq!(st.asked(motor_test(0, 5.0)), Err(gcs::RULE_CALIBRATING));
    }

    #[test]
    fn calibrations_go_to_the_tick_disarmed_only_and_an_end_always() {
        let mut st = station_in(FlightState::Disarmed, REST);
        assert_eq!(st.asked(Request::CalibrateImu), Ok(()));
        assert_eq!(st.asked(Request::CalibrateRadio), Ok(()));
        let g = st.take_gcs().unwrap();
        assert!(g.calibrate_imu);
        assert_eq!(g.radio_calibration, Some(true));

        let mut st = station_in(FlightState::Armed, REST);
        assert_eq!(st.asked(Request::CalibrateImu), Err(gcs::RULE_DISARMED_ONLY));
        assert_eq!(st.asked(Request::CalibrateRadio), Err(gcs::RULE_DISARMED_ONLY));
        assert_eq!(st.take_gcs(), None);
        assert_eq!(st.asked(Request::EndCalibration), Ok(()));
        assert_eq!(st.take_gcs().and_then(|g| g.radio_calibration), Some(false));
    }

    #[test]
    fn the_reference_supervisor_takes_no_command() {
        const CFG: Config = Config { supervisor: SupervisorConfig::Reference, ..Config::DEFAULT };
        let mut st = Station::new(CFG, &CFG);
        st.observe(&status(FlightState::Disarmed, REST, Blockers::default()), 3900, [0; 4], 0);
        assert_eq!(st.asked(Request::CalibrateImu), Err(gcs::RULE_REFERENCE));
        assert_eq!(st.asked(motor_test(0, 5.0)), Err(gcs::RULE_REFERENCE));
        assert_eq!(st.take_gcs(), None);
        // A save has no arming refusal to wait for there.
        assert_eq!(st.asked(Request::SaveParams), Ok(()));
        assert!(st.save_due());
    }

    #[test]
    fn the_pre_arm_check_is_healthy_disarmed_without_a_blocker_and_armed() {
        let mut busy = Blockers::default();
        busy.insert(Blocker::Saving);
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
        busy.blockers.insert(Blocker::Saving);
        assert_eq!(st.asked(Request::SaveParams), Ok(()));
        assert!(!st.save_due(), "the tick does not know yet");
        assert_eq!(st.take_gcs().map(|g| g.saving), Some(true));
        // A snapshot that does not show the refusal, then one that may predate the tick's take.
        st.observe(&idle, 3900, [0; 4], 1005);
        st.observe(&busy, 3900, [0; 4], 1010);
        assert!(!st.save_due());
        st.observe(&busy, 3900, [0; 4], 1015);
        assert!(st.save_due());
        // Calibrating or faulted, the board cannot arm either: the refusal is what counts.
        let mut faulted = busy;
        faulted.state = FlightState::Fault;
        st.observe(&faulted, 3900, [0; 4], 1020);
        assert!(st.save_due());
        // Armed meanwhile (the refusal came too late): no save, and the request is dropped.
        let mut armed = busy;
        armed.state = FlightState::Armed;
        st.observe(&armed, 3900, [0; 4], 1025);
        assert!(!st.save_due());
        assert!(st.take_notice().is_some());
        st.observe(&busy, 3900, [0; 4], 1030);
        st.observe(&busy, 3900, [0; 4], 1035);
        assert!(!st.save_due(), "nothing was changed: nothing left to save");
        assert_eq!(st.asked(Request::SaveParams), Ok(()));
        st.observe(&busy, 3900, [0; 4], 1040);
        assert!(st.save_due());
        st.saved(true);
        assert!(!st.save_due());
        assert_eq!(st.take_gcs().map(|g| g.saving), Some(false), "arming allowed again");
        assert_eq!(st.take_gcs(), None);
    }

    /// A status in `state` showing `blockers`, fed at `now_ms`.
    fn feed(st: &mut Station, state: FlightState, blockers: &[Blocker], now_ms: u32) {
        let mut b = Blockers::default();
        for &blocker in blockers {
            b.insert(blocker);
        }
        st.observe(&status(state, REST, b), 3900, [0; 4], now_ms);
    }

    #[test]
    fn a_reboot_is_due_only_once_the_tick_refuses_to_arm_for_it() {
        let mut st = station_in(FlightState::Disarmed, REST);
        assert_eq!(st.asked(Request::Reboot), Ok(()));
        assert_eq!(st.due(), Due::Nothing, "the tick does not know yet");
        assert_eq!(st.take_gcs().map(|g| g.rebooting), Some(true));
        feed(&mut st, FlightState::Disarmed, &[], 1005);
        feed(&mut st, FlightState::Disarmed, &[Blocker::RebootPending], 1010);
        assert_eq!(st.due(), Due::Nothing, "one snapshot may predate the tick's take");
        feed(&mut st, FlightState::Disarmed, &[Blocker::RebootPending], 1015);
        assert_eq!(st.due(), Due::Reboot);
    }

    #[test]
    fn a_reboot_accepted_disarmed_is_dropped_when_the_board_arms_never_carried_out_in_flight() {
        let mut st = station_in(FlightState::Disarmed, REST);
        assert_eq!(st.asked(Request::Reboot), Ok(()));
        let _ = st.take_gcs();
        // A gesture under way (motors off) is ended by the refusal: the reboot waits for it.
        feed(&mut st, FlightState::Arming, &[Blocker::RebootPending], 1002);
        assert_eq!(st.due(), Due::Nothing);
        assert!(st.reboot_asked());
        // The pilot's gesture won the race against the refusal: armed, then flying for long.
        feed(&mut st, FlightState::Armed, &[], 1005);
        assert_eq!(st.due(), Due::Nothing);
        assert_eq!(st.take_notice(), Some(&b"reboot dropped: the board armed"[..]));
        assert!(!st.reboot_asked());
        assert_eq!(st.take_gcs().map(|g| g.rebooting), Some(false), "arming allowed again");
        for t in (1010..20_000).step_by(5) {
            feed(&mut st, FlightState::Armed, &[], t);
            assert_eq!(st.due(), Due::Nothing, "at {t} ms");
        }
        // Landed and disarmed: the reboot does not come back by surprise.
        for t in (20_000..21_000).step_by(5) {
            feed(&mut st, FlightState::Disarmed, &[], t);
            assert_eq!(st.due(), Due::Nothing, "at {t} ms");
        }
    }

    #[test]
    fn a_reboot_never_confirmed_times_out_with_a_text() {
        let mut st = station_in(FlightState::Disarmed, REST);
        assert_eq!(st.asked(Request::Reboot), Ok(()));
        let _ = st.take_gcs();
        // The tick never shows the refusal (its status stopped, say).
        feed(&mut st, FlightState::Disarmed, &[], 1000 + ACTION_TIMEOUT_MS - 5);
        assert_eq!(st.due(), Due::Nothing);
        assert!(st.reboot_asked());
        feed(&mut st, FlightState::Disarmed, &[], 1000 + ACTION_TIMEOUT_MS);
        assert_eq!(st.due(), Due::Nothing);
        assert_eq!(st.take_notice(), Some(&b"reboot dropped: arming refusal not confirmed in 5 s"[..]));
        assert_eq!(st.take_gcs().map(|g| g.rebooting), Some(false), "arming allowed again");
        // A late confirmation does not revive it.
        feed(&mut st, FlightState::Disarmed, &[Blocker::RebootPending], 1000 + ACTION_TIMEOUT_MS + 5);
        feed(&mut st, FlightState::Disarmed, &[Blocker::RebootPending], 1000 + ACTION_TIMEOUT_MS + 10);
        assert_eq!(st.due(), Due::Nothing);
    }

    #[test]
    fn an_asked_save_that_finds_the_board_armed_is_dropped_and_waits_for_the_disarm() {
        let mut st = station_in(FlightState::Disarmed, REST);
        assert_eq!(st.set_param(parameters::index_of(b"ANGLE_MAX").unwrap() as u16, 25.0).map(|_| ()), Ok(()));
        assert_eq!(st.asked(Request::SaveParams), Ok(()));
        let _ = st.take_gcs();
        feed(&mut st, FlightState::Armed, &[], 1005);
        assert_eq!(st.take_notice(), Some(&b"save dropped: the board armed (the changes are saved after the disarm)"[..]));
        assert_eq!(st.take_gcs().map(|g| g.saving), Some(false), "no save while armed");
        for t in (1010..10_000).step_by(5) {
            feed(&mut st, FlightState::Armed, &[], t);
            assert_eq!(st.due(), Due::Nothing, "never while armed, at {t} ms");
        }
        // Disarmed: the change is still unsaved, and saved once the refusal shows.
        feed(&mut st, FlightState::Disarmed, &[], 10_000);
        assert_eq!(st.take_gcs().map(|g| g.saving), Some(true));
        feed(&mut st, FlightState::Disarmed, &[Blocker::Saving], 10_005);
        feed(&mut st, FlightState::Disarmed, &[Blocker::Saving], 10_010);
        assert_eq!(st.due(), Due::Save);
    }

    #[test]
    fn a_reboot_saves_what_is_unsaved_first() {
        let mut st = station_in(FlightState::Disarmed, REST);
        assert_eq!(st.set_param(parameters::index_of(b"ANGLE_MAX").unwrap() as u16, 25.0).map(|_| ()), Ok(()));
        assert_eq!(st.asked(Request::Reboot), Ok(()));
        let g = st.take_gcs().unwrap();
        assert!(g.saving && g.rebooting, "{g:?}");
        feed(&mut st, FlightState::Disarmed, &[Blocker::Saving, Blocker::RebootPending], 1005);
        feed(&mut st, FlightState::Disarmed, &[Blocker::Saving, Blocker::RebootPending], 1010);
        assert_eq!(st.due(), Due::Save, "not the reboot: the change would be lost");
        st.saved(true);
        assert_eq!(st.take_gcs().map(|g| (g.saving, g.rebooting)), Some((false, true)));
        feed(&mut st, FlightState::Disarmed, &[Blocker::RebootPending], 1015);
        feed(&mut st, FlightState::Disarmed, &[Blocker::RebootPending], 1020);
        assert_eq!(st.due(), Due::Reboot);
    }

    #[test]
    fn a_save_is_refused_during_a_motor_test_and_a_test_while_a_save_or_reboot_is_pending() {
        let mut st = station_in(FlightState::Disarmed, REST);
        feed(&mut st, FlightState::Disarmed, &[Blocker::MotorTest], 1000);
        assert_eq!(st.asked(Request::SaveParams), Err(gcs::RULE_MOTOR_TEST_RUNNING));
        // A change made meanwhile waits for the test to end.
        assert_eq!(st.set_param(parameters::index_of(b"ANGLE_MAX").unwrap() as u16, 25.0).map(|_| ()), Ok(()));
        feed(&mut st, FlightState::Disarmed, &[Blocker::MotorTest], 1000 + SAVE_DEBOUNCE_MS + 100);
        assert_eq!(st.take_gcs().map(|g| g.saving), None);
        assert_eq!(st.due(), Due::Nothing);

        let mut st = station_in(FlightState::Disarmed, REST);
        assert_eq!(st.asked(Request::SaveParams), Ok(()));
        assert_eq!(st.asked(motor_test(0, 5.0)), Err(RULE_SAVING));
        assert_eq!(st.asked(Request::CalibrateImu), Err(RULE_SAVING));
        let mut st = station_in(FlightState::Disarmed, REST);
        assert_eq!(st.asked(Request::Reboot), Ok(()));
        assert_eq!(st.asked(motor_test(0, 5.0)), Err(RULE_REBOOTING));
        assert_eq!(st.asked(Request::CalibrateRadio), Err(RULE_REBOOTING));
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

    #[test]
    fn the_control_loop_gets_the_widest_kind_of_the_changes_since_it_last_took_one() {
        use fcu_core::flight::ChangeKind;
        let mut st = station_in(FlightState::Disarmed, REST);
        assert_eq!(st.take_change(), None);
        st.set_param(index("ANGLE_MAX"), 25.0).unwrap();
        assert_eq!(st.take_change().map(|c| c.kind), Some(ChangeKind::InFlight));
        // A ground-only change, then an in-flight one, before the control loop takes them:
        // together they may change only on the ground (the tick refuses them once armed).
        st.set_param(index("RC1_TRIM"), 1470.0).unwrap();
        st.set_param(index("ANGLE_MAX"), 30.0).unwrap();
        let change = st.take_change().unwrap();
        assert_eq!((change.kind, change.cfg), (ChangeKind::GroundOnly, *st.config()));
        assert_eq!(st.take_change(), None);
    }

    /// The link in front of the station: what a ground station hears back of a set.
    fn echo(st: &mut Station, name: &str, value: f32) -> Vec<f32> {
        use crate::test_support::{drain, param_set, param_values, v2};
        let mut link: fcu_link::Link<512> = fcu_link::Link::default();
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

    #[test]
    fn the_height_is_said_only_while_the_estimate_may_be_flown_on_and_the_failsafe_descent_over_the_mode() {
        let mut st = station_in(FlightState::Disarmed, REST);
        assert_eq!(st.state().altitude, Altitude::default(), "nothing known at boot");
        let mut s = status(FlightState::Armed, REST, Blockers::default());
        s.altitude = AltitudeStatus {
            mode: AltMode::Hold,
            height_m: 2.5,
            climb_m_s: 0.25,
            pressure_pa: Some(100_500.0),
            temperature_c: 21.0,
            estimate_healthy: true,
            ..AltitudeStatus::default()
        };
        st.observe(&s, 3900, [0; 4], 1000);
        let said = st.state().altitude;
        assert_eq!(
            said,
            Altitude {
                height_m: Some(2.5),
                climb_m_s: Some(0.25),
                pressure_pa: Some(100_500.0),
                temperature_c: 21.0,
                mode: VerticalMode::AltitudeHold
            }
        );
        s.altitude.estimate_healthy = false;
        s.altitude.failsafe_descent = true;
        st.observe(&s, 3900, [0; 4], 1005);
        let said = st.state().altitude;
        assert_eq!((said.height_m, said.climb_m_s, said.pressure_pa), (None, None, Some(100_500.0)), "the last sample stays");
        assert_eq!(said.mode, VerticalMode::FailsafeDescent);
        s.altitude = AltitudeStatus::default();
        st.observe(&s, 3900, [0; 4], 1010);
        assert_eq!(st.state().altitude.mode, VerticalMode::Manual);
    }

    #[test]
    fn a_set_mode_is_the_alt_mode_parameters_set_by_name_or_refused_by_name() {
        let mut st = station_in(FlightState::Disarmed, REST);
        let Some(index) = parameters::index_of(ALT_MODE) else {
            // A table without altitude hold: refused with the rule's name, nothing changed.
            assert_eq!(st.request(Request::SetMode(AltMode::Hold)), Err(Refused::denied(gcs::RULE_NO_ALTITUDE_HOLD)));
            assert_eq!(st.request(Request::SetMode(AltMode::Manual)), Err(Refused::denied(gcs::RULE_NO_ALTITUDE_HOLD)));
            assert!(!st.unsaved());
            assert_eq!(st.take_change(), None);
            return;
        };
        let value = |st: &Station| parameters::value(st.config(), index);
        let mut mask = ParamMask::EMPTY;
        mask.insert(index as u16);
        // Taken as a PARAM_SET of ALT_MODE: echoed, saved after the debounce, handed on.
        let set = st.request(Request::SetMode(AltMode::Hold)).unwrap();
        assert!(set.contains(index as u16));
        assert_eq!(value(&st), Some(1.0));
        assert!(st.unsaved());
        assert!(st.take_change().is_some());
        // The mode in force again: still echoed, nothing changes.
        assert_eq!(st.request(Request::SetMode(AltMode::Hold)), Ok(mask));
        assert_eq!(st.take_change(), None);
        // The table's rules are the set's: in flight when the table allows it, refused with its rule
        // otherwise.
        st.observe(&status(FlightState::Armed, UP, Blockers::default()), 3900, [0; 4], 1000);
        let mut armed = st.clone();
        match parameters::set(&mut armed.cfg.clone(), index, 0.0, true) {
            Ok(_) => {
                assert_eq!(armed.request(Request::SetMode(AltMode::Manual)), Ok(mask));
                assert_eq!(value(&armed), Some(0.0));
            }
            Err(refusal) => {
                let refused = armed.request(Request::SetMode(AltMode::Manual)).unwrap_err();
                assert_eq!(refused.rule, refusal.rule);
                assert_eq!(value(&armed), Some(1.0));
            }
        }
    }

    #[test]
    fn the_kind_the_station_hands_on_is_check_changes() {
        // The station classifies its changes with the table alone (`change_kind`): the same
        // verdict `check_change` gives with its checks, for every change it makes.
        let mut st = station_in(FlightState::Disarmed, REST);
        for (name, value) in [("ANGLE_MAX", 25.0), ("RCMAP_ROLL", 3.0), ("RC1_TRIM", 1470.0), ("RATE_YAW_I", 0.0)] {
            let before = *st.config();
            st.set_param(index(name), value).unwrap();
            let kind = parameters::check_change(&before, st.config(), false).map(|c| c.kind);
            assert_eq!(Ok(parameters::change_kind(&before, st.config())), kind, "{name}");
            assert_eq!(st.take_change().map(|c| c.kind), kind.ok().filter(|_| before != *st.config()), "{name}");
        }
        let before = *st.config();
        assert_eq!(st.request(Request::ResetParams), Ok(ParamMask::EMPTY));
        let kind = parameters::check_change(&before, st.config(), false).map(|c| c.kind);
        assert_eq!(st.take_change().map(|c| c.kind), kind.ok());
        assert!(*st.config() == Config::DEFAULT);
    }

    #[test]
    fn a_reset_to_defaults_restores_them() {
        let mut st = station_in(FlightState::Disarmed, REST);
        assert_eq!(st.request(Request::ResetParams), Ok(ParamMask::EMPTY));
        assert!(!st.unsaved(), "at the defaults already: nothing to save");
        assert_eq!(st.take_change(), None);
        assert!(st.set_param(index("ANGLE_MAX"), 25.0).is_ok());
        assert_eq!(st.request(Request::ResetParams), Ok(ParamMask::EMPTY));
        assert!(st.config() == &Config::DEFAULT);
        assert!(st.unsaved());
    }

    #[test]
    fn a_save_with_the_supply_too_low_is_not_attempted_said_and_tried_again_after_the_debounce() {
        let mut st = station_in(FlightState::Disarmed, REST);
        assert!(st.set_param(index("ANGLE_MAX"), 25.0).is_ok());
        assert_eq!(st.asked(Request::SaveParams), Ok(()));
        let _ = st.take_gcs();
        feed(&mut st, FlightState::Disarmed, &[Blocker::Saving], 1005);
        feed(&mut st, FlightState::Disarmed, &[Blocker::Saving], 1010);
        assert_eq!(st.due(), Due::Save);
        st.supply_low();
        assert_eq!(st.take_notice(), Some(&b"parameters NOT saved: supply below 2.7 V"[..]));
        assert!(st.unsaved(), "the change is still to be saved");
        assert_eq!(st.take_gcs().map(|g| g.saving), Some(false), "arming allowed meanwhile");
        feed(&mut st, FlightState::Disarmed, &[], 1015 + SAVE_DEBOUNCE_MS - 20);
        assert_eq!(st.take_gcs(), None, "not every period: after a debounce");
        feed(&mut st, FlightState::Disarmed, &[], 1015 + SAVE_DEBOUNCE_MS);
        assert_eq!(st.take_gcs().map(|g| g.saving), Some(true));
    }
}
