//! The early-stopping search, the heart of bowloc. Features arrive in
//! batches (one batch per extracted tile, or the whole image as one batch)
//! and each batch runs permute → quantize → vote → stop; the answer is ranked
//! at the end:
//!
//! - [`permute`]: a seeded random order of each batch's features (and the
//!   order of the tiles: richest first, or at random);
//! - quantize: blocks of `block` features at a time through a caller's
//!   quantizer (a [`Quantizer`], or known words);
//! - [`vote`]: one feature at a time into the histogram;
//! - [`stop`]: the rule is checked after every vote, so a stop in mid-block
//!   wastes at most one block of quantization; once it fires, the caller
//!   extracts no more batches;
//! - [`rank`]: top-n images with scores comparable across stop points;
//! - [`trace`]: on request, the vote race as plain data (bounded);
//! - [`budget`]: a request's time budget: whether one more tile fits in it,
//!   what tiles cost on this machine, and when a tight one starts with the
//!   coarse pass.
//!
//! [`shard`] runs the same search over a map split into shards by image.
//!
//! [`Search`] is the streaming driver; [`search`] and [`search_words`] run it
//! on one batch whose size is known up front. Pure Rust over plain arrays: no
//! OpenCV, no HTTP.

pub mod budget;
pub mod permute;
pub mod prior;
pub mod rank;
pub mod shard;
pub mod stop;
pub mod trace;
pub mod vote;

pub use permute::TileOrder;
pub use prior::{Posterior, Prior};
pub use rank::Ranked;
pub use stop::{LeaderCheck, Progress, RuleSpec, StopRule};
pub use trace::{Trace, TracePoint};
pub use vote::{Needs, Tally, VoteStats, Voter};

use crate::index::MapRead;
use crate::quantize::Quantizer;
use crate::vocabulary::HammingEmbedding;
use crate::vocabulary::hamming::sign_or_zero;
use ndarray::{Array2, ArrayView2};
use serde::Serialize;
use std::sync::Arc;
use std::time::{Duration, Instant};
pub use vote::HammingWeights;

/// How to run one search.
#[derive(Debug, Clone)]
pub struct SearchOptions {
    pub rule: RuleSpec,
    /// Candidates to return.
    pub top_n: usize,
    /// Seed of the feature permutation.
    pub seed: u64,
    /// Features quantized per batch.
    pub block: usize,
    /// The rule is not consulted before this many features have voted.
    pub min_features: usize,
    /// Candidates scoring below this are dropped.
    pub min_score: f32,
    /// Of the answer's candidates (after verification, if any), those whose
    /// distinctness ([`Ranked::distinct`]) is below this are dropped: 0 keeps
    /// all; a cut such as 0.6 answers only when the leader stands out
    /// (docs/results.md, "A cut to trust an answer by").
    pub min_distinct: f32,
    /// Give up (returning the answer so far) once this instant passes.
    pub deadline: Option<Instant>,
    /// Streamed queries: extract a next tile only when it is expected to
    /// end within this time from the start of decoding (the first tile
    /// always; [`budget`]). `None`: no budget.
    pub budget: Option<Duration>,
    /// A prior over map images (a sequence's prediction, a pose
    /// restriction): the rule `posterior` reads it, a prior that excludes
    /// images keeps them out of the candidates, and the outcome carries the
    /// posterior it gives.
    pub prior: Option<Arc<Prior>>,
    /// Weigh votes by the features' Hamming signatures (`None`: plain tf-idf).
    pub hamming: Option<HammingWeights>,
    /// Images on each side, along the map's order, that count as one place
    /// when a candidate's distinctness is measured ([`Ranked::distinct`]).
    pub place_window: u32,
    /// The order a query's tiles are extracted in.
    pub tile_order: TileOrder,
    /// Vote each batch's features in the order given (numbered from 0)
    /// instead of a random one drawn from the seed: for evaluation, which
    /// can replay its queries sorted (`bowloc eval --feature-order`).
    pub given_order: bool,
    /// When the rule stops a streamed query inside a tile, vote the tile's
    /// other features before ending ([`Search::feed_tile`]). Set when the
    /// answer is verified: the tile's extraction is paid for, its other
    /// features cost only their votes, and verification finds more inliers
    /// with them.
    pub finish_tile: bool,
    /// Whether a core would idle now, asked before each tile of a streamed
    /// query without a budget: when it would, the next tile is extracted
    /// together with the one after it, on that core
    /// ([`crate::features::Tiles::extract_ahead`]). `None`: one at a time.
    pub spare_core: Option<SpareCore>,
    /// Let the ORB pass answer first, when the map has its ORB side and the
    /// search could stop early (`crate::pipeline::orb_pass`); the search
    /// itself ignores it.
    pub orb_pass: bool,
}

/// Whether a core would idle now: the front end's view of its own load (the
/// service's, whether fewer jobs are admitted than there are cores).
#[derive(Clone)]
pub struct SpareCore(Arc<dyn Fn() -> bool + Send + Sync>);

impl SpareCore {
    pub fn new(now: impl Fn() -> bool + Send + Sync + 'static) -> Self {
        Self(Arc::new(now))
    }

    pub fn now(&self) -> bool {
        (self.0)()
    }
}

impl std::fmt::Debug for SpareCore {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("SpareCore")
    }
}

impl Default for SearchOptions {
    fn default() -> Self {
        Self {
            rule: RuleSpec::new("none", None).expect("built-in rule"),
            top_n: 5,
            seed: 0,
            block: 32,
            min_features: 0,
            min_score: 0.0,
            min_distinct: 0.0,
            deadline: None,
            budget: None,
            prior: None,
            hamming: Some(HammingWeights::DEFAULT),
            place_window: Self::PLACE_WINDOW,
            tile_order: TileOrder::default(),
            given_order: false,
            finish_tile: false,
            spare_core: None,
            orb_pass: false,
        }
    }
}

impl SearchOptions {
    /// The rule every front end uses unless told otherwise.
    pub const RECOMMENDED_RULE: &'static str = "place-z";
    /// Its parameter.
    pub const RECOMMENDED_PARAMETER: f64 = 2.25;
    /// Features voted before it is first consulted. `place-z` measures its
    /// own evidence and would stop without one; the warm-up keeps enough
    /// features for a geometric verification of the answer (12 inliers).
    pub const RECOMMENDED_WARMUP: usize = 20;
    /// Its verified stop ([`RuleSpec::or_verified`]): also stop at a tile's
    /// end once the answer has this many inliers at the query's scale
    /// (docs/results.md, "A verified stop beside the rule").
    pub const RECOMMENDED_OR_VERIFIED: f64 = 12.0;
    /// The place window distinctness is measured with (docs/results.md,
    /// "Distinctness").
    pub const PLACE_WINDOW: u32 = 2;
    /// The widest place window accepted: a place is a stretch of a route,
    /// and a rule comparing with the best image outside it tracks
    /// 2·window + 2 leading images.
    pub const MAX_PLACE_WINDOW: u32 = 1000;

    /// Whether a core would idle now ([`SearchOptions::spare_core`]; no
    /// when the front end does not say).
    pub fn core_spare_now(&self) -> bool {
        self.spare_core.as_ref().is_some_and(SpareCore::now)
    }

    /// `window` if it is an accepted place window, else why not: the one
    /// check behind the configuration and every `--place-window`.
    pub fn check_place_window(window: u32) -> Result<u32, String> {
        if window <= Self::MAX_PLACE_WINDOW {
            Ok(window)
        } else {
            Err(format!(
                "must be at most {}, got {window}",
                Self::MAX_PLACE_WINDOW
            ))
        }
    }

    /// `cut` if it is an accepted `min_distinct` (a distinctness, in
    /// [0, 1]), else why not: the one check behind the configuration, the
    /// API and `--min-distinct`.
    pub fn check_min_distinct(cut: f64) -> Result<f32, String> {
        if (0.0..=1.0).contains(&cut) {
            Ok(cut as f32)
        } else {
            Err(format!(
                "must be a number in [0, 1] (a distinctness), got {cut}"
            ))
        }
    }

    /// The settings the service, the CLI and the configuration default to:
    /// the rule, parameter and warm-up chosen by evaluation
    /// (docs/results.md, "The default rule").
    pub fn recommended() -> Self {
        Self {
            rule: RuleSpec::new(Self::RECOMMENDED_RULE, Some(Self::RECOMMENDED_PARAMETER))
                .and_then(|r| r.or_verified(Some(Self::RECOMMENDED_OR_VERIFIED)))
                .expect("a valid built-in rule"),
            min_features: Self::RECOMMENDED_WARMUP,
            ..Self::default()
        }
    }
}

/// One feature as it was voted.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Voted {
    /// Its number over all batches (tiles) of the query.
    pub feature: u32,
    pub word: u32,
    /// Its Hamming signature (0 without an embedding).
    pub signature: u64,
}

/// Why the search ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum StopKind {
    /// The stopping rule fired.
    Rule,
    /// Every feature was used.
    Exhausted,
    /// The deadline passed.
    Deadline,
    /// The next tile would not have ended within the request's time budget.
    Budget,
    /// The ORB pass answered before any SIFT feature was extracted.
    OrbPass,
}

impl StopKind {
    /// Every kind, in the order the answers' documents list them.
    pub const ALL: [StopKind; 5] = [
        StopKind::Rule,
        StopKind::Exhausted,
        StopKind::Deadline,
        StopKind::Budget,
        StopKind::OrbPass,
    ];

    /// How answers spell it (its serialized name).
    pub fn name(self) -> &'static str {
        match self {
            StopKind::Rule => "rule",
            StopKind::Exhausted => "exhausted",
            StopKind::Deadline => "deadline",
            StopKind::Budget => "budget",
            StopKind::OrbPass => "orb-pass",
        }
    }

    /// What it means, for the API documents.
    pub fn about(self) -> &'static str {
        match self {
            StopKind::Rule => "the stopping rule fired",
            StopKind::Exhausted => "every feature was used",
            StopKind::Deadline => "the request's deadline passed (the answer so far)",
            StopKind::Budget => {
                "the next tile would not have ended within the request's `budget_ms` (the answer so far)"
            }
            StopKind::OrbPass => {
                "the ORB pass answered before SIFT (`orb_pass`): no SIFT feature was extracted"
            }
        }
    }
}

/// Where and why the search stopped.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct StopInfo {
    pub kind: StopKind,
    /// Features voted when it stopped.
    pub at_feature: usize,
    pub detail: String,
}

/// Time spent in the search's own stages.
#[derive(Debug, Clone, Copy, Default, Serialize)]
pub struct SearchTimings {
    pub quantize: Duration,
    pub vote: Duration,
    /// Geometric checks of a rule that verifies its leader.
    pub verify: Duration,
}

/// The answer of one search.
#[derive(Debug, Clone)]
pub struct SearchOutcome {
    pub candidates: Vec<Ranked>,
    /// Features given to the search (all of the query's, unless extraction
    /// stopped early).
    pub features_total: usize,
    /// Features quantized and voted.
    pub features_used: usize,
    pub stop: StopInfo,
    pub timings: SearchTimings,
    /// The vote race, when the search was traced.
    pub trace: Option<Trace>,
    /// With a prior: the posterior over map images given the prior and the
    /// votes ([`prior::posterior`], keeping [`Prior::keep`] images).
    pub posterior: Option<Posterior>,
    /// With a prior: the posterior of the votes alone (a uniform prior, the
    /// same κ), the frame's own probabilities.
    pub frame_posterior: Option<Posterior>,
}

impl SearchOutcome {
    /// Fraction of the features given that were quantized and voted (1 for none).
    pub fn fraction_used(&self) -> f64 {
        if self.features_total == 0 {
            1.0
        } else {
            self.features_used as f64 / self.features_total as f64
        }
    }
}

/// Seed of the order inside batch `k`: batch 0 uses the search's seed itself,
/// so a one-batch search orders its features by `permutation(n, seed)`.
fn batch_seed(seed: u64, k: u64) -> u64 {
    seed.wrapping_add(k.wrapping_mul(0x9E37_79B9_7F4A_7C15))
}

/// The order the `count` features of batch `k` are voted in: random from
/// the options' seed, or as given ([`SearchOptions::given_order`]).
fn batch_order(options: &SearchOptions, count: usize, k: u64) -> Vec<u32> {
    if options.given_order {
        (0..count as u32).collect()
    } else {
        permute::permutation(count, batch_seed(options.seed, k))
    }
}

/// A search in progress: feed it batches of features until it stops or the
/// features run out, then [`finish`](Search::finish) it.
pub struct Search<'m> {
    map: &'m dyn MapRead,
    options: SearchOptions,
    voter: Voter<'m>,
    rule: Box<dyn StopRule>,
    words: Vec<u32>,
    signatures: Vec<u64>,
    timings: SearchTimings,
    stop: Option<(StopKind, String)>,
    /// Why the rule fired inside a tile whose other features are still
    /// being voted ([`Search::feed_tile`]).
    finishing: Option<String>,
    /// Whether the query comes in more than one tile and a stop inside one
    /// finishes it ([`SearchOptions::finish_tile`]).
    streamed: bool,
    /// Whether the batch being voted is a coarse pass, where only a
    /// geometric check may stop ([`Progress::coarse`]).
    coarse_batch: bool,
    batches: u64,
    fed: usize,
    /// Features fed before the search started over (after a coarse pass,
    /// [`Search::feed_tile`]): the number of this search's first feature.
    numbered_from: usize,
    /// The last batch was a coarse pass that did not end the search: the
    /// next tile starts it over.
    probed: bool,
    /// Every feature voted, in voting order.
    voted: Vec<Voted>,
    trace: Option<Trace>,
    /// (every, max_points) the trace was asked with.
    trace_asked: Option<(u32, usize)>,
}

impl<'m> Search<'m> {
    pub fn new(map: &'m dyn MapRead, options: &SearchOptions) -> Self {
        let rule = options.rule.build(&stop::RuleContext {
            top_n: options.top_n,
            prior: options.prior.clone(),
            place_window: options.place_window,
        });
        let mut voter = Voter::with_needs(&map.view(), rule.needs());
        if let Some(weights) = options.hamming {
            voter = voter.with_hamming(map, weights);
        }
        Self {
            map,
            options: options.clone(),
            voter,
            rule,
            words: vec![0; options.block.max(1)],
            signatures: vec![0; options.block.max(1)],
            timings: SearchTimings::default(),
            stop: None,
            finishing: None,
            streamed: false,
            coarse_batch: false,
            batches: 0,
            fed: 0,
            numbered_from: 0,
            probed: false,
            voted: Vec::new(),
            trace: None,
            trace_asked: None,
        }
    }

    /// Begin again from nothing, as if no feature had been fed: what a
    /// coarse pass that did not end the search leaves. The time spent so far
    /// is kept, and feature numbers go on from the features fed (a caller's
    /// keypoint list stays valid); the trace starts again.
    fn start_over(&mut self) {
        let mut fresh = Search::new(self.map, &self.options);
        fresh.timings = self.timings;
        fresh.numbered_from = self.numbered_from + self.fed;
        if let Some((every, max_points)) = self.trace_asked {
            fresh = fresh.trace(every, max_points);
        }
        *self = fresh;
    }

    /// Record the vote race: a point every `every` features, at most
    /// `max_points` of them (the step doubles when they would be more).
    pub fn trace(mut self, every: u32, max_points: usize) -> Self {
        let mut trace = Trace::new(every, max_points);
        trace.warm_up = self.options.min_features.min(u32::MAX as usize) as u32;
        self.trace = Some(trace);
        self.trace_asked = Some((every, max_points));
        self
    }

    /// Whether the search has stopped (rule or deadline): feed no more.
    pub fn stopped(&self) -> bool {
        self.stop.is_some()
    }

    /// End the search from outside (between batches: the time budget),
    /// unless it has stopped already.
    pub fn end(&mut self, kind: StopKind, detail: String) {
        self.stop.get_or_insert((kind, detail));
    }

    /// The query has exactly `n` features in all (every batch is known).
    pub fn set_total(&mut self, n: usize) {
        self.voter.set_total(n);
    }

    /// The query is expected to have about `n` features in all.
    pub fn set_expected_total(&mut self, n: f64) {
        self.voter.set_expected_total(n);
    }

    /// Running statistics of the votes.
    pub fn tally(&self) -> &Tally {
        self.voter.tally()
    }

    /// (feature number over all batches, word) of each feature voted so far.
    pub fn voted(&self) -> &[Voted] {
        &self.voted
    }

    /// Vote a batch of `count` features in a random order drawn from the
    /// seed (in their own order with [`SearchOptions::given_order`]). `quantize(indices, words, signatures)` fills
    /// `words[..indices.len()]` and `signatures[..indices.len()]` with the
    /// words and Hamming signatures of the batch's features at `indices`
    /// (numbered in the batch from 0). Returns whether the search has stopped.
    pub fn feed(
        &mut self,
        count: usize,
        quantize: impl FnMut(&[u32], &mut [u32], &mut [u64]),
    ) -> bool {
        self.feed_checked(count, quantize, None)
    }

    /// [`feed`](Self::feed), with a geometric check of candidates for rules
    /// that use one (`verified`).
    pub fn feed_checked(
        &mut self,
        count: usize,
        mut quantize: impl FnMut(&[u32], &mut [u32], &mut [u64]),
        mut leader_check: Option<&mut dyn LeaderCheck>,
    ) -> bool {
        if self.stopped() {
            return true;
        }
        let order = batch_order(&self.options, count, self.batches);
        let offset = (self.numbered_from + self.fed) as u32;
        self.batches += 1;
        self.fed += count;
        if let Some(trace) = &mut self.trace {
            trace.batch_end(self.fed);
        }
        let block = self.options.block.max(1);
        for indices in order.chunks(block) {
            if self.options.deadline.is_some_and(|d| Instant::now() >= d) {
                self.stop = Some((StopKind::Deadline, "deadline passed".to_owned()));
                return true;
            }
            let started = Instant::now();
            quantize(
                indices,
                &mut self.words[..indices.len()],
                &mut self.signatures[..indices.len()],
            );
            let quantized = Instant::now();
            self.timings.quantize += quantized - started;
            let mut checking = Duration::ZERO;
            let batch = self.words[..indices.len()].iter().zip(&self.signatures);
            for (k, (&i, (&w, &signature))) in indices.iter().zip(batch).enumerate() {
                self.voter.vote(w, signature);
                self.voted.push(Voted {
                    feature: offset + i,
                    word: w,
                    signature,
                });
                let features = self.voter.tally().features;
                let at_end = self.voted.len() == self.fed;
                let why = if features < self.options.min_features || self.finishing.is_some() {
                    None
                } else {
                    // A geometric check costs far more than a vote: offered
                    // only at a block's end, saying whether the batch ends.
                    let block_end = k + 1 == indices.len();
                    let check = leader_check
                        .as_mut()
                        .filter(|_| block_end)
                        .map(|c| &mut **c as &mut dyn LeaderCheck);
                    let started = block_end.then(Instant::now);
                    let progress = Progress {
                        coarse: self.coarse_batch,
                        ..Progress::new(&self.voted, check, at_end)
                    };
                    let why = self.rule.check_with(&self.voter, progress);
                    if let Some(started) = started {
                        checking += started.elapsed();
                    }
                    why
                };
                if let Some(trace) = self.trace.as_mut().filter(|t| t.wants(features)) {
                    let statistic = self.rule.statistic(&self.voter);
                    trace.record(TracePoint::of(self.voter.tally(), statistic));
                }
                if let Some(why) = why {
                    if self.streamed && !at_end {
                        // the tile is extracted: its other features cost
                        // only their votes, and the answer gains them
                        self.finishing = Some(why);
                    } else {
                        self.stop = Some((StopKind::Rule, why));
                        break;
                    }
                }
                if at_end && let Some(why) = self.finishing.take() {
                    self.stop = Some((StopKind::Rule, tile_finished(why)));
                }
            }
            self.timings.verify += checking;
            self.timings.vote += quantized.elapsed().saturating_sub(checking);
            if self.stopped() {
                return true;
            }
        }
        false
    }

    /// Feed the features of one tile of a streamed image: `count` features,
    /// after which `step.share` of the image (by area, in (0, 1]) has been
    /// extracted; `step.last` when no tile is left, so N becomes known. N is
    /// estimated meanwhile as the features so far over the share extracted.
    /// With [`SearchOptions::finish_tile`], when the rule stops the search
    /// inside a tile of an image that comes in several, the tile's other
    /// features are voted before it ends. On a coarse pass
    /// (`step.coarse`) only the rule's geometric check may stop the search
    /// ([`Progress::coarse`]); a pass that does not is left behind: the
    /// next tile starts the search over, so its answer is the tiles alone's
    /// (while no tile follows, as when a time budget ends the search there,
    /// the answer is the pass's). `step.share` then counts the tiles alone.
    /// Returns whether the search has stopped.
    pub fn feed_tile(
        &mut self,
        count: usize,
        step: TileStep,
        quantize: impl FnMut(&[u32], &mut [u32], &mut [u64]),
        leader_check: Option<&mut dyn LeaderCheck>,
    ) -> bool {
        if self.probed && !self.stopped() {
            self.start_over();
        }
        let fed = self.fed + count;
        self.streamed |= !step.last && self.options.finish_tile;
        if step.last {
            self.set_total(fed);
        } else {
            self.set_expected_total(fed as f64 / step.share.max(1e-9));
        }
        self.coarse_batch = step.coarse && !step.last;
        let stopped = self.feed_checked(count, quantize, leader_check);
        self.probed = self.coarse_batch && !stopped;
        self.coarse_batch = false;
        stopped
    }

    /// Rank the candidates and say why the search ended.
    pub fn finish(self) -> SearchOutcome {
        let (kind, detail) = self
            .stop
            .unwrap_or_else(|| (StopKind::Exhausted, "all features used".to_owned()));
        let used = self.voter.tally().features;
        let mut trace = self.trace;
        if let Some(trace) = &mut trace {
            let statistic = self.rule.statistic(&self.voter);
            trace.finish(TracePoint::of(self.voter.tally(), statistic));
        }
        let prior = self.options.prior.as_deref();
        let (posterior, frame_posterior) = match prior {
            Some(p) => {
                let (h, touched) = (self.voter.histogram(), self.voter.touched());
                let posterior = prior::posterior(p, h, touched, used, p.keep);
                let frame = if p.is_uniform() {
                    posterior.clone()
                } else {
                    let uniform = Prior::uniform(p.images(), p.kappa);
                    prior::posterior(&uniform, h, touched, used, p.keep)
                };
                (Some(posterior), Some(frame))
            }
            None => (None, None),
        };
        let allowed = prior.filter(|p| p.restricts());
        SearchOutcome {
            candidates: rank::top_n(
                &self.voter,
                self.options.top_n,
                self.options.min_score,
                allowed,
                self.options.place_window,
            ),
            posterior,
            frame_posterior,
            features_total: self.fed,
            features_used: used,
            stop: StopInfo {
                kind,
                at_feature: used,
                detail,
            },
            timings: self.timings,
            trace,
        }
    }
}

/// Search with descriptors: quantize (and sign, with `signer`) each block of
/// permuted rows.
pub fn search(
    quantizer: &dyn Quantizer,
    signer: Option<&HammingEmbedding>,
    map: &dyn MapRead,
    descriptors: ArrayView2<'_, f32>,
    options: &SearchOptions,
) -> SearchOutcome {
    search_with(
        map,
        descriptors.nrows(),
        options,
        descriptor_quantizer(quantizer, signer, descriptors, options.block),
    )
}

/// A `quantize(indices, words, signatures)` callback over rows of
/// `descriptors`, copying each block of permuted rows into one buffer for the
/// quantizer; signatures are 0 without a `signer`.
pub fn descriptor_quantizer<'q>(
    quantizer: &'q dyn Quantizer,
    signer: Option<&'q HammingEmbedding>,
    descriptors: ArrayView2<'q, f32>,
    block: usize,
) -> impl FnMut(&[u32], &mut [u32], &mut [u64]) + 'q {
    let mut buffer = Array2::<f32>::zeros((block.max(1), descriptors.ncols()));
    move |indices, words, signatures| {
        for (mut dst, &i) in buffer.rows_mut().into_iter().zip(indices) {
            dst.assign(&descriptors.row(i as usize));
        }
        let rows = buffer.slice(ndarray::s![..indices.len(), ..]);
        quantizer.quantize(rows, words);
        sign_or_zero(signer, rows, words, signatures);
    }
}

/// Features known in advance: feature i quantized to `words[i]` with
/// signature `signatures[i]` (0 where `signatures` is short).
#[derive(Debug, Clone, Copy)]
pub struct KnownFeatures<'a> {
    pub words: &'a [u32],
    pub signatures: &'a [u64],
}

impl<'a> KnownFeatures<'a> {
    /// Words without signatures (all 0).
    pub fn words(words: &'a [u32]) -> Self {
        Self {
            words,
            signatures: &[],
        }
    }

    pub fn len(&self) -> usize {
        self.words.len()
    }

    pub fn is_empty(&self) -> bool {
        self.words.is_empty()
    }

    /// The `quantize` callback that looks them up.
    fn lookup(&self) -> impl FnMut(&[u32], &mut [u32], &mut [u64]) + '_ {
        move |indices, words, signatures| {
            for ((w, s), &i) in words.iter_mut().zip(signatures.iter_mut()).zip(indices) {
                *w = self.words[i as usize];
                *s = self.signatures.get(i as usize).copied().unwrap_or(0);
            }
        }
    }
}

/// Owned [`KnownFeatures`]: a query quantized and signed once, searched
/// many times.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct CodedFeatures {
    pub words: Vec<u32>,
    pub signatures: Vec<u64>,
}

impl CodedFeatures {
    pub fn known(&self) -> KnownFeatures<'_> {
        KnownFeatures {
            words: &self.words,
            signatures: &self.signatures,
        }
    }
}

/// Where one tile of a streamed image leaves the search ([`Search::feed_tile`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TileStep {
    /// Share of the image (by area, in (0, 1]) extracted with this tile.
    pub share: f64,
    /// No tile is left: N is known.
    pub last: bool,
    /// The tile is a coarse pass (the whole frame at half size).
    pub coarse: bool,
}

/// Why a search stopped at the end of the tile its rule fired in.
fn tile_finished(why: String) -> String {
    format!("{why} (then the rest of the tile voted)")
}

/// Stream an image's tiles through a search, tiles given as their features
/// (known in advance) in extraction order with the image share each one
/// covers, the first a coarse pass when `coarse_first`: what the service
/// does with real tiles (used by evaluation). A coarse pass that does not
/// end the search is left behind ([`Search::feed_tile`]), the tiles' shares
/// counted among themselves.
/// Returns the outcome, the (feature number, word) pairs voted (numbered
/// over every unit, the coarse pass's first) and the units extracted.
pub fn search_tiles(
    map: &dyn MapRead,
    tiles: &[(KnownFeatures<'_>, f64)],
    options: &SearchOptions,
    coarse_first: bool,
    mut leader_check: Option<&mut dyn LeaderCheck>,
) -> (SearchOutcome, Vec<Voted>, usize) {
    let mut s = Search::new(map, options);
    let probe = usize::from(coarse_first && tiles.len() > 1);
    let fine: f64 = tiles[probe..].iter().map(|t| t.1).sum();
    let mut share = 0.0;
    let mut used = 0;
    for (k, (features, area)) in tiles.iter().enumerate() {
        let coarse = k < probe;
        share += area;
        used += 1;
        let step = TileStep {
            share: if coarse {
                share
            } else {
                share / fine.max(1e-12)
            },
            last: k + 1 == tiles.len(),
            coarse,
        };
        let check = leader_check
            .as_mut()
            .map(|c| &mut **c as &mut dyn LeaderCheck);
        if s.feed_tile(features.len(), step, features.lookup(), check) {
            break;
        }
        if coarse {
            share = 0.0;
        }
    }
    let voted = s.voted.clone();
    (s.finish(), voted, used)
}

/// Search over features known in advance. Gives exactly the outcome of
/// [`search`] with a quantizer that returns those words and signatures (used
/// by evaluation, which quantizes each query once and votes many times).
pub fn search_words(
    map: &dyn MapRead,
    features: KnownFeatures<'_>,
    options: &SearchOptions,
) -> SearchOutcome {
    search_with(map, features.len(), options, features.lookup())
}

/// One batch of `total` features. `quantize(indices, words, signatures)`
/// fills `words[..indices.len()]` and `signatures[..indices.len()]` for the
/// features at `indices`.
pub fn search_with(
    map: &dyn MapRead,
    total: usize,
    options: &SearchOptions,
    quantize: impl FnMut(&[u32], &mut [u32], &mut [u64]),
) -> SearchOutcome {
    let mut s = Search::new(map, options);
    s.set_total(total);
    s.feed(total, quantize);
    s.finish()
}

#[cfg(test)]
mod tests;
