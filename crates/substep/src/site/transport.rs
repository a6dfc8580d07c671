//! Blocking socket I/O with deadlines and a stop flag (shared by clients and servers).

use super::protocol::{HEADER_LEN, Header};
use crate::error::Error;
use std::io::{self, Read, Write};
use std::net::TcpStream;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

/// How often a blocked server read looks at its stop flag.
pub(crate) const POLL: Duration = Duration::from_millis(25);

/// Why a read or write did not complete.
#[derive(Debug)]
pub(crate) enum LinkError {
    /// The peer closed the connection (`got` bytes of the current item had arrived).
    Closed {
        got: usize,
    },
    /// The deadline passed (`got` bytes had arrived).
    TimedOut {
        got: usize,
    },
    /// The stop flag was raised.
    Stopped,
    Io(io::Error),
    /// A frame that does not decode.
    Protocol(Error),
}

impl std::fmt::Display for LinkError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            LinkError::Closed { got: 0 } => write!(f, "the peer closed the connection"),
            LinkError::Closed { got } => write!(
                f,
                "the peer closed the connection in the middle of a message ({got} bytes received)"
            ),
            LinkError::TimedOut { got: 0 } => write!(f, "timed out"),
            LinkError::TimedOut { got } => write!(f, "timed out in the middle of a message ({got} bytes received)"),
            LinkError::Stopped => write!(f, "stopped"),
            LinkError::Io(e) => write!(f, "{e}"),
            LinkError::Protocol(e) => write!(f, "{e}"),
        }
    }
}

fn is_timeout(e: &io::Error) -> bool {
    matches!(e.kind(), io::ErrorKind::WouldBlock | io::ErrorKind::TimedOut)
}

/// Fill `buf` from `stream` before `deadline` (`None`: no limit), looking at `stop` every
/// [`POLL`].
pub(crate) fn read_full(
    stream: &mut TcpStream,
    buf: &mut [u8],
    deadline: Option<Instant>,
    stop: Option<&AtomicBool>,
) -> Result<(), LinkError> {
    let mut got = 0;
    while got < buf.len() {
        if stop.is_some_and(|s| s.load(Ordering::Relaxed)) {
            return Err(LinkError::Stopped);
        }
        let mut wait = match deadline {
            Some(d) => {
                let now = Instant::now();
                if now >= d {
                    return Err(LinkError::TimedOut { got });
                }
                Some(d - now)
            }
            None => None,
        };
        if stop.is_some() {
            wait = Some(wait.map_or(POLL, |w| w.min(POLL)));
        }
        // A zero timeout is an error for set_read_timeout; the deadline check above catches it.
        let wait = wait.map(|w| w.max(Duration::from_micros(100)));
        stream.set_read_timeout(wait).map_err(LinkError::Io)?;
        match stream.read(&mut buf[got..]) {
            Ok(0) => return Err(LinkError::Closed { got }),
            Ok(n) => got += n,
            Err(e) if is_timeout(&e) || e.kind() == io::ErrorKind::Interrupted => {}
            Err(e)
                if matches!(
                    e.kind(),
                    io::ErrorKind::ConnectionReset | io::ErrorKind::ConnectionAborted
                ) =>
            {
                return Err(LinkError::Closed { got });
            }
            Err(e) => return Err(LinkError::Io(e)),
        }
    }
    Ok(())
}

/// Write all of `data` with a write timeout.
pub(crate) fn write_all(stream: &mut TcpStream, data: &[u8], timeout: Duration) -> Result<(), LinkError> {
    stream
        .set_write_timeout(Some(timeout.max(Duration::from_micros(100))))
        .map_err(LinkError::Io)?;
    match stream.write_all(data) {
        Ok(()) => Ok(()),
        Err(e) if is_timeout(&e) => Err(LinkError::TimedOut { got: 0 }),
        Err(e)
            if matches!(
                e.kind(),
                io::ErrorKind::BrokenPipe | io::ErrorKind::ConnectionReset | io::ErrorKind::ConnectionAborted
            ) =>
        {
            Err(LinkError::Closed { got: 0 })
        }
        Err(e) => Err(LinkError::Io(e)),
    }
}

/// Read one `SSTP` frame into `frame` (header + payload). The header must arrive before
/// `first_deadline`; the payload before the later of `first_deadline` and `rest_timeout` after
/// the header (a client passes its request deadline and zero). A payload longer than
/// `max_len` (what this connection can legitimately receive, `max_what` in words) is refused
/// before anything is allocated for it. In an `authenticated` session the frame must be a
/// version 2 frame (its tag, counted in `max_len` by the caller, is checked by the caller).
#[allow(clippy::too_many_arguments)]
pub(crate) fn read_frame(
    stream: &mut TcpStream,
    frame: &mut Vec<u8>,
    first_deadline: Option<Instant>,
    rest_timeout: Duration,
    max_len: usize,
    max_what: &str,
    stop: Option<&AtomicBool>,
    authenticated: bool,
) -> Result<Header, LinkError> {
    frame.clear();
    frame.resize(HEADER_LEN, 0);
    read_full(stream, &mut frame[..HEADER_LEN], first_deadline, stop)?;
    let header = Header::parse_session(frame, authenticated).map_err(LinkError::Protocol)?;
    let len = header.len as usize;
    if len > max_len {
        return Err(LinkError::Protocol(Error::invalid(
            "site protocol: header.length",
            format!(
                "a {} of {len} bytes exceeds the {max_len} bytes of {max_what}",
                header.kind.name()
            ),
        )));
    }
    frame.resize(HEADER_LEN + len, 0);
    // The payload must follow within `rest_timeout` (but never before `first_deadline`).
    let now = Instant::now();
    let rest = now.checked_add(rest_timeout).unwrap_or(now);
    let deadline = first_deadline.map_or(rest, |d| d.max(rest));
    read_full(stream, &mut frame[HEADER_LEN..], Some(deadline), stop).map_err(|e| match e {
        LinkError::Closed { got } => LinkError::Closed { got: got + HEADER_LEN },
        LinkError::TimedOut { got } => LinkError::TimedOut { got: got + HEADER_LEN },
        other => other,
    })?;
    Ok(header)
}

/// Ask the kernel to acknowledge received data at once (Linux `TCP_QUICKACK`; the kernel
/// leaves quick-ack mode by itself, so call it before every read).
///
/// Needed for peers that do not set `TCP_NODELAY` and send a message that gets no reply
/// followed by one that does (OpenSees' genericClient: commit `5`, then trial `3`): Nagle's
/// algorithm on their side holds the second message until our delayed ACK (~40 ms) arrives.
#[cfg(target_os = "linux")]
pub(crate) fn quick_ack(stream: &TcpStream) {
    use std::os::fd::AsRawFd;
    unsafe extern "C" {
        fn setsockopt(fd: i32, level: i32, name: i32, value: *const std::ffi::c_void, len: u32) -> i32;
    }
    const IPPROTO_TCP: i32 = 6;
    const TCP_QUICKACK: i32 = 12;
    let one: i32 = 1;
    // SAFETY: the descriptor is owned by `stream` and open for the duration of the call; the
    // option value points to a live `i32` whose size is passed as the length.
    unsafe {
        setsockopt(
            stream.as_raw_fd(),
            IPPROTO_TCP,
            TCP_QUICKACK,
            (&one as *const i32).cast(),
            std::mem::size_of::<i32>() as u32,
        );
    }
}

#[cfg(not(target_os = "linux"))]
pub(crate) fn quick_ack(_stream: &TcpStream) {}
