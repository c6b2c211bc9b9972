//! `bowloc calibrate`: choose each stopping rule's parameter for a map from
//! pseudo-queries made of the map's own images (no ground truth), print the
//! choices, write the most economical one as a configuration file for
//! `bowloc serve --config`, and, given a dataset, check how they transfer to
//! its real queries. A rule that cannot be calibrated is reported with the
//! reason, and the command fails when no rule is; `--out` refuses a choice
//! that misses its target on the real queries unless `--force`.

use super::args::MapFiles;
use bowloc::calibrate::{
    Calibrated, Transfer, auto_warmup, calibrate_rule, choose, full_top1, measure, median_features,
    pseudo_queries, server_config,
};
use bowloc::dataset::Dataset;
use bowloc::eval::sweep::{Ranking, Setting, format_parameter, search_one, seed};
use bowloc::features::DecodeLimits;
use bowloc::index::MapIndex;
use bowloc::pipeline::{extract_all, progress_bar, words_per_image};
use bowloc::search::{CodedFeatures, RuleSpec};
use bowloc::vocabulary::Vocabulary;
use clap::Args;
use std::fmt::Write as _;
use std::path::PathBuf;

#[derive(Args)]
pub struct CalibrateArgs {
    #[command(flatten)]
    files: MapFiles,
    /// Largest share of pseudo-queries whose early top-1 may differ from full search.
    #[arg(long, default_value_t = 0.01)]
    max_disagreement: f64,
    /// Rules to calibrate.
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "place-z,peak-mean,relative,stable-peak,confident"
    )]
    rules: Vec<String>,
    /// Warm-up: features voted before the rule is consulted (default: adapted to
    /// the pseudo-queries, at most 100 and at most a quarter of the median
    /// pseudo-query's features).
    #[arg(long)]
    min_features: Option<usize>,
    /// Random feature orders per pseudo-query.
    #[arg(long, default_value_t = 5)]
    runs: u32,
    /// Write the rule using the fewest features, with the vocabulary and map, as
    /// a configuration file for `bowloc serve --config` here.
    #[arg(long)]
    out: Option<PathBuf>,
    /// A dataset in the shared layout whose real queries check the transfer.
    #[arg(long)]
    dataset: Option<PathBuf>,
    /// Write `--out` even when no rule meets the target on the real queries.
    #[arg(long, requires = "out")]
    force: bool,
}

pub fn run(a: CalibrateArgs) -> anyhow::Result<()> {
    anyhow::ensure!(
        (0.0..1.0).contains(&a.max_disagreement),
        "--max-disagreement must lie in [0, 1)"
    );
    anyhow::ensure!(a.runs >= 1, "--runs must be at least 1");
    a.files.check_defaults()?;
    let vocab = Vocabulary::open(&a.files.vocab, true)?;
    let map = MapIndex::open_for(&a.files.map, &vocab, true)?;
    let pseudo = pseudo_queries(&map, 1);
    anyhow::ensure!(
        !pseudo.queries.is_empty() && pseudo.map.images() > 0,
        "{}: a map of {} images is too small to split into a calibration map and pseudo-queries",
        a.files.map.display(),
        map.images()
    );
    let counts: Vec<usize> = pseudo.queries.iter().map(|q| q.words.len()).collect();
    let warmup = a.min_features.unwrap_or_else(|| auto_warmup(&counts));
    let full = full_top1(&pseudo.map, &pseudo.queries);
    let transfer_data = a
        .dataset
        .as_ref()
        .map(|d| real_queries(d, &vocab))
        .transpose()?;
    let bar = progress_bar(a.rules.len() as u64, "calibrating rules");
    let mut results = Vec::new();
    for rule in &a.rules {
        let found = calibrate_rule(&pseudo, &full, rule, warmup, a.max_disagreement, a.runs)?;
        let transfer = match (&found, &transfer_data) {
            (Ok(c), Some((data, queries))) => {
                Some(transfer(&map, data, queries, c, a.max_disagreement, a.runs))
            }
            _ => None,
        };
        if let Err(why) = &found {
            tracing::warn!(rule, "not calibrated: {why}");
        }
        results.push((rule.clone(), found, transfer));
        bar.inc(1);
    }
    bar.finish_and_clear();

    let mut table = format!(
        "Calibrated on {} pseudo-queries ({} features each, median) against {} map images \
         (max disagreement {}, warm-up {}, {} runs)",
        pseudo.queries.len(),
        median_features(&counts),
        pseudo.map.images(),
        a.max_disagreement,
        warmup,
        a.runs
    );
    if let Some((_, queries)) = &transfer_data {
        let real: Vec<usize> = queries.iter().map(|q| q.words.len()).collect();
        write!(
            table,
            "; transfer checked on {} real queries ({} features each, median)",
            queries.len(),
            median_features(&real)
        )?;
    }
    table.push_str(
        "\n\n| rule | parameter | pseudo-query disagreement | pseudo-query features used |",
    );
    let mut header = "\n| --- | --- | --- | --- |".to_owned();
    if transfer_data.is_some() {
        table.push_str(
            " real-query disagreement | real-query features used | recall@1 full → early | transfer |",
        );
        header.push_str(" --- | --- | --- | --- |");
    }
    table.push_str(&header);
    let columns = if transfer_data.is_some() { 8 } else { 4 };
    for (rule, found, transfer) in &results {
        match found {
            Ok(c) => {
                write!(
                    table,
                    "\n| {} | {} | {:.3} | {:.1}% |",
                    c.rule,
                    format_parameter(c.parameter),
                    c.disagreement,
                    100.0 * c.fraction
                )?;
                if let Some(t) = transfer {
                    write!(
                        table,
                        " {:.3} | {:.1}% | {:.3} → {:.3} | {} |",
                        t.disagreement,
                        100.0 * t.fraction,
                        t.recall_full,
                        t.recall_early,
                        if t.passed {
                            "passed"
                        } else {
                            "missed the target"
                        }
                    )?;
                }
            }
            Err(why) => {
                write!(table, "\n| {rule} | not calibrated: {why} |")?;
                table.push_str(&" – |".repeat(columns - 2));
            }
        }
    }
    outln!("{table}")?;

    let chosen: Vec<(Calibrated, Option<Transfer>)> = results
        .into_iter()
        .filter_map(|(_, found, t)| found.ok().map(|c| (c, t)))
        .collect();
    if chosen.is_empty() {
        anyhow::bail!(
            "no rule could be calibrated to disagree on at most {} of the pseudo-queries at \
             warm-up {warmup} (the reasons are in the table above){}",
            a.max_disagreement,
            if a.out.is_some() {
                "; nothing written"
            } else {
                ""
            }
        );
    }
    if let Some(out) = &a.out {
        let best = choose(&chosen, a.max_disagreement, a.force)?;
        let absolute = |p: &PathBuf| p.canonicalize().unwrap_or_else(|_| p.clone());
        let config = server_config(
            best,
            &absolute(&a.files.vocab),
            &absolute(&a.files.map),
            a.max_disagreement,
        );
        bowloc::store::write_atomic(out, |w| w.write_all(config.as_bytes()))?;
        tracing::info!(path = %out.display(), rule = %best.rule, parameter = best.parameter, "calibrated defaults written");
    }
    Ok(())
}

/// How the calibrated rule `c` does on the dataset's real queries.
fn transfer(
    map: &MapIndex,
    data: &Dataset,
    queries: &[CodedFeatures],
    c: &Calibrated,
    max_disagreement: f64,
    runs: u32,
) -> Transfer {
    let full_real = full_top1(map, queries);
    let setting = setting_of(c);
    let (disagreement, fraction) = measure(map, queries, &full_real, &setting, runs);
    let recall = |s: &Setting| recall_at_1(map, queries, data, s, runs);
    let none = Setting::new(RuleSpec::new("none", None).expect("built in"), 0);
    Transfer {
        disagreement,
        fraction,
        recall_full: recall(&none),
        recall_early: recall(&setting),
        passed: disagreement <= max_disagreement,
    }
}

fn setting_of(c: &Calibrated) -> Setting {
    Setting::new(
        RuleSpec::new(&c.rule, Some(c.parameter)).expect("calibrated within range"),
        c.min_features,
    )
}

/// The dataset's queries, quantized.
fn real_queries(
    dir: &std::path::Path,
    vocab: &Vocabulary,
) -> anyhow::Result<(Dataset, Vec<CodedFeatures>)> {
    let data = Dataset::open(dir)?;
    let desc = extract_all(
        &data.queries,
        &vocab.meta().extract,
        DecodeLimits::default(),
        false,
        "queries",
    )?;
    let words = words_per_image(vocab, &desc);
    Ok((data, words))
}

/// Share of (query with a match, run) whose top-1 is a ground-truth match.
fn recall_at_1(
    map: &MapIndex,
    queries: &[CodedFeatures],
    data: &Dataset,
    s: &Setting,
    runs: u32,
) -> f64 {
    let (mut hits, mut n) = (0usize, 0usize);
    for run in 0..runs {
        for (q, words) in queries.iter().enumerate() {
            if data.truth[q].is_empty() {
                continue;
            }
            n += 1;
            let o = search_one(map, words.known(), s, seed(run, q), Ranking::top(1));
            hits += o
                .candidates
                .first()
                .is_some_and(|c| data.truth[q].contains(&c.id)) as usize;
        }
    }
    hits as f64 / n.max(1) as f64
}
