//! Shared helpers of the end-to-end tests (fixture paths) and the protocol fuzz harness.
pub mod fuzz;

use std::path::PathBuf;

/// `tests/fixtures/NAME` inside the repository.
pub fn fixture(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("fixtures")
        .join(name)
}
