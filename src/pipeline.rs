//! The glue every front end shares: extracting features over image lists,
//! building a vocabulary or a map from images, and answering one query
//! (decode → extract → search → verify → report).

use crate::dataset::ImageRef;
use crate::features::fit::OpenCvFit;
use crate::features::{
    self, CoarseChoice, DecodeLimits, ExtractConfig, FeatureError, Features, TileGrid, Tiles,
};
use crate::geometry::Keypoint;
use crate::geometry::matches::QueryFeature;
use crate::geometry::packed::PackedFeature;
use crate::geometry::verify::{LeaderVerifier, VerifyParams, rerank, with_keypoints};
use crate::index::{ImageWords, MapBuilder, MapIndex, MapRead, Places};
use crate::live::{LiveMap, Opened};
use crate::quantize::{Quantizer, QuantizerKind};
use crate::report::{CandidateMatches, EdgeTimings, Extraction, ImageSize, Localization};
use crate::search::{self, CodedFeatures, Search, SearchOptions};
use crate::vocabulary::kmeans::{KmeansConfig, kmeans};
use crate::vocabulary::{Vocabulary, VocabularyMeta};
use anyhow::{Context, bail};
use cpu_time::ThreadTime;
use indicatif::{ProgressBar, ProgressStyle};
use ndarray::{Array2, ArrayView2, Axis};
use rayon::prelude::*;
use std::path::Path;
use std::time::{Duration, Instant};

/// A progress bar on stderr (hidden when stderr is not a terminal).
pub fn progress_bar(len: u64, what: &str) -> ProgressBar {
    let bar = ProgressBar::new(len);
    bar.set_style(
        ProgressStyle::with_template("{msg:>24} [{bar:40}] {pos}/{len} ({elapsed}, eta {eta})")
            .expect("valid template")
            .progress_chars("=> "),
    );
    bar.set_message(what.to_owned());
    bar
}

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

/// One image's features and what reading them cost.
#[derive(Debug, Clone)]
pub struct Extracted {
    /// Keypoints and descriptor rows tile by tile, in grid order.
    pub features: Features,
    /// Reading and decoding the file (thread CPU time).
    pub decode: Duration,
    /// Feature extraction on the decoded image, all tiles (thread CPU time).
    pub extract: Duration,
    /// Each tile in grid order: its features, its share of the image's area
    /// and its extraction time (one tile when extracted whole).
    pub tiles: Vec<TileCost>,
}

/// What one tile of an image held and cost.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TileCost {
    pub features: usize,
    pub area: f64,
    pub extract: Duration,
    /// FAST corners counted in the tile before extraction (0 for a whole
    /// image), what the tile orders `spread` and `richest` read.
    pub corners: f32,
    /// Its cell (column, row) in the grid ([0, 0] for the coarse pass).
    pub cell: [u32; 2],
}

/// Extract a decoded image tile by tile in grid order, timing each tile by
/// the thread's CPU time (OpenCV runs on the calling thread here), with
/// each tile's corner count (counted first, its time in no tile's).
pub fn extract_tiled(
    image: &features::GrayImage,
    config: &ExtractConfig,
    grid: TileGrid,
) -> Result<(Features, Vec<TileCost>), FeatureError> {
    let mut tiles = Tiles::new(image, config, grid, None)?;
    let corners = tiles.corners()?;
    let cells = tiles.cells();
    let coarse = usize::from(grid.coarse);
    let mut parts = Vec::with_capacity(tiles.total());
    let mut costs = Vec::with_capacity(tiles.total());
    let mut area = 0.0;
    loop {
        let started = ThreadTime::now();
        let Some(tile) = tiles.next_tile() else { break };
        let tile = tile?;
        let share = tiles.share_extracted();
        let unit = costs.len();
        costs.push(TileCost {
            features: tile.len(),
            area: share - area,
            extract: started.elapsed(),
            corners: unit
                .checked_sub(coarse)
                .and_then(|t| corners.get(t).copied())
                .unwrap_or(0.0),
            cell: unit
                .checked_sub(coarse)
                .and_then(|t| cells.get(t).copied())
                .unwrap_or_default(),
        });
        area = share;
        parts.push(tile);
    }
    let refs: Vec<&Features> = parts.iter().collect();
    let features = Features {
        descriptors: stack(&refs),
        keypoints: parts
            .iter()
            .flat_map(|p| p.keypoints.iter().copied())
            .collect(),
    };
    Ok((features, costs))
}

/// A decoded image extracted with each grid of `grids` in turn, `rounds`
/// times over, keeping for each grid its cheapest round (by the thread's CPU
/// time for the whole extraction, corner counting included). The grids are
/// timed back to back under the same load, so their ratios hold even when
/// the machine's speed drifts between minutes. Each result's `decode` is
/// zero: the caller decoded the image.
pub fn extract_interleaved(
    image: &features::GrayImage,
    config: &ExtractConfig,
    grids: &[TileGrid],
    rounds: usize,
) -> Result<Vec<Extracted>, FeatureError> {
    let mut best: Vec<Option<Extracted>> = vec![None; grids.len()];
    for _round in 0..rounds.max(1) {
        for (kept, &grid) in best.iter_mut().zip(grids) {
            let started = ThreadTime::now();
            let (features, tiles) = extract_tiled(image, config, grid)?;
            let extract = started.elapsed();
            if kept.as_ref().is_none_or(|k| extract < k.extract) {
                *kept = Some(Extracted {
                    features,
                    decode: Duration::ZERO,
                    extract,
                    tiles,
                });
            }
        }
    }
    Ok(best.into_iter().flatten().collect())
}

/// Features (keypoints and descriptors) of every image, in parallel, one
/// image per core. Images that
/// cannot be read or decoded are `None`, each named in a warning, with a count
/// at the end; with `strict` the first one is an error.
pub fn extract_all(
    images: &[ImageRef],
    config: &ExtractConfig,
    limits: DecodeLimits,
    strict: bool,
    what: &str,
) -> anyhow::Result<Vec<Option<Features>>> {
    let timed = extract_all_timed(images, config, TileGrid::WHOLE, limits, strict, what)?;
    Ok(timed.into_iter().map(|e| e.map(|e| e.features)).collect())
}

/// [`extract_all`], tile by tile with `grid`, keeping how long each image
/// took to decode and each tile to extract. The times are CPU time of the
/// thread doing the work (one image per thread, OpenCV on one thread), so
/// they price the work as a quiet machine would even when other processes
/// share the cores: wall time there would charge for the waiting too.
pub fn extract_all_timed(
    images: &[ImageRef],
    config: &ExtractConfig,
    grid: TileGrid,
    limits: DecodeLimits,
    strict: bool,
    what: &str,
) -> anyhow::Result<Vec<Option<Extracted>>> {
    let together = extract_all_together(images, config, &[grid], 1, limits, strict, what)?;
    Ok(together
        .into_iter()
        .map(|e| e.and_then(|e| e.into_iter().next()))
        .collect())
}

/// [`extract_all_timed`] with several grids at once: each image is decoded
/// once and extracted with every grid back to back, `rounds` times over
/// ([`extract_interleaved`]), so that the grids' times compare image by
/// image. Per image, one [`Extracted`] per grid, in the order of `grids`.
pub fn extract_all_together(
    images: &[ImageRef],
    config: &ExtractConfig,
    grids: &[TileGrid],
    rounds: usize,
    limits: DecodeLimits,
    strict: bool,
    what: &str,
) -> anyhow::Result<Vec<Option<Vec<Extracted>>>> {
    features::set_opencv_threads(1);
    let bar = progress_bar(images.len() as u64, what);
    let results: Vec<Result<Vec<Extracted>, FeatureError>> = images
        .par_iter()
        .map(|image| {
            let started = ThreadTime::now();
            let r =
                features::decode_file(&image.path, limits, config.max_side).and_then(|decoded| {
                    let read = started.elapsed();
                    let mut each = extract_interleaved(&decoded, config, grids, rounds)?;
                    for e in &mut each {
                        e.decode = read;
                    }
                    Ok(each)
                });
            bar.inc(1);
            r
        })
        .collect();
    bar.finish_and_clear();
    let mut out = Vec::with_capacity(images.len());
    let mut failed = 0;
    for (image, result) in images.iter().zip(results) {
        match result {
            Ok(e) => {
                if e.first().is_some_and(|e| e.features.is_empty()) {
                    tracing::warn!(image = %image.name, "no features found");
                }
                out.push(Some(e));
            }
            Err(e) => {
                if strict {
                    bail!("{}: {e}", image.path.display());
                }
                tracing::warn!(image = %image.path.display(), "skipped: {e}");
                failed += 1;
                out.push(None);
            }
        }
    }
    if failed > 0 {
        tracing::warn!(
            "{failed} of {} images could not be read and were skipped",
            images.len()
        );
    }
    if out.iter().all(Option::is_none) {
        bail!("none of the {} images could be read", images.len());
    }
    Ok(out)
}

/// Stack the descriptor rows of several images.
pub fn stack(parts: &[&Features]) -> Array2<f32> {
    let views: Vec<ArrayView2<'_, f32>> = parts.iter().map(|f| f.descriptors.view()).collect();
    if views.is_empty() {
        return Array2::zeros((0, 128));
    }
    ndarray::concatenate(Axis(0), &views).expect("same width")
}

/// Train a vocabulary on descriptors already extracted with `extract`.
pub fn train_vocabulary(
    descriptors: ArrayView2<'_, f32>,
    extract: &ExtractConfig,
    config: &KmeansConfig,
) -> anyhow::Result<Vocabulary> {
    let bar = progress_bar(config.k as u64, "k-means");
    let (centroids, report) = kmeans(descriptors, config, &bar)?;
    bar.finish_and_clear();
    tracing::info!(
        words = config.k,
        iterations = report.iterations,
        last_change = report.last_change,
        trained_on = report.trained_on,
        reseeded = report.reseeded,
        "vocabulary trained"
    );
    Ok(Vocabulary::trained(
        centroids,
        VocabularyMeta {
            extract: extract.clone(),
            seed: config.seed,
            trained_on: report.trained_on,
            iterations: report.iterations,
            ..Default::default()
        },
        descriptors,
    ))
}

/// Extract descriptors from `images` and train a vocabulary on them.
pub fn build_vocabulary(
    images: &[ImageRef],
    extract: &ExtractConfig,
    config: &KmeansConfig,
    strict: bool,
) -> anyhow::Result<Vocabulary> {
    let all = extract_all(
        images,
        extract,
        DecodeLimits::default(),
        strict,
        "extracting",
    )?;
    let parts: Vec<&Features> = all.iter().flatten().collect();
    let data = stack(&parts);
    tracing::info!(
        descriptors = data.nrows(),
        images = parts.len(),
        "training vocabulary"
    );
    train_vocabulary(data.view(), extract, config)
}

/// Words of every row of `descriptors`, in parallel blocks.
pub fn quantize_all(quantizer: &dyn Quantizer, descriptors: ArrayView2<'_, f32>) -> Vec<u32> {
    let mut words = vec![0u32; descriptors.nrows()];
    descriptors
        .axis_chunks_iter(Axis(0), 256)
        .into_par_iter()
        .zip(words.par_chunks_mut(256))
        .for_each(|(block, out)| quantizer.quantize(block, out));
    words
}

/// Each image's features quantized (exactly) and signed, in order (none for
/// an unreadable image).
pub fn words_per_image(vocab: &Vocabulary, features: &[Option<Features>]) -> Vec<CodedFeatures> {
    features
        .iter()
        .map(|f| {
            f.as_ref()
                .map(|f| code(vocab, f.descriptors.view()))
                .unwrap_or_default()
        })
        .collect()
}

/// Descriptors quantized (exactly) and signed.
pub fn code(vocab: &Vocabulary, descriptors: ArrayView2<'_, f32>) -> CodedFeatures {
    let words = quantize_all(vocab.exact_quantizer(), descriptors);
    let mut signatures = vec![0u64; words.len()];
    vocab.sign(descriptors, &words, &mut signatures);
    CodedFeatures { words, signatures }
}

/// Build a map from per-image features (`None`: unreadable image, kept as
/// an image without features so ids stay equal to list order). The map
/// keeps each feature's word and keypoint for verification.
pub fn index_descriptors(
    vocab: &Vocabulary,
    names: &[String],
    features: &[Option<Features>],
    places: Option<&Places>,
    map_name: &str,
) -> MapIndex {
    let bar = progress_bar(names.len() as u64, "quantizing map");
    let images: Vec<ImageWords> = names
        .par_iter()
        .zip(features)
        .map(|(name, f)| {
            let image = map_image_words(vocab, name, f.as_ref());
            bar.inc(1);
            image
        })
        .collect();
    bar.finish_and_clear();
    let mut builder = MapBuilder::new(vocab.words());
    for image in images {
        builder.add(image);
    }
    builder.build(map_name, &vocab.hash_hex(), places)
}

/// One map image as the map keeps it: each feature's word (exact
/// quantization), signature and keypoint; no features when it could not be
/// read.
pub fn map_image_words(vocab: &Vocabulary, name: &str, f: Option<&Features>) -> ImageWords {
    match f {
        Some(f) => {
            let c = code(vocab, f.descriptors.view());
            ImageWords::with_geometry(name, &c.words, &c.signatures, &f.keypoints)
        }
        None => ImageWords::from_words(name, &[]),
    }
}

/// Extract descriptors from `images` and index them.
pub fn build_map(
    vocab: &Vocabulary,
    images: &[ImageRef],
    places: Option<&Places>,
    map_name: &str,
    strict: bool,
) -> anyhow::Result<MapIndex> {
    let features = extract_all(
        images,
        &vocab.meta().extract,
        DecodeLimits::default(),
        strict,
        "extracting map",
    )?;
    let names: Vec<String> = images.iter().map(|i| i.name.clone()).collect();
    if let Some(places) = places {
        let missing = names
            .iter()
            .enumerate()
            .filter(|(j, n)| places.lookup(n, *j).is_none())
            .count();
        if missing > 0 {
            tracing::warn!("{missing} map images have no row in the places file");
        }
    }
    Ok(index_descriptors(
        vocab, &names, &features, places, map_name,
    ))
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
        let grid = self.grid_for(&options.rule, None);
        let answer = self.localize_tiled(bytes, options, grid, self.verify.enabled)?;
        self.learn(&options.rule, None, &answer);
        Ok(answer)
    }

    /// The tile grid a query is extracted in: the one `asked` for, else the
    /// configured grid when the rule may stop early, else the whole image (a
    /// search that reads every feature gains nothing from tiles and would pay
    /// their overlap). With a learned coarse pass ([`CoarseChoice`]) the
    /// configured grid starts with it or not as the choice says; pass the
    /// answer to [`Localizer::learn`].
    pub fn grid_for(&self, rule: &search::RuleSpec, asked: Option<TileGrid>) -> TileGrid {
        match asked {
            Some(grid) => grid,
            None if rule.info().stops_early => match &self.coarse_choice {
                Some(choice) => TileGrid {
                    coarse: choice.choose(),
                    ..self.tiles
                },
                None => self.tiles,
            },
            None => TileGrid::WHOLE,
        }
    }

    /// Tell the learned coarse pass what `answer` cost, when its grid was
    /// the one [`Localizer::grid_for`] chose for `rule` without being
    /// `asked` for one.
    pub fn learn(&self, rule: &search::RuleSpec, asked: Option<TileGrid>, answer: &Localization) {
        if let Some(choice) = &self.coarse_choice
            && asked.is_none()
            && rule.info().stops_early
        {
            let t = &answer.timings_ms;
            choice.record(
                answer.tiles.grid.coarse,
                t.total - t.decode,
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
        let mut tiles = Tiles::new(
            &image,
            &self.extract,
            grid,
            Some((options.tile_order, options.seed)),
        )?;
        let mut extract = decoded.elapsed();
        let quantizer = self.vocab.quantizer(self.quantizer);
        let snapshot = self.map.snapshot();
        let map: &dyn MapRead = &*snapshot;
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
        loop {
            if search.stopped() && full.as_ref().is_none_or(Search::stopped) {
                break;
            }
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
            search.feed_tile(tile.len(), step, quantize, Some(&mut check));
        }
        let extraction = Extraction {
            tiles_extracted: tiles_used,
            tiles_total: tiles.total(),
            grid,
            tile_order: options.tile_order,
            expected_features: search.tally().total_or_estimate(),
            complete: tiles_used == tiles.total(),
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
        Ok(answer.keeping_distinct(options.min_distinct))
    }

    /// Read a file and answer it as a query, extracted in the grid `tiles`
    /// asks for, else as [`Localizer::grid_for`] chooses.
    pub fn localize_file(
        &self,
        path: &Path,
        options: &SearchOptions,
        tiles: Option<TileGrid>,
    ) -> anyhow::Result<Localization> {
        let bytes =
            std::fs::read(path).with_context(|| format!("{}: cannot read", path.display()))?;
        let grid = self.grid_for(&options.rule, tiles);
        let answer = self
            .localize_tiled(&bytes, options, grid, self.verify.enabled)
            .with_context(|| format!("{}", path.display()))?;
        self.learn(&options.rule, tiles, &answer);
        Ok(answer)
    }
}
