//! `<stem>_probes.json`: the baked probes as an engine reads them (documented in the guide's
//! output chapter, `src/guide/output.md`).
//!
//! One JSON object: `format` (`"lightbake-probes"`), `version` (2), `convention` (how to read
//! the coefficients, in words), `indirectOnly`, `grid` (`origin`, `step`, `count`, `rotation`
//! (the grid's axes, a unit quaternion `x, y, z, w`) and `order`: probe `(i, j, k)` is entry
//! `i + nx·(j + ny·k)`, at `origin + rotation·(step ⊙ (i, j, k))`; `null` for probes placed one
//! by one, from a node's children), `refinement` (absent when no cell is refined: `factor`,
//! `cells` (3 integers per refined cell: its lowest corner's grid coordinates) and `nodes` (3
//! integers per added probe: its fine-lattice coordinates, `factor` × grid coordinates), see
//! [`super::refine`]; the added probes follow the grid's entries), then flat arrays per probe: `positions`
//! (3 floats each: where it was baked), `valid` (0 or 1) and `sh` (27 floats each: coefficient
//! `m` of channel `c` at `27·probe + 3·m + c`). Floats are written in their shortest exact
//! decimal form, so the file reads back bit for bit and its bytes do not depend on the thread
//! count. Version 1 files (no refinement) read as before.

use std::path::Path;

use glam::{Quat, Vec3};
use serde::{Deserialize, Serialize};

use super::Probes;
use crate::{Error, Result};

/// The key of the glTF root's `extras` that names the file: `{"uri": "<stem>_probes.json",
/// "count": N}`, the uri relative to the glTF.
pub const EXTRAS_KEY: &str = "light_probes";
/// The `format` field.
pub const FORMAT: &str = "lightbake-probes";
/// The `version` field.
pub const VERSION: u32 = 2;
/// How to read the coefficients, as the file states it.
pub const CONVENTION: &str = "sh: 9 RGB coefficients of incident radiance per probe, \
    c_m = integral of L(w) Y_m(w) dw, three.js SphericalHarmonics3 order and basis; \
    E(n)/pi = sum_m w_l(m) c_m Y_m(n) with w = 1, 2/3, 1/4 for bands 0, 1, 2 \
    (three.js getIrradianceAt(n) / pi): the lightmaps' unit";

#[derive(Serialize, Deserialize)]
#[serde(rename_all = "camelCase")]
struct ProbeFile {
    format: String,
    version: u32,
    convention: String,
    indirect_only: bool,
    grid: Option<Grid>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    refinement: Option<Refinement>,
    positions: Vec<f32>,
    valid: Vec<u8>,
    sh: Vec<f32>,
}

#[derive(Serialize, Deserialize)]
struct Refinement {
    factor: u32,
    cells: Vec<u32>,
    nodes: Vec<u32>,
}

#[derive(Serialize, Deserialize)]
struct Grid {
    origin: [f32; 3],
    step: [f32; 3],
    count: [u32; 3],
    rotation: [f32; 4],
    order: String,
}

/// The file's bytes for `probes`.
pub fn to_json(probes: &Probes) -> Result<Vec<u8>> {
    let file = ProbeFile {
        format: FORMAT.into(),
        version: VERSION,
        convention: CONVENTION.into(),
        indirect_only: probes.indirect_only,
        grid: probes.grid.map(|g| Grid {
            origin: g.origin.to_array(),
            step: g.step.to_array(),
            count: g.count,
            rotation: g.rotation.to_array(),
            order: "x fastest, then y, then z".into(),
        }),
        refinement: (!probes.refinement.is_empty()).then(|| Refinement {
            factor: super::refine::FACTOR,
            cells: probes.refinement.cells.iter().flatten().copied().collect(),
            nodes: probes.refinement.nodes.iter().flatten().copied().collect(),
        }),
        positions: probes.position.iter().flat_map(|p| p.to_array()).collect(),
        valid: probes.valid.iter().map(|&v| u8::from(v)).collect(),
        sh: (probes.sh.iter())
            .flat_map(|c| c.iter().flat_map(|v| v.to_array()))
            .collect(),
    };
    serde_json::to_vec(&file).map_err(|e| Error::Internal(format!("probes: {e}")))
}

/// Reads a probe file (`path` names it in errors).
pub fn from_json(bytes: &[u8], path: &Path) -> Result<Probes> {
    let file: ProbeFile = serde_json::from_slice(bytes)
        .map_err(|e| Error::invalid(path, format!("not a probe file: {e}")))?;
    if file.format != FORMAT || !(1..=VERSION).contains(&file.version) {
        return Err(Error::invalid(
            path,
            format!(
                "format {:?} version {}, expected {FORMAT:?} version 1 to {VERSION}",
                file.format, file.version
            ),
        ));
    }
    let n = file.valid.len();
    let counts_fit = file.positions.len() == 3 * n && file.sh.len() == 27 * n && n > 0;
    if !counts_fit {
        return Err(Error::invalid(
            path,
            format!(
                "{n} probes need {} position and {} coefficient floats, got {} and {}",
                3 * n,
                27 * n,
                file.positions.len(),
                file.sh.len()
            ),
        ));
    }
    let grid = match &file.grid {
        None => None,
        Some(g) => {
            let [nx, ny, nz] = g.count;
            let step = Vec3::from(g.step);
            let rotation = Quat::from_array(g.rotation);
            let added = file.refinement.as_ref().map_or(0, |r| r.nodes.len() / 3);
            if nx as usize * ny as usize * nz as usize + added != n
                || step.min_element().is_nan()
                || step.min_element() <= 0.0
                || !rotation.is_normalized()
            {
                return Err(Error::invalid(
                    path,
                    format!(
                        "a {nx}×{ny}×{nz} grid of {n} probes, step {step}, rotation {rotation}: \
                         the count must match, the step be positive and the rotation a unit quaternion"
                    ),
                ));
            }
            Some(super::Grid {
                origin: Vec3::from(g.origin),
                step,
                count: g.count,
                rotation,
            })
        }
    };
    let triples = |v: &[u32]| v.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();
    let refinement = match (&file.refinement, &grid) {
        (None, _) => super::Refinement::default(),
        (Some(r), Some(g)) => {
            let refinement = super::Refinement {
                cells: triples(&r.cells),
                nodes: triples(&r.nodes),
            };
            let whole = r.cells.len() % 3 == 0 && r.nodes.len() % 3 == 0;
            if r.factor != super::refine::FACTOR
                || !whole
                || !super::refine::consistent(g, &refinement)
            {
                return Err(Error::invalid(
                    path,
                    format!(
                        "a refinement of factor {} with {} cells and {} nodes that does not fit \
                         its grid (factor {} expected, every refined cell's nodes listed once, sorted)",
                        r.factor,
                        r.cells.len() / 3,
                        r.nodes.len() / 3,
                        super::refine::FACTOR
                    ),
                ));
            }
            refinement
        }
        (Some(_), None) => {
            return Err(Error::invalid(
                path,
                "a refinement without a grid".to_string(),
            ));
        }
    };
    let vec3 = |v: &[f32]| Vec3::new(v[0], v[1], v[2]);
    Ok(Probes {
        grid,
        refinement,
        position: file.positions.chunks_exact(3).map(vec3).collect(),
        valid: file.valid.iter().map(|&v| v != 0).collect(),
        sh: (file.sh.chunks_exact(27))
            .map(|c| std::array::from_fn(|m| vec3(&c[3 * m..])))
            .collect(),
        indirect_only: file.indirect_only,
        rays: 0,
        moved: 0,
    })
}
