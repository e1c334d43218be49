//! The flight controller behind the link: fcu-core's parameter table, configuration and status
//! as the link's [`Vehicle`], one implementation for the firmware and anything else that runs
//! fcu-core behind a ground station.
//!
//! The station holds the configuration in force and a copy of the latest status; its owner
//! (the firmware's link task) feeds it the status, hands the configuration changes it accepts
//! to the control loop ([`Station::take_change`]) and does the flash work it asks for
//! ([`Station::save_due`], [`Station::saved`]). It decides what a ground station may do, with
//! the rules of fcu-core's parameter table; the owner only moves bytes and words.

use fcu_core::flight::Status;
use fcu_core::parameters::{self, snapshot, RULE_ARMED};
use fcu_core::rc::COUNTS_PER_US;
use fcu_core::supervisor::FlightState;
use fcu_core::Config;

use crate::rates::Rates;
use crate::vehicle::{Attitude, Battery, Health, Param, Request, SystemStatus, Vehicle, VehicleState};

/// How long after the last parameter change a save waits, so that a ground station setting
/// twenty parameters in a row (a radio calibration) costs one erase, not twenty.
pub const SAVE_DEBOUNCE_MS: u32 = 2000;

/// Rule of a request the station does not carry out on this board.
pub const RULE_NOT_AVAILABLE: &str = "not available on this board yet";

pub struct Station {
    cfg: Config,
    defaults: Config,
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
}

impl Station {
    /// `cfg` is the configuration the board booted with, `defaults` what a reset restores.
    pub fn new(cfg: Config, defaults: Config) -> Station {
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
        }
    }

    /// The latest status from the control loop, the battery and the radio's widths.
    pub fn observe(&mut self, status: &Status, battery_mv: u32, rc_widths_counts: [u16; 4], now_ms: u32) {
        self.status = Some(*status);
        self.battery_mv = battery_mv.min(u32::from(u16::MAX)) as u16;
        self.rc_widths_counts = rc_widths_counts;
        self.now_ms = now_ms;
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

    /// Whether the parameters should be written to flash now: asked for, or changed and left
    /// alone for [`SAVE_DEBOUNCE_MS`]; never while armed.
    pub fn save_due(&self) -> bool {
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

    fn armed(&self) -> bool {
        self.status.is_some_and(|s| s.state.armed())
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
                health: Health { imu: false, radio: false, estimator: false, battery: true },
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
            health: Health { imu: s.fault.is_none(), radio: s.link, estimator: s.calibrated, battery: true },
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

    fn param_index(&self, name: &str) -> Option<u16> {
        parameters::index_of(name.as_bytes()).map(|i| i as u16)
    }

    fn set_param(&mut self, index: u16, value: f32) -> Result<f32, &'static str> {
        let armed = self.armed();
        let mut next = self.cfg;
        let applied = parameters::set(&mut next, usize::from(index), value, armed).map_err(|r| r.rule)?;
        if !next.is_same_as(&self.cfg) {
            fcu_core::flight::check_change(&self.cfg, &next, armed).map_err(|e| e.rule())?;
            self.cfg = next;
            self.changed();
        }
        Ok(applied.value)
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
                fcu_core::flight::check_change(&self.cfg, &self.defaults, false).map_err(|e| e.rule())?;
                if !self.cfg.is_same_as(&self.defaults) {
                    self.cfg = self.defaults;
                    self.changed();
                }
                Ok(())
            }
            Request::Reboot if self.armed() => Err(RULE_ARMED),
            Request::Reboot => {
                self.reboot_asked = true;
                Ok(())
            }
            Request::StopMotorTest => Ok(()),
            Request::Disarm { .. } | Request::CalibrateImu | Request::CalibrateRadio | Request::MotorTest { .. } => Err(RULE_NOT_AVAILABLE),
        }
    }
}
