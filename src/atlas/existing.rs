//! Reuse of the input's `TEXCOORD_1` as lightmap UVs, after checking it can serve as one: every
//! front instance has one, it lies in [0,1], and no two triangles share a texel centre.
//!
//! All front instances share page 0, sized so the layout gets about `texels_per_unit`. The
//! back-face copy of a double-sided primitive reuses its front's UVs on page 1 (same size): each
//! face gets its own texels without touching the input's UV layout.

use glam::{DVec2, Vec2};

use super::{Atlas, InstanceUv, PageSize, page_side};
use crate::config::AtlasParams;
use crate::scene::{Instance, Scene, Source};
use crate::{Error, Result};

/// UVs this far outside [0,1] are rounding noise and clamped; farther is an error.
const UV_SLACK: f32 = 1e-4;

/// Texel centres claimed by two triangles tolerated as rounding noise (T-junctions), as a
/// fraction of the covered texels.
const OVERLAP_TOLERANCE: f64 = 1e-3;

/// Builds the atlas from the input's `TEXCOORD_1`.
pub(crate) fn reuse(scene: &Scene, source: &Source, params: &AtlasParams) -> Result<Atlas> {
    let mut world_area = 0.0;
    let mut uv_area = 0.0;
    for inst in &scene.instances {
        if !inst.has_uv1 {
            return Err(invalid(
                source,
                inst,
                "has no TEXCOORD_1 to reuse as lightmap UVs (use --uv unwrap)",
            ));
        }
        check_range(scene, source, inst)?;
        if inst.back_of.is_some() {
            continue;
        }
        let (world, uv) = areas(scene, inst);
        if uv <= 0.0 && world > 0.0 {
            return Err(invalid(
                source,
                inst,
                "has a degenerate TEXCOORD_1 (every triangle has zero UV area)",
            ));
        }
        world_area += world;
        uv_area += uv;
    }
    if uv_area <= 0.0 {
        return Err(Error::invalid(
            &source.path,
            "the scene has no triangles with TEXCOORD_1 area to bake",
        ));
    }

    // Texels per side so that a world unit spans about `texels_per_unit` texels on average.
    let tpu = f64::from(params.texels_per_unit);
    let side = page_side(
        (world_area * tpu * tpu / uv_area).sqrt() as f32,
        params.max_page_size,
    );
    let size = PageSize {
        width: side,
        height: side,
    };
    check_overlaps(scene, source, size)?;

    let instances = scene
        .instances
        .iter()
        .map(|inst| instance_uv(scene, inst))
        .collect();
    let double_sided = scene.instances.iter().any(|inst| inst.back_of.is_some());
    let pages = if double_sided {
        vec![size; 2]
    } else {
        vec![size]
    };
    // The density achieved on average (the page side is rounded and clamped).
    let texels_per_unit = (f64::from(side) * (uv_area / world_area).sqrt()) as f32;
    Ok(Atlas {
        pages,
        instances,
        texels_per_unit,
        reused_input_uvs: true,
        shared: Vec::new(),
    })
}

fn invalid(source: &Source, inst: &Instance, what: &str) -> Error {
    Error::invalid(&source.path, format!("{} {what}", describe(source, inst)))
}

/// "mesh 'Name' (#m) primitive p (node n)", the name when the input has one.
fn describe(source: &Source, inst: &Instance) -> String {
    let name = source.json["meshes"][inst.mesh as usize]["name"].as_str();
    let mesh = match name {
        Some(name) => format!("mesh '{name}' (#{})", inst.mesh),
        None => format!("mesh {}", inst.mesh),
    };
    format!("{mesh} primitive {} (node {})", inst.primitive, inst.node)
}

fn local_uv1<'a>(scene: &'a Scene, inst: &Instance) -> &'a [Vec2] {
    &scene.uv1[inst.vertices.start as usize..inst.vertices.end as usize]
}

fn check_range(scene: &Scene, source: &Source, inst: &Instance) -> Result<()> {
    let inside = |uv: &Vec2| {
        uv.is_finite() && uv.min_element() >= -UV_SLACK && uv.max_element() <= 1.0 + UV_SLACK
    };
    match local_uv1(scene, inst).iter().position(|uv| !inside(uv)) {
        None => Ok(()),
        Some(k) => {
            let uv = local_uv1(scene, inst)[k];
            Err(invalid(
                source,
                inst,
                &format!(
                    "has TEXCOORD_1 ({}, {}) at vertex {k}, outside [0,1]",
                    uv.x, uv.y
                ),
            ))
        }
    }
}

/// World area and TEXCOORD_1 area (in units of the [0,1]² page) of an instance.
fn areas(scene: &Scene, inst: &Instance) -> (f64, f64) {
    let (mut world, mut uv) = (0.0, 0.0);
    for tri in &scene.triangles[inst.triangles.start as usize..inst.triangles.end as usize] {
        let [a, b, c] = tri.map(|v| scene.positions[v as usize].as_dvec3());
        world += 0.5 * (b - a).cross(c - a).length();
        let [a, b, c] = tri.map(|v| scene.uv1[v as usize].as_dvec2());
        uv += 0.5 * (b - a).perp_dot(c - a).abs();
    }
    (world, uv)
}

/// TEXCOORD_1 of scene triangle `t`, clamped to [0,1].
fn triangle_uv1(scene: &Scene, t: usize) -> [Vec2; 3] {
    scene.triangles[t].map(|v| scene.uv1[v as usize].clamp(Vec2::ZERO, Vec2::ONE))
}

/// Front instances must not share texel centres: names the culprits when they do.
fn check_overlaps(scene: &Scene, source: &Source, size: PageSize) -> Result<()> {
    let front: Vec<usize> = (0..scene.triangles.len())
        .filter(|&t| {
            scene.instances[scene.triangle_instance[t] as usize]
                .back_of
                .is_none()
        })
        .collect();
    let overlaps = Overlaps::find(size, front.iter().map(|&t| triangle_uv1(scene, t)));
    if overlaps.overlapping as f64 <= OVERLAP_TOLERANCE * overlaps.covered as f64 {
        return Ok(());
    }
    let Some(texel) = overlaps.first else {
        return Ok(());
    };
    // The first two triangles claiming that texel centre.
    let mut claimants = front.iter().filter(|&&t| {
        let mut hit = false;
        for_each_centre_inside(triangle_uv1(scene, t), size, |x, y| hit |= [x, y] == texel);
        hit
    });
    let (Some(&t0), Some(&t1)) = (claimants.next(), claimants.next()) else {
        return Ok(());
    };
    let [i0, i1] = [t0, t1].map(|t| &scene.instances[scene.triangle_instance[t] as usize]);
    let share = format!(
        "{} of {} covered texel centres at {}×{}",
        overlaps.overlapping, overlaps.covered, size.width, size.height
    );
    let message = if std::ptr::eq(i0, i1) {
        format!(
            "{} has TEXCOORD_1 triangles that overlap each other ({share}); use --uv unwrap",
            describe(source, i0)
        )
    } else if (i0.mesh, i0.primitive) == (i1.mesh, i1.primitive) {
        format!(
            "mesh {} is placed by nodes {} and {}, which share one TEXCOORD_1 layout, so their lightmap texels overlap ({share}); use --uv unwrap",
            i0.mesh, i0.node, i1.node
        )
    } else {
        format!(
            "TEXCOORD_1 of {} overlaps that of {} ({share}); use --uv unwrap",
            describe(source, i0),
            describe(source, i1)
        )
    };
    Err(Error::invalid(&source.path, message))
}

fn instance_uv(scene: &Scene, inst: &Instance) -> InstanceUv {
    let uv: Vec<Vec2> = local_uv1(scene, inst)
        .iter()
        .map(|uv| uv.clamp(Vec2::ZERO, Vec2::ONE))
        .collect();
    let triangles: Vec<[u32; 3]> = scene.triangles
        [inst.triangles.start as usize..inst.triangles.end as usize]
        .iter()
        .map(|t| t.map(|v| v - inst.vertices.start))
        .collect();
    let page = u32::from(inst.back_of.is_some());
    InstanceUv {
        xref: (0..uv.len() as u32).collect(),
        uv,
        triangle_page: vec![page; triangles.len()],
        triangles,
    }
}

/// Texel centres claimed by more than one triangle of a page layout.
#[derive(Clone, Copy, Debug, Default)]
pub struct Overlaps {
    /// Texel centres strictly inside at least one triangle.
    pub(crate) covered: u64,
    /// Texel centres strictly inside a second (third, …) triangle, counted once per extra claim.
    pub overlapping: u64,
    /// The first overlapping texel (in triangle order).
    pub(crate) first: Option<[u32; 2]>,
}

impl Overlaps {
    /// Rasterises `triangles` (UVs in \[0, 1\] of a `size` page) and counts shared texel
    /// centres. Centres strictly inside count, with each edge evaluated in a canonical order, so
    /// triangles sharing an edge never both claim a centre on it.
    pub fn find(size: PageSize, triangles: impl Iterator<Item = [Vec2; 3]>) -> Overlaps {
        let mut claimed = vec![0u64; (size.width as usize * size.height as usize).div_ceil(64)];
        let mut overlaps = Overlaps::default();
        for uv in triangles {
            for_each_centre_inside(uv, size, |x, y| {
                let bit = y as usize * size.width as usize + x as usize;
                let (word, mask) = (bit / 64, 1u64 << (bit % 64));
                if claimed[word] & mask == 0 {
                    claimed[word] |= mask;
                    overlaps.covered += 1;
                } else {
                    overlaps.overlapping += 1;
                    overlaps.first.get_or_insert([x, y]);
                }
            });
        }
        overlaps
    }
}

/// Calls `f(x, y)` for every texel whose centre lies strictly inside the triangle `uv` (in [0,1]
/// of a `size` page), whatever its winding. Each edge function is evaluated with the edge's end
/// points in a canonical order, so the two triangles sharing an edge get exactly opposite values
/// there and a centre on the edge is inside neither.
pub(crate) fn for_each_centre_inside(uv: [Vec2; 3], size: PageSize, mut f: impl FnMut(u32, u32)) {
    let scale = DVec2::new(f64::from(size.width), f64::from(size.height));
    let p = uv.map(|v| v.as_dvec2() * scale);
    let lo = p[0].min(p[1]).min(p[2]);
    let hi = p[0].max(p[1]).max(p[2]);
    // Texel x has its centre at x + 0.5.
    let first = |v: f64| (v - 0.5).ceil().max(0.0) as u32;
    let last = |v: f64, n: u32| ((v - 0.5).floor().min(f64::from(n) - 1.0)).max(-1.0) as i64;
    let (x_end, y_end) = (last(hi.x, size.width), last(hi.y, size.height));
    for y in first(lo.y)..(y_end + 1).max(0) as u32 {
        for x in first(lo.x)..(x_end + 1).max(0) as u32 {
            let c = DVec2::new(f64::from(x) + 0.5, f64::from(y) + 0.5);
            let e = [
                edge(p[0], p[1], c),
                edge(p[1], p[2], c),
                edge(p[2], p[0], c),
            ];
            if e.iter().all(|&v| v > 0.0) || e.iter().all(|&v| v < 0.0) {
                f(x, y);
            }
        }
    }
}

/// Which side of the line a → b the point `c` is on, antisymmetric in (a, b) to the last bit.
fn edge(a: DVec2, b: DVec2, c: DVec2) -> f64 {
    if (a.x, a.y) <= (b.x, b.y) {
        (b - a).perp_dot(c - a)
    } else {
        -(a - b).perp_dot(c - b)
    }
}

#[cfg(test)]
mod tests {
    use glam::{Vec2, Vec3};

    use super::super::xatlas::tests::{Part, cube, params, quad, scene_of, source};
    use super::*;
    use crate::config::UvMode;

    fn reuse_params(texels_per_unit: f32) -> AtlasParams {
        AtlasParams {
            uv: UvMode::Existing,
            ..params(texels_per_unit, 1024)
        }
    }

    /// A quad whose TEXCOORD_1 is the given rectangle.
    fn quad_in(origin: Vec3, lo: Vec2, hi: Vec2) -> Part {
        let mut part = quad(origin, 1.0, 1.0);
        let uv = part.uv1.as_mut().unwrap();
        uv.iter_mut().for_each(|v| *v = lo + *v * (hi - lo));
        part
    }

    fn error_of(scene: &Scene) -> String {
        reuse(scene, &source(), &reuse_params(16.0))
            .unwrap_err()
            .to_string()
    }

    #[test]
    fn valid_layout_is_reused_at_the_requested_density() {
        // Two 1×1 quads, each on half of the page: 2 m² on 0.5 of the UV square.
        let scene = scene_of(
            &[
                quad_in(Vec3::ZERO, Vec2::ZERO, Vec2::new(0.5, 0.5)),
                quad_in(Vec3::X * 2.0, Vec2::new(0.5, 0.5), Vec2::ONE),
            ],
            &[],
        );
        let atlas = reuse(&scene, &source(), &reuse_params(16.0)).unwrap();
        atlas.validate(&scene);
        // sqrt(2 × 16² / 0.5) = 32.
        assert_eq!(
            atlas.pages,
            vec![PageSize {
                width: 32,
                height: 32
            }]
        );
        assert!(atlas.reused_input_uvs);
        assert!((atlas.texels_per_unit - 16.0).abs() < 1e-3);
        let inst = &atlas.instances[1];
        assert_eq!(inst.xref, vec![0, 1, 2, 3]);
        assert_eq!(inst.uv[1], Vec2::ONE);
        assert_eq!(inst.triangles, vec![[0, 1, 2], [0, 2, 3]]);
    }

    #[test]
    fn page_size_is_rounded_and_clamped() {
        let scene = scene_of(&[quad(Vec3::ZERO, 1.0, 1.0)], &[]);
        let side = |tpu: f32, max: u32| {
            reuse(
                &scene,
                &source(),
                &AtlasParams {
                    max_page_size: max,
                    ..reuse_params(tpu)
                },
            )
            .unwrap()
            .pages[0]
                .width
        };
        assert_eq!(side(2.0, 1024), 16);
        assert_eq!(side(37.0, 1024), 40);
        assert_eq!(side(4000.0, 512), 512);
    }

    #[test]
    fn back_faces_reuse_the_layout_on_a_second_page() {
        let scene = scene_of(
            &[
                quad_in(Vec3::ZERO, Vec2::ZERO, Vec2::splat(0.5)),
                quad_in(Vec3::X * 2.0, Vec2::splat(0.6), Vec2::splat(0.7)),
            ],
            &[0],
        );
        let atlas = reuse(&scene, &source(), &reuse_params(16.0)).unwrap();
        atlas.validate(&scene);
        assert_eq!(atlas.pages.len(), 2);
        assert_eq!(atlas.pages[0], atlas.pages[1]);
        assert_eq!(atlas.instances[2].triangle_page, vec![1, 1]);
        assert_eq!(atlas.instances[0].triangle_page, vec![0, 0]);
        assert_eq!(atlas.instances[2].uv, atlas.instances[0].uv);
    }

    #[test]
    fn missing_texcoord1_is_an_error() {
        let mut part = quad(Vec3::ZERO, 1.0, 1.0);
        part.uv1 = None;
        part.mesh = 3;
        let message = error_of(&scene_of(&[part], &[]));
        assert!(
            message.contains("test.gltf")
                && message.contains("mesh 3")
                && message.contains("no TEXCOORD_1"),
            "{message}"
        );
    }

    #[test]
    fn out_of_range_uvs_are_an_error_and_rounding_noise_is_clamped() {
        let noisy = quad_in(Vec3::ZERO, Vec2::splat(-5e-5), Vec2::splat(1.0 + 5e-5));
        let atlas = reuse(&scene_of(&[noisy], &[]), &source(), &reuse_params(16.0)).unwrap();
        assert!(
            atlas.instances[0]
                .uv
                .iter()
                .all(|uv| uv.min_element() >= 0.0 && uv.max_element() <= 1.0)
        );

        let message = error_of(&scene_of(
            &[quad_in(Vec3::ZERO, Vec2::ZERO, Vec2::new(1.0, 1.5))],
            &[],
        ));
        assert!(message.contains("outside [0,1]"), "{message}");
        let mut nan = quad(Vec3::ZERO, 1.0, 1.0);
        nan.uv1.as_mut().unwrap()[2].x = f32::NAN;
        assert!(error_of(&scene_of(&[nan], &[])).contains("outside [0,1]"));
    }

    #[test]
    fn instanced_mesh_sharing_one_layout_overlaps() {
        let part = quad(Vec3::ZERO, 1.0, 1.0);
        let scene = scene_of(&[part.clone(), part.moved(Vec3::X * 2.0, 1)], &[]);
        let message = error_of(&scene);
        assert!(
            message.contains("nodes 0 and 1") && message.contains("--uv unwrap"),
            "{message}"
        );
    }

    #[test]
    fn overlapping_primitives_and_folds_are_errors() {
        let mut other = quad_in(Vec3::X * 2.0, Vec2::splat(0.4), Vec2::ONE);
        other.mesh = 1;
        let message = error_of(&scene_of(
            &[quad_in(Vec3::ZERO, Vec2::ZERO, Vec2::splat(0.6)), other],
            &[],
        ));
        assert!(message.contains("overlaps that of"), "{message}");

        // The second triangle folded back over the first.
        let mut folded = quad(Vec3::ZERO, 1.0, 1.0);
        folded.uv1.as_mut().unwrap()[3] = Vec2::new(0.9, 0.9);
        let message = error_of(&scene_of(&[folded], &[]));
        assert!(message.contains("overlap each other"), "{message}");
    }

    #[test]
    fn shared_edges_never_count_as_overlap() {
        // A fine irregular grid mapped onto the whole page: every texel centre claimed once.
        let n = 23;
        // Interior vertices only, different in u and v (no edge runs along a texel diagonal).
        let jitter = |i: u32, j: u32, k: u32| {
            if i.is_multiple_of(n) || j.is_multiple_of(n) {
                0.0
            } else {
                0.3 * ((i * 7 + j * 13 + k) % 5) as f32 / 5.0
            }
        };
        let mut uv = Vec::new();
        for j in 0..=n {
            for i in 0..=n {
                uv.push(
                    Vec2::new(
                        (i as f32 + jitter(i, j, 1)) / n as f32,
                        (j as f32 + jitter(j, i, 3)) / n as f32,
                    )
                    .min(Vec2::ONE),
                );
            }
        }
        let mut triangles = Vec::new();
        for j in 0..n {
            for i in 0..n {
                let a = j * (n + 1) + i;
                triangles.push([uv[a as usize], uv[a as usize + 1], uv[(a + n + 2) as usize]]);
                triangles.push([
                    uv[a as usize],
                    uv[(a + n + 2) as usize],
                    uv[(a + n + 1) as usize],
                ]);
            }
        }
        for side in [16, 61, 128] {
            let size = PageSize {
                width: side,
                height: side,
            };
            let overlaps = Overlaps::find(size, triangles.iter().copied());
            assert_eq!(overlaps.overlapping, 0, "{side}: {overlaps:?}");
            assert_eq!(
                overlaps.covered,
                u64::from(side * side),
                "{side}: {overlaps:?}"
            );
        }
    }

    #[test]
    fn cube_without_texcoord1_falls_back_in_auto_mode() {
        let scene = scene_of(&[cube(1.0, 1)], &[]);
        assert!(reuse(&scene, &source(), &reuse_params(8.0)).is_err());
        let atlas = super::super::build(
            &scene,
            &source(),
            &AtlasParams {
                uv: UvMode::Auto,
                ..reuse_params(8.0)
            },
        )
        .unwrap();
        assert!(!atlas.reused_input_uvs);
    }
}
