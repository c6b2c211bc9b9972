//! `scripts/reversed-datasets.sh` makes each shared dataset with its map and
//! queries swapped: the same images, the same ground-truth pairs read the
//! other way, opened as any dataset is.

mod common;

use std::collections::BTreeSet;

use bowloc::dataset::Dataset;

/// Every ground-truth pair as (query file, map file).
fn pairs(d: &Dataset) -> BTreeSet<(String, String)> {
    d.truth
        .iter()
        .enumerate()
        .flat_map(|(q, maps)| {
            maps.iter()
                .map(move |&m| (d.queries[q].name.clone(), d.map[m as usize].name.clone()))
        })
        .collect()
}

#[test]
fn the_reversed_datasets_swap_map_and_queries_and_read_the_pairs_the_other_way() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let out = tempfile::tempdir().unwrap();
    // twice: a second run over the first rewrites it in place
    for _ in 0..2 {
        let status = std::process::Command::new("bash")
            .arg(root.join("scripts/reversed-datasets.sh"))
            .arg(out.path())
            .status()
            .unwrap();
        assert!(status.success(), "scripts/reversed-datasets.sh failed");
    }
    for name in ["gardens-point", "rtabmap-loop"] {
        let original = Dataset::open(&common::dataset(name)).unwrap();
        let reversed = Dataset::open(&out.path().join(format!("{name}-reversed"))).unwrap();
        let names = |refs: &[bowloc::dataset::ImageRef]| -> Vec<String> {
            refs.iter().map(|r| r.name.clone()).collect()
        };
        assert_eq!(names(&reversed.map), names(&original.queries), "{name}");
        assert_eq!(names(&reversed.queries), names(&original.map), "{name}");
        let swapped: BTreeSet<_> = pairs(&original).into_iter().map(|(q, m)| (m, q)).collect();
        assert!(!swapped.is_empty());
        assert_eq!(pairs(&reversed), swapped, "{name}");
        // the images are the shared ones, reached through the links
        for r in reversed.map.iter().chain(&reversed.queries) {
            assert!(r.path.is_file(), "{} is not there", r.path.display());
        }
    }
}
