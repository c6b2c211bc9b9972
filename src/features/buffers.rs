//! Keeping OpenCV's image buffers mapped between requests. SIFT allocates
//! each image's scale space (about 45 MB for a 640 px frame, upsampled ×2)
//! in blocks of a few MB and frees it when the call returns. glibc's malloc
//! serves such blocks with fresh mappings or trims them off its heaps once
//! they are free, depending on what the process allocated before, so the
//! next image may fault every page in again: measured through the server,
//! 20 ms more on a 45 ms whole-image extraction of an rtabmap-loop query
//! (docs/performance.md, "Buffers kept mapped"). Fixed thresholds make every
//! image reuse the memory the last one freed, whatever ran before.

/// The environment variable that, set to `0`, leaves malloc's defaults
/// (to measure what keeping the buffers saves).
pub const KEEP_BUFFERS_VAR: &str = "BOWLOC_KEEP_BUFFERS";

/// What [`keep_image_buffers`] did.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Buffers {
    /// The thresholds are fixed.
    Kept,
    /// [`KEEP_BUFFERS_VAR`] is `0`: malloc's defaults stay.
    LeftToMalloc,
    /// The allocator refused the thresholds (not glibc).
    Refused,
}

/// Blocks below this come from malloc's heaps, not their own mapping:
/// glibc's largest (32 MiB on 64-bit), above any one buffer of a 640 px
/// scale space.
const MMAP_THRESHOLD: i32 = 32 << 20;

/// Free memory at a heap's top beyond this goes back to the system: a few
/// scale spaces, so a worker keeps its own.
const TRIM_THRESHOLD: i32 = 256 << 20;

/// Fix malloc's thresholds for the whole process (its C++ side included),
/// unless [`KEEP_BUFFERS_VAR`] is `0`. Call once at start, before the
/// threads that extract.
pub fn keep_image_buffers() -> Buffers {
    if std::env::var(KEEP_BUFFERS_VAR).is_ok_and(|v| v.trim() == "0") {
        Buffers::LeftToMalloc
    } else if set_thresholds() {
        Buffers::Kept
    } else {
        Buffers::Refused
    }
}

/// Whether the allocator took both thresholds (always, with glibc; never
/// elsewhere).
#[cfg(target_env = "gnu")]
fn set_thresholds() -> bool {
    // SAFETY: mallopt only sets allocator parameters; both values are in
    // the ranges glibc accepts.
    unsafe {
        libc::mallopt(libc::M_MMAP_THRESHOLD, MMAP_THRESHOLD) == 1
            && libc::mallopt(libc::M_TRIM_THRESHOLD, TRIM_THRESHOLD) == 1
    }
}

#[cfg(not(target_env = "gnu"))]
fn set_thresholds() -> bool {
    false
}
