//! The files a user or a citation manager looks for at the repository's root: both licences
//! Cargo.toml names, a CITATION.cff of this version, and a changelog.

use std::path::Path;

fn root(name: &str) -> String {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join(name);
    std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

fn version() -> String {
    let cargo = root("Cargo.toml");
    let line = cargo
        .lines()
        .find(|l| l.starts_with("version"))
        .expect("version in Cargo.toml");
    line.split('"').nth(1).expect("quoted version").to_string()
}

#[test]
fn the_licences_cargo_names_are_in_the_repository() {
    let cargo = root("Cargo.toml");
    assert!(cargo.contains("license = \"MIT OR Apache-2.0\""));
    // The description named two of the 16 factors only ("lens occlusion, rain").
    let description = cargo
        .lines()
        .find(|l| l.starts_with("description"))
        .expect("description");
    assert!(description.contains("weather") && description.contains("16 factors"));
    assert!(root("LICENSE-MIT").contains("Permission is hereby granted, free of charge"));
    let apache = root("LICENSE-APACHE");
    assert!(apache.contains("Apache License") && apache.contains("Version 2.0, January 2004"));
    assert!(apache.contains("END OF TERMS AND CONDITIONS"));
}

#[test]
fn citation_file_is_valid_cff_of_this_version() {
    let cff: serde_norway::Value = serde_norway::from_str(&root("CITATION.cff")).expect("YAML");
    assert_eq!(cff["cff-version"].as_str(), Some("1.2.0"));
    assert_eq!(cff["type"].as_str(), Some("software"));
    assert_eq!(cff["version"].as_str(), Some(version().as_str()));
    assert_eq!(cff["license"].as_str(), Some("MIT OR Apache-2.0"));
    assert!(cff["title"]
        .as_str()
        .is_some_and(|t| t.starts_with("lidar-noise")));
    let authors = cff["authors"].as_sequence().expect("authors");
    assert!(!authors.is_empty());
    for r in cff["references"].as_sequence().expect("references") {
        assert!(r["title"].as_str().is_some() && r["authors"].as_sequence().is_some());
    }
}

#[test]
fn changelog_has_a_section_for_this_version() {
    let log = root("CHANGELOG.md");
    assert!(log.starts_with("# Changelog"));
    assert!(
        log.contains(&format!("## [Unreleased] ({}", version()))
            || log.contains(&format!("## [{}]", version()))
    );
}
