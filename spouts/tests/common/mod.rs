//! Helpers shared by the integration tests.

use std::path::{Path, PathBuf};

/// A file of the shared data set (`../shared/data` beside the repository);
/// fails the test, saying what is missing, if it is not there.
pub(crate) fn shared(rel: &str) -> PathBuf {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/data").join(rel);
    assert!(
        path.exists(),
        "missing {}: these tests read the shared data set (../shared/data beside the repository)",
        path.display()
    );
    path
}
