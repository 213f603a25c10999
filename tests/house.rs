//! The house keeps its shape: the layers of docs/architecture.md import
//! only from the layers below them, and no production function or file
//! outgrows what a reader can walk (120 and 800 lines, comments and blank
//! lines aside). Read from the sources, tests included for the layers.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// Each layer's modules and the modules it may import (besides its own).
const FOUNDATIONS: &[&str] = &[
    "error",
    "grid",
    "input",
    "output",
    "timing",
    "progress",
    "tool",
    "materials",
    "machine",
    "settings",
    "testing",
    "bail",
    "Error",
    "Result",
    "Grid",
];

fn allowed(module: &str) -> Option<Vec<&'static str>> {
    let with = |more: &[&'static str]| {
        let mut v = FOUNDATIONS.to_vec();
        v.extend_from_slice(more);
        Some(v)
    };
    match module {
        "scene" => with(&[]),
        "relief" => with(&["scene"]),
        "dialect" => Some(vec![]),
        "cutter" => with(&["relief"]),
        "gcode" => with(&["dialect"]),
        "toolpath" => with(&["cutter", "dialect"]),
        "sim" => with(&["gcode", "dialect", "cutter", "relief"]),
        "grbl" => with(&["gcode", "dialect", "sim"]),
        "cam" => with(&[
            "toolpath", "gcode", "dialect", "sim", "cutter", "relief", "preview",
        ]),
        "ops" => with(&[
            "cam", "toolpath", "gcode", "dialect", "sim", "grbl", "cutter", "relief", "scene",
        ]),
        _ => None,
    }
}

/// The source with comments, strings and char literals blanked (lines
/// kept), so that braces and `crate::` are only the code's.
fn code_only(src: &str) -> String {
    let b = src.as_bytes();
    let mut out = String::with_capacity(src.len());
    let mut i = 0;
    let blank = |s: &[u8], out: &mut String| {
        for &c in s {
            out.push(if c == b'\n' { '\n' } else { ' ' });
        }
    };
    while i < b.len() {
        let rest = &b[i..];
        if rest.starts_with(b"//") {
            let end = rest.iter().position(|&c| c == b'\n').unwrap_or(rest.len());
            blank(&rest[..end], &mut out);
            i += end;
        } else if rest.starts_with(b"/*") {
            let end = src[i + 2..].find("*/").map_or(rest.len(), |e| e + 4);
            blank(&rest[..end], &mut out);
            i += end;
        } else if rest.starts_with(b"r\"") || rest.starts_with(b"r#") {
            let hashes = rest[1..].iter().take_while(|&&c| c == b'#').count();
            if rest.get(1 + hashes) != Some(&b'"') {
                out.push('r');
                i += 1;
                continue;
            }
            let close = format!("\"{}", "#".repeat(hashes));
            let start = 2 + hashes;
            let end = src[i + start..]
                .find(&close)
                .map_or(rest.len(), |e| start + e + close.len());
            blank(&rest[..end], &mut out);
            i += end;
        } else if rest[0] == b'"' {
            let mut k = 1;
            while k < rest.len() && rest[k] != b'"' {
                k += if rest[k] == b'\\' { 2 } else { 1 };
            }
            blank(&rest[..(k + 1).min(rest.len())], &mut out);
            i += k + 1;
        } else if rest[0] == b'\'' && (rest.get(2) == Some(&b'\'') || rest.get(1) == Some(&b'\\')) {
            let end = rest[1..]
                .iter()
                .position(|&c| c == b'\'')
                .map_or(1, |e| e + 2);
            blank(&rest[..end], &mut out);
            i += end;
        } else {
            let ch = src[i..].chars().next().unwrap();
            out.push(ch);
            i += ch.len_utf8();
        }
    }
    out
}

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p.is_dir() {
            rust_files(&p, out);
        } else if p.extension().is_some_and(|x| x == "rs") {
            out.push(p);
        }
    }
}

fn sources() -> Vec<(String, String)> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut files = Vec::new();
    rust_files(&root, &mut files);
    files.sort();
    files
        .into_iter()
        .map(|p| {
            let rel = p
                .strip_prefix(&root)
                .unwrap()
                .to_string_lossy()
                .replace('\\', "/");
            (rel, std::fs::read_to_string(&p).unwrap())
        })
        .collect()
}

/// The production part of a file: up to its test module.
fn production(code: &str) -> &str {
    code.find("#[cfg(test)]\nmod tests")
        .map_or(code, |k| &code[..k])
}

/// The span of the block opening at `open` (a `{`), to its `}`.
fn block_end(code: &[u8], open: usize) -> usize {
    let mut depth = 0;
    for (k, &c) in code.iter().enumerate().skip(open) {
        match c {
            b'{' => depth += 1,
            b'}' => {
                depth -= 1;
                if depth == 0 {
                    return k;
                }
            }
            _ => {}
        }
    }
    code.len()
}

#[test]
fn layers_import_only_from_below() {
    let mut wrong: BTreeMap<String, Vec<String>> = BTreeMap::new();
    for (file, src) in sources() {
        let module = file.split(['/', '.']).next().unwrap().to_string();
        let Some(ok) = allowed(&module) else {
            continue;
        };
        let code = code_only(&src);
        for (k, _) in code.match_indices("crate::") {
            let name: String = code[k + 7..]
                .chars()
                .take_while(|c| c.is_ascii_alphanumeric() || *c == '_')
                .collect();
            if !name.is_empty() && name != module && !ok.contains(&name.as_str()) {
                let line = code[..k].lines().count();
                wrong
                    .entry(format!("{file}:{line}"))
                    .or_default()
                    .push(format!("crate::{name}"));
            }
        }
    }
    assert!(
        wrong.is_empty(),
        "imports running up the layers: {wrong:#?}"
    );
}

#[test]
fn functions_and_files_stay_walkable() {
    let mut long = Vec::new();
    for (file, src) in sources() {
        let code = code_only(&src);
        let prod = production(&code);
        let lines = prod.lines().filter(|l| !l.trim().is_empty()).count();
        if lines > 800 {
            long.push(format!("{file}: {lines} lines of production code"));
        }
        let b = prod.as_bytes();
        let mut from = 0;
        while let Some(k) = prod[from..].find("fn ") {
            let at = from + k;
            from = at + 3;
            let word_start = at == 0 || !(b[at - 1].is_ascii_alphanumeric() || b[at - 1] == b'_');
            if !word_start {
                continue;
            }
            // the body's brace, unless a `;` ends a declaration first
            let Some(open) = prod[at..].find(['{', ';']).map(|o| at + o) else {
                break;
            };
            if b[open] == b';' {
                continue;
            }
            let end = block_end(b, open);
            let n = prod[at..end].lines().count();
            if n > 120 {
                let name: String = prod[at + 3..]
                    .chars()
                    .take_while(|c| c.is_ascii_alphanumeric() || *c == '_')
                    .collect();
                long.push(format!("{file}: fn {name} is {n} lines"));
            }
        }
    }
    assert!(long.is_empty(), "too long to walk: {long:#?}");
}

#[test]
fn the_tools_shape_is_matched_only_where_its_geometry_is() {
    let mut outside = Vec::new();
    for (file, src) in sources() {
        if file == "tool.rs" || file.starts_with("cutter/") {
            continue;
        }
        let code = code_only(&src);
        for shape in ["Tool::Ball", "Tool::Flat", "Tool::VBit", "Tool::TaperBall"] {
            for (k, _) in production(&code).match_indices(shape) {
                outside.push(format!("{file}:{}: {shape}", code[..k].lines().count()));
            }
        }
    }
    assert!(
        outside.is_empty(),
        "ask the tool's methods instead: {outside:#?}"
    );
}
