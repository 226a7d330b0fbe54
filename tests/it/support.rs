//! Shared fixtures: the independent reference files in `../shared/reference/`.

use std::path::PathBuf;

/// Path of a file in the shared reference folder (beside the repository, as CI lays it out).
pub fn reference_path(name: &str) -> PathBuf {
    let manifest = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let candidates = [
        manifest.join("../../shared/reference").join(name),
        manifest.join("../shared/reference").join(name),
    ];
    candidates
        .iter()
        .find(|p| p.exists())
        .cloned()
        .unwrap_or_else(|| {
            panic!("reference file {name} not found beside the repository (../shared/reference)")
        })
}

/// Parsed JSON of a reference file.
pub fn reference_json(name: &str) -> serde_json::Value {
    let text = std::fs::read_to_string(reference_path(name)).expect("readable reference file");
    serde_json::from_str(&text).expect("valid reference JSON")
}
