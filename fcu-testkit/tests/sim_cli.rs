//! `fcu-sim fly` / `compare`: files written, exit codes, and errors that name their cause.

use std::process::Command;

use fcu_core::supervisor::FlightState;

fn fcu_sim(args: &[&str]) -> (i32, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_fcu-sim")).args(args).output().unwrap_or_else(|e| panic!("{e}"));
    (out.status.code().unwrap_or(-1), String::from_utf8_lossy(&out.stdout).into_owned(), String::from_utf8_lossy(&out.stderr).into_owned())
}

fn tmp(name: &str) -> std::path::PathBuf {
    let d = std::env::temp_dir().join(format!("fcu-sim-test-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    d
}

#[test]
fn fly_hover_writes_csv_and_svg_and_passes() {
    let dir = tmp("hover");
    let (code, out, err) = fcu_sim(&["fly", "--scenario", "hover", "--out", dir.to_str().unwrap_or_default()]);
    assert_eq!(code, 0, "{out}\n{err}");
    assert!(out.contains("RMS attitude error while hovering") && out.contains("PASS"), "{out}");
    let csv = std::fs::read_to_string(dir.join("flight.csv")).unwrap_or_default();
    let header = csv.lines().next().unwrap_or_default();
    for col in [
        "t_s",
        "state",
        "armed",
        "roll_deg",
        "pitch_deg",
        "yaw_deg",
        "est_roll_deg",
        "est_pitch_deg",
        "roll_target_deg",
        "pitch_target_deg",
        "m1",
        "m2",
        "m3",
        "m4",
        "alt_m",
    ] {
        assert!(header.split(',').any(|c| c == col), "missing column {col} in {header}");
    }
    assert!(csv.lines().count() > 20_000);
    let svg = std::fs::read_to_string(dir.join("flight.svg")).unwrap_or_default();
    assert!(svg.starts_with("<svg") && svg.contains("armed"), "svg");
}

#[test]
fn unknown_scenario_lists_the_known_ones_and_exits_2() {
    let (code, _, err) = fcu_sim(&["fly", "--scenario", "barrel-roll", "--out", "/tmp/x"]);
    assert_eq!(code, 2);
    assert!(err.contains("barrel-roll") && err.contains("hover") && err.contains("link-long"), "{err}");
}

#[test]
fn bad_profile_and_duration_are_named() {
    let (code, _, err) = fcu_sim(&["fly", "--scenario", "hover", "--profile", "fast", "--out", "/tmp/x"]);
    assert_eq!(code, 2);
    assert!(err.contains("--profile"), "{err}");
    let (code, _, err) = fcu_sim(&["fly", "--scenario", "hover", "--duration=-3", "--out", "/tmp/x"]);
    assert_eq!(code, 2);
    assert!(err.contains("--duration"), "{err}");
}

#[test]
fn sticks_file_errors_name_the_line_and_a_good_file_flies() {
    let dir = tmp("sticks");
    let _ = std::fs::create_dir_all(&dir);
    let missing = dir.join("nope.csv");
    let (code, _, err) = fcu_sim(&[
        "fly",
        "--scenario",
        "hover",
        "--sticks",
        missing.to_str().unwrap_or_default(),
        "--out",
        dir.to_str().unwrap_or_default(),
    ]);
    assert_eq!(code, 2);
    assert!(err.contains("nope.csv"), "{err}");

    let bad = dir.join("bad.csv");
    let _ = std::fs::write(&bad, "t_s,ail_us,ele_us,thr_us,rud_us,link\n0,1465.5,1537.75,1000,1599.25,1\n1,1465.5,abc,1000,1599.25,1\n");
    let (code, _, err) =
        fcu_sim(&["fly", "--scenario", "hover", "--sticks", bad.to_str().unwrap_or_default(), "--out", dir.to_str().unwrap_or_default()]);
    assert_eq!(code, 2);
    assert!(err.contains("line 3") && err.contains("ele_us"), "{err}");

    // Arm by gesture from a file, then throttle to 1300 µs: the drone arms and climbs.
    let good = dir.join("good.csv");
    let _ = std::fs::write(
        &good,
        "t_s,ail_us,ele_us,thr_us,rud_us,link\n0,1465.5,1537.75,1000,1599.25,1\n2.5,1090,1163,1000,1975,1\n4,1465.5,1537.75,1000,1599.25,1\n4.5,1465.5,1537.75,1300,1599.25,1\n",
    );
    let (code, out, err) =
        fcu_sim(&["fly", "--scenario", "hover", "--sticks", good.to_str().unwrap_or_default(), "--out", dir.to_str().unwrap_or_default()]);
    assert_eq!(code, 0, "{out}\n{err}");
    let csv = std::fs::read_to_string(dir.join("flight.csv")).unwrap_or_default();
    let states: Vec<Option<FlightState>> = csv.lines().skip(1).map(|l| l.split(',').nth(1).and_then(FlightState::from_name)).collect();
    assert!(!states.is_empty() && states.iter().all(Option::is_some), "a row without a state the core names");
    assert!(states.contains(&Some(FlightState::Armed)), "never armed from the file's gesture");
}

#[test]
fn compare_prints_both_profiles() {
    let (code, out, err) = fcu_sim(&["compare", "--scenario", "link-long", "--seed", "2"]);
    assert_eq!(code, 0, "{err}");
    assert!(out.contains("reference") && out.contains("default") && out.contains("time to level"), "{out}");
}
