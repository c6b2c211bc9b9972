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
    assert_eq!(config.search.min_features, 100);
    // The rule written is one the table printed, with the same parameter.
    let row = format!(
        "| {} | {} |",
        rule.name,
        config
            .search
            .threshold
            .expect("a calibrated rule has a parameter")
    );
    assert!(table.contains(&row), "{row} not in\n{table}");
    // It is the printed rule using the fewest pseudo-query features.
    let used = |line: &str| -> f64 {
        let cells: Vec<&str> = line.split('|').map(str::trim).collect();
        cells[4].trim_end_matches('%').parse().unwrap()
    };
    let rows: Vec<&str> = table
        .lines()
        .filter(|l| l.starts_with("| ") && l.ends_with('|') && !l.contains("---"))
        .skip(1)
        .collect();
    assert!(!rows.is_empty(), "{table}");
    let fewest = rows.iter().map(|l| used(l)).fold(f64::INFINITY, f64::min);
    let written = rows.iter().find(|l| l.starts_with(&row)).unwrap();
    assert_eq!(used(written), fewest, "{table}");
}
