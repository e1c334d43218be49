//! Raw capture-edge streams (any channel, counts and level, mixed with a receiver's valid
//! frames) → `EdgeDecoder` → the default `FlightController` with a level IMU; every
//! invariant of `fcu_testkit::safety::SafetyMonitor` is asserted on every tick.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Err(v) = fcu_fuzz::run(data, fcu_fuzz::Target::EdgesSupervisor) {
        panic!("{v}");
    }
});
