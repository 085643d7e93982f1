//! Materials and their textures: base colour and emission, sRGB-decoded to linear RGB, and the
//! specular parameters the renderer needs ([`Surface`]).

use std::collections::BTreeMap;

use glam::Vec3;
use serde_json::Value;

use super::{Files, warn};
use crate::Result;
use crate::scene::MAX_ALBEDO;
use crate::scene::{Material, Scene, Surface, Texture, Wrap};

/// Appends one [`Material`] per glTF material, in document order, plus glTF's default material
/// when some instance has none. Only materials that instances use get their textures decoded.
pub(super) fn add_materials(
    files: &Files,
    document: &gltf::Document,
    json: &Value,
    buffers: &[Vec<u8>],
    scene: &mut Scene,
) -> Result<()> {
    let count = document.materials().len();
    let mut used = vec![false; count + 1];
    for instance in &scene.instances {
        used[instance.material as usize] = true;
    }
    let mut textures = TextureCache {
        files,
        buffers,
        images: BTreeMap::new(),
        textures: BTreeMap::new(),
    };
    for material in document.materials() {
        let index = material.index().unwrap_or_default();
        let pbr = material.pbr_metallic_roughness();
        let [r, g, b, _] = pbr.base_color_factor();
        if [r, g, b].iter().any(|c| !(0.0..=1.0).contains(c)) {
            // Reflectance outside [0, 1] is not physical (above 1 the radiosity series diverges).
            let message = format!(
                "material {index}: baseColorFactor ({r}, {g}, {b}) is outside [0, 1]; reflectance clamped to [0, {MAX_ALBEDO}]"
            );
            warn(scene, message);
        }
        let emissive = Vec3::from(material.emissive_factor());
        let strength = material.emissive_strength().unwrap_or(1.0);
        if ![r, g, b, strength].iter().all(|x| x.is_finite()) || !emissive.is_finite() {
            let message = format!("material {index}: a colour factor or strength is not finite");
            return Err(files.invalid(message));
        }
        if emissive.min_element() < 0.0 || emissive.max_element() > 1.0 {
            let message =
                format!("material {index}: emissiveFactor {emissive} is outside [0, 1]; clamped");
            warn(scene, message);
        }
        if strength < 0.0 {
            let message = format!(
                "material {index}: KHR_materials_emissive_strength {strength} is negative; clamped to 0"
            );
            warn(scene, message);
        }
        let mut converted = Material {
            name: material.name().map(str::to_string),
            source: Some(index as u32),
            base_color: Vec3::new(r, g, b).max(Vec3::ZERO),
            base_color_texture: None,
            emission: emissive.clamp(Vec3::ZERO, Vec3::ONE) * strength.max(0.0),
            emissive_texture: None,
            normal_texture: None,
            normal_scale: 1.0,
            double_sided: material.double_sided(),
            surface: surface(&json["materials"][index]),
        };
        if used[index] {
            let label = |slot: &str| format!("material {index} {slot}");
            converted.base_color_texture =
                textures.get(pbr.base_color_texture(), &label("baseColorTexture"), scene)?;
            converted.emissive_texture = textures.get(
                material.emissive_texture(),
                &label("emissiveTexture"),
                scene,
            )?;
            if let Some(normal) = material.normal_texture() {
                converted.normal_scale = normal.scale();
                converted.normal_texture = textures.get_linear(
                    normal.texture(),
                    normal.tex_coord(),
                    &label("normalTexture"),
                    scene,
                )?;
            }
        }
        scene.materials.push(converted);
    }
    if used[count] {
        scene.materials.push(Material::default());
    }
    Ok(())
}

/// The specular parameters of glTF material `m` (its JSON: the gltf crate is built without the
/// extensions read here), glTF's defaults where absent.
fn surface(m: &Value) -> Surface {
    let mut s = Surface::default();
    let f = |v: &Value, default: f32| v.as_f64().map_or(default, |x| x as f32);
    let rgb = |v: &Value, default: Vec3| {
        let a = v.as_array().filter(|a| a.len() >= 3);
        a.map_or(default, |a| {
            Vec3::new(f(&a[0], 0.0), f(&a[1], 0.0), f(&a[2], 0.0))
        })
    };
    let pbr = &m["pbrMetallicRoughness"];
    s.metallic = f(&pbr["metallicFactor"], 1.0).clamp(0.0, 1.0);
    s.roughness = f(&pbr["roughnessFactor"], 1.0).clamp(0.0, 1.0);
    let ext = &m["extensions"];
    s.transmission = f(
        &ext["KHR_materials_transmission"]["transmissionFactor"],
        0.0,
    )
    .clamp(0.0, 1.0);
    s.ior = f(&ext["KHR_materials_ior"]["ior"], 1.5).max(1.0);
    let spec = &ext["KHR_materials_specular"];
    s.specular = f(&spec["specularFactor"], 1.0).clamp(0.0, 1.0);
    s.specular_color = rgb(&spec["specularColorFactor"], Vec3::ONE).max(Vec3::ZERO);
    let volume = &ext["KHR_materials_volume"];
    let distance = f(&volume["attenuationDistance"], f32::INFINITY);
    let color = rgb(&volume["attenuationColor"], Vec3::ONE).clamp(Vec3::splat(1e-6), Vec3::ONE);
    if distance.is_finite() && distance > 0.0 {
        s.attenuation = -Vec3::new(color.x.ln(), color.y.ln(), color.z.ln()) / distance;
    }
    s
}

/// A decoded image: width, height, linear texels (row 0 at the top).
type Decoded = (u32, u32, Vec<Vec3>);

/// Decodes each image once and stores each (image, sampler) pair once in `scene.textures`.
struct TextureCache<'a> {
    files: &'a Files<'a>,
    buffers: &'a [Vec<u8>],
    /// Decoded linear texels by (image index, sRGB-encoded); `None` when the image could not
    /// be decoded.
    images: BTreeMap<(usize, bool), Option<Decoded>>,
    /// Scene texture index by (image, sampler, sRGB-encoded).
    textures: BTreeMap<(usize, Option<usize>, bool), Option<u32>>,
}

impl TextureCache<'_> {
    /// The scene texture for a material slot; `None` when there is none or it cannot be
    /// decoded (then the slot acts as white, with a warning).
    fn get(
        &mut self,
        info: Option<gltf::texture::Info>,
        label: &str,
        scene: &mut Scene,
    ) -> Result<Option<u32>> {
        let Some(info) = info else { return Ok(None) };
        self.texture(info.texture(), info.tex_coord(), true, label, scene)
    }

    /// [`TextureCache::get`] for data that is not a colour (a normal map): decoded without
    /// the sRGB transfer function.
    fn get_linear(
        &mut self,
        texture: gltf::Texture,
        tex_coord: u32,
        label: &str,
        scene: &mut Scene,
    ) -> Result<Option<u32>> {
        self.texture(texture, tex_coord, false, label, scene)
    }

    fn texture(
        &mut self,
        texture: gltf::Texture,
        tex_coord: u32,
        srgb: bool,
        label: &str,
        scene: &mut Scene,
    ) -> Result<Option<u32>> {
        if tex_coord != 0 {
            let message = format!(
                "{label} uses TEXCOORD_{tex_coord}; lightbake samples it through TEXCOORD_0"
            );
            warn(scene, message);
        }
        let image = texture.source();
        let sampler = texture.sampler();
        let key = (image.index(), sampler.index(), srgb);
        if let Some(&cached) = self.textures.get(&key) {
            return Ok(cached);
        }
        let decoded = match self.images.get(&(image.index(), srgb)) {
            Some(decoded) => decoded.clone(),
            None => {
                let decoded = self.decode_image(&image, srgb, scene)?;
                self.images.insert((image.index(), srgb), decoded.clone());
                decoded
            }
        };
        let index = decoded.map(|(width, height, texels)| {
            scene.textures.push(Texture {
                width,
                height,
                texels,
                wrap_s: wrap(sampler.wrap_s()),
                wrap_t: wrap(sampler.wrap_t()),
            });
            scene.textures.len() as u32 - 1
        });
        self.textures.insert(key, index);
        Ok(index)
    }

    /// Missing files are errors; unreadable formats (KTX2, WebP, …) only warnings.
    fn decode_image(
        &self,
        image: &gltf::Image,
        srgb: bool,
        scene: &mut Scene,
    ) -> Result<Option<Decoded>> {
        let i = image.index();
        let (bytes, what) = match image.source() {
            gltf::image::Source::Uri { uri, .. } => {
                let what = if uri.starts_with("data:") {
                    format!("image {i}")
                } else {
                    format!("image {i} '{uri}'")
                };
                (self.files.read_uri(uri, &what)?, what)
            }
            gltf::image::Source::View { view, .. } => {
                let start = view.offset();
                let bytes = self.buffers[view.buffer().index()]
                    .get(start..start + view.length())
                    .ok_or_else(|| {
                        let message = format!(
                            "image {i}: bufferView {} is outside its buffer",
                            view.index()
                        );
                        self.files.invalid(message)
                    })?;
                (bytes.to_vec(), format!("image {i}"))
            }
        };
        match decode(&bytes, srgb) {
            Ok(decoded) => Ok(Some(decoded)),
            Err(e) => {
                warn(
                    scene,
                    format!("{what} cannot be decoded ({e}); treated as white"),
                );
                Ok(None)
            }
        }
    }
}

fn wrap(mode: gltf::texture::WrappingMode) -> Wrap {
    match mode {
        gltf::texture::WrappingMode::Repeat => Wrap::Repeat,
        gltf::texture::WrappingMode::MirroredRepeat => Wrap::MirroredRepeat,
        gltf::texture::WrappingMode::ClampToEdge => Wrap::ClampToEdge,
    }
}

/// Decodes a PNG or JPEG to linear RGB (alpha dropped), row 0 at the top: through the sRGB
/// transfer function when `srgb` (colours), as stored otherwise (normal maps).
fn decode(bytes: &[u8], srgb: bool) -> image::ImageResult<Decoded> {
    use image::DynamicImage as D;
    let srgb_to_linear = |c: f32| if srgb { srgb_to_linear(c) } else { c };
    let image = image::load_from_memory(bytes)?;
    let (width, height) = (image.width(), image.height());
    let texels = match image {
        D::ImageLuma8(_) | D::ImageLumaA8(_) | D::ImageRgb8(_) | D::ImageRgba8(_) => {
            let table: Vec<f32> = (0..=255u8)
                .map(|v| srgb_to_linear(v as f32 / 255.0))
                .collect();
            let rgb = image.to_rgb8();
            rgb.pixels()
                .map(|p| Vec3::from(p.0.map(|v| table[v as usize])))
                .collect()
        }
        _ => {
            let rgb = image.to_rgb32f();
            rgb.pixels()
                .map(|p| Vec3::from(p.0.map(|v| srgb_to_linear(v.clamp(0.0, 1.0)))))
                .collect()
        }
    };
    Ok((width, height, texels))
}

fn srgb_to_linear(c: f32) -> f32 {
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}
