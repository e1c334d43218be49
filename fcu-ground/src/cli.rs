//! The commands, from their arguments to their output and exit status.

use std::io::{IsTerminal, Write};
use std::path::Path;
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use mavlink::dialects::common::MavMessage;

use crate::address::LinkAddress;
use crate::connection::Connection;
use crate::param_file::{self, Difference, Entry};
use crate::params;
use crate::record::{Recorder, Recording};
use crate::watch::{self, View};

/// A command's failure: the message (naming what failed), exit status 2.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Failure(pub String);

impl<E: std::fmt::Display> From<E> for Failure {
    fn from(e: E) -> Failure {
        Failure(e.to_string())
    }
}

/// Exit status for differences found or sets refused.
pub const EXIT_DIFFERENT: u8 = 1;

/// Where and how patiently to reach the board.
#[derive(Clone, Debug)]
pub struct Target {
    pub link: LinkAddress,
    pub timeout: Duration,
}

impl Target {
    /// Opens the link and waits for the board's HEARTBEAT.
    fn connect(&self) -> Result<(Connection, mavlink::dialects::common::HEARTBEAT_DATA), Failure> {
        let mut conn = Connection::open(&self.link, self.timeout)?;
        let hb = conn.wait_for_board(self.timeout)?;
        Ok((conn, hb))
    }
}

fn read_file(path: &Path) -> Result<Vec<Entry>, Failure> {
    let text = std::fs::read_to_string(path).map_err(|e| Failure(format!("{}: {e}", path.display())))?;
    param_file::parse(&text).map_err(|e| Failure(format!("{}: {e}", path.display())))
}

/// `params pull FILE`.
pub fn pull(target: &Target, file: &Path) -> Result<ExitCode, Failure> {
    let (mut conn, _) = target.connect()?;
    let board = params::pull(&mut conn, target.timeout)?;
    std::fs::write(file, param_file::write(&board.list)).map_err(|e| Failure(format!("{}: {e}", file.display())))?;
    println!("pulled {} parameters into {}", board.list.len(), file.display());
    Ok(ExitCode::SUCCESS)
}

/// Every entry of the file the board does not have, as one error naming their lines.
fn check_names(file: &Path, entries: &[Entry], board: &std::collections::BTreeMap<String, f32>) -> Result<(), Failure> {
    let unknown: Vec<String> = entries
        .iter()
        .filter(|e| !board.contains_key(&e.name))
        .map(|e| format!("{}: line {}: {}: the board has no such parameter", file.display(), e.line, e.name))
        .collect();
    if unknown.is_empty() {
        Ok(())
    } else {
        Err(Failure(unknown.join("\n")))
    }
}

/// A radio map the file makes (over `board`, if known) that is not a permutation: refused with
/// its line, before any set is sent.
fn check_map(file: &Path, entries: &[Entry], board: Option<&std::collections::BTreeMap<String, f32>>) -> Result<(), Failure> {
    match param_file::map_problem(entries, board) {
        Some(e) => Err(Failure(format!("{}: {e} (the radio map must be a permutation; nothing was set)", file.display()))),
        None => Ok(()),
    }
}

/// `params push FILE`.
pub fn push(target: &Target, file: &Path) -> Result<ExitCode, Failure> {
    let entries = read_file(file)?;
    check_map(file, &entries, None)?;
    let (mut conn, _) = target.connect()?;
    let mut board = params::pull(&mut conn, target.timeout)?.by_name();
    check_names(file, &entries, &board)?;
    check_map(file, &entries, Some(&board))?;
    let report = params::push(&mut conn, &entries, &mut board, &mut |name, old, new| println!("{name}: {old} -> {new}"))?;
    for r in &report.refused {
        let rule = r.rule.as_deref().unwrap_or("the board named no rule");
        println!("{}: refused {} (line {}): {rule}; the board keeps {}", r.entry.name, r.entry.value, r.entry.line, r.in_force);
    }
    println!("{} set, {} refused, {} already held the file's value", report.taken.len(), report.refused.len(), report.unchanged);
    Ok(if report.refused.is_empty() { ExitCode::SUCCESS } else { ExitCode::from(EXIT_DIFFERENT) })
}

/// `params diff FILE`.
pub fn diff(target: &Target, file: &Path) -> Result<ExitCode, Failure> {
    let entries = read_file(file)?;
    let (mut conn, _) = target.connect()?;
    let board = params::pull(&mut conn, target.timeout)?.by_name();
    let differences: Vec<Difference> = param_file::diff(&entries, &board);
    for d in &differences {
        println!("{d}");
    }
    let not_named =
        board.len().saturating_sub(entries.len() - differences.iter().filter(|d| matches!(d, Difference::Unknown { .. })).count());
    if differences.is_empty() {
        println!("no differences: the {} parameters {} names hold its values on the board", entries.len(), file.display());
    } else {
        let n = differences.len();
        println!("{n} difference{}", if n == 1 { "" } else { "s" });
    }
    if not_named > 0 {
        println!("({not_named} parameters of the board are not in {})", file.display());
    }
    Ok(if differences.is_empty() { ExitCode::SUCCESS } else { ExitCode::from(EXIT_DIFFERENT) })
}

/// Ctrl-C sets the returned flag instead of ending the process (a recording is still
/// written); before it is installed, Ctrl-C ends the process as usual.
fn interrupt_flag() -> Arc<AtomicBool> {
    let flag = Arc::new(AtomicBool::new(false));
    let set = Arc::clone(&flag);
    if let Err(e) = ctrlc::set_handler(move || set.store(true, Ordering::Relaxed)) {
        eprintln!("fcu-ground: Ctrl-C will end the process at once ({e})");
    }
    flag
}

fn finished(started: Instant, duration: Option<Duration>, interrupted: &AtomicBool) -> bool {
    interrupted.load(Ordering::Relaxed) || duration.is_some_and(|d| started.elapsed() >= d)
}

/// `record --out DIR [--duration S]`.
pub fn record(target: &Target, out: &Path, duration: Option<Duration>) -> Result<ExitCode, Failure> {
    let dir = fcu_log::OutputDir::prepare(out).map_err(Failure)?;
    // A directory this run created goes again if the run fails.
    let fail = |message: String| dir.abandon(Failure(message));
    let (mut conn, hb) = target.connect().map_err(|e| fail(e.0))?;
    let throttle = match params::read_by_name(&mut conn, "RCMAP_THROTTLE") {
        Ok(Some(v)) if (1.0..=8.0).contains(&v) => Some(v as u8),
        _ => {
            eprintln!("fcu-ground: the board did not say RCMAP_THROTTLE: the thr_us column stays empty");
            None
        }
    };
    // From here on Ctrl-C ends the recording, not the process; before, it ends a wait.
    let interrupted = interrupt_flag();
    let mut recorder = Recorder::new(throttle);
    recorder.on_message(&MavMessage::HEARTBEAT(hb));
    let mut rec = Recording::create(out).map_err(fail)?;
    let started = Instant::now();
    let ended: Result<(), Failure> = loop {
        if finished(started, duration, &interrupted) {
            break Ok(());
        }
        let msg = match conn.recv(Duration::from_millis(100)) {
            Ok(Some(m)) => m,
            Ok(None) => continue,
            Err(e) => break Err(Failure(format!("{e} after {:.1} s of recording", started.elapsed().as_secs_f64()))),
        };
        if let MavMessage::STATUSTEXT(t) = &msg {
            let severity = watch::severity_name(t.severity);
            let text = t.text.to_str().unwrap_or("(not UTF-8)").trim_end().to_string();
            println!("{:8.3} s [{severity}] {text}", recorder.now_s());
            rec.text(recorder.now_s(), severity, &text);
        }
        if let Some(sample) = recorder.on_message(&msg) {
            if let Err(e) = rec.row(&sample) {
                rec.abandon();
                return Err(fail(e));
            }
        }
    };
    if rec.rows() == 0 {
        rec.abandon();
        let why = ended.err().map_or_else(|| "no ATTITUDE from the board: nothing to record".to_string(), |e| e.0);
        return Err(fail(why));
    }
    let rows = rec.rows();
    let title = format!("fcu-ground record: {}, {rows} rows", target.link);
    let [csv, svg, texts] = rec.finish(&title).map_err(fail)?;
    println!("wrote {} ({rows} rows), {} and {}", csv.display(), svg.display(), texts.display());
    ended.map(|()| ExitCode::SUCCESS)
}

/// `watch [--duration S]`.
pub fn watch(target: &Target, duration: Option<Duration>) -> Result<ExitCode, Failure> {
    let (mut conn, hb) = target.connect()?;
    let interrupted = interrupt_flag();
    let title = format!("fcu-ground watch: {}   ({})", target.link, if duration.is_some() { "until --duration" } else { "Ctrl-C ends" });
    let tty = std::io::stdout().is_terminal();
    let period = if tty { Duration::from_millis(200) } else { Duration::from_secs(1) };
    let started = Instant::now();
    let mut view = View::default();
    view.on_message(&MavMessage::HEARTBEAT(hb), 0.0);
    let mut stdout = std::io::stdout();
    if tty {
        let _ = write!(stdout, "\x1b[2J");
    }
    let mut next_draw = started;
    let ended = loop {
        let now = Instant::now();
        if now >= next_draw || finished(started, duration, &interrupted) {
            let screen = view.render(&title, started.elapsed().as_secs_f64());
            let frame = if tty { watch::redraw(&screen) } else { format!("{screen}\n") };
            if stdout.write_all(frame.as_bytes()).and_then(|()| stdout.flush()).is_err() {
                // Nobody reads the output any more (a closed pipe): nothing left to show.
                break Ok(());
            }
            next_draw = now + period;
        }
        if finished(started, duration, &interrupted) {
            break Ok(());
        }
        match conn.recv(next_draw.saturating_duration_since(Instant::now()).min(Duration::from_millis(100))) {
            Ok(Some(m)) => view.on_message(&m, started.elapsed().as_secs_f64()),
            Ok(None) => {}
            Err(e) => break Err(Failure(e.to_string())),
        }
    };
    ended.map(|()| ExitCode::SUCCESS)
}

/// A `--duration` or `--timeout`: seconds, finite, above zero, at most a year.
pub fn parse_seconds(text: &str) -> Result<Duration, String> {
    let s: f64 = text.trim().parse().map_err(|_| format!("`{text}` is not a number of seconds"))?;
    if !s.is_finite() || s <= 0.0 {
        return Err(format!("`{text}`: give a number of seconds above 0"));
    }
    if s > 365.0 * 86_400.0 {
        return Err(format!("`{text}`: at most a year"));
    }
    Duration::try_from_secs_f64(s).map_err(|e| format!("`{text}`: {e}"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_push_whose_radio_map_is_no_permutation_is_refused_before_any_set() {
        use crate::mock_board::{serve, MockParam, MockState};
        let map = ["RCMAP_ROLL", "RCMAP_PITCH", "RCMAP_THROTTLE", "RCMAP_YAW"];
        let params: Vec<MockParam> =
            map.iter().enumerate().map(|(i, &name)| MockParam { name, value: i as f32 + 1.0, min: 1.0, max: 4.0 }).collect();
        let dir = std::env::temp_dir().join(format!("fcu-ground-map-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let run = |text: &str, file: &str| {
            let (port, state) = serve(MockState { params: params.clone(), ..MockState::default() });
            let path = dir.join(file);
            std::fs::write(&path, text).unwrap();
            let target = Target { link: LinkAddress::Tcp { host: "127.0.0.1".into(), port }, timeout: Duration::from_secs(5) };
            let got = push(&target, &path);
            let sets = state.lock().unwrap().sets.clone();
            (got, sets)
        };
        // Sent one at a time, ROLL 2 swapped with pitch and PITCH 2 swapped back: exit 0 and
        // the map as before. Refused, naming the line and the rule, and nothing set.
        let (got, sets) = run("RCMAP_ROLL 2\nRCMAP_PITCH 2\n", "both.param");
        let e = got.unwrap_err().0;
        assert!(e.contains("both.param: line 2: RCMAP_PITCH: RCMAP: each input once"), "{e}");
        assert!(sets.is_empty(), "{sets:?}");
        // One entry, against the board's map.
        let (got, sets) = run("RCMAP_ROLL 2\n", "one.param");
        let e = got.unwrap_err().0;
        assert!(e.contains("one.param: line 1: RCMAP_ROLL: RCMAP: each input once"), "{e}");
        assert!(sets.is_empty(), "{sets:?}");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn params_push_and_diff_take_qgroundcontrol_and_mavproxy_files_alike() {
        use crate::mock_board::{serve, MockParam, MockState};
        let table = |lo: f32, hi: f32| {
            vec![
                MockParam { name: "ANGLE_MAX", value: 30.0, min: 5.0, max: 60.0 },
                MockParam { name: "LO", value: lo, min: 0.0, max: 100.0 },
                MockParam { name: "HI", value: hi, min: 0.0, max: 100.0 },
            ]
        };
        let dir = std::env::temp_dir().join(format!("fcu-ground-formats-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let target = |port| Target { link: LinkAddress::Tcp { host: "127.0.0.1".into(), port }, timeout: Duration::from_secs(5) };
        // QGroundControl's `.params` (its header, tabs, the vehicle's ids and the type), with the
        // byte-order mark a Windows editor adds; MAVProxy's `param save` (names padded to 16).
        let qgc = "\u{feff}# Onboard parameters for Vehicle 1\n#\n# Vehicle-Id\tComponent-Id\tName\tValue\tType\n\
                   1\t1\tHI\t40.000000000000000000\t9\n1\t1\tLO\t30\t9\n";
        let mavproxy = "HI               40.000000\nLO               30.000000\n";
        for (file, text) in [("board.params", qgc), ("board.parm", mavproxy)] {
            let path = dir.join(file);
            std::fs::write(&path, text).unwrap();
            let (port, _) = serve(MockState { params: table(10.0, 20.0), ..MockState::default() });
            assert_eq!(diff(&target(port), &path), Ok(ExitCode::from(EXIT_DIFFERENT)), "{file}");
            let (port, state) = serve(MockState { params: table(10.0, 20.0), ..MockState::default() });
            assert_eq!(push(&target(port), &path), Ok(ExitCode::SUCCESS), "{file}");
            let values: Vec<(&str, f32)> = state.lock().unwrap().params.iter().map(|p| (p.name, p.value)).collect();
            assert_eq!(values, [("ANGLE_MAX", 30.0), ("LO", 30.0), ("HI", 40.0)], "{file}");
            let (port, _) = serve(MockState { params: table(30.0, 40.0), ..MockState::default() });
            assert_eq!(diff(&target(port), &path), Ok(ExitCode::SUCCESS), "{file}");
        }
        // A QGroundControl line whose ids are not whole numbers is not taken for one.
        let path = dir.join("bad.params");
        std::fs::write(&path, "1\t1.5\tHI\t40\t9\n").unwrap();
        let (port, _) = serve(MockState { params: table(10.0, 20.0), ..MockState::default() });
        let e = push(&target(port), &path).unwrap_err().0;
        assert!(e.contains("bad.params: line 1: `HI` after the value"), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn seconds_are_checked() {
        assert_eq!(parse_seconds("2.5"), Ok(Duration::from_millis(2500)));
        for bad in ["0", "-1", "nan", "inf", "1e300", "x", ""] {
            assert!(parse_seconds(bad).is_err(), "{bad}");
        }
    }
}
