//! The yaw rate the pilot's stick asks for, worked out by the harness from the radio frames it
//! sends: their capture edges, decoded by fcu-core's own edge decoder and receiver with the
//! configuration the flight computer flies, give the sticks as the core sees them on each
//! tick, and [`RcConfig::yaw_rate_rad_s`] the rate they ask for. The yaw metric holds the
//! airframe to it whatever flies it (an emulated board's telemetry carries no yaw), as a pilot
//! knows what they asked for. In a failsafe it stays the pilot's stick while the core flies
//! its own, centred one; no yaw window lies in a failsafe.

use fcu_core::rc::{CaptureEdge, EdgeDecoder, RcConfig, Receiver};
use fcu_core::Config;

#[derive(Clone, Debug)]
pub struct StickRate {
    decoder: EdgeDecoder,
    receiver: Receiver,
    rc: RcConfig,
    outer_hz: f32,
}

impl StickRate {
    /// For a flight computer flying `cfg`.
    pub fn new(cfg: &Config) -> StickRate {
        StickRate { decoder: EdgeDecoder::new(cfg.rc.pulses), receiver: Receiver::new(), rc: cfg.rc, outer_hz: cfg.timing.outer_hz() }
    }

    /// One control tick's edges in (in time order); the stick's yaw rate on that tick out, °/s
    /// (0 with the throttle low, as the core has it).
    pub fn yaw_rate_dps(&mut self, edges: impl IntoIterator<Item = CaptureEdge>) -> f64 {
        for edge in edges {
            self.decoder.on_edge(edge);
        }
        let radio = self.receiver.update(&self.rc, &self.decoder.take(), |_| {});
        f64::from(self.rc.yaw_rate_rad_s(&radio.sticks, self.outer_hz)).to_degrees()
    }
}
