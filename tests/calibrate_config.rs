//! End to end: `bowloc calibrate --out FILE` on a map of the real
//! rtabmap-loop images writes a configuration that `bowloc serve --config
//! FILE` loads as is, serving that map with the calibrated rule.

mod common;

use bowloc::server::config::Config;
use std::process::Command;

/// Run bowloc with `args`; its stdout.
fn bowloc(args: &[&std::ffi::OsStr]) -> String {
    let output = Command::new(env!("CARGO_BIN_EXE_bowloc"))
        .args(args)
        .output()
        .expect("bowloc runs");
    assert!(
        output.status.success(),
        "bowloc {args:?} failed:\n{}",
        String::from_utf8_lossy(&output.stderr)
    );
    String::from_utf8(output.stdout).unwrap()
}

#[test]
fn calibrate_out_is_a_configuration_the_server_loads() {
    let dir = tempfile::tempdir().unwrap();
    let (vocab, map, out) = (
        dir.path().join("vocab.bowvoc"),
        dir.path().join("map.bowmap"),
        dir.path().join("calibrated.toml"),
    );
    let images = common::dataset("rtabmap-loop").join("map.txt");
    let os = |s: &'static str| std::ffi::OsStr::new(s);
    bowloc(&[
        os("vocab"),
        os("build"),
        os("--images"),
        images.as_os_str(),
        os("--words"),
        os("200"),
        os("--out"),
        vocab.as_os_str(),
    ]);
    bowloc(&[
        os("map"),
        os("build"),
        os("--vocab"),
        vocab.as_os_str(),
        os("--images"),
        images.as_os_str(),
        os("--out"),
        map.as_os_str(),
    ]);
    let table = bowloc(&[
        os("calibrate"),
        os("--vocab"),
        vocab.as_os_str(),
        os("--map"),
        map.as_os_str(),
        os("--max-disagreement"),
        os("0.05"),
        os("--runs"),
        os("2"),
        os("--out"),
        out.as_os_str(),
    ]);

    let config = Config::load(&out).expect("the written file is a valid configuration");
    assert_eq!(config.files.vocabulary, vocab.canonicalize().unwrap());
    assert_eq!(config.files.map, map.canonicalize().unwrap());
    let rule = config.default_rule().unwrap();
    // The warm-up written is the one printed (adapted to the pseudo-queries:
    // at most 100, at most a quarter of their median feature count).
    let warmup: usize = table
        .split("warm-up ")
        .nth(1)
        .and_then(|t| t.split(|c: char| !c.is_ascii_digit()).next())
        .and_then(|n| n.parse().ok())
        .expect("the warm-up is printed");
    assert_eq!(config.search.min_features, warmup);
    assert!((1..=100).contains(&warmup), "{table}");
    // Calibrated rows: rule, parameter (3 significant digits), disagreement,
    // features used.
    let cells =
        |line: &str| -> Vec<String> { line.split('|').map(|c| c.trim().to_owned()).collect() };
    let rows: Vec<Vec<String>> = table
        .lines()
        .filter(|l| l.starts_with("| ") && l.ends_with('|') && !l.contains("---"))
        .skip(1)
        .map(cells)
        .filter(|c| !c[2].starts_with("not calibrated"))
        .collect();
    assert!(!rows.is_empty(), "{table}");
    let used = |c: &Vec<String>| -> f64 { c[4].trim_end_matches('%').parse().unwrap() };
    // The rule written is one the table printed, with the same parameter,
    // and the one using the fewest pseudo-query features.
    let written = rows
        .iter()
        .find(|c| c[1] == rule.name)
        .unwrap_or_else(|| panic!("{} not in\n{table}", rule.name));
    assert_eq!(
        written[2].parse::<f64>().unwrap(),
        rule.parameter,
        "{table}"
    );
    let fewest = rows.iter().map(used).fold(f64::INFINITY, f64::min);
    assert_eq!(used(written), fewest, "{table}");
}
