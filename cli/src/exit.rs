//! Exit codes and errors, the same for every subcommand.

use std::fmt;
use std::process::{ExitCode, Termination};

/// How the program ends; the numbers are documented in every `--help`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Status {
    Success = 0,
    /// Bad input or a failed run.
    Failure = 1,
    /// What clap exits with for a command line it cannot parse; ours for one
    /// that parses but makes no sense (a `.avi` output, a folder and a file mixed).
    Usage = 2,
    /// 128 + SIGINT, as shells report a program stopped by Ctrl-C.
    Interrupted = 130,
}

impl Termination for Status {
    fn report(self) -> ExitCode {
        ExitCode::from(self as u8)
    }
}

/// The exit codes, for the end of `--help`; a macro so that help texts can `concat!` it.
macro_rules! codes_help {
    () => {
        "Exit status:
  0    success
  1    failure: bad input or a failed run (the message says what is wrong and what to do)
  2    usage error
  130  interrupted by Ctrl-C (or SIGTERM, SIGHUP): the first stops cleanly and keeps
       what was done so far; a second aborts and keeps nothing"
    };
}
pub(crate) use codes_help;

/// What went wrong, worded for the person at the terminal: what is wrong and
/// what to do about it.
#[derive(Debug, Clone)]
pub struct Failure {
    message: String,
    status: Status,
}

impl Failure {
    /// Bad input or a failed run.
    pub fn new(message: impl Into<String>) -> Failure {
        Failure {
            message: message.into(),
            status: Status::Failure,
        }
    }

    /// A command line that parsed but makes no sense.
    pub fn usage(message: impl Into<String>) -> Failure {
        Failure {
            message: message.into(),
            status: Status::Usage,
        }
    }

    /// Prints it as clap prints its own errors; returns the status to exit with.
    pub fn report(&self) -> Status {
        eprintln!("error: {}", self.message);
        if self.status == Status::Usage {
            eprintln!("\nFor more information, try '--help'.");
        }
        self.status
    }
}

impl fmt::Display for Failure {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.message)
    }
}
