//! `bowloc calibrate` on a map of small images (the real rtabmap-loop
//! images downscaled to 160×120 by this test, about a hundred features
//! each): a warm-up larger than the pseudo-queries' feature count is refused
//! with the reason, the adapted default warm-up calibrates a rule that
//! stops early or fails naming why, and `--out` refuses a rule whose
//! transfer check misses its target (queries of another place) unless
//! `--force`.

mod common;

use opencv::core::{Mat, Size, Vector};
use opencv::prelude::*;
use opencv::{imgcodecs, imgproc};
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// Write `list` (paths relative to `src`) downscaled to 160×120 under
/// `dst/prefix`, and return the new relative paths.
fn downscale(src: &Path, list: &[String], dst: &Path, prefix: &str) -> Vec<String> {
    std::fs::create_dir_all(dst.join(prefix)).unwrap();
    list.iter()
        .map(|name| {
            let image =
                imgcodecs::imread(src.join(name).to_str().unwrap(), imgcodecs::IMREAD_COLOR)
                    .unwrap();
            assert!(!image.empty(), "{name}: unreadable");
            let mut small = Mat::default();
            imgproc::resize(
                &image,
                &mut small,
                Size::new(160, 120),
                0.0,
                0.0,
                imgproc::INTER_AREA,
            )
            .unwrap();
            let file = name.replace('/', "_");
            let out = format!("{prefix}/{file}");
            assert!(
                imgcodecs::imwrite(dst.join(&out).to_str().unwrap(), &small, &Vector::new())
                    .unwrap()
            );
            out
        })
        .collect()
}

fn lines(path: &Path) -> Vec<String> {
    std::fs::read_to_string(path)
        .unwrap()
        .lines()
        .filter(|l| !l.trim().is_empty())
        .map(str::to_owned)
        .collect()
}

/// A dataset in the shared layout: rtabmap-loop's map, downscaled, with the
/// queries of `queries_from` (its own, or another dataset's: another place).
fn small_dataset(dir: &Path, queries_from: &str, count: usize) -> PathBuf {
    let rtab = common::dataset("rtabmap-loop");
    let map = downscale(&rtab, &lines(&rtab.join("map.txt")), dir, "map");
    let src = common::dataset(queries_from);
    let names: Vec<String> = lines(&src.join("queries.txt"))
        .into_iter()
        .take(count)
        .collect();
    let queries = downscale(&src, &names, dir, "queries");
    std::fs::write(dir.join("map.txt"), map.join("\n")).unwrap();
    std::fs::write(dir.join("queries.txt"), queries.join("\n")).unwrap();
    let mut truth = String::from("query,match\n");
    if queries_from == "rtabmap-loop" {
        for row in lines(&rtab.join("ground_truth.csv")).iter().skip(1) {
            let (q, m) = row.split_once(',').unwrap();
            let (q, m) = (q.trim().replace('/', "_"), m.trim().replace('/', "_"));
            truth += &format!("queries/{q},map/{m}\n");
        }
    }
    std::fs::write(dir.join("ground_truth.csv"), truth).unwrap();
    dir.to_path_buf()
}

fn bowloc(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_bowloc"))
        .args(args)
        .output()
        .expect("bowloc runs")
}

fn ok(args: &[&str]) -> String {
    let o = bowloc(args);
    assert!(
        o.status.success(),
        "bowloc {args:?} failed:\n{}",
        String::from_utf8_lossy(&o.stderr)
    );
    String::from_utf8(o.stdout).unwrap()
}

/// Vocabulary and map over the dataset's map images.
fn vocab_and_map(data: &Path) -> (String, String) {
    let (vocab, map) = (data.join("vocab.bowvoc"), data.join("map.bowmap"));
    let (vocab, map) = (vocab.to_str().unwrap(), map.to_str().unwrap());
    let images = data.join("map.txt");
    let images = images.to_str().unwrap();
    ok(&[
        "vocab", "build", "--images", images, "--words", "200", "--out", vocab,
    ]);
    ok(&[
        "map", "build", "--vocab", vocab, "--images", images, "--out", map,
    ]);
    (vocab.to_owned(), map.to_owned())
}

/// The warm-up printed in the table's first line.
fn warmup(table: &str) -> usize {
    let after = table
        .split("warm-up ")
        .nth(1)
        .expect("the warm-up is printed");
    after
        .split(|c: char| !c.is_ascii_digit())
        .next()
        .unwrap()
        .parse()
        .unwrap()
}

/// A small-image map with queries from `queries_from`, its vocabulary and
/// map, and where `--out` goes.
struct Case {
    dir: tempfile::TempDir,
    data: PathBuf,
    vocab: String,
    map: String,
}

impl Case {
    fn new(queries_from: &str, count: usize) -> Self {
        let dir = tempfile::tempdir().unwrap();
        let data = small_dataset(dir.path(), queries_from, count);
        let (vocab, map) = vocab_and_map(&data);
        Self {
            dir,
            data,
            vocab,
            map,
        }
    }

    fn out(&self) -> String {
        let out = self.dir.path().join("calibrated.toml");
        out.to_str().unwrap().to_owned()
    }

    /// `bowloc calibrate` on this map, 2 runs, target 0.05, then `extra`.
    fn calibrate(&self, extra: &[&str]) -> Output {
        let args = [
            "calibrate",
            "--vocab",
            &self.vocab,
            "--map",
            &self.map,
            "--runs",
            "2",
            "--max-disagreement",
            "0.05",
        ];
        bowloc(&[&args[..], extra].concat())
    }
}

#[test]
fn small_images_calibrate_with_an_adapted_warm_up_or_say_why() {
    let case = Case::new("rtabmap-loop", 44);
    let out = case.out();
    let out = out.as_str();

    // The old fixed warm-up of 100 is more than these pseudo-queries have.
    let o = case.calibrate(&["--min-features", "100", "--out", out]);
    let stdout = String::from_utf8_lossy(&o.stdout);
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success(), "{stdout}");
    assert!(
        stdout.contains("not calibrated: warm-up 100 ≥ the median pseudo-query's"),
        "{stdout}"
    );
    assert!(stderr.contains("no rule could be calibrated"), "{stderr}");
    assert!(!Path::new(out).exists());

    // The adapted warm-up: either a rule that stops early and transfers, or
    // a refusal naming why.
    let o = case.calibrate(&["--dataset", case.data.to_str().unwrap(), "--out", out]);
    let stdout = String::from_utf8_lossy(&o.stdout);
    let stderr = String::from_utf8_lossy(&o.stderr);
    let w = warmup(&stdout);
    assert!((1..100).contains(&w), "{stdout}");
    println!("{stdout}");
    if o.status.success() {
        let config = bowloc::server::config::Config::load(Path::new(out)).unwrap();
        assert_eq!(config.search.min_features, w);
        let rule = config.default_rule().unwrap();
        let row = stdout
            .lines()
            .find(|l| l.starts_with(&format!("| {} |", rule.name)))
            .unwrap();
        let cells: Vec<&str> = row.split('|').map(str::trim).collect();
        assert_eq!(cells[2].parse::<f64>().unwrap(), rule.parameter, "{row}");
        let used: f64 = cells[4].trim_end_matches('%').parse().unwrap();
        assert!(used < 100.0, "the written rule stops early: {row}");
        assert_eq!(cells[8], "passed", "{row}");
    } else {
        assert!(
            stderr.contains("transfer check failed") || stderr.contains("no rule could be"),
            "{stderr}"
        );
        assert!(!Path::new(out).exists());
    }
}

#[test]
fn out_refuses_a_rule_that_does_not_transfer_unless_forced() {
    // The map is the corridor; the "real" queries are another place.
    let case = Case::new("gardens-point", 40);
    let out = case.out();
    let args = [
        // on this map of small corridor images stable-peak's pseudo-queries
        // are far from the other place's queries (measured: 0.263 real
        // disagreement at a 0.05 target)
        "--rules",
        "stable-peak",
        "--dataset",
        case.data.to_str().unwrap(),
        "--out",
        &out,
    ];
    let o = case.calibrate(&args);
    let stdout = String::from_utf8_lossy(&o.stdout);
    let stderr = String::from_utf8_lossy(&o.stderr);
    println!("{stdout}");
    assert!(!o.status.success(), "{stdout}");
    assert!(
        stderr.contains("transfer check failed") && stderr.contains("--force"),
        "{stderr}"
    );
    assert!(stdout.contains("missed the target"), "{stdout}");
    assert!(!Path::new(&out).exists());

    let o = case.calibrate(&[&args[..], &["--force"]].concat());
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(bowloc::server::config::Config::load(Path::new(&out)).is_ok());
}
