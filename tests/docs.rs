//! The docs and the code point at each other, and both kinds of pointer must resolve.
//! - Code, scripts and docs point readers at a section as `docs/NAME.md, "Section"` (or
//!   `docs/NAME.md "Section"`, `docs/NAME.md ("Section"`). Sections move between files (issue
//!   18's rounds left docs/udlod.md for docs/udlod-rounds.md), so every such reference must
//!   name a file that exists and a heading or bold item in it that starts with the quoted text.
//! - The docs name code as `module::item` or `Type::member` in backticks. Code moves between
//!   modules (`udlod::select` became four), so every such path into this crate must name an
//!   item defined where the path says.

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

/// Docs whose code paths are checked: every doc but the rounds' lab notes, which name code as
/// it was in each round (functions since renamed or removed included).
fn docs_naming_current_code() -> Vec<PathBuf> {
    let root = repo();
    let mut docs = vec![root.join("README.md")];
    if let Ok(entries) = fs::read_dir(root.join("docs")) {
        for entry in entries.flatten() {
            let path = entry.path();
            let name = path.file_name().and_then(|n| n.to_str()).unwrap_or("");
            if name.ends_with(".md") && name != "udlod-rounds.md" {
                docs.push(path);
            }
        }
    }
    docs
}

/// The Rust sources of the crate, its tests, examples, benchmarks and build script, with
/// their module names (a file's stem, or its folder's name for `mod.rs`).
fn rust_sources() -> Vec<(String, PathBuf, String)> {
    let root = repo();
    let mut files = vec![root.join("build.rs")];
    for dir in ["src", "tests", "examples", "benches", "build"] {
        text_files(&root.join(dir), &mut files);
    }
    files
        .into_iter()
        .filter(|f| f.extension().is_some_and(|e| e == "rs"))
        .filter_map(|f| {
            let text = fs::read_to_string(&f).ok()?;
            let stem = f.file_stem()?.to_str()?;
            let module = if stem == "mod" {
                f.parent()?.file_name()?.to_str()?
            } else {
                stem
            };
            Some((module.to_string(), f, text))
        })
        .collect()
}

/// Crates a path in the docs may start with that are not this one: the manifest's
/// dependencies, the standard library, and LLVM's C++ namespace (named in a profile).
fn foreign_roots() -> Vec<String> {
    let manifest = fs::read_to_string(repo().join("Cargo.toml")).unwrap_or_default();
    let mut roots: Vec<String> = ["std", "core", "alloc", "llvm"].map(String::from).to_vec();
    let mut in_dependencies = false;
    for line in manifest.lines() {
        let line = line.trim();
        if line.starts_with('[') {
            in_dependencies = line.ends_with("dependencies]");
        } else if in_dependencies && let Some((name, _)) = line.split_once('=') {
            roots.push(name.trim().replace('-', "_"));
        }
    }
    roots
}

/// The `a::b::c` paths in backticks of a doc (an optional `()` after the last segment).
fn code_paths(doc: &str) -> Vec<Vec<String>> {
    let ident = |s: &str| {
        !s.is_empty()
            && !s.starts_with(|c: char| c.is_ascii_digit())
            && s.chars().all(|c| c.is_ascii_alphanumeric() || c == '_')
    };
    doc.split('`')
        .skip(1)
        .step_by(2)
        .map(|span| span.strip_suffix("()").unwrap_or(span))
        .map(|span| span.split("::").map(String::from).collect::<Vec<_>>())
        .filter(|segments| segments.len() >= 2 && segments.iter().all(|s| ident(s)))
        .collect()
}

/// Whether `text` defines `name`: an item (`fn`, `struct`, `enum`, `const`, `static`, `type`,
/// `trait`, `mod`, `macro_rules!`) or, on a line of its own, a field or enum variant.
fn defines(text: &str, name: &str) -> bool {
    let ident_char = |c: char| c.is_ascii_alphanumeric() || c == '_';
    let item = [
        "fn",
        "struct",
        "enum",
        "const",
        "static",
        "type",
        "trait",
        "mod",
        "macro_rules!",
    ]
    .iter()
    .any(|keyword| {
        let needle = format!("{keyword} {name}");
        text.match_indices(&needle).any(|(at, _)| {
            let before = text[..at].chars().next_back();
            let after = text[at + needle.len()..].chars().next();
            !before.is_some_and(ident_char) && !after.is_some_and(ident_char)
        })
    });
    item || text.lines().any(|line| {
        let line = line.trim_start();
        let line = ["pub(crate) ", "pub(super) ", "pub "]
            .iter()
            .find_map(|p| line.strip_prefix(p))
            .unwrap_or(line);
        line.strip_prefix(name)
            .map(|rest| rest.trim_start())
            .is_some_and(|rest| {
                rest.starts_with([',', '(', '{', '=', ':']) && !rest.starts_with("::")
            })
    })
}

/// Why `path` does not name an item of this crate where it says, or `None` where it does
/// (or where it is another crate's).
/// - `[module::]Type::member` (`Type` the last capitalised segment before the last): a file
///   that defines or implements `Type` defines `member`, and with modules named, one of them
///   defines `Type`; a type the code only imports is another crate's.
/// - `module::item`: a file of one of the modules named (or one with an inline `mod` of that
///   name) defines `item`.
fn unresolved_path(
    path: &[String],
    sources: &[(String, PathBuf, String)],
    foreign: &[String],
) -> Option<String> {
    let (last, before) = path.split_last()?;
    if foreign.contains(&path[0]) {
        return None;
    }
    let in_modules = |modules: &[String], (module, file, text): &(String, PathBuf, String)| {
        modules.iter().any(|m| {
            m == module
                || file.components().any(|c| c.as_os_str() == m.as_str())
                || text.contains(&format!("mod {m} "))
        })
    };
    let Some(at) = before
        .iter()
        .rposition(|s| s.starts_with(|c: char| c.is_ascii_uppercase()))
    else {
        let found = sources
            .iter()
            .any(|s| in_modules(before, s) && defines(&s.2, last));
        return (!found).then(|| format!("no {last} in {}", before.join("::")));
    };
    let (modules, ty) = (&before[..at], &before[at]);
    let defining = |text: &str| {
        ["struct", "enum", "trait", "type"]
            .iter()
            .any(|k| defines_keyword(text, k, ty))
    };
    let holders: Vec<&(String, PathBuf, String)> = sources
        .iter()
        .filter(|(_, _, text)| {
            defining(text)
                || text.contains(&format!("impl {ty}"))
                || text.contains(&format!(" for {ty} "))
        })
        .collect();
    if holders.is_empty() {
        let mentioned = sources.iter().any(|(_, _, text)| contains_word(text, ty));
        return (!mentioned).then(|| format!("no type {ty} in the code"));
    }
    if !modules.is_empty()
        && !sources
            .iter()
            .any(|s| in_modules(modules, s) && defining(&s.2))
    {
        return Some(format!("no type {ty} in {}", modules.join("::")));
    }
    (!holders.iter().any(|(_, _, text)| defines(text, last))).then(|| format!("{ty} has no {last}"))
}

fn defines_keyword(text: &str, keyword: &str, name: &str) -> bool {
    text.contains(&format!("{keyword} {name} "))
        || text.contains(&format!("{keyword} {name}<"))
        || text.contains(&format!("{keyword} {name}("))
        || text.contains(&format!("{keyword} {name};"))
        || text.contains(&format!("{keyword} {name}:"))
}

fn contains_word(text: &str, word: &str) -> bool {
    let ident_char = |c: char| c.is_ascii_alphanumeric() || c == '_';
    text.match_indices(word).any(|(at, _)| {
        !text[..at].chars().next_back().is_some_and(ident_char)
            && !text[at + word.len()..]
                .chars()
                .next()
                .is_some_and(ident_char)
    })
}

#[test]
fn every_code_path_the_docs_name_exists() {
    let root = repo();
    let sources = rust_sources();
    let foreign = foreign_roots();
    assert!(
        foreign.iter().any(|c| c == "ash"),
        "the manifest's dependencies were not read"
    );
    let (mut count, mut unresolved) = (0, Vec::new());
    for doc in docs_naming_current_code() {
        let Ok(text) = fs::read_to_string(&doc) else {
            continue;
        };
        for path in code_paths(&text) {
            count += 1;
            if let Some(why) = unresolved_path(&path, &sources, &foreign) {
                let shown = doc.strip_prefix(&root).unwrap_or(&doc).display();
                unresolved.push(format!("{shown}: `{}`: {why}", path.join("::")));
            }
        }
    }
    // 204 paths when this test was written; an empty scan must not pass.
    assert!(
        count >= 150,
        "only {count} code paths found in the docs: is the scan broken?"
    );
    assert!(
        unresolved.is_empty(),
        "{} of {count} code paths in the docs do not resolve:\n{}",
        unresolved.len(),
        unresolved.join("\n")
    );
}

/// Negative controls: a moved item, a missing member and a missing type are reported; a
/// foreign crate's path and a type the code only imports are not this crate's to check.
#[test]
fn code_paths_parse_and_a_moved_item_does_not_resolve() {
    let doc = "`select::select_tiles` and `Levels::new()`, `std::fs::read`, not `a b::c` or `x`";
    assert_eq!(
        code_paths(doc),
        [
            vec!["select", "select_tiles"],
            vec!["Levels", "new"],
            vec!["std", "fs", "read"]
        ]
    );
    let sources = vec![
        ("select".to_string(), PathBuf::from("src/lod/udlod/select.rs"), "pub fn select_tiles() {}\n".to_string()),
        (
            "levels".to_string(),
            PathBuf::from("src/lod/udlod/levels.rs"),
            "pub struct Levels {\n    pub root_lod: u32,\n}\nimpl Levels {\n    pub fn new() {}\n}\nuse zenoh::CongestionControl;\n"
                .to_string(),
        ),
    ];
    let foreign = vec!["std".to_string()];
    let check = |p: &str| {
        unresolved_path(
            &p.split("::").map(String::from).collect::<Vec<_>>(),
            &sources,
            &foreign,
        )
    };
    assert_eq!(check("select::select_tiles"), None);
    assert_eq!(check("udlod::levels::Levels::new"), None);
    assert_eq!(check("Levels::root_lod"), None);
    assert_eq!(check("std::fs::read"), None);
    assert_eq!(check("CongestionControl::Drop"), None);
    assert!(
        check("select::Levels::new").is_some(),
        "a type in the wrong module resolved"
    );
    assert!(
        check("levels::select_tiles").is_some(),
        "an item in the wrong module resolved"
    );
    assert!(
        check("Levels::stretch").is_some(),
        "a missing member resolved"
    );
    assert!(
        check("SplitField::new").is_some(),
        "a missing type resolved"
    );
}
