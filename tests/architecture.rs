//! The layout rules of the crate, checked on the source text: no import cycle between
//! library files, no file over 900 lines, no printing from the library (outside the
//! viewer's own log), no benchmarks in the library.
//!
//! An import is any `crate::…`, `super::…` or `self::…` path, in a `use` or inline, and
//! a `use` of a child module; it points at the file that defines the longest prefix of
//! the path. Re-exports (`pub use`, `pub(crate) use`) are a module's facade, not a
//! dependency of its code, and are left out, except where the file's own code uses a
//! name it re-exports (`pub use orient::Orientation;` and then `Orientation::…` in the
//! same file imports `orient`); so is `#[cfg(test)]` code. `$crate::…` paths in a
//! `macro_rules!` body are left out too: they are code of the files that expand the
//! macro, not of the file that defines it.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

const MAX_LINES: usize = 900;

fn src() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("src")
}

/// Every `.rs` file below `dir`, relative to `src/`.
fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for e in entries.flatten() {
        let p = e.path();
        if p.is_dir() {
            rust_files(&p, out);
        } else if p.extension().is_some_and(|x| x == "rs") {
            out.push(p.strip_prefix(src()).unwrap_or(&p).to_path_buf());
        }
    }
}

/// The module path of a library file: `render/gpu.rs` → [render, gpu].
fn module_of(file: &Path) -> Vec<String> {
    let mut parts: Vec<String> = file
        .with_extension("")
        .iter()
        .map(|c| c.to_string_lossy().into_owned())
        .collect();
    if matches!(parts.last().map(String::as_str), Some("mod" | "lib")) {
        parts.pop();
    }
    parts
}

/// The code of a file without comments, string contents and `#[cfg(test)]` items.
fn code_of(text: &str) -> String {
    let text = match text.find("#[cfg(test)]") {
        Some(i) => &text[..i],
        None => text,
    };
    let mut out = String::with_capacity(text.len());
    for line in text.lines() {
        let line = match line.find("//") {
            Some(i) => &line[..i],
            None => line,
        };
        out.push_str(line);
        out.push('\n');
    }
    // Drop string literals (paths in messages are not imports).
    let mut clean = String::with_capacity(out.len());
    let mut in_str = false;
    let mut prev = ' ';
    for c in out.chars() {
        if c == '"' && prev != '\\' && prev != '\'' {
            in_str = !in_str;
            clean.push('"');
        } else if !in_str {
            clean.push(c);
        }
        prev = c;
    }
    clean
}

/// `a::{b, c::{d}}` → [a::b, a::c::d].
fn expand(tree: &str) -> Vec<String> {
    let tree = tree.trim();
    let Some(open) = tree.find('{') else {
        return vec![tree.to_owned()];
    };
    let prefix = &tree[..open];
    let inner = &tree[open + 1..tree.rfind('}').unwrap_or(tree.len())];
    let (mut parts, mut depth, mut cur) = (Vec::new(), 0, String::new());
    for c in inner.chars() {
        match c {
            '{' => depth += 1,
            '}' => depth -= 1,
            _ => {}
        }
        if c == ',' && depth == 0 {
            parts.push(std::mem::take(&mut cur));
        } else {
            cur.push(c);
        }
    }
    parts.push(cur);
    parts
        .iter()
        .filter(|p| !p.trim().is_empty())
        .flat_map(|p| expand(p).into_iter().map(move |x| format!("{prefix}{x}")))
        .collect()
}

/// Paths starting with `crate`, `super`, `self` or one of the module's `children` in
/// `code` (outside `use` items): `slicing::Slicing` in `gpu/mod.rs` is an import of
/// `gpu/slicing.rs`.
fn inline_paths(code: &str, children: &BTreeSet<String>) -> Vec<String> {
    let mut out = Vec::new();
    let bytes = code.as_bytes();
    let starts = ["crate", "super", "self"]
        .into_iter()
        .map(str::to_owned)
        .chain(children.iter().cloned())
        .map(|s| format!("{s}::"));
    for start in starts {
        let start = start.as_str();
        let mut from = 0;
        while let Some(i) = code[from..].find(start) {
            let i = from + i;
            from = i + start.len();
            // Not the tail of a longer name or path (`crate::render::reuse::` is found
            // as a whole from `crate::`), and not `$crate::` in a macro body: the
            // expansion's path, an import of the file the macro expands in.
            if i > 0
                && (bytes[i - 1].is_ascii_alphanumeric()
                    || matches!(bytes[i - 1], b'_' | b':' | b'$'))
            {
                continue;
            }
            let end = code[i..]
                .find(|c: char| !(c.is_ascii_alphanumeric() || c == '_' || c == ':'))
                .map_or(code.len(), |e| i + e);
            out.push(code[i..end].trim_end_matches(':').to_owned());
        }
    }
    out
}

/// The re-exported paths of `reexports` whose names `code` uses by themselves (not
/// as a field, a method or the tail of a path): `orient::Orientation` when `code`
/// holds `Orientation::from_spacing`.
fn reexports_used(reexports: &[String], code: &str) -> Vec<String> {
    let ident = |c: char| c.is_ascii_alphanumeric() || c == '_';
    let used = |name: &str| {
        code.match_indices(name).any(|(i, _)| {
            let before = code[..i].chars().next_back();
            let after = code[i + name.len()..].chars().next();
            !before.is_some_and(|c| ident(c) || c == ':' || c == '.') && !after.is_some_and(ident)
        })
    };
    reexports
        .iter()
        .filter(|p| {
            let name = match p.split_once(" as ") {
                Some((_, alias)) => alias,
                None => p.rsplit("::").next().unwrap_or(p),
            };
            let name = name.trim();
            !matches!(name, "*" | "self" | "_" | "") && used(name)
        })
        .cloned()
        .collect()
}

struct Crate {
    /// Module path → file.
    files: BTreeMap<Vec<String>, PathBuf>,
}

impl Crate {
    fn resolve(&self, path: &[String]) -> Option<&PathBuf> {
        (0..=path.len())
            .rev()
            .find_map(|n| self.files.get(&path[..n]))
    }

    /// The absolute module path of `segments` as written in module `here`.
    fn absolute(
        &self,
        here: &[String],
        children: &BTreeSet<String>,
        segments: &[&str],
    ) -> Option<Vec<String>> {
        let segs: Vec<&str> = segments
            .iter()
            .map(|s| s.trim())
            .filter(|s| !s.is_empty())
            .collect();
        let first = *segs.first()?;
        let owned = |s: &[&str]| s.iter().map(|x| x.to_string()).collect::<Vec<_>>();
        match first {
            "crate" => Some(owned(&segs[1..])),
            "self" => Some([here.to_vec(), owned(&segs[1..])].concat()),
            "super" => {
                let mut base = here.to_vec();
                let mut rest = &segs[..];
                while rest.first() == Some(&"super") {
                    base.pop();
                    rest = &rest[1..];
                }
                Some([base, owned(rest)].concat())
            }
            child if children.contains(child) => Some([here.to_vec(), owned(&segs)].concat()),
            _ => None,
        }
    }
}

/// The library's files (everything in `src/` but the binary) and what each imports.
fn import_graph() -> BTreeMap<PathBuf, BTreeSet<PathBuf>> {
    let mut all = Vec::new();
    rust_files(&src(), &mut all);
    all.retain(|f| !f.starts_with("bin") && f != Path::new("main.rs"));
    let krate = Crate {
        files: all.iter().map(|f| (module_of(f), f.clone())).collect(),
    };
    let mut graph = BTreeMap::new();
    for file in &all {
        let text = std::fs::read_to_string(src().join(file)).unwrap_or_default();
        let code = code_of(&text);
        let here = module_of(file);
        let children: BTreeSet<String> = code
            .lines()
            .filter_map(|l| {
                let l = l
                    .trim()
                    .trim_start_matches("pub ")
                    .trim_start_matches("pub(crate) ");
                l.strip_prefix("mod ")?.strip_suffix(';').map(str::to_owned)
            })
            .collect();
        let (mut paths, mut reexports, mut rest) = (Vec::new(), Vec::new(), String::new());
        let mut lines = code.lines();
        while let Some(line) = lines.next() {
            let t = line.trim_start();
            let reexport = ["pub use ", "pub(crate) use ", "pub(super) use "]
                .iter()
                .any(|p| t.starts_with(p));
            if !(reexport || t.starts_with("use ")) {
                rest.push_str(line);
                rest.push('\n');
                continue;
            }
            let mut item = t.to_owned();
            while !item.contains(';') {
                match lines.next() {
                    Some(l) => item.push_str(l),
                    None => break,
                }
            }
            let tree = item
                .split_once("use ")
                .map_or("", |(_, t)| t)
                .split(';')
                .next()
                .unwrap_or("");
            if reexport {
                reexports.extend(expand(tree));
            } else {
                paths.extend(expand(tree));
            }
        }
        paths.extend(inline_paths(&rest, &children));
        paths.extend(reexports_used(&reexports, &rest));
        let deps: BTreeSet<PathBuf> = paths
            .iter()
            .filter_map(|p| {
                let p = p.split(" as ").next().unwrap_or(p);
                let segs: Vec<&str> = p.split("::").collect();
                krate.absolute(&here, &children, &segs)
            })
            .filter_map(|abs| krate.resolve(&abs).cloned())
            .filter(|d| d != file)
            .collect();
        graph.insert(file.clone(), deps);
    }
    graph
}

/// Strongly connected components with more than one file (Tarjan).
fn cycles(graph: &BTreeMap<PathBuf, BTreeSet<PathBuf>>) -> Vec<Vec<PathBuf>> {
    struct State<'a> {
        graph: &'a BTreeMap<PathBuf, BTreeSet<PathBuf>>,
        index: BTreeMap<&'a PathBuf, usize>,
        low: BTreeMap<&'a PathBuf, usize>,
        stack: Vec<&'a PathBuf>,
        found: Vec<Vec<PathBuf>>,
    }
    fn visit<'a>(s: &mut State<'a>, v: &'a PathBuf) {
        let n = s.index.len();
        s.index.insert(v, n);
        s.low.insert(v, n);
        s.stack.push(v);
        for w in s.graph.get(v).into_iter().flatten() {
            if !s.index.contains_key(w) {
                visit(s, w);
                let lw = s.low[w];
                let lv = s.low.get_mut(v).expect("visited");
                *lv = (*lv).min(lw);
            } else if s.stack.contains(&w) {
                let iw = s.index[w];
                let lv = s.low.get_mut(v).expect("visited");
                *lv = (*lv).min(iw);
            }
        }
        if s.low[v] == s.index[v] {
            let mut component = Vec::new();
            while let Some(w) = s.stack.pop() {
                component.push(w.clone());
                if w == v {
                    break;
                }
            }
            if component.len() > 1 {
                s.found.push(component);
            }
        }
    }
    let mut s = State {
        graph,
        index: BTreeMap::new(),
        low: BTreeMap::new(),
        stack: Vec::new(),
        found: Vec::new(),
    };
    for v in graph.keys() {
        if !s.index.contains_key(v) {
            visit(&mut s, v);
        }
    }
    s.found
}

#[test]
fn no_import_cycle_between_library_files() {
    let graph = import_graph();
    assert!(graph.len() > 40, "found only {} library files", graph.len());
    // The checker itself must see imports: render/gpu_volume.rs uses the texels, and
    // gpu/mod.rs names gpu/slicing.rs by a bare child path (`slicing::Slicing`).
    for (from, to) in [
        ("render/gpu_volume.rs", "texels/mod.rs"),
        ("gpu/mod.rs", "gpu/slicing.rs"),
    ] {
        assert!(
            graph[Path::new(from)].contains(Path::new(to)),
            "the import parser missed {from} → {to}"
        );
    }
    let found = cycles(&graph);
    let report: Vec<String> = found
        .iter()
        .map(|c| {
            let edges: Vec<String> = c
                .iter()
                .flat_map(|a| {
                    graph[a]
                        .iter()
                        .filter(|b| c.contains(b))
                        .map(move |b| format!("{} → {}", a.display(), b.display()))
                })
                .collect();
            edges.join(", ")
        })
        .collect();
    assert!(found.is_empty(), "import cycles:\n{}", report.join("\n"));
}

#[test]
fn the_cycle_checker_finds_a_cycle() {
    let a = PathBuf::from("a.rs");
    let b = PathBuf::from("b.rs");
    let graph = BTreeMap::from([
        (a.clone(), BTreeSet::from([b.clone()])),
        (b.clone(), BTreeSet::from([a.clone()])),
    ]);
    assert_eq!(cycles(&graph).len(), 1);
    assert_eq!(expand("a::{b, c::{d, e}}"), ["a::b", "a::c::d", "a::c::e"]);
    // A bare path through a child module is an import of that child, wherever it
    // stands; the tail of a longer path or name is not.
    let children = BTreeSet::from(["reuse".to_owned()]);
    let code = "let n = reuse::MAX_BALLS; let m = crate::render::reuse::X; let k = nonreuse::Y;";
    assert_eq!(
        inline_paths(code, &children),
        ["crate::render::reuse::X", "reuse::MAX_BALLS"]
    );
    // A re-exported name the file uses itself is an import; one it only hands on, or
    // whose name appears only as a method, a field or a longer path, is not.
    let reexports = ["orient::Orientation", "raw::{Endian}", "stats::Stats as S"]
        .iter()
        .flat_map(|t| expand(t))
        .collect::<Vec<_>>();
    let code = "let o = Orientation::new(); s.Endian; other::S; $crate::volume::X";
    assert_eq!(reexports_used(&reexports, code), ["orient::Orientation"]);
    assert!(inline_paths(code, &BTreeSet::new()).is_empty());
}

#[test]
fn no_source_file_over_900_lines() {
    let mut all = Vec::new();
    rust_files(&src(), &mut all);
    let long: Vec<String> = all
        .iter()
        .filter_map(|f| {
            let n = std::fs::read_to_string(src().join(f)).ok()?.lines().count();
            (n > MAX_LINES).then(|| format!("{} ({n} lines)", f.display()))
        })
        .collect();
    assert!(long.is_empty(), "files over {MAX_LINES} lines: {long:?}");
}

#[test]
fn the_library_prints_nothing_and_holds_no_benchmarks() {
    let mut all = Vec::new();
    rust_files(&src(), &mut all);
    let printing: Vec<String> = all
        .iter()
        .filter(|f| !f.starts_with("bin") && !f.starts_with("app") && *f != Path::new("main.rs"))
        .filter(|f| {
            let code = code_of(&std::fs::read_to_string(src().join(f)).unwrap_or_default());
            code.contains("println!") || code.contains("print!(")
        })
        .map(|f| f.display().to_string())
        .collect();
    assert!(
        printing.is_empty(),
        "library files that print: {printing:?}"
    );
    let lib = std::fs::read_to_string(src().join("lib.rs")).unwrap_or_default();
    assert!(
        !lib.contains("pub mod bench"),
        "lib.rs declares a benchmark module"
    );
}
