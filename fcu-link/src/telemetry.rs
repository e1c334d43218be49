//! The periodic messages, from one [`VehicleState`] snapshot per tick.
//!
//! The height streams, from [`crate::Altitude`]:
//! - VFR_HUD: `alt` the height above the take-off point, m (not above sea level: the board
//!   has no GPS and no sea-level pressure), `climb` m/s upward, both NaN while the estimate
//!   may not be flown on; `heading` the yaw in degrees 0..359, clockwise (relative to the
//!   heading at boot: there is no magnetometer in use); `throttle` the motors' mean output,
//!   percent; `airspeed` and `groundspeed` 0 (not measured).
//! - ALTITUDE: `altitude_relative` and `altitude_local` the same height (the local frame's
//!   origin is the take-off point), NaN while unknown; `altitude_monotonic` and
//!   `altitude_amsl` NaN (no altitude kept since boot, no sea-level reference),
//!   `altitude_terrain` -1001 and `bottom_clearance` -1, the spec's "unknown" and "no
//!   measurement".
//! - SCALED_PRESSURE: `press_abs` the barometer's last healthy sample, hPa, `temperature` its
//!   temperature, cdegC, `press_diff` 0 (no differential sensor). Not sent before the first
//!   sample: a ground station sees no pressure rather than a zero it could take for one.

use mavlink::dialects::common::{
    MavBatteryFunction, MavBatteryType, MavProtocolCapability, MavSysStatusSensor, ALTITUDE_DATA, ATTITUDE_DATA, AUTOPILOT_VERSION_DATA,
    BATTERY_STATUS_DATA, RC_CHANNELS_DATA, SCALED_PRESSURE_DATA, SERVO_OUTPUT_RAW_DATA, SYS_STATUS_DATA, VFR_HUD_DATA,
};

use crate::link::{Core, Room};
use crate::vehicle::VehicleState;

/// RC_CHANNELS' value for a channel that is not there.
const NO_CHANNEL: u16 = u16::MAX;

/// BATTERY_STATUS' cell voltages, none there. Copied from flash rather than filled: a fill
/// with a value other than zero would link `__aeabi_memset` (220 B) for this one array.
static NO_CELLS: [u16; 10] = [u16::MAX; 10];

/// ALTITUDE's `altitude_terrain` when unknown: the spec reads anything below -1000 m so.
const TERRAIN_UNKNOWN_M: f32 = -1001.0;

fn sensors_present() -> MavSysStatusSensor {
    MavSysStatusSensor::MAV_SYS_STATUS_SENSOR_3D_GYRO
        | MavSysStatusSensor::MAV_SYS_STATUS_SENSOR_3D_ACCEL
        | MavSysStatusSensor::MAV_SYS_STATUS_SENSOR_ANGULAR_RATE_CONTROL
        | MavSysStatusSensor::MAV_SYS_STATUS_SENSOR_ATTITUDE_STABILIZATION
        | MavSysStatusSensor::MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS
        | MavSysStatusSensor::MAV_SYS_STATUS_SENSOR_RC_RECEIVER
        | MavSysStatusSensor::MAV_SYS_STATUS_AHRS
        | MavSysStatusSensor::MAV_SYS_STATUS_SENSOR_BATTERY
        | MavSysStatusSensor::MAV_SYS_STATUS_PREARM_CHECK
}

impl<const TX: usize> Core<TX> {
    /// Every stream that is due. One that finds no room in the transmit queue stays due and
    /// goes at a later tick: telemetry is never dropped.
    pub(crate) fn telemetry(&mut self, state: &VehicleState) {
        let now = self.now_ms;
        let rates = self.config.rates;
        let heartbeat_ms = if rates.heartbeat_ms == 0 { crate::Rates::DEFAULT.heartbeat_ms } else { rates.heartbeat_ms };
        if self.schedule.heartbeat.ready(now, heartbeat_ms) && self.heartbeat(state) {
            self.schedule.heartbeat.sent(now, heartbeat_ms);
        }
        if self.schedule.attitude.ready(now, rates.attitude_ms) && self.attitude(state) {
            self.schedule.attitude.sent(now, rates.attitude_ms);
        }
        if self.schedule.sys_status.ready(now, rates.sys_status_ms) && self.sys_status(state) {
            self.schedule.sys_status.sent(now, rates.sys_status_ms);
        }
        if self.schedule.battery.ready(now, rates.battery_ms) && self.battery_status(state) {
            self.schedule.battery.sent(now, rates.battery_ms);
        }
        if self.schedule.rc_channels.ready(now, rates.rc_channels_ms) && self.rc_channels(state) {
            self.schedule.rc_channels.sent(now, rates.rc_channels_ms);
        }
        if self.schedule.servo_output.ready(now, rates.servo_output_ms) && self.servo_output(state) {
            self.schedule.servo_output.sent(now, rates.servo_output_ms);
        }
        if self.schedule.vfr_hud.ready(now, rates.vfr_hud_ms) && self.vfr_hud(state) {
            self.schedule.vfr_hud.sent(now, rates.vfr_hud_ms);
        }
        if self.schedule.altitude.ready(now, rates.altitude_ms) && self.altitude(state) {
            self.schedule.altitude.sent(now, rates.altitude_ms);
        }
        // Before the barometer's first sample there is nothing to say: the stream waits.
        if let Some(pressure_pa) = state.altitude.pressure_pa {
            if self.schedule.scaled_pressure.ready(now, rates.scaled_pressure_ms) && self.scaled_pressure(pressure_pa, state) {
                self.schedule.scaled_pressure.sent(now, rates.scaled_pressure_ms);
            }
        }
    }

    fn send_telemetry<D: mavlink::MessageData>(&mut self, data: &D) -> bool {
        self.send(data, Room::Telemetry)
    }

    fn heartbeat(&mut self, state: &VehicleState) -> bool {
        self.send_telemetry(&crate::heartbeat::heartbeat(state.state, state.altitude.mode))
    }

    fn attitude(&mut self, state: &VehicleState) -> bool {
        let a = state.attitude;
        self.send_telemetry(&ATTITUDE_DATA {
            time_boot_ms: self.now_ms,
            roll: a.roll_rad,
            pitch: a.pitch_rad,
            yaw: a.yaw_rad,
            rollspeed: a.roll_rate_rad_s,
            pitchspeed: a.pitch_rate_rad_s,
            yawspeed: a.yaw_rate_rad_s,
        })
    }

    fn sys_status(&mut self, state: &VehicleState) -> bool {
        let h = state.health;
        // The geofence: not present, so never breached. Its health bit set as autopilots with a
        // fence set it when none is breached: ground stations read a clear bit as a breach
        // (MAVProxy says "fence breach" on the first SYS_STATUS without it).
        let when = |ok: bool, bits: MavSysStatusSensor| if ok { bits } else { MavSysStatusSensor::empty() };
        let health = MavSysStatusSensor::MAV_SYS_STATUS_SENSOR_ANGULAR_RATE_CONTROL
            | MavSysStatusSensor::MAV_SYS_STATUS_SENSOR_ATTITUDE_STABILIZATION
            | MavSysStatusSensor::MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS
            | MavSysStatusSensor::MAV_SYS_STATUS_GEOFENCE
            | when(h.imu, MavSysStatusSensor::MAV_SYS_STATUS_SENSOR_3D_GYRO | MavSysStatusSensor::MAV_SYS_STATUS_SENSOR_3D_ACCEL)
            | when(h.radio, MavSysStatusSensor::MAV_SYS_STATUS_SENSOR_RC_RECEIVER)
            | when(h.estimator, MavSysStatusSensor::MAV_SYS_STATUS_AHRS)
            | when(h.battery, MavSysStatusSensor::MAV_SYS_STATUS_SENSOR_BATTERY)
            | when(h.prearm, MavSysStatusSensor::MAV_SYS_STATUS_PREARM_CHECK);
        let reader = self.stats.reader;
        let errors = reader.bad_crc.saturating_add(reader.bad_length);
        self.send_telemetry(&SYS_STATUS_DATA {
            onboard_control_sensors_present: sensors_present(),
            onboard_control_sensors_enabled: sensors_present(),
            onboard_control_sensors_health: health,
            load: state.load_permille,
            voltage_battery: state.battery.voltage_mv,
            current_battery: state.battery.current_ca,
            drop_rate_comm: 0,
            errors_comm: u16::try_from(errors).unwrap_or(u16::MAX),
            errors_count1: 0,
            errors_count2: 0,
            errors_count3: 0,
            errors_count4: 0,
            battery_remaining: state.battery.remaining_pct,
        })
    }

    fn battery_status(&mut self, state: &VehicleState) -> bool {
        // Without cell voltages, the first cell carries the whole battery's and the others are
        // "not there".
        let mut voltages = NO_CELLS;
        voltages[0] = state.battery.voltage_mv;
        self.send_telemetry(&BATTERY_STATUS_DATA {
            current_consumed: -1,
            energy_consumed: -1,
            temperature: i16::MAX,
            voltages,
            current_battery: state.battery.current_ca,
            id: 0,
            battery_function: MavBatteryFunction::MAV_BATTERY_FUNCTION_ALL,
            mavtype: MavBatteryType::MAV_BATTERY_TYPE_LIPO,
            battery_remaining: state.battery.remaining_pct,
        })
    }

    fn rc_channels(&mut self, state: &VehicleState) -> bool {
        let count = usize::from(state.rc_channel_count);
        let mut ch = [NO_CHANNEL; 8];
        for (i, (slot, &width)) in ch.iter_mut().zip(state.rc_widths_us.iter()).enumerate() {
            if i < count && width != 0 {
                *slot = width;
            }
        }
        self.send_telemetry(&RC_CHANNELS_DATA {
            time_boot_ms: self.now_ms,
            chan1_raw: ch[0],
            chan2_raw: ch[1],
            chan3_raw: ch[2],
            chan4_raw: ch[3],
            chan5_raw: ch[4],
            chan6_raw: ch[5],
            chan7_raw: ch[6],
            chan8_raw: ch[7],
            chan9_raw: NO_CHANNEL,
            chan10_raw: NO_CHANNEL,
            chan11_raw: NO_CHANNEL,
            chan12_raw: NO_CHANNEL,
            chan13_raw: NO_CHANNEL,
            chan14_raw: NO_CHANNEL,
            chan15_raw: NO_CHANNEL,
            chan16_raw: NO_CHANNEL,
            chan17_raw: NO_CHANNEL,
            chan18_raw: NO_CHANNEL,
            chancount: state.rc_channel_count.min(8),
            rssi: u8::MAX,
        })
    }

    fn servo_output(&mut self, state: &VehicleState) -> bool {
        let [m1, m2, m3, m4] = state.motor_outputs_us;
        self.send_telemetry(&SERVO_OUTPUT_RAW_DATA {
            time_usec: self.now_ms.wrapping_mul(1000),
            servo1_raw: m1,
            servo2_raw: m2,
            servo3_raw: m3,
            servo4_raw: m4,
            servo5_raw: 0,
            servo6_raw: 0,
            servo7_raw: 0,
            servo8_raw: 0,
            port: 0,
        })
    }

    fn vfr_hud(&mut self, state: &VehicleState) -> bool {
        let a = state.altitude;
        // MAVLink's heading is clockwise from north in whole degrees, 0..359: the nearest one,
        // as floor(x + 0.5) from a truncating cast (no float rounding in no_std; NaN reads 0).
        let half_up = state.attitude.yaw_rad.to_degrees() + 0.5;
        let truncated = half_up as i32;
        let heading_deg = truncated - i32::from(truncated as f32 > half_up);
        let [m1, m2, m3, m4] = state.motor_outputs_us.map(u32::from);
        let mean_us = (m1 + m2 + m3 + m4) / 4;
        self.send_telemetry(&VFR_HUD_DATA {
            airspeed: 0.0,
            groundspeed: 0.0,
            alt: a.height_m.unwrap_or(f32::NAN),
            climb: a.climb_m_s.unwrap_or(f32::NAN),
            heading: heading_deg.rem_euclid(360) as i16,
            throttle: (mean_us.clamp(1000, 2000) - 1000) as u16 / 10,
        })
    }

    fn altitude(&mut self, state: &VehicleState) -> bool {
        let height_m = state.altitude.height_m.unwrap_or(f32::NAN);
        self.send_telemetry(&ALTITUDE_DATA {
            time_usec: u64::from(self.now_ms) * 1000,
            altitude_monotonic: f32::NAN,
            altitude_amsl: f32::NAN,
            altitude_local: height_m,
            altitude_relative: height_m,
            altitude_terrain: TERRAIN_UNKNOWN_M,
            bottom_clearance: -1.0,
        })
    }

    fn scaled_pressure(&mut self, pressure_pa: f32, state: &VehicleState) -> bool {
        self.send_telemetry(&SCALED_PRESSURE_DATA {
            time_boot_ms: self.now_ms,
            press_abs: pressure_pa / 100.0,
            press_diff: 0.0,
            // Saturating: the LPS22HB reads -40..85 °C.
            temperature: (state.altitude.temperature_c * 100.0) as i16,
        })
    }

    pub(crate) fn autopilot_version(&mut self) {
        self.send(
            &AUTOPILOT_VERSION_DATA {
                capabilities: MavProtocolCapability::MAV_PROTOCOL_CAPABILITY_MAVLINK2
                    | MavProtocolCapability::MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_C_CAST,
                uid: self.config.uid,
                flight_sw_version: self.config.flight_sw_version,
                middleware_sw_version: 0,
                os_sw_version: 0,
                board_version: 0,
                vendor_id: 0,
                product_id: 0,
                flight_custom_version: [0; 8],
                middleware_custom_version: [0; 8],
                os_custom_version: [0; 8],
            },
            Room::Answer,
        );
    }
}
