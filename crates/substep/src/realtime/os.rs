//! Operating-system settings for the real-time thread: memory locking and SCHED_FIFO.

use std::fmt;

/// What became of an optional real-time setting. Failing to apply one is reported, not an
/// error: the run goes on without it.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub enum RtSetting {
    #[default]
    NotRequested,
    Applied,
    /// Not permitted or not supported; the reason as the OS gave it.
    Failed(String),
}

impl fmt::Display for RtSetting {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            RtSetting::NotRequested => f.write_str("not requested"),
            RtSetting::Applied => f.write_str("applied"),
            RtSetting::Failed(reason) => write!(f, "failed ({reason})"),
        }
    }
}

/// `mlockall(MCL_CURRENT | MCL_FUTURE)` for the whole process.
pub(crate) fn lock_memory() -> RtSetting {
    #[cfg(unix)]
    {
        // SAFETY: plain system call without pointers.
        let rc = unsafe { libc::mlockall(libc::MCL_CURRENT | libc::MCL_FUTURE) };
        if rc == 0 {
            RtSetting::Applied
        } else {
            RtSetting::Failed(format!("mlockall: {}", std::io::Error::last_os_error()))
        }
    }
    #[cfg(not(unix))]
    RtSetting::Failed("mlockall is not available on this platform".into())
}

/// Undo [`lock_memory`].
pub(crate) fn unlock_memory() {
    #[cfg(unix)]
    // SAFETY: plain system call without pointers.
    unsafe {
        libc::munlockall();
    }
}

/// SCHED_FIFO with `priority` for the calling thread.
pub(crate) fn set_fifo(priority: i32) -> RtSetting {
    #[cfg(target_os = "linux")]
    {
        let param = libc::sched_param {
            sched_priority: priority,
        };
        // SAFETY: `param` outlives the call; `pthread_self` is always valid.
        let rc = unsafe { libc::pthread_setschedparam(libc::pthread_self(), libc::SCHED_FIFO, &param) };
        if rc == 0 {
            RtSetting::Applied
        } else {
            RtSetting::Failed(format!(
                "SCHED_FIFO priority {priority}: {}",
                std::io::Error::from_raw_os_error(rc)
            ))
        }
    }
    #[cfg(not(target_os = "linux"))]
    RtSetting::Failed(format!("SCHED_FIFO priority {priority}: only supported on Linux"))
}
