//! The error type that reaches the command line, with the exit-code contract:
//! 0 success, 1 a check did not hold, 2 bad input or usage, 3 the graphics
//! device or the terminal failed (nothing the user typed was wrong), 4 a file
//! could not be written (a full disk, permissions, a missing folder: the input
//! was fine). Every message prints as one line.

/// What went wrong, and therefore which exit code the process returns.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum Error {
    /// Bad input: unreadable or invalid files, bad arguments, impossible requests (exit 2).
    #[error("{}", one_line(.0))]
    Input(String),
    /// A requested check (e.g. `replay --check`) did not hold (exit 1).
    #[error("{}", one_line(.0))]
    CheckFailed(String),
    /// The graphics device is missing or failed (exit 3).
    #[error("{}", one_line(.0))]
    Device(String),
    /// The terminal cannot be used or went away (exit 3).
    #[error("{}", one_line(.0))]
    Terminal(String),
    /// Writing a file or folder failed (exit 4): the system refused what
    /// valid input asked for.
    #[error("{}", one_line(.0))]
    Io(String),
    /// A signal stopped a long job after it saved its work (exit 128 + the
    /// signal, as shells report it: 130 for SIGINT, 143 for SIGTERM, 129 for
    /// SIGHUP).
    #[error("{}", one_line(.message))]
    Interrupted {
        /// The signal's number.
        signal: i32,
        /// What was saved and how to go on.
        message: String,
    },
}

/// Exit code of [`Error::Device`] and [`Error::Terminal`].
pub const EXIT_ENVIRONMENT: u8 = 3;
/// Exit code of [`Error::Io`].
pub const EXIT_IO: u8 = 4;

impl Error {
    /// Builds an input error from anything printable.
    pub fn input(message: impl Into<String>) -> Self {
        Error::Input(message.into())
    }

    /// Builds a device error.
    pub fn device(message: impl Into<String>) -> Self {
        Error::Device(message.into())
    }

    /// Builds a terminal error.
    pub fn terminal(message: impl Into<String>) -> Self {
        Error::Terminal(message.into())
    }

    /// A failed write: "cannot ACTION PATH: what the system said".
    pub fn io(action: &str, path: &std::path::Path, reason: impl std::fmt::Display) -> Self {
        Error::Io(format!("cannot {action} {}: {reason}", path.display()))
    }

    /// The process exit code for this error.
    pub fn exit_code(&self) -> u8 {
        match self {
            Error::Input(_) => 2,
            Error::CheckFailed(_) => 1,
            Error::Device(_) | Error::Terminal(_) => EXIT_ENVIRONMENT,
            Error::Io(_) => EXIT_IO,
            Error::Interrupted { signal, .. } => (128 + signal).clamp(129, 255) as u8,
        }
    }
}

/// Messages may quote file contents: control characters go, lines join.
fn one_line(message: &str) -> String {
    crate::text::printable(message).replace('\n', " ")
}

/// Result with the command-line error type.
pub type Result<T> = std::result::Result<T, Error>;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exit_codes_and_one_line_messages() {
        assert_eq!(Error::input("x").exit_code(), 2);
        assert_eq!(Error::CheckFailed("x".into()).exit_code(), 1);
        assert_eq!(Error::device("x").exit_code(), 3);
        assert_eq!(Error::terminal("x").exit_code(), 3);
        let full = Error::io(
            "write",
            std::path::Path::new("/out/a.png"),
            "No space left on device",
        );
        assert_eq!(full.exit_code(), 4);
        assert_eq!(
            full.to_string(),
            "cannot write /out/a.png: No space left on device"
        );
        let stopped = |signal| Error::Interrupted {
            signal,
            message: "saved".into(),
        };
        assert_eq!(stopped(libc::SIGINT).exit_code(), 130);
        assert_eq!(stopped(libc::SIGTERM).exit_code(), 143);
        assert_eq!(stopped(libc::SIGHUP).exit_code(), 129);
        assert_eq!(
            Error::input("two\nlines\u{1b}[2J").to_string(),
            "two lines[2J"
        );
    }
}
