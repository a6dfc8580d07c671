//! The library's error type. Every variant names the offending thing and the reason, so that
//! the CLI can print it as one line without further context.

use thiserror::Error;

/// Result alias used across the library.
pub type Result<T, E = Error> = std::result::Result<T, E>;

#[derive(Debug, Error)]
pub enum Error {
    /// A parameter or input value that cannot be used (`what` names it, e.g. `integrator.dt`).
    #[error("{what}: {reason}")]
    InvalidInput { what: String, reason: String },

    /// A numerical operation failed (e.g. a matrix that should be SPD is not).
    #[error("{what}: {reason}")]
    Numerical { what: String, reason: String },

    /// A simulation that produced non-finite values or exceeded a limit.
    #[error("diverged at step {step} (t = {time:.6} s): {reason}")]
    Diverged { step: usize, time: f64, reason: String },

    /// A test stopped in a controlled way: a safety limit was violated or the experimental
    /// side failed (site disconnected, timed out, returned garbage). Records up to `step` are
    /// intact.
    #[error("stopped at step {step} (t = {time:.6} s): {reason}")]
    Stopped { step: usize, time: f64, reason: String },

    /// A file could not be read or parsed.
    #[error("{path}: {reason}")]
    File { path: String, reason: String },

    /// An output file could not be written while or after a run (a full disk, a folder that
    /// turned read-only): a runtime failure, not bad input — the CLI exits 1, as for a run that
    /// stopped. (An output folder that cannot be created before the run is [`Error::File`].)
    #[error("{path}: cannot write: {reason}")]
    Output { path: String, reason: String },
}

impl Error {
    pub fn invalid(what: impl Into<String>, reason: impl Into<String>) -> Self {
        Error::InvalidInput {
            what: one_line(what.into()),
            reason: one_line(reason.into()),
        }
    }
    pub fn numerical(what: impl Into<String>, reason: impl Into<String>) -> Self {
        Error::Numerical {
            what: one_line(what.into()),
            reason: one_line(reason.into()),
        }
    }
    /// [`Error::Output`]: `path` could not be written (`reason`: the I/O error).
    pub fn write(path: &std::path::Path, reason: impl std::fmt::Display) -> Self {
        Error::Output {
            path: one_line(path.display().to_string()),
            reason: one_line(reason.to_string()),
        }
    }
    pub fn file(path: impl Into<String>, reason: impl Into<String>) -> Self {
        Error::File {
            path: one_line(path.into()),
            reason: one_line(reason.into()),
        }
    }
}

/// Messages quote input (a header line, a field, a peer's text): control characters in it are
/// escaped (`\r`, `\u{1b}`), so a message stays one line and cannot drive the terminal.
fn one_line(s: String) -> String {
    if !s.chars().any(char::is_control) {
        return s;
    }
    s.chars()
        .map(|c| {
            if c.is_control() {
                c.escape_default().to_string()
            } else {
                c.to_string()
            }
        })
        .collect()
}

/// Check that a scalar parameter is finite and strictly positive.
pub fn require_positive(what: &str, value: f64) -> Result<f64> {
    if value.is_finite() && value > 0.0 {
        Ok(value)
    } else {
        Err(Error::invalid(
            what,
            format!("must be a finite number > 0, got {value}"),
        ))
    }
}

/// Longest duration accepted from any input, in seconds (about 11.6 days). Far beyond any
/// timeout a test needs, and far below what `Duration` and `Instant` arithmetic can hold, so
/// `Instant::now() + d` can never overflow.
pub const MAX_DURATION_SECS: f64 = 1e6;

/// Convert a duration in seconds from input (a config key, a message) to a `Duration`:
/// finite, > 0 and at most [`MAX_DURATION_SECS`], else an error naming `what`.
pub fn require_duration(what: &str, secs: f64) -> Result<std::time::Duration> {
    if !(secs.is_finite() && secs > 0.0) {
        return Err(Error::invalid(
            what,
            format!("must be a finite number of seconds > 0, got {secs}"),
        ));
    }
    if secs > MAX_DURATION_SECS {
        return Err(Error::invalid(
            what,
            format!("is {secs} s, at most {MAX_DURATION_SECS:e} s is accepted"),
        ));
    }
    Ok(std::time::Duration::from_secs_f64(secs))
}

/// Check that a scalar parameter is finite and not negative.
pub fn require_non_negative(what: &str, value: f64) -> Result<f64> {
    if value.is_finite() && value >= 0.0 {
        Ok(value)
    } else {
        Err(Error::invalid(
            what,
            format!("must be a finite number >= 0, got {value}"),
        ))
    }
}
