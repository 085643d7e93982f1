//! The code's own shape: no function in `src/` (tests aside) grows past [`MAX_FUNCTION_LINES`],
//! the line issue 30 drew when it split the long ones; later work had let six pass it again
//! unnoticed (up to 480 lines). The code is rustfmt-formatted (CI checks it), so a function
//! ends at the first line that closes a brace at its `fn` line's indentation.

use std::path::{Path, PathBuf};

/// Most lines a function may take, its signature and closing brace included.
const MAX_FUNCTION_LINES: usize = 150;

/// The crate's Rust sources under `dir`.
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

/// Each function of `text` before its test module (`#[cfg(test)]` at the left margin): its
/// name, first line (1-based) and length in lines.
fn functions(text: &str) -> Vec<(String, usize, usize)> {
    let lines: Vec<&str> = text.lines().collect();
    let end = (0..lines.len())
        .find(|&i| {
            lines[i].starts_with("#[cfg(test)]")
                && lines.get(i + 1).is_some_and(|l| l.starts_with("mod "))
        })
        .unwrap_or(lines.len());
    let mut found = Vec::new();
    for (i, line) in lines[..end].iter().enumerate() {
        let body = line.trim_start();
        let indent = line.len() - body.len();
        let Some(name) = fn_name(body) else { continue };
        // The signature ends at `{` (a body), `;` (a trait method without one) or `}` (a
        // body on the same line).
        let Some(open) = (i..end).find(|&j| lines[j].trim_end().ends_with(['{', ';', '}'])) else {
            continue;
        };
        if !lines[open].trim_end().ends_with('{') {
            continue;
        }
        let close = (open + 1..end).find(|&j| {
            let l = lines[j];
            l.len() > indent && l[..indent].trim().is_empty() && l[indent..].starts_with('}')
        });
        if let Some(close) = close {
            found.push((name, i + 1, close - i + 1));
        }
    }
    found
}

/// The name of the function a line declares (`pub(crate) const unsafe fn name<…>(`), if any.
fn fn_name(line: &str) -> Option<String> {
    let mut words = line.split_whitespace();
    let mut word = words.next()?;
    while matches!(word, "const" | "unsafe" | "async" | "extern" | "\"C\"")
        || word.starts_with("pub")
    {
        word = words.next()?;
    }
    if word != "fn" {
        return None;
    }
    let name: String = (words.next()?.chars())
        .take_while(|c| c.is_alphanumeric() || *c == '_')
        .collect();
    (!name.is_empty()).then_some(name)
}

#[test]
fn no_function_in_src_is_over_150_lines() {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let mut files = Vec::new();
    sources(&root.join("src"), &mut files);
    files.sort();
    assert!(files.len() > 50, "the crate's sources: {}", files.len());
    let mut long = Vec::new();
    for file in &files {
        let text = std::fs::read_to_string(file).unwrap();
        for (name, line, length) in functions(&text) {
            if length > MAX_FUNCTION_LINES {
                let place = file.strip_prefix(&root).unwrap_or(file).display();
                long.push(format!("{place}:{line} {name} ({length} lines)"));
            }
        }
    }
    assert!(
        long.is_empty(),
        "functions over {MAX_FUNCTION_LINES} lines (split them into named steps):\n{}",
        long.join("\n")
    );
}

#[test]
fn the_measure_finds_functions_and_their_ends() {
    let text = "pub(crate) fn short(\n    a: u32,\n) -> u32 {\n    a\n}\n\nimpl X {\n    \
                fn method(&self) {\n        if true {\n        }\n    }\n    \
                fn declared(&self);\n    fn one(&self) -> u32 { 1 }\n}\n#[cfg(test)]\nmod tests {\n    fn ignored() {\n    }\n}\n";
    assert_eq!(
        functions(text),
        vec![("short".to_string(), 1, 5), ("method".to_string(), 8, 4)]
    );
}
