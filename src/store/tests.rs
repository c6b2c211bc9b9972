//! The file format: a round trip, and every wrong magic, version,
//! truncation and flipped byte refused with its name.

use super::*;

const MAGIC: [u8; 8] = *b"BOWLOCTS";

fn sample(dir: &std::path::Path) -> std::path::PathBuf {
    let path = dir.join("s.bin");
    let floats = [1.0f32, 2.0, 3.5];
    let ints = [7u32, 8, 9, 10];
    StoreWriter::new(MAGIC, 3)
        .f32s("floats", &floats)
        .u32s("ints", &ints)
        .json("meta", &serde_json::json!({"k": 3}))
        .write_atomic(&path)
        .unwrap();
    path
}

fn open(path: &std::path::Path) -> Result<Store, StoreError> {
    Store::open(path, MAGIC, "test", 3, true)
}

#[test]
fn round_trip() {
    let dir = tempfile::tempdir().unwrap();
    let store = open(&sample(dir.path())).unwrap();
    assert_eq!(store.f32s("floats").unwrap(), &[1.0, 2.0, 3.5]);
    assert_eq!(store.u32s("ints").unwrap(), &[7, 8, 9, 10]);
    let meta: serde_json::Value = store.json("meta").unwrap();
    assert_eq!(meta["k"], 3);
    assert!(matches!(
        store.u32s("floats"),
        Err(StoreError::Invalid { .. })
    ));
    assert!(matches!(
        store.f32s("nope"),
        Err(StoreError::MissingSection { .. })
    ));
}

#[test]
fn wrong_magic_and_version_are_named() {
    let dir = tempfile::tempdir().unwrap();
    let path = sample(dir.path());
    let err = Store::open(&path, *b"BOWLOCXX", "other", 3, true).unwrap_err();
    assert!(matches!(err, StoreError::WrongMagic { .. }), "{err}");
    let err = Store::open(&path, MAGIC, "test", 4, true).unwrap_err();
    assert!(
        matches!(err, StoreError::WrongVersion { found: 3, .. }),
        "{err}"
    );
    assert!(err.to_string().contains("s.bin"));
}

#[test]
fn every_truncation_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let path = sample(dir.path());
    let full = std::fs::read(&path).unwrap();
    for len in 0..full.len() {
        std::fs::write(&path, &full[..len]).unwrap();
        assert!(
            open(&path).is_err(),
            "truncated to {len} bytes was accepted"
        );
    }
}

#[test]
fn every_flipped_byte_is_detected() {
    let dir = tempfile::tempdir().unwrap();
    let path = sample(dir.path());
    let full = std::fs::read(&path).unwrap();
    let store = open(&path).unwrap();
    let covered: Vec<(usize, usize)> = ["floats", "ints", "meta"]
        .iter()
        .map(|n| {
            let s = store.section(n).unwrap();
            (s.offset, s.offset + s.len)
        })
        .collect();
    drop(store);
    let table_end = 24 + 3 * 64;
    for i in 0..full.len() {
        // padding between sections is covered by no checksum and may change freely
        let in_payload = covered.iter().any(|&(a, b)| (a..b).contains(&i));
        if !(i < table_end || in_payload) {
            continue;
        }
        let mut bad = full.clone();
        bad[i] ^= 0x40;
        std::fs::write(&path, &bad).unwrap();
        assert!(open(&path).is_err(), "flip at byte {i} was accepted");
    }
}
