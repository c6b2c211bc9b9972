//! Vocabularies and maps from features: k-means training, exact
//! quantization and signing, and the map's inverted index with each
//! feature's geometry.

use super::extract::{extract_all, stack};
use super::progress_bar;
use crate::dataset::ImageRef;
use crate::features::{DecodeLimits, ExtractConfig, Features};
use crate::index::{ImageWords, MapBuilder, MapIndex, Places};
use crate::quantize::Quantizer;
use crate::search::CodedFeatures;
use crate::vocabulary::kmeans::{KmeansConfig, kmeans};
use crate::vocabulary::{Vocabulary, VocabularyMeta};
use ndarray::{ArrayView2, Axis};
use rayon::prelude::*;

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
