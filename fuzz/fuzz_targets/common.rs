//! Shared by the targets: the contract every parser keeps on any input.

/// A refusal is one line naming the thing (`thing: reason`); a panic fails by itself.
pub fn check<T>(result: substep::Result<T>) {
    if let Err(e) = result {
        let msg = e.to_string();
        assert!(
            !msg.is_empty() && !msg.contains(['\n', '\r']) && msg.contains(": "),
            "refusal is not one line naming the thing: {msg:?}"
        );
    }
}

/// The examples directory (relative file names in configs resolve against it).
#[allow(dead_code)] // not every target reads files
pub fn examples() -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples")
}
