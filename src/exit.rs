//! Exit codes, and the error type that carries one through `anyhow`.

use std::fmt;

pub const OK: i32 = 0;
pub const FAILED: i32 = 1;
pub const INVALID: i32 = 2;
pub const CANCELLED: i32 = 130;

/// An error that ends the process with a specific code.
#[derive(Debug)]
pub struct Exit {
    pub code: i32,
    pub message: String,
}

impl fmt::Display for Exit {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.message)
    }
}

impl std::error::Error for Exit {}

/// An invalid graph or argument: exit code 2.
pub fn invalid(message: impl Into<String>) -> anyhow::Error {
    Exit {
        code: INVALID,
        message: message.into(),
    }
    .into()
}

pub fn code_of(e: &anyhow::Error) -> i32 {
    e.downcast_ref::<Exit>().map_or(FAILED, |x| x.code)
}
