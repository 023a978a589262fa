//! `docs/FEATURES.md` lists every behaviour with the test that proves it: every test it names
//! must exist, so a renamed or deleted test cannot leave a row claiming a proof.
#![allow(clippy::unwrap_used)]

use std::path::{Path, PathBuf};

fn sources(dir: &Path, out: &mut Vec<PathBuf>) {
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        let name = path.file_name().unwrap().to_string_lossy().into_owned();
        if path.is_dir() {
            if name != "target" && !name.starts_with('.') {
                sources(&path, out);
            }
        } else if name.ends_with(".rs") || name.ends_with(".py") {
            out.push(path);
        }
    }
}

#[test]
fn every_test_named_in_features_md_exists() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let features = std::fs::read_to_string(root.join("docs/FEATURES.md")).unwrap();
    let mut files = Vec::new();
    sources(&root.join("crates"), &mut files);
    // The interop suite and the Python package's tests (`def test_…`) name tests too.
    for dir in ["tests", "python"] {
        if root.join(dir).is_dir() {
            sources(&root.join(dir), &mut files);
        }
    }
    let mut functions = Vec::new();
    for f in &files {
        let text = std::fs::read_to_string(f).unwrap();
        for line in text.lines() {
            let t = line.trim_start();
            let rest = t
                .strip_prefix("fn ")
                .or_else(|| t.strip_prefix("pub fn "))
                .or_else(|| t.strip_prefix("async fn "))
                .or_else(|| t.strip_prefix("def "));
            if let Some(rest) = rest {
                let name: String = rest
                    .chars()
                    .take_while(|c| c.is_alphanumeric() || *c == '_')
                    .collect();
                functions.push(name);
            }
        }
    }
    let mut missing = Vec::new();
    let mut named = 0;
    for (i, chunk) in features.split('`').enumerate() {
        if i % 2 == 0 {
            continue;
        }
        // Only table cells naming tests: snake_case identifiers with several words, optionally
        // abbreviated with a leading "…_" (a suffix of the test name) or a trailing "_*".
        let (token, suffix, prefix) = if let Some(s) = chunk.strip_prefix('…') {
            (s, true, false)
        } else if let Some(p) = chunk.strip_suffix("_*") {
            (p, false, true)
        } else {
            (chunk, false, false)
        };
        let token = token.rsplit("::").next().unwrap_or(token);
        let is_ident = token.len() > 12
            && token.matches('_').count() >= 2
            && token
                .chars()
                .all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '_');
        if !is_ident {
            continue;
        }
        named += 1;
        let found = functions.iter().any(|f| {
            if suffix {
                f.ends_with(token)
            } else if prefix {
                f.starts_with(token)
            } else {
                f == token
            }
        });
        if !found {
            missing.push(chunk.to_string());
        }
    }
    assert!(named > 100, "FEATURES.md names only {named} tests");
    assert!(
        missing.is_empty(),
        "FEATURES.md names tests that do not exist: {missing:#?}"
    );
}
