//! The golden replay format (`fcu-testkit/data/golden/README.md` §4): one input row per control
//! tick (raw LSM6DSL words in sensor axes, pulse widths, link/armed/calibration flags), one output
//! row per tick (compare values, quaternion, Euler, yaw, rate demands).
//!
//! The replay drives [`FlightController::tick_forced`]: the radio state comes from the row,
//! and the outer step runs right after the tick that made it due, before the row is written,
//! as the reference's main loop does.

use std::fmt::Write as _;

use fcu_core::flight::ForcedRadio;
use fcu_core::imu::RawImu;
use fcu_core::{Config, FlightController};

use crate::csv::{data_lines, fmt_g9, CsvError, Header, Row};

/// One input row.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct InputRow {
    pub tick: u32,
    pub imu: RawImu,
    pub radio: ForcedRadio,
}

/// One output row.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OutputRow {
    pub tick: u32,
    pub ccr: [u16; 4],
    pub q: [f32; 4],
    pub pitch: f32,
    pub roll: f32,
    pub yaw_est: f32,
    pub yaw_target: f32,
    pub s1: [f32; 3],
}

pub const INPUT_COLUMNS: [&str; 14] = [
    "tick",
    "acc_x",
    "acc_y",
    "acc_z",
    "gyro_x",
    "gyro_y",
    "gyro_z",
    "ail_width",
    "ele_width",
    "thr_width",
    "rud_width",
    "link",
    "armed",
    "cal_request",
];

pub const OUTPUT_HEADER: &str = "tick,ccr1,ccr2,ccr3,ccr4,q0,q1,q2,q3,pitch,roll,yaw_est,yaw_target,s1_x,s1_y,s1_z";

/// Parse a replay input file; the error names the first bad line and column.
pub fn parse_input(text: &str) -> Result<Vec<InputRow>, CsvError> {
    let first = text.lines().next().ok_or_else(|| CsvError { line: 1, message: "empty file: no header".into() })?;
    let header = Header::parse(first);
    let ix = header.indices(INPUT_COLUMNS)?;
    let mut rows = Vec::new();
    for (line, l) in data_lines(text) {
        let r = Row::split(line, l, &header)?;
        let [t, ax, ay, az, gx, gy, gz, w0, w1, w2, w3, link, armed, cal] = ix;
        rows.push(InputRow {
            tick: r.get(t)?,
            imu: RawImu { accel: [r.get(ax)?, r.get(ay)?, r.get(az)?], gyro: [r.get(gx)?, r.get(gy)?, r.get(gz)?] },
            radio: ForcedRadio {
                width_counts: [r.get(w0)?, r.get(w1)?, r.get(w2)?, r.get(w3)?],
                link: r.flag(link)?,
                armed: r.flag(armed)?,
                cal_request: r.flag(cal)?,
            },
        });
    }
    Ok(rows)
}

/// Run the rows through a fresh flight controller with `cfg`.
pub fn run(cfg: Config, rows: &[InputRow]) -> Result<Vec<OutputRow>, fcu_core::ConfigError> {
    let mut fc = FlightController::new(&cfg)?;
    Ok(rows
        .iter()
        .map(|row| {
            let out = fc.tick_forced(row.imu, &row.radio);
            if let Some(job) = out.outer_job {
                fc.run_outer(&job);
            }
            let st = fc.status();
            OutputRow {
                tick: row.tick,
                ccr: st.compare,
                q: [st.quat.w, st.quat.x, st.quat.y, st.quat.z],
                pitch: st.tilt.pitch_rad,
                roll: st.tilt.roll_rad,
                yaw_est: st.yaw_est_rad,
                yaw_target: st.target_rad[2],
                s1: st.rate_demand_rad_s,
            }
        })
        .collect())
}

/// Format output rows (with the header) as the golden files do.
pub fn format_output(rows: &[OutputRow]) -> String {
    let mut s = String::with_capacity(rows.len() * 130);
    s.push_str(OUTPUT_HEADER);
    s.push('\n');
    for r in rows {
        let _ = write!(s, "{}", r.tick);
        for c in r.ccr {
            let _ = write!(s, ",{c}");
        }
        let floats = [r.q[0], r.q[1], r.q[2], r.q[3], r.pitch, r.roll, r.yaw_est, r.yaw_target, r.s1[0], r.s1[1], r.s1[2]];
        for v in floats {
            s.push(',');
            s.push_str(&fmt_g9(v));
        }
        s.push('\n');
    }
    s
}

/// Parse an output file (for comparisons).
pub fn parse_output(text: &str) -> Result<Vec<OutputRow>, CsvError> {
    let first = text.lines().next().ok_or_else(|| CsvError { line: 1, message: "empty file: no header".into() })?;
    let header = Header::parse(first);
    let ix = header.indices([
        "tick",
        "ccr1",
        "ccr2",
        "ccr3",
        "ccr4",
        "q0",
        "q1",
        "q2",
        "q3",
        "pitch",
        "roll",
        "yaw_est",
        "yaw_target",
        "s1_x",
        "s1_y",
        "s1_z",
    ])?;
    let mut rows = Vec::new();
    for (line, l) in data_lines(text) {
        let r = Row::split(line, l, &header)?;
        // Expected values must be finite: against inf (or an f32 overflow such as -1e39),
        // every comparison would pass.
        let f = |k: usize| -> Result<f32, CsvError> { r.finite_f32(ix[k]) };
        rows.push(OutputRow {
            tick: r.get(ix[0])?,
            ccr: [r.get(ix[1])?, r.get(ix[2])?, r.get(ix[3])?, r.get(ix[4])?],
            q: [f(5)?, f(6)?, f(7)?, f(8)?],
            pitch: f(9)?,
            roll: f(10)?,
            yaw_est: f(11)?,
            yaw_target: f(12)?,
            s1: [f(13)?, f(14)?, f(15)?],
        });
    }
    Ok(rows)
}

/// How two replays differ, against the tolerances of `docs/golden.md#tolerances`.
#[derive(Debug, Default, Clone, PartialEq)]
pub struct Comparison {
    pub rows: usize,
    /// Float values not bit-identical.
    pub inexact_floats: usize,
    /// Compare values not identical.
    pub inexact_ccr: usize,
    /// Values outside the tolerance (compare ±1; floats 1e-4 relative or 1e-5 absolute).
    pub out_of_tolerance: Vec<String>,
}

/// Compare `got` with `want` row by row.
pub fn compare(got: &[OutputRow], want: &[OutputRow]) -> Comparison {
    let mut c = Comparison { rows: want.len(), ..Comparison::default() };
    if got.len() != want.len() {
        c.out_of_tolerance.push(format!("row count {} vs {}", got.len(), want.len()));
    }
    let names = ["q0", "q1", "q2", "q3", "pitch", "roll", "yaw_est", "yaw_target", "s1_x", "s1_y", "s1_z"];
    for (g, w) in got.iter().zip(want) {
        for (k, (a, b)) in g.ccr.iter().zip(w.ccr).enumerate() {
            if *a != b {
                c.inexact_ccr += 1;
                if a.abs_diff(b) > 1 {
                    c.out_of_tolerance.push(format!("tick {}: ccr{} {} vs {}", w.tick, k + 1, a, b));
                }
            }
        }
        let gf = [g.q[0], g.q[1], g.q[2], g.q[3], g.pitch, g.roll, g.yaw_est, g.yaw_target, g.s1[0], g.s1[1], g.s1[2]];
        let wf = [w.q[0], w.q[1], w.q[2], w.q[3], w.pitch, w.roll, w.yaw_est, w.yaw_target, w.s1[0], w.s1[1], w.s1[2]];
        for ((a, b), name) in gf.iter().zip(wf).zip(names) {
            if a.to_bits() != b.to_bits() && !(a.is_nan() && b.is_nan()) && *a != b {
                c.inexact_floats += 1;
                let diff = (a - b).abs();
                if !(diff <= 1e-5 || diff <= 1e-4 * b.abs()) {
                    c.out_of_tolerance.push(format!("tick {}: {} {} vs {}", w.tick, name, a, b));
                }
            }
        }
    }
    c
}
