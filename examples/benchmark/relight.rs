//! Relighting against baking again (issue 16): a scene baked at draft with the automatic choice,
//! its transport kept and per-light layers written; then relit with other emission and a new
//! floor colour, and baked afresh with those values and the kept settings (no automatic
//! choice), in one run. `--relight` runs this part alone (on the large hall by default).

use std::path::{Path, PathBuf};
use std::time::Instant;

use glam::Vec3;
use lightbake::config::AutoParams;
use lightbake::relight::Edits;
use lightbake::{BakeConfig, NoProgress, bake, kept, metrics};
use serde_json::{Value, json};

/// One scene's relight figures.
pub struct RelightRow {
    pub scene: String,
    pub texels: usize,
    /// The first bake, with `--keep-transport --layers` (pilot, transport, solve, layers).
    pub bake_seconds: f64,
    pub transport_mib: f64,
    /// Relight without layers, and with every default layer.
    pub relight_seconds: f64,
    pub layers: usize,
    pub relight_layers_seconds: f64,
    /// A fresh bake of the edited scene with the kept settings.
    pub fresh_seconds: f64,
    /// Relative L1 difference of the relit and the fresh lightmap (all valid page texels).
    pub difference: f32,
}

impl RelightRow {
    pub fn speedup(&self) -> f64 {
        self.fresh_seconds / self.relight_seconds
    }

    pub const CSV_HEADER: &str = "scene,texels,bake_keep_s,transport_mib,relight_s,layers,relight_layers_s,fresh_bake_s,speedup,relit_vs_fresh_l1";

    pub fn csv(&self) -> String {
        format!(
            "{},{},{:.3},{:.1},{:.3},{},{:.3},{:.3},{:.1},{:.2e}",
            self.scene,
            self.texels,
            self.bake_seconds,
            self.transport_mib,
            self.relight_seconds,
            self.layers,
            self.relight_layers_seconds,
            self.fresh_seconds,
            self.speedup(),
            self.difference
        )
    }

    pub fn markdown(rows: &[RelightRow]) -> String {
        let mut md = String::from(
            "\n## Relight from a kept transport\n\n\
             Baked at draft (automatic choice) with `--keep-transport --layers`, then relit with \
             the emission halved and a new floor colour, and baked afresh with those values and the \
             kept settings (`--no-auto`), in one run.\n\n\
             | scene | texels | bake (keep) | transport | relight | layers | relight + layers | fresh bake | speed-up | relit vs fresh (L1) |\n\
             |---|---|---|---|---|---|---|---|---|---|\n",
        );
        for r in rows {
            md.push_str(&format!(
                "| {} | {} | {:.2} s | {:.0} MiB | {:.2} s | {} | {:.2} s | {:.2} s | {:.1}× | {:.1e} |\n",
                r.scene,
                r.texels,
                r.bake_seconds,
                r.transport_mib,
                r.relight_seconds,
                r.layers,
                r.relight_layers_seconds,
                r.fresh_seconds,
                r.speedup(),
                r.difference
            ));
        }
        md
    }
}

/// Measures `gltf` (a `.gltf` whose buffers are beside it or embedded) in `work`.
pub fn measure(name: &str, gltf: &Path, work: &Path) -> RelightRow {
    let dir = work.join(format!("relight_{name}"));
    let _ = std::fs::remove_dir_all(&dir);
    let mut config = BakeConfig::draft();
    config.auto = Some(AutoParams {
        target_error: AutoParams::for_preset("draft").unwrap(),
        keep: Default::default(),
    });
    config.output.keep_transport = true;
    config.output.layers = Some(Vec::new());
    config.output.float = true; // relit and fresh pages compared without half-float rounding
    let baked_dir = dir.join("baked");
    let t = Instant::now();
    let report = bake(gltf, &baked_dir, &config, &NoProgress).expect("bake");
    let bake_seconds = t.elapsed().as_secs_f64();
    let out = baked_dir.join(gltf.file_name().unwrap());
    let transport_mib =
        std::fs::metadata(kept::path_beside(&out)).unwrap().len() as f64 / 1048576.0;
    let settings = kept::read(&out).expect("kept transport").settings;

    // Half of every emitter's emission, and a new floor colour.
    let emissive: Vec<String> = (settings.emissive.iter())
        .map(|&m| settings.materials[m as usize].label.clone())
        .collect();
    let floor = settings
        .materials
        .iter()
        .find(|m| m.label == "floor")
        .map(|m| m.label.clone());
    let edits = Edits {
        emission: emissive.iter().map(|m| (m.clone(), 0.5)).collect(),
        albedo: floor
            .iter()
            .map(|m| (m.clone(), Vec3::new(0.6, 0.45, 0.3)))
            .collect(),
        ..Default::default()
    };
    let relit_dir = dir.join("relit");
    let t = Instant::now();
    let relit =
        lightbake::relight::relight(&out, &relit_dir, &edits, None, &NoProgress).expect("relight");
    let relight_seconds = t.elapsed().as_secs_f64();
    eprintln!(
        "   bake: {}\n   relight: {}",
        report.summary(),
        relit.summary()
    );
    let t = Instant::now();
    let layered =
        lightbake::relight::relight(&out, &dir.join("layers"), &edits, Some(&[]), &NoProgress)
            .expect("relight with layers");
    let relight_layers_seconds = t.elapsed().as_secs_f64();

    // The edited scene, baked afresh with the kept settings.
    let edited = edited_input(gltf, &dir, &emissive, floor.as_deref());
    let fresh_config = settings.config().expect("kept settings");
    let fresh_dir = dir.join("fresh");
    let t = Instant::now();
    bake(&edited, &fresh_dir, &fresh_config, &NoProgress).expect("fresh bake");
    let fresh_seconds = t.elapsed().as_secs_f64();

    let stem = gltf.file_stem().unwrap().to_string_lossy().into_owned();
    RelightRow {
        scene: name.to_string(),
        texels: report.texels,
        bake_seconds,
        transport_mib,
        relight_seconds,
        layers: layered.layers,
        relight_layers_seconds,
        fresh_seconds,
        difference: page_difference(&relit_dir, &fresh_dir, &stem),
    }
}

/// `gltf` with the emitters' strength halved and the floor's colour set, beside its buffers.
fn edited_input(gltf: &Path, dir: &Path, emissive: &[String], floor: Option<&str>) -> PathBuf {
    let mut json: Value = serde_json::from_slice(&std::fs::read(gltf).unwrap()).unwrap();
    let mut used = false;
    for m in json["materials"].as_array_mut().unwrap() {
        let name = m["name"].as_str().unwrap_or("").to_string();
        if emissive.contains(&name) {
            let s = &mut m["extensions"]["KHR_materials_emissive_strength"]["emissiveStrength"];
            *s = json!(s.as_f64().unwrap_or(1.0) * 0.5);
            used = true;
        }
        if Some(name.as_str()) == floor {
            m["pbrMetallicRoughness"]["baseColorFactor"] = json!([0.6, 0.45, 0.3, 1.0]);
        }
    }
    if used {
        let list = json["extensionsUsed"].as_array_mut();
        match list {
            Some(l) if l.iter().any(|e| e == "KHR_materials_emissive_strength") => {}
            Some(l) => l.push(json!("KHR_materials_emissive_strength")),
            None => json["extensionsUsed"] = json!(["KHR_materials_emissive_strength"]),
        }
    }
    // Beside the original, so relative buffer URIs resolve.
    let path = gltf.with_file_name(format!(
        "edited_{}",
        gltf.file_name().unwrap().to_string_lossy()
    ));
    std::fs::write(&path, serde_json::to_vec(&json).unwrap()).unwrap();
    let _ = dir;
    path
}

/// Relative L1 difference of the EXR pages of two outputs.
fn page_difference(a: &Path, b: &Path, stem: &str) -> f32 {
    let (mut x, mut r) = (Vec::new(), Vec::new());
    for k in 0.. {
        let (pa, pb) = (
            a.join(format!("{stem}_lightmap{k}.exr")),
            b.join(format!("edited_{stem}_lightmap{k}.exr")),
        );
        if !pa.exists() || !pb.exists() {
            break;
        }
        let (pa, pb) = (
            lightbake::output::read_exr(&pa).unwrap(),
            lightbake::output::read_exr(&pb).unwrap(),
        );
        for k in 0..pa.rgb.len().min(pb.rgb.len()) {
            if pa.valid[k] && pb.valid[k] {
                x.push(pa.rgb[k]);
                r.push(pb.rgb[k]);
            }
        }
    }
    metrics::relative_l1(&x, &r)
}
