//! The evaluation's disk cache (by default `data/eval-cache/<dataset>/`): the
//! descriptors of an image list, the vocabulary trained on the map's
//! descriptors and the map built from them, so a second run (other rules,
//! other runs) skips extraction, k-means and indexing.
//!
//! Descriptor files are store files (magic `BOWLOCDE`) with four sections:
//! `meta` (JSON: the extraction settings, each image's name and file size,
//! whether it was readable, how long it took to decode and extract, and
//! which other grids were timed with it),
//! `descriptors` (f32, all rows stacked, 128 wide), `keypoints` (f32, the
//! keypoint of each row: x, y, size, angle, response) and `offsets` (u64,
//! image i owns rows `offsets[i]..offsets[i + 1]`). A file made with other settings or
//! other images is rebuilt, not reused. The queries cut in tiles and whole
//! are extracted together, image by image, so the eval's "× whole-image"
//! times compare extractions taken under the same load. Vocabulary and map file names carry
//! the checksum of the descriptors they come from, so they cannot go stale.

use super::tiles::{Query, Tile};
use crate::dataset::ImageRef;
use crate::features::{DecodeLimits, ExtractConfig, Features, TileGrid, TilePlan};
use crate::geometry::Keypoint;
use crate::index::MapIndex;
use crate::pipeline::{Extracted, extract_all_together, index_descriptors, train_vocabulary};
use crate::search::rank::top_n;
use crate::search::{HammingWeights, Needs, SearchOptions, Voter};
use crate::store::{Store, StoreWriter};
use crate::vocabulary::Vocabulary;
use crate::vocabulary::kmeans::KmeansConfig;
use anyhow::Context;
use ndarray::ArrayView2;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

const MAGIC: [u8; 8] = *b"BOWLOCDE";
/// 2: keypoints beside the descriptors; 3: tiles and their times; 4: the
/// times are thread CPU time; 5: each tile's corner count; 6: its cell;
/// 7: the tiles after a coarse pass keep every scale.
const VERSION: u32 = 7;
/// Descriptor width (SIFT).
const DIM: usize = 128;
/// Values per keypoint row: x, y, size, angle, response.
const KEYPOINT_WIDTH: usize = 5;

/// An input image as the cache knows it: a changed name or size invalidates.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ImageStamp {
    pub name: String,
    pub bytes: u64,
}

/// What a descriptor file holds and how it was made.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct DescriptorMeta {
    pub extract: ExtractConfig,
    pub images: Vec<ImageStamp>,
    /// False for images that could not be read (they have no rows).
    pub readable: Vec<bool>,
    /// Per image: reading and decoding the file, in milliseconds.
    pub decode_ms: Vec<f64>,
    /// Per image: feature extraction on the decoded image, in milliseconds.
    pub extract_ms: Vec<f64>,
    /// How the images were cut into tiles (the rows of an image are in grid
    /// order, tile 0's first).
    #[serde(default = "whole_image")]
    pub grid: TileGrid,
    /// Per image, per tile in grid order: features, area share, time.
    #[serde(default)]
    pub tiles: Vec<Vec<Tile>>,
    /// The other grids the images were extracted with back to back, image
    /// by image, each time the cheapest of [`ROUNDS_TOGETHER`] rounds
    /// ([`descriptors_together`]): times in files extracted together compare
    /// image by image; times in files extracted apart were taken minutes
    /// apart, when a shared machine may have run at another speed.
    #[serde(default)]
    pub timed_with: Vec<TileGrid>,
}

/// Rounds of extraction per image when several grids are timed together.
pub const ROUNDS_TOGETHER: usize = 3;

fn whole_image() -> TileGrid {
    TileGrid::WHOLE
}

/// The descriptors of an image list, memory-mapped from the cache.
pub struct DescriptorSet {
    store: Store,
    meta: DescriptorMeta,
}

impl DescriptorSet {
    pub fn meta(&self) -> &DescriptorMeta {
        &self.meta
    }

    /// Number of images.
    pub fn len(&self) -> usize {
        self.meta.images.len()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    fn offsets(&self) -> &[u64] {
        self.store.u64s("offsets").expect("validated on open")
    }

    /// Every image's rows, stacked.
    pub fn all(&self) -> ArrayView2<'_, f32> {
        let data = self.store.f32s("descriptors").expect("validated on open");
        ArrayView2::from_shape((data.len() / DIM, DIM), data).expect("validated on open")
    }

    /// The rows of image `i` (`None`: the image could not be read).
    pub fn image(&self, i: usize) -> Option<ArrayView2<'_, f32>> {
        if !self.meta.readable[i] {
            return None;
        }
        let o = self.offsets();
        Some(
            self.all()
                .slice_move(ndarray::s![o[i] as usize..o[i + 1] as usize, ..]),
        )
    }

    /// The keypoints of image `i`, one per descriptor row (empty when the
    /// image could not be read).
    pub fn keypoints(&self, i: usize) -> Vec<Keypoint> {
        if !self.meta.readable[i] {
            return Vec::new();
        }
        let o = self.offsets();
        let all = self.store.f32s("keypoints").expect("validated on open");
        all[o[i] as usize * KEYPOINT_WIDTH..o[i + 1] as usize * KEYPOINT_WIDTH]
            .chunks_exact(KEYPOINT_WIDTH)
            .map(|k| Keypoint {
                x: k[0],
                y: k[1],
                size: k[2],
                angle: k[3],
                response: k[4],
            })
            .collect()
    }

    /// Per-image copies, in the form the map builder takes.
    pub fn owned_per_image(&self) -> Vec<Option<Features>> {
        (0..self.len())
            .map(|i| {
                self.image(i).map(|d| Features {
                    keypoints: self.keypoints(i),
                    descriptors: d.to_owned(),
                })
            })
            .collect()
    }

    /// Decoding image `i`, in milliseconds.
    pub fn decode_ms(&self, i: usize) -> f64 {
        self.meta.decode_ms[i]
    }

    /// Decode plus extraction time of image `i`, in milliseconds.
    pub fn extract_ms(&self, i: usize) -> f64 {
        self.decode_ms(i) + self.meta.extract_ms[i]
    }

    /// Image `i` as the sweep replays it, given its words (rows in order):
    /// its keypoints, its tiles, and decoding plus what extraction spends
    /// outside the tiles (downscaling) as the fixed cost.
    pub fn query(&self, i: usize, words: Vec<u32>, signatures: Vec<u64>) -> Query {
        let tiles = self.meta.tiles.get(i).cloned().unwrap_or_default();
        let in_tiles: f64 = tiles.iter().map(|t| t.ms as f64).sum();
        Query {
            words,
            signatures,
            keypoints: self.keypoints(i),
            fixed_ms: (self.extract_ms(i) - in_tiles).max(0.0) as f32,
            tiles,
            coarse_first: self.meta.grid.coarse,
            geometry: None,
        }
    }

    /// Checksum of the descriptors: names the files derived from them.
    pub fn hash(&self) -> u64 {
        self.store
            .section("descriptors")
            .expect("validated on open")
            .checksum
    }
}

fn stamps(images: &[ImageRef]) -> anyhow::Result<Vec<ImageStamp>> {
    images
        .iter()
        .map(|i| {
            let bytes = std::fs::metadata(&i.path)
                .with_context(|| format!("{}: cannot read", i.path.display()))?
                .len();
            Ok(ImageStamp {
                name: i.name.clone(),
                bytes,
            })
        })
        .collect()
}

/// Open a descriptor file and check its structure.
fn open(path: &Path) -> anyhow::Result<DescriptorSet> {
    let store = Store::open(path, MAGIC, "descriptor cache", VERSION, true)?;
    let meta: DescriptorMeta = store.json("meta")?;
    let n = meta.images.len();
    let offsets = store.u64s("offsets")?;
    let rows = store.f32s("descriptors")?.len() / DIM;
    let consistent = offsets.len() == n + 1
        && offsets.first() == Some(&0)
        && offsets.last() == Some(&(rows as u64))
        && offsets.windows(2).all(|w| w[0] <= w[1])
        && store.f32s("descriptors")?.len() % DIM == 0
        && store.f32s("keypoints")?.len() == rows * KEYPOINT_WIDTH
        && [
            meta.readable.len(),
            meta.decode_ms.len(),
            meta.extract_ms.len(),
            meta.tiles.len(),
        ] == [n; 4]
        && (0..n).all(|i| {
            meta.tiles[i].iter().map(|t| t.features as u64).sum::<u64>()
                == offsets[i + 1] - offsets[i]
        });
    if !consistent {
        return Err(store
            .invalid("offsets, rows and image list disagree")
            .into());
    }
    Ok(DescriptorSet { store, meta })
}

/// A dataset's map descriptors (whole images) and query descriptors (tile by
/// tile with `grid`), from the cache folder `cache` or extracted into it.
pub fn dataset_descriptors(
    cache: &Path,
    dataset: &crate::dataset::Dataset,
    config: &ExtractConfig,
    grid: TileGrid,
) -> anyhow::Result<(DescriptorSet, DescriptorSet)> {
    let map = map_descriptors(cache, dataset, config)?;
    Ok((map, queries_alone(cache, dataset, config, grid)?))
}

/// A dataset's queries tile by tile with `grid`, timed on their own.
fn queries_alone(
    cache: &Path,
    dataset: &crate::dataset::Dataset,
    config: &ExtractConfig,
    grid: TileGrid,
) -> anyhow::Result<DescriptorSet> {
    descriptors(
        &query_path(cache, grid),
        &dataset.queries,
        config,
        grid,
        "extracting queries",
    )
}

/// A dataset's map descriptors (whole images), from the cache folder `cache`
/// or extracted into it.
pub fn map_descriptors(
    cache: &Path,
    dataset: &crate::dataset::Dataset,
    config: &ExtractConfig,
) -> anyhow::Result<DescriptorSet> {
    descriptors(
        &cache.join("map.bowdesc"),
        &dataset.map,
        config,
        TileGrid::WHOLE,
        "extracting map",
    )
}

/// The cache file of a dataset's queries cut by `grid`.
fn query_path(cache: &Path, grid: TileGrid) -> PathBuf {
    cache.join(format!("queries-{grid}.bowdesc"))
}

/// A dataset's queries cut by each grid of `plan` ([`TilePlan::grids`]) and,
/// when the plan cuts them, extracted whole too, all timed back to back
/// image by image ([`descriptors_together`]) so that their ratios are the
/// plans' own costs. The whole queries go to a file of their own per plan,
/// so that plans evaluated in turn do not extract each other's again; a
/// learned plan's grids do too, so that the two it compares were timed
/// together.
pub fn query_descriptors_with_whole(
    cache: &Path,
    dataset: &crate::dataset::Dataset,
    config: &ExtractConfig,
    plan: TilePlan,
) -> anyhow::Result<(Vec<DescriptorSet>, Option<DescriptorSet>)> {
    if plan == TilePlan::from(TileGrid::WHOLE) {
        let queries = queries_alone(cache, dataset, config, TileGrid::WHOLE)?;
        return Ok((vec![queries], None));
    }
    let mut files: Vec<(PathBuf, TileGrid)> = plan
        .grids()
        .into_iter()
        .map(|grid| {
            let path = if plan.learn_coarse {
                cache.join(format!("queries-{grid}-in-{plan}.bowdesc"))
            } else {
                query_path(cache, grid)
            };
            (path, grid)
        })
        .collect();
    files.push((
        cache.join(format!("queries-{}-with-{plan}.bowdesc", TileGrid::WHOLE)),
        TileGrid::WHOLE,
    ));
    let mut sets = descriptors_together(
        &files,
        &dataset.queries,
        config,
        "extracting queries tiled and whole",
    )?;
    let whole = sets.pop();
    Ok((sets, whole))
}

/// The descriptors of `images` extracted with `config`, tile by tile with
/// `grid`: from `path` when it holds exactly those, else extracted (in
/// parallel, timed) and written there.
pub fn descriptors(
    path: &Path,
    images: &[ImageRef],
    config: &ExtractConfig,
    grid: TileGrid,
    what: &str,
) -> anyhow::Result<DescriptorSet> {
    let mut sets = descriptors_together(&[(path.to_owned(), grid)], images, config, what)?;
    Ok(sets.pop().expect("one set"))
}

/// The descriptors of `images` extracted with `config` once per grid of
/// `files`, each into its path. When every file holds exactly those
/// (images, settings, grid) and, for more than one grid, was extracted
/// together with the others, the files are served; otherwise all of them
/// are extracted again together: each image decoded once and cut by every
/// grid back to back, the cheapest of [`ROUNDS_TOGETHER`] rounds kept, so
/// the files' times compare image by image.
pub fn descriptors_together(
    files: &[(PathBuf, TileGrid)],
    images: &[ImageRef],
    config: &ExtractConfig,
    what: &str,
) -> anyhow::Result<Vec<DescriptorSet>> {
    let stamps = stamps(images)?;
    let others = |grid: TileGrid| -> Vec<TileGrid> {
        files.iter().map(|f| f.1).filter(|&g| g != grid).collect()
    };
    let cached: Vec<Option<DescriptorSet>> = files
        .iter()
        .map(|(path, grid)| {
            if !path.exists() {
                return None;
            }
            match open(path) {
                Ok(set)
                    if set.meta.extract == *config
                        && set.meta.images == stamps
                        && set.meta.grid == *grid
                        && others(*grid)
                            .iter()
                            .all(|g| set.meta.timed_with.contains(g)) =>
                {
                    Some(set)
                }
                Ok(_) => {
                    tracing::info!(path = %path.display(), "cache made from other images, settings or timings: re-extracting");
                    None
                }
                Err(e) => {
                    tracing::warn!("unusable cache, re-extracting: {e:#}");
                    None
                }
            }
        })
        .collect();
    if cached.iter().all(Option::is_some) {
        let sets: Vec<DescriptorSet> = cached.into_iter().flatten().collect();
        for s in &sets {
            tracing::info!(images = s.len(), grid = %s.meta.grid, "descriptors from cache");
        }
        return Ok(sets);
    }
    let grids: Vec<TileGrid> = files.iter().map(|f| f.1).collect();
    let rounds = if grids.len() > 1 { ROUNDS_TOGETHER } else { 1 };
    let extracted = extract_all_together(
        images,
        config,
        &grids,
        rounds,
        DecodeLimits::default(),
        false,
        what,
    )?;
    files
        .iter()
        .enumerate()
        .map(|(g, (path, grid))| {
            let mut meta = DescriptorMeta {
                extract: config.clone(),
                images: stamps.clone(),
                readable: Vec::with_capacity(images.len()),
                decode_ms: Vec::with_capacity(images.len()),
                extract_ms: Vec::with_capacity(images.len()),
                grid: *grid,
                tiles: Vec::with_capacity(images.len()),
                timed_with: others(*grid),
            };
            let each: Vec<Option<&Extracted>> = extracted
                .iter()
                .map(|e| e.as_ref().map(|e| &e[g]))
                .collect();
            write_set(path, &mut meta, &each)
        })
        .collect()
}

/// Write one grid's extractions of an image list (`None`: unreadable) as a
/// descriptor file at `path`, `meta` filled in image by image, and open it.
fn write_set(
    path: &Path,
    meta: &mut DescriptorMeta,
    extracted: &[Option<&Extracted>],
) -> anyhow::Result<DescriptorSet> {
    let mut data: Vec<f32> = Vec::new();
    let mut keypoints: Vec<f32> = Vec::new();
    let mut offsets = vec![0u64];
    let ms = |d: std::time::Duration| d.as_secs_f64() * 1e3;
    for e in extracted {
        if let Some(e) = e {
            anyhow::ensure!(
                e.features.descriptors.ncols() == DIM,
                "descriptors are not {DIM} wide"
            );
            data.extend(e.features.descriptors.iter());
            keypoints.extend(
                e.features
                    .keypoints
                    .iter()
                    .flat_map(|k| [k.x, k.y, k.size, k.angle, k.response]),
            );
        }
        offsets.push((data.len() / DIM) as u64);
        meta.readable.push(e.is_some());
        meta.decode_ms.push(e.map_or(0.0, |e| ms(e.decode)));
        meta.extract_ms.push(e.map_or(0.0, |e| ms(e.extract)));
        meta.tiles.push(e.map_or_else(Vec::new, |e| {
            e.tiles
                .iter()
                .map(|t| Tile {
                    features: t.features as u32,
                    area: t.area as f32,
                    ms: ms(t.extract) as f32,
                    corners: t.corners,
                    cell: t.cell,
                })
                .collect()
        }));
    }
    StoreWriter::new(MAGIC, VERSION)
        .json("meta", &*meta)
        .f32s("descriptors", &data)
        .f32s("keypoints", &keypoints)
        .u64s("offsets", &offsets)
        .write_atomic(path)?;
    tracing::info!(path = %path.display(), rows = offsets.last(), "descriptors cached");
    open(path)
}

/// A dataset with its descriptors, one vocabulary and the map built with it,
/// all from (or into) the cache folder `data/eval-cache/<dataset>`: where a
/// study of one vocabulary (the examples) starts.
pub struct Prepared {
    pub dataset: crate::dataset::Dataset,
    pub map_descriptors: DescriptorSet,
    /// The queries, tile by tile with the grid asked for.
    pub queries: DescriptorSet,
    /// The queries extracted whole, timed with `queries` image by image
    /// (`None` when the grid asked for is the whole image).
    pub whole_queries: Option<DescriptorSet>,
    pub vocab: Vocabulary,
    pub map: MapIndex,
}

impl Prepared {
    /// The full search's recall@1 and recall@5 (in %) over the queries with
    /// a match, each query given by its descriptors (`None`: no features,
    /// a miss): every feature quantized and voted with Hamming weights, as
    /// the service votes.
    pub fn full_search_recall(&self, images: &[Option<ArrayView2<'_, f32>>]) -> (f64, f64) {
        let view = self.map.view();
        let (mut r1, mut r5, mut n) = (0, 0, 0);
        for (q, truth) in self.dataset.truth.iter().enumerate() {
            if truth.is_empty() {
                continue;
            }
            n += 1;
            let Some(d) = images.get(q).copied().flatten() else {
                continue;
            };
            let coded = crate::pipeline::code(&self.vocab, d);
            let mut voter = Voter::with_needs(&view, Needs::default())
                .with_hamming(&self.map, HammingWeights::DEFAULT);
            for (&w, &s) in coded.words.iter().zip(&coded.signatures) {
                voter.vote(w, s);
            }
            let top = top_n(&voter, 5, 0.0, None, SearchOptions::PLACE_WINDOW);
            r1 += usize::from(top.first().is_some_and(|r| truth.contains(&r.id)));
            r5 += usize::from(top.iter().any(|r| truth.contains(&r.id)));
        }
        let pct = |k: usize| 100.0 * k as f64 / n.max(1) as f64;
        (pct(r1), pct(r5))
    }
}

/// [`Prepared`] for the dataset at `root`, a vocabulary of `words` words
/// from k-means seed `seed` and the queries cut by `grid`, with the default
/// extraction.
pub fn prepare(root: &Path, words: usize, seed: u64, grid: TileGrid) -> anyhow::Result<Prepared> {
    let dataset = crate::dataset::Dataset::open(root)?;
    let dir = Path::new("data/eval-cache").join(&dataset.name);
    std::fs::create_dir_all(&dir)?;
    let config = ExtractConfig::default();
    let map_descriptors = map_descriptors(&dir, &dataset, &config)?;
    let (mut queries, whole_queries) =
        query_descriptors_with_whole(&dir, &dataset, &config, grid.into())?;
    let queries = queries.pop().expect("one grid");
    let kmeans = KmeansConfig {
        k: words,
        seed,
        ..KmeansConfig::default()
    };
    let vocab = vocabulary(&dir, &map_descriptors, &kmeans)?;
    let map = map_index(&dir, &vocab, &map_descriptors, &dataset.name)?;
    Ok(Prepared {
        dataset,
        map_descriptors,
        queries,
        whole_queries,
        vocab,
        map,
    })
}

/// [`prepare`] from a command line's `[DATASET] [WORDS] [SEED]` (after the
/// program name; defaults `../shared/datasets/gardens-point`, 5000, 1).
pub fn prepare_from_args(args: &[String], grid: TileGrid) -> anyhow::Result<Prepared> {
    let root = args
        .get(1)
        .map_or("../shared/datasets/gardens-point", |s| s);
    let words: usize = args.get(2).map_or(Ok(5000), |s| s.parse())?;
    let seed: u64 = args.get(3).map_or(Ok(1), |s| s.parse())?;
    prepare(Path::new(root), words, seed, grid)
}

/// A vocabulary of `config.k` words trained on `map`'s descriptors, cached in
/// `dir` under a name holding K, the seed and the descriptors' checksum.
pub fn vocabulary(
    dir: &Path,
    map: &DescriptorSet,
    config: &KmeansConfig,
) -> anyhow::Result<Vocabulary> {
    let path = dir.join(format!(
        "vocab-k{}-seed{}-{:016x}-he.bowvoc",
        config.k,
        config.seed,
        map.hash()
    ));
    if path.exists() {
        match Vocabulary::open(&path, true) {
            Ok(v) if v.words() == config.k && v.meta().extract == map.meta().extract => {
                tracing::info!(path = %path.display(), "vocabulary from cache");
                return Ok(v);
            }
            Ok(_) => {
                tracing::warn!(path = %path.display(), "cached vocabulary does not fit: retraining")
            }
            Err(e) => tracing::warn!("unusable cached vocabulary, retraining: {e:#}"),
        }
    }
    tracing::info!(
        descriptors = map.all().nrows(),
        words = config.k,
        "training vocabulary"
    );
    let vocab = train_vocabulary(map.all(), &map.meta().extract, config)?;
    vocab.save(&path)?;
    Ok(vocab)
}

/// The map of `map`'s images over `vocab`, cached in `dir` under a name
/// holding the vocabulary's hash and the descriptors' checksum.
pub fn map_index(
    dir: &Path,
    vocab: &Vocabulary,
    map: &DescriptorSet,
    name: &str,
) -> anyhow::Result<MapIndex> {
    let path = map_path(dir, vocab, map);
    if path.exists() {
        match MapIndex::open_for(&path, vocab, true) {
            Ok(m) if m.images() == map.len() => {
                tracing::info!(path = %path.display(), "map from cache");
                return Ok(m);
            }
            Ok(_) => tracing::warn!(path = %path.display(), "cached map does not fit: rebuilding"),
            Err(e) => tracing::warn!("unusable cached map, rebuilding: {e:#}"),
        }
    }
    let names: Vec<String> = map.meta().images.iter().map(|i| i.name.clone()).collect();
    let index = index_descriptors(vocab, &names, &map.owned_per_image(), None, name);
    index.save(&path)?;
    Ok(index)
}

/// Where the map of `vocab` over the descriptors `map` is cached.
fn map_path(dir: &Path, vocab: &Vocabulary, map: &DescriptorSet) -> PathBuf {
    dir.join(format!(
        "map-{}-{:016x}.bowmap",
        vocab.hash_hex(),
        map.hash()
    ))
}

/// The ORB side of the cached map `index` (of `vocab` over `map`), for the
/// ORB pass with `params`: kept beside the map, built from the map images
/// (`images`, extracted with `extract`) when missing or built otherwise.
pub fn orb_side(
    dir: &Path,
    vocab: &Vocabulary,
    map: &DescriptorSet,
    index: &MapIndex,
    images: &[ImageRef],
    extract: &ExtractConfig,
    params: &crate::orb_pass::OrbPassParams,
) -> anyhow::Result<crate::orb_pass::OrbSide> {
    use crate::orb_pass::{OrbSide, OrbSideMeta, file::path_beside};
    let path = path_beside(&map_path(dir, vocab, map));
    let grid = params.grid().map_err(anyhow::Error::msg)?;
    let seed = vocab.meta().seed;
    let wanted = OrbSideMeta::for_map(index.meta(), params.words, seed, params.keypoints, grid);
    if path.exists() {
        match OrbSide::open(&path) {
            Ok(side) if side.meta == wanted => {
                tracing::info!(path = %path.display(), "ORB side from cache");
                return Ok(side);
            }
            Ok(_) => {
                tracing::warn!(path = %path.display(), "cached ORB side does not fit: rebuilding")
            }
            Err(e) => tracing::warn!("unusable cached ORB side, rebuilding: {e:#}"),
        }
    }
    let side = crate::pipeline::orb_side_of(index, extract, seed, images, params)?;
    side.save(&path)?;
    Ok(side)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A hand-made cache file opens with its rows in place; one whose offsets
    /// disagree with its rows is refused.
    #[test]
    fn descriptor_files_open_and_are_checked() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("d.bowdesc");
        let meta = DescriptorMeta {
            extract: ExtractConfig::default(),
            images: vec![
                ImageStamp {
                    name: "a".into(),
                    bytes: 1,
                },
                ImageStamp {
                    name: "b".into(),
                    bytes: 2,
                },
            ],
            readable: vec![true, true],
            decode_ms: vec![1.0, 2.0],
            extract_ms: vec![3.0, 4.0],
            grid: TileGrid::WHOLE,
            timed_with: Vec::new(),
            tiles: vec![
                vec![Tile {
                    features: 1,
                    area: 1.0,
                    ms: 0.5,
                    corners: 0.0,
                    cell: [0, 0],
                }],
                vec![Tile {
                    features: 2,
                    area: 1.0,
                    ms: 0.5,
                    corners: 0.0,
                    cell: [0, 0],
                }],
            ],
        };
        let data: Vec<f32> = (0..3 * DIM).map(|v| v as f32).collect();
        StoreWriter::new(MAGIC, VERSION)
            .json("meta", &meta)
            .f32s("descriptors", &data)
            .f32s("keypoints", &[0.5; 3 * KEYPOINT_WIDTH])
            .u64s("offsets", &[0, 1, 3])
            .write_atomic(&path)
            .unwrap();
        let set = open(&path).unwrap();
        assert_eq!(set.len(), 2);
        assert_eq!(set.all().nrows(), 3);
        assert_eq!(set.image(0).unwrap().nrows(), 1);
        assert_eq!(set.image(1).unwrap()[[1, 0]], (2 * DIM) as f32);
        assert_eq!(set.extract_ms(1), 6.0);
        // image 1 as a query: one tile of 0.5 ms, the rest fixed cost
        let q = set.query(1, vec![7, 8], vec![]);
        assert_eq!(
            (q.tiles.len(), q.fixed_ms, q.fixed_ms + q.tiles[0].ms),
            (1, 5.5, 6.0)
        );
        assert_eq!(set.owned_per_image().len(), 2);
        assert_eq!(set.keypoints(1).len(), 2);
        assert_eq!(set.keypoints(0)[0].size, 0.5);

        // Offsets that do not cover the rows are refused.
        StoreWriter::new(MAGIC, VERSION)
            .json("meta", &meta)
            .f32s("descriptors", &data)
            .f32s("keypoints", &[0.5; 3 * KEYPOINT_WIDTH])
            .u64s("offsets", &[0, 1, 2])
            .write_atomic(&path)
            .unwrap();
        assert!(open(&path).is_err());
    }

    #[test]
    fn stale_caches_are_rebuilt() {
        let dir = tempfile::tempdir().unwrap();
        // An unreadable "image": extracting it fails, so an error proves the
        // cache was not used and a success proves it was.
        std::fs::write(dir.path().join("x.jpg"), b"not an image").unwrap();
        let images = vec![ImageRef {
            name: "x.jpg".into(),
            path: dir.path().join("x.jpg"),
        }];
        let path = dir.path().join("d.bowdesc");
        let meta = DescriptorMeta {
            extract: ExtractConfig::default(),
            images: stamps(&images).unwrap(),
            readable: vec![true],
            decode_ms: vec![0.0],
            extract_ms: vec![0.0],
            grid: TileGrid::WHOLE,
            timed_with: Vec::new(),
            tiles: vec![vec![Tile {
                features: 1,
                area: 1.0,
                ms: 0.5,
                corners: 0.0,
                cell: [0, 0],
            }]],
        };
        let data = vec![0.5f32; DIM];
        let write = |meta: &DescriptorMeta| {
            StoreWriter::new(MAGIC, VERSION)
                .json("meta", meta)
                .f32s("descriptors", &data)
                .f32s("keypoints", &[0.5; KEYPOINT_WIDTH])
                .u64s("offsets", &[0, 1])
                .write_atomic(&path)
                .unwrap();
        };
        write(&meta);
        // Another tile grid: re-extracted.
        let grid: TileGrid = "2x2".parse().unwrap();
        assert!(descriptors(&path, &images, &ExtractConfig::default(), grid, "t").is_err());
        write(&meta);
        // Same images and settings: served from the file.
        let set = descriptors(
            &path,
            &images,
            &ExtractConfig::default(),
            TileGrid::WHOLE,
            "t",
        )
        .unwrap();
        assert_eq!(set.all().nrows(), 1);
        // Other settings: re-extracted, which fails on the fake image.
        let other = ExtractConfig {
            max_side: 320,
            ..ExtractConfig::default()
        };
        assert!(descriptors(&path, &images, &other, TileGrid::WHOLE, "t").is_err());
        // Asked for together with the whole image: a file not extracted
        // with it is re-extracted, one that was is served, alone or paired.
        let tiled = dir.path().join("t.bowdesc");
        let files = [(tiled.clone(), grid), (path.clone(), TileGrid::WHOLE)];
        let config = ExtractConfig::default();
        let write_grid = |at: &Path, grid: TileGrid, with: Vec<TileGrid>| {
            let meta = DescriptorMeta {
                grid,
                timed_with: with,
                ..meta.clone()
            };
            StoreWriter::new(MAGIC, VERSION)
                .json("meta", &meta)
                .f32s("descriptors", &data)
                .f32s("keypoints", &[0.5; KEYPOINT_WIDTH])
                .u64s("offsets", &[0, 1])
                .write_atomic(at)
                .unwrap();
        };
        write_grid(&tiled, grid, vec![]);
        write_grid(&path, TileGrid::WHOLE, vec![]);
        assert!(descriptors_together(&files, &images, &config, "t").is_err());
        write_grid(&tiled, grid, vec![TileGrid::WHOLE]);
        write_grid(&path, TileGrid::WHOLE, vec![grid]);
        let sets = descriptors_together(&files, &images, &config, "t").unwrap();
        assert_eq!(
            sets.iter().map(|s| s.meta().grid).collect::<Vec<_>>(),
            [grid, TileGrid::WHOLE]
        );
        assert!(descriptors(&tiled, &images, &config, grid, "t").is_ok());
        // Same settings but the image changed size: re-extracted too.
        std::fs::write(dir.path().join("x.jpg"), b"still not an image").unwrap();
        assert!(
            descriptors(
                &path,
                &images,
                &ExtractConfig::default(),
                TileGrid::WHOLE,
                "t"
            )
            .is_err()
        );
    }
}
