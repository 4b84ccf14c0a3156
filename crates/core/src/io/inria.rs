//! The cameras of an INRIA 3DGS training run (`cameras.json` in the model
//! folder, beside `point_cloud/iteration_N/point_cloud.ply`): each entry's
//! `rotation` is the camera-to-world rotation (rows of a 3×3 matrix), so its
//! second column is the camera's y axis in the world, which points down the
//! image (COLMAP's convention).

use std::path::{Path, PathBuf};

use glam::Vec3;

/// Folders above a scene file searched for `cameras.json` (the INRIA layout
/// puts it three levels up from the PLY).
const LEVELS_UP: usize = 3;

/// The cameras file of the training run a scene file came from, if any.
pub fn cameras_file(scene: &Path) -> Option<PathBuf> {
    let absolute = std::path::absolute(scene).ok()?;
    absolute
        .ancestors()
        .skip(1)
        .take(LEVELS_UP)
        .map(|dir| dir.join("cameras.json"))
        .find(|p| p.is_file())
}

/// The mean "up" of the cameras in an INRIA `cameras.json` (minus each
/// camera's y axis), or `None` when the file is not such a list.
pub fn mean_camera_up(file: &Path) -> Option<Vec3> {
    let text = std::fs::read_to_string(file).ok()?;
    let cameras: Vec<serde_json::Value> = serde_json::from_str(&text).ok()?;
    let mut sum = Vec3::ZERO;
    for camera in &cameras {
        let rows = camera.get("rotation")?.as_array()?;
        if rows.len() != 3 {
            return None;
        }
        let mut y_axis = Vec3::ZERO;
        for (r, row) in rows.iter().enumerate() {
            let value = row.as_array()?.get(1)?.as_f64()? as f32;
            y_axis[r] = value;
        }
        if !y_axis.is_finite() {
            return None;
        }
        sum -= y_axis;
    }
    (!cameras.is_empty()).then_some(sum)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A cameras.json as INRIA's `camera_to_JSON` writes it (C2W rotation
    /// rows), for two cameras looking at a y-down scene.
    #[test]
    fn camera_up_reads_an_inria_cameras_file() {
        let dir = std::env::temp_dir().join(format!("visage-inria-{}", std::process::id()));
        let ply_dir = dir.join("point_cloud/iteration_30000");
        std::fs::create_dir_all(&ply_dir).unwrap();
        let ply = ply_dir.join("point_cloud.ply");
        std::fs::write(&ply, "ply").unwrap();
        assert_eq!(cameras_file(&ply), None);
        let text = r#"[{"id": 0, "img_name": "a", "width": 10, "height": 10,
            "position": [0, 0, -4], "rotation": [[1, 0, 0], [0, 1, 0], [0, 0, 1]], "fy": 5, "fx": 5},
            {"id": 1, "img_name": "b", "width": 10, "height": 10,
            "position": [4, 0, 0], "rotation": [[0, 0, -1], [0, 1, 0], [1, 0, 0]], "fy": 5, "fx": 5}]"#;
        std::fs::write(dir.join("cameras.json"), text).unwrap();
        let file = cameras_file(&ply).expect("found three levels up");
        let up = mean_camera_up(&file).unwrap();
        assert!(up.normalize().dot(-Vec3::Y) > 0.99, "{up}");
        std::fs::write(dir.join("cameras.json"), "{\"not\": \"a list\"}").unwrap();
        assert_eq!(mean_camera_up(&file), None);
        std::fs::remove_dir_all(&dir).ok();
    }
}
