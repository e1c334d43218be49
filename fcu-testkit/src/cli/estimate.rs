//! `fcu-sim estimate`: run an attitude estimator over a BROAD-format IMU recording.

use std::io::BufWriter;
use std::path::PathBuf;
use std::process::ExitCode;

use super::CliError;
use crate::broad::{self, Profile, Recording};

#[derive(clap::Args, Debug)]
pub struct EstimateArgs {
    /// Estimator profile.
    #[arg(long, value_enum, default_value = "default")]
    pub profile: Profile,
    /// BROAD CSV (`t_s,gyr_x..z [rad/s],acc_x..z [m/s²],ref_qw..qz,movement`), plain or gzip.
    pub input: PathBuf,
    /// Where to write `t_s,qw,qx,qy,qz` (standard output when absent).
    #[arg(long)]
    pub out: Option<PathBuf>,
}

/// Run the estimator from rest (identity, no prior) at the file's own sample period, write one
/// estimate per sample, and print the inclination RMSE to stderr when the file has ground truth.
pub fn run(a: &EstimateArgs) -> Result<ExitCode, CliError> {
    let rec = Recording::read(&a.input).map_err(|e| CliError(e.to_string()))?;
    let dt_s =
        rec.sample_period_s().ok_or_else(|| CliError(format!("{}: need at least two samples with increasing t_s", a.input.display())))?;
    let profile = a.profile;
    let est = broad::run(&rec, profile.estimator_config(dt_s)).map_err(|e| CliError(e.to_string()))?;
    let mut bytes = Vec::new();
    broad::write_estimates(BufWriter::new(&mut bytes), &rec, &est)?;
    super::write_output(a.out.as_deref(), &bytes)?;
    if let Some(rmse) = broad::inclination_rmse_deg(&rec, &est) {
        eprintln!(
            "{}: {} profile, {} samples at {:.1} Hz, inclination RMSE {rmse:.3}°",
            a.input.display(),
            profile.name(),
            rec.samples.len(),
            1.0 / dt_s
        );
    }
    Ok(ExitCode::SUCCESS)
}
