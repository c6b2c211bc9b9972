//! Live maps on a synthetic map of 10 000 images (K = 5 000 words, 300
//! features per image, Zipf word law, stored geometry like a real map):
//!
//! 0. opening the map: with its (empty) change log, read only
//!    (`LiveMap::fixed`), and the map file alone (`MapIndex::open`),
//!    interleaved, 21 each, medians; then the first lookup by name;
//! 1. adds excluding SIFT: weighting, the change log's append and fsync,
//!    publishing the snapshot — 1 000 adds (10 % of the map), median and
//!    90th percentile, and the median of the first and last 100 (the cost of
//!    an add must not grow with the changes before it); and the same change
//!    applied in memory only (no log), to tell the two parts apart;
//! 2. search latency (words known: no SIFT, no quantization) of 1 000-feature
//!    queries, rule `none` (every feature votes) and the default rule,
//!    with those 1 000 images in the change log against the compacted map,
//!    interleaved query by query; medians and their ratio;
//! 3. compaction of the 11 000-image map (fold, atomic write, reopen), three
//!    times, median.
//!
//! `cargo bench --bench live`; `BOWLOC_BENCH_IMAGES=2000` for a smaller map.

use bowloc::geometry::Keypoint;
use bowloc::geometry::packed::pack_image;
use bowloc::index::synthetic::zipf_query;
use bowloc::index::{ImageWords, MapBuilder, MapIndex};
use bowloc::live::{Change, LiveMap, NewImage};
use bowloc::search::{KnownFeatures, RuleSpec, SearchOptions, search_words};
use std::hint::black_box;
use std::time::{Duration, Instant};

const WORDS: usize = 5_000;
const FEATURES: usize = 300;
const QUERY_FEATURES: usize = 1_000;

fn keypoints(n: usize) -> Vec<Keypoint> {
    (0..n)
        .map(|i| Keypoint {
            x: (i % 640) as f32,
            y: (i / 640) as f32,
            size: 4.0,
            angle: 0.0,
            response: 0.0,
        })
        .collect()
}

fn median(v: &mut [Duration]) -> Duration {
    v.sort_unstable();
    v[v.len() / 2]
}

fn ms(d: Duration) -> f64 {
    d.as_secs_f64() * 1e3
}

fn main() {
    // `cargo bench` passes --bench; nothing to filter here
    let images: usize = std::env::var("BOWLOC_BENCH_IMAGES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(10_000);
    let added = images / 10;
    let kps = keypoints(FEATURES);
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("zipf.bowmap");
    let mut b = MapBuilder::new(WORDS);
    for j in 0..images {
        let words = zipf_query(WORDS, FEATURES, j as u64);
        b.add(ImageWords::with_geometry(
            format!("file/{j}"),
            &words,
            &[],
            &kps,
        ));
    }
    b.build("zipf", "synthetic", None).save(&path).unwrap();
    println!("map: {images} images, {WORDS} words, {FEATURES} features per image; {added} adds");

    // 0. open
    let mut opens = [Vec::new(), Vec::new(), Vec::new()];
    for round in 0..21 {
        for which in [0, 1, 2].map(|k| (k + round) % 3) {
            let started = Instant::now();
            match which {
                0 => drop(black_box(
                    LiveMap::open(&path, None, false, usize::MAX).unwrap(),
                )),
                1 => drop(black_box(LiveMap::fixed(
                    MapIndex::open(&path, false).unwrap(),
                ))),
                _ => drop(black_box(MapIndex::open(&path, false).unwrap())),
            }
            opens[which].push(started.elapsed());
        }
    }
    let [with_log, fixed, file] = opens.map(|mut t| median(&mut t));
    println!(
        "open (median of 21): with its change log {:.3} ms, without (read only) {:.3} ms, map file alone {:.3} ms",
        ms(with_log),
        ms(fixed),
        ms(file),
    );

    let (live, _) = LiveMap::open(&path, None, false, usize::MAX).unwrap();
    let started = Instant::now();
    assert_eq!(live.snapshot().id_of("file/7"), Some(7));
    println!(
        "first lookup by name (sorts the file's names): {:.3} ms",
        ms(started.elapsed())
    );

    // 1. adds
    let mut times = Vec::with_capacity(added);
    let mut in_memory = Vec::with_capacity(added);
    for k in 0..added {
        let words = zipf_query(WORDS, FEATURES, 1_000_000 + k as u64);
        let change = Change::Add(NewImage {
            name: format!("added/{k}"),
            place: String::new(),
            pose: Vec::new(),
            features: pack_image(&words, &[], &kps),
            added_at_ms: 0,
        });
        // the same change applied in memory only (no log): the part
        // before the append and fsync
        let record = bowloc::live::Record {
            generation: u64::MAX,
            change: change.clone(),
        };
        let started = Instant::now();
        let mut copy = bowloc::live::Snapshot::clone(&live.snapshot());
        copy.apply(&record, usize::MAX).unwrap();
        in_memory.push(started.elapsed());
        drop(copy);
        let started = Instant::now();
        live.apply(change).unwrap();
        times.push(started.elapsed());
    }
    let mem_first = median(&mut in_memory[..100.min(added)].to_vec());
    let mem_last = median(&mut in_memory[added.saturating_sub(100)..].to_vec());
    println!(
        "add in memory (weigh, copy-on-write, no log): median {:.3} ms; first 100 median {:.3} ms, last 100 median {:.3} ms",
        ms(median(&mut in_memory)),
        ms(mem_first),
        ms(mem_last)
    );
    let first = median(&mut times[..100.min(added)].to_vec());
    let last = median(&mut times[added.saturating_sub(100)..].to_vec());
    let mut all = times.clone();
    let med = median(&mut all);
    let p90 = all[all.len() * 9 / 10];
    println!(
        "add (no SIFT, fsync included): median {:.3} ms, p90 {:.3} ms; first 100 median {:.3} ms, last 100 median {:.3} ms",
        ms(med),
        ms(p90),
        ms(first),
        ms(last)
    );

    // 2. search with the changes in the log against the compacted map
    let with_changes = live.snapshot();
    let compacted_path = dir.path().join("compacted.bowmap");
    bowloc::live::compact::fold(&with_changes)
        .save(&compacted_path)
        .unwrap();
    let compacted = MapIndex::open(&compacted_path, false).unwrap();
    let queries: Vec<Vec<u32>> = (0..60)
        .map(|q| zipf_query(WORDS, QUERY_FEATURES, 5_000_000 + q))
        .collect();
    for (rule, parameter) in [("none", None), ("relative", Some(2.5))] {
        let options = SearchOptions {
            rule: RuleSpec::new(rule, parameter).unwrap(),
            min_features: if rule == "none" { 0 } else { 100 },
            ..SearchOptions::default()
        };
        let (mut live_t, mut file_t) = (Vec::new(), Vec::new());
        // the snapshot's flat copy of the added postings, built once
        let started = Instant::now();
        black_box(with_changes.overlay().flat());
        if rule == "none" {
            println!(
                "flat copy of the {added} added images' postings, built by a snapshot's first query: {:.3} ms",
                ms(started.elapsed())
            );
        }
        for round in 0..3 {
            for q in &queries {
                // alternate which goes first
                for which in [round % 2, 1 - round % 2] {
                    let started = Instant::now();
                    if which == 0 {
                        black_box(search_words(
                            &*with_changes,
                            KnownFeatures::words(q),
                            &options,
                        ));
                        live_t.push(started.elapsed());
                    } else {
                        black_box(search_words(&compacted, KnownFeatures::words(q), &options));
                        file_t.push(started.elapsed());
                    }
                }
            }
        }
        let (l, f) = (median(&mut live_t), median(&mut file_t));
        println!(
            "search, rule {rule}, {QUERY_FEATURES}-feature queries: {added} images in the log {:.3} ms, compacted {:.3} ms (median of {}); ratio {:.3}",
            ms(l),
            ms(f),
            live_t.len(),
            l.as_secs_f64() / f.as_secs_f64()
        );
    }

    // 3. compaction
    let mut compactions = Vec::new();
    for k in 0..3 {
        let words = zipf_query(WORDS, FEATURES, 9_000_000 + k);
        live.apply(Change::Add(NewImage {
            name: format!("extra/{k}"),
            place: String::new(),
            pose: Vec::new(),
            features: pack_image(&words, &[], &kps),
            added_at_ms: 0,
        }))
        .unwrap();
        let started = Instant::now();
        live.compact().unwrap();
        compactions.push(started.elapsed());
    }
    let images_now = live.snapshot().len();
    println!(
        "compaction of {images_now} images (fold, atomic write, reopen): median {:.0} ms of {:?} ms",
        ms(median(&mut compactions.clone())),
        compactions
            .iter()
            .map(|d| ms(*d).round())
            .collect::<Vec<_>>()
    );
}
