//! References into the docs resolve. Code, scripts and docs point readers at a section as
//! `docs/NAME.md, "Section"` (or `docs/NAME.md "Section"`, `docs/NAME.md ("Section"`). Sections
//! move between files (issue 18's rounds left docs/udlod.md for docs/udlod-rounds.md), so every
//! such reference must name a file that exists and a heading or bold item in it that starts
//! with the quoted text.

use std::fs;
use std::path::{Path, PathBuf};

/// Folders whose text files may point into the docs, relative to the repository root.
const SCANNED_DIRS: [&str; 10] = [
    "src",
    "tests",
    "shaders",
    "scripts",
    "docs",
    "config",
    "examples",
    "benches",
    "consumers",
    "build",
];
/// Single files that may point into the docs.
const SCANNED_FILES: [&str; 5] = ["README.md", "Makefile", "build.rs", "Cargo.toml", ".ci/run"];
/// Extensions of the text files scanned in [`SCANNED_DIRS`].
const TEXT_EXTENSIONS: [&str; 10] = [
    "rs", "md", "wgsl", "glsl", "sh", "py", "toml", "c", "h", "txt",
];

/// One `docs/NAME.md, "Section"` reference: where it is, the doc and the quoted section.
#[derive(Debug, PartialEq)]
struct DocRef {
    line: usize,
    doc: String,
    section: String,
}

/// Every reference in `text`. After `docs/NAME.md` (or `` `docs/NAME.md` ``) come at most
/// one of `,` or `:`, one whitespace character (a line break included) and one `(`, then the
/// quoted section: 3 to 120 characters, which may run on over a line break in a comment (the
/// next line's comment marker and indentation read as one space).
fn references(text: &str) -> Vec<DocRef> {
    let bytes = text.as_bytes();
    let mut found = Vec::new();
    let mut from = 0;
    while let Some(at) = text[from..].find("docs/") {
        let start = from + at;
        from = start + 5;
        let name_len = bytes[from..]
            .iter()
            .take_while(|b| {
                b.is_ascii_lowercase() || b.is_ascii_digit() || **b == b'-' || **b == b'_'
            })
            .count();
        let mut i = from + name_len;
        if name_len == 0 || !text[i..].starts_with(".md") {
            continue;
        }
        i += 3;
        let doc = text[start..i].to_string();
        for optional in [&b"`"[..], b",:", b" \n", b"("] {
            if i < bytes.len() && optional.contains(&bytes[i]) {
                i += 1;
            }
        }
        if i >= bytes.len() || bytes[i] != b'"' {
            continue;
        }
        let Some(len) = text[i + 1..].find('"') else {
            continue;
        };
        if let Some(section) = section_text(&text[i + 1..i + 1 + len]) {
            let line = 1 + text[..start].matches('\n').count();
            found.push(DocRef { line, doc, section });
        }
    }
    found
}

/// A quoted section as a reference names it: its lines joined by one space, each line after
/// the first without its indentation and comment marker (`//!`, `///`, `//`, `#`); `None`
/// where it is not 3 to 120 characters.
fn section_text(quoted: &str) -> Option<String> {
    let mut lines = quoted.lines();
    let mut section = lines.next()?.trim_end().to_string();
    for line in lines {
        let line = line.trim_start();
        let line = ["//!", "///", "//", "#"]
            .iter()
            .find_map(|marker| line.strip_prefix(marker))
            .unwrap_or(line);
        section.push(' ');
        section.push_str(line.trim());
    }
    (3..=120)
        .contains(&section.chars().count())
        .then_some(section)
}

/// What a reference may name in a doc: its headings (without the `#`s) and its bold or
/// emphasised items (`**Item**`, `*Item*`, without a trailing `:` or `.`).
fn anchors(doc: &str) -> Vec<String> {
    let mut names: Vec<String> = doc
        .lines()
        .filter(|l| l.starts_with('#'))
        .map(|l| l.trim_start_matches('#').trim().to_string())
        .collect();
    for marker in ["**", "*"] {
        for (k, piece) in doc.split(marker).enumerate() {
            if k % 2 == 1 && !piece.contains('\n') && !piece.is_empty() {
                names.push(piece.trim().trim_end_matches([':', '.']).to_string());
            }
        }
    }
    names
}

/// Whether `section` names one of `anchors`: a heading or item that starts with it (a
/// reference may leave out a heading's parenthesis or the part after its colon).
fn resolves(section: &str, anchors: &[String]) -> bool {
    let section = section.trim_end_matches('.');
    anchors.iter().any(|a| a.starts_with(section))
}

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn text_files(dir: &Path, out: &mut Vec<PathBuf>) {
    let Ok(entries) = fs::read_dir(dir) else {
        return;
    };
    for entry in entries.flatten() {
        let path = entry.path();
        if path.is_dir() {
            text_files(&path, out);
        } else if path
            .extension()
            .and_then(|e| e.to_str())
            .is_some_and(|e| TEXT_EXTENSIONS.contains(&e))
        {
            out.push(path);
        }
    }
}

fn scanned_files() -> Vec<PathBuf> {
    let root = repo();
    let mut files: Vec<PathBuf> = SCANNED_FILES.iter().map(|f| root.join(f)).collect();
    for dir in SCANNED_DIRS {
        text_files(&root.join(dir), &mut files);
    }
    files.retain(|f| f.is_file());
    files
}

#[test]
fn every_reference_into_the_docs_names_a_section_that_exists() {
    let root = repo();
    let mut count = 0;
    let mut unresolved = Vec::new();
    for file in scanned_files() {
        let Ok(text) = fs::read_to_string(&file) else {
            continue;
        };
        for r in references(&text) {
            count += 1;
            let shown = file.strip_prefix(&root).unwrap_or(&file).display();
            match fs::read_to_string(root.join(&r.doc)) {
                Ok(doc) if resolves(&r.section, &anchors(&doc)) => {}
                Ok(_) => unresolved.push(format!(
                    "{shown}:{}: {} has no \"{}\"",
                    r.line, r.doc, r.section
                )),
                Err(_) => unresolved.push(format!("{shown}:{}: {} does not exist", r.line, r.doc)),
            }
        }
    }
    // The scan must see the references the repository has (185 when this test was written),
    // or an empty scan would pass.
    assert!(
        count >= 100,
        "only {count} references into docs/ found: is the scan broken?"
    );
    assert!(
        unresolved.is_empty(),
        "{} of {count} references do not resolve:\n{}",
        unresolved.len(),
        unresolved.join("\n")
    );
}

/// Negative controls: the parser finds the forms the repository uses, and a section that is
/// not in the doc (or a heading it only ends with) does not resolve.
#[test]
fn references_parse_and_a_missing_section_does_not_resolve() {
    let text = "a (docs/udlod.md, \"The seed\") b\n// docs/eval.md\n\"On the earth\" c\n\
                docs/x.md (\"Quoted (first)\" docs/no.md, no quote; docs/.md, \"x\"\n\
                /// (`docs/y.md`, \"Over a\n    /// line\") docs/z.md, \"ab\"";
    let found = references(text);
    let sections: Vec<(&str, &str)> = found
        .iter()
        .map(|r| (r.doc.as_str(), r.section.as_str()))
        .collect();
    assert_eq!(
        sections,
        [
            ("docs/udlod.md", "The seed"),
            ("docs/eval.md", "On the earth"),
            ("docs/x.md", "Quoted (first)"),
            ("docs/y.md", "Over a line"),
        ]
    );
    assert_eq!(found[1].line, 2);

    let doc = "# Title\n## The seed: coarse levels (round 13)\n- **Capacity** (what ...)\n";
    let names = anchors(doc);
    assert!(resolves("The seed", &names));
    assert!(resolves("The seed: coarse levels", &names));
    assert!(resolves("Capacity", &names));
    assert!(
        !resolves("The zone's start", &names),
        "a section the doc lacks resolved"
    );
    assert!(
        !resolves("coarse levels (round 13)", &names),
        "a heading's tail resolved"
    );
    assert!(
        !resolves("Capacity of the lists", &names),
        "more than the item resolved"
    );
}
