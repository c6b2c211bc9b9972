//! Live maps: a map file that takes added and removed images while it
//! serves queries, durably.
//!
//! - [`snapshot`]: one consistent state (map file + changes) that queries
//!   search like a map file, and the scoring policy between compactions;
//! - [`log`]: the append-only, checksummed change log beside the map file;
//! - [`compact`]: folding a snapshot into a new map built from scratch.
//!
//! [`LiveMap`] ties them: queries take the current snapshot (a pointer load,
//! never blocked by a writer); writers are serialised by one mutex, and each
//! change is validated on a copy of the snapshot, appended to the log and
//! fsynced, and only then published — an add is visible whole or not at all,
//! and acknowledged only once durable. Each change bumps the generation;
//! a compaction writes the folded map (atomically, recording its
//! generation), then empties the log. At start-up the log's records newer
//! than the map file's generation are replayed; a log whose records the map
//! file already holds (a crash between the two steps of a compaction) is
//! emptied.

pub mod compact;
pub mod log;
pub mod snapshot;

pub use log::{Change, NewImage, Record};
pub use snapshot::{Applied, ApplyError, Snapshot};

use crate::index::MapIndex;
use crate::vocabulary::Vocabulary;
use arc_swap::ArcSwap;
use log::LogWriter;
use serde::Serialize;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};
use std::time::{Instant, SystemTime, UNIX_EPOCH};

/// A write that was not done.
#[derive(Debug, thiserror::Error)]
pub enum WriteError {
    #[error("this map takes no changes (it was opened without its change log)")]
    ReadOnly,
    #[error(transparent)]
    Apply(#[from] ApplyError),
    /// The change could not be made durable; nothing was changed.
    #[error("the change could not be written to the change log: {0}")]
    Log(String),
    /// A compaction failed half-way; writes stop until a restart.
    #[error("{0}")]
    Broken(String),
}

/// The last compaction.
#[derive(Debug, Clone, Serialize, utoipa::ToSchema)]
pub struct Compaction {
    /// When it wrote the map file, in milliseconds since the Unix epoch.
    pub at_ms: u64,
    /// How long it took (fold, write, reopen), in seconds; `null` when it
    /// ran before the server last started (the map file records only when).
    pub seconds: Option<f64>,
    /// The generation it folded.
    pub generation: u64,
    /// Images in the map it wrote.
    pub images: usize,
}

impl Compaction {
    /// The compaction that wrote `map`'s file, as far as the file records it.
    fn of_file(map: &MapIndex) -> Option<Self> {
        let meta = map.meta();
        meta.compacted_at_ms.map(|at_ms| Self {
            at_ms,
            seconds: None,
            generation: meta.generation,
            images: map.images(),
        })
    }
}

/// The state of the changes, as `/map` reports it.
#[derive(Debug, Clone, Serialize, utoipa::ToSchema)]
pub struct ChangesInfo {
    /// Changes applied since the first map file (each add or removal: +1).
    pub generation: u64,
    /// Generation of the map file (changes folded into it).
    pub file_generation: u64,
    /// Images of the map file, and how many of them are still in the map.
    pub file_images: usize,
    /// Images in the map now.
    pub images: usize,
    /// Images added since the map file was written (replaced or removed
    /// ones included).
    pub added: usize,
    /// Images marked removed since the map file was written (a replaced
    /// image counts as removed).
    pub removed: usize,
    /// Records and bytes in the change log (`null` without a log).
    pub log_records: Option<usize>,
    pub log_bytes: Option<u64>,
    /// The last compaction, if the map file was written by one (also one
    /// that ran before a restart).
    pub last_compaction: Option<Compaction>,
}

/// What opening a live map found in its log.
#[derive(Debug, Clone, Default)]
pub struct Opened {
    /// Records replayed on top of the map file.
    pub replayed: usize,
    /// A torn or corrupt tail that was cut off, and why.
    pub dropped: Option<String>,
    /// The log was emptied: the map file already held all its records.
    pub reset: bool,
}

struct Writer {
    log: LogWriter,
    map_path: PathBuf,
    /// Why writes are refused, after a failure that left file and log out of step.
    broken: Option<String>,
}

/// A map that takes changes while it serves.
pub struct LiveMap {
    current: ArcSwap<Snapshot>,
    writer: Option<Mutex<Writer>>,
    max_images: usize,
    last_compaction: Mutex<Option<Compaction>>,
}

/// Milliseconds since the Unix epoch, now.
pub fn now_ms() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_millis() as u64)
}

impl LiveMap {
    /// A map file on its own, taking no changes.
    pub fn fixed(map: MapIndex) -> Self {
        Self {
            current: ArcSwap::from_pointee(Snapshot::new(Arc::new(map))),
            writer: None,
            max_images: usize::MAX,
            last_compaction: Mutex::new(None),
        }
    }

    /// Open the map file at `path` (checked against `vocab` when given) and its change log
    /// `PATH.changes` (created when missing), replaying the log. The log is
    /// locked: one process at a time writes a map. At most `max_images`
    /// images may be in the map (replayed changes are never refused).
    pub fn open(
        path: &Path,
        vocab: Option<&Vocabulary>,
        verify: bool,
        max_images: usize,
    ) -> anyhow::Result<(Self, Opened)> {
        let base = match vocab {
            Some(vocab) => MapIndex::open_for(path, vocab, verify)?,
            None => MapIndex::open(path, verify)?,
        };
        let fingerprint = base.fingerprint();
        let file_generation = base.meta().generation;
        let last_compaction = Compaction::of_file(&base);
        let mut snapshot = Snapshot::new(Arc::new(base));
        let log_path = log::path_for(path);
        let mut opened = Opened::default();
        let log = match std::fs::read(&log_path) {
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
                LogWriter::create(&log_path, fingerprint)?
            }
            Err(e) => anyhow::bail!("{}: {e}", log_path.display()),
            Ok(bytes) => {
                let parsed = log::parse(&bytes)
                    .map_err(|e| anyhow::anyhow!("{}: {e}", log_path.display()))?;
                let newer: Vec<&Record> = parsed
                    .records
                    .iter()
                    .filter(|r| r.generation > file_generation)
                    .collect();
                if !newer.is_empty() && parsed.fingerprint != fingerprint {
                    anyhow::bail!(
                        "{}: the change log holds {} changes for another map file than {} \
                         (was the map rebuilt?); move the log away to serve the map without them",
                        log_path.display(),
                        newer.len(),
                        path.display()
                    );
                }
                // also when no record before it is replayed: a first record
                // that fails its checksum hides every change after it
                if let Some(why) = &parsed.dropped {
                    tracing::warn!(log = %log_path.display(), "change log tail cut off: {why}");
                    opened.dropped = Some(why.clone());
                }
                let stale = !parsed.records.is_empty() || parsed.fingerprint != fingerprint;
                if newer.is_empty() && stale {
                    // every record is in the map file: a new empty log for it
                    opened.reset = !parsed.records.is_empty();
                    LogWriter::create(&log_path, fingerprint)?
                } else {
                    // the records to replay, or an empty log of this map kept as it is
                    for record in newer {
                        if let Err(e) = snapshot.apply(record, usize::MAX) {
                            tracing::warn!(
                                generation = record.generation,
                                "change log record not applied: {e}"
                            );
                        }
                        opened.replayed += 1;
                    }
                    LogWriter::open(&log_path, parsed.valid_len, parsed.records.len())?
                }
            }
        };
        let live = Self {
            current: ArcSwap::from_pointee(snapshot),
            writer: Some(Mutex::new(Writer {
                log,
                map_path: path.to_path_buf(),
                broken: None,
            })),
            max_images,
            last_compaction: Mutex::new(last_compaction),
        };
        Ok((live, opened))
    }

    /// The current state, for one query: it never changes under the caller.
    pub fn snapshot(&self) -> Arc<Snapshot> {
        self.current.load_full()
    }

    /// Whether the map takes changes.
    pub fn writable(&self) -> bool {
        self.writer.is_some()
    }

    fn writer(&self) -> Result<std::sync::MutexGuard<'_, Writer>, WriteError> {
        let w = self
            .writer
            .as_ref()
            .ok_or(WriteError::ReadOnly)?
            .lock()
            .unwrap_or_else(|e| e.into_inner());
        match &w.broken {
            Some(why) => Err(WriteError::Broken(why.clone())),
            None => Ok(w),
        }
    }

    /// Make one change: validate it, log it durably, publish it. Returns
    /// what it did and the new generation.
    pub fn apply(&self, change: Change) -> Result<(Applied, u64), WriteError> {
        let mut w = self.writer()?;
        let mut next = Snapshot::clone(&self.current.load());
        let record = Record {
            generation: next.generation() + 1,
            change,
        };
        let applied = next.apply(&record, self.max_images)?;
        let bytes = log::encode(&record).map_err(|e| ApplyError::Invalid(e.to_string()))?;
        w.log
            .append(&bytes)
            .map_err(|e| WriteError::Log(e.to_string()))?;
        self.current.store(Arc::new(next));
        Ok((applied, record.generation))
    }

    /// Fold the changes into a new map file and empty the log. Writes wait
    /// meanwhile; queries go on with the snapshot they hold, then see the
    /// new file. Returns `None` when there was nothing to fold.
    pub fn compact(&self) -> Result<Option<Compaction>, WriteError> {
        let mut w = self.writer()?;
        let snapshot = self.snapshot();
        if snapshot.overlay().is_empty() && w.log.is_empty() {
            return Ok(None);
        }
        let started = Instant::now();
        let at_ms = now_ms();
        let folded = compact::fold(&snapshot).compacted_at(at_ms);
        folded
            .save(&w.map_path)
            .map_err(|e| WriteError::Log(format!("writing the compacted map: {e}")))?;
        // From here the file holds every change: failing to reopen it or to
        // empty the log leaves them out of step until a restart sorts it out.
        let reopened = MapIndex::open(&w.map_path, false)
            .map_err(|e| e.to_string())
            .and_then(|map| {
                let fingerprint = map.fingerprint();
                w.log
                    .reset(fingerprint)
                    .map(|()| map)
                    .map_err(|e| e.to_string())
            });
        let map = match reopened {
            Ok(map) => map,
            Err(e) => {
                let why = format!(
                    "a compaction failed after writing the map file ({e}); writes are refused until a restart"
                );
                tracing::error!("{why}");
                w.broken = Some(why.clone());
                return Err(WriteError::Broken(why));
            }
        };
        let images = map.images();
        self.current.store(Arc::new(Snapshot::new(Arc::new(map))));
        let done = Compaction {
            at_ms,
            seconds: Some(started.elapsed().as_secs_f64()),
            generation: snapshot.generation(),
            images,
        };
        *self
            .last_compaction
            .lock()
            .unwrap_or_else(|e| e.into_inner()) = Some(done.clone());
        tracing::info!(
            generation = done.generation,
            images,
            seconds = done.seconds,
            "map compacted"
        );
        Ok(Some(done))
    }

    /// Bytes in the change log (0 without one).
    pub fn log_bytes(&self) -> u64 {
        self.writer
            .as_ref()
            .map_or(0, |w| w.lock().unwrap_or_else(|e| e.into_inner()).log.len())
    }

    /// Generation, counts, log size and the last compaction.
    pub fn status(&self) -> ChangesInfo {
        let s = self.snapshot();
        let o = s.overlay();
        let (log_records, log_bytes) = match &self.writer {
            None => (None, None),
            Some(w) => {
                let w = w.lock().unwrap_or_else(|e| e.into_inner());
                (Some(w.log.records()), Some(w.log.len()))
            }
        };
        ChangesInfo {
            generation: s.generation(),
            file_generation: s.base().meta().generation,
            file_images: s.base().images(),
            images: s.len(),
            added: o.added(),
            removed: o.removed(),
            log_records,
            log_bytes,
            last_compaction: self
                .last_compaction
                .lock()
                .unwrap_or_else(|e| e.into_inner())
                .clone(),
        }
    }
}

#[cfg(test)]
pub(crate) mod tests;
