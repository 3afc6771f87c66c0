//! The one encode/decode pair of the system.
//!
//! Binary messages: bincode 2 (serde, standard config: little-endian, varint lengths), with a decode
//! size limit. JSON messages (metrics, registry metadata): serde_json. Both check [`WIRE_VERSION`]
//! before they trust the rest of the bytes. bincode is reached only from this file, so the binary
//! format can be swapped here alone (bincode 3 on crates.io is an empty tombstone).

use serde::Serialize;
use serde::de::DeserializeOwned;

use crate::{WIRE_VERSION, WireMessage};

/// Largest binary message accepted by [`decode`]: rollout chunks are kept to a few MB and weights to
/// tens of MB, so 256 MiB leaves room without letting a bad length prefix allocate without bound.
pub const MAX_MESSAGE_BYTES: usize = 256 << 20;

/// Largest JSON message accepted by [`decode_json`].
pub const MAX_JSON_BYTES: usize = 16 << 20;

const LIMIT: usize = MAX_MESSAGE_BYTES;

fn config() -> bincode::config::Configuration<
    bincode::config::LittleEndian,
    bincode::config::Varint,
    bincode::config::Limit<LIMIT>,
> {
    bincode::config::standard().with_limit::<LIMIT>()
}

/// Why bytes could not become a message (or a message bytes).
#[derive(Debug, thiserror::Error)]
pub enum CodecError {
    #[error("{what}: message of {len} bytes exceeds the limit of {limit} bytes")]
    TooLarge {
        what: &'static str,
        len: usize,
        limit: usize,
    },
    #[error(
        "{what}: wire version {got} but this build speaks {expected}\nhint: run the same l3p version on every process"
    )]
    WrongVersion {
        what: &'static str,
        got: u32,
        expected: u32,
    },
    #[error("{what}: malformed binary message: {source}")]
    Decode {
        what: &'static str,
        #[source]
        source: bincode::error::DecodeError,
    },
    #[error("{what}: {len} trailing bytes after the message")]
    TrailingBytes { what: &'static str, len: usize },
    #[error("{what}: cannot encode: {source}")]
    Encode {
        what: &'static str,
        #[source]
        source: bincode::error::EncodeError,
    },
    #[error("{what}: malformed JSON: {source}")]
    Json {
        what: &'static str,
        #[source]
        source: serde_json::Error,
    },
}

/// Encode a binary message.
pub fn encode<T: Serialize + WireMessage>(message: &T) -> Result<Vec<u8>, CodecError> {
    let bytes =
        bincode::serde::encode_to_vec(message, config()).map_err(|source| CodecError::Encode {
            what: T::NAME,
            source,
        })?;
    if bytes.len() > MAX_MESSAGE_BYTES {
        return Err(CodecError::TooLarge {
            what: T::NAME,
            len: bytes.len(),
            limit: MAX_MESSAGE_BYTES,
        });
    }
    Ok(bytes)
}

/// Decode a binary message, refusing oversized input, another wire version, malformed or trailing
/// bytes. Never panics and never allocates more than a bounded multiple of the input length.
pub fn decode<T: DeserializeOwned + WireMessage>(bytes: &[u8]) -> Result<T, CodecError> {
    decode_with_limit(bytes, MAX_MESSAGE_BYTES)
}

/// [`decode`] with a tighter size limit (e.g. small robot states on the deploy path).
pub fn decode_with_limit<T: DeserializeOwned + WireMessage>(
    bytes: &[u8],
    limit: usize,
) -> Result<T, CodecError> {
    let limit = limit.min(MAX_MESSAGE_BYTES);
    if bytes.len() > limit {
        return Err(CodecError::TooLarge {
            what: T::NAME,
            len: bytes.len(),
            limit,
        });
    }
    // Every message starts with its `wire_version` field: check it before the layout it governs.
    let (version, _): (u32, usize) =
        bincode::serde::decode_from_slice(bytes, config()).map_err(|source| {
            CodecError::Decode {
                what: T::NAME,
                source,
            }
        })?;
    if version != WIRE_VERSION {
        return Err(CodecError::WrongVersion {
            what: T::NAME,
            got: version,
            expected: WIRE_VERSION,
        });
    }
    let (message, read): (T, usize) =
        bincode::serde::decode_from_slice(bytes, config()).map_err(|source| {
            CodecError::Decode {
                what: T::NAME,
                source,
            }
        })?;
    if read != bytes.len() {
        return Err(CodecError::TrailingBytes {
            what: T::NAME,
            len: bytes.len() - read,
        });
    }
    Ok(message)
}

/// Encode a JSON message (metrics, registry metadata).
pub fn encode_json<T: Serialize + WireMessage>(message: &T) -> Result<Vec<u8>, CodecError> {
    serde_json::to_vec(message).map_err(|source| CodecError::Json {
        what: T::NAME,
        source,
    })
}

/// Decode a JSON message, checking its `wire_version` first.
pub fn decode_json<T: DeserializeOwned + WireMessage>(bytes: &[u8]) -> Result<T, CodecError> {
    if bytes.len() > MAX_JSON_BYTES {
        return Err(CodecError::TooLarge {
            what: T::NAME,
            len: bytes.len(),
            limit: MAX_JSON_BYTES,
        });
    }
    #[derive(serde::Deserialize)]
    struct VersionOnly {
        wire_version: u32,
    }
    let head: VersionOnly = serde_json::from_slice(bytes).map_err(|source| CodecError::Json {
        what: T::NAME,
        source,
    })?;
    if head.wire_version != WIRE_VERSION {
        return Err(CodecError::WrongVersion {
            what: T::NAME,
            got: head.wire_version,
            expected: WIRE_VERSION,
        });
    }
    serde_json::from_slice(bytes).map_err(|source| CodecError::Json {
        what: T::NAME,
        source,
    })
}
