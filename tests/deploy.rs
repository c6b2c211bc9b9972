//! The Kubernetes manifests (deploy/kubernetes): every tree renders and
//! validates against the pinned Kubernetes version's schema with the checks
//! of scripts/k8s_render.py, and the configuration each one mounts is one
//! the service itself accepts, reading its map and vocabulary from the
//! read-only maps volume and never bootstrapping.

use bowloc::server::config::Config;
use std::path::Path;
use std::process::Command;

#[test]
fn manifests_validate_and_their_configuration_loads() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let out = tempfile::tempdir().unwrap();
    let run = Command::new("bash")
        .arg(root.join("scripts/k8s-validate.sh"))
        .arg(out.path())
        .output()
        .expect("bash runs");
    let stdout = String::from_utf8_lossy(&run.stdout);
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(
        run.status.success(),
        "scripts/k8s-validate.sh failed:\n{stdout}\n{stderr}"
    );
    println!("{stdout}");
    let mut configs = 0;
    for entry in std::fs::read_dir(out.path()).unwrap() {
        let path = entry.unwrap().path();
        let config = Config::load(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        assert!(config.files.map.starts_with("/maps"), "{}", path.display());
        assert!(
            config.files.vocabulary.starts_with("/maps"),
            "{}",
            path.display()
        );
        assert!(!config.bootstrap.enabled, "{}", path.display());
        configs += 1;
    }
    // the base and its three overlays
    assert_eq!(configs, 4, "{stdout}");
}
