//! `fcu-pil` on the command line: bad arguments get a message naming them and exit status 2.

use std::process::Command;

fn fcu_pil(args: &[&str]) -> (i32, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_fcu-pil")).args(args).output().expect("run fcu-pil");
    (out.status.code().unwrap_or(-1), String::from_utf8_lossy(&out.stderr).into_owned())
}

#[test]
fn a_missing_elf_is_named() {
    let out = std::env::temp_dir().join("fcu-pil-cli-missing-elf");
    let (code, err) = fcu_pil(&["fly", "--scenario", "hover", "--elf", "/nonexistent/fcu-firmware", "--out", out.to_str().unwrap()]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("--elf /nonexistent/fcu-firmware"), "{err}");
}

#[test]
fn a_file_that_is_not_a_firmware_image_is_refused() {
    let dir = std::env::temp_dir().join("fcu-pil-cli-not-elf");
    std::fs::create_dir_all(&dir).unwrap();
    let bogus = dir.join("not-an-elf");
    std::fs::write(&bogus, b"hello").unwrap();
    let (code, err) =
        fcu_pil(&["fly", "--scenario", "hover", "--elf", bogus.to_str().unwrap(), "--out", dir.join("out").to_str().unwrap()]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("not a 32-bit ELF"), "{err}");
}

#[test]
fn an_unknown_scenario_is_named() {
    let (code, err) = fcu_pil(&["fly", "--scenario", "loop-the-loop", "--elf", "/nonexistent", "--out", "/tmp/x"]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("loop-the-loop"), "{err}");
}

#[test]
fn an_lsi_frequency_outside_its_range_is_refused_before_serving() {
    for bad in ["16999", "47001"] {
        let (code, err) = fcu_pil(&["serve", "--link", "tcp:127.0.0.1:0", "--lsi-hz", bad, "--elf", "/nonexistent"]);
        assert_eq!(code, 2, "{err}");
        assert!(err.contains(&format!("--lsi-hz {bad}")) && err.contains("17000") && err.contains("47000"), "{err}");
    }
}
