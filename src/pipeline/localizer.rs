//! Answering one query: a loaded vocabulary and map ([`Localizer`]) that
//! decode an image, extract it tile by tile into the early-stopping search,
//! verify the candidates and report.

use super::build::map_image_words;
use super::orb_pass::{Look, OrbPass};
use crate::features::fit::OpenCvFit;
use crate::features::{
    self, CoarseChoice, DecodeLimits, ExtractConfig, FeatureError, Frame, TileGrid, Tiles,
};
use crate::geometry::Keypoint;
use crate::geometry::matches::QueryFeature;
use crate::geometry::packed::PackedFeature;
use crate::geometry::verify::{LeaderVerifier, VerifyParams, rerank, with_keypoints};
use crate::index::{MapIndex, MapRead};
use crate::live::{LiveMap, Opened, Snapshot};
use crate::quantize::QuantizerKind;
use crate::report::{CandidateMatches, EdgeTimings, Extraction, ImageSize, Localization};
use crate::search::{self, Search, SearchOptions};
use crate::vocabulary::Vocabulary;
use anyhow::Context;
use std::path::Path;
use std::time::{Duration, Instant};

/// Most points of a traced vote race (the sampling step doubles beyond).
pub const TRACE_POINTS: usize = 256;

/// What a query records of its vote race.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum Tracing {
    /// Nothing (the default).
    #[default]
    Off,
    /// The race up to the stop.
    On,
    /// The race, and the full search over every feature for comparison.
    Full,
}

/// What the units of one request have cost so far: what its time budget
/// and its saving are priced from.
struct Spent {
    /// The coarse pass, when it came first.
    pass: Option<search::budget::UnitCost>,
    /// Each tile after it, in the order extracted.
    tiles: Vec<search::budget::UnitCost>,
    /// Of the tiles' time, their quantization, votes and checks.
    voting: Duration,
    /// The tiles are the configured grid's, whose first tiles the
    /// localizer has learnt.
    configured: bool,
}

impl Spent {
    /// `n` tiles at what the coarse pass took each (`None`: no pass).
    fn each_as_the_pass(&self, n: u32) -> Option<Duration> {
        self.pass.map(|p| p.time * n)
    }
}

/// How a query is extracted ([`Localizer::plan`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Plan {
    pub grid: TileGrid,
    /// The grid is the learned coarse pass's choice ([`CoarseChoice`]), so
    /// what the answer cost teaches it ([`Localizer::learn`]), unless a time
    /// budget ended the search.
    learned: bool,
}

impl Plan {
    /// Whether the grid is the learned coarse pass's choice.
    pub fn learned(&self) -> bool {
        self.learned
    }

    /// The grid a caller asked for: nothing to learn from.
    pub fn asked(grid: TileGrid) -> Self {
        Self {
            grid,
            learned: false,
        }
    }
}

/// A loaded vocabulary and map, ready to answer queries. The map may take
/// changes ([`LiveMap`]); each query searches the snapshot current when it
/// starts.
pub struct Localizer {
    pub vocab: Vocabulary,
    pub map: LiveMap,
    pub limits: DecodeLimits,
    pub quantizer: QuantizerKind,
    /// How queries are extracted: the vocabulary's settings, which a front end
    /// may tighten (e.g. cap `sift.max_features`).
    pub extract: ExtractConfig,
    /// How queries are cut into tiles for streaming extraction
    /// ([`TileGrid::WHOLE`]: the whole image at once).
    pub tiles: TileGrid,
    /// Whether a query's extraction starts with the coarse pass, learned
    /// from what requests cost ([`CoarseChoice`]); `None`: as `tiles` says.
    pub coarse_choice: Option<CoarseChoice>,
    /// Geometric verification ([`Localizer::set_verify`]); off unless a front
    /// end turns it on.
    verify: VerifyParams,
    fit: OpenCvFit,
    /// What tiles cost, learnt from the requests served (what a time budget
    /// prices the next tile with).
    tile_cost: search::budget::TileCostModel,
    /// The map's ORB side, when the ORB pass is to look at queries first
    /// ([`SearchOptions::orb_pass`]).
    pub orb_pass: Option<OrbPass>,
}

impl Localizer {
    /// Open both files and check that the map was built with the vocabulary.
    pub fn open(vocab: &Path, map: &Path, verify: bool) -> anyhow::Result<Self> {
        let vocab_file = Vocabulary::open(vocab, verify)?;
        let map = LiveMap::fixed(MapIndex::open_for(map, &vocab_file, verify)?);
        Ok(Self::with_map(vocab_file, map))
    }

    /// Open both files and the map's change log (replayed; created when
    /// missing), so the map takes changes; at most `max_images` images.
    pub fn open_live(
        vocab: &Path,
        map: &Path,
        verify: bool,
        max_images: usize,
    ) -> anyhow::Result<(Self, Opened)> {
        let vocab_file = Vocabulary::open(vocab, verify)?;
        let (map, opened) = LiveMap::open(map, Some(&vocab_file), verify, max_images)?;
        Ok((Self::with_map(vocab_file, map), opened))
    }

    fn with_map(vocab_file: Vocabulary, map: LiveMap) -> Self {
        let no_verify = VerifyParams {
            enabled: false,
            ..VerifyParams::default()
        };
        Self {
            extract: vocab_file.meta().extract.clone(),
            vocab: vocab_file,
            map,
            limits: DecodeLimits::default(),
            quantizer: QuantizerKind::Exact,
            tiles: TileGrid::WHOLE,
            coarse_choice: None,
            fit: OpenCvFit::new(no_verify.fit()),
            verify: no_verify,
            tile_cost: search::budget::TileCostModel::new(),
            orb_pass: None,
        }
    }

    /// The features an image given as encoded bytes adds to the map: the
    /// whole image extracted with the vocabulary's settings and exactly
    /// quantized, as `bowloc map build` indexes it.
    pub fn map_features(&self, bytes: &[u8]) -> Result<Vec<PackedFeature>, FeatureError> {
        let config = &self.vocab.meta().extract;
        let image = features::decode(bytes, self.limits, config.max_side)?;
        let f = features::extract(&image, config)?;
        Ok(map_image_words(&self.vocab, "", Some(&f)).geometry)
    }

    /// Verification settings; `params.enabled` is the default of
    /// [`Localizer::localize`].
    pub fn set_verify(&mut self, params: VerifyParams) {
        self.fit = OpenCvFit::new(params.fit());
        self.verify = params;
    }

    pub fn verify_params(&self) -> &VerifyParams {
        &self.verify
    }

    /// The search options of a query that will be verified: enough vote
    /// candidates for the top k, none dropped by a vote score (`min_score`
    /// then applies to inliers), and a stop inside a tile finishing the tile
    /// ([`SearchOptions::finish_tile`]).
    pub fn options_for_verify(&self, options: &SearchOptions) -> SearchOptions {
        SearchOptions {
            top_n: options.top_n.max(self.verify.top_k),
            min_score: 0.0,
            finish_tile: true,
            ..options.clone()
        }
    }

    /// Verify the vote candidates of `answer` (searched with
    /// [`Localizer::options_for_verify`]`(options)`) against the query's
    /// features the search used (`query`: word and keypoint), re-rank them
    /// by inliers and keep `options.top_n` scoring at least `options.min_score`.
    pub fn verify(
        &self,
        map: &dyn MapRead,
        answer: Localization,
        query: &[QueryFeature],
        options: &SearchOptions,
    ) -> Localization {
        let started = Instant::now();
        let votes: Vec<(u32, f32)> = answer.candidates.iter().map(|c| (c.id, c.score)).collect();
        let reranked = rerank(
            map,
            &votes,
            query,
            &self.fit,
            &self.verify,
            options.place_window,
        );
        let mut answer = answer.verified(
            map,
            &reranked,
            options.top_n,
            options.min_score,
            started.elapsed(),
        );
        // a traced answer shows each candidate's inliers, those of the fit
        // that counted them
        if let Some(trace) = &mut answer.trace {
            trace.matches = answer
                .candidates
                .iter()
                .filter(|c| c.inliers.unwrap_or(0) > 0)
                .filter_map(|c| reranked.iter().find(|r| r.id == c.id))
                .map(|r| CandidateMatches::new(r.id, &r.inlier_pairs.query, &r.inlier_pairs.map))
                .collect();
        }
        answer
    }

    /// Answer one query image given as encoded bytes: decode, then extract
    /// tile after tile (in the options' tile order, richest first by default)
    /// and feed each
    /// tile's features to the search, until the search stops or the tiles
    /// run out.
    pub fn localize(
        &self,
        bytes: &[u8],
        options: &SearchOptions,
    ) -> Result<Localization, FeatureError> {
        let plan = self.plan(options, None);
        let answer = self.localize_tiled(bytes, options, plan.grid, self.verify.enabled)?;
        self.learn(plan, &answer);
        Ok(answer)
    }

    /// How a query is extracted: in the grid `asked` for, else the
    /// configured grid when the rule may stop early, else the whole image (a
    /// search that reads every feature gains nothing from tiles and would pay
    /// their overlap). With a learned coarse pass ([`CoarseChoice`]) the
    /// configured grid starts with it or not as the choice says; pass the
    /// answer to [`Localizer::learn`]. A time budget too tight for the tiles
    /// starts with the pass ([`search::budget::pass_first`]).
    pub fn plan(&self, options: &SearchOptions, asked: Option<TileGrid>) -> Plan {
        let grid = match asked {
            Some(grid) => return Plan::asked(grid),
            None if options.rule.info().stops_early => match &self.coarse_choice {
                Some(choice) => TileGrid {
                    coarse: choice.choose(),
                    ..self.tiles
                },
                None => self.tiles,
            },
            None => TileGrid::WHOLE,
        };
        let drawn = self.coarse_choice.is_some() && options.rule.info().stops_early;
        let Some(budget) = options.budget else {
            return Plan {
                grid,
                learned: drawn,
            };
        };
        let first_tiles = self
            .tile_cost
            .tiles_to_beat_the_pass(options.core_spare_now());
        let tight = search::budget::pass_first(budget, first_tiles);
        Plan {
            grid: TileGrid {
                coarse: grid.coarse || (tight && grid.count() > 1),
                ..grid
            },
            // a plan the budget chose teaches nothing (nor does a search the
            // budget ended: Localizer::learn)
            learned: drawn && !tight,
        }
    }

    /// What tiles cost, as learnt from the requests so far.
    pub fn tile_cost(&self) -> &search::budget::TileCostModel {
        &self.tile_cost
    }

    /// What the search needs next, in tiles, and how long they are
    /// expected to take ([`search::budget`]): after tiles, the next one,
    /// priced by the keypoints it is expected to hold (the tiles' keypoints
    /// so far shared out by their expected shares), with `two_at_a_time`
    /// the next two, extracted together, at the longer of the two; a tile
    /// extracted ahead by its own keypoints' votes alone. After the coarse
    /// pass alone, [`search::budget::TILES_TO_BEAT_THE_PASS`] tiles at what
    /// the pass took for each wait ([`search::budget::waits`]; pricing them
    /// as [`Localizer::first_tiles_time`] does answered no better:
    /// docs/service.md, "A time budget").
    fn next_tiles_time(
        &self,
        tiles: &Tiles,
        spent: &Spent,
        two_at_a_time: bool,
    ) -> (Duration, u32) {
        if spent.tiles.is_empty() {
            let n = search::budget::TILES_TO_BEAT_THE_PASS;
            let waits = search::budget::waits(n, two_at_a_time);
            return (spent.each_as_the_pass(waits).unwrap_or_default(), n);
        }
        if let Some(keypoints) = tiles.waiting_keypoints() {
            let voted = spent.tiles.iter().map(|c| c.keypoints).sum();
            return (
                search::budget::waiting_tile_time(spent.voting, voted, keypoints),
                1,
            );
        }
        let left = tiles.shares_left();
        let next = &left[..search::budget::tiles_a_wait(two_at_a_time).min(left.len())];
        let longest = next
            .iter()
            .map(|&share| self.priced(tiles, &spent.tiles, &[share]))
            .max();
        (longest.unwrap_or_default(), next.len() as u32)
    }

    /// The tiles with expected shares `left` after those of `costs` (at
    /// least one), priced as [`search::budget::tiles_left_time`] prices them.
    fn priced(&self, tiles: &Tiles, costs: &[search::budget::UnitCost], left: &[f64]) -> Duration {
        let per_keypoint = self.tile_cost.per_keypoint();
        search::budget::tiles_left_time(costs, tiles.share_extracted(), left, per_keypoint)
    }

    /// What the first `n` tiles are expected to take before any is timed,
    /// one at a time (the extraction a stop saves, wherever it would have
    /// run): in the configured grid, what they have taken lately, each place in
    /// the order at its own mean ([`search::budget::TileCostModel::first_tiles`]);
    /// else (another grid, or nothing learnt yet) each at what the coarse
    /// pass took.
    fn first_tiles_time(&self, n: usize, spent: &Spent) -> Duration {
        let learnt = spent
            .configured
            .then(|| self.tile_cost.first_tiles(n, false));
        let each_as_the_pass = spent.each_as_the_pass(n as u32);
        learnt.flatten().or(each_as_the_pass).unwrap_or_default()
    }

    /// What the tiles not extracted yet would have taken: a stop's saving.
    /// After tiles, each priced by its expected keypoints; after the coarse
    /// pass alone, as [`Localizer::first_tiles_time`] prices them.
    fn skipped_time(&self, tiles: &Tiles, spent: &Spent) -> Duration {
        let left = tiles.shares_left();
        match spent.tiles.is_empty() {
            false => self.priced(tiles, &spent.tiles, left),
            true => self.first_tiles_time(left.len(), spent),
        }
    }

    /// Tell the learned coarse pass what `answer` cost, when `plan` was its
    /// choice and no time budget ended the search (a search cut right after
    /// the coarse pass would count as one the pass ended, and the cut's time
    /// as the plan's).
    pub fn learn(&self, plan: Plan, answer: &Localization) {
        if let Some(choice) = &self.coarse_choice
            && plan.learned
            && answer.stop.kind != search::StopKind::Budget
            && answer.stop.kind != search::StopKind::OrbPass
        {
            let t = &answer.timings_ms;
            choice.record(
                answer.tiles.grid.coarse,
                t.total - t.decode - t.orb_pass,
                answer.tiles.extracted <= 1,
            );
        }
    }

    /// [`Localizer::localize`] with another tile grid than the configured
    /// one, saying whether to verify.
    pub fn localize_tiled(
        &self,
        bytes: &[u8],
        options: &SearchOptions,
        grid: TileGrid,
        verify: bool,
    ) -> Result<Localization, FeatureError> {
        self.localize_traced(bytes, options, grid, verify, Tracing::Off)
    }

    /// [`Localizer::localize_tiled`], recording the vote race as `tracing`
    /// asks. With [`Tracing::Full`] the remaining tiles are extracted after
    /// the stop and every feature is voted by a second search without a
    /// rule, to show where and with what answer the full search ends; that
    /// work is not counted in the answer's timings.
    pub fn localize_traced(
        &self,
        bytes: &[u8],
        options: &SearchOptions,
        grid: TileGrid,
        verify: bool,
        tracing: Tracing,
    ) -> Result<Localization, FeatureError> {
        self.answer(bytes, options, grid, verify, tracing, true)
    }

    /// Answer a synthetic query ([`features::warm_up_image`]) on this
    /// thread, as a streamed query of the configured grid is answered (the
    /// coarse pass first when the grid has tiles, then every tile; two at a
    /// time with `pairs`, as on a spare core, then verified when the
    /// answers are), so that the requests after it do not pay for the
    /// thread's first extraction. It teaches nothing: neither the learned
    /// plan nor what tiles cost. Returns the features it extracted.
    pub fn warm_up(&self, pairs: bool) -> Result<usize, FeatureError> {
        let bytes = features::warm_up_image(&self.extract, self.limits.max_pixels)?;
        let options = SearchOptions {
            spare_core: Some(search::SpareCore::new(move || pairs)),
            ..SearchOptions::default()
        };
        let grid = TileGrid {
            coarse: self.tiles.count() > 1,
            ..self.tiles
        };
        let answer = self.answer(
            &bytes,
            &options,
            grid,
            self.verify.enabled,
            Tracing::Off,
            false,
        )?;
        Ok(answer.features.total)
    }

    /// [`Localizer::localize_traced`], teaching what the configured grid's
    /// tiles cost when `learn_tile_costs`.
    fn answer(
        &self,
        bytes: &[u8],
        options: &SearchOptions,
        grid: TileGrid,
        verify: bool,
        tracing: Tracing,
        learn_tile_costs: bool,
    ) -> Result<Localization, FeatureError> {
        // a geometric stop verified its leader: its answer is verified too
        let verify = verify || options.rule.geometric();
        let (searched, options) = match verify {
            true => (self.options_for_verify(options), options),
            false => (options.clone(), options),
        };
        let started = Instant::now();
        let image = features::decode(bytes, self.limits, self.extract.max_side)?;
        let decoded = Instant::now();
        let size = ImageSize {
            width: image.width(),
            height: image.height(),
        };
        let snapshot = self.map.snapshot();
        let map: &dyn MapRead = &*snapshot;
        // the extraction frame, which the ORB pass looks at first when it
        // may answer (the frame's time is the pass's when it answers, else
        // extraction's); if it fails, SIFT answers as without it
        let framing = Instant::now();
        let frame = Frame::new(&image, &self.extract)?;
        let framed = framing.elapsed();
        let look = self
            .orb_pass_for(options, tracing, &snapshot)
            .and_then(|pass| match pass.look(&frame) {
                Ok(mut look) => {
                    if look.answer.is_some() {
                        look.took += framed;
                    }
                    Some(look)
                }
                Err(e) => {
                    tracing::warn!("the ORB pass failed ({e}); the SIFT search answers");
                    None
                }
            });
        if let Some(look) = &look
            && let Some(ranked) = &look.answer
        {
            return Ok(orb_answer(
                map,
                options,
                grid,
                size,
                decoded - started,
                look,
                ranked,
            ));
        }
        let tiling = Instant::now();
        let mut tiles = Tiles::of_frame(frame, grid, Some((options.tile_order, options.seed)))?;
        let mut extract = framed + tiling.elapsed();
        let quantizer = self.vocab.quantizer(self.quantizer);
        let mut search = Search::new(map, &searched);
        let mut full = None;
        if tracing != Tracing::Off {
            search = search.trace(1, TRACE_POINTS);
        }
        if tracing == Tracing::Full {
            let everything = SearchOptions {
                rule: search::RuleSpec::new("none", None).expect("built-in rule"),
                min_features: 0,
                ..searched.clone()
            };
            full = Some(Search::new(map, &everything).trace(1, TRACE_POINTS));
        }
        let mut keypoints: Vec<Keypoint> = Vec::new();
        let mut tiles_used = 0;
        let tiles_only = |g: TileGrid| TileGrid { coarse: false, ..g };
        let mut spent = Spent {
            pass: None,
            tiles: Vec::new(),
            voting: Duration::ZERO,
            configured: tiles_only(grid) == tiles_only(self.tiles),
        };
        // what the tiles the search stopped before would have taken
        let mut skipped = None;
        loop {
            // a core that would idle extracts the tile after this one
            let mut ahead = options.core_spare_now();
            // a budget ends a search only where a tile is left to skip, and
            // never before the first (after a coarse pass, with the pass's
            // votes: the next tile would start the search over); the next
            // two tiles that do not fit together may fit one at a time
            if let Some(budget) = options
                .budget
                .filter(|_| !search.stopped() && (1..tiles.total()).contains(&tiles.extracted()))
            {
                let fits = |two_at_a_time| {
                    let (next, n) = self.next_tiles_time(&tiles, &spent, two_at_a_time);
                    search::budget::next_tiles_fit(budget, started.elapsed(), next, n)
                };
                match search::budget::next_wait(ahead, fits) {
                    Ok(two_at_a_time) => ahead = two_at_a_time,
                    Err(why) => search.end(search::StopKind::Budget, why),
                }
            }
            if search.stopped() && skipped.is_none() {
                skipped = Some(self.skipped_time(&tiles, &spent));
            }
            if search.stopped() && full.as_ref().is_none_or(Search::stopped) {
                break;
            }
            tiles.extract_ahead(ahead);
            let t = Instant::now();
            let Some(tile) = tiles.next_tile() else { break };
            let tile = tile?;
            let took = t.elapsed();
            let step = search::TileStep {
                share: tiles.share_extracted(),
                last: tiles.extracted() == tiles.total(),
                coarse: grid.coarse && tiles.extracted() == 1,
            };
            if let Some(full) = &mut full {
                let quantize = search::descriptor_quantizer(
                    &*quantizer,
                    self.vocab.hamming(),
                    tile.descriptors.view(),
                    options.block,
                );
                full.feed_tile(tile.len(), step, quantize, None);
            }
            if search.stopped() {
                continue;
            }
            extract += took;
            tiles_used += 1;
            keypoints.extend_from_slice(&tile.keypoints);
            let quantize = search::descriptor_quantizer(
                &*quantizer,
                self.vocab.hamming(),
                tile.descriptors.view(),
                options.block,
            );
            let mut check = LeaderVerifier {
                map,
                fit: &self.fit,
                params: &self.verify,
                keypoints: &keypoints,
                place_window: options.place_window,
            };
            let fed = Instant::now();
            search.feed_tile(tile.len(), step, quantize, Some(&mut check));
            let cost = search::budget::UnitCost {
                // the tile's own extraction, not the wait for it
                time: tiles.last_time() + fed.elapsed(),
                keypoints: tile.len(),
            };
            match step.coarse {
                true => spent.pass = Some(cost),
                false => {
                    spent.tiles.push(cost);
                    spent.voting += fed.elapsed();
                }
            }
        }
        // what the tiles of the configured grid cost (not a grid asked for)
        if spent.configured && learn_tile_costs {
            self.tile_cost.record(&spent.tiles);
        }
        let extraction = Extraction {
            tiles_extracted: tiles_used,
            tiles_total: tiles.total(),
            grid,
            tile_order: options.tile_order,
            expected_features: search.tally().total_or_estimate(),
            complete: tiles_used == tiles.total(),
            skipped: skipped.unwrap_or_default(),
            ahead: tiles.ahead(),
        };
        let edge = EdgeTimings {
            decode: decoded - started,
            extract,
        };
        let query = with_keypoints(search.voted(), &keypoints);
        let outcome = search.finish();
        let mut answer = Localization::new(
            map,
            &options.rule,
            options.seed,
            size,
            outcome,
            edge,
            extraction,
        );
        if let Some(full) = full {
            answer.compare_with_full(map, full.finish(), options.top_n);
        }
        if let Some(trace) = &mut answer.trace {
            trace.frame_side = self.extract.max_side;
        }
        let answer = if verify {
            self.verify(map, answer, &query, options)
        } else {
            answer
        };
        let answer = answer.keeping_distinct(options.min_distinct);
        Ok(match look {
            Some(look) => answer.after_orb_pass(look.took, look.checked.len()),
            None => answer,
        })
    }

    /// The ORB pass, if it may answer this query: the map has its ORB side
    /// and has not changed since it was built, the request lets it
    /// ([`SearchOptions::orb_pass`]), and the search could stop early
    /// anyway (not a full search, no prior to update, no trace).
    fn orb_pass_for(
        &self,
        options: &SearchOptions,
        tracing: Tracing,
        snapshot: &Snapshot,
    ) -> Option<&OrbPass> {
        let pass = self.orb_pass.as_ref()?;
        let may = options.orb_pass
            && tracing == Tracing::Off
            && options.prior.is_none()
            && options.rule.info().stops_early
            && pass.is_current(snapshot.generation());
        may.then_some(pass)
    }

    /// Read a file and answer it as a query, extracted in the grid `tiles`
    /// asks for, else as [`Localizer::plan`] chooses.
    pub fn localize_file(
        &self,
        path: &Path,
        options: &SearchOptions,
        tiles: Option<TileGrid>,
    ) -> anyhow::Result<Localization> {
        let bytes =
            std::fs::read(path).with_context(|| format!("{}: cannot read", path.display()))?;
        let plan = self.plan(options, tiles);
        let answer = self
            .localize_tiled(&bytes, options, plan.grid, self.verify.enabled)
            .with_context(|| format!("{}", path.display()))?;
        self.learn(plan, &answer);
        Ok(answer)
    }
}

/// The ORB pass's answer to a query (`ranked`, from `look`): a search
/// stopped before its first feature, answered by the pass's candidates.
fn orb_answer(
    map: &dyn MapRead,
    options: &SearchOptions,
    grid: TileGrid,
    size: ImageSize,
    decode: Duration,
    look: &Look,
    ranked: &[u32],
) -> Localization {
    let mut search = Search::new(map, options);
    let pick = look.checked.iter().find(|c| c.image == ranked[0]);
    search.end(
        search::StopKind::OrbPass,
        format!(
            "the ORB pass verified map image {} with {} inliers",
            ranked[0],
            pick.map_or(0, |c| c.inliers)
        ),
    );
    let extraction = Extraction {
        tiles_extracted: 0,
        tiles_total: grid.count(),
        grid,
        tile_order: options.tile_order,
        expected_features: 0.0,
        complete: false,
        skipped: Duration::ZERO,
        ahead: Default::default(),
    };
    let edge = EdgeTimings {
        decode,
        extract: Duration::ZERO,
    };
    Localization::new(
        map,
        &options.rule,
        options.seed,
        size,
        search.finish(),
        edge,
        extraction,
    )
    .answered_by_orb_pass(
        map,
        ranked,
        &look.checked,
        look.floor,
        options.top_n,
        options.min_score,
        look.took,
    )
}
