//! The docs show the rule table the registry generates (`bowloc rules`),
//! the image formats the decoder accepts, the verification floor of each
//! model and the ORB pass's defaults, not copies that can drift.

use bowloc::search::stop::rules_markdown;

#[test]
fn readme_and_service_docs_show_the_registry_rule_table() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let table = rules_markdown();
    for doc in ["README.md", "docs/service.md"] {
        let text = std::fs::read_to_string(root.join(doc)).unwrap();
        assert!(
            text.contains(&table),
            "{doc} does not hold the output of `bowloc rules`:\n{table}"
        );
    }
}

#[test]
fn service_docs_name_the_formats_the_service_decodes() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let text = std::fs::read_to_string(root.join("docs/service.md")).unwrap();
    let formats = bowloc::features::SUPPORTED_FORMATS;
    assert!(
        text.contains(&format!("**formats**: {formats} (")),
        "docs/service.md's formats do not read `{formats}`"
    );
}

#[test]
fn the_config_readme_and_service_docs_give_each_models_verification_floor() {
    let floors = bowloc::geometry::verify::Model::default_floors();
    for doc in ["config/default.toml", "README.md", "docs/service.md"] {
        assert!(
            words_of(doc).contains(&floors),
            "{doc} does not give the floors `{floors}`"
        );
    }
}

/// `doc`'s text with its words joined by single spaces (lines wrap; a
/// TOML file's comment marks dropped).
fn words_of(doc: &str) -> String {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let text = std::fs::read_to_string(root.join(doc)).unwrap();
    let words: Vec<&str> = text.split_whitespace().filter(|w| *w != "#").collect();
    words.join(" ")
}

#[test]
fn the_orb_pass_defaults_in_the_docs_are_the_codes() {
    use bowloc::orb_pass::OrbPassParams;
    let d = OrbPassParams::default();
    let stated = [
        (
            "docs/service.md",
            vec![
                format!("ORB's {} strongest corners", d.keypoints),
                format!("({} by default, k-majority", d.words),
                format!("`orb_pass.top` ({})", d.top),
                format!("`orb_pass.floor` ({}) inliers", d.floor),
                format!("`orb_pass.window`, {})", d.window),
                format!("`orb_pass.share` ({})", d.share),
            ],
        ),
        (
            "README.md",
            vec![
                format!("the {} best-voted images", d.top),
                format!("at least {} inliers", d.floor),
            ],
        ),
        (
            "config/default.toml",
            vec![format!("ORB ({} corners)", d.keypoints)],
        ),
    ];
    for (doc, phrases) in stated {
        let text = words_of(doc);
        for phrase in phrases {
            assert!(text.contains(&phrase), "{doc} does not say `{phrase}`");
        }
    }
}
