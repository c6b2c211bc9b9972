//! An ORB pass before SIFT, measured against the service's answers: a
//! prototype of a cheap first look that would answer the easy queries
//! without SIFT. Per query, on the service's 640 px frame: ORB (1000
//! keypoints, spread over a grid of cells, `ORB_PASS_GRID`), each
//! descriptor's binary word (`bowloc::vocabulary::binary`, K words by
//! k-majority over the map's ORB descriptors, drawn with the SIFT
//! vocabulary's seed), tf-idf votes over the map images, and the top 10
//! (`ORB_PASS_TOP`) verified by a similarity (RANSAC, 6 px, OpenCV's
//! generator seeded per query) on word pairs (each query feature paired
//! with the nearest map feature of its word, at most 64 bits away). A
//! [`Setting`] says when the pass answers and with which verified
//! candidate (its inliers, its scale against the query's, the places of
//! the others); the answer lists that candidate, then the others in vote
//! order.
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
//! prints, for a few settings, the queries the pass answered, recall@1 and
//! recall@5 against the full search's, the median of the per-query ratios
//! of the request time to the full search's, with the default alone beside
//! them (and the ratio of the medians, the figure `scripts/latency.sh`
//! leads with), and the queries a setting gets wrong where the default is
//! right;
//! then one tab-separated `sweep` line for every setting of the sweep,
//! which `scripts/orb-pass.sh` chooses from (docs/performance.md, "An ORB
//! pass before SIFT").
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
use bowloc::index::build::{ImageWords, MapBuilder, weigh};
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
/// Candidates verified, in vote order (`ORB_PASS_TOP`, default 10).
fn top_from_env() -> anyhow::Result<usize> {
    match std::env::var("ORB_PASS_TOP") {
        Err(_) => Ok(10),
        Ok(v) => v
            .parse()
            .ok()
            .filter(|&n| n > 0)
            .ok_or_else(|| anyhow::anyhow!("ORB_PASS_TOP={v}: want a positive count")),
    }
}
/// The settings printed in full, each with the queries it gets wrong where
/// the default is right (the sweep prints every setting in one line).
const SETTINGS: [Setting; 6] = [
    Setting::new(Pick::NearestScale { share: 0.0 }, 20, 0.1, 0.0),
    Setting::new(Pick::NearestScale { share: 0.0 }, 15, 0.2, 0.0),
    Setting::new(Pick::NearestScale { share: 0.7 }, 15, 0.2, 0.0),
    Setting::new(Pick::NearestScale { share: 0.9 }, 20, 0.3, 0.0),
    Setting::new(Pick::MostInliers, 20, 0.1, 0.0),
    Setting {
        agree: true,
        ..Setting::new(Pick::NearestScale { share: 0.7 }, 10, 0.2, 0.0)
    },
];
/// The sweep's picks, inlier floors, windows and margins, each with and
/// without `agree` (every combination: 1890 settings).
const SWEEP_PICKS: [Pick; 9] = [
    Pick::Refined { share: 0.5 },
    Pick::Refined { share: 0.7 },
    Pick::Refined { share: 0.9 },
    Pick::NearestScale { share: 0.0 },
    Pick::NearestScale { share: 0.5 },
    Pick::NearestScale { share: 0.7 },
    Pick::NearestScale { share: 0.9 },
    Pick::NearestScale { share: 1.0 },
    Pick::MostInliers,
];
const SWEEP_FLOORS: [usize; 7] = [10, 12, 15, 20, 25, 30, 40];
const SWEEP_WINDOWS: [f64; 5] = [0.05, 0.1, 0.15, 0.2, 0.3];
const SWEEP_MARGINS: [f64; 3] = [0.0, 1.0, 1.25];
/// Map images more than this many apart are other places (the sequence
/// the map was taken in; gardens-point's ground truth tolerance).
const PLACE_APART: usize = 2;

/// One setting of the pass: which verified candidate it answers with, the
/// inliers it needs, how far from the query's its scale may be
/// (|ln s| ≤ `window`), and the margin over other places: the pick must
/// have at least `margin` times the inliers of every verified candidate
/// more than `PLACE_APART` map images away (0: no such check); with
/// `agree`, the pick must also lie within `PLACE_APART` map images of the
/// votes' first candidate.
#[derive(Debug, Clone, Copy)]
struct Setting {
    pick: Pick,
    floor: usize,
    window: f64,
    margin: f64,
    agree: bool,
}

impl Setting {
    /// How the output names it: `nearest-0.7 15, |ln s| <= 0.2, margin 0`
    /// (and `, agree`).
    fn label(self) -> String {
        format!(
            "{} {}, |ln s| <= {}, margin {}{}",
            self.pick.name(),
            self.floor,
            self.window,
            self.margin,
            if self.agree { ", agree" } else { "" }
        )
    }

    const fn new(pick: Pick, floor: usize, window: f64, margin: f64) -> Self {
        Self {
            pick,
            floor,
            window,
            margin,
            agree: false,
        }
    }
}

/// Which verified candidate the pass answers with.
#[derive(Debug, Clone, Copy)]
enum Pick {
    /// Of those with `floor` inliers within the window and at least
    /// `share` of the most inliers among them, the one whose scale is
    /// nearest the query's.
    NearestScale { share: f64 },
    /// The one with the most inliers, if it has `floor` and its scale is
    /// within the window.
    MostInliers,
    /// The place of the one with the most inliers, refined by scale: of it
    /// and the verified candidates within `PLACE_APART` map images of it
    /// with at least `share` of its inliers, the one whose scale is nearest
    /// the query's, if it has `floor` and its scale is within the window.
    Refined { share: f64 },
}

impl Pick {
    /// A short name for tables: `nearest-0.7`, `most`.
    fn name(self) -> String {
        match self {
            Pick::NearestScale { share } => format!("nearest-{share}"),
            Pick::MostInliers => "most".into(),
            Pick::Refined { share } => format!("refined-{share}"),
        }
    }
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
    detector: &mut Detector,
) -> anyhow::Result<(Orb, f64, f64)> {
    let t = Instant::now();
    let image = decode(bytes, DecodeLimits::default(), config.max_side)?;
    let mut frame = bowloc::features::Frame::new(&image, config)?;
    let decode_ms = t.elapsed().as_secs_f64() * 1e3;
    let (mat, _) = frame.parts();
    let t = Instant::now();
    let (mut keys, mut raw) = (Vector::<KeyPoint>::new(), Mat::default());
    let orb = &mut detector.orb;
    match detector.grid {
        None => orb.detect_and_compute(mat, &no_array(), &mut keys, &mut raw, false)?,
        Some((cols, rows)) => {
            let mut all = Vector::<KeyPoint>::new();
            orb.detect(mat, &mut all, &no_array())?;
            keys = spread(&all, cols, rows, mat.cols() as f32, mat.rows() as f32);
            orb.compute(mat, &mut keys, &mut raw)?;
        }
    }
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

/// The cells keypoints are spread over (`ORB_PASS_GRID=COLSxROWS`, default
/// 4x3): ORB detects four times as many corners and the strongest of each
/// cell are kept, so the keypoints cover the frame. `ORB_PASS_GRID=none`:
/// ORB's own strongest corners, wherever they are.
fn grid_from_env() -> anyhow::Result<Option<(usize, usize)>> {
    let v = std::env::var("ORB_PASS_GRID").unwrap_or_else(|_| "4x3".into());
    if v == "none" {
        return Ok(None);
    }
    v.split_once('x')
        .and_then(|(c, r)| Some((c.parse().ok()?, r.parse().ok()?)))
        .filter(|&(c, r): &(usize, usize)| c * r > 0 && c * r <= ORB_FEATURES as usize)
        .map(Some)
        .ok_or_else(|| anyhow::anyhow!("ORB_PASS_GRID={v}: want COLSxROWS or none"))
}

/// The strongest keypoints of each of `cols`×`rows` cells, an equal share
/// of `ORB_FEATURES` each.
fn spread(all: &Vector<KeyPoint>, cols: usize, rows: usize, w: f32, h: f32) -> Vector<KeyPoint> {
    let mut cells: Vec<Vec<KeyPoint>> = vec![Vec::new(); cols * rows];
    for k in all.iter() {
        let c = ((k.pt().x / w * cols as f32) as usize).min(cols - 1);
        let r = ((k.pt().y / h * rows as f32) as usize).min(rows - 1);
        cells[r * cols + c].push(k);
    }
    let share = ORB_FEATURES as usize / (cols * rows);
    let mut kept = Vector::<KeyPoint>::new();
    for mut cell in cells {
        cell.sort_by(|a, b| b.response().total_cmp(&a.response()));
        cell.into_iter().take(share).for_each(|k| kept.push(k));
    }
    kept
}

/// An ORB detector and the grid its keypoints are spread over.
struct Detector {
    orb: opencv::core::Ptr<ORB>,
    grid: Option<(usize, usize)>,
}

impl Detector {
    fn new(grid: Option<(usize, usize)>) -> anyhow::Result<Self> {
        // four times the corners when the grid picks among them
        let features = if grid.is_some() {
            4 * ORB_FEATURES
        } else {
            ORB_FEATURES
        };
        let orb = ORB::create(
            features,
            1.2,
            8,
            31,
            0,
            2,
            ORB_ScoreType::HARRIS_SCORE,
            31,
            20,
        )?;
        Ok(Self { orb, grid })
    }
}

/// tf-idf of a word list, L2-normalised, as the SIFT map weighs an image:
/// (word, weight) sorted by word.
fn tf_idf(words: &[u32], idf: &[f32]) -> Vec<(u32, f32)> {
    weigh(&ImageWords::from_words("", words), idf).0
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
        // the SIFT map's idf, over the ORB words
        let mut builder = MapBuilder::new(vocabulary.len());
        for ws in &words_of {
            builder.add(ImageWords::from_words("", ws));
        }
        let idf = builder.idf();
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
    /// The pass's answer under a setting, if it answers: that candidate,
    /// then the others in vote order.
    fn answer(&self, setting: Setting) -> Option<Vec<usize>> {
        let Setting {
            pick,
            floor,
            window,
            margin,
            agree,
        } = setting;
        let scale_gap = |s: f64| if s > 0.0 { s.ln().abs() } else { f64::INFINITY };
        let fits = |v: &&(usize, f64, usize)| v.0 >= floor && scale_gap(v.1) <= window;
        // the most inliers, the nearer scale on ties
        let strongest = || {
            self.verified.iter().max_by(|a, b| {
                a.0.cmp(&b.0)
                    .then(scale_gap(b.1).total_cmp(&scale_gap(a.1)))
            })
        };
        let best = match pick {
            Pick::NearestScale { share } => {
                let strongest = self.verified.iter().filter(fits).map(|v| v.0).max()?;
                self.verified
                    .iter()
                    .filter(fits)
                    .filter(|v| v.0 as f64 >= share * strongest as f64)
                    .min_by(|a, b| scale_gap(a.1).total_cmp(&scale_gap(b.1)))?
            }
            Pick::MostInliers => strongest().filter(fits)?,
            Pick::Refined { share } => {
                let strongest = strongest()?;
                self.verified
                    .iter()
                    .filter(|v| v.2.abs_diff(strongest.2) <= PLACE_APART)
                    .filter(|v| v.0 as f64 >= share * strongest.0 as f64)
                    .min_by(|a, b| scale_gap(a.1).total_cmp(&scale_gap(b.1)))
                    .filter(fits)?
            }
        };
        let other_place = self
            .verified
            .iter()
            .filter(|v| v.2.abs_diff(best.2) > PLACE_APART)
            .map(|v| v.0)
            .max()
            .unwrap_or(0);
        if (best.0 as f64) < margin * other_place as f64 {
            return None;
        }
        if agree && best.2.abs_diff(self.verified.first()?.2) > PLACE_APART {
            return None;
        }
        let rest = self.verified.iter().filter(|v| v.2 != best.2);
        Some(std::iter::once(best.2).chain(rest.map(|v| v.2)).collect())
    }
}

/// The median, of an even count the upper middle one, as
/// `scripts/latency.sh` takes it (the eval's nearest rank takes the lower).
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
    let (grid, top) = (grid_from_env()?, top_from_env()?);
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
        .map(|r| Ok(orb_of(&read(r)?, &localizer.extract, &mut Detector::new(grid)?)?.0))
        .collect::<anyhow::Result<_>>()?;
    let all: Vec<BinaryDescriptor> = map_orb.iter().flat_map(|m| m.descriptors.clone()).collect();
    let vocabulary = BinaryVocabulary::train(&all, WORDS, ITERATIONS, seed);
    let orb_map = OrbMap::build(map_orb, &vocabulary);

    let full = SearchOptions {
        rule: bowloc::search::RuleSpec::new("none", None).map_err(anyhow::Error::msg)?,
        min_features: 0,
        ..default.clone()
    };
    let mut orb = Detector::new(grid)?;
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
        // RANSAC draws from OpenCV's generator: seeded per query, so the
        // pass's answer does not depend on what ran before it
        opencv::core::set_rng_seed(q as i32 + 1)?;
        let verified = orb_map
            .top(&words, top)
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
        "{}: {} queries, {} map images; SIFT K = {}, vocabulary seed {seed}; ORB {ORB_FEATURES} features, K = {WORDS}, top {} verified; {} ({}, {} CPUs), one thread",
        dataset.name,
        dataset.queries.len(),
        dataset.map.len(),
        localizer.vocab.words(),
        top,
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
    let rows = &rows;
    let every: Vec<usize> = (0..rows.len()).collect();
    // over the queries `qs`: recall@1 and recall@5 (%), the median request
    // time and the median per-query ratio to the full search's
    let outcome = |qs: &[usize], answers: &dyn Fn(usize) -> (Vec<usize>, f64)| {
        let answers: Vec<(usize, (Vec<usize>, f64))> =
            qs.iter().map(|&q| (q, answers(q))).collect();
        let share = |n: usize| {
            let hits = answers.iter().filter(|(q, a)| recall(&a.0, *q, n)).count();
            100.0 * hits as f64 / qs.len() as f64
        };
        let times = median(answers.iter().map(|(_, a)| a.1).collect());
        let ratio = median(answers.iter().map(|(q, a)| a.1 / rows[*q].2.1).collect());
        (share(1), share(5), times, ratio)
    };
    let full_alone = |q: usize| rows[q].2.clone();
    let default_alone = |q: usize| rows[q].3.clone();
    let (full_1, full_5, full_ms, _) = outcome(&every, &full_alone);
    println!("full search: recall@1 {full_1:.1}, recall@5 {full_5:.1}, median {full_ms:.1} ms");
    // a query the pass answers costs its decode and the pass; any other
    // the pass and the default
    let with_pass = |setting: Setting| {
        move |q: usize| {
            let (pass, decode_ms, _, service) = &rows[q];
            match pass.answer(setting) {
                Some(ids) => (ids, decode_ms + pass.ms),
                None => (service.0.clone(), pass.ms + service.1),
            }
        }
    };
    let answered = |qs: &[usize], setting: Setting| {
        qs.iter()
            .filter(|&&q| rows[q].0.answer(setting).is_some())
            .count()
    };
    let report = |label: &str, answers: &dyn Fn(usize) -> (Vec<usize>, f64), answered: usize| {
        let (at_1, at_5, times, ratio) = outcome(&every, answers);
        println!(
            "{label:32} answered by the pass {answered:3}; recall@1 {at_1:.1} ({:+.1}), recall@5 {at_5:.1} ({:+.1}); median {times:.1} ms, ratio of medians {:.3}, median ratio to the full search {ratio:.3}",
            at_1 - full_1,
            at_5 - full_5,
            times / full_ms,
        );
    };
    report("default alone", &default_alone, 0);
    for setting in SETTINGS {
        report(
            &setting.label(),
            &with_pass(setting),
            answered(&every, setting),
        );
        // where the pass's answer is wrong and the default's right
        let lost: Vec<String> = (0..rows.len())
            .filter_map(|q| {
                let ids = rows[q].0.answer(setting)?;
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
    // every setting of the sweep, one tab-separated line each, over all
    // the queries and over the even and the odd ones (0, 2, 4, … and 1, 3,
    // 5, …): recall changes in points against the full search and against
    // the default alone, and the median per-query ratio
    // (scripts/orb-pass.sh chooses from these, on one part or dataset, and
    // checks on another)
    println!(
        "sweep\tdataset\tseed\tpart\tpick\tfloor\twindow\tmargin\tagree\tanswered\trecall@1 vs full\trecall@5 vs full\trecall@1 vs default\trecall@5 vs default\tratio"
    );
    let parts = [
        ("all", every.clone()),
        ("even", every.iter().copied().step_by(2).collect::<Vec<_>>()),
        ("odd", every.iter().copied().skip(1).step_by(2).collect()),
    ];
    for (part, qs) in &parts {
        let (full_1, full_5, _, _) = outcome(qs, &full_alone);
        let (default_1, default_5, _, _) = outcome(qs, &default_alone);
        for pick in SWEEP_PICKS {
            for floor in SWEEP_FLOORS {
                for window in SWEEP_WINDOWS {
                    for (margin, agree) in SWEEP_MARGINS
                        .into_iter()
                        .flat_map(|m| [(m, false), (m, true)])
                    {
                        let setting = Setting {
                            agree,
                            ..Setting::new(pick, floor, window, margin)
                        };
                        let (at_1, at_5, _, ratio) = outcome(qs, &with_pass(setting));
                        println!(
                            "sweep\t{}\t{seed}\t{part}\t{}\t{floor}\t{window}\t{margin}\t{agree}\t{}\t{:+.1}\t{:+.1}\t{:+.1}\t{:+.1}\t{ratio:.3}",
                            dataset.name,
                            pick.name(),
                            answered(qs, setting),
                            at_1 - full_1,
                            at_5 - full_5,
                            at_1 - default_1,
                            at_5 - default_5,
                        );
                    }
                }
            }
        }
    }
    println!(
        "the pass alone: median {:.2} ms after a decode of {:.2} ms",
        median(rows.iter().map(|r| r.0.ms).collect()),
        median(rows.iter().map(|r| r.1).collect())
    );
    Ok(())
}
