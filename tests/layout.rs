//! The tree as the house keeps it: no source file over 800 lines, and the
//! library's modules importing one way (no circle between modules that are
//! not one inside the other). What `farm-studio look` checks, here on every
//! test run.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

fn sources(dir: &Path, out: &mut Vec<PathBuf>) {
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.is_dir() {
            sources(&path, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
}

#[test]
fn no_source_file_is_over_800_lines() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut files = Vec::new();
    for dir in ["src", "tests", "benches"] {
        sources(&root.join(dir), &mut files);
    }
    let long: Vec<String> = (files.iter())
        .map(|f| (f, std::fs::read_to_string(f).unwrap().lines().count()))
        .filter(|(_, n)| *n > 800)
        .map(|(f, n)| format!("{} ({n} lines)", f.display()))
        .collect();
    assert!(long.is_empty(), "over 800 lines: {long:?}");
}

/// The library's modules (`a::b`) and the modules each names, from its
/// code (not its comments or its tests).
fn module_graph() -> BTreeMap<String, Vec<String>> {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut files = Vec::new();
    sources(&src, &mut files);
    let mut text: BTreeMap<String, String> = BTreeMap::new();
    for f in files {
        let rel = f.strip_prefix(&src).unwrap().with_extension("");
        let mut parts: Vec<String> = rel
            .iter()
            .map(|p| p.to_string_lossy().into_owned())
            .collect();
        if parts[0] == "bin" || parts.last().is_some_and(|p| p == "tests") || parts == ["lib"] {
            continue;
        }
        if parts.last().is_some_and(|p| p == "mod") {
            parts.pop();
        }
        let code = std::fs::read_to_string(&f).unwrap();
        let code = code.split("#[cfg(test)]").next().unwrap_or("");
        let code: String = (code.lines())
            .filter(|l| !l.trim_start().starts_with("//"))
            .collect::<Vec<_>>()
            .join("\n");
        text.insert(parts.join("::"), code);
    }
    let names: Vec<String> = text.keys().cloned().collect();
    let resolve = |path: &str| {
        let segs: Vec<&str> = path.split("::").collect();
        (1..=segs.len())
            .rev()
            .map(|n| segs[..n].join("::"))
            .find(|k| text.contains_key(k))
    };
    let mut graph = BTreeMap::new();
    for (module, code) in &text {
        let mut named = Vec::new();
        // `crate::a::b` wherever it is written, and `use crate::{a, b::c}` lists.
        for (i, _) in code.match_indices("crate::") {
            let rest = &code[i + 7..];
            if let Some(list) = rest.strip_prefix('{') {
                let list = &list[..list.find("};").unwrap_or(list.len())];
                named.extend(list.split(',').map(|s| s.trim().to_string()));
            } else {
                let path: String = (rest.chars())
                    .take_while(|c| {
                        c.is_ascii_lowercase() || c.is_ascii_digit() || *c == '_' || *c == ':'
                    })
                    .collect();
                named.push(path.trim_end_matches(':').to_string());
            }
        }
        let mut edges: Vec<String> = (named.iter())
            .filter_map(|p| resolve(p))
            .filter(|t| t != module)
            // A module and its parts name each other by design.
            .filter(|t| {
                !t.starts_with(&format!("{module}::")) && !module.starts_with(&format!("{t}::"))
            })
            .collect();
        edges.sort();
        edges.dedup();
        graph.insert(module.clone(), edges);
    }
    assert!(names.len() > 50, "the library's modules were not found");
    graph
}

#[test]
fn the_librarys_modules_import_one_way() {
    let graph = module_graph();
    // Tarjan's strongly connected components; any of more than one module is a circle.
    struct State<'a> {
        graph: &'a BTreeMap<String, Vec<String>>,
        index: BTreeMap<&'a str, (usize, usize)>,
        stack: Vec<&'a str>,
        next: usize,
        circles: Vec<Vec<String>>,
    }
    fn visit<'a>(v: &'a str, s: &mut State<'a>) {
        s.index.insert(v, (s.next, s.next));
        s.next += 1;
        s.stack.push(v);
        for w in &s.graph[v] {
            let w = w.as_str();
            if !s.index.contains_key(w) {
                visit(w, s);
                let low = s.index[w].1.min(s.index[v].1);
                s.index.get_mut(v).unwrap().1 = low;
            } else if s.stack.contains(&w) {
                let low = s.index[w].0.min(s.index[v].1);
                s.index.get_mut(v).unwrap().1 = low;
            }
        }
        if s.index[v].0 == s.index[v].1 {
            let mut circle = Vec::new();
            while let Some(w) = s.stack.pop() {
                circle.push(w.to_string());
                if w == v {
                    break;
                }
            }
            if circle.len() > 1 {
                s.circles.push(circle);
            }
        }
    }
    let mut state = State {
        graph: &graph,
        index: BTreeMap::new(),
        stack: Vec::new(),
        next: 0,
        circles: Vec::new(),
    };
    for v in graph.keys() {
        if !state.index.contains_key(v.as_str()) {
            visit(v, &mut state);
        }
    }
    assert!(
        state.circles.is_empty(),
        "modules in a circle: {:?}",
        state.circles
    );
}
