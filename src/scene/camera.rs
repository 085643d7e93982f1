//! Pinhole cameras: from a glTF camera node (the loader resolves them into
//! [`Scene::cameras`](super::Scene::cameras)), from eye/target/field of view, or framing a box.
//!
//! A camera looks along its −Z axis with +Y up (the glTF convention). `yfov` is the vertical
//! field of view; the horizontal one follows from the image aspect ratio (glTF says the
//! viewport's aspect wins over the camera's `aspectRatio`, which only suggests an image size).

use glam::{Mat4, Vec2, Vec3};

use crate::{Error, Result};

/// A pinhole camera in world space.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    pub(crate) eye: Vec3,
    /// Unit viewing direction (the camera's −Z).
    pub(crate) forward: Vec3,
    /// Unit image-right and image-up directions, orthogonal to `forward`.
    pub(crate) right: Vec3,
    pub(crate) up: Vec3,
    /// Vertical field of view (radians).
    pub yfov: f32,
    /// The glTF camera's `aspectRatio` (width / height) when it has one.
    pub aspect_ratio: Option<f32>,
}

impl Camera {
    /// At `eye` looking at `target`, world +Y up (+Z when looking straight up or down).
    pub fn look_at(eye: Vec3, target: Vec3, yfov: f32) -> Camera {
        let forward = (target - eye).normalize_or(-Vec3::Z);
        let world_up = if forward.cross(Vec3::Y).length_squared() < 1e-8 {
            Vec3::Z
        } else {
            Vec3::Y
        };
        let right = forward.cross(world_up).normalize();
        Camera {
            eye,
            forward,
            right,
            up: right.cross(forward),
            yfov,
            aspect_ratio: None,
        }
    }

    /// From a node's world matrix (scale is ignored: only position and orientation count).
    pub(crate) fn from_world(world: Mat4, yfov: f32, aspect_ratio: Option<f32>) -> Camera {
        let (_, rotation, eye) = world.to_scale_rotation_translation();
        Camera {
            eye,
            forward: rotation * -Vec3::Z,
            right: rotation * Vec3::X,
            up: rotation * Vec3::Y,
            yfov,
            aspect_ratio,
        }
    }

    /// Sees the whole box `[lo, hi]` from the front-right and above (a three-quarter view),
    /// for scenes without a camera.
    pub fn framing(lo: Vec3, hi: Vec3, yfov: f32, aspect: f32) -> Camera {
        let center = 0.5 * (lo + hi);
        let radius = (0.5 * (hi - lo).length()).max(1e-3);
        // The bounding sphere must fit the narrower of the two fields of view.
        let half_fov = (0.5 * yfov).min((aspect * (0.5 * yfov).tan()).atan());
        let distance = radius / half_fov.sin();
        let direction = Vec3::new(0.45, 0.35, 1.0).normalize();
        Camera::look_at(center + direction * distance, center, yfov)
    }

    /// Unit direction through the image point `ndc` ∈ [−1, 1]² (x right, y up) for an image of
    /// `aspect` = width / height.
    #[inline]
    pub(crate) fn direction(&self, ndc: Vec2, aspect: f32) -> Vec3 {
        let tan_y = (0.5 * self.yfov).tan();
        (self.forward + self.right * (ndc.x * tan_y * aspect) + self.up * (ndc.y * tan_y))
            .normalize()
    }
}

/// A perspective camera of the glTF document, placed by its node (orthographic cameras are
/// skipped: a pinhole renderer cannot show them).
#[derive(Clone, Debug)]
pub struct GltfCamera {
    /// The camera's name, else its node's name.
    pub(crate) name: Option<String>,
    /// Index into the document's `cameras`.
    pub(crate) index: usize,
    /// The camera as the renderer uses it.
    pub camera: Camera,
}

/// Picks a camera by name (camera or node name) or by index into the document's `cameras`.
pub fn select<'a>(cameras: &'a [GltfCamera], selector: &str) -> Result<&'a GltfCamera> {
    let by_name = cameras.iter().find(|c| c.name.as_deref() == Some(selector));
    let by_index = || {
        let i: usize = selector.parse().ok()?;
        cameras.iter().find(|c| c.index == i)
    };
    by_name.or_else(by_index).ok_or_else(|| {
        let names: Vec<String> = cameras
            .iter()
            .map(|c| format!("{} ({:?})", c.index, c.name.as_deref().unwrap_or("")))
            .collect();
        Error::Option(format!(
            "no perspective camera {selector:?} in the scene; it has: {}",
            if names.is_empty() {
                "none".to_owned()
            } else {
                names.join(", ")
            }
        ))
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn directions_span_the_field_of_view() {
        let c = Camera::look_at(Vec3::ZERO, -Vec3::Z, 90f32.to_radians());
        let top = c.direction(Vec2::new(0.0, 1.0), 2.0);
        assert!((top - Vec3::new(0.0, 1.0, -1.0).normalize()).length() < 1e-6);
        let right = c.direction(Vec2::new(1.0, 0.0), 2.0);
        assert!((right - Vec3::new(2.0, 0.0, -1.0).normalize()).length() < 1e-6);
    }

    #[test]
    fn framing_sees_the_whole_box() {
        let (lo, hi) = (Vec3::splat(-1.0), Vec3::splat(1.0));
        let c = Camera::framing(lo, hi, 0.8, 1.5);
        let tan_y = (0.4f32).tan();
        for corner in 0..8 {
            let p = Vec3::new(
                if corner & 1 == 0 { lo.x } else { hi.x },
                if corner & 2 == 0 { lo.y } else { hi.y },
                if corner & 4 == 0 { lo.z } else { hi.z },
            );
            let d = p - c.eye;
            let z = d.dot(c.forward);
            assert!(z > 0.0);
            assert!((d.dot(c.up) / z).abs() <= tan_y);
            assert!((d.dot(c.right) / z).abs() <= tan_y * 1.5);
        }
    }
}
