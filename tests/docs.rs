//! The documentation as a reader of a clone meets it: every relative link and image of every Markdown file
//! resolves to a file of the repository, and none points outside it (a clone has nothing beside it).

use std::path::{Path, PathBuf};

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).to_path_buf()
}

/// Every Markdown file of the repository (build outputs, dependencies and hidden directories left out).
fn markdown_files(dir: &Path, out: &mut Vec<PathBuf>) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for e in entries.flatten() {
        let p = e.path();
        let name = e.file_name().to_string_lossy().to_string();
        if p.is_dir() {
            if !(name.starts_with('.')
                || name == "target"
                || name == "node_modules"
                || name == "out")
            {
                markdown_files(&p, out);
            }
        } else if name.ends_with(".md") {
            out.push(p);
        }
    }
}

/// The targets of `[text](target)` and `![alt](target)` in a Markdown text, code blocks left out.
fn link_targets(text: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut in_code = false;
    for line in text.lines() {
        if line.trim_start().starts_with("```") {
            in_code = !in_code;
            continue;
        }
        if in_code {
            continue;
        }
        let mut rest = line;
        while let Some(i) = rest.find("](") {
            let after = &rest[i + 2..];
            let Some(j) = after.find(')') else { break };
            out.push(after[..j].trim().to_string());
            rest = &after[j..];
        }
    }
    out
}

#[test]
fn every_relative_link_resolves_inside_the_repository() {
    let root = root();
    let canon_root = root.canonicalize().expect("root");
    let mut files = Vec::new();
    markdown_files(&root, &mut files);
    assert!(files.len() >= 10, "{files:?}");
    let mut bad = Vec::new();
    for f in &files {
        let text = std::fs::read_to_string(f).expect("read");
        for t in link_targets(&text) {
            let t = t.split_whitespace().next().unwrap_or("").to_string();
            if t.is_empty()
                || t.starts_with('#')
                || t.starts_with("http://")
                || t.starts_with("https://")
                || t.starts_with("mailto:")
            {
                continue;
            }
            let path = t.split('#').next().unwrap_or("");
            let target = f.parent().unwrap_or(&root).join(path);
            match target.canonicalize() {
                Ok(p) if p.starts_with(&canon_root) => {}
                Ok(p) => bad.push(format!(
                    "{}: {t} leaves the repository ({})",
                    f.display(),
                    p.display()
                )),
                Err(_) => bad.push(format!("{}: {t} does not exist", f.display())),
            }
        }
    }
    assert!(bad.is_empty(), "broken links:\n{}", bad.join("\n"));
}

#[test]
fn the_link_finder_sees_links_and_images_and_skips_code() {
    let t = "see [a](docs/a.md) and ![b](img.png)\n```sh\n[c](nope.md)\n```\n[d](https://x.org)";
    assert_eq!(
        link_targets(t),
        vec!["docs/a.md", "img.png", "https://x.org"]
    );
}
