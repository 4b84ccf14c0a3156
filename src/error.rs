//! The error type that reaches the command line, with the exit-code contract:
//! 0 success, 1 a check did not hold, 2 bad input or usage.

use std::fmt;

/// What went wrong, and therefore which exit code the process returns.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Error {
    /// Bad input: unreadable or invalid files, bad arguments, impossible requests (exit 2).
    Input(String),
    /// A requested check (e.g. `replay --check`) did not hold (exit 1).
    CheckFailed(String),
}

impl Error {
    /// Builds an input error from anything printable.
    pub fn input(message: impl Into<String>) -> Self {
        Error::Input(message.into())
    }

    /// The process exit code for this error.
    pub fn exit_code(&self) -> u8 {
        match self {
            Error::Input(_) => 2,
            Error::CheckFailed(_) => 1,
        }
    }
}

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let message = match self {
            Error::Input(m) | Error::CheckFailed(m) => m,
        };
        // Always one line: messages may quote file contents.
        f.write_str(&crate::text::printable(message).replace('\n', " "))
    }
}

impl std::error::Error for Error {}

impl From<String> for Error {
    fn from(message: String) -> Self {
        Error::Input(message)
    }
}

/// Result with the command-line error type.
pub type Result<T> = std::result::Result<T, Error>;
