//! `lightbake build` and `lightbake::build`: the manifest, the content-addressed cache, the
//! report and its schema, the error gate and its exit codes.

use std::path::Path;
use std::process::Command;

use lightbake::build::{BuildReport, Gate, Status};
use lightbake::{Manifest, NoProgress};

use crate::util::{fixture, scratch};

/// `testing::textured` with its texture in the file `png` beside the glTF (a `squares`² checker).
fn textured_scene(dir: &Path, name: &str, png: &str, squares: u32) {
    let bytes = lightbake::testing::textured().to_gltf_bytes();
    let mut json: serde_json::Value = serde_json::from_slice(&bytes).unwrap();
    json["images"][0] = serde_json::json!({ "uri": png });
    std::fs::write(dir.join(name), serde_json::to_vec(&json).unwrap()).unwrap();
    set_texture(dir, png, squares);
}

fn set_texture(dir: &Path, png: &str, squares: u32) {
    lightbake::testing::checker(64, squares)
        .save(dir.join(png))
        .unwrap();
}

const MANIFEST: &str = r#"
[defaults]
quality = "draft"
texels-per-unit = 4

[[scene]]
path = "levels/a.gltf"
output = "baked/a"

[[scene]]
path = "levels/b.gltf"
output = "baked/b"
seed = 3
"#;

/// A manifest in `dir` over a textured scene (a) and an untextured one (b).
fn project(dir: &Path) -> Manifest {
    let levels = dir.join("levels");
    std::fs::create_dir_all(&levels).unwrap();
    textured_scene(&levels, "a.gltf", "checker.png", 4);
    std::fs::copy(fixture("point_light.gltf"), levels.join("b.gltf")).unwrap();
    std::fs::write(dir.join("lightbake.toml"), MANIFEST).unwrap();
    Manifest::load(&dir.join("lightbake.toml")).unwrap()
}

fn statuses(r: &BuildReport) -> Vec<Status> {
    r.scenes.iter().map(|s| s.status).collect()
}

fn schema() -> jsonschema::Validator {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("src/build/report.schema.json");
    let schema: serde_json::Value = serde_json::from_slice(&std::fs::read(path).unwrap()).unwrap();
    jsonschema::validator_for(&schema).unwrap()
}

fn assert_valid(report: &BuildReport) {
    let json: serde_json::Value = serde_json::from_str(&report.to_json()).unwrap();
    let errors: Vec<String> = schema().iter_errors(&json).map(|e| e.to_string()).collect();
    assert!(errors.is_empty(), "{errors:?}\n{json:#}");
}

#[test]
fn a_changed_texture_rebakes_only_the_scene_that_uses_it() {
    let dir = scratch();
    let mut manifest = project(dir.path());
    use Status::{Baked, Skipped};

    let first = lightbake::build(&manifest, &NoProgress);
    assert_eq!(statuses(&first), [Baked, Baked], "{first:?}");
    for s in &first.scenes {
        let e = s.result.estimated_error.expect("the planner ran");
        assert!(e.total.is_some_and(|t| t > 0.0 && t < 1.0), "{e:?}");
        assert!(s.result.texels.unwrap() > 0 && s.result.pages == Some(1));
    }
    assert_valid(&first);

    // Nothing changed: nothing is baked, and the figures are those of the bake.
    let second = lightbake::build(&manifest, &NoProgress);
    assert_eq!(statuses(&second), [Skipped, Skipped]);
    for (a, b) in first.scenes.iter().zip(&second.scenes) {
        assert_eq!(a.result, b.result);
    }
    assert_valid(&second);

    // Only scene a reads the texture.
    set_texture(&dir.path().join("levels"), "checker.png", 8);
    let third = lightbake::build(&manifest, &NoProgress);
    assert_eq!(statuses(&third), [Baked, Skipped]);

    // A damaged output is re-baked.
    let page = dir.path().join("baked/b/b_lightmap0.exr");
    std::fs::write(&page, b"not an exr").unwrap();
    assert_eq!(
        statuses(&lightbake::build(&manifest, &NoProgress)),
        [Skipped, Baked]
    );
    assert!(
        std::fs::read(&page)
            .unwrap()
            .starts_with(&[0x76, 0x2f, 0x31, 0x01])
    );

    // Other options are another key.
    manifest.scenes[1].config.transport.seed = 7;
    assert_eq!(
        statuses(&lightbake::build(&manifest, &NoProgress)),
        [Skipped, Baked]
    );

    manifest.force = true;
    assert_eq!(
        statuses(&lightbake::build(&manifest, &NoProgress)),
        [Baked, Baked]
    );
}

#[test]
fn a_failing_scene_does_not_stop_the_others() {
    let dir = scratch();
    let mut manifest = project(dir.path());
    std::fs::remove_file(dir.path().join("levels/checker.png")).unwrap();
    manifest.scenes[1].config.auto = None;
    let report = lightbake::build(&manifest, &NoProgress);
    assert_eq!(statuses(&report), [Status::Failed, Status::Baked]);
    assert!(report.failed());
    let error = report.scenes[0].error.as_deref().unwrap();
    assert!(error.contains("checker.png"), "{error}");
    // Without the automatic choice there is no estimate, and the gate cannot pass it.
    assert_eq!(report.scenes[1].result.estimated_error, None);
    let gate = Gate {
        max_error: Some(1.0),
        deny_warnings: true,
    };
    let problems = report.gate(&gate);
    assert_eq!(problems.len(), 1, "{problems:?}");
    assert!(problems[0].starts_with("levels/b.gltf: no estimated error"));
    assert_valid(&report);
}

#[test]
fn unknown_manifest_keys_are_named() {
    let root = Path::new("/nowhere");
    let cases = [
        (
            "colour = 1\n[[scene]]\npath = \"a\"\noutput = \"b\"",
            "colour",
        ),
        ("[defaults]\nqualty = \"draft\"", "qualty"),
        (
            "[[scene]]\npath = \"a.gltf\"\noutput = \"b\"\nray = 4",
            "ray",
        ),
        ("[[scene]]\npath = \"a.gltf\"", "output"),
        (
            "[[scene]]\npath = \"a.gltf\"\noutput = \"b\"\nquality = \"best\"",
            "best",
        ),
    ];
    for (text, key) in cases {
        let error = Manifest::parse(text, root).unwrap_err();
        assert!(error.contains(key), "{text:?}: {error}");
    }
    let m = Manifest::parse(MANIFEST, root).unwrap();
    assert_eq!(m.scenes[1].input, root.join("levels/b.gltf"));
    assert_eq!(m.scenes[1].output, root.join("baked/b"));
    assert_eq!(m.scenes[1].config.transport.seed, 3);
    assert_eq!(m.scenes[0].config.transport.seed, 0);
    assert_eq!(m.scenes[0].config.atlas.texels_per_unit, 4.0);
}

#[test]
fn every_bake_option_is_a_manifest_key() {
    let help = Command::new(env!("CARGO_BIN_EXE_lightbake"))
        .args(["bake", "--help"])
        .output()
        .unwrap();
    let help = String::from_utf8(help.stdout).unwrap();
    // How the run is watched, gated or spread over processes is for the command line, not
    // what is baked; `since` (an incremental re-bake) `build` chooses itself from its cache.
    let not_options = [
        "since",
        "output",
        "explain",
        "threads",
        "quiet",
        "help",
        "max-error",
        "deny-warnings",
        "processes",
        "hosts",
        "process",
        "connect-timeout",
    ];
    let names: Vec<&str> = help
        .split_whitespace()
        .filter_map(|w| w.strip_prefix("--"))
        .map(|w| w.trim_end_matches(|c: char| !c.is_ascii_alphanumeric()))
        .filter(|w| !w.is_empty() && !not_options.contains(w))
        .collect();
    assert!(names.len() > 15, "{names:?}");
    for name in names {
        // A known key with a value of no type at all fails on the value, not on the key.
        let text = format!("[defaults]\n{name} = {{ x = 1 }}");
        let error = Manifest::parse(&text, Path::new("")).unwrap_err();
        assert!(!error.contains("unknown field"), "--{name}: {error}");
    }
}

fn lightbake(dir: &Path, args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_lightbake"))
        .current_dir(dir)
        .args(args)
        .output()
        .unwrap()
}

#[test]
fn cli_build_reports_skips_and_gates() {
    let dir = scratch();
    project(dir.path());
    let out = lightbake(dir.path(), &["build", "--report", "report.json"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let report: BuildReport =
        serde_json::from_slice(&std::fs::read(dir.path().join("report.json")).unwrap()).unwrap();
    assert_eq!(statuses(&report), [Status::Baked, Status::Baked]);

    let start = std::time::Instant::now();
    let out = lightbake(
        dir.path(),
        &["build", "lightbake.toml", "--report", "again.json"],
    );
    let seconds = start.elapsed().as_secs_f64();
    assert!(out.status.success());
    let again: BuildReport =
        serde_json::from_slice(&std::fs::read(dir.path().join("again.json")).unwrap()).unwrap();
    assert_eq!(statuses(&again), [Status::Skipped, Status::Skipped]);
    assert!(seconds < 5.0, "an up-to-date build took {seconds} s");

    // The gate: exit code 3, the outputs stay as they are.
    let out = lightbake(dir.path(), &["build", "--max-error", "0.000001"]);
    assert_eq!(
        out.status.code(),
        Some(3),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(String::from_utf8_lossy(&out.stderr).contains("levels/a.gltf"));
    assert!(
        lightbake(dir.path(), &["build", "--max-error", "0.99"])
            .status
            .success()
    );

    // A failed scene: exit code 1, the other scene still runs.
    std::fs::remove_file(dir.path().join("levels/checker.png")).unwrap();
    let out = lightbake(dir.path(), &["build", "--force", "--report", "failed.json"]);
    assert_eq!(out.status.code(), Some(1));
    let failed: BuildReport =
        serde_json::from_slice(&std::fs::read(dir.path().join("failed.json")).unwrap()).unwrap();
    assert_eq!(statuses(&failed), [Status::Failed, Status::Baked]);

    let out = lightbake(dir.path(), &["build", "missing.toml"]);
    assert_eq!(out.status.code(), Some(1));
}

#[test]
fn cli_bake_has_the_gate_too() {
    let dir = scratch();
    let input = fixture("point_light.gltf");
    let bake = |extra: &[&str]| {
        Command::new(env!("CARGO_BIN_EXE_lightbake"))
            .args(["bake", input.to_str().unwrap(), "-o"])
            .arg(dir.path())
            .args(["--quality", "draft", "--texels-per-unit", "4", "--quiet"])
            .args(extra)
            .output()
            .unwrap()
    };
    assert_eq!(bake(&["--max-error", "0.000001"]).status.code(), Some(3));
    assert!(bake(&["--max-error", "0.99"]).status.success());
    assert_eq!(
        bake(&["--no-auto", "--max-error", "0.99"]).status.code(),
        Some(3)
    );
}

#[test]
fn a_damaged_error_map_is_rebaked() {
    let dir = scratch();
    let mut manifest = project(dir.path());
    manifest.scenes[1].config.output.error_map = true;
    let first = lightbake::build(&manifest, &NoProgress);
    assert_eq!(statuses(&first), [Status::Baked, Status::Baked]);
    let map = dir.path().join("baked/b/b_lightmap0_error.exr");
    assert!(!dir.path().join("baked/a/a_lightmap0_error.exr").exists());
    std::fs::write(&map, b"damaged").unwrap();
    let second = lightbake::build(&manifest, &NoProgress);
    assert_eq!(statuses(&second), [Status::Skipped, Status::Baked]);
    assert!(lightbake::output::read_exr(&map).is_ok());
}

/// Three scenes baked one at a time and two at a time: the same report (but for the times)
/// and the same bytes in every output directory.
#[test]
fn scenes_side_by_side_bake_as_one_after_another() {
    let run = |jobs: usize| {
        let dir = scratch();
        let mut manifest = project(dir.path());
        std::fs::copy(fixture("cornell_box.glb"), dir.path().join("levels/c.glb")).unwrap();
        let mut c = manifest.scenes[1].clone();
        c.path = "levels/c.glb".into();
        c.input = dir.path().join(&c.path);
        c.output = dir.path().join("baked/c");
        c.config.output.error_map = true;
        manifest.scenes.push(c);
        manifest.jobs = Some(jobs);
        let mut report = lightbake::build(&manifest, &NoProgress);
        for s in &mut report.scenes {
            assert_eq!(s.status, Status::Baked, "{s:?}");
            s.seconds = 0.0;
        }
        let files: Vec<(String, Vec<u8>)> = ["a", "b", "c"]
            .iter()
            .flat_map(|d| {
                let out = dir.path().join("baked").join(d);
                crate::util::list_files(&out)
                    .into_iter()
                    .map(move |f| (format!("{d}/{f}"), std::fs::read(out.join(&f)).unwrap()))
            })
            .collect();
        (report, files)
    };
    let (one, one_files) = run(1);
    let (two, two_files) = run(2);
    assert_eq!(one, two);
    assert!(one_files.len() >= 12, "{}", one_files.len());
    assert_eq!(
        one_files.iter().map(|f| &f.0).collect::<Vec<_>>(),
        two_files.iter().map(|f| &f.0).collect::<Vec<_>>()
    );
    for (a, b) in one_files.iter().zip(&two_files) {
        assert!(a.1 == b.1, "{} differs", a.0);
    }
}
