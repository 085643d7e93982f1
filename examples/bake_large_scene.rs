//! A procedurally generated 100k+-triangle landscape — a displaced terrain grid with a ring of
//! instanced columns under a sun and a sky — baked at a modest texel density and rendered.
//!
//!     cargo run --release --example bake_large_scene [-- <output dir>]
//!
//! Writes `<dir>/large_scene/` (input and bake) and `<dir>/large_scene.png` (default dir:
//! `target/examples-out`), and prints the time of each stage. The gallery image
//! `examples/gallery/large_scene.png` is this render.

use std::f32::consts::TAU;
use std::path::{Path, PathBuf};
use std::time::Instant;

use glam::{Quat, Vec2, Vec3};
use lightbake::render::{RenderOptions, RenderScene};
use lightbake::testing::{Camera, Face, Geometry, GltfBuilder, Light, Material, Node};
use lightbake::{BakeConfig, NoProgress};

/// Terrain size (m) and grid resolution (quads per side): 2 × 260 × 220 = 114 400 triangles.
const SIZE: Vec2 = Vec2::new(60.0, 50.0);
const QUADS: (u32, u32) = (260, 220);
const SKY: Vec3 = Vec3::new(0.25, 0.35, 0.55);

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let out: PathBuf = std::env::args()
        .nth(1)
        .map_or_else(|| root.join("target/examples-out"), PathBuf::from);
    let work = out.join("large_scene");
    std::fs::create_dir_all(&work)?;

    let t = Instant::now();
    let g = landscape();
    let input = work.join("large_scene.gltf");
    g.write_gltf(&input)?;
    println!(
        "generated {} mesh triangles in {:.2}s",
        g.mesh_triangle_count(),
        t.elapsed().as_secs_f64()
    );

    let mut config = BakeConfig::draft();
    config.atlas.texels_per_unit = 3.0;
    config.transport.sky = SKY;
    let t = Instant::now();
    let baked_dir = work.join("baked");
    let report = lightbake::bake(&input, &baked_dir, &config, &NoProgress)?;
    println!(
        "bake: {} ({:.2}s)",
        report.summary(),
        t.elapsed().as_secs_f64()
    );

    let t = Instant::now();
    let scene = RenderScene::load(&baked_dir.join("large_scene.gltf"))?;
    println!(
        "render setup (load, pages, BVH over {} triangles): {:.2}s",
        scene.tracer.len(),
        t.elapsed().as_secs_f64()
    );
    let camera = scene.camera(None, 1.0)?;
    let options = RenderOptions {
        width: 320,
        height: 320,
        spp: 16,
        background: SKY,
        ..RenderOptions::default()
    };
    let t = Instant::now();
    let image = scene.render(&camera, &options)?;
    println!(
        "render: 320x320, 16 spp, {:.2}s, {:.2} M rays, {} non-finite samples",
        t.elapsed().as_secs_f64(),
        image.rays as f64 * 1e-6,
        image.nonfinite
    );
    let png = out.join("large_scene.png");
    image.save(&png, 0.0)?;
    println!("wrote {}", png.display());
    Ok(())
}

/// Rolling hills: a few octaves of sines, flattened towards the centre where the columns stand.
fn height(p: Vec2) -> f32 {
    let hills = 1.6 * (p.x * 0.21).sin() * (p.y * 0.17).cos()
        + 0.7 * (p.x * 0.53 + 1.3).sin() * (p.y * 0.47 + 0.4).sin()
        + 0.15 * (p.x * 1.9).sin() * (p.y * 2.3).cos();
    let flat = (p.length() / 14.0).clamp(0.0, 1.0);
    hills * flat * flat
}

fn terrain() -> Geometry {
    let (nu, nv) = QUADS;
    let mut positions = Vec::new();
    let mut normals = Vec::new();
    let e = 0.05;
    for j in 0..=nv {
        for i in 0..=nu {
            let p = Vec2::new(i as f32 / nu as f32 - 0.5, j as f32 / nv as f32 - 0.5) * SIZE;
            positions.push(Vec3::new(p.x, height(p), p.y));
            // Normal of the height field from central differences.
            let dx = height(p + Vec2::X * e) - height(p - Vec2::X * e);
            let dz = height(p + Vec2::Y * e) - height(p - Vec2::Y * e);
            normals.push(Vec3::new(-dx, 2.0 * e, -dz).normalize());
        }
    }
    let mut indices = Vec::new();
    let at = |i: u32, j: u32| j * (nu + 1) + i;
    for j in 0..nv {
        for i in 0..nu {
            // Counter-clockwise seen from above (+y).
            let (a, b, c, d) = (at(i, j), at(i + 1, j), at(i + 1, j + 1), at(i, j + 1));
            indices.extend([a, c, b, a, d, c]);
        }
    }
    Geometry::new(&positions, Some(&normals), None, &indices)
}

/// An octagonal column 0.5 m across and 5 m high with a square cap stone.
fn column() -> Geometry {
    let (sides, rings, r, h) = (8u32, 10u32, 0.25f32, 5.0f32);
    let mut positions = Vec::new();
    let mut normals = Vec::new();
    for k in 0..=rings {
        for s in 0..sides {
            let a = TAU * s as f32 / sides as f32;
            let n = Vec3::new(a.cos(), 0.0, a.sin());
            positions.push(n * r + Vec3::Y * (h * k as f32 / rings as f32));
            normals.push(n);
        }
    }
    let mut indices = Vec::new();
    for k in 0..rings {
        for s in 0..sides {
            let (a, b) = (k * sides + s, k * sides + (s + 1) % sides);
            let (c, d) = (a + sides, b + sides);
            indices.extend([a, c, b, b, c, d]);
        }
    }
    let mut g = Geometry::new(&positions, Some(&normals), None, &indices);
    let cap = Geometry::box_faces(
        Vec3::new(-0.4, h, -0.4),
        Vec3::new(0.4, h + 0.3, 0.4),
        &Face::ALL,
        1,
    );
    g.append(&cap.without_uv0());
    g
}

fn landscape() -> GltfBuilder {
    let mut g = GltfBuilder::new("large_scene");
    let grass = g.add_material(Material::diffuse("grass", [0.25, 0.4, 0.15]));
    let stone = g.add_material(Material::diffuse("stone", [0.75, 0.7, 0.6]));
    let ground = g.add_mesh("terrain", terrain(), grass);
    g.add_mesh_node("terrain", ground);
    let column = g.add_mesh("column", column(), stone);
    for k in 0..24 {
        let a = TAU * k as f32 / 24.0;
        let at = Vec3::new(9.0 * a.cos(), -0.2, 9.0 * a.sin());
        let node = Node::new(&format!("column_{k}"))
            .trs(at, Quat::from_rotation_y(a), Vec3::ONE)
            .with_mesh(column);
        g.add_node(node);
    }
    g.add_light_node(
        Light::directional("sun", [1.0, 0.92, 0.8], 3.0),
        Vec3::new(0.0, 20.0, 0.0),
        Vec3::new(-0.7, -0.4, -0.5),
    );
    let camera = Camera::perspective("camera", 50f32.to_radians(), Some(1.0));
    g.add_camera_node(camera, Vec3::new(14.0, 6.0, 18.0), Vec3::new(0.0, 1.5, 0.0));
    g
}
