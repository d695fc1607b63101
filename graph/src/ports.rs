//! Port types. A type is a name ("HeightField", "Image", "Scalar"); the graph language compares
//! names only, so it needs to know nothing of what the values are.

use serde::{Serialize, Serializer};
use std::fmt;

/// The types an input port accepts.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum TypeSet {
    /// Exactly one type.
    One(String),
    /// Any of several types (for example every array-like type, for `npy.write`).
    AnyOf(Vec<String>),
}

impl TypeSet {
    pub fn one(name: &str) -> Self {
        TypeSet::One(name.to_string())
    }

    pub fn any_of<'a>(names: impl IntoIterator<Item = &'a str>) -> Self {
        TypeSet::AnyOf(names.into_iter().map(str::to_string).collect())
    }

    pub fn accepts(&self, ty: &str) -> bool {
        match self {
            TypeSet::One(t) => t == ty,
            TypeSet::AnyOf(ts) => ts.iter().any(|t| t == ty),
        }
    }
}

impl fmt::Display for TypeSet {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            TypeSet::One(t) => f.write_str(t),
            TypeSet::AnyOf(ts) => write!(f, "one of {}", ts.join(", ")),
        }
    }
}

/// Serialized as one string, alternatives joined by `|` ("HeightField|Image"), so scripts read a
/// port's type the same way whether it accepts one type or several.
impl Serialize for TypeSet {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        match self {
            TypeSet::One(t) => s.serialize_str(t),
            TypeSet::AnyOf(ts) => s.serialize_str(&ts.join("|")),
        }
    }
}
