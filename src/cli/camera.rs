//! The camera flags `render` and the editor share: each one replaces that part
//! of the recipe's (or the framed scene's) camera.

use clap::Args;

use crate::error::{Error, Result};
use crate::scene::camera::CameraOverrides;

/// `--yaw`, `--pitch`, `--target`, `--radius`, `--fov` and `--up`.
#[derive(Args, Debug, Clone, Default)]
pub struct CameraArgs {
    /// Camera yaw in degrees about the up axis (0 = in front).
    #[arg(long, value_name = "DEG", allow_hyphen_values = true)]
    yaw: Option<String>,
    /// Camera pitch in degrees (positive looks from above).
    #[arg(long, value_name = "DEG", allow_hyphen_values = true)]
    pitch: Option<String>,
    /// Point the camera orbits and looks at, in scene units.
    #[arg(long, value_name = "X,Y,Z", allow_hyphen_values = true)]
    target: Option<String>,
    /// Distance from the target, in scene units.
    #[arg(long, value_name = "R", allow_hyphen_values = true)]
    radius: Option<String>,
    /// Vertical field of view in degrees.
    #[arg(long, value_name = "DEG", allow_hyphen_values = true)]
    fov: Option<String>,
    /// World axis that is up on screen: +y (heads, the default), -y (COLMAP /
    /// INRIA captures), +z or -z.
    #[arg(long, value_name = "+y|-y|+z|-z", allow_hyphen_values = true)]
    up: Option<String>,
}

impl CameraArgs {
    /// The settings given, checked (a bad value is an input error naming it).
    pub fn overrides(&self) -> Result<CameraOverrides> {
        let mut out = CameraOverrides::default();
        for (key, value) in [
            ("yaw", &self.yaw),
            ("pitch", &self.pitch),
            ("target", &self.target),
            ("radius", &self.radius),
            ("fov", &self.fov),
            ("up", &self.up),
        ] {
            if let Some(v) = value {
                out.set(key, v)
                    .map_err(|e| Error::input(format!("--{key}: {e}")))?;
            }
        }
        Ok(out)
    }
}
