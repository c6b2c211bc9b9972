//! Writing a report out: markdown tables in the layout of the paper's
//! Tables I–IV (one per rule), the warm-up comparison and the time per
//! stage, the features each rule needs at equal recall (on recall at 90 %
//! precision and on plain recall); a CSV with one row per setting, another
//! with the equal-recall tables; a JSON of every number and every query's
//! answers. A figure over several vocabulary seeds reads `mean ± std over
//! seeds`; the spread over feature orders is a row of its own.

use super::Report;
use super::equal_recall::EqualRecall;
use super::recommend::Criterion;
use super::summary::{DistinctCut, SettingSummary, Stat, TOP_N};
use super::sweep::{BASELINE, format_parameter};
use std::fmt::Write as _;
use std::path::Path;

/// A rate as a percentage with one decimal.
pub(super) fn pct(v: f64) -> String {
    format!("{:.1}", 100.0 * v)
}

/// A figure as a percentage: `mean ± std over seeds` with several seeds.
fn pct_seeds(s: &Stat) -> String {
    if s.per_seed.len() > 1 {
        format!("{} ± {}", pct(s.mean), pct(s.std))
    } else {
        pct(s.mean)
    }
}

/// A setting's name in column headers, marked † when degenerate.
fn marked(s: &SettingSummary, name: String) -> String {
    if s.setting.degenerate.is_some() {
        format!("{name} †")
    } else {
        name
    }
}

/// The footnote naming why each degenerate column is so.
fn degenerate_note(columns: &[&SettingSummary]) -> String {
    let notes: Vec<String> = columns
        .iter()
        .filter_map(|s| {
            s.setting
                .degenerate
                .as_ref()
                .map(|why| format!("`{}`: {why}", s.label))
        })
        .collect();
    if notes.is_empty() {
        String::new()
    } else {
        format!(
            "† degenerate grid point, left out of the equal-recall tables and the \
             recommendation — {}.\n\n",
            notes.join("; ")
        )
    }
}

/// Milliseconds with about three significant digits.
fn ms_value(v: f64) -> String {
    match v {
        v if v >= 100.0 => format!("{v:.0}"),
        v if v >= 10.0 => format!("{v:.1}"),
        v if v >= 1.0 => format!("{v:.2}"),
        _ => format!("{v:.3}"),
    }
}

/// Milliseconds: median / p95.
fn ms(q: super::timing::Quantiles) -> String {
    format!("{} / {}", ms_value(q.median), ms_value(q.p95))
}

/// A markdown table from a header row and body rows.
fn markdown_table(header: &[String], rows: &[Vec<String>]) -> String {
    let mut s = String::new();
    let line = |cells: &[String]| format!("| {} |\n", cells.join(" | "));
    s += &line(header);
    s += &line(&vec!["---".to_owned(); header.len()]);
    for r in rows {
        s += &line(r);
    }
    s
}

/// Settings of `rule` at warm-up `w`, by fraction of features used.
fn of_rule<'a>(report: &'a Report, rule: &str, w: usize) -> Vec<&'a SettingSummary> {
    let mut v: Vec<&SettingSummary> = report
        .settings
        .iter()
        .filter(|s| s.setting.rule.name == rule && s.setting.min_features == w)
        .collect();
    v.sort_by(|a, b| a.fraction.mean.total_cmp(&b.fraction.mean));
    v
}

/// The rows of a paper-style table for `columns` (full BoW first).
fn paper_rows(columns: &[&SettingSummary], parameter: &str) -> Vec<Vec<String>> {
    let row = |name: String, f: &dyn Fn(&SettingSummary) -> String| {
        std::iter::once(name)
            .chain(columns.iter().map(|s| f(s)))
            .collect::<Vec<_>>()
    };
    let mut rows: Vec<Vec<String>> = TOP_N
        .iter()
        .map(|&n| {
            row(format!("recall top-{n} @90%P"), &|s| {
                pct_seeds(s.recall90_at(n))
            })
        })
        .collect();
    rows.push(row("(std over feature orders, top-5)".into(), &|s| {
        pct(s.recall90_at(5).runs_std)
    }));
    rows.push(row("% features".into(), &|s| pct_seeds(&s.fraction)));
    rows.push(row(parameter.into(), &|s| {
        s.setting.parameter().map_or("–".into(), format_parameter)
    }));
    rows.push(row("recall@1".into(), &|s| pct_seeds(&s.recall_at_1)));
    rows.push(row("recall@1, per seed".into(), &|s| {
        per_seed(&s.recall_at_1, pct)
    }));
    rows.push(row("recall@5".into(), &|s| pct_seeds(&s.recall_at_5)));
    rows.push(row("recall@5, per seed".into(), &|s| {
        per_seed(&s.recall_at_5, pct)
    }));
    rows.push(row("recall top-1 @90%P by distinctness".into(), &|s| {
        pct_seeds(&s.recall90_top1_distinct)
    }));
    rows.push(row(
        "recall top-1 @90%P by distinctness, per seed".into(),
        &|s| per_seed(&s.recall90_top1_distinct, pct),
    ));
    rows.push(row("its distinctness cut, per seed".into(), &|s| {
        per_seed(&s.cut90_top1_distinct, |c| format!("{c:.3}"))
    }));
    if let Some(cut) = columns.first().and_then(|s| s.at_distinct_cut.as_ref()) {
        let precision: fn(&DistinctCut) -> &Stat = |c| &c.precision;
        let recall: fn(&DistinctCut) -> &Stat = |c| &c.recall;
        for (what, stat) in [("precision", precision), ("recall", recall)] {
            rows.push(row(
                format!("top-1 kept at distinctness ≥ {}: {what}, per seed", cut.cut),
                &|s| {
                    s.at_distinct_cut
                        .as_ref()
                        .map_or("–".into(), |c| per_seed(stat(c), pct))
                },
            ));
        }
    }
    rows
}

/// Each vocabulary seed's value as `show` writes it, "–" where a run had
/// none (NaN).
pub(super) fn per_seed(s: &Stat, show: impl Fn(f64) -> String) -> String {
    let values: Vec<String> = s
        .per_seed
        .iter()
        .map(|&v| if v.is_nan() { "–".into() } else { show(v) })
        .collect();
    values.join(" / ")
}

/// The whole markdown report.
pub fn markdown(report: &Report) -> String {
    let mut s = String::new();
    let d = &report.dataset;
    let c = &report.config;
    let main = c.warmups.first().copied().unwrap_or(0);
    let m = &report.machine;
    let seeds: Vec<String> = c.seeds.iter().map(u64::to_string).collect();
    let _ = writeln!(s, "## {}\n", d.name);
    let _ = writeln!(s, "Command: `{}`\n", report.command);
    let _ = writeln!(
        s,
        "Machine: {} ({} CPUs, {}); OpenCV {}, dispatching {}{}. Descriptor checksums: map \
         `{}`, queries `{}` (SIFT's output depends on the instruction set: another CPU may \
         give other figures).\n",
        m.cpu_model,
        m.cpus,
        m.instruction_set,
        m.opencv.version,
        m.opencv.dispatched,
        m.opencv_cpu_disable
            .as_ref()
            .map_or(String::new(), |v| format!(", OPENCV_CPU_DISABLE={v}")),
        m.map_descriptors,
        m.query_descriptors,
    );
    let _ = writeln!(
        s,
        "{} map images, {} queries ({} with a match in the map), K = {} words, {} vocabularies \
         (k-means seeds {}), {} runs (random feature orders), {} features per query on average \
         (median {}; warm-up `auto` = {}). Recall at 90 % precision is computed per run, then \
         averaged over runs; a figure reads `mean ± std` over the vocabulary seeds, and the \
         spread over feature orders is given apart; all rates in %. Times are measured, so \
         they differ from run to run: they are all in the section \"Time per query and \
         stage\" (and `results.csv`); every other figure is reproducible.\n",
        d.map_images,
        d.queries,
        d.with_match,
        report.vocabularies.first().map_or(0, |v| v.words),
        c.seeds.len(),
        seeds.join(", "),
        c.runs,
        d.mean_features.round(),
        d.median_features,
        c.auto_warmup,
    );
    let Some(base) = report
        .settings
        .iter()
        .find(|s| s.setting.rule.name == BASELINE)
    else {
        return s;
    };
    for rule in &c.rules {
        if rule == BASELINE {
            continue;
        }
        let columns = of_rule(report, rule, main);
        if columns.is_empty() {
            continue;
        }
        let parameter = columns[0]
            .setting
            .rule
            .parameter_name()
            .unwrap_or("parameter");
        let mut all = vec![base];
        all.extend(columns);
        let header: Vec<String> = ["".to_owned(), "full BoW".to_owned()]
            .into_iter()
            .chain(all[1..].iter().map(|x| {
                marked(
                    x,
                    x.setting.parameter().map_or(rule.clone(), |p| {
                        format!("{parameter} {}", format_parameter(p))
                    }),
                )
            }))
            .collect();
        let _ = writeln!(s, "### Rule `{rule}` (warm-up {main})\n");
        s += &markdown_table(&header, &paper_rows(&all, parameter));
        s += "\n";
        s += &degenerate_note(&all);
    }
    s += &explicit_section(report, base);
    s += &warmup_section(report);
    s += &timing_section(report, base);
    for e in [&report.equal_recall, &report.equal_recall_plain]
        .into_iter()
        .flatten()
    {
        s += &equal_recall_section(e);
    }
    if let Some(r) = &report.recommendation {
        let _ = writeln!(
            s,
            "### Recommended setting\n\nThe setting whose worst vocabulary seed uses the fewest \
             features while losing, on every seed, at most {} points of the full search's recall \
             top-5 @90%P (mean {}) and recall@1 (mean {}); degenerate grid points are left out: \
             **{}**, using {} % of the features (worst seed {} %) with recall top-5 @90%P {} and \
             recall@1 {} (means over seeds; largest loss on one seed {} and {} points).\n",
            pct(r.tolerance),
            pct(r.baseline_recall90_top5),
            pct(r.baseline_recall_at_1),
            r.label,
            pct(r.fraction),
            pct(r.worst_fraction),
            pct(r.recall90_top5),
            pct(r.recall_at_1),
            pct(r.worst_loss[0]),
            pct(r.worst_loss[1]),
        );
    }
    if let Some(why) = &report.no_recommendation {
        let _ = writeln!(s, "### Recommended setting\n\nNone: {why}.\n");
    }
    if let Some(h) = &report.histogram {
        let _ = writeln!(
            s,
            "Histogram of the fraction of features used per query ({} seeds × queries × runs) for \
             **{}**: mean {} %, median {} %, 95th percentile {} %.\n",
            h.values,
            h.label,
            pct(h.mean),
            pct(h.median),
            pct(h.p95),
        );
    }
    if let Some(v) = &report.verification {
        let _ = writeln!(s, "{}", super::verify::markdown(v));
    }
    if let Some(o) = &report.orb_pass {
        s += &super::orb_pass::markdown(o, &report.settings);
    }
    s.push_str(&super::plan_orders::markdown(&report.plan_orders));
    s
}

/// The settings asked for with `--set`, next to the full search.
/// The settings asked for, then, with verification, every setting that
/// verifies (those asked for re-ranked, and geometric rules).
fn asked_and_verified(report: &Report) -> impl Iterator<Item = &SettingSummary> {
    let asked = report.explicit.iter().map(|&i| &report.settings[i]);
    asked.chain(report.settings.iter().filter(|s| s.setting.verify))
}

/// Append the settings of `more` not in `list` yet.
fn add_once<'a>(
    list: &mut Vec<&'a SettingSummary>,
    more: impl IntoIterator<Item = &'a SettingSummary>,
) {
    for x in more {
        if !list.iter().any(|p| std::ptr::eq(*p, x)) {
            list.push(x);
        }
    }
}

/// The full search a setting is compared with: verified if it is.
fn full_search_like<'a>(report: &'a Report, s: &SettingSummary) -> Option<&'a SettingSummary> {
    report
        .settings
        .iter()
        .find(|f| f.setting.rule.name == BASELINE && f.setting.verify == s.setting.verify)
}

/// Points of `full`'s recall that `s` loses on each vocabulary seed
/// (negative where it gains), "–" where either has none.
pub(super) fn points_lost(full: &Stat, s: &Stat) -> String {
    let lost: Vec<String> = full
        .per_seed
        .iter()
        .zip(&s.per_seed)
        .map(|(f, v)| match f - v {
            d if d.is_nan() => "–".into(),
            // a tie to the shown digit reads 0.0, not -0.0
            d if d.abs() < 0.0005 => pct(0.0),
            d => pct(d),
        })
        .collect();
    lost.join(" / ")
}

fn explicit_section(report: &Report, base: &SettingSummary) -> String {
    if report.explicit.is_empty() {
        return String::new();
    }
    let mut columns = vec![base];
    add_once(&mut columns, asked_and_verified(report));
    let header: Vec<String> = std::iter::once(String::new())
        .chain(columns.iter().map(|c| marked(c, c.label.clone())))
        .collect();
    let mut rows = paper_rows(&columns, "parameter");
    // how far each setting falls under its full search, which the targets
    // are read against: per seed, in points
    let after = rows
        .iter()
        .position(|r| r[0] == "recall@5, per seed")
        .map_or(rows.len(), |i| i + 1);
    let recall_at_1: fn(&SettingSummary) -> &Stat = |s| &s.recall_at_1;
    let recall_at_5: fn(&SettingSummary) -> &Stat = |s| &s.recall_at_5;
    for (k, (what, stat)) in [("recall@1", recall_at_1), ("recall@5", recall_at_5)]
        .into_iter()
        .enumerate()
    {
        rows.insert(
            after + k,
            std::iter::once(format!("{what} lost to the full search, per seed"))
                .chain(columns.iter().map(|c| {
                    full_search_like(report, c)
                        .map_or("–".into(), |full| points_lost(stat(full), stat(c)))
                }))
                .collect(),
        );
    }
    rows.insert(
        rows.len() - 2,
        std::iter::once("warm-up".to_owned())
            .chain(columns.iter().map(|c| c.setting.min_features.to_string()))
            .collect(),
    );
    format!(
        "### Settings asked for\n\n{}\n{}",
        markdown_table(&header, &rows),
        degenerate_note(&columns)
    )
}

/// Rules swept at several warm-ups: one table per rule, columns = targets.
fn warmup_section(report: &Report) -> String {
    let c = &report.config;
    if c.warmups.len() < 2 {
        return String::new();
    }
    let mut s = String::from(
        "### Warm-up\n\nThe calibrated rules, re-calibrated at each warm-up (features voted \
         before the rule is consulted) for the same target fractions.\n\n",
    );
    for rule in &c.rules {
        let by_target = |w: usize, t: f64| {
            report.settings.iter().find(|x| {
                x.setting.rule.name == *rule
                    && x.setting.min_features == w
                    && x.setting.target == Some(t)
            })
        };
        if !c
            .targets
            .iter()
            .any(|&t| by_target(c.warmups[0], t).is_some())
        {
            continue;
        }
        let header: Vec<String> = std::iter::once(format!("`{rule}`, target % features"))
            .chain(c.targets.iter().map(|&t| pct(t)))
            .collect();
        let mut rows = Vec::new();
        for &w in &c.warmups {
            let cell = |t: f64, f: &dyn Fn(&SettingSummary) -> String| {
                by_target(w, t).map_or("–".to_owned(), f)
            };
            let row = |name: &str, f: &dyn Fn(&SettingSummary) -> String| {
                std::iter::once(format!("w={w}: {name}"))
                    .chain(c.targets.iter().map(|&t| cell(t, f)))
                    .collect::<Vec<_>>()
            };
            rows.push(row("parameter", &|x| {
                marked(
                    x,
                    x.setting.parameter().map_or("–".into(), format_parameter),
                )
            }));
            rows.push(row("% features", &|x| pct_seeds(&x.fraction)));
            rows.push(row("recall top-5 @90%P", &|x| pct_seeds(x.recall90_at(5))));
            rows.push(row("recall@1", &|x| pct_seeds(&x.recall_at_1)));
        }
        s += &markdown_table(&header, &rows);
        s += "\n";
        let points: Vec<&SettingSummary> = c
            .warmups
            .iter()
            .flat_map(|&w| c.targets.iter().filter_map(move |&t| by_target(w, t)))
            .collect();
        s += &degenerate_note(&points);
    }
    s
}

/// Time per stage for the full search (also on whole, untiled queries), the
/// recommended setting, the settings asked for (and verified), and, per rule, the setting
/// nearest half the features, with the share of tiles extracted and the
/// request time against the tiled full search's on the same query.
fn timing_section(report: &Report, base: &SettingSummary) -> String {
    let main = report.config.warmups.first().copied().unwrap_or(0);
    let mut picked: Vec<&SettingSummary> = vec![base];
    if let Some(w) = &report.whole_image {
        picked.push(w);
    }
    add_once(&mut picked, asked_and_verified(report));
    if let Some(r) = &report.recommendation {
        add_once(&mut picked, [&report.settings[r.index]]);
    }
    for rule in &report.config.rules {
        let nearest_half = of_rule(report, rule, main)
            .into_iter()
            .filter(|x| x.setting.rule.name != BASELINE)
            .min_by(|a, b| {
                (a.fraction.mean - 0.5)
                    .abs()
                    .total_cmp(&(b.fraction.mean - 0.5).abs())
            });
        add_once(&mut picked, nearest_half);
    }
    let header: Vec<String> = [
        "setting",
        "% features",
        "% tiles",
        "extract",
        "quantize",
        "vote",
        "verify",
        "total",
        "× full search, mean / median",
    ]
    .map(String::from)
    .to_vec();
    let whole = picked.iter().any(|x| x.time_share_whole.is_some());
    let coarse = picked.iter().any(|x| x.coarse_first > 0.0);
    let mut header = header;
    if whole {
        header.push("× whole-image full search, mean / median".into());
    }
    if coarse {
        header.push("% started coarse".into());
    }
    let rows: Vec<Vec<String>> = picked
        .iter()
        .map(|x| {
            vec![
                x.label.clone(),
                pct(x.fraction.mean),
                pct(x.tiles),
                ms(x.time_ms.extract),
                ms(x.time_ms.quantize),
                ms(x.time_ms.vote),
                ms(x.time_ms.verify),
                ms(x.time_ms.total),
                format!("{:.3} / {:.3}", x.time_share.mean, x.time_share.median),
            ]
            .into_iter()
            .chain(whole.then(|| {
                x.time_share_whole
                    .map_or("–".into(), |w| format!("{:.3} / {:.3}", w.mean, w.median))
            }))
            .chain(coarse.then(|| pct(x.coarse_first)))
            .collect()
        })
        .collect();
    let t = &report.stages;
    format!(
        "### Time per query and stage (ms, median / p95 over seeds × queries × runs)\n\n\
         Wall time {:.1} s (extract {:.1} s, vocabularies {:.1} s, maps {:.1} s, quantize \
         queries {:.1} s, calibrate {:.1} s, sweep {:.1} s, verification {:.1} s, ORB pass \
         {:.1} s). \
         Queries are streamed in `{}` tiles, in the `{}` tile order, each tile's features \
         in the `{}` order, as the service does (its feature order is `random`): \
         extract = decode + SIFT of the tiles extracted (each tile timed when the query was \
         cached; the corner count that orders the tiles is in every tiled query's fixed \
         cost); quantize = the \
         blocked exact quantizer's measured cost per feature × features used; vote = voting \
         and rule checks inside the search; verify = the `verified` rule's checks and the \
         re-ranking. `× full search`: the request time against the full search's on the same \
         query (tiled; the `(whole image)` row is the full search on queries extracted \
         whole); `× whole-image full search`: against that whole-image full search, which is \
         how the service answers `rule=none`. With a learned coarse pass (`,auto`) each \
         setting replays the service's choice from a fresh start over its runs in turn, each \
         the queries in order, from what each search cost; `% started coarse`: the searches it started with the coarse pass \
         (`% tiles` counts that pass as a tile). Measured on this machine with all cores busy (queries run in parallel); \
         every setting's times are in `results.csv`.\n\n{}\n",
        t.total_s,
        t.extract_s,
        t.vocabulary_s,
        t.map_s,
        t.quantize_s,
        t.calibrate_s,
        t.sweep_s,
        t.verify_s,
        t.orb_pass_s,
        report.config.tiles,
        report.config.tile_order,
        report.config.feature_order,
        markdown_table(&header, &rows)
    )
}

/// The fewest features each rule and warm-up needs at each tolerance.
fn equal_recall_section(e: &EqualRecall) -> String {
    let mut header: Vec<String> = ["rule", "warm-up", "settings (degenerate)"]
        .map(String::from)
        .to_vec();
    for &t in &e.tolerances {
        header.push(format!("% features, loss ≤ {} pt", pct(t)));
        header.push(format!("setting, loss ≤ {} pt", pct(t)));
    }
    let rows: Vec<Vec<String>> = e
        .rows
        .iter()
        .map(|r| {
            let mut row = vec![
                format!("`{}`", r.rule),
                r.min_features.to_string(),
                if r.degenerate > 0 {
                    format!("{} ({})", r.settings, r.degenerate)
                } else {
                    r.settings.to_string()
                },
            ];
            for c in &r.cheapest {
                match c {
                    Some(c) if c.worst_fraction > c.fraction + 5e-4 => row.extend([
                        format!("{} (worst seed {})", pct(c.fraction), pct(c.worst_fraction)),
                        c.label.clone(),
                    ]),
                    Some(c) => row.extend([pct(c.fraction), c.label.clone()]),
                    None => row.extend(["–".to_owned(), "not reached".to_owned()]),
                }
            }
            row
        })
        .collect();
    let [a, b] = e.criterion.names();
    let title = match e.criterion {
        Criterion::Precision90 => "Features needed at equal recall",
        Criterion::PlainRecall => "Features needed at equal plain recall",
    };
    format!(
        "### {title}\n\n\
         For each rule and warm-up: the fewest features (% over queries and runs, mean over \
         seeds; chosen by its worst seed, shown when it differs) among the settings evaluated \
         (grid and `--set`, degenerate grid points left out) whose {a} and {b} are both at \
         most the given loss below the full search's (means {} and {}) on every vocabulary \
         seed; – when no setting is. No value between two settings is interpolated: the \
         resolution is the grid's.\n\n{}\n",
        pct(e.baseline[0]),
        pct(e.baseline[1]),
        markdown_table(&header, &rows)
    )
}

/// One CSV row per setting.
pub fn write_csv(report: &Report, path: &Path) -> anyhow::Result<()> {
    Ok(crate::store::write_atomic(path, |out| {
        csv_rows(report, out)
    })?)
}

fn csv_rows(report: &Report, out: &mut dyn std::io::Write) -> std::io::Result<()> {
    let mut w = csv::Writer::from_writer(out);
    let mut header: Vec<String> = [
        "dataset",
        "rule",
        "parameter",
        "min_features",
        "target",
        "degenerate",
        "seeds",
        "runs",
    ]
    .map(String::from)
    .to_vec();
    let names: Vec<String> = TOP_N
        .iter()
        .map(|n| format!("recall90_top{n}"))
        .chain(["recall1", "recall5", "recall90_top1_distinct", "fraction"].map(String::from))
        .collect();
    for name in &names {
        for part in ["mean", "seed_std", "runs_std", "worst"] {
            header.push(format!("{name}_{part}"));
        }
    }
    for stage in ["extract", "quantize", "vote", "search", "total"] {
        header.push(format!("{stage}_ms_median"));
        header.push(format!("{stage}_ms_p95"));
    }
    for of in ["full", "whole_full"] {
        header.push(format!("time_share_{of}_mean"));
        header.push(format!("time_share_{of}_median"));
    }
    header.extend(["tiles_mean", "coarse_first_mean"].map(String::from));
    w.write_record(&header)?;
    for s in &report.settings {
        let mut r = vec![
            report.dataset.name.clone(),
            s.setting.rule.name.clone(),
            s.setting
                .parameter()
                .map_or(String::new(), |p| p.to_string()),
            s.setting.min_features.to_string(),
            s.setting.target.map_or(String::new(), |t| t.to_string()),
            s.setting.degenerate.clone().unwrap_or_default(),
            s.runs.len().to_string(),
            s.runs.first().map_or(0, Vec::len).to_string(),
        ];
        let stats = s
            .recall90
            .iter()
            .chain([&s.recall_at_1, &s.recall_at_5, &s.recall90_top1_distinct])
            .map(|st| (st, st.lowest()))
            .chain([(&s.fraction, s.fraction.highest())]);
        for (st, worst) in stats {
            r.push(format!("{:.6}", st.mean));
            r.push(format!("{:.6}", st.std));
            r.push(format!("{:.6}", st.runs_std));
            r.push(format!("{worst:.6}"));
        }
        let t = &s.time_ms;
        for q in [t.extract, t.quantize, t.vote, t.search, t.total] {
            r.push(format!("{:.4}", q.median));
            r.push(format!("{:.4}", q.p95));
        }
        for share in [Some(s.time_share), s.time_share_whole] {
            r.push(share.map_or(String::new(), |x| format!("{:.4}", x.mean)));
            r.push(share.map_or(String::new(), |x| format!("{:.4}", x.median)));
        }
        r.push(format!("{:.4}", s.tiles));
        r.push(format!("{:.4}", s.coarse_first));
        w.write_record(&r)?;
    }
    w.flush()?;
    Ok(())
}

/// The equal-recall table: one row per rule, warm-up and tolerance; empty
/// setting and fraction where no setting is within the tolerance.
pub fn write_equal_recall_csv(report: &Report, path: &Path) -> anyhow::Result<()> {
    Ok(crate::store::write_atomic(path, |out| {
        equal_recall_rows(report, out)
    })?)
}

fn equal_recall_rows(report: &Report, out: &mut dyn std::io::Write) -> std::io::Result<()> {
    let mut w = csv::Writer::from_writer(out);
    w.write_record([
        "dataset",
        "criterion",
        "rule",
        "min_features",
        "settings",
        "degenerate",
        "tolerance",
        "setting",
        "fraction",
        "worst_fraction",
    ])?;
    for e in [&report.equal_recall, &report.equal_recall_plain]
        .into_iter()
        .flatten()
    {
        let criterion = match e.criterion {
            Criterion::Precision90 => "recall90_top5+recall1",
            Criterion::PlainRecall => "recall1+recall5",
        };
        for r in &e.rows {
            for (t, c) in e.tolerances.iter().zip(&r.cheapest) {
                w.write_record([
                    report.dataset.name.clone(),
                    criterion.to_owned(),
                    r.rule.clone(),
                    r.min_features.to_string(),
                    r.settings.to_string(),
                    r.degenerate.to_string(),
                    t.to_string(),
                    c.as_ref().map_or(String::new(), |c| c.label.clone()),
                    c.as_ref()
                        .map_or(String::new(), |c| format!("{:.6}", c.fraction)),
                    c.as_ref()
                        .map_or(String::new(), |c| format!("{:.6}", c.worst_fraction)),
                ])?;
            }
        }
    }
    w.flush()?;
    Ok(())
}

/// Every number, and every query's answers, as JSON (compact: the answers
/// make it large).
pub fn write_json(report: &Report, path: &Path) -> anyhow::Result<()> {
    let json = serde_json::to_vec(report)?;
    Ok(crate::store::write_atomic(path, |w| w.write_all(&json))?)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::eval::equal_recall::{equal_recall, tolerances};
    use crate::eval::summary::SettingSummary;

    #[test]
    fn equal_recall_table_shows_fractions_dashes_and_full_use() {
        let summaries = vec![
            SettingSummary::hand_made("none", None, 0, 0.915, 0.66, 1.0),
            SettingSummary::hand_made("peak-mean", Some(0.011), 0, 0.912, 0.647, 0.796),
            SettingSummary::hand_made("peak-mean", Some(0.0184), 0, 0.915, 0.658, 0.946),
            SettingSummary::hand_made("relative", Some(11.9), 0, 0.002, 0.272, 0.329),
            SettingSummary::hand_made("hoeffding", Some(0.5), 0, 0.915, 0.66, 1.0),
        ];
        let rules: Vec<String> = ["none", "peak-mean", "relative", "hoeffding"]
            .map(String::from)
            .to_vec();
        let e = equal_recall(
            &summaries,
            &rules,
            &tolerances(0.02),
            Criterion::Precision90,
        )
        .unwrap();
        let md = equal_recall_section(&e);
        let lines: Vec<&str> = md.lines().filter(|l| l.starts_with('|')).collect();
        assert_eq!(
            lines[0],
            "| rule | warm-up | settings (degenerate) | % features, loss ≤ 0.5 pt | setting, loss ≤ 0.5 pt \
             | % features, loss ≤ 2.0 pt | setting, loss ≤ 2.0 pt |"
        );
        assert_eq!(lines[2], "| `none` | 0 | 1 | 100.0 | none | 100.0 | none |");
        assert_eq!(
            lines[3],
            "| `peak-mean` | 0 | 2 | 94.6 | peak-mean 0.0184 | 79.6 | peak-mean 0.011 |"
        );
        assert_eq!(
            lines[4],
            "| `relative` | 0 | 1 | – | not reached | – | not reached |"
        );
        assert_eq!(
            lines[5],
            "| `hoeffding` | 0 | 1 | 100.0 | hoeffding 0.5 | 100.0 | hoeffding 0.5 |"
        );
        assert!(md.contains("full search's (means 91.5 and 66.0)"), "{md}");
    }

    #[test]
    fn points_lost_are_per_seed_signed_and_never_minus_zero() {
        let stat = |per_seed: Vec<f64>| Stat {
            per_seed,
            ..Stat::default()
        };
        let full = stat(vec![0.830, 0.835, 0.850, 0.9]);
        let s = stat(vec![0.820, 0.845, 0.8500004, f64::NAN]);
        assert_eq!(points_lost(&full, &s), "1.0 / -1.0 / 0.0 / –");
    }
}
