//! Chooses the part's memory map and sizes the working storage at build time, so a
//! configuration that does not fit the part fails to link (the linker names the
//! region and the overflow) instead of failing on the target.
//!
//! - `PHOTOTRAVERSE_PART`: a file `parts/<name>.x` (default `mps2-an500`);
//! - `PHOTOTRAVERSE_ARENA_BYTES`, `PHOTOTRAVERSE_FRAME_BYTES`: the arena (everything the
//!   configuration needs but the frames and the link buffers) and one frame buffer, as
//!   the host's memory budget predicts them (`phototraverse run --link qemu` and
//!   `phototraverse budget --part` set them).
use std::{env, fs, path::PathBuf};

fn main() {
    for var in [
        "PHOTOTRAVERSE_PART",
        "PHOTOTRAVERSE_ARENA_BYTES",
        "PHOTOTRAVERSE_FRAME_BYTES",
    ] {
        println!("cargo:rerun-if-env-changed={var}");
    }
    let part = env::var("PHOTOTRAVERSE_PART").unwrap_or_else(|_| "mps2-an500".into());
    let map = PathBuf::from("parts").join(format!("{part}.x"));
    println!("cargo:rerun-if-changed={}", map.display());
    println!("cargo:rerun-if-changed=parts/sections.x");
    let memory = fs::read_to_string(&map).unwrap_or_else(|e| {
        panic!(
            "PHOTOTRAVERSE_PART={part}: no memory map {} ({e})",
            map.display()
        )
    });
    let sections = fs::read_to_string("parts/sections.x").expect("parts/sections.x");
    let out = PathBuf::from(env::var("OUT_DIR").unwrap());
    fs::write(out.join("memory.x"), format!("{memory}\n{sections}")).unwrap();
    println!("cargo:rustc-link-search={}", out.display());

    let bytes = |var: &str| -> usize {
        let v = env::var(var).unwrap_or_else(|_| {
            panic!("{var} is not set: the image is built by `phototraverse run --link qemu` or `phototraverse budget --part`, which size it from a configuration")
        });
        v.trim()
            .parse()
            .unwrap_or_else(|e| panic!("{var}={v:?}: not a byte count ({e})"))
    };
    let arena = bytes("PHOTOTRAVERSE_ARENA_BYTES");
    let frame = bytes("PHOTOTRAVERSE_FRAME_BYTES");
    fs::write(
        out.join("sizes.rs"),
        format!(
            "/// The memory map this image was linked for.\npub const PART: &str = {part:?};\n\
             /// Bytes of the arena.\npub const ARENA_BYTES: usize = {arena};\n\
             /// Bytes of one frame buffer.\npub const FRAME_BYTES: usize = {frame};\n"
        ),
    )
    .unwrap();
}
