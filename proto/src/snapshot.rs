//! The snapshot blob: a [`SnapshotPayload`] framed so that a server can
//! refuse what is not one of its own before decoding anything.
//!
//! Layout, integers little-endian:
//!
//! | bytes | what |
//! |---|---|
//! | 8 | [`MAGIC`] |
//! | 4 | format ([`FORMAT`]) |
//! | 2 | length `k` of the build string, at most [`MAX_BUILD_LEN`] |
//! | k | the build string ([`build`]): crate version and schema digest |
//! | 8 | payload length `n` |
//! | 32 | SHA-256 of everything before it and of the payload |
//! | n | the payload, a protobuf `SnapshotPayload` |
//!
//! The build string names the version and a digest of the protocol's
//! schema, so a blob of another build (whose payload may mean something
//! else) is refused by name, not misread. The digest catches truncation,
//! corruption and a payload altered in transit; it is not a signature (a
//! client may craft a blob with a valid digest), so whoever restores a
//! payload checks every value of it as well.

use crate::v1::SnapshotPayload;
use prost::Message;
use ring::digest::{SHA256, digest};
use std::sync::LazyLock;

/// First bytes of every snapshot blob.
pub const MAGIC: &[u8; 8] = b"MESHSNAP";
/// The layout above; bumped when it changes.
pub const FORMAT: u32 = 1;
/// Longest build string a blob may carry.
pub const MAX_BUILD_LEN: usize = 128;
/// Most bytes of a blob's build string an error quotes (the protocol's
/// quoting rule: at most a 64-character prefix of any input).
const MAX_QUOTE_LEN: usize = 48;
/// Bytes of the SHA-256 digest.
const DIGEST_LEN: usize = 32;

/// This build: `meshless VERSION (schema DIGEST)`, the digest the first
/// 12 hex digits of the SHA-256 of the protocol's file descriptors.
pub fn build() -> &'static str {
    static BUILD: LazyLock<String> = LazyLock::new(|| {
        let hash = digest(&SHA256, crate::FILE_DESCRIPTOR_SET);
        let hex: String = hash.as_ref()[..6]
            .iter()
            .map(|b| format!("{b:02x}"))
            .collect();
        format!("meshless {} (schema {hex})", env!("CARGO_PKG_VERSION"))
    });
    &BUILD
}

/// Why bytes are not a snapshot of this build; nothing was decoded.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum BlobError {
    /// Larger than the limit.
    #[error("the snapshot has {size} bytes, over this server's limit of {limit}")]
    TooLarge {
        /// Its size.
        size: usize,
        /// The limit.
        limit: usize,
    },
    /// Does not start with [`MAGIC`].
    #[error(
        "not a meshless snapshot (it does not start with {:?})",
        String::from_utf8_lossy(MAGIC)
    )]
    NotASnapshot,
    /// Ends before its header or payload does.
    #[error("the snapshot is truncated: {needed} bytes expected, {got} present")]
    Truncated {
        /// Bytes the header announces.
        needed: usize,
        /// Bytes there are.
        got: usize,
    },
    /// Another blob layout.
    #[error("the snapshot has format {got}; this server reads format {FORMAT}")]
    Format {
        /// Its format.
        got: u32,
    },
    /// Written by another build.
    #[error(
        "the snapshot was written by {got:?}; this server is {:?}: restore it on a server of \
         that build",
        build()
    )]
    Build {
        /// The start of its build string (at most 48 bytes, lossily
        /// decoded: an error quotes a short prefix of any input).
        got: String,
    },
    /// Bytes after the payload.
    #[error("the snapshot has {extra} bytes after its payload")]
    Trailing {
        /// How many.
        extra: usize,
    },
    /// The digest does not match: corrupted or altered.
    #[error("the snapshot's checksum does not match its contents: it was corrupted or altered")]
    Checksum,
    /// The payload does not decode.
    #[error("the snapshot's payload does not decode: {0}")]
    Payload(String),
}

/// Frames `payload` as a blob of this build.
pub fn encode(payload: &SnapshotPayload) -> Vec<u8> {
    let body = payload.encode_to_vec();
    let build = build().as_bytes();
    let mut blob = Vec::with_capacity(body.len() + 64 + build.len());
    blob.extend_from_slice(MAGIC);
    blob.extend_from_slice(&FORMAT.to_le_bytes());
    // The build string is ours and short (see `MAX_BUILD_LEN`).
    blob.extend_from_slice(&(build.len() as u16).to_le_bytes());
    blob.extend_from_slice(build);
    blob.extend_from_slice(&(body.len() as u64).to_le_bytes());
    let sum = checksum(&blob, &body);
    blob.extend_from_slice(&sum);
    blob.extend_from_slice(&body);
    blob
}

/// SHA-256 of `header` then `body`.
fn checksum(header: &[u8], body: &[u8]) -> [u8; DIGEST_LEN] {
    let mut context = ring::digest::Context::new(&SHA256);
    context.update(header);
    context.update(body);
    let mut out = [0; DIGEST_LEN];
    out.copy_from_slice(context.finish().as_ref());
    out
}

/// Reads the next `len` bytes at `*at`, or says how many were needed.
fn take<'a>(blob: &'a [u8], at: &mut usize, len: usize) -> Result<&'a [u8], BlobError> {
    let end = at.saturating_add(len);
    let bytes = blob.get(*at..end).ok_or(BlobError::Truncated {
        needed: end,
        got: blob.len(),
    })?;
    *at = end;
    Ok(bytes)
}

/// The payload of a blob of this build, checked in order: size, magic,
/// format, build, length, digest, then decoded.
///
/// # Errors
/// [`BlobError`]; nothing past the first failed check is read.
pub fn decode(blob: &[u8], limit: usize) -> Result<SnapshotPayload, BlobError> {
    if blob.len() > limit {
        return Err(BlobError::TooLarge {
            size: blob.len(),
            limit,
        });
    }
    let mut at = 0;
    if take(blob, &mut at, MAGIC.len()).map_err(|_| BlobError::NotASnapshot)? != MAGIC {
        return Err(BlobError::NotASnapshot);
    }
    let word = |bytes: &[u8]| -> u64 {
        let mut buf = [0u8; 8];
        buf[..bytes.len()].copy_from_slice(bytes);
        u64::from_le_bytes(buf)
    };
    let format = word(take(blob, &mut at, 4)?) as u32;
    if format != FORMAT {
        return Err(BlobError::Format { got: format });
    }
    let build_len = word(take(blob, &mut at, 2)?) as usize;
    let theirs = take(blob, &mut at, build_len.min(MAX_BUILD_LEN))?;
    if build_len > MAX_BUILD_LEN || theirs != build().as_bytes() {
        // Quoted as any input is: a short prefix, never all of it.
        let quoted = &theirs[..theirs.len().min(MAX_QUOTE_LEN)];
        return Err(BlobError::Build {
            got: String::from_utf8_lossy(quoted).into_owned(),
        });
    }
    let len = usize::try_from(word(take(blob, &mut at, 8)?)).unwrap_or(usize::MAX);
    let header_end = at;
    let sum = take(blob, &mut at, DIGEST_LEN)?;
    let body = take(blob, &mut at, len)?;
    if at < blob.len() {
        return Err(BlobError::Trailing {
            extra: blob.len() - at,
        });
    }
    if checksum(&blob[..header_end], body) != sum {
        return Err(BlobError::Checksum);
    }
    SnapshotPayload::decode(body).map_err(|e| BlobError::Payload(e.to_string()))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::v1::{SessionRecord, WorldSnapshot};

    fn payload() -> SnapshotPayload {
        SnapshotPayload {
            world: Some(WorldSnapshot {
                step: 7,
                time: 0.5,
                systems: Vec::new(),
            }),
            session: Some(SessionRecord {
                id: "s-1".into(),
                owner: "alice".into(),
                ..Default::default()
            }),
            ..Default::default()
        }
    }

    #[test]
    fn a_blob_round_trips() {
        let blob = encode(&payload());
        assert_eq!(decode(&blob, usize::MAX), Ok(payload()));
    }

    #[test]
    fn every_truncation_is_refused() {
        let blob = encode(&payload());
        for len in 0..blob.len() {
            let err = decode(&blob[..len], usize::MAX).expect_err("truncated");
            assert!(
                matches!(err, BlobError::Truncated { .. } | BlobError::NotASnapshot),
                "{len}: {err}"
            );
        }
    }

    #[test]
    fn every_flipped_byte_is_refused() {
        let blob = encode(&payload());
        for at in 0..blob.len() {
            let mut bad = blob.clone();
            bad[at] ^= 0x20;
            assert!(decode(&bad, usize::MAX).is_err(), "byte {at} flipped");
        }
    }

    #[test]
    fn another_build_or_format_is_refused_by_name() {
        let blob = encode(&payload());
        let mut other = blob.clone();
        other[MAGIC.len()] = 2;
        assert_eq!(
            decode(&other, usize::MAX),
            Err(BlobError::Format { got: 2 })
        );
        // "meshless 0.1.0" -> "meshless 9.1.0": the digest would catch it
        // too, but the build is named first.
        let mut other = blob.clone();
        let version_at = MAGIC.len() + 4 + 2 + "meshless ".len();
        other[version_at] = b'9';
        let err = decode(&other, usize::MAX).expect_err("another build");
        assert!(err.to_string().contains("meshless 9"), "{err}");
        assert!(err.to_string().contains(build()), "{err}");
    }

    #[test]
    fn size_limit_and_trailing_bytes_are_refused() {
        let blob = encode(&payload());
        assert_eq!(
            decode(&blob, blob.len() - 1),
            Err(BlobError::TooLarge {
                size: blob.len(),
                limit: blob.len() - 1
            })
        );
        let mut longer = blob.clone();
        longer.push(0);
        assert_eq!(
            decode(&longer, usize::MAX),
            Err(BlobError::Trailing { extra: 1 })
        );
    }

    #[test]
    fn a_huge_build_length_is_refused_without_reading_it() {
        let mut blob = MAGIC.to_vec();
        blob.extend_from_slice(&FORMAT.to_le_bytes());
        blob.extend_from_slice(&u16::MAX.to_le_bytes());
        blob.extend_from_slice(&[b'x'; 200]);
        let err = decode(&blob, usize::MAX).expect_err("refused");
        let BlobError::Build { got } = err else {
            panic!("{err}")
        };
        assert_eq!(got.len(), MAX_QUOTE_LEN, "a short prefix, never all of it");
    }
}
