//! Start-up of the map: build the configured vocabulary and map from the
//! bootstrap dataset when they are missing (so `make run` works from a fresh
//! clone), then open them memory-mapped with the configured limits.

use super::config::Config;
use crate::dataset::image_list;
use crate::features::DecodeLimits;
use crate::pipeline::{Localizer, build_map, build_vocabulary};
use crate::quantize::QuantizerKind;
use crate::vocabulary::Vocabulary;
use crate::vocabulary::kmeans::KmeansConfig;
use anyhow::{Context, bail};
use std::path::Path;
use std::time::Instant;

/// Build what is missing, then open the vocabulary and map.
pub fn load(config: &Config) -> anyhow::Result<Localizer> {
    let files = &config.files;
    let (vocab_missing, map_missing) = (!files.vocabulary.exists(), !files.map.exists());
    if vocab_missing || map_missing {
        if !config.bootstrap.enabled {
            bail!(
                "{} is missing and bootstrap is disabled (bootstrap.enabled)",
                missing_names(config)
            );
        }
        build_missing(config, vocab_missing)?;
    }
    tracing::info!(
        vocabulary = %files.vocabulary.display(),
        map = %files.map.display(),
        verify = files.verify,
        "loading"
    );
    let mut localizer = Localizer::open(&files.vocabulary, &files.map, files.verify)?;
    localizer.limits = DecodeLimits {
        max_pixels: config.limits.pixels,
    };
    localizer.quantizer = config.quantizer().map_err(anyhow::Error::msg)?;
    localizer.set_verify(config.verify.clone());
    if let QuantizerKind::Tree { .. } = localizer.quantizer {
        // build the tree now, not in the first request
        let groups = localizer.vocab.tree_quantizer().groups();
        tracing::info!(groups, "quantization tree built");
    }
    localizer.tiles = config.tiles().map_err(anyhow::Error::msg)?;
    let cap = config.limits.max_features;
    let sift = &mut localizer.extract.sift;
    if cap > 0 && (sift.max_features == 0 || sift.max_features > cap) {
        sift.max_features = cap;
    }
    Ok(localizer)
}

fn missing_names(config: &Config) -> String {
    [&config.files.vocabulary, &config.files.map]
        .into_iter()
        .filter(|p| !p.exists())
        .map(|p| p.display().to_string())
        .collect::<Vec<_>>()
        .join(" and ")
}

/// Build the map (and the vocabulary first, when `vocab_missing`) from the
/// bootstrap dataset's map images.
fn build_missing(config: &Config, vocab_missing: bool) -> anyhow::Result<()> {
    let b = &config.bootstrap;
    let list = b.dataset.join("map.txt");
    if !list.is_file() {
        bail!(
            "{} is missing, and the bootstrap dataset has no {} (set files.vocabulary and \
             files.map to existing files, or bootstrap.dataset to a dataset folder)",
            missing_names(config),
            list.display()
        );
    }
    let images = image_list(&list)?;
    let started = Instant::now();
    let vocab = if vocab_missing {
        tracing::info!(
            dataset = %b.dataset.display(),
            images = images.len(),
            words = b.words,
            seed = b.seed,
            "bootstrap: building the vocabulary (extracting features, then k-means; this can take a minute or more)"
        );
        let kmeans = KmeansConfig {
            k: b.words,
            seed: b.seed,
            ..Default::default()
        };
        let vocab = build_vocabulary(&images, &Default::default(), &kmeans, false)?;
        create_parent(&config.files.vocabulary)?;
        vocab.save(&config.files.vocabulary)?;
        tracing::info!(
            path = %config.files.vocabulary.display(),
            words = vocab.words(),
            seconds = started.elapsed().as_secs(),
            "bootstrap: vocabulary written"
        );
        vocab
    } else {
        Vocabulary::open(&config.files.vocabulary, config.files.verify)?
    };
    tracing::info!(
        dataset = %b.dataset.display(),
        images = images.len(),
        "bootstrap: building the map"
    );
    let name = b
        .dataset
        .canonicalize()
        .ok()
        .and_then(|p| p.file_name().map(|n| n.to_string_lossy().into_owned()))
        .unwrap_or_else(|| "default".into());
    let map = build_map(&vocab, &images, None, &name, false)?;
    create_parent(&config.files.map)?;
    map.save(&config.files.map)?;
    tracing::info!(
        path = %config.files.map.display(),
        images = map.images(),
        seconds = started.elapsed().as_secs(),
        "bootstrap: map written"
    );
    Ok(())
}

fn create_parent(path: &Path) -> anyhow::Result<()> {
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir)
            .with_context(|| format!("{}: cannot create", dir.display()))?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn missing_files_without_bootstrap_name_the_files() {
        let dir = tempfile::tempdir().unwrap();
        let mut c = Config::default();
        c.files.vocabulary = dir.path().join("v.bowvoc");
        c.files.map = dir.path().join("m.bowmap");
        c.bootstrap.enabled = false;
        let e = load(&c).err().unwrap().to_string();
        assert!(e.contains("v.bowvoc") && e.contains("m.bowmap"), "{e}");
        c.bootstrap.enabled = true;
        c.bootstrap.dataset = dir.path().join("nowhere");
        let e = load(&c).err().unwrap().to_string();
        assert!(e.contains("nowhere"), "{e}");
    }
}
