//! End to end: `bowloc shards` on the real rtabmap-loop dataset (a small
//! vocabulary, one random order): every vote-only rule answers on 2 and 8
//! shards exactly as on one machine, and the messages are printed.

mod common;

use std::process::Command;

use bowloc::search::SearchOptions;

#[test]
fn sharded_search_answers_as_one_machine_on_real_images() {
    let dir = tempfile::tempdir().unwrap();
    let output = Command::new(env!("CARGO_BIN_EXE_bowloc"))
        .arg("shards")
        .arg("--dataset")
        .arg(common::dataset("rtabmap-loop"))
        .arg("--cache")
        .arg(dir.path())
        .args(["--words", "200", "--vocab-seeds", "1", "--runs", "1"])
        .args(["--shards", "2,8", "--log", "warn"])
        .output()
        .expect("bowloc runs");
    let stdout = String::from_utf8_lossy(&output.stdout);
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(
        output.status.success(),
        "bowloc shards failed:\n{stdout}\n{stderr}"
    );
    // 44 queries × every setting in the table × 2 shard counts
    let settings = stdout
        .lines()
        .filter(|l| l.starts_with('|') && l.split('|').nth(2).map(str::trim) == Some("2"))
        .count();
    assert!(settings >= 9, "{stdout}");
    let searches = 44 * settings * 2;
    assert!(
        stdout.contains(&format!(
            "rtabmap-loop: 0 of {searches} sharded searches differ"
        )),
        "{stdout}"
    );
    // the default rule among them
    let default = format!(
        "| {} {} w={} | 8 |",
        SearchOptions::RECOMMENDED_RULE,
        SearchOptions::RECOMMENDED_PARAMETER,
        SearchOptions::RECOMMENDED_WARMUP
    );
    for setting in ["| none | 2 |", "| lossless | 8 |", default.as_str()] {
        assert!(stdout.contains(setting), "{setting} missing:\n{stdout}");
    }
}
