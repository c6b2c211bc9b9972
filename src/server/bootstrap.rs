//! Start-up of the map: build the default vocabulary and map from the
//! bootstrap dataset when they are missing (so `make run` works from a fresh
//! clone), reporting each step for `/readyz`, then open them memory-mapped
//! with the configured limits. Bootstrap only ever writes the default files
//! it owns (the built-in `files.vocabulary` and `files.map`); any other path
//! must name an existing file.

use super::config::{Config, FilesConfig};
use crate::dataset::image_list;
use crate::features::DecodeLimits;
use crate::pipeline::{Localizer, build_map, extract_all, stack};
use crate::quantize::QuantizerKind;
use crate::vocabulary::kmeans::{KmeansConfig, kmeans};
use crate::vocabulary::{Vocabulary, VocabularyMeta};
use anyhow::{Context, bail};
use indicatif::ProgressBar;
use std::path::Path;
use std::time::Instant;

/// What loading the map is doing now: a step and, for the steps that count
/// (k-means seeding and iterations), how far along it is. Shared between
/// the loader and `/readyz`.
#[derive(Clone)]
pub struct Progress {
    bar: ProgressBar,
}

impl Default for Progress {
    fn default() -> Self {
        let bar = ProgressBar::hidden();
        bar.set_message("starting");
        Self { bar }
    }
}

impl Progress {
    /// Begin a step that does not count.
    pub(super) fn begin(&self, step: impl Into<String>) {
        self.bar.set_length(0);
        self.bar.set_position(0);
        self.bar.set_message(step.into());
    }

    /// The step now, e.g. `loading` or `k-means: Lloyd iterations 12/40`.
    pub fn step(&self) -> String {
        let message = self.bar.message();
        match self.bar.length() {
            Some(n) if n > 0 => format!("{message} {}/{n}", self.bar.position()),
            _ => message,
        }
    }
}

/// Build what is missing (the default files only), then open the vocabulary
/// and map, reporting each step to `progress`.
pub fn load(config: &Config, progress: &Progress) -> anyhow::Result<Localizer> {
    let files = &config.files;
    for (path, what) in [(&files.vocabulary, "vocabulary"), (&files.map, "map")] {
        if path.is_dir() {
            bail!("{}: is a directory, not a {what} file", path.display());
        }
    }
    let defaults = FilesConfig::default();
    let own_files = files.vocabulary == defaults.vocabulary && files.map == defaults.map;
    if own_files && config.bootstrap.enabled {
        retire_old_default_map(&files.map);
    }
    let (vocab_missing, map_missing) = (!files.vocabulary.exists(), !files.map.exists());
    if vocab_missing || map_missing {
        if !own_files {
            bail!(
                "{} (bootstrap builds only the default files {} and {})",
                missing(config),
                defaults.vocabulary.display(),
                defaults.map.display()
            );
        }
        if !config.bootstrap.enabled {
            bail!(
                "{} and bootstrap is disabled (bootstrap.enabled)",
                missing(config)
            );
        }
        build_missing(config, vocab_missing, progress)?;
    }
    progress.begin("loading the vocabulary and map");
    tracing::info!(
        vocabulary = %files.vocabulary.display(),
        map = %files.map.display(),
        verify = files.verify,
        "loading"
    );
    let mut localizer = open(config)?;
    localizer.limits = DecodeLimits {
        max_pixels: config.limits.pixels,
    };
    localizer.quantizer = config.quantizer().map_err(anyhow::Error::msg)?;
    localizer.set_verify(config.verify.clone());
    if let QuantizerKind::Tree { .. } = localizer.quantizer {
        // build the tree now, not in the first request
        progress.begin("building the quantization tree");
        let groups = localizer.vocab.tree_quantizer().groups();
        tracing::info!(groups, "quantization tree built");
    }
    let plan = config.tiles().map_err(anyhow::Error::msg)?;
    localizer.tiles = plan.grid;
    localizer.coarse_choice = plan
        .learn_coarse
        .then(crate::features::CoarseChoice::default);
    let cap = config.limits.max_features;
    let sift = &mut localizer.extract.sift;
    if cap > 0 && (sift.max_features == 0 || sift.max_features > cap) {
        sift.max_features = cap;
    }
    // bootstrap writes the default map's side where it looks for it
    let bootstraps =
        own_files && config.bootstrap.enabled && config.orb_pass.file.as_os_str().is_empty();
    localizer.orb_pass = load_orb_pass(config, &localizer, bootstraps, progress)?;
    Ok(localizer)
}

/// The map's ORB side for the ORB pass: opened when its file exists
/// (requests may then ask for the pass with `orb_pass=true`). When
/// `orb_pass.enabled` (the default), bootstrap builds the default map's
/// side if it is missing (`bootstraps`; also when it was built for another
/// map); any other map without one is served without the pass, with a
/// warning that says how to build it. A side built for another map (or before the map's
/// changes were folded into it) is left out with a warning: the service
/// answers without the pass until it is rebuilt.
fn load_orb_pass(
    config: &Config,
    localizer: &Localizer,
    bootstraps: bool,
    progress: &Progress,
) -> anyhow::Result<Option<crate::pipeline::OrbPass>> {
    let (path, params) = (config.orb_pass_file(), &config.orb_pass);
    let snapshot = localizer.map.snapshot();
    let map = snapshot.base().meta();
    // the side is read once: built for this map, it is the pass
    let opened = crate::pipeline::OrbPass::open(&path, map, params);
    let pass = match opened {
        Ok(pass) => pass,
        Err(_) if params.enabled && bootstraps => {
            let list = config.bootstrap.dataset.join("map.txt");
            progress.begin("the map's ORB side");
            tracing::info!(path = %path.display(), "bootstrap: building the map's ORB side");
            let side = crate::pipeline::build_orb_side(localizer, &image_list(&list)?, params)?;
            side.save(&path)?;
            crate::pipeline::OrbPass::new(side, params)
        }
        Err(_) if !path.exists() && params.enabled => {
            tracing::warn!(
                path = %path.display(),
                "the map has no ORB side, so the ORB pass is off: build it with \
                 `bowloc map orb-pass --vocab {} --map {} --images IMAGES` (the map's image \
                 list), or set orb_pass.enabled = false",
                config.files.vocabulary.display(),
                config.files.map.display()
            );
            return Ok(None);
        }
        Err(_) if !path.exists() => return Ok(None),
        Err(e) => {
            tracing::warn!("{e:#}: the ORB pass is off");
            return Ok(None);
        }
    };
    let built = (pass.meta.keypoints, pass.meta.grid);
    if built != (params.keypoints, params.grid().ok().flatten()) {
        let grid = crate::orb_pass::params::grid_name(built.1);
        tracing::warn!(
            path = %path.display(),
            "this ORB side was built with {} keypoints per image and grid `{grid}`, not the {} \
             and `{}` of [orb_pass]: its queries are detected as its images were; rebuild it \
             with `bowloc map orb-pass` to use the configured ones",
            built.0,
            params.keypoints,
            params.grid
        );
    }
    tracing::info!(
        path = %path.display(),
        images = pass.meta.map_images,
        keypoints = pass.meta.keypoints,
        enabled = params.enabled,
        "ORB pass loaded"
    );
    Ok(Some(pass))
}

/// The vocabulary and map, the map with its change log (replayed) when
/// writes are configured or a log exists; otherwise read only, and no log
/// is created.
fn open(config: &Config) -> anyhow::Result<Localizer> {
    let files = &config.files;
    let log = crate::live::log::path_for(&files.map);
    if config.auth.write_token.is_none() && !log.exists() {
        return Localizer::open(&files.vocabulary, &files.map, files.verify);
    }
    let (localizer, opened) = Localizer::open_live(
        &files.vocabulary,
        &files.map,
        files.verify,
        config.changes.max_images,
    )?;
    let status = localizer.map.status();
    tracing::info!(
        log = %log.display(),
        replayed = opened.replayed,
        generation = status.generation,
        images = status.images,
        "change log opened"
    );
    if opened.reset {
        tracing::warn!(
            log = %log.display(),
            "the change log held only changes the map file already has (a compaction was interrupted); emptied"
        );
    }
    Ok(localizer)
}

/// `A is missing` or `A and B are missing`.
fn missing(config: &Config) -> String {
    let names: Vec<String> = [&config.files.vocabulary, &config.files.map]
        .into_iter()
        .filter(|p| !p.exists())
        .map(|p| p.display().to_string())
        .collect();
    let verb = if names.len() > 1 { "are" } else { "is" };
    format!("{} {verb} missing", names.join(" and "))
}

/// Build the map (and the vocabulary first, when `vocab_missing`) from the
/// bootstrap dataset's map images.
/// A default map of an older format (from an earlier version of bowloc) is
/// moved aside as `<name>.old`, so bootstrap builds it again: the default
/// files are bootstrap's own. A user's map is never touched.
fn retire_old_default_map(map: &std::path::Path) {
    if let Err(crate::store::StoreError::WrongVersion {
        found, expected, ..
    }) = crate::index::MapIndex::open(map, false)
    {
        let old = map.with_extension("bowmap.old");
        tracing::warn!(
            map = %map.display(),
            found,
            expected,
            "the default map has an older format: moved to {} and rebuilt",
            old.display()
        );
        if let Err(e) = std::fs::rename(map, &old) {
            tracing::warn!("cannot move {} aside: {e}", map.display());
        }
    }
}

fn build_missing(config: &Config, vocab_missing: bool, progress: &Progress) -> anyhow::Result<()> {
    let b = &config.bootstrap;
    let list = b.dataset.join("map.txt");
    if !list.is_file() {
        bail!(
            "{}, and the bootstrap dataset has no {} (set files.vocabulary and \
             files.map to existing files, or bootstrap.dataset to a dataset folder)",
            missing(config),
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
            "bootstrap: building the vocabulary (extracting features, then k-means; this can take minutes)"
        );
        progress.begin(format!(
            "vocabulary: extracting the features of {} images",
            images.len()
        ));
        let extract = Default::default();
        let all = extract_all(
            &images,
            &extract,
            DecodeLimits::default(),
            false,
            "extracting",
        )?;
        let parts: Vec<_> = all.iter().flatten().collect();
        let data = stack(&parts);
        let kmeans_config = KmeansConfig {
            k: b.words,
            seed: b.seed,
            ..Default::default()
        };
        progress.begin("k-means");
        let (centroids, report) = kmeans(data.view(), &kmeans_config, &progress.bar)?;
        let meta = VocabularyMeta {
            extract,
            seed: b.seed,
            trained_on: report.trained_on,
            iterations: report.iterations,
            ..Default::default()
        };
        let vocab = Vocabulary::trained(centroids, meta, data.view());
        create_parent(&config.files.vocabulary)?;
        vocab.save(&config.files.vocabulary)?;
        tracing::info!(
            path = %config.files.vocabulary.display(),
            words = vocab.words(),
            iterations = report.iterations,
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
    progress.begin(format!("map: indexing {} images", images.len()));
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

    fn load_err(c: &Config) -> String {
        load(c, &Progress::default()).err().unwrap().to_string()
    }

    #[test]
    fn missing_files_without_bootstrap_name_the_files() {
        let dir = tempfile::tempdir().unwrap();
        let mut c = Config::default();
        c.files.vocabulary = dir.path().join("v.bowvoc");
        c.files.map = dir.path().join("m.bowmap");
        c.bootstrap.enabled = false;
        let e = load_err(&c);
        assert!(e.contains("v.bowvoc") && e.contains("m.bowmap"), "{e}");
    }

    #[test]
    fn bootstrap_never_builds_a_path_it_does_not_own() {
        let dir = tempfile::tempdir().unwrap();
        let mut c = Config::default();
        // a mistyped map path, bootstrap enabled with a real dataset
        c.files.map = dir.path().join("typo.bowmap");
        let e = load_err(&c);
        assert!(e.contains("typo.bowmap") && e.contains("missing"), "{e}");
        assert!(e.contains("only the default files"), "{e}");
        assert!(!c.files.map.exists());
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
    }

    #[test]
    fn a_directory_is_named_as_one() {
        let dir = tempfile::tempdir().unwrap();
        let mut c = Config::default();
        c.files.vocabulary = dir.path().to_path_buf();
        let e = load_err(&c);
        assert!(e.ends_with("is a directory, not a vocabulary file"), "{e}");
        c.files.vocabulary = dir.path().join("v.bowvoc");
        c.files.map = dir.path().to_path_buf();
        let e = load_err(&c);
        assert!(e.ends_with("is a directory, not a map file"), "{e}");
    }

    #[test]
    fn progress_names_the_step_and_counts() {
        let p = Progress::default();
        assert_eq!(p.step(), "starting");
        p.begin("k-means");
        p.bar.set_message("Lloyd iterations");
        p.bar.set_length(40);
        p.bar.set_position(12);
        assert_eq!(p.step(), "Lloyd iterations 12/40");
        p.begin("map: indexing 200 images");
        assert_eq!(p.step(), "map: indexing 200 images");
    }
}
