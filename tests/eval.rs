//! End to end: `bowloc eval` on the real rtabmap-loop dataset with small
//! vocabularies (two k-means seeds) and few runs, then a second run served
//! from the cache; and options that are wrong fail before any work.

mod common;

use serde_json::Value;
use std::path::Path;
use std::process::Command;

fn run_eval(out: &Path, cache: &Path, extra: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_bowloc"))
        .arg("eval")
        .arg("--dataset")
        .arg(common::dataset("rtabmap-loop"))
        .arg("--out")
        .arg(out)
        .arg("--cache")
        .arg(cache)
        .args(["--words", "200", "--vocab-seeds", "2", "--log", "info"])
        .args(extra)
        .output()
        .expect("bowloc runs")
}

fn eval(out: &Path, cache: &Path, extra: &[&str]) -> String {
    let output = run_eval(out, cache, extra);
    let stderr = String::from_utf8_lossy(&output.stderr).into_owned();
    assert!(output.status.success(), "bowloc eval failed:\n{stderr}");
    stderr
}

#[test]
fn bad_set_histogram_and_plan_order_values_fail_before_any_extraction() {
    let dir = tempfile::tempdir().unwrap();
    let (out, cache) = (dir.path().join("out"), dir.path().join("cache"));
    let cases: [(&[&str], &str); 7] = [
        (&["--set", "relative=2.5x"], "--set relative=2.5x"),
        (&["--set", "nope=1"], "unknown rule `nope`"),
        (
            &["--histogram", "peak-mean=abc"],
            "--histogram peak-mean=abc",
        ),
        (&["--histogram", "nope"], "rule `nope` is not in the sweep"),
        (
            &["--plan-orders", "2"],
            "--plan-orders replays a learned coarse pass",
        ),
        (
            &["--orb-pass", "--orb-floor", "2"],
            "--orb-pass: floor must be at least 3",
        ),
        (
            &["--orb-pass", "--orb-grid", "0x3"],
            "--orb-pass: grid `0x3`: want COLSxROWS",
        ),
    ];
    for (args, says) in cases {
        let started = std::time::Instant::now();
        let o = run_eval(&out, &cache, args);
        let stderr = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success(), "{args:?} accepted");
        assert!(stderr.contains(says), "{args:?}: {stderr}");
        // nothing was extracted or trained
        assert!(!cache.exists() && !out.exists(), "{args:?}");
        assert!(!stderr.contains("extract"), "{args:?}: {stderr}");
        assert!(started.elapsed().as_secs() < 5, "{args:?}");
    }
}

fn mean(v: &Value) -> f64 {
    v["mean"].as_f64().expect("a mean")
}

#[test]
fn eval_writes_consistent_tables_plots_and_reuses_its_cache() {
    let dir = tempfile::tempdir().unwrap();
    let (out, cache) = (dir.path().join("out"), dir.path().join("cache"));
    let log = eval(
        &out,
        &cache,
        &[
            "--runs",
            "3",
            "--min-features",
            "0,100",
            "--targets",
            "0.3,0.4,0.7",
        ],
    );
    assert!(log.contains("training vocabulary"), "{log}");

    for f in ["results.md", "results.csv", "results.json"] {
        assert!(out.join(f).metadata().unwrap().len() > 0, "{f}");
    }
    for stem in ["recall_vs_features", "warmup", "fraction_histogram"] {
        let png = std::fs::read(out.join(format!("{stem}.png"))).unwrap();
        assert_eq!(&png[..8], b"\x89PNG\r\n\x1a\n", "{stem}.png");
        let svg = std::fs::read_to_string(out.join(format!("{stem}.svg"))).unwrap();
        assert!(
            svg.contains("<svg") && svg.contains("features used"),
            "{stem}.svg"
        );
    }

    let report: Value =
        serde_json::from_slice(&std::fs::read(out.join("results.json")).unwrap()).unwrap();
    assert_eq!(report["dataset"]["queries"], 44);
    assert_eq!(report["dataset"]["with_match"], 44);
    // Two vocabularies, and where they were made.
    let vocabularies = report["vocabularies"].as_array().unwrap();
    assert_eq!(vocabularies.len(), 2);
    assert_ne!(vocabularies[0]["hash"], vocabularies[1]["hash"]);
    assert_eq!(report["config"]["seeds"], serde_json::json!([1, 2]));
    let machine = &report["machine"];
    assert!(!machine["cpu_model"].as_str().unwrap().is_empty());
    assert!(
        machine["opencv"]["version"]
            .as_str()
            .unwrap()
            .starts_with('4')
    );
    assert_eq!(machine["map_descriptors"].as_str().unwrap().len(), 16);
    let settings = report["settings"].as_array().unwrap();
    let find = |rule: &str, p: Option<f64>| {
        settings
            .iter()
            .find(|s| {
                s["setting"]["rule"]["name"] == rule
                    && p.is_none_or(|p| s["setting"]["rule"]["parameter"].as_f64() == Some(p))
            })
            .unwrap_or_else(|| panic!("no setting {rule} {p:?}"))
    };

    // The full search uses every feature and finds most places (measured:
    // recall@5 and recall top-5 @90%P 0.977 with K = 200, 3 runs).
    let full = find("none", None);
    assert_eq!(mean(&full["fraction"]), 1.0);
    assert!(
        mean(&full["recall_at_5"]) >= 0.85,
        "{}",
        full["recall_at_5"]
    );
    assert!(mean(&full["recall90"][1]) >= 0.8, "{}", full["recall90"]);

    // The naive rule uses its fraction (one query without features counts 1).
    let half = mean(&find("fixed", Some(0.5))["fraction"]);
    assert!((0.48..=0.55).contains(&half), "fixed 0.5 used {half}");

    // Calibrated rules ran at both warm-ups, and peak-mean spans the targets.
    for w in [0, 100] {
        assert!(
            settings
                .iter()
                .any(|s| s["setting"]["rule"]["name"] == "stable-peak"
                    && s["setting"]["min_features"] == w)
        );
    }
    let peak: Vec<f64> = settings
        .iter()
        .filter(|s| {
            s["setting"]["rule"]["name"] == "peak-mean" && s["setting"]["min_features"] == 0
        })
        .map(|s| mean(&s["fraction"]))
        .collect();
    assert_eq!(peak.len(), 3);
    assert!(peak.iter().any(|&f| (0.3..0.5).contains(&f)), "{peak:?}");
    assert!(peak.iter().any(|&f| (0.6..0.8).contains(&f)), "{peak:?}");

    // A warm-up of 100 leaves these queries (162 features on average) no
    // way to 30 % of the features: those grid points are marked degenerate
    // and neither the equal-recall tables nor the recommendation use them.
    let degenerate: Vec<usize> = settings
        .iter()
        .enumerate()
        .filter(|(_, s)| s["setting"]["degenerate"].is_string())
        .map(|(i, _)| i)
        .collect();
    assert!(!degenerate.is_empty());
    for &i in &degenerate {
        assert_eq!(settings[i]["setting"]["min_features"], 100);
    }
    let mut used: Vec<u64> = vec![report["recommendation"]["index"].as_u64().unwrap()];
    for table in ["equal_recall", "equal_recall_plain"] {
        for row in report[table]["rows"].as_array().unwrap() {
            for c in row["cheapest"].as_array().unwrap() {
                used.extend(c["index"].as_u64());
            }
        }
    }
    assert!(used.len() > 10);
    assert!(used.iter().all(|i| !degenerate.contains(&(*i as usize))));

    // Every query's answers, for re-scoring: [seed][setting][run][query].
    let per_query = &report["per_query"]["outcomes"];
    assert_eq!(per_query.as_array().unwrap().len(), 2);
    assert_eq!(per_query[0].as_array().unwrap().len(), settings.len());
    assert_eq!(per_query[0][0].as_array().unwrap().len(), 3);
    let answer = per_query[1][0][2]
        .as_array()
        .unwrap()
        .iter()
        .find(|a| a["total"].as_u64() > Some(0))
        .unwrap();
    assert_eq!(answer["used"], answer["total"]);
    assert_eq!(answer["stop"], "exhausted");
    let top = answer["candidates"].as_array().unwrap();
    assert!(!top.is_empty() && top.len() <= 10 && top[0].as_array().unwrap().len() == 2);

    // Per run, recall at 90 % precision grows with n and never exceeds
    // plain recall@5 for n = 5.
    for s in settings {
        for run in s["runs"]
            .as_array()
            .unwrap()
            .iter()
            .flat_map(|r| r.as_array().unwrap())
        {
            let r: Vec<f64> = run["recall90"]
                .as_array()
                .unwrap()
                .iter()
                .map(|v| v.as_f64().unwrap())
                .collect();
            assert!(r[0] <= r[1] && r[1] <= r[2], "{run}");
            assert!(
                r[1] <= run["recall_at_5"].as_f64().unwrap() + 1e-12,
                "{run}"
            );
        }
        assert_eq!(s["runs"].as_array().unwrap().len(), 2);
        assert_eq!(s["runs"][1].as_array().unwrap().len(), 3);
        let per_seed = s["recall_at_1"]["per_seed"].as_array().unwrap();
        assert_eq!(per_seed.len(), 2);
    }

    // One CSV row per setting.
    let csv = std::fs::read_to_string(out.join("results.csv")).unwrap();
    assert_eq!(csv.lines().count(), settings.len() + 1);
    let md = std::fs::read_to_string(out.join("results.md")).unwrap();
    assert!(md.contains("recall top-5 @90%P") && md.contains("### Rule `peak-mean`"));
    assert!(md.contains("### Features needed at equal plain recall"));
    assert!(md.contains(" ± ") && md.contains("(std over feature orders, top-5)"));
    assert!(md.contains("† degenerate grid point"));

    // A second run with other rules reuses descriptors, vocabulary and map.
    let out2 = dir.path().join("out2");
    let log = eval(
        &out2,
        &cache,
        &[
            "--runs",
            "1",
            "--rules",
            "fixed",
            "--set",
            "relative=2.5@100",
            "--no-plots",
        ],
    );
    assert!(log.contains("descriptors from cache"), "{log}");
    assert!(log.contains("vocabulary from cache"), "{log}");
    assert!(log.contains("map from cache"), "{log}");
    assert!(!log.contains("training vocabulary"), "{log}");
    let again: Value =
        serde_json::from_slice(&std::fs::read(out2.join("results.json")).unwrap()).unwrap();
    assert_eq!(again["vocabularies"], report["vocabularies"]);
    // Full search, three fixed fractions and the setting asked for.
    let settings = again["settings"].as_array().unwrap();
    assert_eq!(settings.len(), 5);
    let asked = &settings[again["explicit"][0].as_u64().unwrap() as usize];
    assert_eq!(asked["setting"]["rule"]["name"], "relative");
    assert_eq!(asked["setting"]["min_features"], 100);
    let md = std::fs::read_to_string(out2.join("results.md")).unwrap();
    assert!(md.contains("### Settings asked for") && md.contains("relative 2.5 w=100"));
    // each setting's loss to the full search, for each of the two
    // vocabulary seeds: none for the full search itself, and a number (or –)
    // for the setting asked for
    for what in ["recall@1", "recall@5"] {
        let label = format!("| {what} lost to the full search, per seed |");
        let line = md.lines().find(|l| l.starts_with(&label)).expect(&label);
        let cells: Vec<&str> = line.split('|').map(str::trim).collect();
        assert_eq!(cells[2], "0.0 / 0.0", "{line}");
        for cell in &cells[3..cells.len() - 1] {
            let values: Vec<&str> = cell.split(" / ").collect();
            assert_eq!(values.len(), 2, "{line}");
            assert!(
                values.iter().all(|v| *v == "–" || v.parse::<f64>().is_ok()),
                "{line}"
            );
        }
    }
    assert!(!out2.join("recall_vs_features.png").exists());

    // The learned coarse pass, replayed: the trials alternate between the
    // two plans, and the full search (which never stops early) never
    // starts with the coarse pass.
    let out3 = dir.path().join("out3");
    eval(
        &out3,
        &cache,
        &[
            "--runs",
            "2",
            "--rules",
            "none",
            "--set",
            "place-z=2+verified=12@20",
            "--tiles",
            "2x2+24,auto",
            "--plan-orders",
            "4",
            "--no-plots",
        ],
    );
    let learned: Value =
        serde_json::from_slice(&std::fs::read(out3.join("results.json")).unwrap()).unwrap();
    let asked = learned["explicit"][0].as_u64().unwrap() as usize;
    assert_ne!(asked, 0);
    let started_coarse = |setting: usize| -> Vec<bool> {
        learned["per_query"]["outcomes"]
            .as_array()
            .unwrap()
            .iter()
            .flat_map(|seed| seed[setting].as_array().unwrap().iter())
            .flat_map(|run| run.as_array().unwrap().iter())
            .map(|o| o["coarse"] == true)
            .collect()
    };
    assert!(started_coarse(0).iter().all(|&c| !c));
    let per_seed = started_coarse(asked);
    let queries = per_seed.len() / 4; // 2 seeds × 2 runs
    for seed in per_seed.chunks(2 * queries) {
        // plain first, then the coarse pass, through the trials
        assert_eq!(seed[..16], [false, true].repeat(8)[..], "{seed:?}");
    }
    let md = std::fs::read_to_string(out3.join("results.md")).unwrap();
    assert!(md.contains("% started coarse"), "{md}");
    // plans over random query orders: the setting asked for (it stops
    // early), on each seed, fresh and restarted, four orders of two passes
    // each; every fresh order goes through its trials (16 of its searches
    // or more with the coarse pass), a restarted one need not
    let orders = learned["plan_orders"].as_array().unwrap();
    assert_eq!(orders.len(), 4, "{orders:?}");
    let starts: Vec<&str> = orders
        .iter()
        .map(|r| r["start"].as_str().unwrap())
        .collect();
    assert_eq!(starts, ["fresh", "restarted", "fresh", "restarted"]);
    for row in orders {
        assert_eq!(row["passes"], 2);
        assert!(row["full_median_ms"].as_f64().unwrap() > 0.0);
        let replays = row["orders"].as_array().unwrap();
        assert_eq!(replays.len(), 4);
        let least = match row["start"].as_str().unwrap() {
            "fresh" => 16.0 / (2 * queries) as f64,
            _ => 0.0,
        };
        for o in replays {
            let started = o["started_coarse"].as_f64().unwrap();
            assert!(started >= least && started <= 1.0, "{o}");
            assert!(o["median_ms"].as_f64().unwrap() > 0.0, "{o}");
            assert!(o["recall_at_1"].as_f64().unwrap() > 0.5, "{o}");
            assert!(o["settled_coarse"].is_boolean(), "{o}");
        }
    }
    assert!(md.contains("## The learned plan over query orders"), "{md}");

    // The ORB pass first: the map's ORB side built beside the cached map
    // on the first run and reused on the next; the full search and the
    // setting asked for (verified) again with the pass first, which answers
    // some queries with no SIFT feature and so uses fewer features and less
    // time than the setting alone.
    let orb_args = [
        "--runs",
        "1",
        "--rules",
        "none",
        "--verify",
        "--set",
        "place-z=2.25+verified=12@20",
        "--orb-pass",
        "--no-plots",
    ];
    let out4 = dir.path().join("out4");
    let log = eval(&out4, &cache, &orb_args);
    assert!(!log.contains("ORB side from cache"), "{log}");
    let log = eval(&out4, &cache, &orb_args);
    assert!(log.contains("ORB side from cache"), "{log}");
    let orb: Value =
        serde_json::from_slice(&std::fs::read(out4.join("results.json")).unwrap()).unwrap();
    let pass = &orb["orb_pass"];
    let looks = pass["looks"].as_array().unwrap();
    assert_eq!(looks.len(), 2, "one per vocabulary seed");
    let settings = orb["settings"].as_array().unwrap();
    for (seed, l) in looks.iter().enumerate() {
        let l = l.as_array().unwrap();
        assert_eq!(l.len(), 44);
        let answered = l.iter().filter(|q| !q["answer"].is_null()).count();
        let share = pass["answered"]["per_seed"][seed].as_f64().unwrap();
        assert!((share - answered as f64 / 44.0).abs() < 1e-9, "{share}");
        assert!(answered > 0 && answered < 44, "{answered}");
        for q in l {
            assert!(q["pass_ms"].as_f64().unwrap() > 0.0, "{q}");
        }
    }
    let rows = pass["rows"].as_array().unwrap();
    let alone: Vec<&str> = rows
        .iter()
        .map(|r| {
            settings[r["alone"].as_u64().unwrap() as usize]["label"]
                .as_str()
                .unwrap()
        })
        .collect();
    assert_eq!(
        alone,
        ["none +verify", "place-z 2.25 or verified 12 w=20 +verify"]
    );
    for (r, label) in rows.iter().zip(&alone) {
        let with = &r["with"];
        assert_eq!(with["label"], format!("{label} +orb"));
        let before = &settings[r["alone"].as_u64().unwrap() as usize];
        assert!(mean(&with["fraction"]) < mean(&before["fraction"]), "{r}");
        let median = |s: &Value| s["time_share_whole"]["median"].as_f64().unwrap();
        assert!(median(with) < median(before), "{r}");
    }
    let md = std::fs::read_to_string(out4.join("results.md")).unwrap();
    assert!(md.contains("## The ORB pass first"), "{md}");
    assert!(md.contains("| none +verify +orb |"), "{md}");
}

#[test]
fn a_sequence_eval_warms_up_as_the_service_does() {
    let dir = tempfile::tempdir().unwrap();
    let cache = dir.path().join("cache");
    let inject = common::dataset("rtabmap-loop").join("map.txt");
    let sequence = |name: &str, stop: &str| {
        let out = dir.path().join(name);
        let o = run_eval(
            &out,
            &cache,
            &[
                "--sequence",
                "--runs",
                "1",
                "--injections",
                "2",
                "--inject",
                inject.to_str().unwrap(),
                "--stop",
                stop,
            ],
        );
        (o, out)
    };
    // a warm-up that is neither fails before any work
    let (o, _) = sequence("bad", "posterior=0.7@soon");
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert!(
        stderr.contains("neither a number of features nor `auto`"),
        "{stderr}"
    );
    assert!(!cache.exists(), "{stderr}");
    let report = |out: &Path| -> Value {
        serde_json::from_str(&std::fs::read_to_string(out.join("sequence.json")).unwrap()).unwrap()
    };
    // `auto`: a quarter of the map images' median feature count, at most 100
    let (o, out) = sequence("auto", "posterior=0.7@auto");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let auto = report(&out);
    let w = auto["min_features"].as_u64().unwrap();
    assert!(w > 0 && w < 100, "rtabmap-loop's small frames: {w}");
    let modes = auto["modes"].as_array().unwrap();
    let row = |filter: bool, stopped: bool| {
        modes
            .iter()
            .find(|m| m["filter"] == filter && (m["rule"] != "full") == stopped)
            .unwrap_or_else(|| panic!("no mode filter={filter} stopped={stopped}"))
    };
    assert_eq!(
        row(true, true)["rule"],
        format!("posterior (epsilon 0.7) w={w}")
    );
    // the filter's stop reads fewer features than its full search
    let features = |m: &Value| m["features"]["mean"].as_f64().unwrap();
    assert!(features(row(true, true)) < features(row(true, false)));
    // a number is taken as it is
    let (o, out) = sequence("fixed", "posterior=0.7@40");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert_eq!(report(&out)["min_features"], 40);
}
