//! Enums whose values are words on the command line, in configs and in messages: each value has one
//! name (and maybe aliases), written once in [`named_enum!`], from which come `Display`, `FromStr`,
//! serde's string form, clap's `ValueEnum` and the list of names that help texts and errors show.

use thiserror::Error;

/// Text that names no value of a domain type, or names a value twice where a set is given.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum ParseError {
    /// A word that is none of the type's names; the message lists them.
    #[error("unknown {what} `{given}`: use {expected}")]
    Unknown {
        /// What was being parsed (`task`, `model`, …).
        what: &'static str,
        /// The word given (cut to 64 characters).
        given: String,
        /// The accepted names, comma-separated.
        expected: String,
    },
    /// A name given twice in a comma-separated set.
    #[error("{what} `{name}` is named twice")]
    Repeated {
        /// What was being parsed.
        what: &'static str,
        /// The repeated name.
        name: String,
    },
}

impl ParseError {
    /// An [`ParseError::Unknown`] for `given`, cut to a bounded length so that a huge input does not
    /// make a huge message.
    pub fn unknown(what: &'static str, given: &str, expected: String) -> Self {
        const MAX: usize = 64;
        let given = match given.char_indices().nth(MAX) {
            Some((cut, _)) => format!("{}…", &given[..cut]),
            None => given.to_string(),
        };
        ParseError::Unknown { what, given, expected }
    }
}

/// Defines a fieldless enum whose values are named words:
///
/// ```
/// equiarm_types::named_enum! {
///     /// A colour.
///     pub enum Colour: "colour" {
///         /// Red.
///         Red = "red" | "r",
///         /// Blue.
///         Blue = "blue",
///     }
/// }
/// assert_eq!("r".parse::<Colour>().unwrap(), Colour::Red);
/// assert_eq!(Colour::Blue.to_string(), "blue");
/// assert_eq!(Colour::names(), "red, blue");
/// ```
///
/// The enum gets `ALL` (every value in declaration order), `name()`, `names()` (for help and error
/// texts), `Display`, `FromStr` (the name or an alias; an unknown word is a [`ParseError`] listing the
/// names), serde's string form (serialised as its name, read through `FromStr`) and clap's
/// `ValueEnum` (same names and aliases).
#[macro_export]
macro_rules! named_enum {
    (
        $(#[$meta:meta])*
        $vis:vis enum $name:ident : $what:literal {
            $( $(#[$vmeta:meta])* $variant:ident = $text:literal $(| $alias:literal)* ),+ $(,)?
        }
    ) => {
        $(#[$meta])*
        #[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, ::clap::ValueEnum)]
        $vis enum $name {
            $( $(#[$vmeta])* #[value(name = $text $(, alias = $alias)*)] $variant ),+
        }

        impl $name {
            /// How many values there are.
            pub const COUNT: usize = [$($text),+].len();
            /// Every value, in declaration order.
            pub const ALL: [$name; $name::COUNT] = [$($name::$variant),+];
            /// What a value of this type is called in messages.
            pub const WHAT: &'static str = $what;

            /// The value's name on the command line, in configs and in messages.
            pub fn name(self) -> &'static str {
                match self { $( $name::$variant => $text ),+ }
            }

            /// Every name, comma-separated (for help and error texts).
            pub fn names() -> String {
                [$($text),+].join(", ")
            }

            /// The value a name or alias stands for, or `None`.
            pub fn from_name(word: &str) -> Option<Self> {
                match word {
                    $( $text $(| $alias)* => Some($name::$variant), )+
                    _ => None,
                }
            }
        }

        impl ::std::fmt::Display for $name {
            fn fmt(&self, f: &mut ::std::fmt::Formatter<'_>) -> ::std::fmt::Result {
                f.write_str(self.name())
            }
        }

        impl ::std::str::FromStr for $name {
            type Err = $crate::ParseError;
            fn from_str(word: &str) -> ::std::result::Result<Self, Self::Err> {
                Self::from_name(word.trim())
                    .ok_or_else(|| $crate::ParseError::unknown($what, word, Self::names()))
            }
        }

        impl ::serde::Serialize for $name {
            fn serialize<S: ::serde::Serializer>(&self, s: S) -> ::std::result::Result<S::Ok, S::Error> {
                s.serialize_str(self.name())
            }
        }

        impl<'de> ::serde::Deserialize<'de> for $name {
            fn deserialize<D: ::serde::Deserializer<'de>>(d: D) -> ::std::result::Result<Self, D::Error> {
                let word = <::std::borrow::Cow<'de, str> as ::serde::Deserialize>::deserialize(d)?;
                word.parse().map_err(::serde::de::Error::custom)
            }
        }
    };
}
