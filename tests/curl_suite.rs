//! Runs the curl suite (`tests/curl/run.sh`) against the binary cargo built,
//! so that `cargo test` exercises the real server over HTTP.

use std::path::Path;
use std::process::Command;

#[test]
fn curl_suite() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let datasets = root.join("../shared/datasets");
    let output = Command::new("bash")
        .arg(root.join("tests/curl/run.sh"))
        .arg(env!("CARGO_BIN_EXE_bowloc"))
        .arg(&datasets)
        .env_remove("RUST_LOG")
        .output()
        .expect("bash runs");
    let stdout = String::from_utf8_lossy(&output.stdout);
    let stderr = String::from_utf8_lossy(&output.stderr);
    println!("{stdout}");
    eprintln!("{stderr}");
    let last = stdout.lines().last().unwrap_or("");
    assert!(
        output.status.success() && last.ends_with(" 0 failed"),
        "curl suite failed: {last}"
    );
}
