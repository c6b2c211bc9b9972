//! The service's sequences: one [`Filter`] per sequence name, bounded. At
//! most `sequence.max_sequences` are kept (the least recently used is dropped
//! beyond), one without a frame for `sequence.idle_ms` is dropped, and each
//! holds only its tracked images, so memory follows the sequences and
//! `sequence.track`, not the map. Each sequence has its own lock: frames of
//! one sequence are applied one at a time, in the order they take the lock;
//! frames of different sequences run in parallel.

use super::metrics;
use crate::sequence::Filter;
use lru::LruCache;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// One sequence's state behind its own lock.
pub type Slot = Arc<tokio::sync::Mutex<Filter>>;

struct Entry {
    slot: Slot,
    used: Instant,
}

/// Every live sequence.
pub struct Sequences {
    live: Mutex<LruCache<String, Entry>>,
    cap: usize,
    idle: Duration,
}

impl Sequences {
    pub fn new(cap: usize, idle: Duration) -> Self {
        Self {
            live: Mutex::new(LruCache::unbounded()),
            cap: cap.max(1),
            idle,
        }
    }

    /// The sequence `name`, made if it is not live, marked as just used.
    /// Drops idle sequences and, beyond the cap, the least recently used.
    pub fn slot(&self, name: &str) -> Slot {
        let now = Instant::now();
        let mut live = self.live.lock().unwrap_or_else(|e| e.into_inner());
        self.drop_idle(&mut live, now);
        let slot = match live.get_mut(name) {
            Some(e) => {
                e.used = now;
                e.slot.clone()
            }
            None => {
                let slot = Slot::default();
                live.put(
                    name.to_owned(),
                    Entry {
                        slot: slot.clone(),
                        used: now,
                    },
                );
                while live.len() > self.cap {
                    live.pop_lru();
                    metrics::sequence_evicted("capacity");
                }
                slot
            }
        };
        metrics::sequences_live(live.len());
        slot
    }

    /// Forget the sequence `name`; whether it was live.
    pub fn remove(&self, name: &str) -> bool {
        let mut live = self.live.lock().unwrap_or_else(|e| e.into_inner());
        let removed = live.pop(name).is_some();
        metrics::sequences_live(live.len());
        removed
    }

    /// Drop the sequences idle for longer than the timeout (least recently
    /// used first, so it stops at the first one still in use).
    pub fn sweep(&self) {
        let mut live = self.live.lock().unwrap_or_else(|e| e.into_inner());
        self.drop_idle(&mut live, Instant::now());
        metrics::sequences_live(live.len());
    }

    fn drop_idle(&self, live: &mut LruCache<String, Entry>, now: Instant) {
        while live
            .peek_lru()
            .is_some_and(|(_, e)| now.duration_since(e.used) > self.idle)
        {
            live.pop_lru();
            metrics::sequence_evicted("idle");
        }
    }

    /// Live sequences.
    pub fn len(&self) -> usize {
        self.live.lock().unwrap_or_else(|e| e.into_inner()).len()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// A sequence name: 1 to 128 characters among letters, digits, `-`, `_`,
/// `.` and `:`.
pub fn valid_name(name: &str) -> Result<&str, String> {
    let ok = (1..=128).contains(&name.len())
        && name
            .bytes()
            .all(|b| b.is_ascii_alphanumeric() || b"-_.:".contains(&b));
    if ok {
        Ok(name)
    } else {
        Err(format!(
            "`{}` is not a sequence name: 1 to 128 letters, digits, `-`, `_`, `.` or `:`",
            name.chars().take(140).collect::<String>()
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::search::prior::posterior;
    use crate::sequence::{SequenceModel, Topology};

    #[test]
    fn the_least_recently_used_goes_beyond_the_cap() {
        let s = Sequences::new(2, Duration::from_secs(60));
        let a = s.slot("a");
        s.slot("b");
        assert!(Arc::ptr_eq(&a, &s.slot("a"))); // a is now the most recent
        s.slot("c"); // drops b
        assert_eq!(s.len(), 2);
        assert!(Arc::ptr_eq(&a, &s.slot("a")));
        assert!(s.remove("c"));
        assert!(!s.remove("b"));
        assert_eq!(s.len(), 1);
    }

    #[test]
    fn idle_sequences_are_dropped() {
        let s = Sequences::new(10, Duration::from_millis(20));
        s.slot("a");
        std::thread::sleep(Duration::from_millis(40));
        s.sweep();
        assert!(s.is_empty());
    }

    #[test]
    fn names_are_checked() {
        assert!(valid_name("robot-7.run:2").is_ok());
        for bad in ["", "a b", "é", "a/b", &"x".repeat(129)] {
            assert!(valid_name(bad).is_err(), "{bad}");
        }
    }

    #[tokio::test(flavor = "multi_thread", worker_threads = 4)]
    async fn concurrent_frames_of_one_sequence_apply_one_at_a_time() {
        let s = Arc::new(Sequences::new(10, Duration::from_secs(60)));
        let model = SequenceModel::default();
        let topology = Topology::Order { images: 100 };
        let mut tasks = Vec::new();
        for _ in 0..64 {
            let s = s.clone();
            let topology = topology.clone();
            tasks.push(tokio::spawn(async move {
                let slot = s.slot("robot");
                let mut filter = slot.lock().await;
                let prediction = filter.predict(&model, &topology, None);
                let before = filter.frames();
                tokio::task::yield_now().await; // hold the lock across a suspension
                let mut h = vec![0.0f32; 100];
                h[10] = 5.0;
                filter.update(posterior(&prediction.prior, &h, &[10], 1, 8), &prediction);
                assert_eq!(filter.frames(), before + 1);
            }));
        }
        for t in tasks {
            t.await.unwrap();
        }
        let slot = s.slot("robot");
        let filter = slot.lock().await;
        // every frame applied, each one after the other: frames 0..=63
        assert_eq!(filter.frames(), 64);
        assert_eq!(filter.last_frame(), Some(63));
    }
}
