//! `bowloc calibrate`: choose each stopping rule's parameter for a map from
//! pseudo-queries made of the map's own images (no ground truth), print the
//! choices, write the most economical one as a configuration file for
//! `bowloc serve --config`, and, given a dataset, check how they transfer to
//! its real queries.

use bowloc::calibrate::{
    Calibrated, calibrate_rule, full_top1, measure, pseudo_queries, server_config,
};
use bowloc::dataset::Dataset;
use bowloc::eval::sweep::{Setting, search_one, seed};
use bowloc::features::DecodeLimits;
use bowloc::index::MapIndex;
use bowloc::pipeline::{extract_all, words_per_image};
use bowloc::search::RuleSpec;
use bowloc::vocabulary::Vocabulary;
use clap::Args;
use std::fmt::Write as _;
use std::path::PathBuf;

#[derive(Args)]
pub struct CalibrateArgs {
    /// Vocabulary file.
    #[arg(long)]
    vocab: PathBuf,
    /// Map file.
    #[arg(long)]
    map: PathBuf,
    /// Largest share of pseudo-queries whose early top-1 may differ from full search.
    #[arg(long, default_value_t = 0.01)]
    max_disagreement: f64,
    /// Rules to calibrate.
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "peak-mean,relative,stable-peak,confident"
    )]
    rules: Vec<String>,
    /// Warm-up: features voted before the rule is consulted.
    #[arg(long, default_value_t = 100)]
    min_features: usize,
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
}

pub fn run(a: CalibrateArgs) -> anyhow::Result<()> {
    anyhow::ensure!(
        (0.0..1.0).contains(&a.max_disagreement),
        "--max-disagreement must lie in [0, 1)"
    );
    let vocab = Vocabulary::open(&a.vocab, true)?;
    let map = MapIndex::open_for(&a.map, &vocab, true)?;
    let pseudo = pseudo_queries(&map, 1);
    let full = full_top1(&pseudo.map, &pseudo.queries);
    let mut chosen = Vec::new();
    for rule in &a.rules {
        match calibrate_rule(
            &pseudo,
            &full,
            rule,
            a.min_features,
            a.max_disagreement,
            a.runs,
        )? {
            Some(c) => chosen.push(c),
            None => tracing::warn!(rule, "no parameter meets the disagreement target"),
        }
    }
    let mut table = format!(
        "Calibrated on {} pseudo-queries against {} map images (max disagreement {}, warm-up {}, {} runs)\n\n\
         | rule | parameter | pseudo-query disagreement | pseudo-query features used |",
        pseudo.queries.len(),
        pseudo.map.images(),
        a.max_disagreement,
        a.min_features,
        a.runs
    );
    let mut header = "\n| --- | --- | --- | --- |".to_owned();
    let transfer = a
        .dataset
        .as_ref()
        .map(|d| real_queries(d, &vocab))
        .transpose()?;
    if transfer.is_some() {
        table.push_str(
            " real-query disagreement | real-query features used | recall@1 full → early |",
        );
        header.push_str(" --- | --- | --- |");
    }
    table.push_str(&header);
    for c in &chosen {
        write!(
            table,
            "\n| {} | {} | {:.3} | {:.1}% |",
            c.rule,
            c.parameter,
            c.disagreement,
            100.0 * c.fraction
        )?;
        if let Some((data, queries)) = &transfer {
            let full_real = full_top1(&map, queries);
            let setting = setting_of(c);
            let (dis, frac) = measure(&map, queries, &full_real, &setting, a.runs);
            let recall = |s: &Setting| recall_at_1(&map, queries, data, s, a.runs);
            let none = Setting {
                rule: RuleSpec::new("none", None).expect("built in"),
                min_features: 0,
                target: None,
                verify: false,
            };
            write!(
                table,
                " {dis:.3} | {:.1}% | {:.3} → {:.3} |",
                100.0 * frac,
                recall(&none),
                recall(&setting)
            )?;
        }
    }
    println!("{table}");
    if let Some(out) = &a.out {
        let best = chosen
            .iter()
            .min_by(|x, y| x.fraction.total_cmp(&y.fraction))
            .ok_or_else(|| anyhow::anyhow!("no rule met the target; nothing written"))?;
        let absolute = |p: &PathBuf| p.canonicalize().unwrap_or_else(|_| p.clone());
        let config = server_config(
            best,
            &absolute(&a.vocab),
            &absolute(&a.map),
            a.max_disagreement,
        );
        bowloc::store::write_atomic(out, |w| w.write_all(config.as_bytes()))?;
        tracing::info!(path = %out.display(), rule = %best.rule, parameter = best.parameter, "calibrated defaults written");
    }
    Ok(())
}

fn setting_of(c: &Calibrated) -> Setting {
    Setting {
        rule: RuleSpec::new(&c.rule, Some(c.parameter)).expect("calibrated within range"),
        min_features: c.min_features,
        target: None,
        verify: false,
    }
}

/// The dataset's queries, quantized.
fn real_queries(
    dir: &std::path::Path,
    vocab: &Vocabulary,
) -> anyhow::Result<(Dataset, Vec<Vec<u32>>)> {
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
    queries: &[Vec<u32>],
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
            let o = search_one(map, words, s, seed(run, q), 1);
            hits += o
                .candidates
                .first()
                .is_some_and(|c| data.truth[q].contains(&c.id)) as usize;
        }
    }
    hits as f64 / n.max(1) as f64
}
