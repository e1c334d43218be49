//! fcu-log: the flight log, the same for a simulated flight (`fcu-sim fly`, `fcu-pil fly`) and
//! one recorded from a board (`fcu-ground record`), so both are read and plotted alike.
//!
//! - one logged instant, [`LogRow`]; `flight.csv` from [`CSV_HEADER`] and [`LogRow::write_csv`];
//! - `flight.svg` from [`plot::write_svg`];
//! - the reader for the project's numeric CSV files, [`csv`];
//! - the `--out` directory a flight's files go to, [`OutputDir`].

pub mod csv;
pub mod plot;

use std::path::{Path, PathBuf};

use fcu_core::altitude::{AltMode, AltitudeStatus};
use fcu_core::baro::BaroFault;
use fcu_core::supervisor::FlightState;

/// One logged control tick (or, recorded from a board, one ATTITUDE with the latest of the
/// rest: NaN where there is no value, which the plot does not draw).
#[derive(Clone, Debug, PartialEq)]
pub struct LogRow {
    pub t_s: f64,
    pub state: FlightState,
    pub armed: bool,
    /// The transmitter's link flag from the timeline (what the receiver is sending).
    pub link_tx: bool,
    /// The core's own link verdict.
    pub link_core: bool,
    /// True attitude (reference convention: roll about body Y, pitch about body X).
    pub roll_deg: f64,
    pub pitch_deg: f64,
    pub yaw_deg: f64,
    pub yaw_rate_dps: f64,
    pub est_roll_deg: f64,
    pub est_pitch_deg: f64,
    pub roll_target_deg: f64,
    pub pitch_target_deg: f64,
    pub yaw_target_deg: f64,
    /// The yaw rate the pilot's stick asks for on this tick, °/s (not written to the CSV):
    /// what the simulator's yaw metric compares the airframe's rate with.
    pub yaw_rate_cmd_dps: f64,
    pub motors: [u16; 4],
    pub alt_m: f64,
    pub battery_v: f64,
    pub thr_us: f64,
    pub calibrated: bool,
    pub calibrating: bool,
    pub calibration_restarts: u16,
    /// The vertical half: the height estimate, the hold and the barometer.
    pub vertical: Vertical,
}

/// Who sets the collective thrust at a logged instant (the CSV's `vmode`), and a barometer
/// fault's name (the CSV's `baro_fault`): the core's words, the same as its STATUS line's, so
/// a log recorded from the board's text lines and one of a simulated flight name them alike.
pub use fcu_core::telemetry::{baro_fault_name, VerticalMode};

/// The vertical columns of a row. NaN (or `None`) where the row has no value: a flight
/// computer that reports no altitude, a recording without the simulator's truth. Those are
/// written as empty fields and not drawn.
#[derive(Clone, Copy, Debug)]
pub struct Vertical {
    /// The flight computer's height estimate above the take-off point, m.
    pub est_alt_m: f64,
    /// The height the hold holds or moves to, m (NaN when not holding).
    pub alt_target_m: f64,
    /// The true climb rate (upward), m/s.
    pub climb_m_s: f64,
    /// The flight computer's estimate of it, m/s.
    pub est_climb_m_s: f64,
    /// Who sets the thrust.
    pub mode: Option<VerticalMode>,
    /// The mode the pilot chose (`ALT_MODE`), whether or not it is in force.
    pub mode_chosen: Option<AltMode>,
    /// The barometer's fault now.
    pub baro_fault: Option<BaroFault>,
}

/// Equal when every column would be written the same: an absent value (NaN) equals an absent
/// one, so that two logs of one flight compare equal row by row.
impl PartialEq for Vertical {
    fn eq(&self, other: &Self) -> bool {
        let same = |a: f64, b: f64| a.to_bits() == b.to_bits() || a == b;
        same(self.est_alt_m, other.est_alt_m)
            && same(self.alt_target_m, other.alt_target_m)
            && same(self.climb_m_s, other.climb_m_s)
            && same(self.est_climb_m_s, other.est_climb_m_s)
            && self.mode == other.mode
            && self.mode_chosen == other.mode_chosen
            && self.baro_fault == other.baro_fault
    }
}

impl Vertical {
    /// A row with no vertical values at all.
    pub const ABSENT: Vertical = Vertical {
        est_alt_m: f64::NAN,
        alt_target_m: f64::NAN,
        climb_m_s: f64::NAN,
        est_climb_m_s: f64::NAN,
        mode: None,
        mode_chosen: None,
        baro_fault: None,
    };

    /// What a flight computer's `status` says, with the true climb rate `climb_m_s` (NaN
    /// if unknown).
    pub fn from_status(status: &AltitudeStatus, climb_m_s: f64) -> Vertical {
        Vertical {
            est_alt_m: f64::from(status.height_m),
            alt_target_m: status.target_m.map_or(f64::NAN, f64::from),
            climb_m_s,
            est_climb_m_s: f64::from(status.climb_m_s),
            mode: Some(VerticalMode::of(status)),
            mode_chosen: Some(status.mode),
            baro_fault: status.baro_fault,
        }
    }
}

/// The header of a flight's CSV, one row per control tick ([`LogRow::write_csv`]).
pub const CSV_HEADER: &str = "t_s,state,armed,link,roll_deg,pitch_deg,yaw_deg,est_roll_deg,est_pitch_deg,roll_target_deg,\
                              pitch_target_deg,yaw_target_deg,yaw_rate_dps,m1,m2,m3,m4,alt_m,battery_v,thr_us,\
                              est_alt_m,alt_target_m,climb_m_s,est_climb_m_s,vmode,alt_mode,baro_fault\n";

/// A value of the vertical columns: empty when absent.
fn or_empty(v: f64, decimals: usize) -> String {
    if v.is_finite() {
        format!("{v:.decimals$}")
    } else {
        String::new()
    }
}

impl LogRow {
    /// An armed, level row at `t_s` with nothing happening: motors at 900 counts, 1 m up, the
    /// battery at 4 V, the throttle at 1500 µs, the vertical columns absent. What tests of the
    /// metrics and the plot build their logs from, changing the columns they look at.
    pub fn steady(t_s: f64) -> LogRow {
        LogRow {
            t_s,
            state: FlightState::Armed,
            armed: true,
            link_tx: true,
            link_core: true,
            roll_deg: 0.0,
            pitch_deg: 0.0,
            yaw_deg: 0.0,
            yaw_rate_dps: 0.0,
            est_roll_deg: 0.0,
            est_pitch_deg: 0.0,
            roll_target_deg: 0.0,
            pitch_target_deg: 0.0,
            yaw_target_deg: 0.0,
            yaw_rate_cmd_dps: 0.0,
            motors: [900; 4],
            alt_m: 1.0,
            battery_v: 4.0,
            thr_us: 1500.0,
            calibrated: true,
            calibrating: false,
            calibration_restarts: 0,
            vertical: Vertical::ABSENT,
        }
    }

    /// This row as one line of the flight's CSV (under [`CSV_HEADER`]).
    pub fn write_csv(&self, w: &mut impl std::io::Write) -> std::io::Result<()> {
        let r = self;
        let v = &r.vertical;
        writeln!(
            w,
            "{:.5},{},{},{},{:.3},{:.3},{:.3},{:.3},{:.3},{:.3},{:.3},{:.3},{:.2},{},{},{},{},{:.4},{:.3},{:.1},{},{},{},{},{},{},{}",
            r.t_s,
            r.state.name(),
            u8::from(r.armed),
            u8::from(r.link_tx),
            r.roll_deg,
            r.pitch_deg,
            r.yaw_deg,
            r.est_roll_deg,
            r.est_pitch_deg,
            r.roll_target_deg,
            r.pitch_target_deg,
            r.yaw_target_deg,
            r.yaw_rate_dps,
            r.motors[0],
            r.motors[1],
            r.motors[2],
            r.motors[3],
            r.alt_m,
            r.battery_v,
            r.thr_us,
            or_empty(v.est_alt_m, 4),
            or_empty(v.alt_target_m, 4),
            or_empty(v.climb_m_s, 4),
            or_empty(v.est_climb_m_s, 4),
            v.mode.map_or("", VerticalMode::name),
            v.mode_chosen.map_or("", |m| match m {
                AltMode::Manual => "manual",
                AltMode::Hold => "hold",
            }),
            v.baro_fault.map_or("", baro_fault_name),
        )
    }
}

/// `rows` as the CSV text of a whole flight (header included).
pub fn to_csv(rows: &[LogRow]) -> String {
    let mut bytes = CSV_HEADER.as_bytes().to_vec();
    for r in rows {
        // Writing to a Vec cannot fail.
        let _ = r.write_csv(&mut bytes);
    }
    String::from_utf8_lossy(&bytes).into_owned()
}

/// The `--out` directory of a flight: checked writable before the flight starts (not after
/// it), and removed again if this run created it and then failed.
pub struct OutputDir {
    path: PathBuf,
    created: bool,
}

impl OutputDir {
    /// Creates `path` if need be and checks a file can be written there; the error names the
    /// `--out` option and the path.
    pub fn prepare(path: &Path) -> Result<OutputDir, String> {
        let created = !path.exists();
        std::fs::create_dir_all(path).map_err(|e| format!("--out {}: {e}", path.display()))?;
        let probe = path.join(".fcu-write-check");
        let writable = std::fs::write(&probe, b"").and_then(|()| std::fs::remove_file(&probe));
        let dir = OutputDir { path: path.to_path_buf(), created };
        match writable {
            Ok(()) => Ok(dir),
            Err(e) => Err(dir.abandon(format!("--out {}: cannot write there: {e}", path.display()))),
        }
    }

    /// The run failed: remove the directory if this run made it, and hand the error on.
    pub fn abandon<E>(&self, e: E) -> E {
        if self.created {
            let _ = std::fs::remove_dir_all(&self.path);
        }
        e
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_directory_this_run_made_goes_when_it_fails_one_that_was_there_stays() {
        let base = std::env::temp_dir().join(format!("fcu-log-out-{}", std::process::id()));
        let made = base.join("made");
        let dir = OutputDir::prepare(&made).unwrap();
        assert!(made.is_dir());
        assert_eq!(dir.abandon("failed"), "failed");
        assert!(!made.exists());
        let dir = OutputDir::prepare(&base).unwrap();
        dir.abandon(());
        assert!(base.is_dir(), "it was there before this run");
        std::fs::remove_dir_all(&base).unwrap();
    }

    #[test]
    fn a_csv_line_per_row_under_the_header() {
        let row = LogRow {
            t_s: 0.00125,
            state: FlightState::Armed,
            armed: true,
            link_tx: true,
            link_core: true,
            roll_deg: 1.0,
            pitch_deg: -2.0,
            yaw_deg: 3.0,
            yaw_rate_dps: 4.0,
            est_roll_deg: 1.5,
            est_pitch_deg: -2.5,
            roll_target_deg: 0.0,
            pitch_target_deg: 0.0,
            yaw_target_deg: f64::NAN,
            yaw_rate_cmd_dps: 9.0,
            motors: [1, 2, 3, 4],
            alt_m: 0.5,
            battery_v: 3.9,
            thr_us: 1500.0,
            calibrated: true,
            calibrating: false,
            calibration_restarts: 0,
            vertical: Vertical::ABSENT,
        };
        let holding = LogRow {
            vertical: Vertical {
                est_alt_m: 0.98,
                alt_target_m: 1.0,
                climb_m_s: -0.01,
                est_climb_m_s: 0.02,
                mode: Some(VerticalMode::Hold),
                mode_chosen: Some(AltMode::Hold),
                baro_fault: Some(BaroFault::Stuck),
            },
            ..row.clone()
        };
        let text = to_csv(&[row, holding]);
        let mut lines = text.lines();
        assert_eq!(Some(CSV_HEADER.trim_end()), lines.next());
        assert_eq!(
            lines.next(),
            Some("0.00125,armed,1,1,1.000,-2.000,3.000,1.500,-2.500,0.000,0.000,NaN,4.00,1,2,3,4,0.5000,3.900,1500.0,,,,,,,")
        );
        assert_eq!(
            lines.next(),
            Some(
                "0.00125,armed,1,1,1.000,-2.000,3.000,1.500,-2.500,0.000,0.000,NaN,4.00,1,2,3,4,0.5000,3.900,1500.0,\
                 0.9800,1.0000,-0.0100,0.0200,hold,hold,stuck"
            )
        );
        assert_eq!(lines.next(), None);
    }

    #[test]
    fn the_vertical_mode_in_force_is_the_descent_then_the_hold_then_the_stick() {
        let mut st = AltitudeStatus { mode: AltMode::Hold, ..AltitudeStatus::default() };
        assert_eq!(VerticalMode::of(&st), VerticalMode::Manual, "chosen but not in force");
        st.holding = true;
        assert_eq!(VerticalMode::of(&st), VerticalMode::Hold);
        st.failsafe_descent = true;
        assert_eq!(VerticalMode::of(&st), VerticalMode::Descent);
        for m in [VerticalMode::Manual, VerticalMode::Hold, VerticalMode::Descent] {
            assert_eq!(VerticalMode::from_name(m.name()), Some(m));
        }
        let v = Vertical::from_status(&AltitudeStatus { target_m: None, ..st }, 0.5);
        assert!(v.alt_target_m.is_nan() && v.climb_m_s == 0.5);
        assert_eq!(v, v, "absent values compare equal: one flight's log equals itself");
        assert_ne!(v, Vertical { alt_target_m: 1.0, ..v });
    }
}
