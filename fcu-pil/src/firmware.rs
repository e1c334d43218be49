//! Finding (and if needed building) the release firmware ELF: the very file `cargo fw-run`
//! flashes.

use std::path::{Path, PathBuf};
use std::process::Command;

/// The repository root (fcu-pil sits one level below it).
pub fn repo_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).parent().map_or_else(|| PathBuf::from("."), Path::to_path_buf)
}

/// Where `cargo fw` puts the release ELF.
pub fn default_elf_path() -> PathBuf {
    repo_root().join("fcu-firmware/target/thumbv7em-none-eabihf/release/fcu-firmware")
}

/// Builds the release firmware exactly as `cargo fw` does and returns the ELF's path.
pub fn build_release_elf() -> Result<PathBuf, String> {
    build(&[], None)
}

/// Builds the release firmware with `--features esc` (TIM4 at 400 Hz, idle pulse 850) into its
/// own target directory, and returns the ELF's path.
pub fn build_esc_elf() -> Result<PathBuf, String> {
    build(&["--features", "esc"], Some(repo_root().join("fcu-firmware/target/esc")))
}

fn build(extra: &[&str], target_dir: Option<PathBuf>) -> Result<PathBuf, String> {
    let cargo = std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into());
    let manifest = repo_root().join("fcu-firmware/Cargo.toml");
    eprintln!("fcu-pil: building the release firmware ({} {})", manifest.display(), extra.join(" "));
    let mut cmd = Command::new(cargo);
    cmd.args(["build", "--release", "--target", "thumbv7em-none-eabihf", "--manifest-path"]).arg(&manifest).args(extra);
    if let Some(dir) = &target_dir {
        cmd.arg("--target-dir").arg(dir);
    }
    let status = cmd.status().map_err(|e| format!("could not run cargo to build the firmware: {e}"))?;
    if !status.success() {
        return Err(format!(
            "building the firmware failed ({status}); `rustup target add thumbv7em-none-eabihf` and `cargo install flip-link` are needed"
        ));
    }
    let elf = match target_dir {
        Some(dir) => dir.join("thumbv7em-none-eabihf/release/fcu-firmware"),
        None => default_elf_path(),
    };
    if elf.is_file() {
        Ok(elf)
    } else {
        Err(format!("the firmware build did not produce {}", elf.display()))
    }
}

/// The ELF to fly: `explicit` if given, else `FCU_PIL_ELF` from the environment, else the
/// release build (built now, so it is never stale).
pub fn resolve_elf(explicit: Option<&Path>) -> Result<PathBuf, String> {
    if let Some(p) = explicit {
        return if p.is_file() { Ok(p.to_path_buf()) } else { Err(format!("--elf {}: no such file", p.display())) };
    }
    if let Some(p) = std::env::var_os("FCU_PIL_ELF") {
        let p = PathBuf::from(p);
        return if p.is_file() { Ok(p) } else { Err(format!("FCU_PIL_ELF={}: no such file", p.display())) };
    }
    build_release_elf()
}
