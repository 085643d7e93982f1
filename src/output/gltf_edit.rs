//! Edits to a glTF lightbake has written: its JSON read from the `.gltf` or `.glb`, changed and
//! written back in the same container, the binary chunk as it was. A relight writes its new
//! light and material values this way, and a bake with layers names them in the glTF; the files
//! the glTF references are staged beside it ([`copy_referenced`]).

use std::path::Path;

use glam::Vec3;
use serde_json::{Value, json};

use super::{PageFiles, Staging, decode_uri, glb};
use crate::{Error, Result};

/// The JSON of `bytes`, a `.gltf` file or a `.glb`.
pub(crate) fn json_of(bytes: &[u8], path: &Path) -> Result<Value> {
    let json = match bytes.starts_with(b"glTF") {
        true => {
            gltf::binary::Glb::from_slice(bytes)
                .map_err(|e| Error::invalid(path, format!("not a GLB: {e}")))?
                .json
        }
        false => bytes.into(),
    };
    serde_json::from_slice(&json).map_err(|e| Error::invalid(path, format!("not glTF JSON: {e}")))
}

/// `bytes` (a `.gltf` or `.glb`) with its JSON changed by `edit`.
pub(crate) fn edit_gltf(
    bytes: &[u8],
    path: &Path,
    edit: impl FnOnce(&mut Value) -> Result<()>,
) -> Result<Vec<u8>> {
    let mut json = json_of(bytes, path)?;
    edit(&mut json)?;
    let invalid = |e: serde_json::Error| {
        Error::Internal(format!("{}: cannot write the glTF: {e}", path.display()))
    };
    if bytes.starts_with(b"glTF") {
        let glb = gltf::binary::Glb::from_slice(bytes)
            .map_err(|e| Error::invalid(path, format!("not a GLB: {e}")))?;
        let bin = glb.bin.map(|b| b.into_owned()).unwrap_or_default();
        Ok(glb::container(
            serde_json::to_vec(&json).map_err(invalid)?,
            bin,
        ))
    } else {
        serde_json::to_vec_pretty(&json).map_err(invalid)
    }
}

/// Multiplies `KHR_lights_punctual` light `light`'s `color × intensity` by `factor` per
/// channel: the colour kept within [0, 1] (glTF's range), the intensity taking the rest.
pub(crate) fn scale_light(json: &mut Value, light: usize, factor: Vec3) {
    let light = &mut json["extensions"]["KHR_lights_punctual"]["lights"][light];
    let color = light.get("color").and_then(rgb).unwrap_or(Vec3::ONE);
    let intensity = light
        .get("intensity")
        .and_then(Value::as_f64)
        .unwrap_or(1.0) as f32;
    let v = color * factor;
    let peak = v.max_element();
    if peak > 0.0 {
        light["color"] = json!((v / peak).to_array());
        light["intensity"] = json!(intensity * peak);
    } else {
        light["intensity"] = json!(0.0);
    }
}

/// Multiplies material `material`'s emission by `factor` through its
/// `KHR_materials_emissive_strength` (1 when it has none), which the glTF then declares used.
pub(crate) fn scale_emission(json: &mut Value, material: usize, factor: f32) {
    let ext = &mut json["materials"][material]["extensions"]["KHR_materials_emissive_strength"];
    let strength = ext
        .get("emissiveStrength")
        .and_then(Value::as_f64)
        .unwrap_or(1.0);
    ext["emissiveStrength"] = json!(strength as f32 * factor);
    match json["extensionsUsed"].as_array_mut() {
        Some(used) if used.iter().any(|e| e == "KHR_materials_emissive_strength") => {}
        Some(used) => used.push(json!("KHR_materials_emissive_strength")),
        None => json["extensionsUsed"] = json!(["KHR_materials_emissive_strength"]),
    }
}

/// Sets material `material`'s base colour factor to `color` (its alpha kept).
pub(crate) fn set_base_color(json: &mut Value, material: usize, color: Vec3) {
    let material = &mut json["materials"][material]["pbrMetallicRoughness"];
    let alpha = material["baseColorFactor"][3].as_f64().unwrap_or(1.0) as f32;
    material["baseColorFactor"] = json!([color.x, color.y, color.z, alpha]);
}

/// The materials that are one of `sources` (input material indices) or a lightmap copy the
/// bake made of the material `name` (`<name> (lightmap k)`): an edit to it goes to all.
pub(crate) fn material_copies(json: &Value, sources: &[u32], name: &str) -> Vec<usize> {
    let copy = |n: &str| {
        n.strip_prefix(name)
            .and_then(|rest| rest.strip_prefix(" (lightmap "))
            .and_then(|rest| rest.strip_suffix(')'))
            .is_some_and(|k| k.parse::<u32>().is_ok())
    };
    let materials = json["materials"].as_array().map_or(&[][..], Vec::as_slice);
    (materials.iter().enumerate())
        .filter(|(k, m)| sources.contains(&(*k as u32)) || m["name"].as_str().is_some_and(copy))
        .map(|(k, _)| k)
        .collect()
}

fn rgb(v: &Value) -> Option<Vec3> {
    let a = v.as_array()?;
    let c = |k: usize| a.get(k).and_then(Value::as_f64).map(|x| x as f32);
    Some(Vec3::new(c(0)?, c(1)?, c(2)?))
}

/// One lightmap layer as the glTF names it (`extras.lightmap_layers`).
pub(crate) struct LayerExtras<'a> {
    pub(crate) name: &'a str,
    /// The lights and emissive materials whose light it holds, by name.
    pub(crate) lights: Vec<String>,
    pub(crate) emissive_materials: Vec<String>,
    pub(crate) sky: bool,
    pub(crate) pages: &'a [PageFiles],
}

/// Sets the glTF root's `extras.lightmap_layers` to `layers` (nothing when there are none): per
/// layer its name, sources and pages, which line up with the lightmap's (page k of a
/// primitive's `extras.lightmap.page`, or of the node's for a mesh written once under
/// `--instancing share`, is page k of every layer). An engine mixes them as
/// `lightmap = Σ weight_layer × layer page`.
pub(crate) fn set_layer_extras(json: &mut Value, layers: &[LayerExtras]) -> Result<()> {
    if layers.is_empty() {
        return Ok(());
    }
    let entries: Vec<Value> = (layers.iter())
        .map(|layer| {
            let pages: Vec<Value> = (layer.pages.iter())
                .map(|f| json!({"exr": f.exr, "png": f.png}))
                .collect();
            json!({
                "name": layer.name,
                "lights": layer.lights,
                "emissiveMaterials": layer.emissive_materials,
                "sky": layer.sky,
                "pages": pages,
            })
        })
        .collect();
    let root = json
        .as_object_mut()
        .ok_or_else(|| Error::Internal("the glTF is not a JSON object".to_string()))?;
    let extras = root.entry("extras").or_insert_with(|| json!({}));
    let extras = extras.as_object_mut().ok_or_else(|| {
        Error::Option(
            "the glTF's root extras is not an object: the layers cannot be named in it".to_string(),
        )
    })?;
    extras.insert("lightmap_layers".to_string(), Value::Array(entries));
    Ok(())
}

/// Sets `key` of the glTF root's `extras` (made an object if missing) to `value`.
pub(crate) fn set_root_extra(json: &mut Value, key: &str, value: Value) -> Result<()> {
    let root = json
        .as_object_mut()
        .ok_or_else(|| Error::Internal("the glTF is not a JSON object".to_string()))?;
    let extras = root.entry("extras").or_insert_with(|| json!({}));
    let extras = extras.as_object_mut().ok_or_else(|| {
        Error::Option(format!(
            "the glTF's root extras is not an object: {key} cannot be named in it"
        ))
    })?;
    extras.insert(key.to_string(), value);
    Ok(())
}

/// Stages a copy of every external buffer and image `json` (the glTF at `gltf`) references
/// that is not staged yet (the pages are).
pub(crate) fn copy_referenced(staging: &mut Staging, gltf: &Path, json: &Value) -> Result<()> {
    let dir = gltf.parent().unwrap_or(Path::new("."));
    for key in ["buffers", "images"] {
        for item in json[key].as_array().map_or(&[][..], Vec::as_slice) {
            let Some(uri) = item["uri"].as_str().filter(|u| !u.starts_with("data:")) else {
                continue;
            };
            let name = decode_uri(uri).unwrap_or_else(|| uri.to_string());
            if staging.contains(&name) {
                continue;
            }
            let path = dir.join(&name);
            let bytes = std::fs::read(&path).map_err(|e| Error::io(&path, e))?;
            staging.write(&name, &bytes)?;
        }
    }
    Ok(())
}
