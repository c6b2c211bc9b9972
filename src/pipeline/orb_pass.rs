//! The ORB pass in the pipeline: a map's ORB side made from its images
//! ([`build_orb_side`]), and a loaded side ([`OrbPass`]) that looks at a
//! decoded query before SIFT does ([`OrbPass::look`]).

use super::Localizer;
use super::progress_bar;
use crate::dataset::ImageRef;
use crate::features::fit::OpenCvFit;
use crate::features::orb::OrbDetector;
use crate::features::{self, DecodeLimits, ExtractConfig, FeatureError, Frame};
use crate::index::{MapIndex, MapMeta};
use crate::orb_pass::{
    Checked, FIT, OrbImage, OrbIndex, OrbPassParams, OrbSide, OrbSideMeta, Setting, answer,
};
use crate::vocabulary::binary::{BinaryDescriptor, BinaryVocabulary};
use anyhow::{Context, bail};
use rayon::prelude::*;
use std::path::Path;
use std::time::{Duration, Instant};

/// Rounds of k-majority when the side's words are trained.
const ITERATIONS: usize = 8;

/// The ORB side of `localizer`'s map file, built from its images
/// (`images`, in map order: each one's name must be the map image's) in the
/// extraction frame of its vocabulary: ORB over every image (an unreadable
/// one has none; `params`' keypoints and grid), then `params.words` binary
/// words drawn with the vocabulary's seed.
pub fn build_orb_side(
    localizer: &Localizer,
    images: &[ImageRef],
    params: &OrbPassParams,
) -> anyhow::Result<OrbSide> {
    let snapshot = localizer.map.snapshot();
    let seed = localizer.vocab.meta().seed;
    orb_side_of(snapshot.base(), &localizer.extract, seed, images, params)
}

/// [`build_orb_side`] for the map `base`, whose images were extracted with
/// `config`, and the vocabulary seed `seed`.
pub fn orb_side_of(
    base: &MapIndex,
    config: &ExtractConfig,
    seed: u64,
    images: &[ImageRef],
    params: &OrbPassParams,
) -> anyhow::Result<OrbSide> {
    let map = base.meta();
    let (words, keypoints) = (params.words, params.keypoints);
    let grid = params.grid().map_err(anyhow::Error::msg)?;
    if images.len() != map.images {
        bail!(
            "{} images given for a map of {} images: give the list the map was built from",
            images.len(),
            map.images
        );
    }
    if let Some((j, image)) = images
        .iter()
        .enumerate()
        .find(|(j, image)| image.name != base.image(*j as u32).name)
    {
        bail!(
            "image {j} is {} but the map's image {j} is {}: give the list the map was built from",
            image.name,
            base.image(j as u32).name
        );
    }
    // a grid ORB cannot spread over is named before any image is read
    OrbDetector::new(keypoints, grid)?;
    let bar = progress_bar(images.len() as u64, "ORB over the map");
    let orb: Vec<OrbImage> = images
        .par_iter()
        .map(|r| {
            let read = || -> anyhow::Result<OrbImage> {
                let bytes = std::fs::read(&r.path)
                    .with_context(|| format!("{}: cannot read", r.path.display()))?;
                let image = features::decode(&bytes, DecodeLimits::default(), config.max_side)?;
                Ok(OrbDetector::new(keypoints, grid)?.detect(&Frame::new(&image, config)?)?)
            };
            let orb = read().unwrap_or_else(|e| {
                tracing::warn!("{e:#}: no ORB features for it");
                OrbImage::default()
            });
            bar.inc(1);
            orb
        })
        .collect();
    bar.finish_and_clear();
    let all: Vec<BinaryDescriptor> = orb
        .iter()
        .flat_map(|m| m.descriptors.iter().copied())
        .collect();
    let vocabulary = BinaryVocabulary::train(&all, words, ITERATIONS, seed);
    Ok(OrbSide {
        meta: OrbSideMeta::for_map(map, vocabulary.len(), seed, keypoints, grid),
        vocabulary,
        images: orb,
    })
}

/// What the pass saw of one query.
#[derive(Debug, Clone)]
pub struct Look {
    /// The checked candidates, in vote order.
    pub checked: Vec<Checked>,
    /// The pass's answer (the pick first, then the other checked images in
    /// vote order), when it answers.
    pub answer: Option<Vec<u32>>,
    /// ORB, its words, the votes and the checks.
    pub took: Duration,
    /// Inliers a checked image needs to count as verified (the setting's
    /// floor).
    pub floor: usize,
}

/// A map's ORB side, loaded, with the setting it answers by.
pub struct OrbPass {
    pub meta: OrbSideMeta,
    vocabulary: BinaryVocabulary,
    index: OrbIndex,
    pub setting: Setting,
    top: usize,
    fit: OpenCvFit,
}

impl OrbPass {
    /// Open the side at `path` for the map `map` (refused if it was built
    /// for another map, or the map has changed since).
    pub fn open(path: &Path, map: &MapMeta, params: &OrbPassParams) -> anyhow::Result<Self> {
        let side = OrbSide::open(path)?;
        if !side.meta.matches(map) {
            bail!(
                "{}: this ORB side was built for map `{}` ({} images, {} features, generation {}), \
                 not for the map loaded (`{}`, {} images, {} features, generation {}); rebuild it \
                 with `bowloc map orb-pass --vocab VOCAB --map MAP --images IMAGES`",
                path.display(),
                side.meta.map_name,
                side.meta.map_images,
                side.meta.map_features,
                side.meta.map_generation,
                map.name,
                map.images,
                map.features,
                map.generation
            );
        }
        Ok(Self::new(side, params))
    }

    /// A side in memory, with `params`' setting.
    pub fn new(side: OrbSide, params: &OrbPassParams) -> Self {
        Self {
            index: OrbIndex::build(side.images, &side.vocabulary),
            meta: side.meta,
            vocabulary: side.vocabulary,
            setting: params.setting(),
            top: params.top,
            fit: OpenCvFit::new(FIT),
        }
    }

    /// Whether the side answers for the map at `generation`: it has no
    /// changes since the side was built (a live map's adds and removes are
    /// not in it until it is rebuilt for the compacted map).
    pub fn is_current(&self, generation: u64) -> bool {
        generation == self.meta.map_generation
    }

    /// Look at a query in its extraction frame (the one SIFT goes on with
    /// if the pass does not answer): ORB, its words voted over the map, the
    /// best-voted checked, and the setting's answer if it answers.
    pub fn look(&self, frame: &Frame) -> Result<Look, FeatureError> {
        let started = Instant::now();
        let query = OrbDetector::new(self.meta.keypoints, self.meta.grid)?.detect(frame)?;
        let words = self.vocabulary.words_of(&query.descriptors);
        let checked = self.index.check(&query, &words, self.top, &self.fit);
        Ok(Look {
            answer: answer(&checked, self.setting),
            checked,
            took: started.elapsed(),
            floor: self.setting.floor,
        })
    }
}
