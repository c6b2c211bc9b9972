//! Helpers shared by the integration tests.

use std::path::PathBuf;

/// A shared dataset's folder (`../shared/datasets/NAME` beside the project),
/// with a clear failure when it is missing.
pub fn dataset(name: &str) -> PathBuf {
    let d = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/datasets")
        .join(name);
    assert!(
        d.join("map.txt").is_file(),
        "{} is missing: the shared datasets sit beside the project",
        d.display()
    );
    d
}
