//! `<stem>_probes.json`: the baked probes as an engine reads them (documented in the guide's
//! output chapter, `src/guide/output.md`).
//!
//! One JSON object: `format` (`"lightbake-probes"`), `version` (3), `convention` (how to read
//! the coefficients, in words), `indirectOnly`, `grid` (`origin`, `step`, `count`, `rotation`
//! (the grid's axes, a unit quaternion `x, y, z, w`) and `order`: probe `(i, j, k)` is entry
//! `i + nx·(j + ny·k)`, at `origin + rotation·(step ⊙ (i, j, k))`; `null` for probes placed one
//! by one, from a node's children), `refinement` (absent when no cell is divided: `factor`,
//! `levels` `L`, `cells` (one array per level `ℓ`, 3 integers per divided cell: its lowest
//! corner on level `ℓ`'s lattice, `factor^ℓ` × grid coordinates) and `nodes` (3 integers per
//! added probe: its coordinates on the finest lattice, `factor^L` × grid coordinates), see
//! [`super::refine`]; the added probes follow the grid's entries), then flat arrays per probe:
//! `positions` (3 floats each: where it was baked), `valid` (0 or 1) and `sh` (27 floats each:
//! coefficient `m` of channel `c` at `27·probe + 3·m + c`). Floats are written in their shortest
//! exact decimal form, so the file reads back bit for bit and its bytes do not depend on the
//! thread count. Version 1 files (no refinement) and version 2 files (one level: `cells` one flat
//! array, no `levels`) read as before.

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
pub const VERSION: u32 = 3;
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
    /// Absent in version 2 (one level).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    levels: Option<u32>,
    cells: Cells,
    nodes: Vec<u32>,
}

/// Divided cells: one array per level (version 3), or one flat array (version 2, one level).
#[derive(Serialize, Deserialize)]
#[serde(untagged)]
enum Cells {
    Levels(Vec<Vec<u32>>),
    Flat(Vec<u32>),
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
            levels: Some(probes.refinement.levels()),
            cells: Cells::Levels(
                (probes.refinement.cells.iter())
                    .map(|l| l.iter().flatten().copied().collect())
                    .collect(),
            ),
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
            let levels: Vec<&[u32]> = match &r.cells {
                Cells::Levels(l) => l.iter().map(Vec::as_slice).collect(),
                Cells::Flat(f) => vec![f.as_slice()],
            };
            let whole = levels.iter().all(|l| l.len() % 3 == 0) && r.nodes.len() % 3 == 0;
            let refinement = super::Refinement {
                cells: levels.iter().map(|l| triples(l)).collect(),
                nodes: triples(&r.nodes),
            };
            // Version 3 states its levels; version 2 holds one level in a flat array.
            let stated = match (file.version, r.levels, &r.cells) {
                (3.., Some(l), Cells::Levels(c)) => l as usize == c.len(),
                (..=2, None, Cells::Flat(_)) => true,
                _ => false,
            };
            if r.factor != super::refine::FACTOR
                || !whole
                || !stated
                || !super::refine::consistent(g, &refinement)
            {
                return Err(Error::invalid(
                    path,
                    format!(
                        "a refinement of factor {} with {} levels, {} cells and {} nodes that does \
                         not fit its grid (factor {} expected, each level's cells within divided \
                         cells of the level above, every divided cell's nodes listed once, sorted)",
                        r.factor,
                        levels.len(),
                        levels.iter().map(|l| l.len() / 3).sum::<usize>(),
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
        budget: 0,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::probes::{Grid as ProbeGrid, Refinement as Tree};

    /// Probes on a 4 × 3 × 3 grid refined over `cells` (per level), each probe its own value.
    fn probes(cells: Vec<Vec<[u32; 3]>>) -> Probes {
        let grid = ProbeGrid {
            origin: Vec3::new(-1.0, 0.5, 2.0),
            step: Vec3::new(0.5, 0.25, 1.0),
            count: [4, 3, 3],
            rotation: Quat::IDENTITY,
        };
        let tree = Tree {
            nodes: super::super::refine::node_set(&cells),
            cells,
        };
        let n = grid.len() + tree.nodes.len();
        Probes {
            grid: Some(grid),
            refinement: tree,
            position: (0..n).map(|i| Vec3::splat(i as f32 * 0.1)).collect(),
            valid: (0..n).map(|i| i % 7 != 3).collect(),
            sh: (0..n)
                .map(|i| std::array::from_fn(|m| Vec3::new(i as f32, m as f32, 0.5)))
                .collect(),
            indirect_only: false,
            rays: 0,
            moved: 0,
            budget: 0,
        }
    }

    #[test]
    fn a_multilevel_file_reads_back_and_version_2_still_reads() {
        let path = Path::new("probes.json");
        let two = probes(vec![vec![[1, 0, 0], [2, 1, 1]], vec![[3, 1, 1]]]);
        assert!(super::super::refine::consistent(
            &two.grid.unwrap(),
            &two.refinement
        ));
        let bytes = to_json(&two).unwrap();
        assert_eq!(from_json(&bytes, path).unwrap(), two);
        // One level as version 2 wrote it: `cells` one flat array, no `levels`.
        let one = probes(vec![vec![[1, 0, 0], [2, 1, 1]]]);
        let mut v: serde_json::Value = serde_json::from_slice(&to_json(&one).unwrap()).unwrap();
        v["version"] = 2.into();
        let r = v["refinement"].as_object_mut().unwrap();
        assert_eq!(r.remove("levels"), Some(1.into()));
        let flat: Vec<serde_json::Value> = r["cells"][0].as_array().unwrap().clone();
        r["cells"] = flat.into();
        assert_eq!(
            from_json(&serde_json::to_vec(&v).unwrap(), path).unwrap(),
            one
        );
        // Levels that do not match the cells, or a cell outside a divided one: refused.
        let mut bad: serde_json::Value = serde_json::from_slice(&bytes).unwrap();
        bad["refinement"]["levels"] = 3.into();
        assert!(from_json(&serde_json::to_vec(&bad).unwrap(), path).is_err());
        let mut bad: serde_json::Value = serde_json::from_slice(&bytes).unwrap();
        bad["refinement"]["cells"][1] = serde_json::json!([0, 0, 0]);
        assert!(from_json(&serde_json::to_vec(&bad).unwrap(), path).is_err());
    }
}
