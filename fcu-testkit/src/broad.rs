//! Scoring attitude estimators on BROAD recordings (real IMU data with optical ground truth).
//!
//! The format is the one of `fcu-testkit/data/broad/README.md`: a header
//! `t_s,gyr_x,gyr_y,gyr_z,acc_x,acc_y,acc_z,ref_qw,ref_qx,ref_qy,ref_qz,movement`, gyroscope in
//! rad/s, accelerometer in m/s², the ground truth a unit quaternion rotating IMU-frame vectors
//! into an east-north-up frame (`nan` where the cameras lost the markers), `movement` 1 for the
//! samples that are scored. Files may be gzip-compressed (detected by their magic bytes).
//!
//! The estimator is fed exactly what the flight pipeline feeds it: accelerometer in mg and gyro
//! in mdps, body axes, one update per sample. The pipeline's third argument, "throttle low"
//! (motors stopped), is set per profile as [`Profile::throttle_low`] explains.

use std::fmt;
use std::io::Write;
use std::path::Path;

use fcu_core::ahrs::{Estimator, EstimatorConfig, MahonyConfig, VqfConfig};
use fcu_core::math::Quat;
use fcu_core::ConfigError;

/// The header every BROAD CSV starts with.
pub const HEADER: &str = "t_s,gyr_x,gyr_y,gyr_z,acc_x,acc_y,acc_z,ref_qw,ref_qx,ref_qy,ref_qz,movement";

const COLUMNS: [&str; 12] =
    ["t_s", "gyr_x", "gyr_y", "gyr_z", "acc_x", "acc_y", "acc_z", "ref_qw", "ref_qx", "ref_qy", "ref_qz", "movement"];

/// Gravity used to turn m/s² into mg: 9.81, the value the recordings' README gives at rest
/// (`fcu-testkit/data/broad/README.md`), not the standard 9.80665.
pub const GRAVITY_M_S2: f64 = 9.81;

/// rad/s → mdps.
pub const RAD_S_TO_MDPS: f64 = 180.0 / std::f64::consts::PI * 1000.0;

/// One recorded sample.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sample {
    pub t_s: f64,
    pub gyr_rad_s: [f64; 3],
    pub acc_m_s2: [f64; 3],
    /// Ground truth `(w, x, y, z)`, IMU → ENU; `None` where any component is `nan`.
    pub ref_q: Option<[f64; 4]>,
    /// Whether the sample counts for the error.
    pub movement: bool,
}

impl Sample {
    /// The accelerometer in mg, as the flight pipeline hands it to the estimator.
    pub fn accel_mg(&self) -> [f32; 3] {
        self.acc_m_s2.map(|a| (a / GRAVITY_M_S2 * 1000.0) as f32)
    }

    /// The gyroscope in mdps, as the flight pipeline hands it to the estimator.
    pub fn gyro_mdps(&self) -> [f32; 3] {
        self.gyr_rad_s.map(|g| (g * RAD_S_TO_MDPS) as f32)
    }
}

/// A whole recording.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Recording {
    pub samples: Vec<Sample>,
}

/// A reading error: where (line number counted from 1, the header being line 1, and the column)
/// and what.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct BroadError {
    /// The file, when reading one.
    pub file: Option<String>,
    pub line: Option<usize>,
    pub column: Option<&'static str>,
    pub message: String,
}

impl fmt::Display for BroadError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if let Some(file) = &self.file {
            write!(f, "{file}: ")?;
        }
        match (self.line, self.column) {
            (Some(l), Some(c)) => write!(f, "line {l}, column {c}: {}", self.message),
            (Some(l), None) => write!(f, "line {l}: {}", self.message),
            _ => f.write_str(&self.message),
        }
    }
}

impl std::error::Error for BroadError {}

fn err_at(line: usize, column: Option<&'static str>, message: impl Into<String>) -> BroadError {
    BroadError { file: None, line: Some(line), column, message: message.into() }
}

impl Recording {
    /// Parse the text of a BROAD CSV.
    pub fn parse(text: &str) -> Result<Recording, BroadError> {
        let mut lines = text.lines().enumerate();
        let header = lines.next().map(|(_, l)| l.trim()).unwrap_or("");
        if header != HEADER {
            return Err(err_at(1, None, format!("expected the header `{HEADER}`, found `{}`", crate::csv::echo(header))));
        }
        let mut samples: Vec<Sample> = Vec::new();
        for (i, raw) in lines {
            let line_no = i + 1;
            let line = raw.trim();
            if line.is_empty() {
                continue;
            }
            let sample = parse_line(line, line_no)?;
            // The estimator runs at the mean step: a time that stands still or goes back is a
            // broken file, not a sample.
            if let Some(prev) = samples.last() {
                if sample.t_s <= prev.t_s {
                    return Err(err_at(
                        line_no,
                        Some("t_s"),
                        format!(
                            "{} does not come after the previous sample's {}",
                            crate::csv::short_number(sample.t_s),
                            crate::csv::short_number(prev.t_s)
                        ),
                    ));
                }
            }
            samples.push(sample);
        }
        Ok(Recording { samples })
    }

    /// Read a file, plain or gzip-compressed.
    pub fn read(path: &Path) -> Result<Recording, BroadError> {
        let file = Some(path.display().to_string());
        let text =
            crate::csv::read_text(path).map_err(|e| BroadError { file: file.clone(), line: None, column: None, message: e.to_string() })?;
        Recording::parse(&text).map_err(|e| BroadError { file, ..e })
    }

    /// The sample period, s: the mean step over the recording (BROAD: 0.0035 s). `None` for
    /// fewer than two samples or a time column that does not increase.
    pub fn sample_period_s(&self) -> Option<f64> {
        let (first, last) = (self.samples.first()?, self.samples.last()?);
        let n = self.samples.len();
        let dt = (last.t_s - first.t_s) / (n as f64 - 1.0);
        (n >= 2 && dt.is_finite() && dt > 0.0).then_some(dt)
    }

    /// Whether any sample can be scored.
    pub fn has_ground_truth(&self) -> bool {
        self.samples.iter().any(|s| s.movement && s.ref_q.is_some())
    }
}

fn parse_line(line: &str, line_no: usize) -> Result<Sample, BroadError> {
    let mut v = [0.0f64; 12];
    let mut fields = line.split(',');
    for (k, (slot, name)) in v.iter_mut().zip(COLUMNS).enumerate() {
        let field =
            fields.next().ok_or_else(|| err_at(line_no, Some(name), format!("missing (expected {} columns, found {k})", COLUMNS.len())))?;
        let field = field.trim();
        let x: f64 = field.parse().map_err(|_| err_at(line_no, Some(name), format!("`{field}` is not a number")))?;
        // Only the ground truth may be missing.
        let may_be_nan = (7..11).contains(&k);
        if !(x.is_finite() || (may_be_nan && x.is_nan())) {
            return Err(err_at(line_no, Some(name), format!("`{field}` is not a finite number")));
        }
        *slot = x;
    }
    if fields.next().is_some() {
        return Err(err_at(line_no, None, format!("more than {} columns", COLUMNS.len())));
    }
    let [t_s, gx, gy, gz, ax, ay, az, qw, qx, qy, qz, mv] = v;
    let movement = if mv == 1.0 {
        true
    } else if mv == 0.0 {
        false
    } else {
        return Err(err_at(line_no, Some("movement"), format!("`{mv}` is neither 0 nor 1")));
    };
    let ref_q = [qw, qx, qy, qz];
    let norm = ref_q.iter().map(|c| c * c).sum::<f64>().sqrt();
    if norm.is_finite() && !(0.5..=1.5).contains(&norm) {
        // A ground truth of norm 0 (or far from 1) cannot be a rotation: the error would be NaN.
        return Err(err_at(line_no, Some("ref_qw"), format!("the ground-truth quaternion has norm {norm:.3}, not a rotation")));
    }
    Ok(Sample {
        t_s,
        gyr_rad_s: [gx, gy, gz],
        acc_m_s2: [ax, ay, az],
        ref_q: ref_q.iter().all(|c| c.is_finite()).then_some(ref_q),
        movement,
    })
}

pub use crate::Profile;

/// What the BROAD scorer needs of a profile.
impl Profile {
    /// What the recording tells the estimator about the motors. A handheld IMU has none, so
    /// for the default estimator "throttle low" (motors off: a still IMU really is at rest, and
    /// its rest-based bias estimation may run) is the truth. The reference Mahony reads the same
    /// flag as "use the ground gain kP 10"; it is scored with its flight gain kP 0.4, the
    /// gains of the BROAD README's Mahony row.
    pub fn throttle_low(self) -> bool {
        matches!(self, Profile::Default)
    }

    /// The estimator configuration of this profile for a sample period of `dt_s`.
    pub fn estimator_config(self, dt_s: f64) -> EstimatorConfig {
        match self {
            Profile::Default => EstimatorConfig::Vqf(VqfConfig::at_rate(dt_s as f32)),
            Profile::Reference => EstimatorConfig::Mahony(MahonyConfig { dt_s, ..MahonyConfig::REFERENCE }),
        }
    }
}

/// Run an estimator from its initial state over every sample; one estimate per sample. An
/// estimator fcu-core was built without is refused.
pub fn run(rec: &Recording, cfg: EstimatorConfig) -> Result<Vec<Quat>, ConfigError> {
    let throttle_low = match cfg {
        EstimatorConfig::Mahony(_) => Profile::Reference.throttle_low(),
        EstimatorConfig::Vqf(_) => Profile::Default.throttle_low(),
    };
    let mut est = Estimator::new(cfg)?;
    Ok(rec
        .samples
        .iter()
        .map(|s| {
            est.update(s.accel_mg(), s.gyro_mdps(), throttle_low);
            est.quat()
        })
        .collect())
}

/// Inclination error of one estimate against the ground truth, rad (README: q_err = q_est ⊗
/// q_ref⁻¹, error = 2·acos(clamp(√(w² + z²), 0, 1))). The estimate is normalised first so a
/// filter keeping a norm slightly off 1 (the reference's 0.9983) is not charged for it.
pub fn inclination_error_rad(est: Quat, ref_q: [f64; 4]) -> f64 {
    let [ew, ex, ey, ez] = [est.w, est.x, est.y, est.z].map(f64::from);
    let n = (ew * ew + ex * ex + ey * ey + ez * ez).sqrt();
    let (ew, ex, ey, ez) = (ew / n, ex / n, ey / n, ez / n);
    let [rw, rx, ry, rz] = ref_q;
    let rn2 = rw * rw + rx * rx + ry * ry + rz * rz;
    // q_ref⁻¹ = conj / |q|².
    let (bw, bx, by, bz) = (rw / rn2, -rx / rn2, -ry / rn2, -rz / rn2);
    let w = ew * bw - ex * bx - ey * by - ez * bz;
    let z = ew * bz + ex * by - ey * bx + ez * bw;
    2.0 * (w * w + z * z).sqrt().clamp(0.0, 1.0).acos()
}

/// Inclination RMSE, degrees, over the samples with `movement = 1` and a ground truth; `None`
/// when there are none (or the estimate count does not match).
pub fn inclination_rmse_deg(rec: &Recording, est: &[Quat]) -> Option<f64> {
    if est.len() != rec.samples.len() {
        return None;
    }
    let (sum_sq, n) = rec
        .samples
        .iter()
        .zip(est)
        .filter(|(s, _)| s.movement)
        .filter_map(|(s, q)| s.ref_q.map(|r| inclination_error_rad(*q, r)))
        .fold((0.0, 0usize), |(acc, n), e| (acc + e * e, n + 1));
    (n > 0).then(|| (sum_sq / n as f64).sqrt().to_degrees())
}

/// Write the estimates as `t_s,qw,qx,qy,qz`, one row per sample.
pub fn write_estimates<W: Write>(mut w: W, rec: &Recording, est: &[Quat]) -> std::io::Result<()> {
    writeln!(w, "t_s,qw,qx,qy,qz")?;
    for (s, q) in rec.samples.iter().zip(est) {
        writeln!(w, "{:.6},{:.7},{:.7},{:.7},{:.7}", s.t_s, q.w, q.x, q.y, q.z)?;
    }
    w.flush()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_nan_ground_truth_and_names_bad_cells() {
        let ok = format!("{HEADER}\n0.0,0,0,0,0,0,9.81,nan,nan,nan,nan,0\n0.0035,0,0,0,0,0,9.81,1,0,0,0,1\n");
        let rec = Recording::parse(&ok).unwrap();
        assert_eq!(rec.samples.len(), 2);
        assert_eq!(rec.samples[0].ref_q, None);
        assert_eq!(rec.samples[1].ref_q, Some([1.0, 0.0, 0.0, 0.0]));
        assert!((rec.sample_period_s().unwrap() - 0.0035).abs() < 1e-12);

        let bad = format!("{HEADER}\n0.0,0,0,0,0,0,9.81,1,0,0,0,1\n0.0035,0,0,x,0,0,9.81,1,0,0,0,1\n");
        let e = Recording::parse(&bad).unwrap_err();
        assert_eq!((e.line, e.column), (Some(3), Some("gyr_z")));
        assert!(e.to_string().starts_with("line 3, column gyr_z"), "{e}");

        let short = format!("{HEADER}\n0.0,0,0\n");
        let e = Recording::parse(&short).unwrap_err();
        assert_eq!((e.line, e.column), (Some(2), Some("gyr_z")));

        let nan_gyro = format!("{HEADER}\n0.0,nan,0,0,0,0,9.81,1,0,0,0,1\n");
        assert_eq!(Recording::parse(&nan_gyro).unwrap_err().column, Some("gyr_x"));
        assert_eq!(Recording::parse("t,a\n").unwrap_err().line, Some(1));
    }

    #[test]
    fn inclination_error_ignores_heading() {
        let yaw = Quat::from_axis_angle(fcu_core::math::Vec3::new(0.0, 0.0, 1.0), 1.0);
        assert!(inclination_error_rad(yaw, [1.0, 0.0, 0.0, 0.0]) < 1e-6);
        let tilt = Quat::from_axis_angle(fcu_core::math::Vec3::new(1.0, 0.0, 0.0), 0.1);
        assert!((inclination_error_rad(tilt, [1.0, 0.0, 0.0, 0.0]) - 0.1).abs() < 1e-6);
        // Heading and tilt together: only the tilt counts.
        let both = yaw.mul(tilt);
        assert!((inclination_error_rad(both, [1.0, 0.0, 0.0, 0.0]) - 0.1).abs() < 1e-6);
    }
}
