//! examples/frame3d_reduced.toml (101 388 DOFs, 13 s to reduce) scaled down to a 120-DOF frame
//! for the tests that run it (`crates/substep/tests/examples.rs`, `crates/substep-cli/tests/lab.rs`
//! through `#[path]`; python/tests/conftest.py keeps the same list); benches/frame3d_reduced.sh
//! runs the real one.

/// The replacements, each of which must be in the file.
pub const SCALING: [(&str, &str); 7] = [
    ("bays = 30\n", "bays = 2\n"),
    ("bays_y = 15\n", "bays_y = 2\n"),
    ("stories = 68\n", "stories = 4\n"),
    ("modes = 40\n", "modes = 12\n"),
    // Floor 4's U_x with rigid floors: 3 · (3 + 3 · 9) + 1.
    ("keep = [99898]", "keep = [91]"),
    // The damper scaled with the first floor's mass (80 t instead of 9 000 t).
    ("stiffness = 5.0e7 ", "stiffness = 5.0e5 "),
    ("damping = 5.0e6 ", "damping = 5.0e4 "),
];

/// The example's text (`text`) with [`SCALING`] applied; panics naming the line that is gone.
pub fn scaled_frame3d(text: &str) -> String {
    let mut text = text.to_string();
    for (from, to) in SCALING {
        assert!(
            text.contains(from),
            "frame3d_reduced.toml changed ({from:?}): adapt SCALING"
        );
        text = text.replace(from, to);
    }
    text
}
