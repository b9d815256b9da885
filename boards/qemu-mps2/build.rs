//! Puts this board's MEMORY block on the linker search path (the top-level
//! memory.x includes it) and adds cortex-m-rt's link.x, for this crate's
//! binaries only.
use std::path::PathBuf;

fn main() {
    let out = PathBuf::from(std::env::var_os("OUT_DIR").expect("cargo sets OUT_DIR"));
    let manifest = PathBuf::from(
        std::env::var_os("CARGO_MANIFEST_DIR").expect("cargo sets CARGO_MANIFEST_DIR"),
    );
    std::fs::copy(manifest.join("board-memory.x"), out.join("board-memory.x"))
        .expect("copy board-memory.x");
    println!("cargo:rustc-link-search={}", out.display());
    // The workspace root holds memory.x (the shared entry that INCLUDEs ours).
    println!(
        "cargo:rustc-link-search={}",
        manifest.join("../..").display()
    );
    println!("cargo:rerun-if-changed=board-memory.x");
    println!("cargo:rerun-if-changed=../../memory.x");
    println!("cargo:rustc-link-arg-bins=--nmagic");
    println!("cargo:rustc-link-arg-bins=-Tlink.x");
}
