//! The request parser of the monitor's HTTP server (`substep run --monitor`, docs/monitor.md).
//!
//! Pure and incremental: [`parse_request`] looks at the bytes received so far on a connection
//! and says whether a whole request is there, more bytes are needed, or the request is refused
//! (with the HTTP status and the reason). The server (in the `substep` binary) reads
//! non-blocking into a buffer of at most [`MAX_HEAD`] + [`MAX_BODY`] bytes and calls it after
//! every read, so a client that sends one byte at a time costs one bounded buffer and never a
//! thread, and the deadline per request is the server's, not the socket's.
//!
//! Accepted: `METHOD SP TARGET SP HTTP/1.x CRLF`, header lines `Name: value` (CRLF or LF line
//! ends), an empty line, then exactly `Content-Length` bytes of body (no chunked bodies: the
//! page never sends them). Anything else is refused, never guessed at.

/// Longest request head accepted (request line and headers) \[bytes\].
pub const MAX_HEAD: usize = 8192;
/// Longest request body accepted \[bytes\] (a control request is about 60).
pub const MAX_BODY: usize = 4096;

/// One parsed request; `body` borrows from the connection's buffer.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Request<'a> {
    pub method: &'a str,
    /// The request target without its query string.
    pub path: &'a str,
    pub body: &'a [u8],
}

/// What the bytes received so far amount to.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Parsed<'a> {
    /// A whole request (bytes after it are ignored: every response closes the connection).
    Complete(Request<'a>),
    /// The head or the body is not complete yet.
    Incomplete,
    /// Refused: the HTTP status to answer and why.
    Refused(u16, &'static str),
}

/// Parse the bytes a connection has sent so far (see the module docs).
pub fn parse_request(buf: &[u8]) -> Parsed<'_> {
    let Some(head_end) = find_head_end(buf) else {
        return if buf.len() > MAX_HEAD {
            Parsed::Refused(413, "request head too long")
        } else {
            Parsed::Incomplete
        };
    };
    let (head, body_start) = head_end;
    if head.len() > MAX_HEAD {
        return Parsed::Refused(413, "request head too long");
    }
    let Ok(head) = std::str::from_utf8(head) else {
        return Parsed::Refused(400, "request head is not UTF-8");
    };
    let mut lines = head.split('\n').map(|l| l.strip_suffix('\r').unwrap_or(l));
    let request_line = lines.next().unwrap_or("");
    let mut parts = request_line.split(' ');
    let (Some(method), Some(target), Some(version), None) = (parts.next(), parts.next(), parts.next(), parts.next())
    else {
        return Parsed::Refused(400, "malformed request line");
    };
    if method.is_empty() || !method.bytes().all(|b| b.is_ascii_uppercase()) {
        return Parsed::Refused(400, "malformed request method");
    }
    if !target.starts_with('/') {
        return Parsed::Refused(400, "malformed request target");
    }
    if version != "HTTP/1.1" && version != "HTTP/1.0" {
        return Parsed::Refused(400, "not an HTTP/1.x request");
    }
    let mut length: Option<usize> = None;
    for line in lines {
        if line.is_empty() {
            continue;
        }
        let Some((name, value)) = line.split_once(':') else {
            return Parsed::Refused(400, "malformed header line");
        };
        let name = name.trim();
        if name.eq_ignore_ascii_case("content-length") {
            let value = value.trim();
            // Digits only (no sign, no spaces inside); a second, different length is a smuggling attempt.
            if value.is_empty() || value.len() > 12 || !value.bytes().all(|b| b.is_ascii_digit()) {
                return Parsed::Refused(400, "malformed Content-Length");
            }
            let n: usize = value.parse().unwrap_or(usize::MAX);
            if length.is_some_and(|l| l != n) {
                return Parsed::Refused(400, "conflicting Content-Length headers");
            }
            length = Some(n);
        } else if name.eq_ignore_ascii_case("transfer-encoding") {
            return Parsed::Refused(400, "Transfer-Encoding is not supported (send Content-Length)");
        }
    }
    let length = length.unwrap_or(0);
    if length > MAX_BODY {
        return Parsed::Refused(413, "request body too long");
    }
    let rest = &buf[body_start..];
    if rest.len() < length {
        return Parsed::Incomplete;
    }
    let path = target.split('?').next().unwrap_or(target);
    Parsed::Complete(Request {
        method,
        path,
        body: &rest[..length],
    })
}

/// The head (without its final empty line) and where the body starts, once the empty line that
/// ends the head has arrived (CRLF CRLF or LF LF).
fn find_head_end(buf: &[u8]) -> Option<(&[u8], usize)> {
    let limit = buf.len().min(MAX_HEAD + 4);
    let mut i = 0;
    while i < limit {
        if buf[i] == b'\n' {
            if buf.get(i + 1) == Some(&b'\n') {
                return Some((&buf[..i], i + 2));
            }
            if buf.get(i + 1) == Some(&b'\r') && buf.get(i + 2) == Some(&b'\n') {
                return Some((&buf[..i], i + 3));
            }
        }
        i += 1;
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_request_arrives_byte_by_byte() {
        let full = b"POST /control?x=1 HTTP/1.1\r\nHost: a\r\nContent-Length: 5\r\n\r\nhello";
        for n in 0..full.len() {
            assert_eq!(parse_request(&full[..n]), Parsed::Incomplete, "after {n} bytes");
        }
        assert_eq!(
            parse_request(full),
            Parsed::Complete(Request {
                method: "POST",
                path: "/control",
                body: b"hello"
            })
        );
    }

    #[test]
    fn lf_only_heads_and_no_body() {
        assert_eq!(
            parse_request(b"GET /state HTTP/1.0\nAccept: */*\n\n"),
            Parsed::Complete(Request {
                method: "GET",
                path: "/state",
                body: b""
            })
        );
    }

    #[test]
    fn bad_requests_are_refused_with_a_reason() {
        let cases: &[(&[u8], u16)] = &[
            (b"GET /\r\n\r\n", 400),
            (b"GET / HTTP/1.1 extra\r\n\r\n", 400),
            (b"get / HTTP/1.1\r\n\r\n", 400),
            (b"GET state HTTP/1.1\r\n\r\n", 400),
            (b"GET / SSTP/1\r\n\r\n", 400),
            (b"POST / HTTP/1.1\r\nContent-Length: -1\r\n\r\n", 400),
            (b"POST / HTTP/1.1\r\nContent-Length: 1e3\r\n\r\n", 400),
            (
                b"POST / HTTP/1.1\r\nContent-Length: 5\r\nContent-Length: 6\r\n\r\n",
                400,
            ),
            (b"POST / HTTP/1.1\r\nTransfer-Encoding: chunked\r\n\r\n", 400),
            (b"POST / HTTP/1.1\r\nContent-Length: 4097\r\n\r\n", 413),
            (b"POST / HTTP/1.1\r\nContent-Length: 99999999999999999999\r\n\r\n", 400),
            (b"GET / HTTP/1.1\r\nno colon here\r\n\r\n", 400),
            (b"GET / HTTP/1.1\r\nX: \xff\r\n\r\n", 400),
        ];
        for (bytes, code) in cases {
            match parse_request(bytes) {
                Parsed::Refused(c, why) => assert_eq!(c, *code, "{:?}: {why}", String::from_utf8_lossy(bytes)),
                other => panic!("{:?} gave {other:?}", String::from_utf8_lossy(bytes)),
            }
        }
    }

    #[test]
    fn a_head_without_end_is_refused_once_it_is_too_long() {
        let mut head = b"GET / HTTP/1.1\r\n".to_vec();
        while head.len() <= MAX_HEAD {
            assert_eq!(parse_request(&head), Parsed::Incomplete);
            head.extend_from_slice(b"X-Pad: aaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaa\r\n");
        }
        assert_eq!(parse_request(&head), Parsed::Refused(413, "request head too long"));
    }
}
