//! An ORB pass before SIFT, measured against the service's answers: a
//! prototype of a cheap first look that would answer the easy queries
//! without SIFT, as the library has it (`bowloc::orb_pass`). Per query, on
//! the service's 640 px frame: ORB (`ORB_PASS_KEYPOINTS` keypoints, by
//! default the service's, spread over a grid of cells, `ORB_PASS_GRID`;
//! `bowloc::features::orb`), each descriptor's binary word
//! (`bowloc::vocabulary::binary`, K words by k-majority over the map's ORB
//! descriptors, drawn with the SIFT vocabulary's seed), tf-idf votes over
//! the map images, and the best-voted (`ORB_PASS_TOP`, by default the
//! service's `orb_pass.top`) verified by a similarity (RANSAC, 6 px,
//! OpenCV's fixed seed) on word pairs (each query feature paired with the nearest map feature of its
//! word, at most 64 bits away), the inliers counted as the service's
//! verification counts them and their scale the spread of the map's
//! inliers over the query's. A [`Setting`] says when the pass answers and
//! with which verified candidate (its inliers, its scale against the
//! query's, the places of the others); the answer lists that candidate,
//! then the others in vote order.
//!
//! The SIFT map and vocabulary are given; they are loaded and searched as
//! `bowloc serve` loads and searches them with its default configuration
//! (its default rule, extraction plan and verification, without the ORB
//! pass, which is measured beside it; one request at a time, so no spare
//! core; image buffers kept mapped, one OpenCV thread).
//! Every query is answered once by the default first, as by a server that
//! has been answering a while (its plan learns). Then, one query after the
//! other on this thread, three timings from the same bytes: the full search
//! on the whole image (`rule=none`, no tiles: what streaming and stopping
//! save against), the service's default, and the pass. A query the pass
//! answers costs its decode and the pass (with the extraction frame it
//! looks at); any other costs the pass (its decode left out: the service
//! would decode once) and the default, which makes the frame again where
//! the service hands the pass's frame on to SIFT (a downscale counted
//! twice: the figures lean against the pass). It
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
use bowloc::features::{DecodeLimits, Frame, TileGrid, decode};
use bowloc::orb_pass::params::parse_grid;
use bowloc::orb_pass::{Checked, OrbPassParams, Pick, Setting, answer};
use bowloc::pipeline::{OrbPass, build_orb_side};
use bowloc::search::SearchOptions;
use bowloc::server::config::Config;
use std::time::Instant;

/// A positive count from the environment variable `name`, `default`
/// when it is not set: `ORB_PASS_TOP`, the candidates verified in vote
/// order, and `ORB_PASS_KEYPOINTS`, ORB's keypoints per image (both by
/// default the service's).
fn count_from_env(name: &str, default: usize) -> anyhow::Result<usize> {
    match std::env::var(name) {
        Err(_) => Ok(default),
        Ok(v) => v
            .parse()
            .ok()
            .filter(|&n| n > 0)
            .ok_or_else(|| anyhow::anyhow!("{name}={v}: want a positive count")),
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
/// The cells keypoints are spread over (`ORB_PASS_GRID=COLSxROWS`, default
/// 4x3): ORB detects four times as many corners and the strongest of each
/// cell are kept, so the keypoints cover the frame. `ORB_PASS_GRID=none`:
/// ORB's own strongest corners, wherever they are.
fn grid_from_env() -> anyhow::Result<String> {
    let v = std::env::var("ORB_PASS_GRID").unwrap_or_else(|_| "4x3".into());
    parse_grid(&v).map_err(|e| anyhow::anyhow!("ORB_PASS_GRID={e}"))?;
    Ok(v)
}

/// What the pass found for one query: each checked candidate in vote
/// order, and the pass's time after the decode.
struct Pass {
    checked: Vec<Checked>,
    ms: f64,
}

impl Pass {
    /// The pass's answer under a setting, if it answers (map image ids).
    fn answer(&self, setting: Setting) -> Option<Vec<usize>> {
        answer(&self.checked, setting).map(|ids| ids.into_iter().map(|m| m as usize).collect())
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
    // the SIFT search alone: the pass is measured beside it
    config.orb_pass.enabled = false;
    let localizer = bowloc::server::bootstrap::load(&config, &Default::default())?;
    let default = config.search_options().map_err(anyhow::Error::msg)?;
    let verify = config.verify.enabled;
    let seed = localizer.vocab.meta().seed;
    let read = |r: &bowloc::dataset::ImageRef| std::fs::read(&r.path);
    let service = OrbPassParams::default();
    let params = OrbPassParams {
        top: count_from_env("ORB_PASS_TOP", service.top)?,
        keypoints: count_from_env("ORB_PASS_KEYPOINTS", service.keypoints)?,
        grid: grid_from_env()?,
        ..service
    };
    params.validate().map_err(anyhow::Error::msg)?;
    let side = build_orb_side(&localizer, &dataset.map, &params)?;
    let words = side.vocabulary.len();
    let orb_pass = OrbPass::new(side, &params);

    let full = SearchOptions {
        rule: bowloc::search::RuleSpec::new("none", None).map_err(anyhow::Error::msg)?,
        min_features: 0,
        ..default.clone()
    };
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
        let t = Instant::now();
        let image = decode(&bytes, DecodeLimits::default(), localizer.extract.max_side)?;
        let decode_ms = t.elapsed().as_secs_f64() * 1e3;
        // the pass with the extraction frame it looks at
        let t = Instant::now();
        let look = orb_pass.look(&Frame::new(&image, &localizer.extract)?)?;
        let pass = Pass {
            checked: look.checked,
            ms: t.elapsed().as_secs_f64() * 1e3,
        };
        rows.push((pass, decode_ms, whole, service));
    }

    let cpu = Cpu::here();
    println!(
        "{}: {} queries, {} map images; SIFT K = {}, vocabulary seed {seed}; ORB {} features, K = {words}, top {} verified; {} ({}, {} CPUs), one thread",
        dataset.name,
        dataset.queries.len(),
        dataset.map.len(),
        localizer.vocab.words(),
        params.keypoints,
        params.top,
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
