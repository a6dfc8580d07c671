//! One socket to (or from) a lab target, UDP or TCP, with every receive bounded by a deadline.

use std::io::{self, Read, Write};
use std::net::{SocketAddr, TcpStream, UdpSocket};
use std::time::{Duration, Instant};

/// The transport of a lab link.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LinkTransport {
    Udp,
    Tcp,
}

impl LinkTransport {
    pub fn name(self) -> &'static str {
        match self {
            Self::Udp => "udp",
            Self::Tcp => "tcp",
        }
    }
}

/// What a bounded receive got.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Received {
    /// A frame of this many bytes (TCP: always the buffer's length).
    Frame(usize),
    /// Nothing before the deadline.
    TimedOut,
    /// The peer closed the connection (TCP).
    Closed,
}

/// A connected socket.
#[derive(Debug)]
pub enum Link {
    Udp(UdpSocket),
    Tcp(TcpStream),
}

/// The shortest read timeout handed to the OS (a zero timeout is an error there).
const MIN_WAIT: Duration = Duration::from_micros(20);

impl Link {
    /// Connect to `peer` (UDP: a socket of our own connected to it; TCP: within
    /// `connect_timeout`, and every send bounded by `send_timeout`, the exchange's budget, so
    /// that a target that stops reading cannot block the sub-step longer).
    pub fn connect(
        transport: LinkTransport,
        peer: SocketAddr,
        local: Option<SocketAddr>,
        connect_timeout: Duration,
        send_timeout: Duration,
    ) -> io::Result<Self> {
        Ok(match transport {
            LinkTransport::Udp => {
                let local: SocketAddr = local.unwrap_or_else(|| {
                    if peer.is_ipv4() {
                        "0.0.0.0:0".parse().expect("valid")
                    } else {
                        "[::]:0".parse().expect("valid")
                    }
                });
                let s = UdpSocket::bind(local)?;
                s.connect(peer)?;
                Self::Udp(s)
            }
            LinkTransport::Tcp => {
                let s = TcpStream::connect_timeout(&peer, connect_timeout.max(MIN_WAIT))?;
                s.set_nodelay(true)?;
                s.set_write_timeout(Some(send_timeout.max(MIN_WAIT)))?;
                Self::Tcp(s)
            }
        })
    }

    pub fn send(&mut self, bytes: &[u8]) -> io::Result<()> {
        match self {
            // A connected UDP socket reports an earlier ICMP "port unreachable" on the next
            // send: nobody listens at the target. That datagram is lost like any other; the
            // exchange's deadline then decides (hold, and after `hold_limit` the target is gone).
            Self::Udp(s) => match s.send(bytes) {
                Err(e) if e.kind() == io::ErrorKind::ConnectionRefused => Ok(()),
                r => r.map(|_| ()),
            },
            Self::Tcp(s) => s.write_all(bytes),
        }
    }

    /// One frame into `buf` before `deadline`. TCP reads exactly `buf.len()` bytes; a deadline
    /// that passes in the middle of a frame is an error (the stream is out of step). UDP takes
    /// one datagram (its length is returned; a longer one is cut to `buf`). A UDP "connection
    /// refused" (nobody listens at the target's port) counts as nothing received.
    pub fn recv(&mut self, buf: &mut [u8], deadline: Instant) -> io::Result<Received> {
        match self {
            Self::Udp(s) => loop {
                let now = Instant::now();
                if now >= deadline {
                    return Ok(Received::TimedOut);
                }
                s.set_read_timeout(Some((deadline - now).max(MIN_WAIT)))?;
                match s.recv(buf) {
                    Ok(n) => return Ok(Received::Frame(n)),
                    Err(e) if matches!(e.kind(), io::ErrorKind::WouldBlock | io::ErrorKind::TimedOut) => {}
                    Err(e) if e.kind() == io::ErrorKind::ConnectionRefused => {
                        // Nobody listening: wait out the budget rather than spin on the error.
                        std::thread::sleep(
                            deadline
                                .saturating_duration_since(Instant::now())
                                .min(Duration::from_millis(1)),
                        );
                    }
                    Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
                    Err(e) => return Err(e),
                }
            },
            Self::Tcp(s) => {
                let mut got = 0;
                while got < buf.len() {
                    let now = Instant::now();
                    if now >= deadline {
                        if got == 0 {
                            return Ok(Received::TimedOut);
                        }
                        return Err(io::Error::new(
                            io::ErrorKind::TimedOut,
                            format!("timed out in the middle of a frame ({got} of {} bytes)", buf.len()),
                        ));
                    }
                    s.set_read_timeout(Some((deadline - now).max(MIN_WAIT)))?;
                    match s.read(&mut buf[got..]) {
                        Ok(0) if got == 0 => return Ok(Received::Closed),
                        Ok(0) => {
                            return Err(io::Error::new(
                                io::ErrorKind::UnexpectedEof,
                                format!("closed in the middle of a frame ({got} of {} bytes)", buf.len()),
                            ));
                        }
                        Ok(n) => got += n,
                        Err(e)
                            if matches!(
                                e.kind(),
                                io::ErrorKind::WouldBlock | io::ErrorKind::TimedOut | io::ErrorKind::Interrupted
                            ) => {}
                        Err(e) if e.kind() == io::ErrorKind::ConnectionReset => return Ok(Received::Closed),
                        Err(e) => return Err(e),
                    }
                }
                Ok(Received::Frame(got))
            }
        }
    }

    /// UDP: read and discard the datagrams already waiting (stale replies); their count. TCP: 0
    /// (a stream has no stale frames to skip: every frame is read in order).
    pub fn drain(&mut self, buf: &mut [u8]) -> usize {
        match self {
            Self::Udp(s) => {
                let mut n = 0;
                if s.set_nonblocking(true).is_err() {
                    return 0;
                }
                while s.recv(buf).is_ok() {
                    n += 1;
                }
                let _ = s.set_nonblocking(false);
                n
            }
            Self::Tcp(_) => 0,
        }
    }
}
