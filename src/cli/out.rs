//! What the subcommands print on standard output. They print through
//! [`outln!`] and [`out!`], which return the write's error where `println!`
//! panics; a reader that stopped reading (`bowloc query … | head`) ends
//! the command quietly and successfully ([`reader_gone`]), as it ends any
//! Unix tool.

/// `println!` that returns the write's error.
macro_rules! outln {
    ($($arg:tt)*) => {{
        use std::io::Write as _;
        writeln!(std::io::stdout().lock(), $($arg)*)
    }};
}

/// `print!` that returns the write's error.
macro_rules! out {
    ($($arg:tt)*) => {{
        use std::io::Write as _;
        write!(std::io::stdout().lock(), $($arg)*)
    }};
}

/// Whether `e` is standard output's reader having closed the pipe.
pub fn reader_gone(e: &anyhow::Error) -> bool {
    e.chain().any(|cause| {
        cause
            .downcast_ref::<std::io::Error>()
            .is_some_and(|io| io.kind() == std::io::ErrorKind::BrokenPipe)
    })
}

#[cfg(test)]
mod tests {
    use super::reader_gone;

    #[test]
    fn a_closed_pipe_is_told_apart_from_other_errors() {
        let pipe = std::io::Error::from(std::io::ErrorKind::BrokenPipe);
        assert!(reader_gone(&anyhow::Error::new(pipe).context("printing")));
        let other = std::io::Error::from(std::io::ErrorKind::NotFound);
        assert!(!reader_gone(&anyhow::Error::new(other)));
        assert!(!reader_gone(&anyhow::anyhow!("broken pipe")));
    }
}
