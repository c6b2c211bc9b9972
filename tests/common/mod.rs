//! Helpers shared by the integration tests.

use std::path::PathBuf;

/// A shared dataset's folder (`../shared/datasets/NAME` beside the project),
/// with a clear failure when it is missing.
pub fn dataset(name: &str) -> PathBuf {
    let d = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/datasets")
        .join(name);
    assert!(
        d.join("map.txt").is_file(),
        "{} is missing: the shared datasets sit beside the project",
        d.display()
    );
    d
}

/// A shared dataset made ready for searching: a vocabulary of K words
/// (k-means seed 1) trained on its map images, the map over them, and its
/// queries extracted, as `bowloc eval` does with one vocabulary.
#[allow(dead_code)]
pub struct RealMap {
    pub data: bowloc::dataset::Dataset,
    pub vocab: bowloc::vocabulary::Vocabulary,
    pub map: bowloc::index::MapIndex,
    pub queries: Vec<Option<bowloc::features::Features>>,
}

/// [`RealMap`] for the shared dataset `name` at `words` words.
#[allow(dead_code)]
pub fn real_map(name: &str, words: usize) -> RealMap {
    use bowloc::features::{DecodeLimits, ExtractConfig};
    use bowloc::pipeline::{extract_all, index_descriptors, stack, train_vocabulary};
    let data = bowloc::dataset::Dataset::open(&dataset(name)).unwrap();
    let extract = ExtractConfig::default();
    let limits = DecodeLimits::default();
    let map_desc = extract_all(&data.map, &extract, limits, false, "map").unwrap();
    let parts: Vec<_> = map_desc.iter().flatten().collect();
    let config = bowloc::vocabulary::kmeans::KmeansConfig {
        k: words,
        seed: 1,
        ..Default::default()
    };
    let vocab = train_vocabulary(stack(&parts).view(), &extract, &config).unwrap();
    let names: Vec<String> = data.map.iter().map(|i| i.name.clone()).collect();
    let map = index_descriptors(&vocab, &names, &map_desc, None, name);
    let queries = extract_all(&data.queries, &extract, limits, false, "queries").unwrap();
    RealMap {
        data,
        vocab,
        map,
        queries,
    }
}

impl RealMap {
    /// A localizer over this vocabulary and map, as the service opens them
    /// (both saved to files first; `verify` is the localizer's default for
    /// geometric verification). The files may go once opened: the map is
    /// mapped or read whole.
    #[allow(dead_code)]
    pub fn localizer(&self, verify: bool) -> bowloc::pipeline::Localizer {
        let dir = tempfile::tempdir().unwrap();
        let (vpath, mpath) = (dir.path().join("v.bowvoc"), dir.path().join("m.bowmap"));
        self.vocab.save(&vpath).unwrap();
        self.map.save(&mpath).unwrap();
        bowloc::pipeline::Localizer::open(&vpath, &mpath, verify).unwrap()
    }
}
