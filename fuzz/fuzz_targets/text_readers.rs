//! Any bytes as the text files the host tools read: a `--sticks` timeline, a replay input, a
//! replay expectation, a BROAD recording, and as a firmware STATUS line. Each reader must
//! answer with rows or an error (never a panic), and an error message must stay short and
//! printable; a STATUS line that parses must print back as a line that parses to the same.
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
    match fcu_core::telemetry::parse_status_line(&text) {
        Ok(fields) => {
            let mut line = fcu_core::telemetry::LineBuf::<{ fcu_core::telemetry::STATUS_LINE_MAX }>::new();
            fcu_core::telemetry::write_status_line(&mut line, &fields);
            assert!(!line.is_truncated(), "{}", line.as_str());
            assert_eq!(fcu_core::telemetry::parse_status_line(line.as_str()), Ok(fields));
        }
        Err(e) => check(e.to_string()),
    }
});
