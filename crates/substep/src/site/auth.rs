//! Shared-secret authentication of `SSTP` sessions: an HMAC-SHA256 challenge–response in the
//! handshake, mutual and bound to the session parameters, and a MAC on every message of the
//! session after it.
//!
//! ```text
//! client                                   site (started with the secret)
//! Hello #0  (session parameters H)  ──▶
//!                                   ◀──   Challenge #0 (fresh 32-byte nonce Ns from the OS RNG)
//! Auth #1   (nonce Nc, MAC_c)       ──▶    MAC_c checked in constant time; only then is the
//!                                          specimen built
//!                                   ◀──   Accept #1 (n_c, MAC_s)   (or Reject)
//! MAC_s checked: the site knows the secret too
//! Substep/Step/… #2, #3, …  (each with a tag under K_C)  ──▶  tag and number checked
//!                   ◀──  Measured/StepResult/… #2, #3, …  (each with a tag under K_S)
//! ```
//!
//! `MAC_r = HMAC-SHA256(secret, "SSTP-1 auth" ‖ r ‖ Ns ‖ Nc ‖ len(H) ‖ H)` with the role byte
//! `r` (`C` client, `S` site) and `H` the Hello payload exactly as sent. A recorded handshake
//! does not authenticate a later session (the site's nonce is new each time), a client MAC
//! cannot be reflected as a site MAC (role byte), and a proof is valid only for the parameters
//! it was made for (`H` is inside the MAC).
//!
//! After the handshake every message in both directions carries a tag ([`SessionKeys`]): the
//! session key of the sender's direction is
//! `K_r = HMAC-SHA256(secret, "SSTP-1 session" ‖ r ‖ Ns ‖ Nc ‖ len(H) ‖ H)` (`r` = `C` for
//! client → site, `S` for site → client), and the tag is the first [`TAG_LEN`] bytes of
//! `HMAC-SHA256(K_r, header ‖ payload)`: the header includes the type and the sequence number,
//! so a changed, injected, replayed, reordered or reflected message is detected (the frame
//! layout is in [`super::protocol`]). Without a secret nothing is authenticated, and the
//! frames are those of protocol version 1 byte for byte (`docs/security.md`).

use crate::error::{Error, Result};
use hmac::{Hmac, Mac};
use sha2::Sha256;
use std::io::Read;
use std::path::Path;
use std::sync::Arc;

pub const NONCE_LEN: usize = 32;
pub const MAC_LEN: usize = 32;
/// Length of the tag of a session message: HMAC-SHA256 truncated to 128 bits.
pub const TAG_LEN: usize = 16;
/// Shortest secret accepted, in bytes (128 bits).
pub const MIN_SECRET_LEN: usize = 16;
/// Longest secret file read, in bytes.
pub const MAX_SECRET_LEN: usize = 4096;
/// Environment variable holding the secret when no `secret_file` is configured.
pub const SECRET_ENV: &str = "SUBSTEP_SITE_SECRET";

/// Who computes a MAC (domain separation between the two proofs).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Role {
    Client,
    Site,
}

/// The shared secret (its bytes are never printed).
#[derive(Clone)]
pub struct Secret(Arc<[u8]>);

impl std::fmt::Debug for Secret {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Secret({} bytes)", self.0.len())
    }
}

impl PartialEq for Secret {
    fn eq(&self, other: &Self) -> bool {
        // Only used to compare configurations; not on the authentication path.
        self.0 == other.0
    }
}

impl Secret {
    /// A secret from its bytes; surrounding ASCII whitespace (a trailing newline of a file or
    /// `openssl rand -hex 32` output) is not part of it. `what` names the source in errors.
    pub fn new(bytes: &[u8], what: &str) -> Result<Self> {
        let trimmed = bytes.trim_ascii();
        if trimmed.len() < MIN_SECRET_LEN {
            return Err(Error::invalid(
                what,
                format!(
                    "the secret is {} bytes, at least {MIN_SECRET_LEN} are needed (make one with `openssl rand -hex 32`)",
                    trimmed.len()
                ),
            ));
        }
        if trimmed.len() > MAX_SECRET_LEN {
            return Err(Error::invalid(
                what,
                format!("the secret is longer than {MAX_SECRET_LEN} bytes"),
            ));
        }
        Ok(Secret(Arc::from(trimmed)))
    }

    /// Read the secret from a regular file (at most [`MAX_SECRET_LEN`] bytes are read).
    pub fn from_file(path: &Path, what: &str) -> Result<Self> {
        let name = format!("{what} ({})", path.display());
        let meta =
            std::fs::metadata(path).map_err(|e| Error::invalid(&name, format!("cannot read the secret file: {e}")))?;
        if !meta.is_file() {
            return Err(Error::invalid(&name, "is not a regular file"));
        }
        let mut bytes = Vec::new();
        std::fs::File::open(path)
            .and_then(|f| f.take(MAX_SECRET_LEN as u64 + 1).read_to_end(&mut bytes))
            .map_err(|e| Error::invalid(&name, format!("cannot read the secret file: {e}")))?;
        Self::new(&bytes, &name)
    }

    /// The secret in [`SECRET_ENV`], if that variable is set (and not empty).
    pub fn from_env() -> Result<Option<Self>> {
        match std::env::var_os(SECRET_ENV) {
            Some(v) if !v.is_empty() => Self::new(v.as_encoded_bytes(), SECRET_ENV).map(Some),
            _ => Ok(None),
        }
    }

    fn hmac(
        &self,
        label: &[u8],
        role: Role,
        site_nonce: &[u8; NONCE_LEN],
        client_nonce: &[u8; NONCE_LEN],
        hello: &[u8],
    ) -> Hmac<Sha256> {
        let mut m = <Hmac<Sha256> as Mac>::new_from_slice(&self.0).expect("HMAC accepts keys of any length");
        m.update(label);
        m.update(match role {
            Role::Client => b"C",
            Role::Site => b"S",
        });
        m.update(site_nonce);
        m.update(client_nonce);
        m.update(&(hello.len() as u64).to_le_bytes());
        m.update(hello);
        m
    }

    /// The proof of `role` for a handshake.
    pub fn mac(
        &self,
        role: Role,
        site_nonce: &[u8; NONCE_LEN],
        client_nonce: &[u8; NONCE_LEN],
        hello: &[u8],
    ) -> [u8; MAC_LEN] {
        self.hmac(b"SSTP-1 auth", role, site_nonce, client_nonce, hello)
            .finalize()
            .into_bytes()
            .into()
    }

    /// Whether `tag` is the proof of `role` (constant-time comparison).
    pub fn verify(
        &self,
        role: Role,
        site_nonce: &[u8; NONCE_LEN],
        client_nonce: &[u8; NONCE_LEN],
        hello: &[u8],
        tag: &[u8; MAC_LEN],
    ) -> bool {
        self.hmac(b"SSTP-1 auth", role, site_nonce, client_nonce, hello)
            .verify_slice(tag)
            .is_ok()
    }

    /// The session keys of `role` after a successful handshake: `role`'s own direction to
    /// seal, the peer's to open.
    pub fn session_keys(
        &self,
        role: Role,
        site_nonce: &[u8; NONCE_LEN],
        client_nonce: &[u8; NONCE_LEN],
        hello: &[u8],
    ) -> SessionKeys {
        let key = |direction: Role| -> Hmac<Sha256> {
            let k = self
                .hmac(b"SSTP-1 session", direction, site_nonce, client_nonce, hello)
                .finalize()
                .into_bytes();
            <Hmac<Sha256> as Mac>::new_from_slice(&k).expect("HMAC accepts keys of any length")
        };
        let peer = match role {
            Role::Client => Role::Site,
            Role::Site => Role::Client,
        };
        SessionKeys {
            send: key(role),
            receive: key(peer),
        }
    }
}

/// The keys of one authenticated session, as keyed HMAC states: computing a tag clones one
/// (a copy of two SHA-256 states on the stack), so the per-message cost is the hashing of the
/// header and payload, with no allocation.
#[derive(Clone)]
pub struct SessionKeys {
    send: Hmac<Sha256>,
    receive: Hmac<Sha256>,
}

impl std::fmt::Debug for SessionKeys {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "SessionKeys(..)")
    }
}

impl SessionKeys {
    /// The tag of an outgoing message `header ‖ payload`.
    pub fn tag(&self, message: &[u8]) -> [u8; TAG_LEN] {
        let mut m = self.send.clone();
        m.update(message);
        let full = m.finalize().into_bytes();
        let mut tag = [0u8; TAG_LEN];
        tag.copy_from_slice(&full[..TAG_LEN]);
        tag
    }

    /// Whether `tag` is the peer's tag of the incoming message `header ‖ payload` (constant
    /// time).
    pub fn verify(&self, message: &[u8], tag: &[u8]) -> bool {
        if tag.len() != TAG_LEN {
            return false;
        }
        let mut m = self.receive.clone();
        m.update(message);
        m.verify_truncated_left(tag).is_ok()
    }
}

/// A fresh nonce from the operating system's RNG.
pub fn nonce() -> Result<[u8; NONCE_LEN]> {
    let mut n = [0u8; NONCE_LEN];
    getrandom::fill(&mut n).map_err(|e| {
        Error::invalid(
            "site authentication",
            format!("the OS random number generator failed: {e}"),
        )
    })?;
    Ok(n)
}
