//! Interleaved capture edges and raw sensor words through the whole `FlightController`, in
//! the default, ESC and reference profiles. Default/ESC: every invariant of the monitor;
//! reference (whose supervisor is the reference's latch): compare range and no panic.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Err(v) = fcu_fuzz::run(data, fcu_fuzz::Target::FlightController) {
        panic!("{v}");
    }
});
