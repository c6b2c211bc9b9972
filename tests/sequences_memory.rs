//! The service's sequence state stays bounded: 10 000 distinct sequence
//! names, each with a full belief, under a cap of 1 000 sequences, then
//! 10 000 under a cap of 10 000; prints the resident memory (RSS from
//! /proc/self/status) before and after each (`scripts/sequence-memory.sh`).

use bowloc::search::prior::posterior;
use bowloc::sequence::{SequenceModel, Topology};
use bowloc::server::sequences::Sequences;
use std::time::Duration;

fn rss_kib() -> u64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("VmRSS:"))
                .and_then(|l| l.split_whitespace().nth(1)?.parse().ok())
        })
        .unwrap_or(0)
}

/// Send one frame to each of `names` sequences; returns the live count.
fn fill(store: &Sequences, names: usize, map_images: usize) -> usize {
    let model = SequenceModel::default();
    let topology = Topology::Order { images: map_images };
    // votes spread over many images, so every belief tracks `track` images
    let hist: Vec<f32> = (0..map_images).map(|j| (j % 97) as f32).collect();
    let touched: Vec<u32> = (0..map_images as u32).collect();
    for i in 0..names {
        let slot = store.slot(&format!("robot-{i}"));
        let mut filter = slot.try_lock().expect("no one else holds it");
        let p = filter.predict(&model, &topology, None);
        filter.update(posterior(&p.prior, &hist, &touched, 100, model.track), &p);
        assert_eq!(filter.belief().unwrap().top.len(), model.track);
    }
    store.len()
}

#[test]
fn ten_thousand_sequences_stay_bounded() {
    let map_images = 10_000;
    for cap in [1_000, 10_000] {
        let store = Sequences::new(cap, Duration::from_secs(600));
        let before = rss_kib();
        let live = fill(&store, 10_000, map_images);
        let after = rss_kib();
        assert_eq!(live, cap.min(10_000));
        let per = (after.saturating_sub(before)) as f64 * 1024.0 / live as f64;
        println!(
            "cap {cap}: 10000 sequence names, {live} live on a {map_images}-image map: \
             RSS {before} KiB before, {after} KiB after (+{} KiB, {per:.0} bytes a sequence)",
            after.saturating_sub(before)
        );
        // a belief of 64 tracked images, not one of 10 000: far below the
        // 160 kB a dense belief over the map would take
        assert!(per < 16_384.0, "{per} bytes a sequence");
    }
}
