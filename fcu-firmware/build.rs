//! Puts the repository's `memory.x` (the one place the STM32F401CC memory map is written)
//! on the linker search path, so `-Tlink.x` finds it wherever cargo is run from, and passes the
//! firmware's link scripts (cortex-m-rt's link.x, defmt's defmt.x) to its binary only.
use std::{env, fs, path::PathBuf};

fn main() {
    let out = PathBuf::from(env::var_os("OUT_DIR").expect("cargo sets OUT_DIR"));
    let manifest_dir = PathBuf::from(env::var_os("CARGO_MANIFEST_DIR").expect("cargo sets CARGO_MANIFEST_DIR"));
    let memory_x = manifest_dir.join("..").join("memory.x");
    fs::copy(&memory_x, out.join("memory.x")).expect("copy ../memory.x to OUT_DIR");
    println!("cargo:rustc-link-search={}", out.display());
    // --icf=all: the linker folds identical functions into one (compiler-builtins' word-aligned
    // memcpy/memclr variants, the panic stubs); nothing here compares function addresses.
    // docs/performance.md, "Profiles".
    for arg in ["--nmagic", "-Tlink.x", "-Tdefmt.x", "--icf=all"] {
        println!("cargo:rustc-link-arg-bins={arg}");
    }
    println!("cargo:rerun-if-changed={}", memory_x.display());
    println!("cargo:rerun-if-changed=build.rs");
}
