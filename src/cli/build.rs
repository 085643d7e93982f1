//! `lightbake build`: every scene of a manifest, skipping those whose outputs are up to date.

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use lightbake::Manifest;
use lightbake::build::Status;

use crate::progress::Bars;
use crate::{GateArgs, RunArgs};

#[derive(clap::Args)]
#[command(after_help = AFTER_HELP)]
pub struct Args {
    /// The manifest (TOML; see the guide, src/guide/build.md).
    #[arg(default_value = "lightbake.toml")]
    manifest: PathBuf,
    /// Bake every scene, even those whose outputs are up to date.
    #[arg(long)]
    force: bool,
    /// Write what happened to each scene as JSON (schema: src/build/report.schema.json).
    #[arg(long, value_name = "FILE.json")]
    report: Option<PathBuf>,
    /// Most scenes baked at once [default: as many as threads]; fewer run side by side when
    /// their estimated peak memory does not fit the memory available. Outputs and the report
    /// are the same for any N.
    #[arg(long, value_name = "N")]
    jobs: Option<usize>,
    #[command(flatten)]
    gate: GateArgs,
    #[command(flatten)]
    run: RunArgs,
}

const AFTER_HELP: &str = "\
Exit codes: 0 all scenes baked or up to date (and the gate passed); 1 a scene failed or the
manifest is wrong (the other scenes still ran); 2 bad command line; 3 the error gate failed
(--max-error or --deny-warnings); 130/143 interrupted.";

pub fn run(args: &Args) -> Result<()> {
    args.run.start()?;
    let mut manifest = Manifest::load(&args.manifest)
        .with_context(|| format!("reading the manifest {}", args.manifest.display()))?;
    manifest.force = args.force;
    manifest.jobs = args.jobs;
    let bars = Bars::new(args.run.quiet);
    let report = lightbake::build(&manifest, &bars);
    if let Some(path) = &args.report {
        std::fs::write(path, report.to_json())
            .with_context(|| format!("writing the report {}", path.display()))?;
    }
    for scene in &report.scenes {
        let path = scene.path.display();
        match (&scene.status, &scene.error) {
            (Status::Failed, error) => {
                eprintln!("failed  {path}: {}", error.as_deref().unwrap_or("?"))
            }
            (status, _) if !args.run.quiet => {
                let error = scene.result.estimated_error.and_then(|e| e.total);
                println!(
                    "{:<7} {path} ({:.2}s, {} texels, estimated error {})",
                    format!("{status:?}").to_lowercase(),
                    scene.seconds,
                    scene.result.texels.unwrap_or(0),
                    error.map_or("unknown".into(), |e| format!("{:.1}%", e * 100.0)),
                );
            }
            _ => {}
        }
    }
    let failed = report.scenes.iter().filter(|s| s.status == Status::Failed);
    let failed = failed.count();
    if failed > 0 {
        bail!("{failed} of {} scene(s) failed", report.scenes.len());
    }
    crate::check_gate(report.gate(&args.gate.gate()))
}
