//! The on-disk container shared by every file bowloc writes (vocabulary, map,
//! descriptor cache): a small self-describing header, a table of typed,
//! 64-byte-aligned sections, a checksum per section, memory-mapped on open.
//!
//! Layout (all integers little-endian):
//!
//! ```text
//! 0   magic            [u8; 8]   which kind of file ("BOWLOCVO", "BOWLOCMA", ...)
//! 8   format version   u32
//! 12  section count    u32
//! 16  table checksum   u64       xxh3 of the section table
//! 24  section table    count × 64 bytes: name [u8; 32], dtype u32, reserved u32,
//!                      offset u64, length u64, xxh3 checksum u64
//! ..  sections         each starts on a 64-byte boundary
//! ```
//!
//! Opening a file maps it, checks magic, version, table checksum and that every
//! section lies inside the file; section checksums are verified on open unless
//! the caller opts out. Nothing is parsed or copied: typed sections are slices
//! into the mapping. Writing goes through a temporary file that is renamed into
//! place ([`write_atomic`]), so a crash leaves either the old file or the new
//! one.

mod atomic;
mod reader;
mod writer;

pub use atomic::write_atomic;
pub use reader::{Section, Store};
pub use writer::StoreWriter;

use std::path::PathBuf;

/// Bytes before the section table.
const HEADER_LEN: usize = 24;
/// Bytes per section-table entry.
const ENTRY_LEN: usize = 64;
/// Bytes of a section name.
const NAME_LEN: usize = 32;
/// Alignment of every section's first byte.
const ALIGN: usize = 64;

/// Element type of a section, recorded so a reader can refuse a mismatch.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u32)]
pub enum Dtype {
    Bytes = 0,
    F32 = 1,
    U32 = 2,
    U64 = 3,
    F64 = 4,
}

impl Dtype {
    fn from_u32(v: u32) -> Option<Self> {
        Some(match v {
            0 => Self::Bytes,
            1 => Self::F32,
            2 => Self::U32,
            3 => Self::U64,
            4 => Self::F64,
            _ => return None,
        })
    }

    fn size(self) -> usize {
        match self {
            Self::Bytes => 1,
            Self::F32 | Self::U32 => 4,
            Self::U64 | Self::F64 => 8,
        }
    }
}

/// Everything that can be wrong with a bowloc file. Every variant names the file.
#[derive(Debug, thiserror::Error)]
pub enum StoreError {
    /// (The I/O error is in the message, not a source: a chain printed
    /// with its sources would say it twice.)
    #[error("{path}: {cause}")]
    Io {
        path: PathBuf,
        cause: std::io::Error,
    },
    #[error("{path}: not a bowloc {expected} file (magic bytes {found:?})")]
    WrongMagic {
        path: PathBuf,
        expected: &'static str,
        found: String,
    },
    #[error(
        "{path}: format version {found}, this build reads version {expected}; rebuild the file"
    )]
    WrongVersion {
        path: PathBuf,
        found: u32,
        expected: u32,
    },
    #[error("{path}: file is truncated or damaged ({detail})")]
    Corrupt { path: PathBuf, detail: String },
    #[error("{path}: checksum mismatch in section '{section}': the file is damaged")]
    Checksum { path: PathBuf, section: String },
    #[error("{path}: missing section '{section}'")]
    MissingSection { path: PathBuf, section: String },
    #[error("{path}: {detail}")]
    Invalid { path: PathBuf, detail: String },
}

impl StoreError {
    pub(crate) fn io(path: &std::path::Path, cause: std::io::Error) -> Self {
        Self::Io {
            path: path.to_path_buf(),
            cause,
        }
    }
}

/// xxh3-64 checksum used throughout the format.
pub fn checksum(bytes: &[u8]) -> u64 {
    xxhash_rust::xxh3::xxh3_64(bytes)
}

#[cfg(test)]
mod tests;
