//! One control tick of the flight core as the firmware runs it, for every host-side driver
//! (the simulator, the safety rig, the tests): the tick's capture edges into the edge decoder
//! first (the capture interrupt outranks the control tick), then the pulses taken, the tick,
//! and its outer step when one is due, run at once (the firmware runs it in a lower-priority
//! task that finishes well before the next tick).

use fcu_core::baro::RawBaro;
use fcu_core::flight::{FlightController, TickOutput};
use fcu_core::imu::RawImu;
use fcu_core::rc::{CaptureEdge, EdgeDecoder, PulseBatch};

/// What one [`tick`] fed and got back.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ticked {
    /// The tick's output (its outer job, if any, has already run).
    pub out: TickOutput,
    /// The pulses the decoder handed to the tick.
    pub pulses: PulseBatch,
}

/// `edges` (in time order) → `decoder` → one tick of `fc` with `imu` → its outer step.
pub fn tick(fc: &mut FlightController, decoder: &mut EdgeDecoder, imu: RawImu, edges: impl IntoIterator<Item = CaptureEdge>) -> Ticked {
    tick_reading_baro(fc, decoder, imu, edges, || None)
}

/// [`tick`], with the barometer burst `read_baro` returns handed to the outer step when one
/// runs (`FlightController::set_baro`), read then and only then, as the firmware reads the
/// part once per outer step: a read clears the part's data-ready flag.
pub fn tick_reading_baro(
    fc: &mut FlightController,
    decoder: &mut EdgeDecoder,
    imu: RawImu,
    edges: impl IntoIterator<Item = CaptureEdge>,
    read_baro: impl FnOnce() -> Option<RawBaro>,
) -> Ticked {
    for edge in edges {
        decoder.on_edge(edge);
    }
    let pulses = decoder.take();
    let out = fc.tick(imu, &pulses);
    if let Some(job) = &out.outer_job {
        if let Some(raw) = read_baro() {
            fc.set_baro(Some(raw));
        }
        fc.run_outer(job);
    }
    Ticked { out, pulses }
}
