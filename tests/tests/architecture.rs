//! ARCHITECTURE.md stays true: every source path it cites exists, and every name it cites
//! (a `Type`, a `CONSTANT`, a `snake_case` item, a `path::to::item`) is defined somewhere in
//! the workspace's sources. Prose can still go stale; citations cannot.

use std::path::{Path, PathBuf};

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// Every file under `dir`, skipping build output and hidden folders.
fn files(dir: &Path, out: &mut Vec<PathBuf>) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for entry in entries.flatten() {
        let path = entry.path();
        let name = entry.file_name().to_string_lossy().to_string();
        if name.starts_with('.') || name == "target" {
            continue;
        }
        if path.is_dir() {
            files(&path, out);
        } else {
            out.push(path);
        }
    }
}

/// Backticked spans of `text`, each with the crate folder of the section it is in (from
/// headings like "### `visnode/`").
fn citations(text: &str) -> Vec<(String, Option<String>)> {
    let mut section = None;
    let mut cited = Vec::new();
    for line in text.lines() {
        if let Some(heading) = line.strip_prefix("### `") {
            section = heading.strip_suffix("/`").map(str::to_string);
        } else if line.starts_with("## ") {
            section = None;
        }
        let mut parts = line.split('`');
        parts.next();
        while let (Some(span), Some(_)) = (parts.next(), parts.next()) {
            cited.push((span.to_string(), section.clone()));
        }
    }
    cited
}

/// A source path the map cites: a folder (`render/`) or a source file (`plan.rs`), with no
/// placeholders. Output files the programs write (`board.json`) are not sources.
fn is_source_path(span: &str) -> bool {
    const EXTENSIONS: [&str; 9] = [
        ".rs", ".proto", ".wgsl", ".sh", ".py", ".toml", ".yml", ".yaml", ".md",
    ];
    !span.contains([' ', '<', '*', '$', '~', '='])
        && (span.ends_with('/')
            || span.ends_with("Dockerfile")
            || EXTENSIONS.iter().any(|e| span.ends_with(e)))
}

/// Names the map cites from outside the workspace (std, tokio).
const EXTERNAL_NAMES: [&str; 1] = ["try_recv"];

/// A name the map cites: `Type`, `CONSTANT`, `snake_case`, `path::to::item`.
fn is_name(span: &str) -> bool {
    let word = |w: &str| {
        !w.is_empty()
            && w.chars().all(|c| c.is_ascii_alphanumeric() || c == '_')
            && !w.starts_with(|c: char| c.is_ascii_digit())
    };
    let segments: Vec<&str> = span.split("::").collect();
    if !segments.iter().all(|s| word(s)) {
        return false;
    }
    let last = segments[segments.len() - 1];
    segments.len() > 1
        || last.contains('_')
        || (last.starts_with(|c: char| c.is_ascii_uppercase()) && last.len() > 1)
}

/// Whether `name` is defined in `source`: an item (`fn`, `struct`, `enum`, `trait`,
/// `const`, `static`, `mod`, `type`), a field or enum variant at the start of a line, or a
/// protobuf message or rpc.
fn defines(source: &str, name: &str) -> bool {
    let is_word_end =
        |rest: &str| !rest.starts_with(|c: char| c.is_ascii_alphanumeric() || c == '_');
    for keyword in [
        "fn ", "struct ", "enum ", "trait ", "const ", "static ", "mod ", "type ", "message ",
        "rpc ", "service ",
    ] {
        let needle = format!("{keyword}{name}");
        let mut from = 0;
        while let Some(at) = source[from..].find(&needle) {
            let start = from + at;
            let before_ok = start == 0
                || !source[..start].ends_with(|c: char| c.is_ascii_alphanumeric() || c == '_');
            if before_ok && is_word_end(&source[start + needle.len()..]) {
                return true;
            }
            from = start + needle.len();
        }
    }
    source.lines().any(|line| {
        let line = line.trim_start();
        let line = line
            .strip_prefix("pub(crate) ")
            .or_else(|| line.strip_prefix("pub "))
            .unwrap_or(line);
        line.strip_prefix(name).is_some_and(|rest| {
            is_word_end(rest) && rest.trim_start().starts_with([':', ',', '(', '{'])
        })
    })
}

#[test]
fn every_path_and_name_in_the_architecture_map_exists() {
    let root = root();
    let map = std::fs::read_to_string(root.join("ARCHITECTURE.md")).unwrap();
    let mut all = Vec::new();
    files(&root, &mut all);
    let relative: Vec<String> = all
        .iter()
        .map(|p| {
            p.strip_prefix(&root)
                .unwrap_or(p)
                .to_string_lossy()
                .replace('\\', "/")
        })
        .collect();
    let sources: String = all
        .iter()
        .filter(|p| {
            p.extension()
                .is_some_and(|e| e == "rs" || e == "proto" || e == "wgsl")
        })
        .filter_map(|p| std::fs::read_to_string(p).ok())
        .collect::<Vec<_>>()
        .join("\n");
    let mut missing = Vec::new();
    let mut checked = (0, 0);
    for (span, section) in citations(&map) {
        if is_source_path(&span) {
            checked.0 += 1;
            // From the root, from the section's crate, or as the tail of a path in that crate.
            let within = |path: &String| {
                section
                    .as_ref()
                    .is_none_or(|s| path.starts_with(&format!("{s}/")))
            };
            let tail = span.trim_end_matches('/');
            let found = root.join(tail).exists()
                || section
                    .as_ref()
                    .is_some_and(|s| root.join(s).join(tail).exists())
                || relative
                    .iter()
                    .filter(|p| within(p))
                    .any(|p| p.ends_with(&format!("/{tail}")) || p.contains(&format!("/{tail}/")));
            if !found {
                missing.push(format!("path `{span}` (section {section:?})"));
            }
        } else if is_name(&span) && !EXTERNAL_NAMES.contains(&span.as_str()) {
            checked.1 += 1;
            for segment in span.split("::") {
                // Crate names are folders, not items.
                if root.join(segment).is_dir() {
                    continue;
                }
                if !defines(&sources, segment) {
                    missing.push(format!("name `{span}`: `{segment}` is defined nowhere"));
                }
            }
        }
    }
    assert!(
        checked.0 > 30 && checked.1 > 30,
        "the parser found too little to check: {checked:?}"
    );
    assert!(
        missing.is_empty(),
        "ARCHITECTURE.md cites what does not exist:\n{}",
        missing.join("\n")
    );
}

/// The checker itself: it finds definitions and refuses look-alikes.
#[test]
fn the_checker_tells_definitions_from_mentions() {
    let source = "pub struct Balancer {\n    pub c_start: f64,\n}\nenum E { BadWeight, Other(u8) }\nfn assign_all() {}\n// Renderer is mentioned here only\n";
    assert!(defines(source, "Balancer"));
    assert!(defines(source, "c_start"));
    assert!(defines(source, "assign_all"));
    assert!(!defines(source, "assign"), "a prefix is not a definition");
    assert!(
        !defines(source, "Renderer"),
        "a comment is not a definition"
    );
    assert!(is_name("Balancer::assign") && is_name("DEPTH_JUMP_PIXELS") && is_name("t_nz"));
    assert!(!is_name("relief") && !is_name("T = 0") && !is_name("D"));
    assert!(is_source_path("src/lib.rs") && is_source_path("render/"));
    assert!(!is_source_path("board.json") && !is_source_path("lod-<hash>.bin"));
    let cited = citations("### `visnode/`\n- `plan.rs`: `Plan` and `x`.\n## Other\n`y`");
    assert_eq!(cited[0], ("visnode/".into(), Some("visnode".into())));
    assert_eq!(cited[1], ("plan.rs".into(), Some("visnode".into())));
    assert_eq!(cited[4], ("y".into(), None));
}
