//! Golden vectors of the default profile, the one that ships: capture edges, raw sensor words
//! and the battery voltage in, compare values, quaternion and flight state out, tick for tick, for the first seconds of
//! several scenarios (boot, calibration, the arm gesture, take-off, steps, a link loss). The
//! inputs are stored, so the simulator can change without touching them; only a change of the
//! core's behaviour moves the outputs, and every value is compared bit for bit.
//!
//! A deliberate behaviour change regenerates them with one command, and the diff of
//! `fcu-testkit/data/golden-default/` then shows what moved:
//!
//! ```sh
//! FCU_BLESS=1 cargo test -p fcu-testkit --test golden_default
//! ```

use std::fmt::Write as _;
use std::io::{Read, Write as _};

use fcu_core::imu::RawImu;
use fcu_core::rc::CaptureEdge;
use fcu_testkit::sim::radio_model::TimedEdge;
use fcu_testkit::sim::{self, scenario, ComputerView, FlightComputer, InProcess, RunOptions, SimError};
use fcu_testkit::Profile;

/// The scenarios and the seconds recorded of each: boot (2 s), calibration, the arm gesture
/// (2.5..4 s), take-off, the 20° roll step at 8 s, the 0.5 s link loss at 8 s, the calibration
/// retried while the drone is rocked, a full-stick yaw turn from 8 s and its stop at 11 s (the
/// shaped turn).
const SCENARIOS: [(&str, f64); 5] = [("hover", 6.0), ("steps", 9.5), ("link-short", 10.0), ("calibration-motion", 10.0), ("yaw", 12.0)];

fn path(name: &str) -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("data/golden-default").join(format!("{name}.csv.gz"))
}

/// Records what the in-process core is given and what it answers, tick by tick.
struct Recorder {
    core: InProcess,
    text: String,
    tick: u64,
}

fn output_fields(out: &mut String, compare: [u16; 4], core: &InProcess) {
    let st = core.controller().status();
    let q = st.quat;
    let _ = write!(
        out,
        "{},{},{},{},{:08x},{:08x},{:08x},{:08x},{}",
        compare[0],
        compare[1],
        compare[2],
        compare[3],
        q.w.to_bits(),
        q.x.to_bits(),
        q.y.to_bits(),
        q.z.to_bits(),
        st.state.name()
    );
}

impl FlightComputer for Recorder {
    fn tick_hz(&self) -> f64 {
        self.core.tick_hz()
    }

    fn step(&mut self, t_end_s: f64, edges: &[TimedEdge], imu: RawImu, battery_v: f64) -> Result<[u16; 4], SimError> {
        let compare = self.core.step(t_end_s, edges, imu, battery_v)?;
        let g = imu.gyro;
        let a = imu.accel;
        // The battery as the core is given it (whole millivolts).
        let battery_mv = (battery_v * 1000.0).round() as u32;
        let _ = write!(self.text, "{},{},{},{},{},{},{},{battery_mv},", self.tick, g[0], g[1], g[2], a[0], a[1], a[2]);
        let edge_field: Vec<String> =
            edges.iter().map(|e| format!("{}:{}:{}", e.edge.channel, e.edge.capture_counts, u8::from(e.edge.level_high))).collect();
        let _ = write!(self.text, "{},", edge_field.join(";"));
        output_fields(&mut self.text, compare, &self.core);
        self.text.push('\n');
        self.tick += 1;
        Ok(compare)
    }

    fn view(&self) -> ComputerView {
        self.core.view()
    }
}

const HEADER: &str = "tick,gx,gy,gz,ax,ay,az,battery_mv,edges,m1,m2,m3,m4,qw_bits,qx_bits,qy_bits,qz_bits,state\n";

fn record(name: &str, seconds: f64) -> String {
    let sc = scenario::by_name(name).unwrap_or_else(|| panic!("no scenario {name}"));
    let mut rec = Recorder { core: InProcess::new(Profile::Default.config()).unwrap(), text: HEADER.to_string(), tick: 0 };
    let opts = RunOptions { seed: 1, duration_s: Some(seconds), ..RunOptions::default() };
    let _ = sim::run_with(&mut rec, &sc, Profile::Default, &opts).unwrap();
    rec.text
}

fn read_gz(p: &std::path::Path) -> String {
    let file =
        std::fs::File::open(p).unwrap_or_else(|e| panic!("{}: {e} (regenerate with FCU_BLESS=1, see this file's docs)", p.display()));
    let mut s = String::new();
    flate2::read::GzDecoder::new(file).read_to_string(&mut s).unwrap();
    s
}

fn write_gz(p: &std::path::Path, text: &str) {
    std::fs::create_dir_all(p.parent().unwrap()).unwrap();
    let file = std::fs::File::create(p).unwrap();
    let mut gz = flate2::write::GzEncoder::new(file, flate2::Compression::best());
    gz.write_all(text.as_bytes()).unwrap();
    gz.finish().unwrap();
}

/// Replays a stored file's inputs through a fresh default-profile core and checks every output.
fn replay(name: &str, seconds: f64) {
    let p = path(name);
    if std::env::var_os("FCU_BLESS").is_some() {
        write_gz(&p, &record(name, seconds));
    }
    let text = read_gz(&p);
    let mut lines = text.lines();
    assert_eq!(lines.next().map(|h| format!("{h}\n")), Some(HEADER.to_string()), "{name}: header");
    let mut core = InProcess::new(Profile::Default.config()).unwrap();
    let mut rows = 0;
    for (i, line) in lines.enumerate() {
        let f: Vec<&str> = line.split(',').collect();
        assert_eq!(f.len(), 18, "{name} line {}: {line}", i + 2);
        let n = |k: usize| f[k].parse::<i16>().unwrap_or_else(|_| panic!("{name} line {}: field {}", i + 2, k + 1));
        let imu = RawImu { gyro: [n(1), n(2), n(3)], accel: [n(4), n(5), n(6)] };
        let battery_mv: u32 = f[7].parse().unwrap_or_else(|_| panic!("{name} line {}: battery_mv", i + 2));
        let edges: Vec<TimedEdge> = f[8]
            .split(';')
            .filter(|e| !e.is_empty())
            .map(|e| {
                let p: Vec<&str> = e.split(':').collect();
                let edge = CaptureEdge { channel: p[0].parse().unwrap(), capture_counts: p[1].parse().unwrap(), level_high: p[2] == "1" };
                TimedEdge { t_s: 0.0, edge }
            })
            .collect();
        let compare = core.step(0.0, &edges, imu, f64::from(battery_mv) / 1000.0).unwrap();
        let mut got = String::new();
        output_fields(&mut got, compare, &core);
        let want = f[9..].join(",");
        assert_eq!(
            got, want,
            "{name}, tick {}: the default profile's output moved (a deliberate change? FCU_BLESS=1, see this file)",
            f[0]
        );
        rows += 1;
    }
    assert_eq!(rows, (seconds * 800.0).round() as usize, "{name}: rows");
}

#[test]
fn the_default_profile_replays_its_golden_vectors_bit_for_bit() {
    for (name, seconds) in SCENARIOS {
        replay(name, seconds);
    }
}
