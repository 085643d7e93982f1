//! The README and the user guide (`src/guide/*.md`): every code block is checked. Rust blocks
//! are doctests (`src/guide/mod.rs` includes the files, so `cargo test --doc` compiles them);
//! here, every command line of a shell block parses with the CLI's own parser (the binary with
//! `LIGHTBAKE_PARSE_ONLY=1`), JSON and TOML blocks parse (a manifest as a manifest),
//! JavaScript passes `node --check` where Node is installed, no block goes untagged, every flag
//! named in the prose (`--quality`, in a table or a sentence) is one of the CLI's, and every
//! relative link names a file that exists.

use std::path::{Path, PathBuf};
use std::process::Command;

/// The languages a block may be tagged with; a `rust` block is a doctest.
const LANGUAGES: [&str; 7] = ["rust", "sh", "console", "text", "json", "toml", "js"];

/// A fenced code block of a Markdown file.
struct Block {
    /// `file:line` of the opening fence.
    place: String,
    /// The info string's first word (`rust` for "rust,no_run").
    lang: String,
    text: String,
}

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// README.md and the guide's chapters.
fn documents() -> Vec<PathBuf> {
    let mut files = vec![root().join("README.md")];
    let mut guide: Vec<PathBuf> = std::fs::read_dir(root().join("src/guide"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "md"))
        .collect();
    guide.sort();
    assert!(guide.len() >= 8, "the guide's chapters: {guide:?}");
    files.extend(guide);
    files
}

fn relative(path: &Path) -> String {
    path.strip_prefix(root()).unwrap().display().to_string()
}

/// The fenced blocks of `path` (fences may be indented, as in a list item).
fn blocks(path: &Path) -> Vec<Block> {
    let text = std::fs::read_to_string(path).unwrap();
    let mut out = Vec::new();
    let mut open: Option<(usize, usize, String, String)> = None; // line, indent, lang, text
    for (k, line) in text.lines().enumerate() {
        let trimmed = line.trim_start();
        let indent = line.len() - trimmed.len();
        match &mut open {
            None if trimmed.starts_with("```") => {
                let info = trimmed.trim_start_matches('`').trim();
                let lang = info.split([',', ' ']).next().unwrap_or("").to_string();
                open = Some((k + 1, indent, lang, String::new()));
            }
            None => {}
            Some((line_no, _, lang, body)) if trimmed.starts_with("```") => {
                out.push(Block {
                    place: format!("{}:{line_no}", relative(path)),
                    lang: std::mem::take(lang),
                    text: std::mem::take(body),
                });
                open = None;
            }
            Some((_, fence_indent, _, body)) => {
                let cut = line.len().min(*fence_indent).min(indent);
                body.push_str(&line[cut..]);
                body.push('\n');
            }
        }
    }
    assert!(
        open.is_none(),
        "{}: a code block is not closed",
        path.display()
    );
    out
}

fn all_blocks() -> Vec<Block> {
    documents().iter().flat_map(|p| blocks(p)).collect()
}

/// Splits a shell line into words: single and double quotes, backslash escapes, `#` comments.
fn words(line: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut word: Option<String> = None;
    let mut chars = line.chars();
    while let Some(c) = chars.next() {
        match c {
            '#' if word.is_none() => break,
            c if c.is_whitespace() => out.extend(word.take()),
            '\'' => {
                let w = word.get_or_insert_with(String::new);
                w.extend(chars.by_ref().take_while(|&c| c != '\''));
            }
            '"' => {
                let w = word.get_or_insert_with(String::new);
                while let Some(c) = chars.next() {
                    match c {
                        '"' => break,
                        '\\' => w.extend(chars.next()),
                        c => w.push(c),
                    }
                }
            }
            '\\' => word.get_or_insert_with(String::new).extend(chars.next()),
            c => word.get_or_insert_with(String::new).push(c),
        }
    }
    out.extend(word);
    out
}

/// The command lines of a shell block, as words: continuation lines joined; in a `console`
/// block only the lines after a `$ ` prompt.
fn commands(block: &Block) -> Vec<Vec<String>> {
    let mut out = Vec::new();
    let mut pending = String::new();
    for line in block.text.lines() {
        let line = match block.lang.as_str() {
            "console" if pending.is_empty() => match line.strip_prefix("$ ") {
                Some(command) => command,
                None => continue, // output
            },
            _ => line,
        };
        match line.trim_end().strip_suffix('\\') {
            Some(head) => {
                pending.push_str(head);
                pending.push(' ');
            }
            None => {
                pending.push_str(line);
                let w = words(&pending);
                if !w.is_empty() {
                    out.push(w);
                }
                pending.clear();
            }
        }
    }
    assert!(pending.is_empty(), "{}: a line ends in '\\'", block.place);
    out
}

/// The `[[example]]` names of Cargo.toml.
fn examples() -> Vec<String> {
    let manifest: toml::Table = std::fs::read_to_string(root().join("Cargo.toml"))
        .unwrap()
        .parse()
        .unwrap();
    manifest["example"]
        .as_array()
        .unwrap()
        .iter()
        .map(|e| e["name"].as_str().unwrap().to_string())
        .collect()
}

/// Why `args` (after `lightbake`) do not parse, if they do not.
fn cli_refuses(args: &[String]) -> Option<String> {
    let o = Command::new(env!("CARGO_BIN_EXE_lightbake"))
        .args(args)
        .env("LIGHTBAKE_PARSE_ONLY", "1")
        .output()
        .expect("run lightbake");
    match o.status.success() {
        true => None,
        false => Some(String::from_utf8_lossy(&o.stderr).into_owned()),
    }
}

/// What is wrong with one command line of a shell block, if anything.
fn check_command(command: &[String], examples: &[String]) -> Option<String> {
    let words: Vec<&str> = command.iter().map(String::as_str).collect();
    if let Some(w) = words.iter().find(|w| w.contains('<') || w.contains('>')) {
        return Some(format!(
            "a placeholder or redirection {w:?}: write a real value"
        ));
    }
    match words[..] {
        ["lightbake", ..] => cli_refuses(&command[1..]),
        ["cargo", "run", "--release", "--", ..] => cli_refuses(&command[4..]),
        ["cargo", "run", "--release", "--example", name, ..] => {
            let known = examples.iter().any(|e| e == name);
            (!known).then(|| format!("no [[example]] {name:?} in Cargo.toml"))
        }
        ["cargo", "test" | "build" | "doc" | "install", ..] => None,
        _ => Some("not a lightbake or cargo command".to_string()),
    }
}

#[test]
fn readme_is_short() {
    let lines = std::fs::read_to_string(root().join("README.md"))
        .unwrap()
        .lines()
        .count();
    assert!(
        lines <= 250,
        "README.md has {lines} lines: move text to the guide"
    );
}

#[test]
fn every_block_has_a_known_language() {
    let bad: Vec<String> = (all_blocks().iter())
        .filter(|b| !LANGUAGES.contains(&b.lang.as_str()))
        .map(|b| format!("{}: {:?}", b.place, b.lang))
        .collect();
    assert!(
        bad.is_empty(),
        "blocks tagged with none of {LANGUAGES:?}: {bad:#?}"
    );
}

#[test]
fn shell_commands_parse_with_the_cli() {
    let examples = examples();
    let mut checked = 0;
    let mut bad = Vec::new();
    for block in all_blocks()
        .iter()
        .filter(|b| ["sh", "console"].contains(&&*b.lang))
    {
        for command in commands(block) {
            checked += 1;
            if let Some(problem) = check_command(&command, &examples) {
                bad.push(format!(
                    "{}: `{}`: {problem}",
                    block.place,
                    command.join(" ")
                ));
            }
        }
    }
    assert!(checked >= 30, "only {checked} command lines found");
    assert!(bad.is_empty(), "{}", bad.join("\n"));
}

#[test]
fn the_parse_only_mode_refuses_unknown_flags() {
    let args = |s: &str| -> Vec<String> { s.split(' ').map(String::from).collect() };
    assert_eq!(
        cli_refuses(&args("bake x.gltf -o out --quality high")),
        None
    );
    let refused = cli_refuses(&args("bake x.gltf -o out --qualty high")).unwrap();
    assert!(refused.contains("--qualty"), "{refused}");
    assert!(cli_refuses(&args("bake x.gltf --quality best -o out")).is_some());
    assert!(cli_refuses(&args("frobnicate x.gltf")).is_some());
}

#[test]
fn shell_words_and_commands() {
    assert_eq!(
        words(r#"lightbake bake 'a b.gltf' -o "out dir" x\ y  # comment"#),
        ["lightbake", "bake", "a b.gltf", "-o", "out dir", "x y"]
    );
    let block = Block {
        place: String::new(),
        lang: "console".into(),
        text: "$ lightbake bake a.gltf \\\n    -o out\nwrote out/a.gltf\n".into(),
    };
    assert_eq!(
        commands(&block),
        [["lightbake", "bake", "a.gltf", "-o", "out"]]
    );
}

#[test]
fn json_and_toml_blocks_parse() {
    let mut bad = Vec::new();
    for block in all_blocks() {
        let problem = match block.lang.as_str() {
            "json" => serde_json::from_str::<serde_json::Value>(&block.text)
                .err()
                .map(|e| e.to_string()),
            "toml" if block.text.contains("[[scene]]") => {
                lightbake::Manifest::parse(&block.text, Path::new("."))
                    .err()
                    .map(|e| format!("not a manifest: {e}"))
            }
            "toml" => block
                .text
                .parse::<toml::Table>()
                .err()
                .map(|e| e.to_string()),
            _ => None,
        };
        bad.extend(problem.map(|p| format!("{}: {p}", block.place)));
    }
    assert!(bad.is_empty(), "{}", bad.join("\n"));
}

#[test]
fn js_blocks_pass_node_check() {
    if Command::new("node").arg("--version").output().is_err() {
        eprintln!("node is not installed: JavaScript blocks not checked");
        return;
    }
    let dir = crate::util::scratch();
    let mut bad = Vec::new();
    for (k, block) in all_blocks().iter().filter(|b| b.lang == "js").enumerate() {
        // A module: the snippets use top-level `await`.
        let file = dir.path().join(format!("block{k}.mjs"));
        std::fs::write(&file, &block.text).unwrap();
        let o = Command::new("node")
            .arg("--check")
            .arg(&file)
            .output()
            .unwrap();
        if !o.status.success() {
            bad.push(format!(
                "{}: {}",
                block.place,
                String::from_utf8_lossy(&o.stderr)
            ));
        }
    }
    assert!(bad.is_empty(), "{}", bad.join("\n"));
}

/// The text of `path` outside fenced blocks.
fn prose(path: &Path) -> String {
    let text = std::fs::read_to_string(path).unwrap();
    let mut out = String::new();
    let mut fenced = false;
    for line in text.lines() {
        if line.trim_start().starts_with("```") {
            fenced = !fenced;
        } else if !fenced {
            out.push_str(line);
            out.push('\n');
        }
    }
    out
}

/// The flags of every `lightbake` command, from their `--help`.
fn cli_flags() -> Vec<String> {
    let mut flags = Vec::new();
    for command in "bake relight render reference compare probes build view".split(' ') {
        let o = Command::new(env!("CARGO_BIN_EXE_lightbake"))
            .args([command, "--help"])
            .output()
            .unwrap();
        assert!(o.status.success(), "lightbake {command} --help");
        let help = String::from_utf8(o.stdout).unwrap();
        flags.extend(help.split_whitespace().filter_map(flag));
    }
    flags
}

/// `word` as a long flag (`--quality`), without what follows its name.
fn flag(word: &str) -> Option<String> {
    let name = word.strip_prefix("--")?;
    let name: String = (name.chars())
        .take_while(|c| c.is_ascii_alphanumeric() || *c == '-')
        .collect();
    (!name.is_empty()).then(|| format!("--{name}"))
}

#[test]
fn flags_in_the_prose_exist() {
    let known = cli_flags();
    let mut bad = Vec::new();
    for doc in documents() {
        // Inline code that is a lightbake command line or starts with a flag.
        for span in prose(&doc).split('`').skip(1).step_by(2) {
            if !(span.starts_with("--") || span.starts_with("lightbake ")) {
                continue;
            }
            for f in span.split_whitespace().filter_map(flag) {
                if !known.contains(&f) {
                    bad.push(format!("{}: `{span}`: no command has {f}", relative(&doc)));
                }
            }
        }
    }
    assert!(bad.is_empty(), "{}", bad.join("\n"));
}

/// Relative link targets of `text` (inline `](target)` and definitions `[name]: target`).
fn link_targets(text: &str) -> Vec<String> {
    let mut out = Vec::new();
    for line in text.lines() {
        let mut rest = line;
        while let Some(i) = rest.find("](") {
            let tail = &rest[i + 2..];
            let end = tail.find(')').unwrap_or(tail.len());
            out.push(tail[..end].to_string());
            rest = &tail[end..];
        }
        let trimmed = line.trim_start();
        if trimmed.starts_with('[')
            && let Some(i) = trimmed.find("]: ")
        {
            out.push(trimmed[i + 3..].trim().to_string());
        }
    }
    out.retain(|t| !t.contains("://") && !t.starts_with('#'));
    out
}

#[test]
fn relative_links_name_files_that_exist() {
    let mut bad = Vec::new();
    for doc in documents() {
        let prose = prose(&doc); // code blocks hold no links
        for target in link_targets(&prose) {
            let path = target.split('#').next().unwrap();
            if !doc.parent().unwrap().join(path).exists() {
                bad.push(format!("{}: {target}", relative(&doc)));
            }
        }
        // Every reference-style link `[text][name]` has its definition `[name]: …`.
        for (i, _) in prose.match_indices("][") {
            let name = &prose[i + 2..];
            let name = &name[..name.find(']').unwrap_or(0)];
            if !prose.contains(&format!("\n[{name}]: ")) {
                bad.push(format!("{}: [{name}] is not defined", relative(&doc)));
            }
        }
    }
    assert!(bad.is_empty(), "{}", bad.join("\n"));
}
