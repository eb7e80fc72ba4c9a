//! Sealed zenoh payloads: who may read a session's frames.
//!
//! zenoh's access control is static (set when a zenoh session opens) and
//! matches key expressions, so it cannot follow sessions that come and go
//! with owners and observers, and a subscriber on
//! `meshless/v1/sessions/*/frames` is as legal as one on a single session.
//! A server with tokens therefore seals what it puts on a session's keys
//! (frames, status changes, latest-frame replies) with a key of that
//! session, which only the callers that may read the session receive, over
//! gRPC (`Session.seal_key`). Anyone else on the zenoh plane, a router
//! included, sees ciphertext; a sealed payload altered, moved to another
//! key expression or sealed with another key does not open.
//!
//! Layout of a sealed payload: one version byte ([`VERSION`]), a 12-byte
//! nonce (4 zero bytes, then a big-endian counter that the sealer never
//! repeats), then the message's bytes encrypted with AES-256-GCM and its
//! 16-byte tag. The key expression the payload is put on is the
//! associated data. Subscribers refuse a counter at or below the last one
//! they took on a key, so a recorded payload cannot be played again.

use prost::Message;
use ring::aead::{AES_256_GCM, Aad, LessSafeKey, NONCE_LEN, Nonce, UnboundKey};
use ring::rand::{SecureRandom, SystemRandom};
use std::sync::atomic::{AtomicU64, Ordering};

/// Bytes of a session's seal key.
pub const KEY_LEN: usize = 32;
/// First byte of every sealed payload.
pub const VERSION: u8 = 1;
/// Bytes before the ciphertext: the version and the nonce.
const HEADER_LEN: usize = 1 + NONCE_LEN;
/// Bytes of the authentication tag after the ciphertext.
const TAG_LEN: usize = 16;

/// Why a key or a sealed payload was refused.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum SealError {
    /// A key that is not [`KEY_LEN`] bytes long.
    #[error("a seal key has {KEY_LEN} bytes, this one {0}")]
    KeyLength(usize),
    /// The system's random source failed.
    #[error("no randomness for a seal key")]
    Random,
    /// Too short to hold the header and the tag.
    #[error("{0} bytes is too short for a sealed payload (at least {min})", min = HEADER_LEN + TAG_LEN)]
    TooShort(usize),
    /// A version byte this build does not know, e.g. a plain message.
    #[error("sealed payload version {0}, expected {VERSION}")]
    Version(u8),
    /// The tag does not match: another key, another key expression, or
    /// altered bytes.
    #[error("the payload does not open with the session's key on this key expression")]
    NotAuthentic,
}

/// A session's seal key. Its `Debug` form never shows the key.
pub struct SealKey {
    bytes: [u8; KEY_LEN],
    key: LessSafeKey,
}

impl std::fmt::Debug for SealKey {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("SealKey(..)")
    }
}

impl SealKey {
    /// A fresh random key.
    ///
    /// # Errors
    /// [`SealError::Random`] when the system has no randomness to give.
    pub fn generate() -> Result<Self, SealError> {
        let mut bytes = [0; KEY_LEN];
        SystemRandom::new()
            .fill(&mut bytes)
            .map_err(|_| SealError::Random)?;
        Self::from_bytes(&bytes)
    }

    /// The key a server handed out (`Session.seal_key`).
    ///
    /// # Errors
    /// [`SealError::KeyLength`] unless `bytes` has [`KEY_LEN`] bytes.
    pub fn from_bytes(bytes: &[u8]) -> Result<Self, SealError> {
        let bytes: [u8; KEY_LEN] = bytes
            .try_into()
            .map_err(|_| SealError::KeyLength(bytes.len()))?;
        let unbound =
            UnboundKey::new(&AES_256_GCM, &bytes).map_err(|_| SealError::KeyLength(KEY_LEN))?;
        Ok(Self {
            bytes,
            key: LessSafeKey::new(unbound),
        })
    }

    /// The key's bytes, to hand to a reader.
    pub fn bytes(&self) -> &[u8; KEY_LEN] {
        &self.bytes
    }

    /// Opens `payload`, sealed for `key_expr`, in place: the message's
    /// bytes and the counter it was sealed with.
    ///
    /// # Errors
    /// [`SealError::TooShort`], [`SealError::Version`] or
    /// [`SealError::NotAuthentic`].
    pub fn open<'a>(
        &self,
        key_expr: &str,
        payload: &'a mut [u8],
    ) -> Result<(u64, &'a [u8]), SealError> {
        if payload.len() < HEADER_LEN + TAG_LEN {
            return Err(SealError::TooShort(payload.len()));
        }
        let (header, sealed) = payload.split_at_mut(HEADER_LEN);
        if header[0] != VERSION {
            return Err(SealError::Version(header[0]));
        }
        let nonce: [u8; NONCE_LEN] = header[1..].try_into().expect("12 nonce bytes");
        let counter = u64::from_be_bytes(nonce[4..].try_into().expect("8 counter bytes"));
        let plain = self
            .key
            .open_in_place(
                Nonce::assume_unique_for_key(nonce),
                Aad::from(key_expr.as_bytes()),
                sealed,
            )
            .map_err(|_| SealError::NotAuthentic)?;
        Ok((counter, plain))
    }
}

/// Seals a session's payloads, each under a nonce it never uses again.
#[derive(Debug)]
pub struct Sealer {
    key: SealKey,
    counter: AtomicU64,
}

impl Sealer {
    /// A sealer with a fresh random key.
    ///
    /// # Errors
    /// [`SealError::Random`].
    pub fn generate() -> Result<Self, SealError> {
        Ok(Self::new(SealKey::generate()?))
    }

    /// A sealer with `key`, counting from 1.
    pub fn new(key: SealKey) -> Self {
        Self {
            key,
            counter: AtomicU64::new(1),
        }
    }

    /// The key that opens what this sealer seals.
    pub fn key(&self) -> &SealKey {
        &self.key
    }

    /// `message` encoded and sealed for `key_expr`. It is encoded straight
    /// into the sealed payload's buffer and encrypted in place, so a frame
    /// of tens of megabytes is never copied.
    pub fn seal(&self, key_expr: &str, message: &impl Message) -> Vec<u8> {
        self.seal_with(key_expr, message.encoded_len(), |out| {
            message.encode(out).expect("a Vec grows to any message");
        })
    }

    /// An already encoded message sealed for `key_expr`: the same payload
    /// as [`Self::seal`] of the message, for a sender that encodes once
    /// and seals per key (the server's frames, encoded once per step).
    pub fn seal_encoded(&self, key_expr: &str, encoded: &[u8]) -> Vec<u8> {
        self.seal_with(key_expr, encoded.len(), |out| {
            out.extend_from_slice(encoded);
        })
    }

    /// Header, the `len` plain bytes `write` appends, encrypted in place,
    /// and the tag.
    fn seal_with(&self, key_expr: &str, len: usize, write: impl FnOnce(&mut Vec<u8>)) -> Vec<u8> {
        // 2^64 payloads would take millennia at any rate a server reaches,
        // so the counter never wraps to a used nonce.
        let counter = self.counter.fetch_add(1, Ordering::Relaxed);
        let mut nonce = [0; NONCE_LEN];
        nonce[4..].copy_from_slice(&counter.to_be_bytes());
        let mut out = Vec::with_capacity(HEADER_LEN + len + TAG_LEN);
        out.push(VERSION);
        out.extend_from_slice(&nonce);
        write(&mut out);
        let tag = self
            .key
            .key
            .seal_in_place_separate_tag(
                Nonce::assume_unique_for_key(nonce),
                Aad::from(key_expr.as_bytes()),
                &mut out[HEADER_LEN..],
            )
            .expect("AES-GCM seals any length a Vec holds");
        out.extend_from_slice(tag.as_ref());
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::v1;

    fn status(step: u64) -> v1::SessionStatus {
        v1::SessionStatus {
            session_id: "abc".into(),
            step,
            ..Default::default()
        }
    }

    #[test]
    fn a_sealed_message_opens_with_its_key_on_its_key_expression_only() {
        let sealer = Sealer::generate().expect("random");
        let key = SealKey::from_bytes(sealer.key().bytes()).expect("32 bytes");
        let mut sealed = sealer.seal("k/status", &status(7));
        let plain_len = status(7).encoded_len();
        assert_eq!(sealed.len(), HEADER_LEN + plain_len + TAG_LEN);

        let (counter, plain) = key
            .open("k/status", &mut sealed.clone())
            .map(|(c, p)| (c, p.to_vec()))
            .expect("opens");
        assert_eq!(counter, 1);
        assert_eq!(
            v1::SessionStatus::decode(&plain[..]).expect("decodes"),
            status(7)
        );

        assert_eq!(
            key.open("k/frames", &mut sealed.clone()),
            Err(SealError::NotAuthentic),
            "moved to another key expression"
        );
        let stranger = SealKey::generate().expect("random");
        assert_eq!(
            stranger.open("k/status", &mut sealed.clone()),
            Err(SealError::NotAuthentic)
        );
        let last = sealed.len() - 1;
        sealed[HEADER_LEN] ^= 1;
        assert_eq!(
            key.open("k/status", &mut sealed.clone()),
            Err(SealError::NotAuthentic)
        );
        sealed[HEADER_LEN] ^= 1;
        sealed[last] ^= 0x80;
        assert_eq!(
            key.open("k/status", &mut sealed),
            Err(SealError::NotAuthentic)
        );
    }

    #[test]
    fn every_payload_has_its_own_nonce_and_plain_messages_do_not_open() {
        let sealer = Sealer::generate().expect("random");
        let a = sealer.seal("k", &status(1));
        let b = sealer.seal("k", &status(1));
        let encoded = sealer.seal_encoded("k", &status(1).encode_to_vec());
        assert_eq!(encoded.len(), a.len());
        assert_eq!(
            sealer
                .key()
                .open("k", &mut encoded.clone())
                .map(|(c, p)| (c, p.to_vec())),
            Ok((3, status(1).encode_to_vec())),
            "an encoded message seals as the message does"
        );
        assert_ne!(a[1..HEADER_LEN], b[1..HEADER_LEN], "nonces differ");
        assert_ne!(a, b, "the same message seals differently");
        let key = sealer.key();
        assert_eq!(key.open("k", &mut b.clone()).map(|(c, _)| c), Ok(2));

        let mut plain = status(1).encode_to_vec();
        assert!(matches!(
            key.open("k", &mut plain),
            Err(SealError::TooShort(_) | SealError::Version(_))
        ));
        assert_eq!(key.open("k", &mut [0; 3]), Err(SealError::TooShort(3)));
        let mut versioned = a.clone();
        versioned[0] = 2;
        assert_eq!(key.open("k", &mut versioned), Err(SealError::Version(2)));
    }

    #[test]
    fn keys_have_32_bytes_and_never_print() {
        assert_eq!(
            SealKey::from_bytes(&[0; 31]).err(),
            Some(SealError::KeyLength(31))
        );
        assert!(SealKey::from_bytes(&[]).is_err());
        let key = SealKey::from_bytes(&[7; KEY_LEN]).expect("32 bytes");
        assert_eq!(format!("{key:?}"), "SealKey(..)");
        assert_ne!(
            SealKey::generate().expect("random").bytes(),
            SealKey::generate().expect("random").bytes()
        );
    }
}
