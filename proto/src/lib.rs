//! Wire types of l3p: every message the system sends, the key expressions it sends them on, and the one
//! codec that turns them into bytes.
//!
//! Main types: [`RolloutChunk`] (actor → learner), [`PolicyAnnounce`] and [`WeightsBlob`] (learner →
//! actors), [`MetricsRecord`] (anyone → subscribers, JSON), the registry messages in [`registry`],
//! [`RobotState`] and [`RobotCommand`] (robot ↔ deploy controller), [`OperatorCommand`] and
//! [`DeployStatus`] (operator ↔ deploy controller). Every message carries
//! [`WIRE_VERSION`]; [`codec`] checks it before decoding the rest.
//!
//! Architecture invariants: key expressions are built only by [`keys`]; bytes are produced and parsed
//! only by [`codec`]; this crate depends on no other project crate but the leaf `l3p-names` (enum spellings).

/// `impl WireMessage` for a message struct with a `wire_version` field (defined before the modules
/// that use it: `macro_rules!` scope is textual).
macro_rules! wire_message {
    ($ty:ty, $name:literal) => {
        impl WireMessage for $ty {
            const NAME: &'static str = $name;
            fn wire_version(&self) -> u32 {
                self.wire_version
            }
        }
    };
}

pub mod codec;
pub mod config;
pub mod keys;
mod messages;
pub mod registry;
mod validate;

pub use messages::*;

/// Lower-case hex SHA-256 of `bytes`: how blobs are named and checked everywhere (registry
/// artifacts, announced policy weights).
pub fn sha256_hex(bytes: &[u8]) -> String {
    use sha2::{Digest, Sha256};
    hex::encode(Sha256::digest(bytes))
}
pub use validate::ValidationError;

/// Version of the wire format. Bump it whenever a message's layout changes; a peer that sends another
/// version gets a clear error instead of garbage.
pub const WIRE_VERSION: u32 = 2;

/// A message type that travels on the wire: it carries the version it was written with.
pub trait WireMessage {
    /// Short name used in error messages (`rollout chunk`, `robot state`, ...).
    const NAME: &'static str;
    /// The `wire_version` field of this message.
    fn wire_version(&self) -> u32;
}
