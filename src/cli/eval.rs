//! `bowloc eval`: reproduce the paper's evaluation on a dataset in the shared
//! layout (tables, CSV, JSON and plots in `--out`).

use super::args::{ExtractArgs, SequenceArgs, VerifyArgs, dataset_name, place_window, vocab_seeds};
use bowloc::calibrate::Warmup;
use bowloc::eval::machine::OpenCvInfo;
use bowloc::eval::{self, DEFAULT_TARGETS, EvalConfig};
use bowloc::features::TilePlan;
use bowloc::orb_pass::OrbPassParams;
use bowloc::search::SearchOptions;
use clap::Args;
use std::path::PathBuf;

#[derive(Args)]
pub struct EvalArgs {
    /// Dataset folder (map.txt, queries.txt, ground_truth.csv).
    #[arg(long)]
    dataset: PathBuf,
    /// Vocabulary size K (trained on the map images, cached).
    #[arg(long, default_value_t = 1000)]
    words: usize,
    /// Monte Carlo runs (random feature orders) to average over.
    #[arg(long, default_value_t = 10)]
    runs: u32,
    /// Rules to sweep, comma-separated (default: all); the full search is always run.
    #[arg(long, value_delimiter = ',')]
    rules: Vec<String>,
    /// Extra settings to run, RULE=VALUE or RULE=VALUE@WARMUP (repeatable);
    /// RULE=VALUE+verified=M[@WARMUP] also stops once the leader is verified
    /// with M inliers.
    #[arg(long = "set", value_name = "RULE=VALUE[+verified=M][@WARMUP]")]
    set: Vec<String>,
    /// Warm-ups (min_features) for the calibrated rules; the first is used for the main
    /// tables. `auto`: at most 100, and at most a quarter of the median query's features.
    #[arg(long, value_delimiter = ',', default_values_t = [Warmup::Features(0), Warmup::Features(20), Warmup::Auto])]
    min_features: Vec<Warmup>,
    /// Mean fractions of features the calibrated grids aim at.
    #[arg(long, value_delimiter = ',', default_values_t = DEFAULT_TARGETS.to_vec())]
    targets: Vec<f64>,
    /// Recall (absolute) the recommended setting may lose against the full search.
    #[arg(long, default_value_t = 0.02)]
    tolerance: f64,
    /// Setting of the histogram figure: RULE or RULE=VALUE (default: the recommended one).
    #[arg(long)]
    histogram: Option<String>,
    /// Vocabularies to train: N (k-means seeds 1..=N) or a list of seeds `a,b,…`
    /// (a seed repeated counts once: `7,7` is seed 7 alone).
    #[arg(long, value_delimiter = ',', default_value = "3")]
    vocab_seeds: Vec<u64>,
    /// Use this vocabulary instead of training one (its extraction settings are used).
    #[arg(long)]
    vocab: Option<PathBuf>,
    /// Output folder (default data/eval/<dataset>-k<K>).
    #[arg(long)]
    out: Option<PathBuf>,
    /// Cache folder (default data/eval-cache/<dataset>).
    #[arg(long)]
    cache: Option<PathBuf>,
    /// Skip the PNG/SVG figures.
    #[arg(long)]
    no_plots: bool,
    /// The queries' tile grid for streaming extraction,
    /// COLSxROWS[+MARGIN][,coarse|,auto] (1x1: whole images; `,coarse`: a
    /// half-size pass first; `,auto`: the coarse pass learned per request as
    /// the service learns it: per setting, from a fresh start, over the runs
    /// in turn, each the queries in order). The full search also runs on
    /// whole queries.
    #[arg(long, default_value = "2x2+24")]
    tiles: TilePlan,
    /// With `--tiles …,auto`: also replay, for every setting given with
    /// --set that stops early, this many plans on fresh servers (just
    /// started) and as many on restarted ones (going on from the plan
    /// another server kept), each over the queries once per run, every time
    /// in a random order of its own, and
    /// report per vocabulary seed how many settled on the coarse pass, the
    /// share of searches they started with it, their median request against
    /// the whole-image full search's and their recall@1.
    #[arg(long, default_value_t = 0)]
    plan_orders: u32,
    /// The order the tiles are replayed in, as the service extracts them.
    #[arg(long, default_value_t = bowloc::search::TileOrder::default(), value_parser = super::args::choice_parser::<bowloc::search::TileOrder>())]
    tile_order: bowloc::search::TileOrder,
    /// The order each tile's features are voted in (the service votes in a
    /// random one).
    #[arg(long, default_value_t = bowloc::eval::tiles::FeatureOrder::default(), value_parser = super::args::choice_parser::<bowloc::eval::tiles::FeatureOrder>())]
    feature_order: bowloc::eval::tiles::FeatureOrder,
    /// Images on each side, along the map's order, that count as one place
    /// when a candidate's distinctness is measured (and for the rule
    /// place-lead).
    #[arg(long, default_value_t = SearchOptions::PLACE_WINDOW, value_parser = place_window)]
    place_window: u32,
    /// Also report precision and recall of the top answer kept when its
    /// distinctness is at least this (a cut chosen on another dataset: the
    /// tables print each seed's cut at 90 % precision).
    #[arg(long, value_parser = super::args::min_distinct)]
    distinct_cut: Option<f32>,
    #[command(flatten)]
    extract: ExtractArgs,
    /// With --verify: rows with and without geometric verification for the
    /// full search and the --set settings.
    #[command(flatten)]
    verify: VerifyArgs,
    /// Replay the queries in list order as one camera's frames, with and
    /// without the sequence filter (docs/results.md, "Sequences").
    #[arg(long)]
    sequence: bool,
    /// With --sequence: the stopping rule of the stopped modes, RULE=VALUE or
    /// RULE=VALUE@WARMUP, the warm-up a number of features or `auto` (a
    /// quarter of the map images' median feature count, at most 100, as the
    /// service's `sequence.min_features = "auto"`). The default is the
    /// service's.
    #[arg(long, default_value = "posterior=0.7@auto")]
    stop: String,
    /// With --sequence: unrelated images to inject into the sequence (a list or a folder).
    #[arg(long)]
    inject: Option<PathBuf>,
    /// With --sequence: how many unrelated images to inject, evenly spaced.
    #[arg(long, default_value_t = 4)]
    injections: usize,
    #[command(flatten)]
    model: SequenceArgs,
    #[command(flatten)]
    orb: OrbPassEvalArgs,
}

/// `--orb-pass` and its setting (the service's `[orb_pass]` defaults).
#[derive(Debug, clap::Args)]
struct OrbPassEvalArgs {
    /// Also run the full search and the --set settings (verified, with
    /// --verify) with the service's ORB pass first, on every vocabulary
    /// (the map's ORB side is built beside the cached map).
    #[arg(long)]
    orb_pass: bool,
    /// With --orb-pass: best-voted map images the pass checks.
    #[arg(long, default_value_t = OrbPassParams::default().top)]
    orb_top: usize,
    /// With --orb-pass: inliers its pick needs.
    #[arg(long, default_value_t = OrbPassParams::default().floor)]
    orb_floor: usize,
    /// With --orb-pass: how far its pick's scale may be from the query's
    /// (|ln s| at most this).
    #[arg(long, default_value_t = OrbPassParams::default().window)]
    orb_window: f64,
    /// With --orb-pass: the share of the most inliers a candidate needs to
    /// be picked by its scale.
    #[arg(long, default_value_t = OrbPassParams::default().share)]
    orb_share: f64,
    /// With --orb-pass: whether its pick must see the votes' first place.
    #[arg(long, default_value_t = OrbPassParams::default().agree, action = clap::ArgAction::Set)]
    orb_agree: bool,
    /// With --orb-pass: binary words of the ORB side's vocabulary.
    #[arg(long, default_value_t = OrbPassParams::default().words)]
    orb_words: usize,
    /// With --orb-pass: ORB keypoints per image.
    #[arg(long, default_value_t = OrbPassParams::default().keypoints)]
    orb_keypoints: usize,
    /// With --orb-pass: `none` (ORB's strongest corners) or COLSxROWS.
    #[arg(long, default_value_t = OrbPassParams::default().grid)]
    orb_grid: String,
}

impl OrbPassEvalArgs {
    fn params(&self) -> anyhow::Result<Option<OrbPassParams>> {
        if !self.orb_pass {
            return Ok(None);
        }
        let params = OrbPassParams {
            top: self.orb_top,
            floor: self.orb_floor,
            window: self.orb_window,
            share: self.orb_share,
            agree: self.orb_agree,
            words: self.orb_words,
            keypoints: self.orb_keypoints,
            grid: self.orb_grid.clone(),
            ..OrbPassParams::default()
        };
        params
            .validate()
            .map_err(|e| anyhow::anyhow!("--orb-pass: {e}"))?;
        Ok(Some(params))
    }
}

pub fn run(a: EvalArgs) -> anyhow::Result<()> {
    let name = dataset_name(&a.dataset);
    let seeds = vocab_seeds(&a.vocab_seeds);
    if a.sequence {
        return sequence(a, name, seeds);
    }
    let verify = a.verify.params()?;
    let config = EvalConfig {
        verify: verify.enabled.then_some(verify),
        words: a.words,
        seeds,
        runs: a.runs,
        rules: a.rules,
        explicit: a.set,
        warmups: a.min_features,
        targets: a.targets,
        tolerance: a.tolerance,
        histogram: a.histogram,
        extract: a.extract.config(),
        tiles: a.tiles,
        place_window: a.place_window,
        distinct_cut: a.distinct_cut,
        tile_order: a.tile_order,
        feature_order: a.feature_order,
        plan_orders: a.plan_orders,
        orb_pass: a.orb.params()?,
        vocab: a.vocab,
        out: a
            .out
            .unwrap_or_else(|| PathBuf::from("data/eval").join(format!("{name}-k{}", a.words))),
        cache: a
            .cache
            .unwrap_or_else(|| PathBuf::from("data/eval-cache").join(&name)),
        plots: !a.no_plots,
        command: std::env::args().collect::<Vec<_>>().join(" "),
        dataset: a.dataset,
        opencv: opencv_info(),
    };
    let report = eval::run(&config)?;
    tracing::info!(
        out = %config.out.display(),
        settings = report.settings.len(),
        seconds = format!("{:.1}", report.stages.total_s),
        "evaluation written"
    );
    if let Some(r) = &report.recommendation {
        outln!(
            "recommended: {} ({:.1} % of features, worst seed {:.1} %; recall top-5 @90%P {:.1} % vs {:.1} %, recall@1 {:.1} % vs {:.1} %, means over seeds)",
            r.label,
            100.0 * r.fraction,
            100.0 * r.worst_fraction,
            100.0 * r.recall90_top5,
            100.0 * r.baseline_recall90_top5,
            100.0 * r.recall_at_1,
            100.0 * r.baseline_recall_at_1
        )?;
    }
    let degenerate = report
        .settings
        .iter()
        .filter(|s| s.setting.degenerate.is_some())
        .count();
    if degenerate > 0 {
        outln!(
            "{degenerate} degenerate grid points (target out of reach or warm-up too long), \
             marked † in results.md and left out of the equal-recall tables and the recommendation"
        )?;
    }
    if let Some(why) = &report.no_recommendation {
        outln!("no recommendation: {why}")?;
    }
    if let Some(v) = &report.verification {
        for r in &v.rows {
            outln!(
                "{}: recall@1 {:.1} % → {:.1} % with verification, recall@5 {:.1} % → {:.1} %, recall top-1 @90%P {:.1} % → {:.1} %, recall top-5 @90%P {:.1} % → {:.1} %, verification {:.2} ms per query (median)",
                r.label,
                100.0 * r.without.recall_at_1.mean,
                100.0 * r.with.recall_at_1.mean,
                100.0 * r.without.recall_at_5.mean,
                100.0 * r.with.recall_at_5.mean,
                100.0 * r.without.recall90_top1.mean,
                100.0 * r.with.recall90_top1.mean,
                100.0 * r.without.recall90_top5.mean,
                100.0 * r.with.recall90_top5.mean,
                r.verify_ms.median,
            )?;
        }
    }
    for r in &report.plan_orders {
        let [lo, _, hi] = r.spread(|o| r.ratio(o));
        outln!(
            "{}, vocabulary seed {}, {} servers: {} of {} query orders settled on the coarse pass; \
             median request {lo:.3} to {hi:.3} of the whole-image full search's",
            r.label,
            r.seed,
            r.start.name(),
            r.settled_coarse(),
            r.orders.len(),
        )?;
    }
    outln!("{}", config.out.join("results.md").display())?;
    Ok(())
}

/// `bowloc eval --sequence`.
fn sequence(a: EvalArgs, name: String, seeds: Vec<u64>) -> anyhow::Result<()> {
    // the warm-up may be `auto`, which only the map resolves
    let (body, warmup) = match a.stop.rsplit_once('@') {
        Some((body, w)) => (
            body,
            w.parse::<Warmup>()
                .map_err(|e| anyhow::anyhow!("--stop {}: warm-up: {e}", a.stop))?,
        ),
        None => (a.stop.as_str(), Warmup::Features(0)),
    };
    let stop = eval::sweep::parse_setting(body, 0)
        .map_err(|e| anyhow::anyhow!("--stop {}: {e}", a.stop))?;
    anyhow::ensure!(
        !a.tiles.learn_coarse,
        "--sequence replays one grid: --tiles {} learns the coarse pass, give {} or {},coarse",
        a.tiles,
        a.tiles.grid,
        a.tiles.grid
    );
    let config = eval::sequence::SequenceEvalConfig {
        words: a.words,
        seeds,
        runs: a.runs,
        extract: a.extract.config(),
        tiles: a.tiles.grid,
        out: a.out.unwrap_or_else(|| {
            PathBuf::from("data/eval").join(format!("{name}-k{}-sequence", a.words))
        }),
        cache: a
            .cache
            .unwrap_or_else(|| PathBuf::from("data/eval-cache").join(&name)),
        model: a.model.model()?,
        stop: stop.rule,
        min_features: warmup,
        verify: a.verify.params()?,
        inject: a.inject,
        injections: a.injections,
        command: std::env::args().collect::<Vec<_>>().join(" "),
        dataset: a.dataset,
    };
    let report = eval::sequence::run(&config)?;
    out!("{}", eval::sequence::markdown(&report))?;
    outln!("{}", config.out.join("sequence.md").display())?;
    Ok(())
}

/// OpenCV's version and the SIMD level its dispatcher uses on this CPU.
fn opencv_info() -> OpenCvInfo {
    let cpu_features = opencv::core::get_cpu_features_line().unwrap_or_default();
    OpenCvInfo {
        version: opencv::core::get_version_string().unwrap_or_else(|_| "unknown".into()),
        dispatched: OpenCvInfo::dispatched_level(&cpu_features),
        cpu_features,
    }
}
