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
        "est_alt_m",
        "alt_target_m",
        "climb_m_s",
        "est_climb_m_s",
        "vmode",
        "alt_mode",
        "baro_fault",
    ] {
        assert!(header.split(',').any(|c| c == col), "missing column {col} in {header}");
    }
    assert!(csv.lines().count() > 20_000);
    assert!(out.contains("height RMS error while holding") && out.contains("touchdown speed"), "{out}");
    let svg = std::fs::read_to_string(dir.join("flight.svg")).unwrap_or_default();
    assert!(svg.starts_with("<svg"), "not an SVG: {}", svg.get(..80).unwrap_or_default());
    assert!(svg.contains("height (m above take-off"), "no height panel");
    // The state panel labels every state whatever the flight did; the state line is what must
    // show this one: calibrated, disarmed, through arming to armed, and disarmed at the end.
    let trace = state_trace(&svg);
    let mut wanted = ["calibrating", "disarmed", "arming", "armed", "disarmed"].into_iter().peekable();
    for state in &trace {
        if wanted.peek() == Some(&state.as_str()) {
            wanted.next();
        }
    }
    assert!(wanted.peek().is_none(), "the plotted state line went {trace:?}");
    assert_eq!(trace.last().map(String::as_str), Some("disarmed"), "the plotted state line went {trace:?}");
}

/// The states the SVG's state line passes through, in order (repeats merged): each point of
/// the thick black polyline with the most points, named after the state-axis label at its
/// height.
fn state_trace(svg: &str) -> Vec<String> {
    const STATES: [&str; 7] = ["fault", "calibrating", "disarmed", "arming", "failsafe2", "failsafe1", "armed"];
    let attr = |tag: &str, name: &str| -> Option<String> {
        let from = tag.find(&format!(" {name}=\""))? + name.len() + 3;
        let len = tag.get(from..)?.find('"')?;
        tag.get(from..from + len).map(str::to_string)
    };
    // Axis labels: <text ... y="Y" ...>\nNAME\n</text>.
    let labels: Vec<(f64, &str)> = svg
        .split("<text ")
        .skip(1)
        .filter_map(|t| {
            let (tag, rest) = t.split_once('>')?;
            let name = rest.split("</text>").next()?.trim();
            let state = STATES.into_iter().find(|s| *s == name)?;
            Some((attr(tag, "y")?.parse().ok()?, state))
        })
        .collect();
    assert_eq!(labels.len(), STATES.len(), "state axis labels: {labels:?}");
    let line = svg
        .split("<polyline ")
        .skip(1)
        .filter_map(|p| p.split_once("/>").map(|(tag, _)| tag))
        .filter(|tag| tag.contains("stroke=\"#000000\"") && tag.contains("stroke-width=\"2\""))
        .filter_map(|tag| attr(tag, "points"))
        .max_by_key(|points| points.split_whitespace().count())
        .unwrap_or_default();
    let mut trace: Vec<String> = Vec::new();
    for point in line.split_whitespace() {
        let y: f64 = point.split_once(',').and_then(|(_, y)| y.parse().ok()).unwrap_or(f64::NAN);
        let (label_y, state) = labels.iter().copied().min_by(|a, b| (a.0 - y).abs().total_cmp(&(b.0 - y).abs())).unwrap_or((0.0, "?"));
        assert!((label_y - y).abs() <= 2.0, "state line point {point} is at no state's level: {labels:?}");
        if trace.last().map(String::as_str) != Some(state) {
            trace.push(state.to_string());
        }
    }
    trace
}

#[test]
fn unknown_scenario_lists_the_known_ones_and_exits_2() {
    let (code, _, err) = fcu_sim(&["fly", "--scenario", "barrel-roll", "--out", "/tmp/x"]);
    assert_eq!(code, 2);
    assert!(err.contains("barrel-roll"), "{err}");
    for name in fcu_testkit::sim::scenario::names() {
        assert!(err.contains(name), "the error does not name {name}: {err}");
    }
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

#[test]
fn fly_help_lists_every_scenario_from_the_table() {
    let (code, out, err) = fcu_sim(&["fly", "--help"]);
    assert_eq!(code, 0, "{err}");
    for name in fcu_testkit::sim::scenario::names() {
        assert!(out.contains(name), "`fly --help` does not name {name}:\n{out}");
    }
}

#[test]
fn a_parameter_file_with_a_byte_order_mark_in_qgroundcontrols_format_flies_and_a_bad_map_is_named() {
    let dir = tmp("params-formats");
    let _ = std::fs::create_dir_all(&dir);
    let out = dir.join("flight");
    let out = out.to_str().unwrap_or_default();
    // ANGLE_MAX 60 was saved and pulled as 60.000004, which this reader refused (above the
    // maximum); a BOM made the first name unknown; QGroundControl's lines did not read.
    let good = dir.join("qgc.params");
    let _ =
        std::fs::write(&good, "\u{feff}# Vehicle-Id Component-Id Name Value Type\n1\t1\tANGLE_MAX\t60\t9\n1\t1\tYAW_RATE_MAX\t120\t9\n");
    let good = good.to_str().unwrap_or_default();
    // Taken, the flight runs (half a second of it, so its checks may fail: exit 1, not 2).
    let (code, stdout, err) = fcu_sim(&["fly", "--scenario", "hover", "--duration", "0.5", "--params", good, "--out", out]);
    assert!(code != 2 && stdout.contains("profile default"), "{code}: {stdout}\n{err}");
    // A radio map that is no permutation: its line and the rule, not a map rearranged.
    let bad = dir.join("map.parm");
    let _ = std::fs::write(&bad, "RCMAP_ROLL 2\nRCMAP_PITCH 2\n");
    let bad = bad.to_str().unwrap_or_default();
    let (code, _, err) = fcu_sim(&["fly", "--scenario", "hover", "--duration", "0.5", "--params", bad, "--out", out]);
    assert_eq!(code, 2);
    assert!(err.contains("map.parm: line 2: RCMAP: each input once"), "{err}");
}

#[test]
fn a_parameter_file_flies_the_other_transmitter_and_a_bad_one_is_named() {
    let dir = tmp("params");
    let _ = std::fs::create_dir_all(&dir);
    let out = dir.join("flight");
    let out = out.to_str().unwrap_or_default();
    let parm = concat!(env!("CARGO_MANIFEST_DIR"), "/data/other-transmitter.parm");
    let (code, stdout, err) = fcu_sim(&["fly", "--scenario", "other-transmitter", "--params", parm, "--out", out]);
    assert_eq!(code, 0, "{stdout}\n{err}");
    let (code, stdout, _) = fcu_sim(&["fly", "--scenario", "other-transmitter", "--duration", "5", "--out", out]);
    assert_eq!(code, 1, "without its parameters: {stdout}");

    let bad = dir.join("bad.parm");
    let _ = std::fs::write(&bad, "RCMAP_ROLL 2\n# fine so far\nRC1_MAX 9000\n");
    let bad = bad.to_str().unwrap_or_default();
    let (code, _, err) = fcu_sim(&["fly", "--scenario", "hover", "--params", bad, "--out", out]);
    assert_eq!(code, 2);
    assert!(err.contains("--params") && err.contains("bad.parm") && err.contains("line 3"), "{err}");
    let (code, _, err) = fcu_sim(&["fly", "--scenario", "hover", "--profile", "reference", "--params", parm, "--out", out]);
    assert_eq!(code, 2);
    assert!(err.contains("reference profile keeps no parameters"), "{err}");
}
