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

/// Which world axis points up on screen. Heads (FLAME's frame) are +y up;
/// COLMAP and INRIA 3DGS captures are usually y-down (`-y`), Blender-style
/// scenes z-up.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub enum UpAxis {
    /// +y up (the head frame; the default).
    #[default]
    #[serde(rename = "+y")]
    PosY,
    /// -y up (COLMAP / INRIA captures).
    #[serde(rename = "-y")]
    NegY,
    /// +z up.
    #[serde(rename = "+z")]
    PosZ,
    /// -z up.
    #[serde(rename = "-z")]
    NegZ,
}

impl UpAxis {
    /// Every axis with its name, for parsing and help.
    pub const ALL: [(UpAxis, &'static str); 4] = [
        (UpAxis::PosY, "+y"),
        (UpAxis::NegY, "-y"),
        (UpAxis::PosZ, "+z"),
        (UpAxis::NegZ, "-z"),
    ];

    /// Parses `+y`, `y`, `-y`, `+z`, `z` or `-z`.
    pub fn parse(text: &str) -> Option<UpAxis> {
        let text = text.trim();
        let text = if text.len() == 1 {
            format!("+{text}")
        } else {
            text.to_string()
        };
        Self::ALL.iter().find(|(_, n)| *n == text).map(|(a, _)| *a)
    }

    /// The axis's name (`+y`, `-y`, `+z`, `-z`).
    pub fn name(self) -> &'static str {
        Self::ALL
            .iter()
            .find(|(a, _)| *a == self)
            .map_or("+y", |(_, n)| n)
    }

    /// The same axis pointing the other way: what turns an upside-down view
    /// the right way up.
    pub fn flipped(self) -> UpAxis {
        match self {
            UpAxis::PosY => UpAxis::NegY,
            UpAxis::NegY => UpAxis::PosY,
            UpAxis::PosZ => UpAxis::NegZ,
            UpAxis::NegZ => UpAxis::PosZ,
        }
    }

    /// True for +y, the head frame (left out of recipe files).
    pub fn is_default(&self) -> bool {
        *self == UpAxis::PosY
    }

    /// The rotation taking the orbit's own frame (+y up, yaw 0 looking down -z
    /// from +z) to the world: +y goes to this axis. Rotations about x, so
    /// y-down scenes are seen from -z, the way COLMAP cameras look (+z forward).
    pub fn rotation(self) -> glam::Quat {
        use std::f32::consts::{FRAC_PI_2, PI};
        match self {
            UpAxis::PosY => glam::Quat::IDENTITY,
            UpAxis::NegY => glam::Quat::from_rotation_x(PI),
            UpAxis::PosZ => glam::Quat::from_rotation_x(FRAC_PI_2),
            UpAxis::NegZ => glam::Quat::from_rotation_x(-FRAC_PI_2),
        }
    }

    /// A vector of the orbit's frame in world space (exactly `v` for +y).
    pub fn apply(self, v: Vec3) -> Vec3 {
        match self {
            UpAxis::PosY => v,
            other => other.rotation() * v,
        }
    }
}

/// An orbit around a target: yaw about the up axis (0 = in front of the face),
/// pitch up, radius, vertical field of view in degrees, and which world axis is up.
#[derive(Clone, Copy, PartialEq, Serialize, Deserialize)]
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
    /// World axis that points up on screen (+y for heads).
    #[serde(skip_serializing_if = "UpAxis::is_default")]
    pub up: UpAxis,
}

/// Prints like a derived `Debug`, leaving `up` out while it is +y: state hashes
/// (which hash the recipe's `Debug` text) stay what they were before the
/// field existed, so recorded sessions keep their expected hashes.
impl std::fmt::Debug for Orbit {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let mut d = f.debug_struct("Orbit");
        d.field("yaw_deg", &self.yaw_deg)
            .field("pitch_deg", &self.pitch_deg)
            .field("radius", &self.radius)
            .field("fov_deg", &self.fov_deg)
            .field("target", &self.target);
        if !self.up.is_default() {
            d.field("up", &self.up);
        }
        d.finish()
    }
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
        up: UpAxis::PosY,
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
        Vec3::from(self.target) + self.up.apply(dir * self.radius)
    }

    /// The camera for an image of the given size.
    pub fn camera(&self, width: u32, height: u32) -> Camera {
        Camera {
            eye: self.eye(),
            target: Vec3::from(self.target),
            up: self.up.apply(Vec3::Y),
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

/// Camera settings a user gives explicitly (`--target`, `--radius`, `--fov`,
/// `--up`, `--yaw`, `--pitch`, or the editor's `set-camera`): each one set
/// replaces that part of an orbit. Text form: `yaw=D pitch=D radius=R fov=D
/// target=X,Y,Z up=AXIS`, only the parts set.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct CameraOverrides {
    /// Yaw in degrees.
    pub yaw_deg: Option<f32>,
    /// Pitch in degrees.
    pub pitch_deg: Option<f32>,
    /// Distance from the target (scene units).
    pub radius: Option<f32>,
    /// Vertical field of view in degrees.
    pub fov_deg: Option<f32>,
    /// Point orbited.
    pub target: Option<[f32; 3]>,
    /// World axis up on screen.
    pub up: Option<UpAxis>,
}

impl CameraOverrides {
    /// The keys of the text form.
    pub const KEYS: [&'static str; 6] = ["yaw", "pitch", "radius", "fov", "target", "up"];

    /// True when nothing is set.
    pub fn is_empty(&self) -> bool {
        *self == CameraOverrides::default()
    }

    /// `orbit` with every part that is set replaced.
    pub fn apply(&self, orbit: Orbit) -> Orbit {
        Orbit {
            yaw_deg: self.yaw_deg.unwrap_or(orbit.yaw_deg),
            pitch_deg: self.pitch_deg.unwrap_or(orbit.pitch_deg),
            radius: self.radius.unwrap_or(orbit.radius),
            fov_deg: self.fov_deg.unwrap_or(orbit.fov_deg),
            target: self.target.unwrap_or(orbit.target),
            up: self.up.unwrap_or(orbit.up),
        }
    }

    /// Sets one part from its key and text, checking it.
    pub fn set(&mut self, key: &str, value: &str) -> Result<(), String> {
        let shown = crate::text::printable(value);
        let number = |what: &str| -> Result<f32, String> {
            value
                .trim()
                .parse::<f32>()
                .ok()
                .filter(|x| x.is_finite() && x.abs() < 1e9)
                .ok_or_else(|| format!("{what} '{shown}' is not a finite number"))
        };
        match key {
            "yaw" => self.yaw_deg = Some(number("yaw")?),
            "pitch" => self.pitch_deg = Some(number("pitch")?),
            "radius" => {
                let r = number("radius")?;
                if r <= 0.0 {
                    return Err(format!("radius '{shown}' must be positive"));
                }
                self.radius = Some(r);
            }
            "fov" => {
                let f = number("field of view")?;
                if !(0.1..=170.0).contains(&f) {
                    return Err(format!(
                        "field of view '{shown}' must lie between 0.1 and 170 degrees"
                    ));
                }
                self.fov_deg = Some(f);
            }
            "target" => {
                let parts: Vec<&str> = value.split(',').collect();
                let parsed: Option<Vec<f32>> = parts
                    .iter()
                    .map(|p| {
                        p.trim()
                            .parse::<f32>()
                            .ok()
                            .filter(|x| x.is_finite() && x.abs() < 1e9)
                    })
                    .collect();
                match parsed.as_deref() {
                    Some([x, y, z]) => self.target = Some([*x, *y, *z]),
                    _ => {
                        return Err(format!(
                            "target '{shown}' is not X,Y,Z (three finite numbers)"
                        ))
                    }
                }
            }
            "up" => {
                self.up = Some(
                    UpAxis::parse(value)
                        .ok_or_else(|| format!("up axis '{shown}' is not one of +y, -y, +z, -z"))?,
                )
            }
            other => {
                return Err(format!(
                    "unknown camera setting '{}' (settings: {})",
                    crate::text::printable(other),
                    Self::KEYS.join(", ")
                ))
            }
        }
        Ok(())
    }

    /// Parses `key=value` words.
    pub fn parse<'a>(words: impl IntoIterator<Item = &'a str>) -> Result<Self, String> {
        let mut out = CameraOverrides::default();
        for word in words {
            let (k, v) = word
                .split_once('=')
                .ok_or_else(|| format!("'{}' is not KEY=VALUE", crate::text::printable(word)))?;
            out.set(k, v)?;
        }
        if out.is_empty() {
            return Err(format!(
                "no camera setting given (settings: {})",
                Self::KEYS.join(", ")
            ));
        }
        Ok(out)
    }
}

impl std::fmt::Display for CameraOverrides {
    /// The `key=value` words [`CameraOverrides::parse`] reads back.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let mut words = Vec::new();
        let mut number = |k: &str, v: Option<f32>| {
            if let Some(v) = v {
                words.push(format!("{k}={v}"));
            }
        };
        number("yaw", self.yaw_deg);
        number("pitch", self.pitch_deg);
        number("radius", self.radius);
        number("fov", self.fov_deg);
        if let Some([x, y, z]) = self.target {
            words.push(format!("target={x},{y},{z}"));
        }
        if let Some(up) = self.up {
            words.push(format!("up={}", up.name()));
        }
        write!(f, "{}", words.join(" "))
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

    /// With -y up (COLMAP), the world's -y is up on screen and the front view
    /// looks along +z; with +z up, +z is up on screen.
    #[test]
    fn up_axis_turns_the_view() {
        for (up, world_up) in [
            (UpAxis::PosY, Vec3::Y),
            (UpAxis::NegY, Vec3::NEG_Y),
            (UpAxis::PosZ, Vec3::Z),
            (UpAxis::NegZ, Vec3::NEG_Z),
        ] {
            let orbit = Orbit {
                up,
                target: [1.0, 2.0, 3.0],
                ..Orbit::STUDY
            };
            let cam = orbit.camera(100, 100);
            let above =
                cam.view_projection() * (Vec3::from(orbit.target) + 0.01 * world_up).extend(1.0);
            assert!(
                above.y / above.w > 0.01,
                "{up:?}: a point above the target is drawn above it"
            );
            assert!((cam.eye - Vec3::from(orbit.target)).length() - orbit.radius < 1e-4);
            assert_eq!(UpAxis::parse(up.name()), Some(up));
        }
        let colmap = Orbit {
            up: UpAxis::NegY,
            ..Orbit::STUDY
        }
        .camera(10, 10);
        assert!((cam_forward(&colmap) - Vec3::Z).length() < 1e-5);
        assert_eq!(UpAxis::parse("z"), Some(UpAxis::PosZ));
        assert_eq!(UpAxis::parse("up"), None);
    }

    #[test]
    fn camera_overrides_parse_print_and_refuse() {
        let o = CameraOverrides::parse([
            "target=0.1,-2,3e-3",
            "radius=4",
            "fov=30",
            "up=-y",
            "yaw=-10",
        ])
        .unwrap();
        assert_eq!(o.target, Some([0.1, -2.0, 3e-3]));
        assert_eq!(CameraOverrides::parse(o.to_string().split(' ')).unwrap(), o);
        let orbit = o.apply(Orbit::STUDY);
        assert_eq!(
            (orbit.radius, orbit.fov_deg, orbit.up, orbit.pitch_deg),
            (4.0, 30.0, UpAxis::NegY, 0.0)
        );
        for (bad, needle) in [
            ("radius=0", "positive"),
            ("radius=nan", "finite"),
            ("fov=180", "between"),
            ("target=1,2", "X,Y,Z"),
            ("target=1,2,inf", "X,Y,Z"),
            ("up=x", "+y, -y"),
            ("zoom=2", "unknown camera setting"),
            ("radius", "KEY=VALUE"),
        ] {
            let e = CameraOverrides::parse([bad]).unwrap_err();
            assert!(e.contains(needle), "{bad}: {e}");
        }
        assert!(CameraOverrides::parse([]).is_err());
    }

    fn cam_forward(c: &Camera) -> Vec3 {
        (c.target - c.eye).normalize()
    }

    /// Leaving `up` at +y keeps the recipe text and the Debug text (state
    /// hashes) what they were before the field existed.
    #[test]
    fn default_up_is_invisible_in_text() {
        let text = toml::to_string(&Orbit::STUDY).unwrap();
        assert!(!text.contains("up"), "{text}");
        assert_eq!(
            format!("{:?}", Orbit::STUDY),
            "Orbit { yaw_deg: 0.0, pitch_deg: 0.0, radius: 2.5, fov_deg: 7.5, target: [0.0, -0.025, 0.0] }"
        );
        let down = Orbit {
            up: UpAxis::NegY,
            ..Orbit::STUDY
        };
        let back: Orbit = toml::from_str(&toml::to_string(&down).unwrap()).unwrap();
        assert_eq!(back, down);
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
