//! docs/ARCHITECTURE.md's table of crates is a map a newcomer trusts: every
//! crate of the workspace has its row, its dependencies are the ones its
//! Cargo.toml names (each on a row above it: the layering), and its size
//! is within 15% (or 100 lines) of the lines its sources hold. When a crate grows, this
//! test names the row to update and the count to write.
#![allow(clippy::unwrap_used)]

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::process::Command;

/// How far a row's size may drift from the sources before it must be
/// rewritten.
const SIZE_TOLERANCE: f64 = 0.15;
/// ... or by this many lines (a row says ~N.Nk).
const SIZE_SLACK: f64 = 100.0;

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .unwrap()
        .to_path_buf()
}

/// A row of the table: its dependencies and its size in lines.
struct Row {
    order: usize,
    deps: BTreeSet<String>,
    lines: f64,
}

/// The rows of the table after "| crate | depends on | lines | one idea |".
fn table(text: &str) -> BTreeMap<String, Row> {
    let mut rows = BTreeMap::new();
    let mut inside = false;
    for line in text.lines() {
        if line.starts_with("| crate | depends on | lines |") {
            inside = true;
            continue;
        }
        if !inside || line.starts_with("|---") {
            continue;
        }
        if !line.starts_with('|') {
            if !rows.is_empty() {
                break;
            }
            continue;
        }
        let cells: Vec<&str> = line.split('|').map(str::trim).collect();
        let (name, deps, lines) = (cells[1], cells[2], cells[3]);
        // "files, geometry (+ tch)"; the cli's "a, b; c, d only with `network`"
        let listed = deps.split('(').next().unwrap();
        let deps: BTreeSet<String> = listed
            .split(';')
            .flat_map(|part| part.split(" only with").next().unwrap().split(','))
            .map(|d| d.trim().to_owned())
            .filter(|d| !d.is_empty() && d != "-")
            .collect();
        let size = lines.trim_start_matches('~').trim_end_matches('k');
        let lines: f64 = size
            .parse::<f64>()
            .unwrap_or_else(|_| panic!("row {name}: size {lines:?} is not ~N.Nk"))
            * 1000.0;
        let order = rows.len();
        rows.insert(name.to_owned(), Row { order, deps, lines });
    }
    rows
}

/// Lines of the `.rs` files under `dir`.
fn source_lines(dir: &Path) -> usize {
    let mut n = 0;
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.is_dir() {
            n += source_lines(&path);
        } else if path.extension().is_some_and(|e| e == "rs") {
            n += std::fs::read_to_string(&path).unwrap().lines().count();
        }
    }
    n
}

#[test]
fn the_crate_table_matches_the_workspace() {
    let root = root();
    let text = std::fs::read_to_string(root.join("docs/ARCHITECTURE.md")).unwrap();
    let rows = table(&text);
    assert!(rows.len() > 10, "no crate table found");
    let out = Command::new(env!("CARGO"))
        .args([
            "metadata",
            "--format-version",
            "1",
            "--no-deps",
            "--offline",
        ])
        .current_dir(&root)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let meta: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let short = |name: &str| name.trim_start_matches("mfm-").to_owned();
    let mut problems = Vec::new();
    for package in meta["packages"].as_array().unwrap() {
        let name = short(package["name"].as_str().unwrap());
        let Some(row) = rows.get(&name) else {
            problems.push(format!("{name}: no row"));
            continue;
        };
        let deps: BTreeSet<String> = package["dependencies"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|d| d["kind"].is_null())
            .filter_map(|d| d["name"].as_str())
            .filter(|d| d.starts_with("mfm-"))
            .map(short)
            .collect();
        if deps != row.deps {
            problems.push(format!(
                "{name}: the row says it depends on {:?}, its Cargo.toml on {deps:?}",
                row.deps
            ));
        }
        for d in &deps {
            if rows.get(d).is_none_or(|r| r.order >= row.order) {
                problems.push(format!(
                    "{name}: its dependency {d} is not on a row above it"
                ));
            }
        }
        let manifest = Path::new(package["manifest_path"].as_str().unwrap());
        let lines = source_lines(&manifest.parent().unwrap().join("src")) as f64;
        if (lines - row.lines).abs() > (SIZE_TOLERANCE * lines).max(SIZE_SLACK) {
            problems.push(format!(
                "{name}: the row says ~{:.1}k lines, its sources hold {lines} (write ~{:.1}k)",
                row.lines / 1000.0,
                lines / 1000.0
            ));
        }
    }
    let names: BTreeSet<String> = meta["packages"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| short(p["name"].as_str().unwrap()))
        .collect();
    for name in rows.keys() {
        if !names.contains(name) {
            problems.push(format!(
                "{name}: a row for a crate the workspace does not have"
            ));
        }
    }
    assert!(
        problems.is_empty(),
        "docs/ARCHITECTURE.md:\n{}",
        problems.join("\n")
    );
}
