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
//!
//! Each line is tied to the requests that caused it. A worker running a
//! request's job holds a [`Section`], which writes a marker line into the
//! same pipe when it opens and another when it closes (a write of under
//! `PIPE_BUF` bytes is never interleaved with another), so the reader knows
//! which requests' jobs were running when a library wrote its line: the
//! event carries `request_id` when one was, `request_ids` (comma-separated)
//! when several were.

use std::collections::BTreeMap;
use std::fs::File;
use std::io::{BufRead, BufReader, Error, PipeReader};
use std::os::fd::{AsFd, AsRawFd};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc::{Receiver, channel};
use std::time::Duration;
use tracing_subscriber::fmt::writer::BoxMakeWriter;

/// Whether descriptor 2 is captured now, so sections write their markers.
static CAPTURING: AtomicBool = AtomicBool::new(false);
/// The next section's number.
static NEXT_SECTION: AtomicU64 = AtomicU64::new(0);
/// Starts a marker line (ASCII record separator); no library's message does.
const MARK: char = '\u{1e}';
/// The longest request id a marker carries.
const MAX_ID: usize = 200;

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
    CAPTURING.store(true, Ordering::SeqCst);
    let (done, drained) = channel();
    let reader = std::thread::Builder::new()
        .name("native-stderr".into())
        .spawn(move || {
            log_lines(read);
            let _ = done.send(());
        });
    if let Err(e) = reader {
        CAPTURING.store(false, Ordering::SeqCst);
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

/// A request's job running on this thread, for the lines the native
/// libraries write meanwhile; see the module's comment. Does nothing while
/// descriptor 2 is not captured.
pub struct Section {
    number: Option<u64>,
}

/// Open a section for the request `request_id` (its printable ASCII
/// characters, cut to a bounded length).
pub fn section(request_id: &str) -> Section {
    if !CAPTURING.load(Ordering::SeqCst) {
        return Section { number: None };
    }
    let number = NEXT_SECTION.fetch_add(1, Ordering::Relaxed);
    let id: String = request_id
        .chars()
        .filter(char::is_ascii_graphic)
        .take(MAX_ID)
        .collect();
    write_line(&format!("\n{MARK}+{number} {id}\n"));
    Section {
        number: Some(number),
    }
}

impl Drop for Section {
    fn drop(&mut self) {
        if let Some(number) = self.number {
            write_line(&format!("\n{MARK}-{number}\n"));
        }
    }
}

/// Write `line` to descriptor 2 in one call (a marker is far under
/// `PIPE_BUF`, so no other write splits it). A marker starts with a newline
/// of its own, so that it starts a line even after a library's message that
/// did not end one (the empty line this may leave is not logged).
fn write_line(line: &str) {
    // SAFETY: the buffer is valid for its length; descriptor 2 is open.
    unsafe { libc::write(2, line.as_ptr().cast(), line.len()) };
}

/// What the reader makes of one line read from the pipe.
#[derive(Debug, PartialEq, Eq)]
enum Read<'a> {
    /// A marker or an empty line: nothing to log.
    Nothing,
    /// A library's line, and the requests whose jobs were running.
    Message {
        text: &'a str,
        requests: Vec<String>,
    },
}

/// The sections open at the point the reader has reached in the pipe.
#[derive(Default)]
struct Sections {
    open: BTreeMap<u64, String>,
}

impl Sections {
    fn read<'a>(&mut self, line: &'a str) -> Read<'a> {
        let text = line.trim_end();
        if let Some(marker) = text.strip_prefix(MARK) {
            if let Some(opened) = marker.strip_prefix('+') {
                let (number, id) = opened.split_once(' ').unwrap_or((opened, ""));
                if let Ok(number) = number.parse() {
                    self.open.insert(number, id.to_owned());
                }
            } else if let Some(Ok(number)) = marker.strip_prefix('-').map(str::parse::<u64>) {
                self.open.remove(&number);
            }
            return Read::Nothing;
        }
        if text.is_empty() {
            return Read::Nothing;
        }
        Read::Message {
            text,
            requests: self.open.values().cloned().collect(),
        }
    }
}

/// Log every line written to the pipe until its last writer closes it.
fn log_lines(pipe: PipeReader) {
    let mut sections = Sections::default();
    for line in BufReader::new(pipe).split(b'\n') {
        let Ok(line) = line else { break };
        let line = String::from_utf8_lossy(&line);
        let Read::Message { text, requests } = sections.read(&line) else {
            continue;
        };
        match requests.as_slice() {
            [] => tracing::warn!(target: "native", "{text}"),
            [one] => tracing::warn!(target: "native", request_id = %one, "{text}"),
            many => tracing::warn!(target: "native", request_ids = %many.join(","), "{text}"),
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
        CAPTURING.store(false, Ordering::SeqCst);
        if restore(&self.original) {
            let _ = self.drained.recv_timeout(DRAIN_WAIT);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn message<'a>(text: &'a str, requests: &[&str]) -> Read<'a> {
        Read::Message {
            text,
            requests: requests.iter().map(|r| r.to_string()).collect(),
        }
    }

    #[test]
    fn lines_carry_the_requests_running_when_they_were_written() {
        let mut s = Sections::default();
        assert_eq!(
            s.read("before any request\n"),
            message("before any request", &[])
        );
        assert_eq!(s.read("\u{1e}+7 abc-1\n"), Read::Nothing);
        assert_eq!(
            s.read("libpng error: cut\n"),
            message("libpng error: cut", &["abc-1"])
        );
        assert_eq!(s.read("\u{1e}+8 def-2"), Read::Nothing);
        assert_eq!(
            s.read("Corrupt JPEG data"),
            message("Corrupt JPEG data", &["abc-1", "def-2"])
        );
        assert_eq!(s.read("\u{1e}-7"), Read::Nothing);
        assert_eq!(s.read("after"), message("after", &["def-2"]));
        assert_eq!(s.read("\u{1e}-8"), Read::Nothing);
        assert_eq!(s.read("   "), Read::Nothing);
        assert_eq!(s.read("last"), message("last", &[]));
    }

    #[test]
    fn a_marker_after_an_unfinished_line_is_still_read_as_one() {
        let mut s = Sections::default();
        let pipe = "\n\u{1e}+1 abc\nlibpng error: no newline\n\u{1e}-1\nlater\n";
        let read: Vec<Read> = pipe.split('\n').map(|line| s.read(line)).collect();
        assert_eq!(
            read,
            [
                Read::Nothing,
                Read::Nothing,
                message("libpng error: no newline", &["abc"]),
                Read::Nothing,
                message("later", &[]),
                Read::Nothing,
            ]
        );
    }

    #[test]
    fn a_marker_with_no_id_or_a_bad_number_changes_nothing_else() {
        let mut s = Sections::default();
        assert_eq!(s.read("\u{1e}+3"), Read::Nothing);
        assert_eq!(s.read("\u{1e}+x y"), Read::Nothing);
        assert_eq!(s.read("\u{1e}-y"), Read::Nothing);
        assert_eq!(s.open.len(), 1);
        assert_eq!(s.read("\u{1e}-3"), Read::Nothing);
        assert!(s.open.is_empty());
    }

    #[test]
    fn a_section_writes_nothing_while_stderr_is_not_captured() {
        assert!(section("any").number.is_none());
    }
}
