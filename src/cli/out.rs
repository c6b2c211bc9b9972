//! What the subcommands print on standard output. They print through
//! [`outln!`] and [`out!`], which return the write's error where `println!`
//! panics; a reader that stopped reading (`bowloc query … | head`) ends
//! the command quietly and successfully ([`reader_gone`]), as it ends any
//! Unix tool. Only standard output's closed pipe does: a broken pipe
//! anywhere else (a socket `bowloc healthcheck` writes to) stays an error.

use std::fmt;
use std::io::Write;

/// `println!` that returns the write's error.
macro_rules! outln {
    ($($arg:tt)*) => {
        crate::cli::out::print(format_args!($($arg)*), true)
    };
}

/// `print!` that returns the write's error.
macro_rules! out {
    ($($arg:tt)*) => {
        crate::cli::out::print(format_args!($($arg)*), false)
    };
}

/// Standard output's reader has gone.
#[derive(Debug, thiserror::Error)]
#[error("standard output was closed")]
pub struct ReaderGone;

/// Write `args` (and a newline) on standard output; a closed pipe is
/// [`ReaderGone`].
pub fn print(args: fmt::Arguments, newline: bool) -> anyhow::Result<()> {
    let mut stdout = std::io::stdout().lock();
    let written = stdout.write_fmt(args).and_then(|()| {
        if newline {
            stdout.write_all(b"\n")
        } else {
            Ok(())
        }
    });
    match written {
        Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => Err(ReaderGone.into()),
        other => Ok(other?),
    }
}

/// Whether `e` is standard output's reader having closed the pipe.
pub fn reader_gone(e: &anyhow::Error) -> bool {
    e.chain().any(|cause| cause.is::<ReaderGone>())
}

#[cfg(test)]
mod tests {
    use super::{ReaderGone, reader_gone};

    #[test]
    fn only_standard_output_s_closed_pipe_is_the_reader_gone() {
        assert!(reader_gone(
            &anyhow::Error::new(ReaderGone).context("printing")
        ));
        // a socket's broken pipe (healthcheck) is a failure, not a reader gone
        let pipe = std::io::Error::from(std::io::ErrorKind::BrokenPipe);
        assert!(!reader_gone(&anyhow::Error::new(pipe)));
        assert!(!reader_gone(&anyhow::anyhow!("broken pipe")));
    }
}
