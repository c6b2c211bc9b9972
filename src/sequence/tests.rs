//! The sequence filter on simulated cameras: noisy vote evidence along a
//! route, kidnapping, driving past its end, out-of-order frames and gaps.

use super::*;
use crate::search::prior::posterior;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Votes of a frame taken at image `at`: noise everywhere, and a peak at
/// `at` — or, for an ambiguous frame, at `decoy` instead.
fn votes(rng: &mut ChaCha8Rng, images: usize, peak_at: usize) -> Vec<f32> {
    let mut h: Vec<f32> = (0..images).map(|_| rng.random_range(0.0..3.0)).collect();
    h[peak_at] += 8.0;
    if peak_at + 1 < images {
        h[peak_at + 1] += 2.0;
    }
    h
}

struct Run {
    filtered: usize,
    single: usize,
    frames: usize,
}

/// Drive a filter along `path` (the true image of each frame), with each
/// frame's peak at the truth with probability `reliable`, else elsewhere.
fn run(path: &[usize], reliable: f64, seed: u64, mut visit: impl FnMut(usize, u32)) -> Run {
    let images = 200;
    // the synthetic votes' scale: a weaker evidence weight than the default
    let model = SequenceModel {
        kappa: 0.5,
        ..SequenceModel::default()
    };
    let topology = Topology::Order { images };
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut filter = Filter::new();
    let touched: Vec<u32> = (0..images as u32).collect();
    let (mut filtered, mut single) = (0, 0);
    for (f, &truth) in path.iter().enumerate() {
        let peak = if rng.random_bool(reliable) {
            truth
        } else {
            rng.random_range(0..images)
        };
        let h = votes(&mut rng, images, peak);
        let prediction = filter.predict(&model, &topology, None);
        let post = posterior(&prediction.prior, &h, &touched, 1, model.track);
        let alone = posterior(&Prior::uniform(images, model.kappa), &h, &touched, 1, 1);
        let near = |j: u32| (j as i64 - truth as i64).abs() <= 1;
        let leader = post.leader().unwrap().0;
        filtered += near(leader) as usize;
        single += near(alone.leader().unwrap().0) as usize;
        visit(f, leader);
        filter.update(post, &prediction);
        assert!(filter.belief().unwrap().top.len() <= model.track);
    }
    Run {
        filtered,
        single,
        frames: path.len(),
    }
}

#[test]
fn the_filter_recovers_a_path_from_noisy_evidence() {
    let path: Vec<usize> = (0..150).map(|f| 20 + f).collect();
    for seed in 0..5 {
        let r = run(&path, 0.6, seed, |_, _| {});
        let (filtered, single) = (
            r.filtered as f64 / r.frames as f64,
            r.single as f64 / r.frames as f64,
        );
        assert!(single < 0.75, "seed {seed}: frames alone {single}");
        assert!(
            filtered > 0.85 && filtered > single + 0.25,
            "seed {seed}: filtered {filtered} vs alone {single}"
        );
    }
}

/// Frames after `from` until the filter's leader is within one image of the
/// camera on `path` (reliable frames), for each of 5 seeds.
fn frames_to_find(path: &[usize], from: usize) -> Vec<usize> {
    (0..5)
        .map(|seed| {
            let mut back = None;
            run(path, 0.9, seed, |f, leader| {
                if f >= from && back.is_none() && (leader as i64 - path[f] as i64).abs() <= 1 {
                    back = Some(f - from);
                }
            });
            back.unwrap_or_else(|| panic!("seed {seed}: never found again"))
        })
        .collect()
}

#[test]
fn the_filter_follows_a_kidnapped_camera_within_a_few_frames() {
    // the camera walks 10..90, then is carried to 150 and walks on
    let path: Vec<usize> = (0..80)
        .map(|f| 10 + f)
        .chain((0..30).map(|f| 150 + f))
        .collect();
    let back = frames_to_find(&path, 80);
    assert!(
        back.iter().all(|&b| b <= 4),
        "recovered after {back:?} frames"
    );
}

#[test]
fn a_camera_driving_past_the_routes_end_is_found_at_its_start() {
    // a loop: the camera drives 170..199, on past the map's last image, and
    // round to 0..30 again (the order topology knows no loop closure)
    let path: Vec<usize> = (170..200).chain(0..30).collect();
    let back = frames_to_find(&path, 30);
    assert!(
        back.iter().all(|&b| b <= 1),
        "found again after {back:?} frames"
    );
}

#[test]
fn out_of_order_frames_and_long_gaps_restart() {
    let model = SequenceModel::default();
    let topology = Topology::Order { images: 50 };
    let mut filter = Filter::new();
    let h = vec![0.0f32; 50];
    let step = |frame: Option<u64>, filter: &mut Filter| {
        let p = filter.predict(&model, &topology, frame);
        let mut hist = h.clone();
        hist[20] = 20.0;
        filter.update(posterior(&p.prior, &hist, &[20], 1, model.track), &p);
        (p.restart, p.steps, p.prior)
    };
    assert_eq!(step(Some(5), &mut filter).0, Some(Restart::First));
    let (restart, steps, prior) = step(Some(7), &mut filter);
    assert_eq!((restart, steps), (None, 2));
    // the prediction spreads around image 20
    assert!(prior.of(20) > prior.of(30) && prior.of(21) > prior.of(24));
    assert_eq!(step(None, &mut filter).1, 1); // frame 8
    assert_eq!(filter.last_frame(), Some(8));
    assert_eq!(step(Some(8), &mut filter).0, Some(Restart::OutOfOrder));
    assert_eq!(filter.frames(), 1);
    assert_eq!(step(Some(8 + 11), &mut filter).0, Some(Restart::Gap));
    let (restart, _, prior) = step(Some(20), &mut filter);
    assert_eq!(restart, None);
    assert!(filter.heap_bytes() < 64 * 16 + 128);
    assert!(prior.tracked().len() <= model.track);
}

#[test]
fn prediction_keeps_probability_mass() {
    let model = SequenceModel::default();
    let topology = Topology::Order { images: 30 };
    let belief = Posterior {
        top: vec![(0, 0.5), (10, 0.3)],
        rest: 0.2,
        images: 30,
    };
    let prior = predict(&belief, &model, &topology, 1);
    let total: f64 = (0..30).map(|j| prior.of(j)).sum();
    assert!((total - 1.0).abs() < 1e-9);
    assert!(prior.of(0) > prior.of(10) && prior.of(10) > prior.of(20));
    assert!(prior.of(20) > 0.0);
}
