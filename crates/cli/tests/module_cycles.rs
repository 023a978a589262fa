//! No circles of modules inside a crate (DESIGN.md, layers): module `a` of a crate may
//! use `crate::b…` only if nothing in `b` reaches back to `a`, directly or through other
//! modules. The test reads every crate's `src/**/*.rs` under `crates/` and `python/src`,
//! extracts each file module's `crate::…` and sibling `super::…` edges, and fails naming
//! every cycle it finds.
//!
//! An edge goes from a file module to the longest known module its path names. Edges to
//! the crate root or to an ancestor of the using module are not counted (a parent declares
//! its children; a child taking its parent's items is not a circle of files), and neither
//! are paths into the using module itself.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// A module path inside one crate, `[]` for the root.
type ModPath = Vec<String>;

/// Replaces comments, string and character literals with spaces, keeping line structure.
fn strip(src: &str) -> String {
    let b: Vec<char> = src.chars().collect();
    let mut out = String::with_capacity(src.len());
    let mut i = 0;
    let blank = |c: char| if c == '\n' { '\n' } else { ' ' };
    while i < b.len() {
        let c = b[i];
        let next = b.get(i + 1).copied();
        if c == '/' && next == Some('/') {
            while i < b.len() && b[i] != '\n' {
                out.push(' ');
                i += 1;
            }
        } else if c == '/' && next == Some('*') {
            let mut depth = 0usize;
            while i < b.len() {
                if b[i] == '/' && b.get(i + 1) == Some(&'*') {
                    depth += 1;
                    out.push_str("  ");
                    i += 2;
                } else if b[i] == '*' && b.get(i + 1) == Some(&'/') {
                    depth -= 1;
                    out.push_str("  ");
                    i += 2;
                    if depth == 0 {
                        break;
                    }
                } else {
                    out.push(blank(b[i]));
                    i += 1;
                }
            }
        } else if c == 'r'
            && (next == Some('"') || next == Some('#'))
            && !b[..i]
                .last()
                .is_some_and(|p| p.is_alphanumeric() || *p == '_')
        {
            // A raw string r"…" or r#"…"#.
            let mut j = i + 1;
            let mut hashes = 0;
            while b.get(j) == Some(&'#') {
                hashes += 1;
                j += 1;
            }
            if b.get(j) != Some(&'"') {
                out.push(c);
                i += 1;
                continue;
            }
            j += 1;
            loop {
                if j >= b.len() {
                    break;
                }
                if b[j] == '"' && (0..hashes).all(|k| b.get(j + 1 + k) == Some(&'#')) {
                    j += 1 + hashes;
                    break;
                }
                j += 1;
            }
            for &ch in &b[i..j.min(b.len())] {
                out.push(blank(ch));
            }
            i = j;
        } else if c == '"' {
            out.push(' ');
            i += 1;
            while i < b.len() && b[i] != '"' {
                if b[i] == '\\' {
                    out.push(' ');
                    i += 1;
                }
                if i < b.len() {
                    out.push(blank(b[i]));
                    i += 1;
                }
            }
            out.push(' ');
            i += 1;
        } else if c == '\'' {
            // A character literal ('a', '\n', '\u{1F}'), not a lifetime ('a).
            let lit_end = if next == Some('\\') {
                (i + 2..b.len().min(i + 12)).find(|&j| b[j] == '\'')
            } else if b.get(i + 2) == Some(&'\'') {
                Some(i + 2)
            } else {
                None
            };
            match lit_end {
                Some(e) => {
                    for _ in i..=e {
                        out.push(' ');
                    }
                    i = e + 1;
                }
                None => {
                    out.push(c);
                    i += 1;
                }
            }
        } else {
            out.push(c);
            i += 1;
        }
    }
    out
}

/// A token: an identifier, `::`, or one punctuation character.
#[derive(Debug, Clone, PartialEq, Eq)]
enum Tok {
    Ident(String),
    Colons,
    Punct(char),
}

fn tokens(src: &str) -> Vec<Tok> {
    let b: Vec<char> = src.chars().collect();
    let mut out = Vec::new();
    let mut i = 0;
    while i < b.len() {
        let c = b[i];
        if c.is_whitespace() {
            i += 1;
        } else if c.is_alphanumeric() || c == '_' {
            let s = i;
            while i < b.len() && (b[i].is_alphanumeric() || b[i] == '_') {
                i += 1;
            }
            out.push(Tok::Ident(b[s..i].iter().collect()));
        } else if c == ':' && b.get(i + 1) == Some(&':') {
            out.push(Tok::Colons);
            i += 2;
        } else {
            out.push(Tok::Punct(c));
            i += 1;
        }
    }
    out
}

/// The paths a `use` tree starting at `toks[*at]` names, each as its segments; stops after
/// the tree (at `;`, `,` or `}` of an enclosing group).
fn use_tree(toks: &[Tok], at: &mut usize, prefix: &[String], out: &mut Vec<Vec<String>>) {
    let mut path = prefix.to_vec();
    loop {
        match toks.get(*at) {
            Some(Tok::Colons) => *at += 1,
            Some(Tok::Ident(id)) if id == "as" => {
                *at += 2;
                out.push(path);
                return;
            }
            Some(Tok::Ident(id)) => {
                path.push(id.clone());
                *at += 1;
            }
            Some(Tok::Punct('{')) => {
                *at += 1;
                loop {
                    match toks.get(*at) {
                        None => return,
                        Some(Tok::Punct('}')) => {
                            *at += 1;
                            return;
                        }
                        Some(Tok::Punct(',')) => *at += 1,
                        _ => use_tree(toks, at, &path, out),
                    }
                }
            }
            Some(Tok::Punct('*')) => {
                *at += 1;
                out.push(path);
                return;
            }
            _ => {
                out.push(path);
                return;
            }
        }
    }
}

/// The module paths (relative to the crate root) a file names through `crate::` and
/// `super::`, given the file's own module path. Each comes with the inline module it was
/// written in, so that `super::` resolves from there.
fn named_paths(src: &str, module: &[String]) -> Vec<ModPath> {
    let toks = tokens(&strip(src));
    // The inline modules open at each point: (module path, brace depth it closes at).
    let mut scopes: Vec<(ModPath, usize)> = vec![(module.to_vec(), 0)];
    let mut depth = 0usize;
    let mut out = Vec::new();
    let mut i = 0;
    let resolve = |first: &str, rest: &[String], here: &ModPath| -> Option<ModPath> {
        let mut base: ModPath = match first {
            "crate" => Vec::new(),
            "super" => {
                let mut b = here.clone();
                b.pop()?;
                b
            }
            "self" => here.clone(),
            _ => return None,
        };
        let mut rest = rest;
        while let Some(seg) = rest.first() {
            if seg == "super" {
                base.pop()?;
            } else if seg != "self" {
                break;
            }
            rest = &rest[1..];
        }
        base.extend(rest.iter().cloned());
        Some(base)
    };
    while i < toks.len() {
        let here = scopes.last().map(|s| s.0.clone()).unwrap_or_default();
        match &toks[i] {
            Tok::Punct('{') => {
                depth += 1;
                i += 1;
            }
            Tok::Punct('}') => {
                depth = depth.saturating_sub(1);
                if scopes.len() > 1 && scopes.last().is_some_and(|s| s.1 == depth) {
                    scopes.pop();
                }
                i += 1;
            }
            Tok::Ident(kw) if kw == "mod" => {
                if let (Some(Tok::Ident(name)), Some(Tok::Punct('{'))) =
                    (toks.get(i + 1), toks.get(i + 2))
                {
                    let mut inner = here.clone();
                    inner.push(name.clone());
                    scopes.push((inner, depth));
                    depth += 1;
                    i += 3;
                } else {
                    i += 1;
                }
            }
            Tok::Ident(kw) if kw == "use" => {
                i += 1;
                let mut trees = Vec::new();
                use_tree(&toks, &mut i, &[], &mut trees);
                for t in trees {
                    if let Some((first, rest)) = t.split_first()
                        && let Some(p) = resolve(first, rest, &here)
                    {
                        out.push(p);
                    }
                }
            }
            Tok::Ident(first)
                if (first == "crate" || first == "super")
                    && toks.get(i + 1) == Some(&Tok::Colons)
                    && !(i > 0 && toks[i - 1] == Tok::Punct('$'))
                    && !(i > 0 && toks[i - 1] == Tok::Colons) =>
            {
                let mut rest = Vec::new();
                let mut j = i + 1;
                while toks.get(j) == Some(&Tok::Colons) {
                    match toks.get(j + 1) {
                        Some(Tok::Ident(s)) => {
                            rest.push(s.clone());
                            j += 2;
                        }
                        _ => break,
                    }
                }
                if let Some(p) = resolve(first, &rest, &here) {
                    out.push(p);
                }
                i = j;
            }
            _ => i += 1,
        }
    }
    out
}

/// The longest module in `known` that `path` starts with.
fn target<'a>(path: &[String], known: &'a BTreeSet<ModPath>) -> Option<&'a ModPath> {
    (0..=path.len())
        .rev()
        .find_map(|n| known.get(&path[..n].to_vec()))
}

/// The edges between a crate's file modules: `files` maps each module to its source.
fn edges(files: &BTreeMap<ModPath, String>) -> BTreeMap<ModPath, BTreeSet<ModPath>> {
    let known: BTreeSet<ModPath> = files.keys().cloned().collect();
    let mut graph: BTreeMap<ModPath, BTreeSet<ModPath>> = BTreeMap::new();
    for (module, src) in files {
        let entry = graph.entry(module.clone()).or_default();
        for p in named_paths(src, module) {
            let Some(t) = target(&p, &known) else {
                continue;
            };
            // The root, an ancestor, or the module itself: not an edge between files.
            if module.starts_with(t) {
                continue;
            }
            entry.insert(t.clone());
        }
    }
    graph
}

/// Every strongly connected set of more than one module, each as a shortest cycle through
/// its first module.
fn cycles(graph: &BTreeMap<ModPath, BTreeSet<ModPath>>) -> Vec<Vec<ModPath>> {
    components(graph)
        .iter()
        .map(|members| {
            let set: BTreeSet<&ModPath> = members.iter().collect();
            cycle_through(graph, &set, &members[0])
        })
        .collect()
}

/// Every strongly connected set of more than one module, its modules sorted.
fn components(graph: &BTreeMap<ModPath, BTreeSet<ModPath>>) -> Vec<Vec<ModPath>> {
    // Tarjan's strongly connected components; module graphs are shallow enough to recurse.
    struct State<'g> {
        graph: &'g BTreeMap<ModPath, BTreeSet<ModPath>>,
        index: BTreeMap<&'g ModPath, usize>,
        low: BTreeMap<&'g ModPath, usize>,
        stack: Vec<&'g ModPath>,
        on_stack: BTreeSet<&'g ModPath>,
        next: usize,
        sccs: Vec<Vec<&'g ModPath>>,
    }
    fn visit<'g>(s: &mut State<'g>, v: &'g ModPath) {
        s.index.insert(v, s.next);
        s.low.insert(v, s.next);
        s.next += 1;
        s.stack.push(v);
        s.on_stack.insert(v);
        if let Some(ws) = s.graph.get(v) {
            for w in ws {
                let Some((w, _)) = s.graph.get_key_value(w) else {
                    continue;
                };
                if !s.index.contains_key(w) {
                    visit(s, w);
                    let lw = s.low[w];
                    let lv = s.low[v];
                    s.low.insert(v, lv.min(lw));
                } else if s.on_stack.contains(w) {
                    let iw = s.index[w];
                    let lv = s.low[v];
                    s.low.insert(v, lv.min(iw));
                }
            }
        }
        if s.low[v] == s.index[v] {
            let mut scc = Vec::new();
            while let Some(w) = s.stack.pop() {
                s.on_stack.remove(w);
                scc.push(w);
                if w == v {
                    break;
                }
            }
            s.sccs.push(scc);
        }
    }
    let mut s = State {
        graph,
        index: BTreeMap::new(),
        low: BTreeMap::new(),
        stack: Vec::new(),
        on_stack: BTreeSet::new(),
        next: 0,
        sccs: Vec::new(),
    };
    for v in graph.keys() {
        if !s.index.contains_key(v) {
            visit(&mut s, v);
        }
    }
    let mut out: Vec<Vec<ModPath>> = s
        .sccs
        .into_iter()
        .filter(|c| c.len() > 1)
        .map(|c| {
            let mut members: Vec<ModPath> = c.into_iter().cloned().collect();
            members.sort();
            members
        })
        .collect();
    out.sort();
    out
}

/// A shortest cycle from `start` back to itself inside `members`.
fn cycle_through(
    graph: &BTreeMap<ModPath, BTreeSet<ModPath>>,
    members: &BTreeSet<&ModPath>,
    start: &ModPath,
) -> Vec<ModPath> {
    let mut prev: BTreeMap<ModPath, ModPath> = BTreeMap::new();
    let mut queue = std::collections::VecDeque::from([start.clone()]);
    while let Some(v) = queue.pop_front() {
        for w in graph.get(&v).into_iter().flatten() {
            if !members.contains(w) {
                continue;
            }
            if w == start {
                let mut path = vec![v.clone()];
                let mut at = v.clone();
                while let Some(p) = prev.get(&at) {
                    path.push(p.clone());
                    at = p.clone();
                }
                path.reverse();
                return path;
            }
            if !prev.contains_key(w) && w != start {
                prev.insert(w.clone(), v.clone());
                queue.push_back(w.clone());
            }
        }
    }
    vec![start.clone()]
}

/// The module path of a source file below `src`.
fn module_of(src: &Path, file: &Path) -> Option<ModPath> {
    let rel = file.strip_prefix(src).ok()?;
    let mut parts: Vec<String> = rel
        .iter()
        .map(|p| p.to_string_lossy().into_owned())
        .collect();
    let last = parts.pop()?;
    let stem = last.strip_suffix(".rs")?;
    if !matches!(stem, "lib" | "main" | "mod") || !parts.is_empty() && stem != "mod" {
        parts.push(stem.to_owned());
    }
    Some(parts)
}

fn rs_files(dir: &Path, out: &mut Vec<PathBuf>) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    let mut entries: Vec<_> = entries.filter_map(Result::ok).map(|e| e.path()).collect();
    entries.sort();
    for p in entries {
        if p.is_dir() {
            // A `src/bin` folder holds separate crates.
            if p.file_name().is_some_and(|n| n != "bin") {
                rs_files(&p, out);
            }
        } else if p.extension().is_some_and(|e| e == "rs") {
            out.push(p);
        }
    }
}

/// The module graph of the crate whose sources are in `src`.
fn crate_graph(src: &Path) -> BTreeMap<ModPath, BTreeSet<ModPath>> {
    let mut files = Vec::new();
    rs_files(src, &mut files);
    let mut modules = BTreeMap::new();
    for f in files {
        let Some(m) = module_of(src, &f) else {
            continue;
        };
        let text = std::fs::read_to_string(&f).unwrap_or_else(|e| panic!("{}: {e}", f.display()));
        modules.insert(m, text);
    }
    edges(&modules)
}

fn show(m: &ModPath) -> String {
    if m.is_empty() {
        "crate".into()
    } else {
        m.join("::")
    }
}

#[test]
fn no_module_cycles_in_any_crate() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let mut srcs: Vec<PathBuf> = std::fs::read_dir(root.join("crates"))
        .expect("the crates folder")
        .filter_map(Result::ok)
        .map(|e| e.path().join("src"))
        .filter(|p| p.is_dir())
        .collect();
    srcs.push(root.join("python/src"));
    srcs.sort();
    let mut found = Vec::new();
    for src in &srcs {
        let name = src
            .parent()
            .and_then(Path::file_name)
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        let graph = crate_graph(src);
        for members in components(&graph) {
            let set: BTreeSet<&ModPath> = members.iter().collect();
            let cycle = cycle_through(&graph, &set, &members[0]);
            let mut names: Vec<String> = cycle.iter().map(show).collect();
            names.push(show(&cycle[0]));
            let all: Vec<String> = members.iter().map(show).collect();
            found.push(format!(
                "{name}: {} (the circle's modules: {})",
                names.join(" -> "),
                all.join(", ")
            ));
        }
    }
    assert!(
        found.is_empty(),
        "modules that reach each other:\n  {}",
        found.join("\n  ")
    );
}

#[cfg(test)]
mod extractor {
    use super::*;

    fn crate_of(files: &[(&str, &str)]) -> BTreeMap<ModPath, String> {
        files
            .iter()
            .map(|(m, s)| {
                let path = if m.is_empty() {
                    Vec::new()
                } else {
                    m.split("::").map(str::to_owned).collect()
                };
                (path, (*s).to_owned())
            })
            .collect()
    }

    fn p(s: &str) -> ModPath {
        s.split("::").map(str::to_owned).collect()
    }

    #[test]
    fn a_two_module_cycle_is_found() {
        let files = crate_of(&[
            ("", "mod a; mod b;"),
            ("a", "use crate::b::Thing;\npub struct Other;"),
            (
                "b",
                "pub struct Thing;\nfn f() -> crate::a::Other { todo() }",
            ),
        ]);
        assert_eq!(cycles(&edges(&files)), vec![vec![p("a"), p("b")]]);
    }

    #[test]
    fn grouped_uses_and_sibling_super_paths_are_edges() {
        let files = crate_of(&[
            ("", "mod a; mod b; mod c;"),
            ("a", "use crate::{b::{X, Y}, c as see};"),
            ("b", ""),
            ("c", ""),
            ("c::d", "use super::super::a::Z;"),
            ("c::e", "use super::d; use super::Parent;"),
        ]);
        let g = edges(&files);
        assert_eq!(g[&p("a")], [p("b"), p("c")].into_iter().collect());
        assert_eq!(g[&p("c::d")], [p("a")].into_iter().collect());
        assert_eq!(g[&p("c::e")], [p("c::d")].into_iter().collect());
        // c::d -> a -> c is a cycle only if a reaches c::d: it reaches c, d's parent.
        assert!(cycles(&g).is_empty());
    }

    #[test]
    fn a_longer_cycle_is_found_and_a_child_does_not_close_it() {
        let files = crate_of(&[
            ("", "mod a; mod b; mod c;"),
            ("a", "mod x; pub fn f() { crate::b::g() }"),
            ("a::x", "pub fn h() {}"),
            ("b", "pub fn g() { crate::c::k() }"),
            ("c", "use crate::a::x::h;\npub fn k() {}"),
        ]);
        // c reaches a's child x, which reaches nothing: no cycle yet.
        assert!(cycles(&edges(&files)).is_empty());
        let mut files = files;
        files.insert(p("a::x"), "pub fn h() { super::super::c::k() }".into());
        files.insert(p("c"), "pub fn k() { crate::a::f() }".into());
        assert_eq!(cycles(&edges(&files)), vec![vec![p("a"), p("b"), p("c")]]);
    }

    #[test]
    fn no_cycle_when_edges_go_one_way() {
        let files = crate_of(&[
            ("", "pub use a::A; mod a; mod b;"),
            ("a", "use crate::b; use crate::A as _;"),
            (
                "b",
                "use crate::A; // use crate::a::x;\nconst S: &str = \"crate::a::x\";",
            ),
        ]);
        let g = edges(&files);
        assert_eq!(g[&p("a")], [p("b")].into_iter().collect());
        assert!(g[&p("b")].is_empty());
        assert!(cycles(&g).is_empty());
    }

    #[test]
    fn super_in_an_inline_module_names_its_file() {
        let files = crate_of(&[
            ("", "mod a; mod b;"),
            (
                "a",
                "pub fn f() {}\n#[cfg(test)]\nmod tests {\n    use super::*;\n    use crate::b::g;\n}",
            ),
            ("b", "pub fn g() {}"),
        ]);
        let g = edges(&files);
        assert_eq!(g[&p("a")], [p("b")].into_iter().collect());
        assert!(cycles(&g).is_empty());
    }

    #[test]
    fn file_paths_become_module_paths() {
        let src = Path::new("/x/src");
        assert_eq!(module_of(src, Path::new("/x/src/lib.rs")), Some(vec![]));
        assert_eq!(module_of(src, Path::new("/x/src/a.rs")), Some(p("a")));
        assert_eq!(module_of(src, Path::new("/x/src/a/mod.rs")), Some(p("a")));
        assert_eq!(module_of(src, Path::new("/x/src/a/b.rs")), Some(p("a::b")));
        assert_eq!(
            module_of(src, Path::new("/x/src/a/lib.rs")),
            Some(p("a::lib"))
        );
    }
}
