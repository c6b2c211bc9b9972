//! The docs show the rule table the registry generates (`bowloc rules`),
//! the image formats the decoder accepts and the verification floor of each
//! model, not copies that can drift.

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
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let floors = bowloc::geometry::verify::Model::default_floors();
    for doc in ["config/default.toml", "README.md", "docs/service.md"] {
        // the config's comment wraps lines: compare with its words joined
        let text = std::fs::read_to_string(root.join(doc)).unwrap();
        let words: Vec<&str> = text.split_whitespace().filter(|w| *w != "#").collect();
        assert!(
            words.join(" ").contains(&floors),
            "{doc} does not give the floors `{floors}`"
        );
    }
}
