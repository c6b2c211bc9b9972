//! A live map against a map built from scratch (changes between
//! compactions, compaction, maps without stored features, bad changes), its
//! change log across restarts, torn tails and crashes, and its ids and names.

use super::*;
use crate::geometry::Keypoint;
use crate::geometry::packed::pack_image;
use crate::index::{ImageWords, MapBuilder, MapRead};
use crate::search::{KnownFeatures, RuleSpec, SearchOptions, search_words};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

const WORDS: usize = 60;

fn random_words(rng: &mut ChaCha8Rng, n: usize) -> Vec<u32> {
    (0..n)
        .map(|_| {
            // a skewed law, so df varies across words
            let u: f64 = rng.random();
            ((u * u) * WORDS as f64) as u32
        })
        .collect()
}

fn features(words: &[u32]) -> Vec<crate::geometry::packed::PackedFeature> {
    let kps: Vec<Keypoint> = (0..words.len())
        .map(|i| Keypoint {
            x: i as f32,
            y: 1.0,
            size: 2.0,
            angle: 0.0,
            response: 0.0,
        })
        .collect();
    pack_image(words, &[], &kps)
}

fn new_image(name: &str, words: &[u32]) -> NewImage {
    NewImage {
        name: name.into(),
        place: format!("place of {name}"),
        pose: vec![],
        features: features(words),
        added_at_ms: 1,
    }
}

fn image_words(i: &NewImage) -> ImageWords {
    let words: Vec<u32> = i.features.iter().map(|f| f.word).collect();
    ImageWords {
        geometry: i.features.clone(),
        ..ImageWords::from_words(i.name.clone(), &words)
    }
}

/// 30 file images, 12 added, 5 of the file's removed, one replaced.
struct Scenario {
    file: Vec<NewImage>,
    changes: Vec<Change>,
    /// The images in the map at the end, in id order.
    kept: Vec<NewImage>,
    queries: Vec<Vec<u32>>,
}

fn scenario() -> Scenario {
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let file: Vec<NewImage> = (0..30)
        .map(|j| new_image(&format!("f{j}"), &random_words(&mut rng, 40)))
        .collect();
    let mut changes = Vec::new();
    let mut added = Vec::new();
    for k in 0..12 {
        let i = new_image(&format!("a{k}"), &random_words(&mut rng, 40));
        added.push(i.clone());
        changes.push(Change::Add(i));
    }
    let removed = ["f3", "f4", "f10", "f29", "a2"];
    for name in removed {
        changes.push(Change::Remove { name: name.into() });
    }
    // replacing f7: removed from its place, added at the end
    let f7 = new_image("f7", &random_words(&mut rng, 40));
    changes.push(Change::Add(f7.clone()));
    let kept: Vec<NewImage> = file
        .iter()
        .chain(&added)
        .filter(|i| !removed.contains(&i.name.as_str()) && i.name != "f7")
        .cloned()
        .chain([f7])
        .collect();
    let queries = (0..20).map(|_| random_words(&mut rng, 30)).collect();
    Scenario {
        file,
        changes,
        kept,
        queries,
    }
}

fn file_map(images: &[NewImage]) -> MapIndex {
    let mut b = MapBuilder::new(WORDS);
    for i in images {
        b.add(image_words(i));
    }
    b.build("t", "v", None)
}

/// (name, score) of each answer, for every query, under rule `none`.
fn answers(map: &dyn MapRead, queries: &[Vec<u32>]) -> Vec<Vec<(String, f32)>> {
    let options = SearchOptions {
        rule: RuleSpec::new("relative", Some(0.5)).unwrap(),
        top_n: 8,
        ..SearchOptions::default()
    };
    queries
        .iter()
        .map(|q| {
            search_words(map, KnownFeatures::words(q), &options)
                .candidates
                .iter()
                .map(|c| (map.image(c.id).name.to_owned(), c.score))
                .collect()
        })
        .collect()
}

fn live_with_changes(s: &Scenario) -> Snapshot {
    let mut snapshot = Snapshot::new(Arc::new(file_map(&s.file)));
    for (g, change) in s.changes.iter().enumerate() {
        let record = Record {
            generation: g as u64 + 1,
            change: change.clone(),
        };
        snapshot.apply(&record, usize::MAX).unwrap();
    }
    snapshot
}

#[test]
fn between_compactions_idf_is_frozen_and_changes_search_like_a_map() {
    let s = scenario();
    let live = live_with_changes(&s);
    assert_eq!(live.len(), s.kept.len());
    assert_eq!(live.generation(), s.changes.len() as u64);
    // the same images built from scratch, weighted under the file's idf
    let frozen = file_map(&s.file).view().idf.to_vec();
    let mut b = MapBuilder::new(WORDS);
    for i in &s.kept {
        b.add(image_words(i));
    }
    let scratch = b.build_with_idf(frozen, "t", "v", None);
    let (got, want) = (answers(&live, &s.queries), answers(&scratch, &s.queries));
    assert!(got.iter().all(|a| !a.is_empty()));
    assert_eq!(got, want);
    // removed images are never answered
    assert!(got.iter().flatten().all(|(n, _)| n != "f3" && n != "a2"));
}

#[test]
fn a_compacted_map_answers_like_one_built_from_scratch() {
    let s = scenario();
    let live = live_with_changes(&s);
    let folded = compact::fold(&live);
    assert_eq!(folded.meta().generation, live.generation());
    assert_eq!(folded.images(), s.kept.len());
    let scratch = file_map(&s.kept);
    let (got, want) = (answers(&folded, &s.queries), answers(&scratch, &s.queries));
    assert_eq!(got, want);
    // and the places of added images survive
    let id = folded.images() as u32 - 1;
    assert_eq!(folded.image(id).name, "f7");
    assert_eq!(folded.image(id).place, Some("place of f7"));
}

#[test]
fn a_map_without_stored_features_folds_from_its_postings() {
    let s = scenario();
    let mut b = MapBuilder::new(WORDS);
    for i in &s.file {
        let words: Vec<u32> = i.features.iter().map(|f| f.word).collect();
        b.add(ImageWords::from_words(i.name.clone(), &words));
    }
    let snapshot = Snapshot::new(Arc::new(b.build("t", "v", None)));
    let folded = compact::fold(&snapshot);
    assert_eq!(answers(&folded, &s.queries), answers(&snapshot, &s.queries));
}

#[test]
fn bad_changes_change_nothing() {
    let s = scenario();
    let mut live = Snapshot::new(Arc::new(file_map(&s.file)));
    let before = answers(&live, &s.queries);
    let remove = |name: &str| Record {
        generation: 1,
        change: Change::Remove { name: name.into() },
    };
    assert!(matches!(
        live.apply(&remove("nope"), usize::MAX),
        Err(ApplyError::NotFound(_))
    ));
    let add = Record {
        generation: 1,
        change: Change::Add(new_image("new", &[1, 2])),
    };
    assert!(matches!(live.apply(&add, 30), Err(ApplyError::Full(30))));
    let mut bad_pose = new_image("new", &[1]);
    bad_pose.pose = vec![1.0];
    let bad = Record {
        generation: 1,
        change: Change::Add(bad_pose),
    };
    assert!(matches!(
        live.apply(&bad, usize::MAX),
        Err(ApplyError::Invalid(_))
    ));
    assert_eq!(live.generation(), 0);
    assert_eq!(answers(&live, &s.queries), before);
}

fn saved(dir: &Path, images: &[NewImage]) -> PathBuf {
    let path = dir.join("m.bowmap");
    file_map(images).save(&path).unwrap();
    path
}

/// The scenario's file images saved as a map in a fresh folder (kept alive
/// by the returned guard).
fn scenario_saved() -> (Scenario, tempfile::TempDir, PathBuf) {
    let s = scenario();
    let dir = tempfile::tempdir().unwrap();
    let path = saved(dir.path(), &s.file);
    (s, dir, path)
}

fn names(live: &LiveMap) -> Vec<String> {
    let s = live.snapshot();
    s.ids().map(|id| s.image(id).name.to_owned()).collect()
}

#[test]
fn changes_survive_a_restart_a_torn_tail_and_a_compaction() {
    let (s, _dir, path) = scenario_saved();
    let (live, opened) = LiveMap::open(&path, None, true, usize::MAX).unwrap();
    assert_eq!(opened.replayed, 0);
    assert!(
        live.status().last_compaction.is_none(),
        "a built map was never compacted"
    );
    let held = live.snapshot();
    for change in &s.changes {
        live.apply(change.clone()).unwrap();
    }
    // a query's snapshot does not move under it
    assert_eq!(held.len(), s.file.len());
    let want: Vec<String> = s.kept.iter().map(|i| i.name.clone()).collect();
    let mut sorted_want = want.clone();
    sorted_want.sort();
    let sorted = |mut v: Vec<String>| {
        v.sort();
        v
    };
    assert_eq!(sorted(names(&live)), sorted_want);
    let answers_before = answers(&*live.snapshot(), &s.queries);
    drop(live);

    // a torn record at the end
    let log = log::path_for(&path);
    let mut bytes = std::fs::read(&log).unwrap();
    bytes.extend_from_slice(&[9, 0, 0, 0, 1, 2]);
    std::fs::write(&log, &bytes).unwrap();
    let (live, opened) = LiveMap::open(&path, None, true, usize::MAX).unwrap();
    assert_eq!(opened.replayed, s.changes.len());
    assert!(opened.dropped.is_some());
    assert_eq!(sorted(names(&live)), sorted_want);
    assert_eq!(answers(&*live.snapshot(), &s.queries), answers_before);
    assert_eq!(live.status().generation, s.changes.len() as u64);

    // compaction: the file holds everything, the log nothing
    let done = live.compact().unwrap().unwrap();
    assert_eq!(done.images, s.kept.len());
    assert_eq!(live.status().log_records, Some(0));
    assert_eq!(names(&live), want);
    assert!(live.compact().unwrap().is_none(), "nothing left to fold");
    assert!(done.seconds.is_some());
    live.apply(Change::Remove { name: "f0".into() }).unwrap();
    drop(live);
    let (live, opened) = LiveMap::open(&path, None, true, usize::MAX).unwrap();
    // the map file remembers its compaction across the restart
    let last = live
        .status()
        .last_compaction
        .expect("compaction after a restart");
    assert_eq!(last.at_ms, done.at_ms);
    assert_eq!(last.generation, done.generation);
    assert_eq!(last.images, done.images);
    assert_eq!(last.seconds, None);
    assert_eq!(opened.replayed, 1);
    assert_eq!(live.status().generation, s.changes.len() as u64 + 1);
    assert_eq!(live.status().file_generation, s.changes.len() as u64);
    assert_eq!(names(&live).len(), s.kept.len() - 1);
}

#[test]
fn a_crash_between_writing_the_compacted_map_and_emptying_the_log_loses_nothing() {
    let (s, _dir, path) = scenario_saved();
    let (live, _) = LiveMap::open(&path, None, true, usize::MAX).unwrap();
    for change in &s.changes {
        live.apply(change.clone()).unwrap();
    }
    let want = names(&live);
    // the first step of a compaction only
    compact::fold(&live.snapshot()).save(&path).unwrap();
    drop(live);
    let (live, opened) = LiveMap::open(&path, None, true, usize::MAX).unwrap();
    assert!(opened.reset && opened.replayed == 0);
    assert_eq!(names(&live), want);
    assert_eq!(live.status().log_records, Some(0));
}

#[test]
fn a_log_of_another_map_is_refused() {
    let (s, dir, path) = scenario_saved();
    let (live, _) = LiveMap::open(&path, None, true, usize::MAX).unwrap();
    live.apply(s.changes[0].clone()).unwrap();
    drop(live);
    saved(dir.path(), &s.file[..10]); // the map rebuilt
    let e = LiveMap::open(&path, None, true, usize::MAX)
        .err()
        .unwrap()
        .to_string();
    assert!(e.contains("another map file"), "{e}");
}

#[test]
fn a_fixed_map_takes_no_changes() {
    let s = scenario();
    let live = LiveMap::fixed(file_map(&s.file));
    assert!(matches!(
        live.apply(s.changes[0].clone()),
        Err(WriteError::ReadOnly)
    ));
}

#[test]
fn ids_run_past_the_image_count_once_images_were_removed_and_added() {
    let s = scenario();
    let live = live_with_changes(&s);
    let adds = s
        .changes
        .iter()
        .filter(|c| matches!(c, Change::Add(_)))
        .count();
    assert_eq!(live.id_range(), s.file.len() + adds);
    // fewer images than ids: code sized by the count would miss the last ids
    assert!(live.meta().images < live.id_range());
    let last = live.ids().last().unwrap();
    assert!(live.contains(last) && last as usize >= live.meta().images);
}

#[test]
fn names_find_the_images_in_the_map_and_only_those() {
    let s = scenario();
    let live = live_with_changes(&s);
    for (id, i) in live.ids().zip(&s.kept) {
        assert_eq!(live.id_of(&i.name), Some(id), "{}", i.name);
    }
    assert_eq!(live.len(), s.kept.len());
    assert_eq!(live.len(), live.ids().count());
    // removed ones, from the file and added
    for name in ["f3", "f29", "a2", "nope", ""] {
        assert_eq!(live.id_of(name), None, "{name}");
    }
    // replaced: the added image, not the file's
    assert!(live.id_of("f7").unwrap() as usize >= s.file.len());
    // a snapshot taken before a change keeps its names
    let before = Snapshot::new(Arc::new(file_map(&s.file)));
    assert!(before.id_of("f3").is_some());
    let mut after = before.clone();
    let remove = Record {
        generation: 1,
        change: Change::Remove { name: "f3".into() },
    };
    after.apply(&remove, usize::MAX).unwrap();
    assert_eq!((before.id_of("f3"), after.id_of("f3")), (Some(3), None));
}

#[test]
fn of_two_file_images_of_one_name_the_later_is_found() {
    let mut images: Vec<NewImage> = (0..5).map(|j| new_image(&format!("i{j}"), &[j])).collect();
    images[3].name = "i1".into();
    let live = Snapshot::new(Arc::new(file_map(&images)));
    assert_eq!(live.id_of("i1"), Some(3));
    assert_eq!(live.id_of("i4"), Some(4));
    assert_eq!(live.id_of("i3"), None);
}

#[test]
fn a_corrupt_first_record_is_reported_though_nothing_is_replayed() {
    let (s, _dir, path) = scenario_saved();
    let (live, _) = LiveMap::open(&path, None, true, usize::MAX).unwrap();
    for change in &s.changes[..3] {
        live.apply(change.clone()).unwrap();
    }
    drop(live);
    let log = log::path_for(&path);
    let mut bytes = std::fs::read(&log).unwrap();
    bytes[log::HEADER_LEN + 8] ^= 0x40; // the first record's payload
    std::fs::write(&log, &bytes).unwrap();
    let (live, opened) = LiveMap::open(&path, None, true, usize::MAX).unwrap();
    assert_eq!(opened.replayed, 0);
    let why = opened.dropped.expect("the cut reported");
    assert!(why.contains("after record 0"), "{why}");
    assert_eq!(live.snapshot().len(), s.file.len());
}

#[test]
fn an_empty_log_of_the_map_is_kept_and_its_torn_tail_cut() {
    use std::os::unix::fs::MetadataExt;
    let (s, _dir, path) = scenario_saved();
    let log = log::path_for(&path);
    drop(LiveMap::open(&path, None, true, usize::MAX).unwrap());
    let inode = std::fs::metadata(&log).unwrap().ino();
    let mut bytes = std::fs::read(&log).unwrap();
    bytes.extend_from_slice(&[9, 0, 0]);
    std::fs::write(&log, &bytes).unwrap();
    let (live, opened) = LiveMap::open(&path, None, true, usize::MAX).unwrap();
    assert!(opened.dropped.is_some() && !opened.reset && opened.replayed == 0);
    assert_eq!(
        std::fs::metadata(&log).unwrap().ino(),
        inode,
        "not rewritten"
    );
    assert_eq!(std::fs::read(&log).unwrap().len(), log::HEADER_LEN);
    live.apply(s.changes[0].clone()).unwrap();
    drop(live);
    let (_, opened) = LiveMap::open(&path, None, true, usize::MAX).unwrap();
    assert_eq!(opened.replayed, 1);
}

/// A map file of 3 images with pose fields `y, x` (image 1 has none), image
/// 0 removed and one image added at (7, 8).
pub(crate) fn posed_snapshot() -> Snapshot {
    let mut b = MapBuilder::new(WORDS);
    for j in 0..3 {
        b.add(ImageWords::from_words(format!("f{j}"), &[1, 2, 3]));
    }
    let mut places = crate::index::Places {
        pose_fields: vec!["y".into(), "x".into()],
        ..Default::default()
    };
    places
        .rows
        .insert("f0".into(), (String::new(), vec![2.0, 1.0]));
    places
        .rows
        .insert("f2".into(), (String::new(), vec![6.0, 5.0]));
    let mut s = Snapshot::new(Arc::new(b.build("t", "v", Some(&places))));
    let mut added = new_image("a", &[1, 2]);
    added.pose = vec![8.0, 7.0];
    for (g, change) in [Change::Remove { name: "f0".into() }, Change::Add(added)]
        .into_iter()
        .enumerate()
    {
        let record = Record {
            generation: g as u64 + 1,
            change,
        };
        s.apply(&record, usize::MAX).unwrap();
    }
    s
}

#[test]
fn positions_run_over_the_id_range_with_added_images() {
    let s = posed_snapshot();
    let positions = s.positions().unwrap();
    assert_eq!(positions.len(), s.id_range());
    assert_eq!(positions[0], [1.0, 2.0]); // removed, still at its id
    assert!(positions[1].iter().all(|v| v.is_nan()));
    assert_eq!(positions[2], [5.0, 6.0]);
    assert_eq!(positions[3], [7.0, 8.0]);
    let mut ids = Vec::new();
    assert!(s.each_position(&mut |j, _| ids.push(j)));
    assert_eq!(ids, [0, 1, 2, 3]);
    let plain = Snapshot::new(Arc::new(file_map(&scenario().file)));
    assert!(plain.positions().is_none());
    assert!(!plain.each_position(&mut |_, _| panic!("no positions")));
}

#[test]
fn the_auto_warm_up_follows_the_images_in_the_map() {
    // 30 file images of 40 features: a quarter of the median
    let s = scenario();
    let mut snapshot = Snapshot::new(Arc::new(file_map(&s.file)));
    assert_eq!(snapshot.auto_warmup(), 10);
    // 40 larger images added: the median moves to theirs, the cap holds
    let mut rng = ChaCha8Rng::seed_from_u64(9);
    for k in 0..40 {
        let record = Record {
            generation: k + 1,
            change: Change::Add(new_image(&format!("big{k}"), &random_words(&mut rng, 600))),
        };
        snapshot.apply(&record, usize::MAX).unwrap();
    }
    assert_eq!(snapshot.auto_warmup(), crate::calibrate::MAX_WARMUP);
}
