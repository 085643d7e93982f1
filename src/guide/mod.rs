//! # The lightbake user guide
//!
//! The README and the guide's chapters, compiled as documentation: each chapter is a Markdown
//! file beside this module (`src/guide/*.md`, read on GitHub as they are), included here so
//! that `cargo test --doc` compiles every Rust example in them. `tests/docs.rs` checks the
//! other blocks: every command line of a shell block parses with the CLI's own parser, JSON
//! and TOML parse, JavaScript passes `node --check`.
//!
//! 1. [README](readme): what lightbake is, two commands, a tour.
//! 2. [Output files and the glTF contract](output).
//! 3. [Looking at a bake: the viewer, three.js, Bevy, Godot](engines).
//! 4. [Baking: options, methods, solvers and the automatic choice](baking).
//! 5. [Measuring a bake: render, reference, compare](accuracy).
//! 6. [Bad input](bad_input).
//! 7. [Using lightbake as a library](library).
//! 8. [Relighting and per-light layers](relight).
//! 9. [Building many scenes](build).
//! 10. [Baking on several machines](distributed).
//! 11. [Accuracy and speed](performance).
//! 12. [Incremental re-bake](incremental).

/// The chapters' links by name, as rustdoc resolves them. The Markdown files define the same
/// names as relative `.md` paths (for GitHub); in a Markdown document the first definition of
/// a name wins, so these come before each chapter's text.
macro_rules! links {
    () => {
        "[output]: crate::guide::output\n\
         [engines]: crate::guide::engines\n\
         [baking]: crate::guide::baking\n\
         [accuracy]: crate::guide::accuracy\n\
         [bad_input]: crate::guide::bad_input\n\
         [library]: crate::guide::library\n\
         [relight]: crate::guide::relight\n\
         [build]: crate::guide::build\n\
         [distributed]: crate::guide::distributed\n\
         [performance]: crate::guide::performance\n\
         [incremental]: crate::guide::incremental\n"
    };
}

/// A chapter: `links!()`, then the Markdown file.
macro_rules! chapter {
    ($name:ident, $file:literal) => {
        #[doc = links!()]
        #[doc = include_str!($file)]
        pub mod $name {}
    };
}

chapter!(readme, "../../README.md");
chapter!(output, "output.md");
chapter!(engines, "engines.md");
chapter!(baking, "baking.md");
chapter!(accuracy, "accuracy.md");
chapter!(bad_input, "bad_input.md");
chapter!(library, "library.md");
chapter!(relight, "relight.md");
chapter!(build, "build.md");
chapter!(distributed, "distributed.md");
chapter!(performance, "performance.md");
chapter!(incremental, "incremental.md");
