//! An ORB pass before SIFT, measured against the service's answers: a
//! prototype of a cheap first look that would answer the easy queries
//! without SIFT. Per query, on the service's 640 px frame: ORB (1000
//! keypoints), each descriptor's binary word (`bowloc::vocabulary::binary`,
//! K words by k-majority over the map's ORB descriptors, drawn with the
//! SIFT vocabulary's seed), tf-idf votes over the map images, and the top 5
//! verified by a similarity (RANSAC, 6 px) on word pairs (each query
//! feature paired with the nearest map feature of its word, at most 64
//! bits away). The pass answers with a verified candidate that has at
//! least `floor` inliers at a scale within e^±`window` of the query's:
//! either the one of those whose scale is nearest the query's
//! (`NearestScale`), or the candidate with the most inliers when it
//! qualifies (`MostInliers`); then the other candidates in vote order.
//!
//! The SIFT map and vocabulary are given; they are loaded and searched as
//! `bowloc serve` loads and searches them with its default configuration
//! (its default rule, extraction plan and verification; one request at a
//! time, so no spare core; image buffers kept mapped, one OpenCV thread).
//! Every query is answered once by the default first, as by a server that
//! has been answering a while (its plan learns). Then, one query after the
//! other on this thread, three timings from the same bytes: the full search
//! on the whole image (`rule=none`, no tiles: what streaming and stopping
//! save against), the service's default, and the pass. A query the pass
//! answers costs its decode and the pass; any other costs the pass (its
//! decode left out: the service would decode once) and the default. It
//! prints, per setting, the queries the pass answered, recall@1 and
//! recall@5 against the full search's, and the median of the per-query
//! ratios of the request time to the full search's, with the default alone
//! beside it (docs/performance.md, "An ORB pass before SIFT").
//!
//! With a fourth argument EVERY, only every EVERY-th query is used (query
//! numbers in the output count those), as `scripts/latency.sh` takes them.
//!
//! ```sh
//! scripts/orb-pass.sh
//! ```

use bowloc::dataset::Dataset;
use bowloc::eval::machine::Cpu;
use bowloc::features::{DecodeLimits, ExtractConfig, TileGrid, decode};
use bowloc::search::SearchOptions;
use bowloc::server::config::Config;
use bowloc::vocabulary::binary::{BinaryDescriptor, BinaryVocabulary, from_rows, hamming};
use opencv::core::{KeyPoint, Mat, Point2f, Vector, no_array};
use opencv::features2d::{ORB, ORB_ScoreType};
use opencv::prelude::*;
use rayon::prelude::*;
use std::collections::HashMap;
use std::time::Instant;

const ORB_FEATURES: i32 = 1000;
const WORDS: usize = 1000;
const ITERATIONS: usize = 8;
const TOP: usize = 5;
/// The pass's settings: (pick, inlier floor, |ln scale| window).
const SETTINGS: [(Pick, usize, f64); 6] = [
    (Pick::NearestScale, 20, 0.1),
    (Pick::NearestScale, 30, 0.1),
    (Pick::MostInliers, 20, 0.05),
    (Pick::MostInliers, 20, 0.1),
    (Pick::MostInliers, 30, 0.1),
    (Pick::MostInliers, 40, 0.1),
];

/// Which verified candidate the pass answers with.
#[derive(Debug, Clone, Copy)]
enum Pick {
    /// Of those with `floor` inliers within the window, the one whose
    /// scale is nearest the query's.
    NearestScale,
    /// The one with the most inliers, if it has `floor` and its scale is
    /// within the window.
    MostInliers,
}

/// One image's ORB keypoint centres and descriptors.
struct Orb {
    centres: Vec<(f32, f32)>,
    descriptors: Vec<BinaryDescriptor>,
}

/// ORB of an image decoded to the frame of `config` (the vocabulary's
/// extraction settings, as the service's); with the time the decode and ORB
/// took (ms).
fn orb_of(
    bytes: &[u8],
    config: &ExtractConfig,
    detector: &mut opencv::core::Ptr<ORB>,
) -> anyhow::Result<(Orb, f64, f64)> {
    let t = Instant::now();
    let image = decode(bytes, DecodeLimits::default(), config.max_side)?;
    let mut frame = bowloc::features::Frame::new(&image, config)?;
    let decode_ms = t.elapsed().as_secs_f64() * 1e3;
    let (mat, _) = frame.parts();
    let t = Instant::now();
    let (mut keys, mut raw) = (Vector::<KeyPoint>::new(), Mat::default());
    detector.detect_and_compute(mat, &no_array(), &mut keys, &mut raw, false)?;
    let descriptors = if raw.empty() {
        Vec::new()
    } else {
        from_rows(raw.data_bytes()?)
    };
    let orb = Orb {
        centres: keys.iter().map(|k| (k.pt().x, k.pt().y)).collect(),
        descriptors,
    };
    Ok((orb, decode_ms, t.elapsed().as_secs_f64() * 1e3))
}

fn detector() -> anyhow::Result<opencv::core::Ptr<ORB>> {
    Ok(ORB::create(
        ORB_FEATURES,
        1.2,
        8,
        31,
        0,
        2,
        ORB_ScoreType::HARRIS_SCORE,
        31,
        20,
    )?)
}

/// tf-idf of a word list: (word, weight) sorted by word, L2-normalised.
fn tf_idf(words: &[u32], idf: &[f32]) -> Vec<(u32, f32)> {
    let mut sorted = words.to_vec();
    sorted.sort_unstable();
    let mut v: Vec<(u32, f32)> = Vec::new();
    for w in sorted {
        match v.last_mut() {
            Some((last, x)) if *last == w => *x += idf[w as usize],
            _ => v.push((w, idf[w as usize])),
        }
    }
    let norm = v.iter().map(|(_, x)| x * x).sum::<f32>().sqrt().max(1e-12);
    v.iter_mut().for_each(|(_, x)| *x /= norm);
    v
}

/// The map's ORB images as an inverted tf-idf index.
struct OrbMap {
    images: Vec<Orb>,
    words_of: Vec<Vec<u32>>,
    postings: Vec<Vec<(u32, f32)>>,
    idf: Vec<f32>,
}

impl OrbMap {
    fn build(images: Vec<Orb>, vocabulary: &BinaryVocabulary) -> Self {
        let words_of: Vec<Vec<u32>> = images
            .par_iter()
            .map(|m| m.descriptors.iter().map(|d| vocabulary.word(d)).collect())
            .collect();
        let mut df = vec![0u32; vocabulary.len()];
        for ws in &words_of {
            let mut seen = ws.clone();
            seen.sort_unstable();
            seen.dedup();
            seen.into_iter().for_each(|w| df[w as usize] += 1);
        }
        let n = images.len() as f32;
        let idf: Vec<f32> = df
            .iter()
            .map(|&d| if d == 0 { 0.0 } else { (n / d as f32).ln() })
            .collect();
        let mut postings = vec![Vec::new(); vocabulary.len()];
        for (image, ws) in words_of.iter().enumerate() {
            for (w, x) in tf_idf(ws, &idf) {
                postings[w as usize].push((image as u32, x));
            }
        }
        Self {
            images,
            words_of,
            postings,
            idf,
        }
    }

    /// The `n` map images of the highest cosine score, best first.
    fn top(&self, words: &[u32], n: usize) -> Vec<usize> {
        let mut score = vec![0f32; self.images.len()];
        for (w, x) in tf_idf(words, &self.idf) {
            for &(image, y) in &self.postings[w as usize] {
                score[image as usize] += x * y;
            }
        }
        let mut order: Vec<usize> = (0..score.len()).collect();
        order.sort_by(|&a, &b| score[b].total_cmp(&score[a]));
        order.truncate(n);
        order
    }

    /// Inliers of a similarity fitted to word pairs from the query to map
    /// image `m`, and its scale.
    fn verify(&self, query: &Orb, words: &[u32], m: usize) -> anyhow::Result<(usize, f64)> {
        let map = &self.images[m];
        let mut by_word: HashMap<u32, Vec<usize>> = HashMap::new();
        for (j, &w) in self.words_of[m].iter().enumerate() {
            by_word.entry(w).or_default().push(j);
        }
        let (mut from, mut to) = (Vector::<Point2f>::new(), Vector::<Point2f>::new());
        for (i, w) in words.iter().enumerate() {
            let nearest = by_word.get(w).and_then(|js| {
                js.iter()
                    .map(|&j| (hamming(&query.descriptors[i], &map.descriptors[j]), j))
                    .min()
            });
            if let Some((h, j)) = nearest
                && h <= 64
            {
                from.push(Point2f::new(query.centres[i].0, query.centres[i].1));
                to.push(Point2f::new(map.centres[j].0, map.centres[j].1));
            }
        }
        if from.len() < 4 {
            return Ok((0, 0.0));
        }
        let mut mask = Mat::default();
        let model = opencv::calib3d::estimate_affine_partial_2d(
            &from,
            &to,
            &mut mask,
            opencv::calib3d::RANSAC,
            6.0,
            2000,
            0.99,
            10,
        )?;
        if model.empty() {
            return Ok((0, 0.0));
        }
        let (a, b) = (*model.at_2d::<f64>(0, 0)?, *model.at_2d::<f64>(1, 0)?);
        Ok((opencv::core::count_non_zero(&mask)? as usize, a.hypot(b)))
    }
}

/// What the pass found for one query: each verified candidate's (inliers,
/// scale, map image) in vote order, and the pass's time after the decode.
struct Pass {
    verified: Vec<(usize, f64, usize)>,
    ms: f64,
}

impl Pass {
    /// The pass's answer under (pick, floor, window), if it answers: that
    /// candidate, then the others in vote order.
    fn answer(&self, pick: Pick, floor: usize, window: f64) -> Option<Vec<usize>> {
        let scale_gap = |s: f64| if s > 0.0 { s.ln().abs() } else { f64::INFINITY };
        let fits = |v: &&(usize, f64, usize)| v.0 >= floor && scale_gap(v.1) <= window;
        let best = match pick {
            Pick::NearestScale => self
                .verified
                .iter()
                .filter(fits)
                .min_by(|a, b| scale_gap(a.1).total_cmp(&scale_gap(b.1)))?,
            Pick::MostInliers => self
                .verified
                .iter()
                .max_by(|a, b| {
                    a.0.cmp(&b.0)
                        .then(scale_gap(b.1).total_cmp(&scale_gap(a.1)))
                })
                .filter(fits)?,
        };
        let rest = self.verified.iter().filter(|v| v.2 != best.2);
        Some(std::iter::once(best.2).chain(rest.map(|v| v.2)).collect())
    }
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v.get(v.len() / 2).copied().unwrap_or(f64::NAN)
}

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let [_, dir, vocab, map_path, rest @ ..] = args.as_slice() else {
        anyhow::bail!("usage: orb_pass DATASET VOCAB.bowvoc MAP.bowmap [EVERY]");
    };
    // every EVERY-th query only (the first, the EVERY+1-th, …), as
    // scripts/latency.sh takes them
    let every: usize = rest.first().map_or(Ok(1), |s| s.parse())?;
    anyhow::ensure!(every > 0, "EVERY must be at least 1");
    // as the binary does: image buffers kept mapped, one OpenCV thread
    bowloc::features::keep_image_buffers();
    bowloc::features::set_opencv_threads(1);
    let mut dataset = Dataset::open(std::path::Path::new(dir))?;
    let keep = |i: &usize| i.is_multiple_of(every);
    dataset.queries = (0..dataset.queries.len())
        .filter(keep)
        .map(|i| dataset.queries[i].clone())
        .collect();
    dataset.truth = (0..dataset.truth.len())
        .filter(keep)
        .map(|i| dataset.truth[i].clone())
        .collect();
    // the service's default configuration on these files
    let mut config = Config::default();
    config.files.vocabulary = vocab.into();
    config.files.map = map_path.into();
    config.bootstrap.enabled = false;
    let localizer = bowloc::server::bootstrap::load(&config, &Default::default())?;
    let default = config.search_options().map_err(anyhow::Error::msg)?;
    let verify = config.verify.enabled;
    let seed = localizer.vocab.meta().seed;
    let read = |r: &bowloc::dataset::ImageRef| std::fs::read(&r.path);
    let map_orb: Vec<Orb> = dataset
        .map
        .par_iter()
        .map(|r| Ok(orb_of(&read(r)?, &localizer.extract, &mut detector()?)?.0))
        .collect::<anyhow::Result<_>>()?;
    let all: Vec<BinaryDescriptor> = map_orb.iter().flat_map(|m| m.descriptors.clone()).collect();
    let vocabulary = BinaryVocabulary::train(&all, WORDS, ITERATIONS, seed);
    let orb_map = OrbMap::build(map_orb, &vocabulary);

    let full = SearchOptions {
        rule: bowloc::search::RuleSpec::new("none", None).map_err(anyhow::Error::msg)?,
        min_features: 0,
        ..default.clone()
    };
    let mut orb = detector()?;
    // the service learns its plan from the requests it answers: one round
    // of every query first, as a server that has been answering a while
    for (q, r) in dataset.queries.iter().enumerate() {
        let default = SearchOptions {
            seed: q as u64 + 1,
            ..default.clone()
        };
        let plan = localizer.plan(&default, None);
        let answer = localizer.localize_tiled(&read(r)?, &default, plan.grid, verify)?;
        localizer.learn(plan, &answer);
    }
    // per query: the pass, the full search's and the default's ranked ids
    // and times (ms)
    let mut rows = Vec::new();
    for (q, r) in dataset.queries.iter().enumerate() {
        let bytes = read(r)?;
        // a seed of its own for each query, as the service draws one
        let default = SearchOptions {
            seed: q as u64 + 1,
            ..default.clone()
        };
        let time = |f: &mut dyn FnMut() -> anyhow::Result<Vec<usize>>| {
            let t = Instant::now();
            let ids = f()?;
            anyhow::Ok((ids, t.elapsed().as_secs_f64() * 1e3))
        };
        let ids =
            |a: bowloc::report::Localization| a.candidates.iter().map(|c| c.id as usize).collect();
        let whole = time(&mut || {
            Ok(ids(localizer.localize_tiled(
                &bytes,
                &full,
                TileGrid::WHOLE,
                verify,
            )?))
        })?;
        let plan = localizer.plan(&default, None);
        let service = time(&mut || {
            let answer = localizer.localize_tiled(&bytes, &default, plan.grid, verify)?;
            localizer.learn(plan, &answer);
            Ok(ids(answer))
        })?;
        let (query, decode_ms, orb_ms) = orb_of(&bytes, &localizer.extract, &mut orb)?;
        let t = Instant::now();
        let words: Vec<u32> = query
            .descriptors
            .iter()
            .map(|d| vocabulary.word(d))
            .collect();
        let verified = orb_map
            .top(&words, TOP)
            .into_iter()
            .map(|m| orb_map.verify(&query, &words, m).map(|(n, s)| (n, s, m)))
            .collect::<anyhow::Result<Vec<_>>>()?;
        let pass = Pass {
            verified,
            ms: orb_ms + t.elapsed().as_secs_f64() * 1e3,
        };
        rows.push((pass, decode_ms, whole, service));
    }

    let cpu = Cpu::here();
    println!(
        "{}: {} queries, {} map images; SIFT K = {}, vocabulary seed {seed}; ORB {ORB_FEATURES} features, K = {WORDS}, top {TOP} verified; {} ({}, {} CPUs), one thread",
        dataset.name,
        dataset.queries.len(),
        dataset.map.len(),
        localizer.vocab.words(),
        cpu.model,
        cpu.instruction_set,
        cpu.cpus
    );
    let recall = |ranked: &[usize], q: usize, n: usize| {
        ranked
            .iter()
            .take(n)
            .any(|&m| dataset.truth[q].contains(&(m as u32)))
    };
    let percent = |hits: usize| 100.0 * hits as f64 / rows.len() as f64;
    let count = |f: &dyn Fn(usize) -> bool| (0..rows.len()).filter(|&q| f(q)).count();
    let full_1 = count(&|q| recall(&rows[q].2.0, q, 1));
    let full_5 = count(&|q| recall(&rows[q].2.0, q, 5));
    println!(
        "full search: recall@1 {:.1}, recall@5 {:.1}, median {:.1} ms",
        percent(full_1),
        percent(full_5),
        median(rows.iter().map(|r| r.2.1).collect())
    );
    let report = |label: &str, answers: &dyn Fn(usize) -> (Vec<usize>, f64), answered: usize| {
        let at_1 = count(&|q| recall(&answers(q).0, q, 1));
        let at_5 = count(&|q| recall(&answers(q).0, q, 5));
        let ratio = median(
            rows.iter()
                .enumerate()
                .map(|(q, r)| answers(q).1 / r.2.1)
                .collect(),
        );
        let times = median((0..rows.len()).map(|q| answers(q).1).collect());
        println!(
            "{label:32} answered by the pass {answered:3}; recall@1 {:.1} ({:+.1}), recall@5 {:.1} ({:+.1}); median {times:.1} ms, median ratio to the full search {ratio:.3}",
            percent(at_1),
            percent(at_1) - percent(full_1),
            percent(at_5),
            percent(at_5) - percent(full_5),
        );
    };
    report("default alone", &|q| rows[q].3.clone(), 0);
    for (pick, floor, window) in SETTINGS {
        let answered = count(&|q| rows[q].0.answer(pick, floor, window).is_some());
        report(
            &format!("{pick:?} {floor}, |ln s| <= {window}"),
            &|q| {
                let (pass, decode_ms, _, service) = &rows[q];
                match pass.answer(pick, floor, window) {
                    Some(ids) => (ids, decode_ms + pass.ms),
                    None => (service.0.clone(), pass.ms + service.1),
                }
            },
            answered,
        );
        // where the pass's answer is wrong and the default's right
        let lost: Vec<String> = (0..rows.len())
            .filter_map(|q| {
                let ids = rows[q].0.answer(pick, floor, window)?;
                (!recall(&ids, q, 1) && recall(&rows[q].3.0, q, 1))
                    .then(|| format!("{q}→{}", ids[0]))
            })
            .collect();
        println!(
            "{:32} wrong where the default is right (query→map image): {}",
            "",
            lost.join(" ")
        );
    }
    println!(
        "the pass alone: median {:.2} ms after a decode of {:.2} ms",
        median(rows.iter().map(|r| r.0.ms).collect()),
        median(rows.iter().map(|r| r.1).collect())
    );
    Ok(())
}
