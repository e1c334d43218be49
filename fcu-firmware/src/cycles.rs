//! Waits timed on the DWT cycle counter, which `init` starts first: real cycles at 84 MHz
//! (16 MHz before the clock switch), whatever the flash wait states make of a loop.

use cortex_m::peripheral::DWT;

/// The cycle count now, for [`wait_since`].
pub fn now() -> u32 {
    DWT::cycle_count()
}

/// Spins until `cycles` have passed since `since`, a count taken with [`now`].
pub fn wait_since(since: u32, cycles: u32) {
    while DWT::cycle_count().wrapping_sub(since) < cycles {}
}

/// Polls `ready` until it gives a value, or gives up once `bound` cycles have passed.
pub fn poll<T>(bound: u32, mut ready: impl FnMut() -> Option<T>) -> Option<T> {
    let start = DWT::cycle_count();
    loop {
        if let Some(value) = ready() {
            return Some(value);
        }
        if DWT::cycle_count().wrapping_sub(start) > bound {
            return None;
        }
    }
}
