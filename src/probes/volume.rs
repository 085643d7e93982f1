//! `<stem>_probes.ktx2`: the probe grid as Bevy's irradiance volume (`bevy::light::IrradianceVolume`),
//! a KTX2 3D texture of ambient cubes that Bevy samples with hardware trilinear filtering.
//!
//! ## What Bevy reads (checked against Bevy's source, `bevy_pbr/src/light_probe/irradiance_volume.wesl`)
//!
//! A grid of `(Rx, Ry, Rz)` voxels is a 3D texture of `(Rx, 2·Ry, 3·Rz)` texels. Voxel
//! `(x, y, z)` keeps six colours, one per side `S`, at texel `(s, t, p)`:
//!
//! ```text
//!   s = x
//!   t = y          for +X, +Y, +Z          t = y + Ry   for −X, −Y, −Z
//!   p = z          for ±X      p = z + Rz   for ±Y      p = z + 2·Rz   for ±Z
//! ```
//!
//! The shader picks the half `t + Ry` where the normal's component is negative
//! (`neg_offset = select(0, 0.5, N < 0)`), and shades `Σ_a N_a² · C_a` over the three axes
//! (Valve's ambient cube). The module comment above Bevy's Rust type states the halves the
//! other way round; the shader is what renders, and Bevy's own example volume
//! (`assets/irradiance_volumes/Example.vxgi.ktx2`) agrees with it: its `+Y` half, facing the sky,
//! is four times brighter than its `−Y` half.
//!
//! The volume is Bevy's unit cube `[−0.5, 0.5]³` under the light probe's `Transform`; voxel
//! centres sit at `(i + ½)/R − ½` of it (the shader samples `(unit + ½)·R`, clamped half a
//! voxel in from the edges). lightbake's grid puts probes at the centres of equal cells of a
//! box too, so the Transform is that box: translation at its centre
//! (`origin + step·(count − 1)/2`), scale its size (`step·count`), and rotation the grid's
//! axes (none for the automatic grid). Texel rows and slices run along the grid's own x, y, z,
//! in the glTF's world axes (Bevy's are the same: +Y up, right-handed).
//!
//! ## What lightbake writes
//!
//! Pixel format `R16G16B16A16_SFLOAT` (`Rgba16Float` in wgpu): filterable on every backend
//! (`Rgba32Float` is not, without a device feature); alpha is 1.
//! One mip level, no supercompression, the Khronos data format descriptor of that format
//! (built by the `ktx2` crate, the reader Bevy uses) and a `KTXwriter` entry. Values are
//! clamped to `[0, 65504]` (the largest half), so no texel holds NaN or infinity.
//!
//! Each side's colour is `E(n)/π` from the probe's L2 SH at the axis direction `n`
//! ([`sh::irradiance_over_pi`]): the lightmaps' unit, exact on the six axes; between them the
//! ambient cube's `N²` blend differs from the SH (it has no band-2 cross terms, and its band 1
//! is `n²`-shaped). Measured on `two_rooms` (draft, 1024 probes, 20 000 random normals at valid
//! probes): the blend differs from the SH by 18.6% relative RMS; the least-squares fit of the six
//! colours to the SH over the sphere, not exact on the axes, still differs by 16.6%, so the
//! colours stay the SH's values on the axes. Bevy computes
//! `voxel × intensity × diffuse colour` for a mesh in the volume and
//! `lightmap × lightmap_exposure × diffuse colour` for a lightmapped one (both times the view's
//! exposure), so an `IrradianceVolume::intensity` equal to the materials' `lightmap_exposure`
//! (1 by default) lights moving meshes as the lightmaps light the static ones. Bevy does no
//! visibility test: light leaks through walls thinner than the spacing, and buried probes hold
//! their neighbours' mean (see the module docs of [`super`]).

use glam::Vec3;
use half::f16;

use super::{Grid, Probes, sh};
use crate::{Error, Result};

/// The key of `extras.light_probes` that names the volume: `{"uri", "translation",
/// "rotation", "scale", "resolution"}`.
pub const EXTRAS_KEY: &str = "irradiance_volume";

/// The six sides in the order of [`ambient_cube`]: +X, −X, +Y, −Y, +Z, −Z.
pub const SIDES: [Vec3; 6] = [
    Vec3::X,
    Vec3::NEG_X,
    Vec3::Y,
    Vec3::NEG_Y,
    Vec3::Z,
    Vec3::NEG_Z,
];

/// Bytes per texel (four halves).
const TEXEL: usize = 8;

/// The ambient cube of radiance coefficients `c`: `E(n)/π` for `n` = +X, −X, +Y, −Y, +Z, −Z.
#[must_use]
pub fn ambient_cube(c: &sh::Sh2) -> [Vec3; 6] {
    SIDES.map(|n| sh::irradiance_over_pi(c, n))
}

/// Where Bevy's unit cube must go for the volume to cover the grid: its `Transform`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Placement {
    /// The cube's centre (world).
    pub translation: Vec3,
    /// The grid's axes as a rotation (`x, y, z, w`): identity for the automatic grid.
    pub rotation: [f32; 4],
    /// The cube's size along its axes.
    pub scale: Vec3,
    /// Voxels along x, y, z.
    pub resolution: [u32; 3],
}

/// The Transform of the volume of `grid`.
#[must_use]
pub fn placement(grid: &Grid) -> Placement {
    let count = Vec3::from(grid.count.map(|c| c as f32));
    Placement {
        translation: grid.origin + grid.rotation * (grid.step * (count - Vec3::ONE) * 0.5),
        rotation: grid.rotation.to_array(),
        scale: grid.step * count,
        resolution: grid.count,
    }
}

/// Texel `(s, t, p)` of side `side` (index into [`SIDES`]) of voxel `(x, y, z)` in a grid of
/// `r` voxels (see the module docs).
#[inline]
#[must_use]
pub fn texel([x, y, z]: [u32; 3], side: usize, r: [u32; 3]) -> [u32; 3] {
    let negative = side % 2 == 1;
    let axis = (side / 2) as u32;
    [x, y + if negative { r[1] } else { 0 }, z + axis * r[2]]
}

/// A half that holds `v`: NaN as 0, clamped to `[0, 65504]`.
fn half(v: f32) -> [u8; 2] {
    let v = if v.is_nan() {
        0.0
    } else {
        v.clamp(0.0, 65504.0)
    };
    f16::from_f32(v).to_le_bytes()
}

/// The KTX2 file's bytes for the grid of `probes` (an error for probes not on a grid).
pub fn to_ktx2(probes: &Probes) -> Result<Vec<u8>> {
    let Some(grid) = probes.grid else {
        return Err(Error::Internal(
            "probes: an irradiance volume needs probes on a grid".into(),
        ));
    };
    let r = grid.count;
    let [w, h, d] = [r[0], 2 * r[1], 3 * r[2]];
    let texels = w as usize * h as usize * d as usize;
    // The grid's entries come first; probes a refinement adds are not on the grid.
    if texels == 0 || probes.sh.len() < grid.len() {
        return Err(Error::Internal(format!(
            "probes: {} probes for a {r:?} grid",
            probes.sh.len()
        )));
    }
    // The image: x fastest, then rows t, then slices p (KTX2's order, and wgpu's).
    let mut image = vec![0u8; texels * TEXEL];
    for (i, c) in probes.sh[..grid.len()].iter().enumerate() {
        let voxel = super::place::unflatten(i, r);
        for (side, e) in ambient_cube(c).into_iter().enumerate() {
            let [s, t, p] = texel(voxel, side, r);
            let at = ((p as usize * h as usize + t as usize) * w as usize + s as usize) * TEXEL;
            let rgba = [e.x, e.y, e.z, 1.0];
            for (k, v) in rgba.into_iter().enumerate() {
                image[at + 2 * k..at + 2 * k + 2].copy_from_slice(&half(v));
            }
        }
    }

    let format = ktx2::Format::R16G16B16A16_SFLOAT;
    let (basic, type_size) = ktx2::dfd::Basic::from_format(format)
        .map_err(|e| Error::Internal(format!("probes: KTX2 format descriptor: {e}")))?;
    let block = ktx2::dfd::Block::Basic(basic).to_vec();
    // The descriptor section starts with its own total length.
    let mut dfd = ((4 + block.len()) as u32).to_le_bytes().to_vec();
    dfd.extend_from_slice(&block);
    // One key/value entry, padded to 4 bytes (KTX2 §3.11).
    let entry = format!("KTXwriter\0lightbake {}\0", env!("CARGO_PKG_VERSION"));
    let mut kvd = (entry.len() as u32).to_le_bytes().to_vec();
    kvd.extend_from_slice(entry.as_bytes());
    kvd.resize(kvd.len().next_multiple_of(4), 0);

    let dfd_at = ktx2::Header::LENGTH + ktx2::LevelIndex::LENGTH;
    let kvd_at = dfd_at + dfd.len();
    // Level data aligned to lcm(texel size, 4) = 8 (KTX2 §3.12, mip padding).
    let image_at = (kvd_at + kvd.len()).next_multiple_of(TEXEL);
    let header = ktx2::Header {
        format: Some(format),
        type_size,
        pixel_width: w,
        pixel_height: h,
        pixel_depth: d,
        layer_count: 0,
        face_count: 1,
        level_count: 1,
        supercompression_scheme: None,
        index: ktx2::Index {
            dfd_byte_offset: dfd_at as u32,
            dfd_byte_length: dfd.len() as u32,
            kvd_byte_offset: kvd_at as u32,
            kvd_byte_length: kvd.len() as u32,
            sgd_byte_offset: 0,
            sgd_byte_length: 0,
        },
    };
    let level = ktx2::LevelIndex {
        byte_offset: image_at as u64,
        byte_length: image.len() as u64,
        uncompressed_byte_length: image.len() as u64,
    };
    let mut out = Vec::with_capacity(image_at + image.len());
    out.extend_from_slice(&header.as_bytes());
    out.extend_from_slice(&level.as_bytes());
    out.extend_from_slice(&dfd);
    out.extend_from_slice(&kvd);
    out.resize(image_at, 0);
    out.extend_from_slice(&image);
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn texels_follow_bevys_shader() {
        // Bevy's shader: uvw = (stp + (0, neg·R_y, axis·R_z)) / (R_x, 2R_y, 3R_z).
        let r = [4, 3, 2];
        assert_eq!(texel([1, 2, 1], 0, r), [1, 2, 1]); // +X
        assert_eq!(texel([1, 2, 1], 1, r), [1, 5, 1]); // −X: the second half of t
        assert_eq!(texel([1, 2, 1], 2, r), [1, 2, 3]); // +Y: the second third of p
        assert_eq!(texel([1, 2, 1], 3, r), [1, 5, 3]); // −Y
        assert_eq!(texel([1, 2, 1], 4, r), [1, 2, 5]); // +Z
        assert_eq!(texel([1, 2, 1], 5, r), [1, 5, 5]); // −Z
    }

    #[test]
    fn halves_hold_no_nan_nor_infinity() {
        for (v, expected) in [
            (f32::NAN, 0.0),
            (f32::INFINITY, 65504.0),
            (-1.0, 0.0),
            (0.5, 0.5),
            (1e9, 65504.0),
        ] {
            let h = f16::from_le_bytes(half(v)).to_f32();
            assert_eq!(h, expected, "{v}");
        }
    }
}
