//! Regenerates the committed test scenes in `fixtures/` (see `fixtures/README.md`).
//!
//!     cargo run --example make_fixtures
//!
//! The output is deterministic; a unit test in `lightbake::testing` fails when the committed
//! files differ from what this writes.

use std::path::Path;

fn main() -> std::io::Result<()> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures");
    std::fs::create_dir_all(&dir)?;
    for (name, bytes) in lightbake::testing::fixture_files() {
        let path = dir.join(name);
        std::fs::write(&path, &bytes)?;
        println!("{} ({} bytes)", path.display(), bytes.len());
    }
    Ok(())
}
