//! Typed errors of the scene model (the import layer has its own, `ImportError`).

/// What can go wrong while choosing what to sample from a scene.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum SceneError {
    /// `--animation NAME|INDEX` named no clip of the file.
    #[error("no animation {requested:?}; available: {}", available_list(.available))]
    UnknownClip {
        requested: String,
        available: Vec<String>,
    },
}

fn available_list(available: &[String]) -> String {
    if available.is_empty() {
        "none (the scene has no animations)".to_string()
    } else {
        available.join(", ")
    }
}
