//! The engine's module structure against `docs/ARCHITECTURE.md`: every top-level module in one layer, uses
//! only of the same or earlier layers, no cycles between modules, and the analysis' remaining uses of the
//! simulator exactly the listed ones.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).to_path_buf()
}

/// The layer table of docs/ARCHITECTURE.md: module → layer number.
fn layers() -> BTreeMap<String, usize> {
    let text =
        std::fs::read_to_string(root().join("docs/ARCHITECTURE.md")).expect("docs/ARCHITECTURE.md");
    let mut out = BTreeMap::new();
    let mut in_table = false;
    for line in text.lines() {
        if line.starts_with("| layer | modules |") {
            in_table = true;
            continue;
        }
        if in_table {
            if !line.starts_with('|') {
                break;
            }
            let cells: Vec<&str> = line.split('|').map(str::trim).collect();
            let Some(n) = cells.get(1).and_then(|c| c.split_whitespace().next()) else {
                continue;
            };
            let Ok(n) = n.parse::<usize>() else {
                continue; // the |---| row
            };
            for m in cells[2].split(',') {
                let prev = out.insert(m.trim().to_string(), n);
                assert!(prev.is_none(), "{m} is in two layers");
            }
        }
    }
    assert!(
        !out.is_empty(),
        "no layer table found in docs/ARCHITECTURE.md"
    );
    out
}

/// A source file without its test code: everything from `#[cfg(test)]` + `mod tests` on, the item right after
/// any other `#[cfg(test)]`, and line comments (doc comments kept: their `crate::…` links are uses).
fn non_test_code(text: &str) -> String {
    let mut out = String::new();
    let mut skip_next_item = false;
    let lines: Vec<&str> = text.lines().collect();
    let mut i = 0;
    while i < lines.len() {
        let l = lines[i].trim_start();
        if l.starts_with("#[cfg(test)]") {
            let next = lines.get(i + 1).map(|s| s.trim_start()).unwrap_or("");
            if next.starts_with("mod tests") {
                break;
            }
            skip_next_item = true;
            i += 1;
            continue;
        }
        if skip_next_item {
            skip_next_item = false;
            if l.ends_with(';') {
                i += 1;
                continue;
            }
        }
        // a doc comment's `crate::…` links are uses (rustdoc resolves them; a reader follows them): kept
        let code = if l.starts_with("///") || l.starts_with("//!") {
            l
        } else {
            match l.find("//") {
                Some(k) => &l[..k],
                None => l,
            }
        };
        out.push_str(code);
        out.push('\n');
        i += 1;
    }
    out
}

/// The top-level modules a text uses through `crate::` paths (root re-exports mapped to their module).
fn uses(text: &str, modules: &BTreeSet<String>) -> BTreeSet<String> {
    let mut found = BTreeSet::new();
    for (k, _) in text.match_indices("crate::") {
        if k > 0 {
            let before = text.as_bytes()[k - 1];
            if before.is_ascii_alphanumeric() || before == b'_' {
                continue; // e.g. `my_crate::`
            }
        }
        let rest = &text[k + "crate::".len()..];
        let name: String = rest
            .chars()
            .take_while(|c| c.is_ascii_alphanumeric() || *c == '_')
            .collect();
        let m = match name.as_str() {
            "Error" | "Result" => "error".to_string(),
            "Config" => "config".to_string(),
            other => other.to_string(),
        };
        if modules.contains(&m) {
            found.insert(m);
        }
    }
    found
}

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for e in std::fs::read_dir(dir).expect("dir").flatten() {
        let p = e.path();
        if p.is_dir() {
            rust_files(&p, out);
        } else if p.extension().is_some_and(|x| x == "rs") {
            out.push(p);
        }
    }
}

/// Top-level module of a file under engine/src (`None` for lib.rs and the binaries).
fn module_of(src: &Path, file: &Path) -> Option<String> {
    let rel = file.strip_prefix(src).ok()?;
    let first = rel
        .components()
        .next()?
        .as_os_str()
        .to_string_lossy()
        .to_string();
    let name = first.trim_end_matches(".rs").to_string();
    (name != "lib" && name != "bin").then_some(name)
}

#[test]
fn the_engine_follows_its_documented_layers_without_cycles() {
    let layer = layers();
    let src = root().join("engine/src");
    let mut files = Vec::new();
    rust_files(&src, &mut files);
    files.sort();
    let on_disk: BTreeSet<String> = files.iter().filter_map(|f| module_of(&src, f)).collect();
    let documented: BTreeSet<String> = layer.keys().cloned().collect();
    assert_eq!(
        on_disk, documented,
        "the engine's top-level modules and docs/ARCHITECTURE.md's layer table differ"
    );
    let mut edges: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    let mut simulate_users = BTreeSet::new();
    let mut wrong = Vec::new();
    for f in &files {
        let Some(m) = module_of(&src, f) else {
            continue;
        };
        let text = non_test_code(&std::fs::read_to_string(f).expect("read"));
        for u in uses(&text, &documented) {
            if u == m {
                continue;
            }
            if layer[&u] > layer[&m] {
                wrong.push(format!(
                    "{} (layer {}) uses {u} (layer {})",
                    f.strip_prefix(&src).unwrap_or(f).display(),
                    layer[&m],
                    layer[&u]
                ));
            }
            // the analysis sees neither the simulator nor the truth (the scoring, a later layer, reads it)
            if m == "analysis" && ["simulate", "session", "studies", "truth"].contains(&u.as_str())
            {
                simulate_users.insert(f.strip_prefix(&src).unwrap_or(f).display().to_string());
            }
            edges.entry(m.clone()).or_default().insert(u);
        }
    }
    assert!(
        wrong.is_empty(),
        "uses against the layers:\n{}",
        wrong.join("\n")
    );
    // no cycles: a depth-first search over the module graph
    fn visit(
        m: &str,
        edges: &BTreeMap<String, BTreeSet<String>>,
        state: &mut BTreeMap<String, u8>,
        path: &mut Vec<String>,
    ) -> Option<Vec<String>> {
        match state.get(m) {
            Some(2) => return None,
            Some(1) => {
                let k = path.iter().position(|p| p == m).unwrap_or(0);
                let mut cycle = path[k..].to_vec();
                cycle.push(m.to_string());
                return Some(cycle);
            }
            _ => {}
        }
        state.insert(m.to_string(), 1);
        path.push(m.to_string());
        for n in edges.get(m).into_iter().flatten() {
            if let Some(c) = visit(n, edges, state, path) {
                return Some(c);
            }
        }
        path.pop();
        state.insert(m.to_string(), 2);
        None
    }
    let mut state = BTreeMap::new();
    for m in &documented {
        if let Some(c) = visit(m, &edges, &mut state, &mut Vec::new()) {
            panic!("import cycle: {}", c.join(" → "));
        }
    }
    assert!(
        simulate_users.is_empty(),
        "the analysis must see neither the simulator nor the truth (docs/ARCHITECTURE.md): {simulate_users:?}"
    );
}

#[test]
fn the_checker_sees_uses_and_skips_tests_and_comments() {
    let modules: BTreeSet<String> = ["analysis", "config", "error", "testkit"]
        .iter()
        .map(|s| s.to_string())
        .collect();
    let text = "use crate::analysis::X;\n// crate::testkit in a comment\nfn f() -> crate::Result<()> {}\n\
                #[cfg(test)]\nuse crate::testkit::a;\nlet c: crate::Config;\n#[cfg(test)]\nmod tests {\n use crate::testkit;\n}\n";
    let code = non_test_code(text);
    let u = uses(&code, &modules);
    let expect: BTreeSet<String> = ["analysis", "error", "config"]
        .iter()
        .map(|s| s.to_string())
        .collect();
    assert_eq!(u, expect);
}
