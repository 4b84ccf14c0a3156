//! Pinhole cameras and the orbit controller used by the editor and `visage render`.
//!
//! Conventions: world is the head frame (y up, +z out of the face). Camera space
//! is right-handed with x right, y up and the camera looking down -z (OpenGL
//! style); image rows go top to bottom.

use glam::{Mat4, Vec3, Vec4};
use serde::{Deserialize, Serialize};

/// A pinhole camera with an image size.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    /// Camera position in world space.
    pub eye: Vec3,
    /// Point the camera looks at.
    pub target: Vec3,
    /// Approximate up direction.
    pub up: Vec3,
    /// Vertical field of view in radians.
    pub fov_y: f32,
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// Near clipping distance (Gaussians closer than this are culled).
    pub near: f32,
    /// Far clipping distance.
    pub far: f32,
}

impl Camera {
    /// World → camera transform (camera looks down -z).
    pub fn view(&self) -> Mat4 {
        let forward = (self.target - self.eye).normalize_or(Vec3::NEG_Z);
        let mut right = forward.cross(self.up);
        if right.length_squared() < 1e-12 {
            right = forward.any_orthonormal_vector();
        }
        let right = right.normalize();
        let up = right.cross(forward);
        Mat4::from_cols(
            Vec4::new(right.x, up.x, -forward.x, 0.0),
            Vec4::new(right.y, up.y, -forward.y, 0.0),
            Vec4::new(right.z, up.z, -forward.z, 0.0),
            Vec4::new(
                -right.dot(self.eye),
                -up.dot(self.eye),
                forward.dot(self.eye),
                1.0,
            ),
        )
    }

    /// Focal lengths in pixels (fx, fy); pixels are square.
    pub fn focal_px(&self) -> (f32, f32) {
        let fy = 0.5 * self.height as f32 / (0.5 * self.fov_y).tan();
        (fy, fy)
    }

    /// Camera → clip transform (OpenGL style, depth in [-1, 1]).
    pub fn projection(&self) -> Mat4 {
        let aspect = self.width as f32 / self.height.max(1) as f32;
        let f = 1.0 / (0.5 * self.fov_y).tan();
        let (n, far) = (self.near, self.far);
        Mat4::from_cols(
            Vec4::new(f / aspect, 0.0, 0.0, 0.0),
            Vec4::new(0.0, f, 0.0, 0.0),
            Vec4::new(0.0, 0.0, (far + n) / (n - far), -1.0),
            Vec4::new(0.0, 0.0, 2.0 * far * n / (n - far), 0.0),
        )
    }

    /// World → clip transform.
    pub fn view_projection(&self) -> Mat4 {
        self.projection() * self.view()
    }
}

/// An orbit around a target: yaw about +y (0 = in front of the face), pitch up,
/// radius, and vertical field of view in degrees.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Orbit {
    /// Yaw in degrees; positive moves the camera towards the subject's left (+x).
    pub yaw_deg: f32,
    /// Pitch in degrees; positive looks from above.
    pub pitch_deg: f32,
    /// Distance from the target in metres.
    pub radius: f32,
    /// Vertical field of view in degrees.
    pub fov_deg: f32,
    /// Point orbited, in world space.
    pub target: [f32; 3],
}

impl Default for Orbit {
    fn default() -> Self {
        Self::STUDY
    }
}

impl Orbit {
    /// The thesis's study camera: radius 2.5, looking at the head, with a field of
    /// view that frames a head at that distance.
    pub const STUDY: Orbit = Orbit {
        yaw_deg: 0.0,
        pitch_deg: 0.0,
        radius: 2.5,
        fov_deg: 7.5,
        target: [0.0, -0.025, 0.0],
    };
    /// Yaw limit of the study preset (degrees).
    pub const STUDY_YAW_LIMIT: f32 = 45.0;
    /// Pitch limit of the study preset (degrees).
    pub const STUDY_PITCH_LIMIT: f32 = 15.0;

    /// Camera position.
    pub fn eye(&self) -> Vec3 {
        let (yaw, pitch) = (self.yaw_deg.to_radians(), self.pitch_deg.to_radians());
        let dir = Vec3::new(
            yaw.sin() * pitch.cos(),
            pitch.sin(),
            yaw.cos() * pitch.cos(),
        );
        Vec3::from(self.target) + dir * self.radius
    }

    /// The camera for an image of the given size.
    pub fn camera(&self, width: u32, height: u32) -> Camera {
        Camera {
            eye: self.eye(),
            target: Vec3::from(self.target),
            up: Vec3::Y,
            fov_y: self.fov_deg.to_radians(),
            width,
            height,
            near: 0.01 * self.radius.max(1e-3),
            far: 100.0 * self.radius.max(1e-3),
        }
    }

    /// An orbit that frames points with the given bounding box at the current
    /// angles: the target goes to the box centre and the radius is chosen so the
    /// bounding sphere fills the vertical field of view.
    pub fn framing(&self, min: Vec3, max: Vec3) -> Orbit {
        let center = 0.5 * (min + max);
        let sphere = 0.5 * (max - min).length().max(1e-6);
        let half_fov = 0.5 * self.fov_deg.to_radians().clamp(1e-3, 3.0);
        Orbit {
            target: center.into(),
            radius: sphere / half_fov.sin() * 1.05,
            ..*self
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn target_projects_to_image_centre() {
        let orbit = Orbit {
            yaw_deg: 30.0,
            pitch_deg: 10.0,
            ..Orbit::STUDY
        };
        let cam = orbit.camera(200, 100);
        let clip = cam.view_projection() * Vec3::from(orbit.target).extend(1.0);
        let ndc = clip.truncate() / clip.w;
        assert!(ndc.x.abs() < 1e-5 && ndc.y.abs() < 1e-5, "{ndc}");
        let in_view = cam.view() * Vec3::from(orbit.target).extend(1.0);
        assert!(
            (in_view.z + orbit.radius).abs() < 1e-4,
            "target is in front (-z)"
        );
    }

    #[test]
    fn framing_contains_the_box() {
        let o = Orbit::STUDY.framing(Vec3::splat(-1.0), Vec3::splat(1.0));
        let cam = o.camera(64, 64);
        for corner in [
            Vec3::splat(-1.0),
            Vec3::splat(1.0),
            Vec3::new(1.0, -1.0, 1.0),
        ] {
            let c = cam.view_projection() * corner.extend(1.0);
            let n = c.truncate() / c.w;
            assert!(n.x.abs() <= 1.0 && n.y.abs() <= 1.0, "{corner} -> {n}");
        }
    }
}
