//! Any bytes as the text files the host tools read: a `--sticks` timeline, a replay input, a
//! replay expectation, a BROAD recording. Each reader must answer with rows or an error (never
//! a panic), and an error message must stay short and printable.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let text = String::from_utf8_lossy(data);
    let check = |e: String| {
        assert!(e.len() < 400, "message of {} bytes", e.len());
        assert!(!e.chars().any(|c| c.is_control() && c != '\n'), "unprintable message {e:?}");
    };
    if let Err(e) = fcu_testkit::sim::scenario::Timeline::parse_csv(&text) {
        check(e);
    }
    if let Err(e) = fcu_testkit::replay::parse_input(&text) {
        check(e.to_string());
    }
    if let Err(e) = fcu_testkit::replay::parse_output(&text) {
        check(e.to_string());
    }
    if let Err(e) = fcu_testkit::broad::Recording::parse(&text) {
        check(e.to_string());
    }
});
