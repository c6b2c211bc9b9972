//! The native libraries' messages as log events, for a JSON log. libpng,
//! libjpeg and OpenCV write their warnings about a damaged upload
//! (`libpng error: …`, `Corrupt JPEG data: …`, `[ WARN:0@…] …`) straight to
//! file descriptor 2, where they would sit between the service's JSON lines
//! and break a log collector's parsing. [`capture`] points descriptor 2 at a
//! pipe and logs each line read from it as a warning with target `native`;
//! the log itself writes to a copy of the original stderr
//! ([`Captured::log_writer`]). Dropping the
//! [`Captured`] guard points descriptor 2 back and logs what was left in the
//! pipe. A library that aborts the process right after writing may take its
//! last line with it; the exit status still tells.

use std::fs::File;
use std::io::{BufRead, BufReader, Error, PipeReader};
use std::os::fd::{AsFd, AsRawFd};
use std::sync::Arc;
use std::sync::mpsc::{Receiver, channel};
use std::time::Duration;
use tracing_subscriber::fmt::writer::BoxMakeWriter;

/// Descriptor 2 captured until this is dropped.
pub struct Captured {
    /// A copy of the original stderr: the log writes to it, and descriptor 2
    /// is pointed back at it.
    original: Arc<File>,
    /// Says when the reader has logged the pipe's last line.
    drained: Receiver<()>,
}

/// How long dropping a [`Captured`] waits for the reader to finish: a copy
/// of the pipe's write end left open elsewhere must not hold the process.
const DRAIN_WAIT: Duration = Duration::from_secs(1);

/// Capture descriptor 2 until the guard is dropped.
pub fn capture() -> Result<Captured, Error> {
    let original = Arc::new(File::from(std::io::stderr().as_fd().try_clone_to_owned()?));
    let (read, write) = std::io::pipe()?;
    // SAFETY: both descriptors are open; descriptor 2 now writes to the pipe.
    if unsafe { libc::dup2(write.as_raw_fd(), 2) } < 0 {
        return Err(Error::last_os_error());
    }
    drop(write);
    let (done, drained) = channel();
    let reader = std::thread::Builder::new()
        .name("native-stderr".into())
        .spawn(move || {
            log_lines(read);
            let _ = done.send(());
        });
    if let Err(e) = reader {
        restore(&original);
        return Err(e);
    }
    Ok(Captured { original, drained })
}

impl Captured {
    /// Where the log writes: the original stderr.
    pub fn log_writer(&self) -> BoxMakeWriter {
        BoxMakeWriter::new(self.original.clone())
    }
}

/// Log every line written to the pipe until its last writer closes it.
fn log_lines(pipe: PipeReader) {
    for line in BufReader::new(pipe).split(b'\n') {
        let Ok(line) = line else { break };
        let text = String::from_utf8_lossy(&line);
        let text = text.trim_end();
        if !text.is_empty() {
            tracing::warn!(target: "native", "{text}");
        }
    }
}

/// Point descriptor 2 back at `original`; whether it worked.
fn restore(original: &File) -> bool {
    // SAFETY: both descriptors are open.
    unsafe { libc::dup2(original.as_raw_fd(), 2) >= 0 }
}

impl Drop for Captured {
    fn drop(&mut self) {
        // Once descriptor 2 no longer writes to the pipe, the reader reads
        // what is left and stops at its end.
        if restore(&self.original) {
            let _ = self.drained.recv_timeout(DRAIN_WAIT);
        }
    }
}
