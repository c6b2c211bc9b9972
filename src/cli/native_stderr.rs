//! The native libraries' messages as log events, for a JSON log. libpng,
//! libjpeg and OpenCV write their warnings about a damaged upload
//! (`libpng error: …`, `Corrupt JPEG data: …`, `[ WARN:0@…] …`) straight to
//! file descriptor 2, where they would sit between the service's JSON lines
//! and break a log collector's parsing. [`capture`] points descriptor 2 at a
//! pipe and logs each line read from it as a warning with target `native`;
//! the log itself writes to a copy of the original stderr. Dropping the
//! [`Captured`] guard points descriptor 2 back and logs what was left in the
//! pipe. A library that aborts the process right after writing may take its
//! last line with it; the exit status still tells.

use std::fs::File;
use std::io::{BufRead, BufReader, Error};
use std::os::fd::{AsRawFd, FromRawFd, OwnedFd};
use std::sync::mpsc::{Receiver, channel};
use std::time::Duration;

/// Descriptor 2 captured until this is dropped.
pub struct Captured {
    original: OwnedFd,
    /// Says when the reader has logged the pipe's last line.
    drained: Receiver<()>,
}

/// How long dropping a [`Captured`] waits for the reader to finish: a copy
/// of the pipe's write end left open elsewhere must not hold the process.
const DRAIN_WAIT: Duration = Duration::from_secs(1);

/// Capture descriptor 2. Returns the guard and the original stderr, for the
/// log to write to.
pub fn capture() -> Result<(Captured, File), Error> {
    let original = duplicate(2)?;
    let log = File::from(original.try_clone()?);
    let mut ends = [0; 2];
    // SAFETY: `ends` has room for the two descriptors pipe2 writes.
    if unsafe { libc::pipe2(ends.as_mut_ptr(), libc::O_CLOEXEC) } != 0 {
        return Err(Error::last_os_error());
    }
    // SAFETY: pipe2 succeeded, so both are open descriptors owned by no one else.
    let (read, write) = unsafe { (OwnedFd::from_raw_fd(ends[0]), OwnedFd::from_raw_fd(ends[1])) };
    // SAFETY: both descriptors are open; descriptor 2 now writes to the pipe.
    if unsafe { libc::dup2(write.as_raw_fd(), 2) } < 0 {
        return Err(Error::last_os_error());
    }
    drop(write);
    let (done, drained) = channel();
    let reader = std::thread::Builder::new()
        .name("native-stderr".into())
        .spawn(move || {
            log_lines(File::from(read));
            let _ = done.send(());
        });
    match reader {
        Ok(_) => Ok((Captured { original, drained }, log)),
        Err(e) => {
            restore(&original);
            Err(e)
        }
    }
}

/// Log every line written to the pipe until its last writer closes it.
fn log_lines(pipe: File) {
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
fn restore(original: &OwnedFd) -> bool {
    // SAFETY: both descriptors are open.
    unsafe { libc::dup2(original.as_raw_fd(), 2) >= 0 }
}

fn duplicate(fd: i32) -> Result<OwnedFd, Error> {
    // SAFETY: fcntl with F_DUPFD_CLOEXEC only creates a new descriptor.
    let copy = unsafe { libc::fcntl(fd, libc::F_DUPFD_CLOEXEC, 3) };
    if copy < 0 {
        return Err(Error::last_os_error());
    }
    // SAFETY: fcntl succeeded, so `copy` is an open descriptor owned by no one else.
    Ok(unsafe { OwnedFd::from_raw_fd(copy) })
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
