//! Writing a report out: markdown tables in the layout of the paper's
//! Tables I–IV (one per rule), the warm-up comparison and the time per
//! stage, the features each rule needs at equal recall; a CSV with one row
//! per setting, another with the equal-recall table; a JSON of every number.

use super::Report;
use super::equal_recall::EqualRecall;
use super::summary::{SettingSummary, TOP_N};
use super::sweep::{BASELINE, format_parameter};
use std::fmt::Write as _;
use std::path::Path;

/// A rate as a percentage with one decimal.
fn pct(v: f64) -> String {
    format!("{:.1}", 100.0 * v)
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
                pct(s.recall90_at(n).mean)
            })
        })
        .collect();
    rows.push(row("(std over runs, top-5)".into(), &|s| {
        pct(s.recall90_at(5).std)
    }));
    rows.push(row("% features".into(), &|s| pct(s.fraction.mean)));
    rows.push(row(parameter.into(), &|s| {
        s.setting.parameter().map_or("–".into(), format_parameter)
    }));
    rows.push(row("recall@1".into(), &|s| pct(s.recall_at_1.mean)));
    rows.push(row("recall@5".into(), &|s| pct(s.recall_at_5.mean)));
    rows.push(row(
        "search ms (quantize + vote), median / p95".into(),
        &|s| ms(s.time_ms.search),
    ));
    rows
}

/// The whole markdown report.
pub fn markdown(report: &Report) -> String {
    let mut s = String::new();
    let d = &report.dataset;
    let c = &report.config;
    let main = c.warmups.first().copied().unwrap_or(0);
    let _ = writeln!(s, "## {}\n", d.name);
    let _ = writeln!(s, "Command: `{}`\n", report.command);
    let _ = writeln!(
        s,
        "{} map images, {} queries ({} with a match in the map), K = {} words, {} runs \
         (random feature orders), {} features per query on average. Recall at 90 % precision \
         is computed per run, then averaged over runs; all rates in %. Wall time {:.1} s \
         (extract {:.1} s, vocabulary {:.1} s, map {:.1} s, quantize queries {:.1} s, \
         calibrate {:.1} s, sweep {:.1} s).\n",
        d.map_images,
        d.queries,
        d.with_match,
        report.vocabulary.words,
        c.runs,
        d.mean_features.round(),
        report.stages.total_s,
        report.stages.extract_s,
        report.stages.vocabulary_s,
        report.stages.map_s,
        report.stages.quantize_s,
        report.stages.calibrate_s,
        report.stages.sweep_s,
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
                x.setting.parameter().map_or(rule.clone(), |p| {
                    format!("{parameter} {}", format_parameter(p))
                })
            }))
            .collect();
        let _ = writeln!(s, "### Rule `{rule}` (warm-up {main})\n");
        s += &markdown_table(&header, &paper_rows(&all, parameter));
        s += "\n";
    }
    s += &explicit_section(report, base);
    s += &warmup_section(report);
    s += &timing_section(report, base);
    if let Some(e) = &report.equal_recall {
        s += &equal_recall_section(e);
    }
    if let Some(r) = &report.recommendation {
        let _ = writeln!(
            s,
            "### Recommended setting\n\nThe setting using the fewest features while losing at most \
             {} points of the full search's recall top-5 @90%P ({}) and recall@1 ({}): \
             **{}**, using {} % of the features with recall top-5 @90%P {} and recall@1 {}.\n",
            pct(r.tolerance),
            pct(r.baseline_recall90_top5),
            pct(r.baseline_recall_at_1),
            r.label,
            pct(r.fraction),
            pct(r.recall90_top5),
            pct(r.recall_at_1),
        );
    }
    if let Some(h) = &report.histogram {
        let _ = writeln!(
            s,
            "Histogram of the fraction of features used per query ({} queries × runs) for \
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
    s
}

/// The settings asked for with `--set`, next to the full search.
fn explicit_section(report: &Report, base: &SettingSummary) -> String {
    if report.explicit.is_empty() {
        return String::new();
    }
    let mut columns = vec![base];
    columns.extend(report.explicit.iter().map(|&i| &report.settings[i]));
    let header: Vec<String> = std::iter::once(String::new())
        .chain(columns.iter().map(|c| c.label.clone()))
        .collect();
    let mut rows = paper_rows(&columns, "parameter");
    rows.insert(
        rows.len() - 3,
        std::iter::once("warm-up".to_owned())
            .chain(columns.iter().map(|c| c.setting.min_features.to_string()))
            .collect(),
    );
    format!(
        "### Settings asked for\n\n{}\n",
        markdown_table(&header, &rows)
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
                x.setting.parameter().map_or("–".into(), format_parameter)
            }));
            rows.push(row("% features", &|x| pct(x.fraction.mean)));
            rows.push(row("recall top-5 @90%P", &|x| pct(x.recall90_at(5).mean)));
            rows.push(row("recall@1", &|x| pct(x.recall_at_1.mean)));
        }
        s += &markdown_table(&header, &rows);
        s += "\n";
    }
    s
}

/// Time per stage for the full search, the recommended setting and, per
/// rule, the setting nearest half the features.
fn timing_section(report: &Report, base: &SettingSummary) -> String {
    let main = report.config.warmups.first().copied().unwrap_or(0);
    let mut picked: Vec<&SettingSummary> = vec![base];
    if let Some(r) = &report.recommendation {
        picked.push(&report.settings[r.index]);
    }
    for rule in &report.config.rules {
        if let Some(x) = of_rule(report, rule, main)
            .into_iter()
            .filter(|x| x.setting.rule.name != BASELINE)
            .min_by(|a, b| {
                (a.fraction.mean - 0.5)
                    .abs()
                    .total_cmp(&(b.fraction.mean - 0.5).abs())
            })
            && !picked.iter().any(|p| std::ptr::eq(*p, x))
        {
            picked.push(x);
        }
    }
    let header: Vec<String> = [
        "setting",
        "% features",
        "extract",
        "quantize",
        "vote",
        "quantize + vote",
        "total",
    ]
    .map(String::from)
    .to_vec();
    let rows: Vec<Vec<String>> = picked
        .iter()
        .map(|x| {
            vec![
                x.label.clone(),
                pct(x.fraction.mean),
                ms(x.time_ms.extract),
                ms(x.time_ms.quantize),
                ms(x.time_ms.vote),
                ms(x.time_ms.search),
                ms(x.time_ms.total),
            ]
        })
        .collect();
    format!(
        "### Time per query and stage (ms, median / p95 over queries × runs)\n\n\
         Extract = decode + SIFT, measured once per query while extracting; quantize = the \
         blocked exact quantizer's measured cost per feature × features used; vote = voting \
         and rule checks inside the search. Measured on this machine with all cores busy \
         (queries run in parallel).\n\n{}\n",
        markdown_table(&header, &rows)
    )
}

/// The fewest features each rule and warm-up needs at each tolerance.
fn equal_recall_section(e: &EqualRecall) -> String {
    let mut header: Vec<String> = ["rule", "warm-up", "settings"].map(String::from).to_vec();
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
                r.settings.to_string(),
            ];
            for c in &r.cheapest {
                match c {
                    Some(c) => row.extend([pct(c.fraction), c.label.clone()]),
                    None => row.extend(["–".to_owned(), "not reached".to_owned()]),
                }
            }
            row
        })
        .collect();
    format!(
        "### Features needed at equal recall\n\n\
         For each rule and warm-up: the fewest features (mean % over queries and runs) among \
         the settings evaluated (grid and `--set`) whose recall top-5 @90%P and recall@1 are \
         both at most the given loss below the full search's ({} and {}); – when no setting \
         is. No value between two settings is interpolated: the resolution is the grid's.\n\n{}\n",
        pct(e.baseline_recall90_top5),
        pct(e.baseline_recall_at_1),
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
        "runs",
    ]
    .map(String::from)
    .to_vec();
    for n in TOP_N {
        header.push(format!("recall90_top{n}_mean"));
        header.push(format!("recall90_top{n}_std"));
    }
    for name in ["recall1", "recall5", "fraction"] {
        header.push(format!("{name}_mean"));
        header.push(format!("{name}_std"));
    }
    for stage in ["extract", "quantize", "vote", "search", "total"] {
        header.push(format!("{stage}_ms_median"));
        header.push(format!("{stage}_ms_p95"));
    }
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
            s.runs.len().to_string(),
        ];
        let stats = s
            .recall90
            .iter()
            .chain([&s.recall_at_1, &s.recall_at_5, &s.fraction]);
        for st in stats {
            r.push(format!("{:.6}", st.mean));
            r.push(format!("{:.6}", st.std));
        }
        let t = &s.time_ms;
        for q in [t.extract, t.quantize, t.vote, t.search, t.total] {
            r.push(format!("{:.4}", q.median));
            r.push(format!("{:.4}", q.p95));
        }
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
        "rule",
        "min_features",
        "settings",
        "tolerance",
        "setting",
        "fraction",
    ])?;
    if let Some(e) = &report.equal_recall {
        for r in &e.rows {
            for (t, c) in e.tolerances.iter().zip(&r.cheapest) {
                w.write_record([
                    report.dataset.name.clone(),
                    r.rule.clone(),
                    r.min_features.to_string(),
                    r.settings.to_string(),
                    t.to_string(),
                    c.as_ref().map_or(String::new(), |c| c.label.clone()),
                    c.as_ref()
                        .map_or(String::new(), |c| format!("{:.6}", c.fraction)),
                ])?;
            }
        }
    }
    w.flush()?;
    Ok(())
}

/// Every number, as JSON.
pub fn write_json(report: &Report, path: &Path) -> anyhow::Result<()> {
    let json = serde_json::to_vec_pretty(report)?;
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
        let e = equal_recall(&summaries, &rules, &tolerances(0.02)).unwrap();
        let md = equal_recall_section(&e);
        let lines: Vec<&str> = md.lines().filter(|l| l.starts_with('|')).collect();
        assert_eq!(
            lines[0],
            "| rule | warm-up | settings | % features, loss ≤ 0.5 pt | setting, loss ≤ 0.5 pt \
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
        assert!(md.contains("full search's (91.5 and 66.0)"), "{md}");
    }
}
