//! Keeping the image buffers mapped, checked in a process of its own:
//! mallopt must not run while other threads allocate, so this test has no
//! harness and no threads. With glibc's defaults a block of a few MiB (the
//! size of a SIFT scale-space buffer) gets a mapping of its own, which the
//! next image faults in again; after [`keep_image_buffers`] it comes from
//! malloc's heap.

use bowloc::features::{Buffers, KEEP_BUFFERS_VAR, keep_image_buffers};

/// Whether a block of `bytes` got a mapping of its own (glibc counts those).
#[cfg(target_env = "gnu")]
fn block_is_mapped(bytes: usize) -> bool {
    // SAFETY: mallinfo2 only reads the allocator's counters; the block is
    // freed before returning and never touched.
    unsafe {
        let before = libc::mallinfo2().hblks;
        // black_box: a block never used would be optimized away
        let p = std::hint::black_box(libc::malloc(bytes));
        assert!(!p.is_null(), "malloc({bytes}) failed");
        let mapped = libc::mallinfo2().hblks > before;
        libc::free(p);
        mapped
    }
}

#[cfg(target_env = "gnu")]
fn main() {
    // SAFETY: the process has one thread.
    unsafe { std::env::set_var(KEEP_BUFFERS_VAR, "0") };
    assert_eq!(keep_image_buffers(), Buffers::LeftToMalloc);
    // glibc maps it (and raises its own threshold to 1 MiB once it is freed)
    assert!(
        block_is_mapped(1 << 20),
        "malloc's default maps a 1 MiB block"
    );
    // SAFETY: the process has one thread.
    unsafe { std::env::remove_var(KEEP_BUFFERS_VAR) };
    assert_eq!(keep_image_buffers(), Buffers::Kept);
    // above the 1 MiB glibc raised its threshold to: mapped unless kept
    assert!(
        !block_is_mapped(8 << 20),
        "an 8 MiB block comes from the heap once the buffers are kept"
    );
    println!(
        "buffers: a kept 8 MiB block came from the heap; with {KEEP_BUFFERS_VAR}=0 a 1 MiB block was mapped"
    );
}

#[cfg(not(target_env = "gnu"))]
fn main() {
    assert_eq!(keep_image_buffers(), Buffers::Refused);
}
