//! A `map build` killed while it writes leaves the previous map intact: files
//! are written to a temporary file and renamed into place. The test slows the
//! writer down (`BOWLOC_WRITE_DELAY_MS` pauses after each section), kills it
//! once the temporary file exists, and checks the old map still opens with
//! every checksum verified; then lets a run finish and checks the new map.

mod common;

use bowloc::index::MapIndex;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

fn bowloc() -> Command {
    Command::new(env!("CARGO_BIN_EXE_bowloc"))
}

fn temp_files(dir: &Path) -> Vec<PathBuf> {
    std::fs::read_dir(dir)
        .unwrap()
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.to_string_lossy().ends_with(".tmp"))
        .collect()
}

#[test]
fn killed_map_build_leaves_previous_map_intact() {
    let rtab = common::dataset("rtabmap-loop");
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let s = |p: &Path| p.to_string_lossy().into_owned();
    let (vocab, map) = (d.join("v.bowvoc"), d.join("m.bowmap"));
    let list = d.join("few.txt");
    let few: Vec<String> = (1..=5)
        .map(|i| s(&rtab.join(format!("images/{i}.jpg"))))
        .collect();
    std::fs::write(&list, few.join("\n")).unwrap();
    let ok = |c: &mut Command| assert!(c.status().unwrap().success());
    ok(bowloc().args([
        "vocab",
        "build",
        "--images",
        &s(&list),
        "--words",
        "50",
        "--out",
        &s(&vocab),
    ]));
    // the previous map: 5 images
    ok(bowloc().args([
        "map",
        "build",
        "--vocab",
        &s(&vocab),
        "--images",
        &s(&list),
        "--out",
        &s(&map),
    ]));
    let before = std::fs::read(&map).unwrap();

    // a new map over all 40 images, killed mid-write, three times
    let all = s(&rtab.join("map.txt"));
    for _ in 0..3 {
        let mut child = bowloc()
            .args([
                "map",
                "build",
                "--vocab",
                &s(&vocab),
                "--images",
                &all,
                "--out",
                &s(&map),
            ])
            .env("BOWLOC_WRITE_DELAY_MS", "300")
            .spawn()
            .unwrap();
        let started = Instant::now();
        while temp_files(d).is_empty() {
            assert!(
                started.elapsed() < Duration::from_secs(60),
                "writer never started writing"
            );
            std::thread::sleep(Duration::from_millis(5));
        }
        std::thread::sleep(Duration::from_millis(400));
        child.kill().unwrap();
        child.wait().unwrap();
        assert_eq!(std::fs::read(&map).unwrap(), before, "previous map changed");
        let old = MapIndex::open(&map, true).expect("previous map opens and verifies");
        assert_eq!(old.images(), 5);
        for t in temp_files(d) {
            std::fs::remove_file(t).unwrap();
        }
    }

    // uninterrupted, the new map replaces the old one
    ok(bowloc().args([
        "map",
        "build",
        "--vocab",
        &s(&vocab),
        "--images",
        &all,
        "--out",
        &s(&map),
    ]));
    assert_eq!(MapIndex::open(&map, true).unwrap().images(), 40);
    assert!(temp_files(d).is_empty());
}
