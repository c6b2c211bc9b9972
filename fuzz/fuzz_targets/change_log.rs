//! Arbitrary bytes as a change log (`MAP.changes`): reading it must give the
//! records before the first bad one, or an error for a bad header, never a
//! panic. What was read must encode back to the very bytes it came from,
//! and replaying it onto a small map must apply or refuse each record
//! cleanly.
#![no_main]

use bowloc::index::{ImageWords, MapBuilder};
use bowloc::live::{Snapshot, log};
use libfuzzer_sys::fuzz_target;
use std::sync::Arc;

fuzz_target!(|data: &[u8]| {
    let Ok(parsed) = log::parse(data) else {
        return;
    };
    assert!(parsed.valid_len <= data.len());
    assert_eq!(parsed.dropped.is_some(), parsed.valid_len < data.len());
    let mut again = log::header(parsed.fingerprint).to_vec();
    for r in &parsed.records {
        again.extend(log::encode(r).expect("a record read encodes"));
    }
    assert_eq!(&again[log::HEADER_LEN..], &data[log::HEADER_LEN..parsed.valid_len]);
    let mut b = MapBuilder::new(16);
    b.add(ImageWords::from_words("a", &[1, 2, 3]));
    b.add(ImageWords::from_words("b", &[3, 4]));
    let mut s = Snapshot::new(Arc::new(b.build("fuzz", "0", None)));
    for r in &parsed.records {
        let _ = s.apply(r, 64);
    }
    let _ = bowloc::live::compact::fold(&s);
});
