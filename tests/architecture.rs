//! The engine's module structure against `docs/ARCHITECTURE.md`.
//!
//! Every file of `engine/src` is parsed (`syn`; items under `#[cfg(test)]` left out) and every path it names is
//! a use: each `use` tree (groups, renames, globs), every path in an expression, type, pattern or macro, and
//! the `crate::…` links of doc comments. A path is resolved to the library's absolute path: `crate::` as is,
//! `engine::` (the crate's own name, as the binaries write it) the same, `super::`/`self::` from the file's
//! module (inline `mod`s included), and a bare path through the file's own `use`s and child `mod`s.
//! `crate::Error`, `crate::Result` and `crate::Config` (lib.rs's re-exports) are `error`, `error` and `config`.
//!
//! Checked on that set of uses:
//! * every top-level module is in exactly one layer of the table, uses only its own or earlier layers, and the
//!   top-level modules use each other without a cycle;
//! * inside each top-level module, its files and inline modules use each other without a cycle (code uses
//!   only; a module and its own submodules count as one), except the elementary cycles listed in
//!   [`KNOWN_CYCLES`] (the list must match exactly, so it shrinks as they are fixed);
//! * no file of `analysis` or `solution` uses `simulate`, `session`, `studies` or `truth`;
//! * the truth-carrying and as-built items ([`forbidden`]: `TruthRow` and `crate::truth`, the simulator
//!   `crate::simulate` with `Simulator` and `FocalPlaneSimulator`, the as-built instrument — any path segment
//!   `as_built` or type `AsBuilt…`) are named by no file of the analysis (`engine/src/analysis/`: the
//!   per-image analysis, transit photometry `analysis/stare_photometry.rs` and `analysis/lightcurve.rs`), of
//!   the astrometric solution (`engine/src/solution/`) and by no product reader, except the uses
//!   listed in [`KNOWN_FORBIDDEN`] (again exactly). The product readers ([`is_product_reader`]) are the files
//!   of `engine/src/io/` whose job is reading products back — `analysis_input.rs` (an image and its instrument
//!   products for the analysis), `readout_header.rs` (the readout timing a header states), `sequence_view.rs`
//!   (a sequence's products for the explorer), `sky_reference.rs` (the reference catalogue the solution is
//!   anchored to), any io file named `read…` — and every io function named `read…` (e.g. the instrument
//!   products' readers in `instrument.rs`, whose writers may take the simulator) but `read_truth…` (the
//!   scoring's reader of the answer key).

use proc_macro2::{TokenStream, TokenTree};
use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use syn::visit::{self, Visit};

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).to_path_buf()
}

/// Intra-module import cycles allowed (elementary cycles of module paths, written from the smallest): none. The
/// test fails on any cycle not listed here and on a listed one that has gone.
const KNOWN_CYCLES: &[&str] = &[];

/// Uses of forbidden items that exist today: (file under engine/src, what it names, why). The test fails on any
/// other and on a listed one that has gone.
const KNOWN_FORBIDDEN: &[(&str, &str, &str)] = &[(
    "io/analysis_input.rs",
    "truth",
    "AnalysisInput carries a given truth file or the image's TRUTH extension beside the image, for the scoring",
)];

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

/// A library file's module path (`analysis/epsf/fit.rs` → `[analysis, epsf, fit]`, a `mod.rs` its
/// directory's, `lib.rs` the root); `None` for the binaries (engine/src/bin), whose `crate::` is their own.
fn module_path(rel: &Path) -> Option<Vec<String>> {
    let mut parts: Vec<String> = rel
        .components()
        .map(|c| c.as_os_str().to_string_lossy().to_string())
        .collect();
    if parts.first().is_some_and(|p| p == "bin") {
        return None;
    }
    let last = parts.pop()?;
    let stem = last.trim_end_matches(".rs");
    if !(stem == "mod" || (parts.is_empty() && stem == "lib")) {
        parts.push(stem.to_string());
    }
    Some(parts)
}

/// lib.rs's re-exports: the root name → the top-level module it comes from (`None`: the root itself).
fn reexport(name: &str) -> Option<Option<&'static str>> {
    match name {
        "Error" | "Result" => Some(Some("error")),
        "Config" => Some(Some("config")),
        "VERSION" | "ARCSEC_PER_RAD" => Some(None),
        _ => None,
    }
}

/// One use: the path named, resolved to the library's absolute path without `crate` where it could be (else the
/// path as written, e.g. `std::…` or a local name), where, and from which module and function.
#[derive(Clone, Debug)]
struct Use {
    path: Vec<String>,
    resolved: bool,
    line: usize,
    /// the module the use sits in (a file's, or an inline `mod`'s inside it); empty in a binary
    from: Vec<String>,
    /// the outermost function it sits in, if any
    func: Option<String>,
    /// a doc comment's link, not code
    doc: bool,
}

impl Use {
    /// The top-level module a resolved path is in (root re-exports mapped; `None` for the root's own items).
    fn top(&self) -> Option<String> {
        let first = self.path.first().filter(|_| self.resolved)?;
        match reexport(first) {
            Some(m) => m.map(str::to_string),
            None => Some(first.clone()),
        }
    }
}

/// What a file uses, and the inline modules it declares (module paths).
#[derive(Debug, Default)]
struct FileUses {
    uses: Vec<Use>,
    inline_mods: Vec<Vec<String>>,
}

/// An item attribute list that is compiled only for tests: `#[cfg(test)]` or `#[cfg(all(…, test, …))]`.
fn is_test_only(attrs: &[syn::Attribute]) -> bool {
    fn test_only(m: &syn::Meta) -> bool {
        match m {
            syn::Meta::Path(p) => p.is_ident("test"),
            syn::Meta::List(l) if l.path.is_ident("all") => l
                .parse_args_with(
                    syn::punctuated::Punctuated::<syn::Meta, syn::Token![,]>::parse_terminated,
                )
                .is_ok_and(|ms| ms.iter().any(test_only)),
            _ => false,
        }
    }
    attrs.iter().any(|a| {
        a.path().is_ident("cfg") && a.parse_args::<syn::Meta>().is_ok_and(|m| test_only(&m))
    })
}

/// The `a::b::c` paths in a token stream (a macro's arguments), recursing into groups.
fn token_paths(ts: TokenStream, out: &mut Vec<(Vec<String>, usize)>) {
    let tokens: Vec<TokenTree> = ts.into_iter().collect();
    let mut i = 0;
    while i < tokens.len() {
        match &tokens[i] {
            TokenTree::Group(g) => {
                token_paths(g.stream(), out);
                i += 1;
            }
            TokenTree::Ident(id) => {
                let line = id.span().start().line;
                let mut segs = vec![id.to_string()];
                let mut j = i + 1;
                while let (
                    Some(TokenTree::Punct(a)),
                    Some(TokenTree::Punct(b)),
                    Some(TokenTree::Ident(n)),
                ) = (tokens.get(j), tokens.get(j + 1), tokens.get(j + 2))
                {
                    if a.as_char() != ':' || b.as_char() != ':' {
                        break;
                    }
                    segs.push(n.to_string());
                    j += 3;
                }
                if segs.len() > 1 {
                    out.push((segs, line));
                }
                i = j;
            }
            _ => i += 1,
        }
    }
}

/// The `crate::a::b` paths in a doc comment's text (its intra-doc links): `crate` left out.
fn doc_paths(text: &str) -> Vec<Vec<String>> {
    let mut out = Vec::new();
    for (k, _) in text.match_indices("crate::") {
        let before = text[..k].chars().next_back();
        if before.is_some_and(|c| c.is_alphanumeric() || c == '_') {
            continue; // e.g. `my_crate::`
        }
        let rest = &text[k + "crate::".len()..];
        let mut segs = Vec::new();
        let mut s = rest;
        loop {
            let n = s
                .find(|c: char| !(c.is_alphanumeric() || c == '_'))
                .unwrap_or(s.len());
            if n == 0 {
                break;
            }
            segs.push(s[..n].to_string());
            match s[n..].strip_prefix("::") {
                Some(r) => s = r,
                None => break,
            }
        }
        if !segs.is_empty() {
            out.push(segs);
        }
    }
    out
}

/// The walk over one file: first its `use`s and `mod`s (names in scope), then every path.
struct Walker {
    /// a library file (a binary's `crate::` is its own)
    lib: bool,
    /// the current module (a file's, then each inline `mod`'s)
    module: Vec<String>,
    functions: Vec<String>,
    collecting_names: bool,
    /// recording a doc comment's links
    in_doc: bool,
    /// a name a `use` brought in → its resolved path (`None`: not the library's)
    names: BTreeMap<String, Option<Vec<String>>>,
    /// (module, child) for each `mod child` declared
    children: BTreeSet<(Vec<String>, String)>,
    out: FileUses,
}

impl Walker {
    /// Resolves a path as written in the current module: `Some((path, resolved))`, or `None` when it is the
    /// binary's own (`crate::…` in a binary) or names nothing (`super` past the root).
    fn resolve(&self, segs: &[String]) -> Option<(Vec<String>, bool)> {
        let first = segs.first()?;
        let rest = || segs[1..].to_vec();
        match first.as_str() {
            "engine" => Some((rest(), true)),
            "crate" => self.lib.then(|| (rest(), true)),
            "self" => self.lib.then(|| {
                let mut p = self.module.clone();
                p.extend(rest());
                (p, true)
            }),
            "super" => {
                if !self.lib {
                    return None;
                }
                let n = segs.iter().take_while(|s| *s == "super").count();
                let keep = self.module.len().checked_sub(n)?;
                let mut p = self.module[..keep].to_vec();
                p.extend(segs[n..].iter().cloned());
                Some((p, true))
            }
            "Self" => Some((segs.to_vec(), false)),
            name => {
                match self.names.get(name) {
                    Some(Some(target)) => {
                        let mut p = target.clone();
                        p.extend(rest());
                        return Some((p, true));
                    }
                    Some(None) => return Some((segs.to_vec(), false)), // another crate's
                    None => {}
                }
                if self
                    .children
                    .contains(&(self.module.clone(), name.to_string()))
                {
                    let mut p = self.module.clone();
                    p.extend(segs.iter().cloned());
                    return Some((p, true));
                }
                Some((segs.to_vec(), false))
            }
        }
    }

    fn record(&mut self, segs: &[String], line: usize) {
        if let Some((path, resolved)) = self.resolve(segs) {
            self.out.uses.push(Use {
                path,
                resolved,
                line,
                from: self.module.clone(),
                func: self.functions.first().cloned(),
                doc: self.in_doc,
            });
        }
    }

    /// A `use` tree under `prefix`: records each leaf and the name it brings in.
    fn use_tree(&mut self, prefix: &mut Vec<String>, tree: &syn::UseTree) {
        let line = |id: &syn::Ident| id.span().start().line;
        match tree {
            syn::UseTree::Path(p) => {
                prefix.push(p.ident.to_string());
                self.use_tree(prefix, &p.tree);
                prefix.pop();
            }
            syn::UseTree::Name(n) => {
                let (full, name) = if n.ident == "self" {
                    (prefix.clone(), prefix.last().cloned().unwrap_or_default())
                } else {
                    let mut f = prefix.clone();
                    f.push(n.ident.to_string());
                    (f, n.ident.to_string())
                };
                self.bring(&full, name, line(&n.ident));
            }
            syn::UseTree::Rename(r) => {
                let mut full = prefix.clone();
                if r.ident != "self" {
                    full.push(r.ident.to_string());
                }
                self.bring(&full, r.rename.to_string(), line(&r.ident));
            }
            syn::UseTree::Glob(g) => {
                let l = g.star_token.spans[0].start().line;
                self.record(&prefix.clone(), l);
            }
            syn::UseTree::Group(g) => {
                for t in &g.items {
                    self.use_tree(prefix, t);
                }
            }
        }
    }

    fn bring(&mut self, full: &[String], name: String, line: usize) {
        let target = self.resolve(full);
        self.record(full, line);
        if name != "_" {
            let t = match target {
                Some((p, true)) => Some(p),
                _ => None,
            };
            self.names.insert(name, t);
        }
    }
}

impl<'ast> Visit<'ast> for Walker {
    fn visit_item(&mut self, i: &'ast syn::Item) {
        let attrs: &[syn::Attribute] = match i {
            syn::Item::Const(x) => &x.attrs,
            syn::Item::Enum(x) => &x.attrs,
            syn::Item::ExternCrate(x) => &x.attrs,
            syn::Item::Fn(x) => &x.attrs,
            syn::Item::ForeignMod(x) => &x.attrs,
            syn::Item::Impl(x) => &x.attrs,
            syn::Item::Macro(x) => &x.attrs,
            syn::Item::Mod(x) => &x.attrs,
            syn::Item::Static(x) => &x.attrs,
            syn::Item::Struct(x) => &x.attrs,
            syn::Item::Trait(x) => &x.attrs,
            syn::Item::TraitAlias(x) => &x.attrs,
            syn::Item::Type(x) => &x.attrs,
            syn::Item::Union(x) => &x.attrs,
            syn::Item::Use(x) => &x.attrs,
            _ => &[],
        };
        if !is_test_only(attrs) {
            visit::visit_item(self, i);
        }
    }

    fn visit_impl_item(&mut self, i: &'ast syn::ImplItem) {
        let attrs: &[syn::Attribute] = match i {
            syn::ImplItem::Const(x) => &x.attrs,
            syn::ImplItem::Fn(x) => &x.attrs,
            syn::ImplItem::Type(x) => &x.attrs,
            syn::ImplItem::Macro(x) => &x.attrs,
            _ => &[],
        };
        if !is_test_only(attrs) {
            visit::visit_impl_item(self, i);
        }
    }

    fn visit_local(&mut self, i: &'ast syn::Local) {
        if !is_test_only(&i.attrs) {
            visit::visit_local(self, i);
        }
    }

    fn visit_item_mod(&mut self, i: &'ast syn::ItemMod) {
        if self.collecting_names {
            self.children
                .insert((self.module.clone(), i.ident.to_string()));
        }
        if i.content.is_some() {
            self.module.push(i.ident.to_string());
            if self.collecting_names {
                self.out.inline_mods.push(self.module.clone());
            }
            visit::visit_item_mod(self, i);
            self.module.pop();
        } else if !self.collecting_names {
            for a in &i.attrs {
                self.visit_attribute(a);
            }
        }
    }

    fn visit_item_use(&mut self, i: &'ast syn::ItemUse) {
        if self.collecting_names {
            self.use_tree(&mut Vec::new(), &i.tree);
        }
    }

    fn visit_item_fn(&mut self, i: &'ast syn::ItemFn) {
        self.functions.push(i.sig.ident.to_string());
        visit::visit_item_fn(self, i);
        self.functions.pop();
    }

    fn visit_impl_item_fn(&mut self, i: &'ast syn::ImplItemFn) {
        self.functions.push(i.sig.ident.to_string());
        visit::visit_impl_item_fn(self, i);
        self.functions.pop();
    }

    /// `pub(crate)`, `pub(super)`: a reach, not a use.
    fn visit_visibility(&mut self, _: &'ast syn::Visibility) {}

    /// Doc comments' `crate::…` links are uses (rustdoc resolves them; a reader follows them); other
    /// attributes are not looked into.
    fn visit_attribute(&mut self, a: &'ast syn::Attribute) {
        if self.collecting_names || !self.lib || !a.path().is_ident("doc") {
            return;
        }
        if let syn::Meta::NameValue(nv) = &a.meta
            && let syn::Expr::Lit(syn::ExprLit {
                lit: syn::Lit::Str(s),
                ..
            }) = &nv.value
        {
            let line = s.span().start().line;
            self.in_doc = true;
            for p in doc_paths(&s.value()) {
                let mut segs = vec!["crate".to_string()];
                segs.extend(p);
                self.record(&segs, line);
            }
            self.in_doc = false;
        }
    }

    fn visit_path(&mut self, p: &'ast syn::Path) {
        if !self.collecting_names {
            let segs: Vec<String> = p.segments.iter().map(|s| s.ident.to_string()).collect();
            let line = p
                .segments
                .first()
                .map_or(0, |s| s.ident.span().start().line);
            self.record(&segs, line);
        }
        visit::visit_path(self, p);
    }

    /// A macro's arguments are tokens to syn: their `a::b` paths are uses too.
    fn visit_macro(&mut self, m: &'ast syn::Macro) {
        visit::visit_macro(self, m);
        if !self.collecting_names {
            let mut found = Vec::new();
            token_paths(m.tokens.clone(), &mut found);
            for (segs, line) in found {
                self.record(&segs, line);
            }
        }
    }
}

/// Every use of one source file, `rel` its path under engine/src (which gives its module).
fn file_uses(rel: &Path, text: &str) -> FileUses {
    let file = syn::parse_file(text).unwrap_or_else(|e| panic!("{}: {e}", rel.display()));
    let module = module_path(rel);
    let mut w = Walker {
        lib: module.is_some(),
        module: module.unwrap_or_default(),
        functions: Vec::new(),
        collecting_names: true,
        in_doc: false,
        names: BTreeMap::new(),
        children: BTreeSet::new(),
        out: FileUses::default(),
    };
    w.visit_file(&file);
    w.collecting_names = false;
    w.visit_file(&file);
    w.out
}

/// The forbidden item a use names, if any: `truth` (the module or `TruthRow`), `simulate` (the module,
/// `Simulator`, `FocalPlaneSimulator`) or `as_built` (the module `crate::instrument`, which draws the as-built
/// instrument, a segment `as_built` or `as_built_oracle`, a type `AsBuilt…`). Names are
/// matched in unresolved paths too, so a re-export elsewhere does not hide them.
fn forbidden(u: &Use) -> Option<&'static str> {
    let first = u.path.first().filter(|_| u.resolved).map(String::as_str);
    if first == Some("truth") || u.path.iter().any(|s| s == "TruthRow") {
        return Some("truth");
    }
    if first == Some("simulate")
        || u.path
            .iter()
            .any(|s| s == "Simulator" || s == "FocalPlaneSimulator")
    {
        return Some("simulate");
    }
    if first == Some("instrument")
        || u.path
            .iter()
            .any(|s| s == "as_built" || s.starts_with("AsBuilt") || s == "as_built_oracle")
    {
        return Some("as_built");
    }
    None
}

/// Whether a use in file `rel` (under engine/src) sits in a product reader (see the module's doc).
fn is_product_reader(rel: &str, u: &Use) -> bool {
    let Some(name) = rel.strip_prefix("io/") else {
        return false;
    };
    let file = name.rsplit('/').next().unwrap_or(name);
    [
        "analysis_input.rs",
        "readout_header.rs",
        "sequence_view.rs",
        "sky_reference.rs",
    ]
    .contains(&name)
        || file.starts_with("read")
        || u.func
            .as_deref()
            .is_some_and(|f| f.starts_with("read") && !f.starts_with("read_truth"))
}

/// Whether the forbidden items' rule applies to a use in file `rel`: the analysis, the solution and the product
/// readers.
fn rule_applies(rel: &str, u: &Use) -> bool {
    rel.starts_with("analysis/") || rel.starts_with("solution/") || is_product_reader(rel, u)
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

/// Every file of engine/src: its path relative to it (with `/`) and its uses.
fn engine_uses() -> Vec<(String, FileUses)> {
    let src = root().join("engine/src");
    let mut files = Vec::new();
    rust_files(&src, &mut files);
    files.sort();
    files
        .iter()
        .map(|f| {
            let rel = f.strip_prefix(&src).expect("under engine/src");
            let text = std::fs::read_to_string(f).expect("read");
            let key = rel
                .components()
                .map(|c| c.as_os_str().to_string_lossy().to_string())
                .collect::<Vec<_>>()
                .join("/");
            (key, file_uses(rel, &text))
        })
        .collect()
}

#[test]
fn the_engine_follows_its_documented_layers_without_cycles() {
    let layer = layers();
    let all = engine_uses();
    let tops = |rel: &str| module_path(Path::new(rel)).and_then(|m| m.first().cloned());
    let on_disk: BTreeSet<String> = all.iter().filter_map(|(rel, _)| tops(rel)).collect();
    let documented: BTreeSet<String> = layer.keys().cloned().collect();
    assert_eq!(
        on_disk, documented,
        "the engine's top-level modules and docs/ARCHITECTURE.md's layer table differ"
    );
    let mut edges: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    let mut simulate_users = BTreeSet::new();
    let mut wrong = BTreeSet::new();
    for (rel, fu) in &all {
        let Some(m) = tops(rel) else {
            continue;
        };
        for u in &fu.uses {
            let Some(t) = u.top().filter(|t| documented.contains(t) && *t != m) else {
                continue;
            };
            if layer[&t] > layer[&m] {
                wrong.insert(format!(
                    "{rel}:{} (layer {}) uses {t} (layer {}): {}",
                    u.line,
                    layer[&m],
                    layer[&t],
                    u.path.join("::")
                ));
            }
            // the analysis sees neither the simulator nor the truth (the scoring, a later layer, reads it)
            if (m == "analysis" || m == "solution")
                && ["simulate", "session", "studies", "truth"].contains(&t.as_str())
            {
                simulate_users.insert(format!("{rel}:{}: {}", u.line, u.path.join("::")));
            }
            edges.entry(m.clone()).or_default().insert(t);
        }
    }
    assert!(
        wrong.is_empty(),
        "uses against the layers:\n{}",
        wrong.into_iter().collect::<Vec<_>>().join("\n")
    );
    let top_cycles = elementary_cycles(&edges);
    assert!(
        top_cycles.is_empty(),
        "import cycles between top-level modules: {top_cycles:?}"
    );
    assert!(
        simulate_users.is_empty(),
        "the analysis must see neither the simulator nor the truth (docs/ARCHITECTURE.md): {simulate_users:?}"
    );
}

/// The modules inside each top-level module (files and inline `mod`s) and the code uses between them: from →
/// to → where (file:line). A use counts toward the module holding the item (the longest module path that is a
/// prefix of the used path). Left out: doc links (a reference for the reader, not a dependency of the code)
/// and uses between a module and its own submodules (a `mod.rs` declares and re-exports its children, the
/// children use its items through `super`: one unit).
fn intra_module_edges(
    all: &[(String, FileUses)],
) -> BTreeMap<String, BTreeMap<String, Vec<String>>> {
    let mut modules: BTreeSet<Vec<String>> = BTreeSet::new();
    for (rel, fu) in all {
        if let Some(m) = module_path(Path::new(rel)) {
            modules.insert(m);
        }
        modules.extend(fu.inline_mods.iter().cloned());
    }
    let mut edges: BTreeMap<String, BTreeMap<String, Vec<String>>> = BTreeMap::new();
    for (rel, fu) in all {
        for u in fu.uses.iter().filter(|u| u.resolved && !u.doc) {
            if u.from.is_empty() || u.path.first() != u.from.first() {
                continue;
            }
            let Some(to) = (1..=u.path.len())
                .rev()
                .map(|k| &u.path[..k])
                .find(|p| modules.contains(*p))
            else {
                continue;
            };
            if to.starts_with(&u.from) || u.from.starts_with(to) {
                continue;
            }
            edges
                .entry(u.from.join("::"))
                .or_default()
                .entry(to.join("::"))
                .or_default()
                .push(format!("{rel}:{}", u.line));
        }
    }
    edges
}

/// The elementary cycles of a graph, each written from its smallest node (`a → b → a`), sorted.
fn elementary_cycles(edges: &BTreeMap<String, BTreeSet<String>>) -> Vec<String> {
    fn walk(
        start: &str,
        v: &str,
        edges: &BTreeMap<String, BTreeSet<String>>,
        path: &mut Vec<String>,
        out: &mut Vec<String>,
    ) {
        for w in edges.get(v).into_iter().flatten() {
            if w == start {
                out.push(format!("{} → {start}", path.join(" → ")));
            } else if w.as_str() > start && !path.contains(w) && out.len() < 1000 {
                path.push(w.clone());
                walk(start, w, edges, path, out);
                path.pop();
            }
        }
    }
    let mut out = Vec::new();
    for v in edges.keys() {
        walk(v, v, edges, &mut vec![v.clone()], &mut out);
    }
    out.sort();
    out
}

#[test]
fn the_files_inside_each_module_use_each_other_without_new_cycles() {
    let all = engine_uses();
    let detail = intra_module_edges(&all);
    let edges: BTreeMap<String, BTreeSet<String>> = detail
        .iter()
        .map(|(f, t)| (f.clone(), t.keys().cloned().collect()))
        .collect();
    let found = elementary_cycles(&edges);
    let found_set: BTreeSet<&str> = found.iter().map(String::as_str).collect();
    let known: BTreeSet<&str> = KNOWN_CYCLES.iter().copied().collect();
    let new: Vec<&&str> = found_set.difference(&known).collect();
    let gone: Vec<&&str> = known.difference(&found_set).collect();
    let mut explain = String::new();
    for c in &new {
        explain.push_str(&format!("cycle {c}:\n"));
        let nodes: Vec<&str> = c.split(" → ").collect();
        for w in nodes.windows(2) {
            let at = &detail[w[0]][w[1]];
            explain.push_str(&format!("  {} → {} at {}\n", w[0], w[1], at.join(", ")));
        }
    }
    assert!(
        new.is_empty() && gone.is_empty(),
        "intra-module import cycles: new {new:?}, fixed (remove from KNOWN_CYCLES) {gone:?}\n{explain}"
    );
}

#[test]
fn the_analysis_and_the_product_readers_name_no_truth_simulator_or_as_built_instrument() {
    let all = engine_uses();
    let mut found: BTreeMap<(String, &str), Vec<String>> = BTreeMap::new();
    for (rel, fu) in &all {
        for u in &fu.uses {
            if let Some(item) = forbidden(u).filter(|_| rule_applies(rel, u)) {
                found.entry((rel.clone(), item)).or_default().push(format!(
                    "{}: {}",
                    u.line,
                    u.path.join("::")
                ));
            }
        }
    }
    let known: BTreeSet<(String, &str)> = KNOWN_FORBIDDEN
        .iter()
        .map(|(f, i, _)| (f.to_string(), *i))
        .collect();
    let new: Vec<String> = found
        .iter()
        .filter(|(k, _)| !known.contains(k))
        .map(|((f, i), at)| format!("{f} names {i} (lines {})", at.join(", ")))
        .collect();
    let gone: Vec<&(String, &str)> = known.iter().filter(|k| !found.contains_key(*k)).collect();
    assert!(
        new.is_empty() && gone.is_empty(),
        "forbidden items in the analysis or a product reader (docs/ARCHITECTURE.md):\nnew:\n{}\nfixed (remove from KNOWN_FORBIDDEN): {gone:?}",
        new.join("\n")
    );
}

/// The top-level modules and forbidden items a fixture source at `rel` (under engine/src) uses.
fn fixture(rel: &str, text: &str) -> (BTreeSet<String>, BTreeSet<&'static str>) {
    let fu = file_uses(Path::new(rel), text);
    let tops = fu.uses.iter().filter_map(Use::top).collect();
    let items = fu.uses.iter().filter_map(forbidden).collect();
    (tops, items)
}

#[test]
fn the_checker_finds_the_truth_however_it_is_written() {
    let cases = [
        (
            "analysis/x.rs",
            "use crate::{config::Config, truth::TruthRow};",
        ),
        (
            "analysis/x.rs",
            "use crate::{config::{self, Config}, truth};",
        ),
        ("analysis/x/mod.rs", "use super::super::truth;"),
        ("analysis/x.rs", "use super::super::truth::TruthRow;"),
        ("analysis/x/y.rs", "use super::super::super::truth;"),
        ("analysis/x.rs", "use crate::truth::*;"),
        (
            "analysis/x.rs",
            "fn f() { let r = crate::truth::TruthRow::default(); }",
        ),
        ("analysis/x.rs", "fn f(r: &crate::truth::TruthRow) {}"),
        (
            "analysis/x.rs",
            "fn f() -> Vec<crate::truth::TruthRow> { Vec::new() }",
        ),
        (
            "analysis/x.rs",
            "use crate::truth as t;\nfn f() { let r = t::TruthRow::default(); }",
        ),
        (
            "analysis/x.rs",
            "use crate::truth;\nfn f() -> truth::TruthRow { todo!() }",
        ),
        (
            "analysis/x.rs",
            "fn f() { match r { crate::truth::Kind::A => {} } }",
        ),
        (
            "analysis/x.rs",
            "fn f() { let v = vec![crate::truth::TruthRow::default()]; }",
        ),
        (
            "analysis/x.rs",
            "mod inner { use super::super::super::truth; }",
        ),
        (
            "bin/jsim/cmd.rs",
            "fn f() { let r = engine::truth::TruthRow::default(); }",
        ),
        (
            "bin/jsim/cmd.rs",
            "use engine::{config::Config, truth::TruthRow};",
        ),
        (
            "analysis/x.rs",
            "//! Compared with [`crate::truth::TruthRow`].",
        ),
    ];
    for (rel, text) in cases {
        let (tops, items) = fixture(rel, text);
        assert!(
            tops.contains("truth"),
            "{rel}: {text}\nnot seen as a use of truth: {tops:?}"
        );
        assert!(
            items.contains("truth"),
            "{rel}: {text}\nnot seen as forbidden: {items:?}"
        );
    }
    // the other forbidden items, and root re-exports
    let (_, items) = fixture("analysis/x.rs", "use crate::simulate::Simulator;");
    assert_eq!(items, BTreeSet::from(["simulate"]));
    let (_, items) = fixture(
        "io/readout_header.rs",
        "fn f(i: &crate::instrument::as_built::Instrument) {}",
    );
    assert_eq!(items, BTreeSet::from(["as_built"]));
    let (_, items) = fixture("io/x.rs", "use crate::config::AsBuiltInstrument;");
    assert_eq!(items, BTreeSet::from(["as_built"]));
    let (_, items) = fixture(
        "analysis/x.rs",
        "fn f(c: &crate::config::Config) { let _ = crate::instrument::realise(c); }",
    );
    assert_eq!(items, BTreeSet::from(["as_built"]));
    let (tops, _) = fixture(
        "scene/x.rs",
        "fn f() -> crate::Result<crate::Config> { todo!() }\nconst V: &str = crate::VERSION;",
    );
    assert_eq!(
        tops,
        BTreeSet::from(["error".to_string(), "config".to_string()])
    );
}

#[test]
fn the_forbidden_items_rule_covers_the_analysis_and_the_product_readers() {
    let text = "fn read_model_psf() { crate::truth::f(); }\nfn write_model_psf() { crate::truth::f(); }\n\
                fn read_truth() { crate::truth::f(); }\nimpl X { fn read(&self) { crate::truth::f(); } }";
    let covered = |rel: &str| -> Vec<bool> {
        let fu = file_uses(Path::new(rel), text);
        fu.uses
            .iter()
            .filter(|u| forbidden(u).is_some())
            .map(|u| rule_applies(rel, u))
            .collect()
    };
    for rel in [
        "analysis/pipeline.rs",
        "solution/solve.rs",
        "analysis/stare_photometry.rs",
        "analysis/lightcurve.rs",
        "io/analysis_input.rs",
        "io/sequence_view.rs",
        "io/readout_header.rs",
        "io/sky_reference.rs",
        "io/read_anything.rs",
    ] {
        assert_eq!(covered(rel), [true; 4], "{rel}");
    }
    assert_eq!(covered("io/instrument.rs"), [true, false, false, true]);
    assert_eq!(covered("scoring/image.rs"), [false; 4]);
    assert_eq!(covered("studies/transit/run.rs"), [false; 4]);
}

#[test]
fn the_checker_skips_tests_comments_and_what_is_not_the_truth() {
    let cases = [
        (
            "analysis/x.rs",
            "#[cfg(test)]\nmod tests {\n    use crate::truth::TruthRow;\n}",
        ),
        (
            "analysis/x.rs",
            "#[cfg(test)]\nuse crate::truth;\nfn f() {}",
        ),
        (
            "analysis/x.rs",
            "#[cfg(all(test, unix))]\nfn g() -> crate::truth::TruthRow { todo!() }",
        ),
        (
            "analysis/x.rs",
            "fn f() {\n    // crate::truth::TruthRow in a comment\n}",
        ),
        ("analysis/x.rs", "/* crate::truth::TruthRow */ fn f() {}"),
        (
            "analysis/x.rs",
            "fn f() { let s = \"crate::truth::TruthRow\"; }",
        ),
        // analysis/x/y.rs: `super::super` is crate::analysis, so this is crate::analysis::truth
        ("analysis/x/y.rs", "use super::super::truth;"),
        (
            "analysis/x.rs",
            "fn f(truth: &[f64]) -> usize { truth.len() }",
        ),
        (
            "analysis/x.rs",
            "fn f() -> my_crate::truth::Thing { todo!() }",
        ),
        // a binary's own `crate::` is not the library's
        ("bin/jsim/cmd.rs", "use crate::truth::Thing;"),
    ];
    for (rel, text) in cases {
        let (tops, items) = fixture(rel, text);
        assert!(
            !tops.contains("truth"),
            "{rel}: {text}\nwrongly seen as a use of truth: {tops:?}"
        );
        assert!(
            items.is_empty(),
            "{rel}: {text}\nwrongly seen as forbidden: {items:?}"
        );
    }
    // a file's module, and `super` from it
    let fu = file_uses(
        Path::new("analysis/epsf/fit.rs"),
        "use super::Epsf;\nuse super::super::crowded::forced;",
    );
    let paths: Vec<String> = fu.uses.iter().map(|u| u.path.join("::")).collect();
    assert_eq!(paths, ["analysis::epsf::Epsf", "analysis::crowded::forced"]);
    let fu = file_uses(
        Path::new("analysis/epsf/mod.rs"),
        "pub mod fit;\npub use fit::fit_star;\nfn f() { smooth::g(); }\nmod smooth {}",
    );
    let paths: Vec<String> = fu.uses.iter().map(|u| u.path.join("::")).collect();
    assert_eq!(
        paths,
        ["analysis::epsf::fit::fit_star", "analysis::epsf::smooth::g"]
    );
}
