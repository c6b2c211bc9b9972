//! Arbitrary bytes as a vocabulary file and as a map file: opening must give
//! a value or an error, never a panic or undefined behaviour — with checksums
//! verified and, to reach the structural checks, without. Whatever opens is
//! then used: image metadata, postings and a short search (votes weighed by
//! signatures, so the map's stored features are read too).
#![no_main]

use bowloc::index::MapIndex;
use bowloc::search::{KnownFeatures, RuleSpec, SearchOptions, search_words};
use bowloc::vocabulary::Vocabulary;
use libfuzzer_sys::fuzz_target;
use std::io::Write;

fuzz_target!(|data: &[u8]| {
    let mut file = tempfile::NamedTempFile::new().unwrap();
    file.write_all(data).unwrap();
    file.flush().unwrap();
    for verify in [true, false] {
        if let Ok(vocab) = Vocabulary::open(file.path(), verify) {
            let _ = vocab.hash_hex();
            let _ = vocab.centroids();
        }
        if let Ok(map) = MapIndex::open(file.path(), verify) {
            let words = map.words() as u32;
            for id in 0..map.images().min(4) as u32 {
                let _ = map.image(id);
            }
            let query: Vec<u32> = data.iter().take(64).map(|&b| b as u32 % words.max(1)).collect();
            // signatures from the same bytes, so weighed votes read the map's features
            let signatures: Vec<u64> = data
                .iter()
                .take(64)
                .map(|&b| (b as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15))
                .collect();
            let features = KnownFeatures {
                words: &query,
                signatures: &signatures,
            };
            for rule in ["none", "lossless"] {
                let options = SearchOptions {
                    rule: RuleSpec::new(rule, None).unwrap(),
                    ..Default::default()
                };
                let _ = search_words(&map, features, &options);
            }
        }
    }
});
