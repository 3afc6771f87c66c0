//! String names of fieldless enums, written once: the [`string_enum!`] macro and [`join_names`].
//!
//! A leaf crate (no dependencies) so that every crate with config, CLI or wire spellings — the wire
//! types of `l3p-proto`, the terrain types and reward terms of `l3p-task`, the leg ids of `l3p-robot`, the PPO modes of
//! `l3p-learner` — shares one implementation without depending on each other.

/// The string names of a fieldless enum, written once as `Variant => "name"` rows: `ALL` (every
/// variant in order), `as_str`, `from_name`, `names()` ("a, b or c", for error messages) and
/// `Display`. A name may be any `&'static str` constant expression (a literal, or `stringify!` in
/// another macro). The enum keeps its own declaration (docs, derives); where it also derives serde,
/// each user tests that the serde names are these.
#[macro_export]
macro_rules! string_enum {
    ($ty:ident { $($variant:ident => $name:expr),+ $(,)? }) => {
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
                Self::ALL.into_iter().find(|v| v.as_str() == name)
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

#[cfg(test)]
mod tests {
    use super::join_names;

    #[derive(Debug, Clone, Copy, PartialEq, Eq)]
    enum Gait {
        Trot,
        Pace,
        Bound,
    }

    crate::string_enum!(Gait {
        Trot => "trot",
        Pace => stringify!(pace),
        Bound => "bound",
    });

    #[test]
    fn names_round_trip_in_declaration_order() {
        assert_eq!(Gait::ALL, [Gait::Trot, Gait::Pace, Gait::Bound]);
        for g in Gait::ALL {
            assert_eq!(Gait::from_name(g.as_str()), Some(g));
        }
        assert_eq!(Gait::Pace.as_str(), "pace");
        assert_eq!(Gait::from_name("gallop"), None);
        assert_eq!(Gait::from_name("Trot"), None, "names are case-sensitive");
        assert_eq!(Gait::names(), "trot, pace or bound");
        assert_eq!(
            format!("[{:>6}]", Gait::Trot),
            "[  trot]",
            "Display honours padding"
        );
    }

    #[test]
    fn join_names_reads_as_a_list() {
        assert_eq!(join_names(&[]), "");
        assert_eq!(join_names(&["a"]), "a");
        assert_eq!(join_names(&["a", "b"]), "a or b");
        assert_eq!(join_names(&["a", "b", "c"]), "a, b or c");
    }
}
