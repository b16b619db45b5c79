//! House rules the module tree cannot show (issue #53).
//!
//! * Files small enough to read in one sitting, functions short enough to hold in one's head: no
//!   Rust source file of the workspace over [`MAX_FILE_LINES`] lines, and no function (free, method or a
//!   trait's provided one, tests included) over [`MAX_FN_LINES`] lines from its `fn` — its doc comments
//!   and attributes not counted — to its closing brace. The functions are found by parsing each file with `syn`,
//!   so a `fn` inside a string, a comment or a macro's text is not one.
//! * One way to FITS: no file outside `engine/src/formats` names the `fitsio` crate — the rest of the
//!   engine, the app and the Python module read and write FITS through `formats::fits` and
//!   `formats::fits_reader` (tests, which check files with it, excepted).

use std::path::{Path, PathBuf};
use syn::visit::{self, Visit};

/// The most lines a source file may have.
const MAX_FILE_LINES: usize = 1000;
/// The most lines a function may span, `fn` to closing brace.
const MAX_FN_LINES: usize = 150;

/// The folders of Rust code that the rules cover, relative to the workspace root.
const DIRS: &[&str] = &[
    "engine/src",
    "engine/tests",
    "engine/benches",
    "engine/python/src",
    "app/src",
    "tests",
];

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).to_path_buf()
}

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for e in entries.flatten() {
        let p = e.path();
        if p.is_dir() {
            rust_files(&p, out);
        } else if p.extension().is_some_and(|x| x == "rs") {
            out.push(p);
        }
    }
}

/// Each function's name, first line (its `fn`, after the attributes) and line count.
#[derive(Default)]
struct Functions {
    found: Vec<(String, usize, usize)>,
}

impl Functions {
    /// Record a function whose signature starts at `sig` and whose body is `block`.
    fn add(&mut self, name: String, sig: proc_macro2::Span, block: &syn::Block) {
        let first = sig.start().line;
        let last = block.brace_token.span.close().end().line;
        self.found.push((name, first, last + 1 - first));
    }
}

impl<'ast> Visit<'ast> for Functions {
    fn visit_item_fn(&mut self, f: &'ast syn::ItemFn) {
        let sig = f.sig.fn_token.span;
        self.add(f.sig.ident.to_string(), sig, &f.block);
        visit::visit_item_fn(self, f);
    }

    fn visit_impl_item_fn(&mut self, f: &'ast syn::ImplItemFn) {
        let sig = f.sig.fn_token.span;
        self.add(f.sig.ident.to_string(), sig, &f.block);
        visit::visit_impl_item_fn(self, f);
    }

    fn visit_trait_item_fn(&mut self, f: &'ast syn::TraitItemFn) {
        if let Some(block) = &f.default {
            let sig = f.sig.fn_token.span;
            self.add(f.sig.ident.to_string(), sig, block);
        }
        visit::visit_trait_item_fn(self, f);
    }
}

/// Every covered file's path (relative to the root) and text.
fn sources() -> Vec<(String, String)> {
    let mut files = Vec::new();
    for d in DIRS {
        rust_files(&root().join(d), &mut files);
    }
    files.sort();
    assert!(files.len() > 100, "found only {} Rust files", files.len());
    files
        .iter()
        .map(|f| {
            let rel = f.strip_prefix(root()).expect("under the root");
            let text = std::fs::read_to_string(f).expect("read a source file");
            (rel.to_string_lossy().replace('\\', "/"), text)
        })
        .collect()
}

/// The functions of one file's text over `max` lines: "file:line name (n lines)".
fn long_functions(rel: &str, text: &str, max: usize) -> Vec<String> {
    let file = syn::parse_file(text).unwrap_or_else(|e| panic!("{rel}: {e}"));
    let mut v = Functions::default();
    v.visit_file(&file);
    v.found
        .into_iter()
        .filter(|(_, _, n)| *n > max)
        .map(|(name, line, n)| format!("{rel}:{line} {name} ({n} lines)"))
        .collect()
}

#[test]
fn no_file_is_over_a_thousand_lines_and_no_function_over_150() {
    let mut long = Vec::new();
    for (rel, text) in sources() {
        let lines = text.lines().count();
        if lines > MAX_FILE_LINES {
            long.push(format!("{rel}: {lines} lines (at most {MAX_FILE_LINES})"));
        }
        long.extend(long_functions(&rel, &text, MAX_FN_LINES));
    }
    assert!(long.is_empty(), "too long:\n{}", long.join("\n"));
}

#[test]
fn the_counter_measures_from_fn_to_the_closing_brace_and_skips_fn_in_text() {
    let body: String = (0..8).map(|k| format!("    let a{k} = {k};\n")).collect();
    let text = format!(
        "/// doc\n/// more doc\n#[inline]\nfn free() {{\n{body}}}\n\
         struct S;\nimpl S {{\n    fn method(&self) {{\n{body}    }}\n}}\n\
         trait T {{\n    fn provided() {{\n{body}    }}\n    fn required();\n}}\n\
         const C: &str = \"fn not_one() {{ }}\";\n"
    );
    // each function: its `fn` line, 8 body lines, its closing brace
    let found = long_functions("fixture.rs", &text, 9);
    assert_eq!(
        found,
        vec![
            "fixture.rs:4 free (10 lines)",
            "fixture.rs:16 method (10 lines)",
            "fixture.rs:28 provided (10 lines)",
        ]
    );
    assert!(long_functions("fixture.rs", &text, 10).is_empty());
}

#[test]
fn only_the_formats_layer_names_cfitsio() {
    let mut found = Vec::new();
    for (rel, text) in sources() {
        let tests = rel.starts_with("tests/") || rel.starts_with("engine/tests/");
        if tests || rel.starts_with("engine/src/formats/") {
            continue;
        }
        for (k, line) in text.lines().enumerate() {
            let code = line.split("//").next().unwrap_or("");
            if code.contains("fitsio::") || code.trim_start().starts_with("use fitsio") {
                found.push(format!("{rel}:{}", k + 1));
            }
        }
    }
    assert!(
        found.is_empty(),
        "CFITSIO named outside engine/src/formats: {found:?}"
    );
}
