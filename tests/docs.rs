//! The docs show the rule table the registry generates (`bowloc rules`) and
//! the image formats the decoder accepts, not copies that can drift.

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
