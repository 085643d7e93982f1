//! `lightbake view`: the viewer page of a baked scene on 127.0.0.1 (see [`lightbake::view`]).

use std::path::PathBuf;

use anyhow::{Context, Result};
use lightbake::view::{self, Viewer};

#[derive(clap::Args)]
pub struct Args {
    /// The baked scene (.gltf or .glb written by `lightbake bake`).
    scene: PathBuf,
    /// Port on 127.0.0.1 (0: any free port).
    #[arg(long, default_value_t = 8080)]
    port: u16,
    /// A point reference (CSV written by `lightbake reference SCENE --points N -o FILE`): adds
    /// the per-point error view.
    #[arg(long)]
    points: Option<PathBuf>,
}

pub fn run(args: &Args) -> Result<()> {
    let viewer = Viewer::new(&args.scene, args.points.as_deref())
        .with_context(|| format!("loading {} failed", args.scene.display()))?;
    let server = view::bind(args.port)?;
    let address = server
        .server_addr()
        .to_ip()
        .context("the server has no IP address")?;
    // The first line is the URL (tests read it); Ctrl-C ends the process.
    println!("http://{address}/");
    println!("serving {} (Ctrl-C stops)", args.scene.display());
    view::serve(&viewer, &server);
    Ok(())
}
