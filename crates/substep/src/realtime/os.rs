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

/// `mlockall(MCL_CURRENT | MCL_FUTURE)` for the whole process. Not attempted for a non-root
/// user under a finite `RLIMIT_MEMLOCK`: with `MCL_FUTURE`, allocations beyond the limit would
/// fail later (and abort the program) instead of failing here.
pub(crate) fn lock_memory() -> RtSetting {
    #[cfg(unix)]
    {
        let mut limit = libc::rlimit {
            rlim_cur: 0,
            rlim_max: 0,
        };
        // SAFETY: `limit` is a valid out-pointer; `geteuid` has no preconditions.
        let (rc, euid) = unsafe { (libc::getrlimit(libc::RLIMIT_MEMLOCK, &mut limit), libc::geteuid()) };
        if euid != 0 && (rc != 0 || limit.rlim_cur != libc::RLIM_INFINITY) {
            return RtSetting::Failed(format!(
                "mlockall: not attempted, RLIMIT_MEMLOCK is {} kB for this user (raise `memlock` in \
                 /etc/security/limits.d or run with CAP_IPC_LOCK)",
                limit.rlim_cur / 1024
            ));
        }
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
