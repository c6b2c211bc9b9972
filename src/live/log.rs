//! The change log beside a map file (`MAP.changes`): every acknowledged add
//! and removal, appended and fsynced before it is acknowledged, replayed at
//! start-up, emptied by a compaction.
//!
//! Layout (integers little-endian):
//!
//! ```text
//! header   magic "BOWLOCLG" [u8; 8] | version u32 | reserved u32 | map fingerprint u64
//! record   payload length u32 | crc32 of the payload u32 | payload
//! payload  kind u8 (1 add, 2 remove) | generation u64 | name (u16 length + UTF-8)
//!          add only: added at, ms since the epoch u64 | place (u16 length + UTF-8)
//!                    | pose values u16 + f64 each | features u32 + 12 bytes each
//! ```
//!
//! The fingerprint names the map file the records apply to. A reader stops at
//! the first record that is cut short, fails its checksum or does not decode:
//! that is a torn or corrupt tail, reported so the caller can warn and cut it.

use crate::geometry::packed::{PACKED_BYTES, PackedFeature};
use std::fs::File;
use std::io::Write;
use std::path::{Path, PathBuf};

const MAGIC: [u8; 8] = *b"BOWLOCLG";
/// 2: each feature carries its Hamming signature (20 bytes).
const VERSION: u32 = 2;
/// Bytes of the header.
pub const HEADER_LEN: usize = 24;
/// Largest payload a record may have.
pub const MAX_PAYLOAD: usize = 64 << 20;
/// Longest name or place label, in bytes.
pub const MAX_TEXT: usize = u16::MAX as usize;

/// One image added to the map.
#[derive(Debug, Clone, PartialEq)]
pub struct NewImage {
    pub name: String,
    /// "" when unknown.
    pub place: String,
    /// One value per pose field of the map (NaN when unknown), or none.
    pub pose: Vec<f64>,
    /// Its features (word and keypoint), sorted by word.
    pub features: Vec<PackedFeature>,
    /// When it was added, in milliseconds since the Unix epoch.
    pub added_at_ms: u64,
}

/// One change to the map.
#[derive(Debug, Clone, PartialEq)]
pub enum Change {
    /// Add an image, replacing any image of the same name.
    Add(NewImage),
    /// Remove the image of this name.
    Remove { name: String },
}

impl Change {
    pub fn name(&self) -> &str {
        match self {
            Change::Add(i) => &i.name,
            Change::Remove { name } => name,
        }
    }
}

/// A change and the map generation it makes.
#[derive(Debug, Clone, PartialEq)]
pub struct Record {
    pub generation: u64,
    pub change: Change,
}

/// What a log holds.
#[derive(Debug, Clone, PartialEq)]
pub struct Parsed {
    pub fingerprint: u64,
    pub records: Vec<Record>,
    /// Bytes up to the end of the last whole record.
    pub valid_len: usize,
    /// Why the bytes after `valid_len` were not read, if there are any.
    pub dropped: Option<String>,
}

/// A log that cannot be read at all.
#[derive(Debug, thiserror::Error)]
pub enum LogError {
    /// (The I/O error is in the message only, as in [`crate::store::StoreError::Io`].)
    #[error("{path}: {cause}")]
    Io {
        path: PathBuf,
        cause: std::io::Error,
    },
    #[error("{0}")]
    Invalid(String),
}

fn io(path: &Path) -> impl Fn(std::io::Error) -> LogError + '_ {
    move |cause| LogError::Io {
        path: path.to_path_buf(),
        cause,
    }
}

/// The header of a log for the map of `fingerprint`.
pub fn header(fingerprint: u64) -> [u8; HEADER_LEN] {
    let mut h = [0u8; HEADER_LEN];
    h[..8].copy_from_slice(&MAGIC);
    h[8..12].copy_from_slice(&VERSION.to_le_bytes());
    h[16..24].copy_from_slice(&fingerprint.to_le_bytes());
    h
}

/// Read a whole log. Only a bad header is an error; a bad record ends the
/// records read and is reported in `dropped`.
pub fn parse(bytes: &[u8]) -> Result<Parsed, LogError> {
    if bytes.len() < HEADER_LEN || bytes[..8] != MAGIC {
        return Err(LogError::Invalid(
            "not a bowloc change log (no BOWLOCLG header)".into(),
        ));
    }
    let version = u32::from_le_bytes(bytes[8..12].try_into().expect("4 bytes"));
    if version != VERSION {
        return Err(LogError::Invalid(format!(
            "change log version {version}, this build reads version {VERSION}"
        )));
    }
    let fingerprint = u64::from_le_bytes(bytes[16..24].try_into().expect("8 bytes"));
    let mut records = Vec::new();
    let mut at = HEADER_LEN;
    let mut dropped = None;
    while at < bytes.len() {
        match record_at(&bytes[at..]) {
            Ok((record, len)) => {
                records.push(record);
                at += len;
            }
            Err(why) => {
                dropped = Some(format!(
                    "{} bytes after record {} dropped: {why}",
                    bytes.len() - at,
                    records.len()
                ));
                break;
            }
        }
    }
    Ok(Parsed {
        fingerprint,
        records,
        valid_len: at,
        dropped,
    })
}

/// The record at the start of `bytes` and its length in bytes.
fn record_at(bytes: &[u8]) -> Result<(Record, usize), String> {
    if bytes.len() < 8 {
        return Err("a record header cut short".into());
    }
    let len = u32::from_le_bytes(bytes[..4].try_into().expect("4 bytes")) as usize;
    let crc = u32::from_le_bytes(bytes[4..8].try_into().expect("4 bytes"));
    if len > MAX_PAYLOAD {
        return Err(format!("a record of {len} bytes, over the limit"));
    }
    let Some(payload) = bytes.get(8..8 + len) else {
        return Err("a record cut short".into());
    };
    if crc32fast::hash(payload) != crc {
        return Err("a record fails its checksum".into());
    }
    let record = decode(payload).ok_or("a record that does not decode")?;
    Ok((record, 8 + len))
}

/// Reads fields off a payload; `None` when it runs out.
struct Cursor<'a>(&'a [u8]);

impl<'a> Cursor<'a> {
    fn take(&mut self, n: usize) -> Option<&'a [u8]> {
        if self.0.len() < n {
            return None;
        }
        let (a, b) = self.0.split_at(n);
        self.0 = b;
        Some(a)
    }
    fn u8(&mut self) -> Option<u8> {
        Some(self.take(1)?[0])
    }
    fn u16(&mut self) -> Option<u16> {
        Some(u16::from_le_bytes(self.take(2)?.try_into().ok()?))
    }
    fn u32(&mut self) -> Option<u32> {
        Some(u32::from_le_bytes(self.take(4)?.try_into().ok()?))
    }
    fn u64(&mut self) -> Option<u64> {
        Some(u64::from_le_bytes(self.take(8)?.try_into().ok()?))
    }
    fn text(&mut self) -> Option<String> {
        let n = self.u16()? as usize;
        String::from_utf8(self.take(n)?.to_vec()).ok()
    }
}

fn decode(payload: &[u8]) -> Option<Record> {
    let mut c = Cursor(payload);
    let kind = c.u8()?;
    let generation = c.u64()?;
    let name = c.text()?;
    let change = match kind {
        1 => {
            let added_at_ms = c.u64()?;
            let place = c.text()?;
            let poses = c.u16()? as usize;
            let pose = (0..poses)
                .map(|_| c.u64().map(f64::from_bits))
                .collect::<Option<Vec<f64>>>()?;
            let n = c.u32()? as usize;
            let bytes = c.take(n.checked_mul(PACKED_BYTES)?)?;
            let features: Vec<PackedFeature> = bytes
                .chunks_exact(PACKED_BYTES)
                .map(bytemuck::pod_read_unaligned)
                .collect();
            Change::Add(NewImage {
                name,
                place,
                pose,
                features,
                added_at_ms,
            })
        }
        2 => Change::Remove { name },
        _ => return None,
    };
    // trailing bytes make the record malformed
    c.0.is_empty().then_some(Record { generation, change })
}

/// The record as bytes (length, checksum, payload). Names and labels over
/// [`MAX_TEXT`] bytes, or more than 65 535 pose values, are refused.
pub fn encode(record: &Record) -> Result<Vec<u8>, String> {
    fn text(out: &mut Vec<u8>, s: &str, what: &str) -> Result<(), String> {
        let n = u16::try_from(s.len()).map_err(|_| format!("{what} over {MAX_TEXT} bytes"))?;
        out.extend_from_slice(&n.to_le_bytes());
        out.extend_from_slice(s.as_bytes());
        Ok(())
    }
    let mut p = Vec::new();
    let kind: u8 = match record.change {
        Change::Add(_) => 1,
        Change::Remove { .. } => 2,
    };
    p.push(kind);
    p.extend_from_slice(&record.generation.to_le_bytes());
    text(&mut p, record.change.name(), "the name")?;
    if let Change::Add(i) = &record.change {
        p.extend_from_slice(&i.added_at_ms.to_le_bytes());
        text(&mut p, &i.place, "the place")?;
        let poses = u16::try_from(i.pose.len()).map_err(|_| "too many pose values")?;
        p.extend_from_slice(&poses.to_le_bytes());
        for v in &i.pose {
            p.extend_from_slice(&v.to_bits().to_le_bytes());
        }
        let n = u32::try_from(i.features.len()).map_err(|_| "too many features")?;
        p.extend_from_slice(&n.to_le_bytes());
        p.extend_from_slice(bytemuck::cast_slice(&i.features));
    }
    if p.len() > MAX_PAYLOAD {
        return Err(format!("a change of {} bytes, over the limit", p.len()));
    }
    let mut out = Vec::with_capacity(8 + p.len());
    out.extend_from_slice(&(p.len() as u32).to_le_bytes());
    out.extend_from_slice(&crc32fast::hash(&p).to_le_bytes());
    out.extend_from_slice(&p);
    Ok(out)
}

/// The open log a writer appends to; it holds an exclusive lock on the file,
/// so two processes never write one map's changes.
pub struct LogWriter {
    path: PathBuf,
    file: File,
    len: u64,
    records: usize,
}

impl LogWriter {
    /// Open the log at `path` for appending after its first `valid_len`
    /// bytes (anything after them, a torn tail, is cut off first).
    pub fn open(path: &Path, valid_len: usize, records: usize) -> Result<Self, LogError> {
        let file = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .open(path)
            .map_err(io(path))?;
        lock(&file, path)?;
        let len = file.metadata().map_err(io(path))?.len();
        if len != valid_len as u64 {
            file.set_len(valid_len as u64).map_err(io(path))?;
            file.sync_all().map_err(io(path))?;
        }
        Ok(Self {
            path: path.to_path_buf(),
            file,
            len: valid_len as u64,
            records,
        })
    }

    /// Replace the log at `path` by an empty one for the map of
    /// `fingerprint` (atomically: a crash leaves the old log or the new).
    pub fn create(path: &Path, fingerprint: u64) -> Result<Self, LogError> {
        crate::store::write_atomic(path, |w| w.write_all(&header(fingerprint)))
            .map_err(|e| LogError::Invalid(e.to_string()))?;
        Self::open(path, HEADER_LEN, 0)
    }

    /// Empty the log for the map of `fingerprint` (after a compaction).
    pub fn reset(&mut self, fingerprint: u64) -> Result<(), LogError> {
        *self = Self::create(&self.path, fingerprint)?;
        Ok(())
    }

    /// Append one record and make it durable (fsync) before returning. On
    /// failure the log is cut back to where it was, so a later append is
    /// not hidden behind a torn record.
    pub fn append(&mut self, bytes: &[u8]) -> Result<(), LogError> {
        use std::io::{Seek, SeekFrom};
        let path = self.path.clone();
        let written = self
            .file
            .seek(SeekFrom::Start(self.len))
            .and_then(|_| self.file.write_all(bytes))
            .and_then(|_| self.file.sync_data());
        if let Err(e) = written {
            let _ = self
                .file
                .set_len(self.len)
                .and_then(|_| self.file.sync_data());
            return Err(io(&path)(e));
        }
        self.len += bytes.len() as u64;
        self.records += 1;
        Ok(())
    }

    /// Bytes in the log, header included.
    pub fn len(&self) -> u64 {
        self.len
    }

    /// Records in the log.
    pub fn records(&self) -> usize {
        self.records
    }

    pub fn is_empty(&self) -> bool {
        self.records == 0
    }
}

fn lock(file: &File, path: &Path) -> Result<(), LogError> {
    file.try_lock().map_err(|e| match e {
        std::fs::TryLockError::WouldBlock => LogError::Invalid(format!(
            "{}: the change log is in use by another process (a running `bowloc serve`?)",
            path.display()
        )),
        std::fs::TryLockError::Error(e) => io(path)(e),
    })
}

/// Where the change log of the map at `map` lives: `MAP.changes`.
pub fn path_for(map: &Path) -> PathBuf {
    let mut name = map.as_os_str().to_owned();
    name.push(".changes");
    PathBuf::from(name)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::Keypoint;
    use crate::geometry::packed::pack_image;

    fn add(generation: u64, name: &str, words: &[u32]) -> Record {
        let kps: Vec<Keypoint> = words
            .iter()
            .map(|&w| Keypoint {
                x: w as f32,
                y: 2.0,
                size: 3.0,
                angle: 10.0,
                response: 0.0,
            })
            .collect();
        Record {
            generation,
            change: Change::Add(NewImage {
                name: name.into(),
                place: "lab".into(),
                pose: vec![1.5, f64::NAN],
                features: pack_image(words, &[], &kps),
                added_at_ms: 1_700_000_000_000,
            }),
        }
    }

    fn log_of(records: &[Record]) -> Vec<u8> {
        let mut bytes = header(42).to_vec();
        for r in records {
            bytes.extend(encode(r).unwrap());
        }
        bytes
    }

    fn same(a: &[Record], b: &[Record]) {
        // NaN poses compare by bits
        assert_eq!(format!("{a:?}"), format!("{b:?}"));
    }

    #[test]
    fn records_round_trip() {
        let records = vec![
            add(1, "a", &[3, 1, 1]),
            Record {
                generation: 2,
                change: Change::Remove { name: "a".into() },
            },
            add(3, "b", &[]),
        ];
        let p = parse(&log_of(&records)).unwrap();
        same(&p.records, &records);
        assert_eq!(p.fingerprint, 42);
        assert_eq!(p.dropped, None);
    }

    #[test]
    fn a_torn_or_corrupt_tail_is_dropped_at_every_cut() {
        let records = vec![add(1, "a", &[3, 1]), add(2, "b", &[5])];
        let whole = log_of(&records);
        let first_end = HEADER_LEN + encode(&records[0]).unwrap().len();
        for cut in HEADER_LEN..whole.len() {
            let p = parse(&whole[..cut]).unwrap();
            let kept = if cut >= first_end { 1 } else { 0 };
            assert_eq!(p.records.len(), kept, "cut at {cut}");
            assert_eq!(p.valid_len, if kept == 1 { first_end } else { HEADER_LEN });
            assert_eq!(p.dropped.is_some(), cut != p.valid_len);
        }
        for flip in first_end..whole.len() {
            let mut bad = whole.clone();
            bad[flip] ^= 0x40;
            let p = parse(&bad).unwrap();
            assert_eq!(p.records.len(), 1, "flip at {flip}");
            assert!(p.dropped.is_some());
        }
    }

    #[test]
    fn a_bad_header_is_an_error() {
        assert!(parse(b"").is_err());
        assert!(parse(b"BOWLOCMA0000000000000000").is_err());
        let mut h = header(1);
        h[8] = 9;
        assert!(parse(&h).unwrap_err().to_string().contains("version 9"));
    }

    #[test]
    fn appends_are_read_back_and_a_second_writer_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let path = path_for(&dir.path().join("m.bowmap"));
        let mut w = LogWriter::create(&path, 7).unwrap();
        let r = add(1, "x", &[2]);
        w.append(&encode(&r).unwrap()).unwrap();
        let e = LogWriter::open(&path, w.len() as usize, 1).err().unwrap();
        assert!(e.to_string().contains("in use"), "{e}");
        let p = parse(&std::fs::read(&path).unwrap()).unwrap();
        same(&p.records, &[r]);
        w.reset(8).unwrap();
        let p = parse(&std::fs::read(&path).unwrap()).unwrap();
        assert!(p.records.is_empty());
        assert_eq!(p.fingerprint, 8);
    }
}
