//! Telemetry rates and what they cost on a 115200 baud UART.
//!
//! 115200 baud with 8N1 framing carries 11,520 bytes/s. A MAVLink 2 frame is 12 bytes of
//! header and CRC around its payload (trailing zero bytes of the payload are not sent). At the
//! defaults, counting every payload at its full length:
//!
//! | message | frame, B | rate | B/s |
//! |---|---|---|---|
//! | HEARTBEAT | 21 | 1 Hz | 21 |
//! | ATTITUDE | 40 | 25 Hz | 1,000 |
//! | SYS_STATUS | 43 | 1 Hz | 43 |
//! | BATTERY_STATUS | 48 | 1 Hz | 48 |
//! | RC_CHANNELS | 54 | 10 Hz | 540 |
//! | SERVO_OUTPUT_RAW | 33 | 10 Hz | 330 |
//! | VFR_HUD | 32 | 10 Hz | 320 |
//! | ALTITUDE | 44 | 5 Hz | 220 |
//! | SCALED_PRESSURE | 26 | 2 Hz | 52 |
//! | telemetry | | | 2,574 (22 %) |
//! | PARAM_VALUE during a download | 37 | 100 Hz | 3,700 |
//! | all | | | 6,274 (54 %) |
//!
//! The height streams are chosen as the others: VFR_HUD, which QGroundControl's instruments and
//! MAVProxy's console show (height, climb, throttle, heading), as often as the radio and the
//! motors, quick enough for a climb to read smoothly; ALTITUDE, for logs and plots, at half
//! that (the height estimate changes slowly); SCALED_PRESSURE, the raw barometer, twice a
//! second, the rate of the raw sensors' health a ground station checks.
//!
//! which leaves half the line for answers, STATUSTEXTs and a ground station asking twice.
//! `budget_bytes_per_s` computes the same from the frame lengths the crate declares, and a test
//! holds the defaults under 60 % of the line.

use mavlink::dialects::common::{
    ALTITUDE_DATA, ATTITUDE_DATA, BATTERY_STATUS_DATA, HEARTBEAT_DATA, PARAM_VALUE_DATA, RC_CHANNELS_DATA, SCALED_PRESSURE_DATA,
    SERVO_OUTPUT_RAW_DATA, SYS_STATUS_DATA, VFR_HUD_DATA,
};
use mavlink::MessageData;

/// Bytes per second at 115200 baud, 8N1 (10 bits a byte).
pub const UART_BYTES_PER_S: u32 = 115_200 / 10;

/// Period of each stream, ms; 0 turns a stream off (HEARTBEAT cannot be turned off: a ground
/// station drops a vehicle without one, so 0 there means the default).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Rates {
    /// HEARTBEAT period (default 1000 ms).
    pub heartbeat_ms: u16,
    /// ATTITUDE period (default 40 ms, 25 Hz).
    pub attitude_ms: u16,
    /// SYS_STATUS period (default 1000 ms).
    pub sys_status_ms: u16,
    /// BATTERY_STATUS period (default 1000 ms).
    pub battery_ms: u16,
    /// RC_CHANNELS period (default 100 ms, 10 Hz).
    pub rc_channels_ms: u16,
    /// SERVO_OUTPUT_RAW period (default 100 ms, 10 Hz).
    pub servo_output_ms: u16,
    /// VFR_HUD period (default 100 ms, 10 Hz).
    pub vfr_hud_ms: u16,
    /// ALTITUDE period (default 200 ms, 5 Hz).
    pub altitude_ms: u16,
    /// SCALED_PRESSURE period (default 500 ms, 2 Hz; none before the barometer's first
    /// sample).
    pub scaled_pressure_ms: u16,
    /// Gap between two PARAM_VALUEs of a parameter download (default 10 ms). A download also
    /// waits while the transmit queue is short of room, so it never crowds out telemetry.
    pub param_ms: u16,
}

impl Rates {
    /// The defaults of the table in the module docs.
    pub const DEFAULT: Self = Self {
        heartbeat_ms: 1000,
        attitude_ms: 40,
        sys_status_ms: 1000,
        battery_ms: 1000,
        rc_channels_ms: 100,
        servo_output_ms: 100,
        vfr_hud_ms: 100,
        altitude_ms: 200,
        scaled_pressure_ms: 500,
        param_ms: 10,
    };

    /// Bytes per second these rates send at most (every payload at its full length), with
    /// a parameter download running.
    pub fn budget_bytes_per_s(&self) -> u32 {
        fn rate<D: MessageData>(period_ms: u16) -> u32 {
            if period_ms == 0 {
                return 0;
            }
            (12 + D::ENCODED_LEN as u32) * 1000 / u32::from(period_ms)
        }
        let heartbeat = if self.heartbeat_ms == 0 { Self::DEFAULT.heartbeat_ms } else { self.heartbeat_ms };
        rate::<HEARTBEAT_DATA>(heartbeat)
            + rate::<ATTITUDE_DATA>(self.attitude_ms)
            + rate::<SYS_STATUS_DATA>(self.sys_status_ms)
            + rate::<BATTERY_STATUS_DATA>(self.battery_ms)
            + rate::<RC_CHANNELS_DATA>(self.rc_channels_ms)
            + rate::<SERVO_OUTPUT_RAW_DATA>(self.servo_output_ms)
            + rate::<VFR_HUD_DATA>(self.vfr_hud_ms)
            + rate::<ALTITUDE_DATA>(self.altitude_ms)
            + rate::<SCALED_PRESSURE_DATA>(self.scaled_pressure_ms)
            + rate::<PARAM_VALUE_DATA>(self.param_ms)
    }
}

impl Default for Rates {
    fn default() -> Self {
        Self::DEFAULT
    }
}
