//! Bad input files and options for `fcu-sim`: each gets a short, printable error naming it and
//! exit status 2.

use std::process::Command;

fn fcu_sim(args: &[&str]) -> (i32, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_fcu-sim")).args(args).output().unwrap_or_else(|e| panic!("{e}"));
    (out.status.code().unwrap_or(-1), String::from_utf8_lossy(&out.stdout).into_owned(), String::from_utf8_lossy(&out.stderr).into_owned())
}

fn dir(name: &str) -> std::path::PathBuf {
    let d = std::env::temp_dir().join(format!("fcu-sim-inputs-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

#[test]
fn a_stick_time_of_1e308_is_an_error_not_a_crash() {
    let d = dir("huge-t");
    let sticks = d.join("s.csv");
    std::fs::write(&sticks, "t_s,ail_us,ele_us,thr_us,rud_us,link\n0,1500,1500,1000,1500,1\n1e308,1500,1500,1000,1500,1\n").unwrap();
    let (code, _, err) =
        fcu_sim(&["fly", "--scenario", "hover", "--sticks", sticks.to_str().unwrap(), "--out", d.join("out").to_str().unwrap()]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("line 3") && err.len() < 300, "{err}");
}

#[test]
fn a_duration_shorter_than_one_tick_is_refused() {
    let d = dir("short");
    let (code, _, err) = fcu_sim(&["fly", "--scenario", "hover", "--duration", "0.0001", "--out", d.join("out").to_str().unwrap()]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("--duration"), "{err}");
}

#[test]
fn an_expected_value_that_cannot_fail_is_refused() {
    let d = dir("inf");
    let input = concat!(env!("CARGO_MANIFEST_DIR"), "/data/golden/replay/scenario_1.in.csv.gz");
    let expect = concat!(env!("CARGO_MANIFEST_DIR"), "/data/golden/replay/scenario_1.out.csv.gz");
    let text = fcu_testkit::csv::read_text(std::path::Path::new(expect)).unwrap();
    let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
    let mut f: Vec<String> = lines[1].split(',').map(str::to_string).collect();
    f[5] = "inf".into();
    lines[1] = f.join(",");
    let bad = d.join("expect.csv");
    std::fs::write(&bad, lines.join("\n") + "\n").unwrap();
    let (code, _, err) = fcu_sim(&[
        "replay",
        "--profile",
        "reference",
        input,
        "--expect",
        bad.to_str().unwrap(),
        "--out",
        d.join("o.csv").to_str().unwrap(),
    ]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("line 2") && err.contains("not a finite f32"), "{err}");
}

#[test]
fn a_byte_order_mark_is_accepted() {
    let d = dir("bom");
    let sticks = d.join("s.csv");
    std::fs::write(&sticks, "\u{feff}t_s,ail_us,ele_us,thr_us,rud_us,link\n0,1500,1500,1000,1500,1\n").unwrap();
    let (code, out, err) = fcu_sim(&[
        "fly",
        "--scenario",
        "hover",
        "--sticks",
        sticks.to_str().unwrap(),
        "--duration",
        "0.5",
        "--out",
        d.join("out").to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{out}\n{err}");
}

#[test]
fn an_unwritable_out_is_named_before_the_flight_and_nothing_is_left_behind() {
    let d = dir("unwritable");
    // A file where the directory should be.
    let blocker = d.join("file");
    std::fs::write(&blocker, b"x").unwrap();
    let (code, out, err) = fcu_sim(&["fly", "--scenario", "hover", "--out", blocker.join("out").to_str().unwrap()]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("--out"), "{err}");
    assert!(!out.contains("simulated"), "the flight ran before the output was checked: {out}");
}

#[test]
fn replay_to_a_full_disk_is_an_error() {
    if !std::path::Path::new("/dev/full").exists() {
        return;
    }
    let input = concat!(env!("CARGO_MANIFEST_DIR"), "/data/golden/replay/scenario_1.in.csv.gz");
    let out = Command::new(env!("CARGO_BIN_EXE_fcu-sim"))
        .args(["replay", "--profile", "reference", input])
        .stdout(std::fs::File::create("/dev/full").unwrap())
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2), "{}", String::from_utf8_lossy(&out.stderr));
    assert!(String::from_utf8_lossy(&out.stderr).contains("standard output"));
}

#[test]
fn a_recording_whose_time_goes_back_or_whose_truth_is_zero_is_refused() {
    let d = dir("broad");
    let header = fcu_testkit::broad::HEADER;
    for (name, rows) in [
        ("back", "0.01,0,0,0,0,0,9.81,1,0,0,0,1\n0.005,0,0,0,0,0,9.81,1,0,0,0,1\n"),
        ("zero", "0.01,0,0,0,0,0,9.81,0,0,0,0,1\n0.02,0,0,0,0,0,9.81,1,0,0,0,1\n"),
    ] {
        let f = d.join(format!("{name}.csv"));
        std::fs::write(&f, format!("{header}\n{rows}")).unwrap();
        let (code, _, err) = fcu_sim(&["estimate", f.to_str().unwrap(), "--out", d.join("est.csv").to_str().unwrap()]);
        assert_eq!(code, 2, "{name}: {err}");
        assert!(err.contains("line 2") || err.contains("line 3"), "{name}: {err}");
        assert!(!d.join("est.csv").exists(), "{name}: output left behind");
    }
}

#[test]
#[cfg(unix)]
fn the_flight_log_is_streamed_and_a_write_error_stops_the_flight_at_once() {
    // The CSV is written as the flight runs: with its file on a full disk, the first buffer
    // that reaches it fails within the first few dozen rows of an hour's flight (were the log
    // written at the end, this test would fly the whole hour), and nothing is left behind.
    if !std::path::Path::new("/dev/full").exists() {
        eprintln!("skipped: no /dev/full on this system");
        return;
    }
    let d = dir("stream");
    let out = d.join("out");
    std::fs::create_dir_all(&out).unwrap();
    std::os::unix::fs::symlink("/dev/full", out.join(".flight.csv.partial")).unwrap();
    let (code, _, err) = fcu_sim(&["fly", "--scenario", "hover", "--duration", "3600", "--out", out.to_str().unwrap()]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("flight.csv") && err.contains("No space left"), "{err}");
    let left: Vec<_> = std::fs::read_dir(&out).unwrap().map(|e| e.unwrap().file_name()).collect();
    assert!(left.is_empty(), "left behind: {left:?}");
}

#[test]
fn margins_refuses_bad_options_by_name() {
    for (args, named) in [
        (&["margins", "--extra-delay-ticks", "100"][..], "--extra-delay-ticks"),
        (&["margins", "--spread", "2"][..], "--spread"),
        (&["margins", "--profile", "fast"][..], "--profile"),
        (&["margins", "--spread", "NaN"][..], "--spread"),
        (&["margins", "--seed", "x"][..], "--seed"),
        (&["margins", "--extra-delay-ticks", "-1"][..], "--extra-delay-ticks"),
        (&["margins", "--out"][..], "--out"),
    ] {
        let (code, _, err) = fcu_sim(args);
        assert_eq!(code, 2, "{args:?}: {err}");
        assert!(err.contains(named) && err.len() < 300, "{args:?}: {err}");
    }
}

#[test]
fn margins_writes_its_response_and_bode_plot_and_passes() {
    let d = dir("margins");
    let out = d.join("out");
    let (code, stdout, err) = fcu_sim(&["margins", "--out", out.to_str().unwrap()]);
    assert_eq!(code, 0, "{stdout}{err}");
    assert!(stdout.contains("PASS") && stdout.contains("pitch") && stdout.contains("yaw"), "{stdout}");
    let csv = std::fs::read_to_string(out.join("margins.csv")).unwrap();
    assert!(csv.starts_with("freq_hz,pitch_gain_db,pitch_phase_deg,pitch_coherence,roll_gain_db"), "{csv}");
    assert!(csv.lines().count() > 30);
    // Every row: a frequency and, per axis, a gain, a phase and a coherence in 0..1.
    for line in csv.lines().skip(1) {
        let v: Vec<f64> = line.split(',').map(|x| x.parse().unwrap_or(f64::NAN)).collect();
        assert_eq!(v.len(), 10, "{line}");
        assert!(v[0] > 0.0 && [3, 6, 9].iter().all(|&k| (0.0..=1.0).contains(&v[k])), "{line}");
    }
    let svg = std::fs::read_to_string(out.join("margins.svg")).unwrap();
    assert!(svg.contains("<svg") && svg.contains("PM") && svg.contains("coherence"), "svg without its legend");
    let left: Vec<_> = std::fs::read_dir(&out).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    assert!(left.iter().all(|n| !n.contains("partial")), "temporary files left: {left:?}");
    // The reference's gains fail the requirement: exit 1.
    let (code, stdout, _) = fcu_sim(&["margins", "--profile", "reference"]);
    assert_eq!(code, 1, "{stdout}");
}

#[test]
fn margins_cannot_write_into_a_file_and_says_so() {
    let d = dir("margins-file");
    let file = d.join("not-a-dir");
    std::fs::write(&file, b"x").unwrap();
    let (code, _, err) = fcu_sim(&["margins", "--out", file.to_str().unwrap()]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("--out") && err.len() < 300, "{err}");
    assert_eq!(std::fs::read(&file).unwrap(), b"x");
}
