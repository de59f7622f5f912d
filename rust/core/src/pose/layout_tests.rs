//! The pose room's floors (see the map in `pose/mod.rs`): no module imports one that imports it,
//! and each imports only modules on the floors below its own. Read from the source: every path
//! through `super::`, `self::`, `crate::pose::` or a child module's name in a module's non-test
//! code is an import of the module it names (the deepest one; an item re-exported by a `mod.rs`
//! is an import of that `mod.rs`). Test files (`tests.rs`, `*_tests.rs`) and inline test modules
//! are left out: they import freely and nothing imports them.

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

/// A module of the room as the path of its names below `pose` (`[]` is `pose/mod.rs`).
type Module = Vec<String>;

/// The floor of each module directly below `pose`, the root (`mod.rs`) on top. A module's
/// children (`judge/*`, `trust/*`) stand on their parent's floor; among them only the cycle
/// check applies.
const FLOORS: [(&str, usize); 9] = [
    ("types", 0),
    ("model", 1),
    ("scene", 2),
    ("surface", 2),
    ("judge", 3),
    ("ccp_path", 4),
    ("ppf_path", 4),
    ("trust", 4),
    ("", 5),
];

/// The leaves, which import nothing of the room but each other (on lower floors).
const LEAVES: [&str; 4] = ["types", "model", "scene", "surface"];

fn floor_of(m: &Module) -> Option<usize> {
    let top = m.first().map_or("", String::as_str);
    FLOORS.iter().find(|(name, _)| *name == top).map(|(_, f)| *f)
}

fn is_test_file(name: &str) -> bool {
    name == "tests.rs" || name.ends_with("_tests.rs")
}

/// Every non-test source file of the folder `dir` (the room's `pose/`), by module.
fn sources(dir: &Path) -> BTreeMap<Module, String> {
    fn walk(dir: &Path, prefix: &Module, out: &mut BTreeMap<Module, String>) {
        for entry in std::fs::read_dir(dir).expect("the pose folder") {
            let path = entry.expect("a directory entry").path();
            let name = path.file_name().unwrap().to_string_lossy().into_owned();
            if path.is_dir() {
                let mut sub = prefix.clone();
                sub.push(name);
                walk(&path, &sub, out);
            } else if let Some(stem) = name.strip_suffix(".rs") {
                if is_test_file(&name) {
                    continue;
                }
                let mut m = prefix.clone();
                if stem != "mod" {
                    m.push(stem.to_string());
                }
                out.insert(m, std::fs::read_to_string(&path).expect("a source file"));
            }
        }
    }
    let mut out = BTreeMap::new();
    walk(dir, &Vec::new(), &mut out);
    out
}

/// `src` without comments, string literals and inline test modules (`#[cfg(test)] mod x {`
/// to the end of the file).
fn code_of(src: &str) -> String {
    let inline_tests = src
        .match_indices("#[cfg(test)]\nmod ")
        .map(|(i, _)| i)
        .find(|&i| src[i..].lines().nth(1).is_some_and(|l| l.trim_end().ends_with('{')));
    let src = &src[..inline_tests.unwrap_or(src.len())];
    let mut out = String::with_capacity(src.len());
    let mut chars = src.chars().peekable();
    while let Some(c) = chars.next() {
        match c {
            '/' if chars.peek() == Some(&'/') => {
                for c in chars.by_ref() {
                    if c == '\n' {
                        out.push('\n');
                        break;
                    }
                }
            }
            '"' => {
                let mut escaped = false;
                for c in chars.by_ref() {
                    if c == '"' && !escaped {
                        break;
                    }
                    escaped = c == '\\' && !escaped;
                }
                out.push_str("\"\"");
            }
            _ => out.push(c),
        }
    }
    out
}

fn is_ident(c: char) -> bool {
    c.is_alphanumeric() || c == '_'
}

/// The path tree that starts at `s[*i]` (`a::b::{c, d::e}`): each full path, as segments.
fn paths(s: &[char], i: &mut usize, prefix: &[String], out: &mut Vec<Vec<String>>) {
    let skip_space = |i: &mut usize| {
        while *i < s.len() && s[*i].is_whitespace() {
            *i += 1;
        }
    };
    let mut segs = prefix.to_vec();
    loop {
        skip_space(i);
        if s.get(*i) == Some(&'{') {
            *i += 1;
            loop {
                skip_space(i);
                if s.get(*i) == Some(&'}') {
                    *i += 1;
                    return;
                }
                paths(s, i, &segs, out);
                skip_space(i);
                match s.get(*i) {
                    Some(',') => *i += 1,
                    Some('}') => {
                        *i += 1;
                        return;
                    }
                    _ => return,
                }
            }
        }
        let start = *i;
        while *i < s.len() && (is_ident(s[*i]) || s[*i] == '*') {
            *i += 1;
        }
        segs.push(s[start..*i].iter().collect());
        if s.get(*i) == Some(&':') && s.get(*i + 1) == Some(&':') {
            *i += 2;
        } else {
            out.push(segs);
            return;
        }
    }
}

/// The modules of the room that `code` (of module `at`) imports.
fn imports(at: &Module, code: &str, modules: &BTreeSet<Module>) -> BTreeSet<Module> {
    let s: Vec<char> = code.chars().collect();
    let children: Vec<String> = modules
        .iter()
        .filter(|m| m.len() == at.len() + 1 && m.starts_with(at))
        .map(|m| m.last().unwrap().clone())
        .collect();
    let mut found = BTreeSet::new();
    let mut i = 0;
    while i < s.len() {
        // A path starts at a word not inside a longer path: `super`, `self`, `crate` or a child.
        if !is_ident(s[i]) || (i > 0 && (is_ident(s[i - 1]) || s[i - 1] == ':')) {
            i += 1;
            continue;
        }
        let end = (i..s.len()).find(|&j| !is_ident(s[j])).unwrap_or(s.len());
        let word: String = s[i..end].iter().collect();
        let is_path = s.get(end) == Some(&':') && s.get(end + 1) == Some(&':');
        if is_path && (["super", "self", "crate"].contains(&word.as_str()) || children.contains(&word)) {
            let mut found_paths = Vec::new();
            let mut j = i;
            paths(&s, &mut j, &[], &mut found_paths);
            for path in found_paths {
                if let Some(m) = resolve(at, &path, modules) {
                    if &m != at {
                        found.insert(m);
                    }
                }
            }
        }
        i = end;
    }
    found
}

/// The deepest module of the room that `path`, written in module `at`, names; `None` outside it.
fn resolve(at: &Module, path: &[String], modules: &BTreeSet<Module>) -> Option<Module> {
    let mut segs = path.iter().map(String::as_str).peekable();
    let mut base: Module = match segs.peek().copied() {
        Some("crate") => {
            segs.next();
            if segs.next() != Some("pose") {
                return None;
            }
            Vec::new()
        }
        Some("self") => {
            segs.next();
            at.clone()
        }
        _ => at.clone(),
    };
    while segs.peek() == Some(&"super") {
        segs.next();
        base.pop()?;
    }
    for seg in segs {
        let mut next = base.clone();
        next.push(seg.to_string());
        if !modules.contains(&next) {
            break;
        }
        base = next;
    }
    Some(base)
}

/// Module → the modules it imports, over every non-test source file of `dir`.
fn import_graph(dir: &Path) -> BTreeMap<Module, BTreeSet<Module>> {
    let src = sources(dir);
    let modules: BTreeSet<Module> = src.keys().cloned().collect();
    src.iter()
        .map(|(m, s)| (m.clone(), imports(m, &code_of(s), &modules)))
        .collect()
}

/// One import cycle (its first module repeated at the end), or `None`.
fn find_cycle(graph: &BTreeMap<Module, BTreeSet<Module>>) -> Option<Vec<Module>> {
    fn visit(
        m: &Module,
        graph: &BTreeMap<Module, BTreeSet<Module>>,
        state: &mut BTreeMap<Module, bool>,
        stack: &mut Vec<Module>,
    ) -> Option<Vec<Module>> {
        state.insert(m.clone(), false);
        stack.push(m.clone());
        for next in graph.get(m).into_iter().flatten() {
            match state.get(next) {
                Some(false) => {
                    let at = stack.iter().position(|s| s == next).unwrap();
                    let mut cycle = stack[at..].to_vec();
                    cycle.push(next.clone());
                    return Some(cycle);
                }
                Some(true) => {}
                None => {
                    if let Some(c) = visit(next, graph, state, stack) {
                        return Some(c);
                    }
                }
            }
        }
        stack.pop();
        state.insert(m.clone(), true);
        None
    }
    let mut state = BTreeMap::new();
    for m in graph.keys() {
        if !state.contains_key(m) {
            if let Some(c) = visit(m, graph, &mut state, &mut Vec::new()) {
                return Some(c);
            }
        }
    }
    None
}

fn name(m: &Module) -> String {
    if m.is_empty() {
        "pose".into()
    } else {
        m.join("/")
    }
}

fn module(path: &str) -> Module {
    path.split('/').filter(|s| !s.is_empty()).map(String::from).collect()
}

fn room() -> BTreeMap<Module, BTreeSet<Module>> {
    import_graph(&Path::new(env!("CARGO_MANIFEST_DIR")).join("src/pose"))
}

#[test]
fn the_parser_reads_paths_groups_and_parents_and_skips_comments_strings_and_tests() {
    let modules: BTreeSet<Module> = ["", "a", "b", "judge", "judge/depth", "judge/outline"]
        .iter()
        .map(|p| module(p))
        .collect();
    let code = code_of(
        "use super::a::{X, Y};\n\
         use crate::pose::judge::depth::{share, DepthTest};\n\
         use crate::geometry::Point; // super::b::Z is a comment\n\
         fn f() { let s = \"super::b\"; super::super::b::g(); }\n\
         #[cfg(test)]\nmod tests {\n    use super::*;\n}\n",
    );
    let at = module("judge/outline");
    // `super::a` from judge/outline names no module below judge: an item of judge/mod.rs.
    assert_eq!(
        imports(&at, &code, &modules),
        [module("judge"), module("judge/depth"), module("b")]
            .into_iter()
            .collect(),
        "{code}"
    );
    // A mod.rs reaches its children by name, and a group's items each by their own path.
    let code = code_of("use depth::{share, DepthTest};\nuse crate::pose::{a::X, b};\nfn g() { outline::f(); }\n");
    assert_eq!(
        imports(&module("judge"), &code, &modules),
        [module("judge/depth"), module("judge/outline"), module("a"), module("b")]
            .into_iter()
            .collect()
    );
}

#[test]
fn the_cycle_finder_finds_a_cycle() {
    let g: BTreeMap<Module, BTreeSet<Module>> = [
        (module("a"), [module("b")].into_iter().collect()),
        (module("b"), [module("c")].into_iter().collect()),
        (module("c"), [module("a")].into_iter().collect()),
    ]
    .into_iter()
    .collect();
    assert_eq!(
        find_cycle(&g),
        Some(vec![module("a"), module("b"), module("c"), module("a")])
    );
    let g: BTreeMap<Module, BTreeSet<Module>> = [(module("a"), [module("b")].into_iter().collect())]
        .into_iter()
        .collect();
    assert_eq!(find_cycle(&g), None);
}

#[test]
fn the_import_graph_sees_the_room() {
    let graph = room();
    let has = |from: &str, to: &str| graph.get(&module(from)).is_some_and(|e| e.contains(&module(to)));
    assert!(has("judge", "model"));
    assert!(has("judge", "judge/depth"));
    assert!(has("judge/continuation", "judge/depth"));
    assert!(has("trust/unseen_turns", "trust/fit"));
    assert!(has("ppf_path", "judge"));
    assert!(has("", "trust"));
    assert!(has("surface", "model"));
}

#[test]
fn no_module_of_the_pose_room_imports_one_that_imports_it() {
    let graph = room();
    if let Some(cycle) = find_cycle(&graph) {
        let names: Vec<String> = cycle.iter().map(name).collect();
        panic!("import cycle in pose/: {}", names.join(" -> "));
    }
}

#[test]
fn each_module_imports_only_the_floors_below_it() {
    let graph = room();
    let mut wrong = Vec::new();
    for (m, targets) in &graph {
        let Some(floor) = floor_of(m) else {
            wrong.push(format!("{} is on no floor: add it to FLOORS", name(m)));
            continue;
        };
        for t in targets {
            let same_room = !m.is_empty() && t.first() == m.first();
            if !same_room && floor_of(t).is_none_or(|f| f >= floor) {
                wrong.push(format!("{} (floor {floor}) imports {}", name(m), name(t)));
            }
        }
    }
    assert!(wrong.is_empty(), "{}", wrong.join("\n"));
}

#[test]
fn the_leaves_import_no_sibling_above_them() {
    let graph = room();
    for leaf in LEAVES {
        let m = module(leaf);
        let targets = graph.get(&m).unwrap_or_else(|| panic!("no {leaf}.rs in pose/"));
        for t in targets {
            assert!(
                LEAVES.contains(&name(t).as_str()) && floor_of(t) < floor_of(&m),
                "the leaf {leaf}.rs imports {}",
                name(t)
            );
        }
    }
}
