//! Configuration factors through the real pipeline against Howell's catalogue, reciprocity,
//! bounded rows and the furnace, for the all-pairs methods (`point`, `polygon`) and Monte Carlo.

use std::path::{Path, PathBuf};
use std::time::Instant;

use glam::Vec3;
use lightbake::config::{FormFactors, RowSolver, Technique};
use lightbake::testing::{self, Geometry, GltfBuilder, Material};
use lightbake::transport::Rows;
use lightbake::transport::kernel::{
    parallel_rectangles, perpendicular_rectangles, point_to_coaxial_disk, point_to_disk_bound,
    point_to_point,
};
use lightbake::{BakeConfig, Baked, NoProgress, compute};

use crate::util::{fixture, quick, scratch};

fn config(method: FormFactors, texels_per_unit: f32) -> BakeConfig {
    let mut c = quick();
    c.technique = Technique::stored(method, RowSolver::Jacobi);
    c.atlas.texels_per_unit = texels_per_unit;
    c.transport.light_samples = 64; // polygon: 2×2 visibility rays per pair
    c.solve.tolerance = 1e-5;
    c
}

/// Writes `gltf` into `dir` and bakes it in memory.
fn bake(gltf: &GltfBuilder, dir: &Path, config: &BakeConfig) -> Baked {
    let path: PathBuf = dir.join("scene.gltf");
    gltf.write_gltf(&path).unwrap();
    compute(&path, config, &NoProgress).unwrap()
}

/// Two plates, the first in `first`, the second in `second` (each an origin and two edges; the
/// front faces `edge_u × edge_v`). The second emits, so the scene is not black.
fn two_plates(first: [Vec3; 3], second: [Vec3; 3]) -> GltfBuilder {
    let mut gltf = GltfBuilder::new("plates");
    let grey = gltf.add_material(Material::grey("grey", 0.5));
    let lit = gltf.add_material(Material::grey("lit", 0.5).emitting([1.0; 3], 1.0));
    for (name, [o, u, v], material) in [("one", first, grey), ("two", second, lit)] {
        let mesh = gltf.add_mesh(name, Geometry::grid(o, u, v, 1, 1), material);
        gltf.add_mesh_node(name, mesh);
    }
    gltf
}

/// Directly opposed `a × b` rectangles at distance `c`: plate 1 at y = 0 facing +y, plate 2 at
/// y = c facing −y.
fn opposed(a: f32, b: f32, c: f32) -> GltfBuilder {
    two_plates(
        [Vec3::ZERO, Vec3::Z * b, Vec3::X * a],
        [Vec3::Y * c, Vec3::X * a, Vec3::Z * b],
    )
}

/// Unit squares sharing the edge x = y = 0: a floor facing +y and a wall facing +x.
fn perpendicular() -> GltfBuilder {
    two_plates(
        [Vec3::ZERO, Vec3::Z, Vec3::X],
        [Vec3::ZERO, Vec3::Y, Vec3::Z],
    )
}

/// Area-weighted plate-to-plate factor `F_12 = Σ_{i∈1} A_i Σ_{j∈2} F_ij / A_1`, and the Monte
/// Carlo standard error of that estimate for `k` binomial rays per texel.
fn plate_factor(
    baked: &Baked,
    one: impl Fn(Vec3) -> bool,
    two: impl Fn(Vec3) -> bool,
    k: u32,
) -> (f64, f64) {
    let (t, tr) = (&baked.texels, &baked.transport);
    let a_1: f64 = (0..t.len())
        .filter(|&i| one(t.normal[i]))
        .map(|i| t.area[i] as f64)
        .sum();
    let (mut f_12, mut variance) = (0.0f64, 0.0f64);
    for i in (0..t.len()).filter(|&i| one(t.normal[i])) {
        let p: f64 = tr
            .row(i)
            .filter(|&(j, _)| two(t.normal[j as usize]))
            .map(|(_, f)| f as f64)
            .sum();
        let w = t.area[i] as f64 / a_1;
        f_12 += w * p;
        variance += w * w * p * (1.0 - p) / k as f64;
    }
    (f_12, variance.sqrt())
}

/// Checks one configuration against its closed form: polygon within 1%, Monte Carlo within 3σ,
/// the (cured) point method within `point_tolerance`.
fn check_configuration(
    name: &str,
    gltf: &GltfBuilder,
    one: fn(Vec3) -> bool,
    two: fn(Vec3) -> bool,
    want: f64,
    point_tolerance: f64,
) {
    let dir = scratch();
    let start = Instant::now();
    let polygon = bake(gltf, dir.path(), &config(FormFactors::Polygon, 16.0));
    let (f_polygon, _) = plate_factor(&polygon, one, two, 1);
    let polygon_time = start.elapsed().as_secs_f64();

    let start = Instant::now();
    let point = bake(gltf, dir.path(), &config(FormFactors::Point, 16.0));
    let (f_point, _) = plate_factor(&point, one, two, 1);
    let point_time = start.elapsed().as_secs_f64();

    let k = 1024;
    let mut mc = config(FormFactors::MonteCarlo, 16.0);
    mc.transport.gather_rays = k;
    let start = Instant::now();
    let montecarlo = bake(gltf, dir.path(), &mc);
    let (f_mc, sigma) = plate_factor(&montecarlo, one, two, k);
    let percent = |f: f64| 100.0 * (f - want) / want;
    let texels = polygon.texels.len();
    eprintln!(
        "{name}: Howell {want:.5}, polygon {f_polygon:.5} ({:+.2}%, {texels} texels, \
         {polygon_time:.2} s), point {f_point:.5} ({:+.2}%, {point_time:.2} s), \
         montecarlo K={k} {f_mc:.5} ± {sigma:.5} ({:+.1}σ, {:.2} s)",
        percent(f_polygon),
        percent(f_point),
        (f_mc - want) / sigma,
        start.elapsed().as_secs_f64()
    );
    assert!(
        (f_polygon - want).abs() / want < 0.01,
        "{name}: polygon {f_polygon} vs {want}"
    );
    assert!(
        (f_mc - want).abs() < 3.0 * sigma,
        "{name}: montecarlo {f_mc} ± {sigma} vs {want}"
    );
    assert!(
        (f_point - want).abs() / want < point_tolerance,
        "{name}: point {f_point} vs {want}"
    );
}

/// The point method's tolerance for plates that do not touch (measured ≤ 0.2%).
const POINT_FAR: f64 = 0.01;

fn up(n: Vec3) -> bool {
    n.y > 0.5
}
fn down(n: Vec3) -> bool {
    n.y < -0.5
}
fn east(n: Vec3) -> bool {
    n.x > 0.5
}

#[test]
fn opposed_unit_squares_at_distance_1() {
    let want = parallel_rectangles(1.0, 1.0, 1.0);
    check_configuration(
        "squares at 1",
        &opposed(1.0, 1.0, 1.0),
        up,
        down,
        want,
        POINT_FAR,
    );
}

#[test]
fn opposed_unit_squares_at_distance_2() {
    let want = parallel_rectangles(1.0, 1.0, 2.0);
    check_configuration(
        "squares at 2",
        &opposed(1.0, 1.0, 2.0),
        up,
        down,
        want,
        POINT_FAR,
    );
}

#[test]
fn opposed_unit_squares_at_distance_half() {
    let want = parallel_rectangles(1.0, 1.0, 0.5);
    check_configuration(
        "squares at 0.5",
        &opposed(1.0, 1.0, 0.5),
        up,
        down,
        want,
        POINT_FAR,
    );
}

#[test]
fn opposed_rectangles_1_by_1_5_at_distance_half() {
    let want = parallel_rectangles(1.0, 1.5, 0.5);
    check_configuration(
        "1×1.5 at 0.5",
        &opposed(1.0, 1.5, 0.5),
        up,
        down,
        want,
        POINT_FAR,
    );
}

#[test]
fn perpendicular_unit_squares_sharing_an_edge() {
    let want = perpendicular_rectangles(1.0, 1.0, 1.0);
    // Next to the shared edge the point kernel is capped by the disk bound, but texels there
    // still overestimate (measured +4.7% at 16 texels per unit).
    check_configuration("perpendicular", &perpendicular(), up, east, want, 0.06);
}

/// A small square receiver (side `side`, centred at the origin, facing +y) under a coaxial disk
/// of radius `r` at height `h` facing down, the disk a 96-segment emissive fan (its area is
/// 0.07% short of the circle's).
fn plate_under_disk(side: f32, r: f32, h: f32) -> GltfBuilder {
    let mut gltf = GltfBuilder::new("disk");
    let grey = gltf.add_material(Material::grey("grey", 0.5));
    let lit = gltf.add_material(Material::grey("lit", 0.5).emitting([1.0; 3], 1.0));
    let plate = Geometry::grid(
        Vec3::new(-side / 2.0, 0.0, -side / 2.0),
        Vec3::Z * side,
        Vec3::X * side,
        1,
        1,
    );
    let mesh = gltf.add_mesh("plate", plate, grey);
    gltf.add_mesh_node("plate", mesh);
    let n = 96u32;
    let mut positions = vec![Vec3::new(0.0, h, 0.0)];
    positions.extend((0..n).map(|k| {
        let a = k as f32 / n as f32 * std::f32::consts::TAU;
        Vec3::new(r * a.cos(), h, r * a.sin())
    }));
    // Counter-clockwise seen from below (front facing −y).
    let indices: Vec<u32> = (0..n).flat_map(|k| [0, 1 + k, 1 + (k + 1) % n]).collect();
    let normals = vec![Vec3::NEG_Y; positions.len()];
    let disk = Geometry::new(&positions, Some(&normals), None, &indices);
    let mesh = gltf.add_mesh("disk", disk, lit);
    gltf.add_mesh_node("disk", mesh);
    gltf
}

/// Howell's differential area to a parallel coaxial disk, `F = r²/(h² + r²)`, at the texel on
/// the axis (the polygon method evaluates at the receiving texel's sample point, the
/// differential area itself), and over the plate (every texel near the axis).
#[test]
fn differential_area_to_a_coaxial_disk() {
    let dir = scratch();
    for (r, h) in [(0.5f32, 0.5f32), (0.3, 1.0), (0.6, 0.25)] {
        let want = point_to_coaxial_disk(r as f64, h as f64);
        let gltf = plate_under_disk(0.1, r, h);
        let baked = bake(&gltf, dir.path(), &config(FormFactors::Polygon, 64.0));
        let t = &baked.texels;
        let centre = (0..t.len())
            .filter(|&i| up(t.normal[i]))
            .min_by(|&a, &b| t.position[a].length().total_cmp(&t.position[b].length()))
            .unwrap();
        let f: f64 = baked
            .transport
            .row(centre)
            .filter(|&(j, _)| down(t.normal[j as usize]))
            .map(|(_, f)| f as f64)
            .sum();
        let k = 1024;
        let mut mc = config(FormFactors::MonteCarlo, 64.0);
        mc.transport.gather_rays = k;
        let montecarlo = bake(&gltf, dir.path(), &mc);
        let (f_mc, sigma) = plate_factor(&montecarlo, up, down, k);
        // The plate's texels are up to 5 cm off the axis, where F is lower by O((x/h)²).
        let off_axis: f64 = {
            let (mut sum, mut area) = (0.0f64, 0.0f64);
            for i in (0..t.len()).filter(|&i| up(t.normal[i])) {
                let p = t.position[i];
                let x = (p.x * p.x + p.z * p.z).sqrt() as f64;
                // Differential area off the axis of a disk: the exact formula (Howell B-13).
                let (hh, rr) = (h as f64, r as f64);
                let z = hh * hh + x * x + rr * rr;
                let f_x =
                    0.5 * (1.0 - (z - 2.0 * rr * rr) / (z * z - 4.0 * rr * rr * x * x).sqrt());
                sum += f_x * t.area[i] as f64;
                area += t.area[i] as f64;
            }
            sum / area
        };
        eprintln!(
            "disk r={r} h={h}: Howell {want:.5}; polygon at the axis {f:.5} ({:+.2}%); \
             montecarlo K={k} over the plate {f_mc:.5} ± {sigma:.5} vs {off_axis:.5} ({:+.1}σ)",
            100.0 * (f - want) / want,
            (f_mc - off_axis) / sigma
        );
        assert!((f - want).abs() / want < 0.01, "polygon {f} vs {want}");
        assert!(
            (f_mc - off_axis).abs() < 3.0 * sigma + 1e-3 * off_axis,
            "montecarlo {f_mc} vs {off_axis}"
        );
    }
}

/// Largest `Σ_j F_ij` over the rows.
fn max_row_sum(baked: &Baked) -> f32 {
    (0..baked.transport.len())
        .map(|i| baked.transport.row(i).map(|(_, f)| f).sum::<f32>())
        .fold(0.0, f32::max)
}

/// (mean, worst) relative error of the lightmap against `expected`.
fn errors(baked: &Baked, expected: f32) -> (f32, f32) {
    let mut worst = 0.0f32;
    let mut sum = 0.0f32;
    for v in &baked.lightmap {
        let e = (v.x - expected).abs() / expected;
        sum += e;
        worst = worst.max(e);
    }
    (sum / baked.lightmap.len() as f32, worst)
}

fn furnace(method: FormFactors, name: &str, rho: f32) -> (f32, f32) {
    let start = Instant::now();
    let baked = compute(&fixture(name), &config(method, 8.0), &NoProgress).unwrap();
    let (mean, worst) = errors(&baked, 1.0 / (1.0 - rho));
    let sum = max_row_sum(&baked);
    eprintln!(
        "{name} {method:?}: mean error {:.3}%, worst {:.3}%, max row sum {sum:.5}, {} texels, \
         {} sweeps, {:.2} s",
        100.0 * mean,
        100.0 * worst,
        baked.texels.len(),
        baked.solution.history.len(),
        start.elapsed().as_secs_f64()
    );
    assert!(
        baked.solution.converged,
        "{name} {method:?} did not converge"
    );
    assert!(baked.lightmap.iter().all(|v| v.is_finite()));
    assert!(sum <= 1.0 + 1e-4, "{name} {method:?}: row sum {sum}");
    (mean, worst)
}

#[test]
fn furnace_polygon() {
    for (name, rho) in [("furnace.gltf", 0.5), ("furnace_09.gltf", 0.9)] {
        let (mean, worst) = furnace(FormFactors::Polygon, name, rho);
        assert!(
            mean < 0.01 && worst < 0.01,
            "{name}: mean {mean}, worst {worst}"
        );
    }
}

#[test]
fn furnace_point() {
    for (name, rho) in [("furnace.gltf", 0.5), ("furnace_09.gltf", 0.9)] {
        let (mean, worst) = furnace(FormFactors::Point, name, rho);
        assert!(
            mean < 0.01 && worst < 0.01,
            "{name}: mean {mean}, worst {worst}"
        );
    }
}

/// The documented failure: the raw kernel's rows exceed 1 where walls touch.
#[test]
fn raw_point_kernel_rows_exceed_one_at_corners() {
    let baked = compute(
        &fixture("furnace.gltf"),
        &config(FormFactors::Polygon, 8.0),
        &NoProgress,
    )
    .unwrap();
    let t = &baked.texels;
    // The box is convex: every pair sees each other, no visibility needed.
    let raw_max = testing::raw_point_kernel_max_row_sum(t);
    // The cure before row normalisation: entries capped by the disk bound.
    let capped = |i: usize| {
        (0..t.len())
            .filter(|&j| j != i)
            .map(|j| {
                let raw = point_to_point(
                    t.position[i],
                    t.normal[i],
                    t.position[j],
                    t.normal[j],
                    t.area[j],
                );
                raw.min(point_to_disk_bound(
                    t.position[i].distance_squared(t.position[j]),
                    t.area[j],
                ))
            })
            .sum::<f32>()
    };
    let (capped_min, capped_max) = (0..t.len())
        .map(capped)
        .fold((f32::INFINITY, 0.0f32), |(lo, hi), s| {
            (lo.min(s), hi.max(s))
        });
    eprintln!(
        "point kernel in the furnace: raw max row sum {raw_max:.4}; capped by the disk bound \
         {capped_min:.4}..{capped_max:.4} (then rows > 1 are scaled to 1)"
    );
    assert!(raw_max > 1.0, "raw row sums stay below 1 ({raw_max})");
}

/// Reciprocity `A_i F_ij ≈ A_j F_ji` of the polygon method over pairs at least four texel
/// sides apart with `F_ij > 10⁻³`: (fraction of pairs within 5%, Σ|A_i F_ij − A_j F_ji| / Σ A_i F_ij).
/// Closer pairs are left out: the receiver is a point (its centre), so the midpoint rule is
/// not reciprocal within a couple of texels (10% there in the furnace, 18% on the Cornell box
/// where floor texels straddle the blocks' contact lines).
fn reciprocity(name: &str) -> (f64, f64) {
    let baked = compute(
        &fixture(name),
        &config(FormFactors::Polygon, 8.0),
        &NoProgress,
    )
    .unwrap();
    let (t, tr) = (&baked.texels, &baked.transport);
    let Rows::Weights(w) = &tr.rows else {
        panic!("polygon rows hold f32 weights")
    };
    let f = |i: usize, j: usize| {
        let r = w.row_start[i] as usize..w.row_start[i + 1] as usize;
        w.col[r.clone()]
            .binary_search(&(j as u32))
            .map_or(0.0, |k| w.f[r.start + k])
    };
    let side = |i: usize| t.area[i].sqrt();
    let (mut pairs, mut close, mut asymmetry, mut total) = (0, 0, 0.0f64, 0.0f64);
    for i in 0..t.len() {
        for (j, f_ij) in tr.row(i) {
            let j = j as usize;
            let apart = t.position[i].distance(t.position[j]) >= 4.0 * side(i).max(side(j));
            if f_ij < 1e-3 || !apart {
                continue;
            }
            let forward = t.area[i] * f_ij;
            let backward = t.area[j] * f(j, i);
            pairs += 1;
            if (forward - backward).abs() <= 0.05 * forward.max(backward) {
                close += 1;
            }
            asymmetry += (forward - backward).abs() as f64;
            total += forward as f64;
        }
    }
    let (fraction, relative) = (close as f64 / pairs as f64, asymmetry / total);
    eprintln!(
        "{name} polygon reciprocity: {close}/{pairs} pairs within 5%, \
         Σ|A_i F_ij − A_j F_ji| / Σ A_i F_ij = {:.2}%",
        100.0 * relative
    );
    (fraction, relative)
}

/// Without occluders the only asymmetry is the point receiver's.
#[test]
fn polygon_is_reciprocal_in_the_furnace() {
    let (fraction, relative) = reciprocity("furnace.gltf");
    assert!(fraction > 0.99 && relative < 0.02, "{fraction}, {relative}");
}

/// With occluders, penumbrae add asymmetry: a point receiver sees a source partly, while the
/// source's centre sees the receiver's texel area partly — a different fraction.
#[test]
fn polygon_is_reciprocal_on_the_cornell_box() {
    let (fraction, relative) = reciprocity("cornell_box.gltf");
    assert!(fraction > 0.85 && relative < 0.07, "{fraction}, {relative}");
}

#[test]
fn all_pairs_methods_refuse_large_scenes() {
    let mut c = config(FormFactors::Polygon, 48.0); // ≈ 6 × 48² = 13 800 texels
    c.transport.validity = false;
    let started = Instant::now();
    let error = compute(&fixture("furnace.gltf"), &c, &NoProgress)
        .unwrap_err()
        .to_string();
    assert!(
        error.contains("montecarlo") && error.contains("10000"),
        "{error}"
    );
    assert!(started.elapsed().as_secs_f64() < 30.0);
}

/// No gathering ray leaves a closed box: a tracer that lets one in 25 000 out (BVH boxes padded
/// by epsilon/16 instead of epsilon) made the ρ = 0.99 furnace 0.8% dark.
#[test]
fn closed_box_lets_no_ray_out() {
    let dir = scratch();
    let path = dir.path().join("furnace.gltf");
    lightbake::testing::furnace(0.99, 1.0)
        .write_gltf(&path)
        .unwrap();
    for tpu in [8.0, 16.0, 32.0] {
        let mut c = config(FormFactors::MonteCarlo, tpu);
        c.transport.gather_rays = 256;
        let baked = compute(&path, &c, &NoProgress).unwrap();
        let escaped: f32 = baked.transport.escape.iter().sum();
        assert_eq!(escaped, 0.0, "{tpu} texels/m: rays escaped the closed box");
    }
}
