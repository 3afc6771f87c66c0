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
//! only by [`codec`]; this crate depends on no other project crate.

/// The string names of a fieldless enum, written once as `Variant => "name"` rows: `ALL` (every
/// variant in order), `as_str`, `from_name`, `names()` ("a, b or c", for error messages) and
/// `Display`. The enum keeps its own declaration (docs, derives); where it also derives serde, each
/// user tests that the serde names are these (see `registry`'s tests).
#[macro_export]
macro_rules! string_enum {
    ($ty:ident { $($variant:ident => $name:literal),+ $(,)? }) => {
        impl $ty {
            /// Every variant, in declaration order.
            pub const ALL: [$ty; [$($name),+].len()] = [$($ty::$variant),+];

            /// The variant's name (config, CLI and wire spelling).
            pub fn as_str(self) -> &'static str {
                match self {
                    $($ty::$variant => $name,)+
                }
            }

            /// The variant called `name`, if any.
            pub fn from_name(name: &str) -> Option<Self> {
                match name {
                    $($name => Some($ty::$variant),)+
                    _ => None,
                }
            }

            /// Every name, as "a, b or c".
            pub fn names() -> String {
                $crate::join_names(&[$($name),+])
            }
        }

        impl ::std::fmt::Display for $ty {
            fn fmt(&self, f: &mut ::std::fmt::Formatter<'_>) -> ::std::fmt::Result {
                f.pad(self.as_str())
            }
        }
    };
}

/// `["a", "b", "c"]` → `"a, b or c"` (for [`string_enum!`]'s `names`).
pub fn join_names(names: &[&str]) -> String {
    match names {
        [] => String::new(),
        [one] => (*one).to_string(),
        [init @ .., last] => format!("{} or {last}", init.join(", ")),
    }
}

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
