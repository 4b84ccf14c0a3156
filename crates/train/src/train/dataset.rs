//! Multi-view video datasets in GaussianAvatars' layout (what VHAP writes for
//! NeRSemble, and `visage capture`): `transforms_{train,val,test}.json`, each
//! with frames naming an image (`file_path`, `.png` added when it has no
//! extension, as GaussianAvatars does), a camera-to-world `transform_matrix`
//! in the NeRF/Blender convention, intrinsics (`fl_x fl_y cx cy w h`, per
//! frame or at the top, or `camera_angle_x` with a centred principal point),
//! `timestep_index`, `camera_index`, `flame_param_path` and an optional
//! `fg_mask_path`. Every malformed piece is one line naming the file and frame.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde_json::Value;

use super::project::TrainCamera;
use crate::error::{Error, Result};
use crate::model::head::HeadModel;

/// One image of a split.
#[derive(Clone, Debug, PartialEq)]
pub struct View {
    /// The camera.
    pub camera: TrainCamera,
    /// The image file.
    pub image: PathBuf,
    /// The foreground mask, when given.
    pub mask: Option<PathBuf>,
    /// Which timestep (FLAME parameters) it shows.
    pub timestep: usize,
    /// Which camera of the rig.
    pub camera_index: usize,
}

/// A dataset: its three splits and each timestep's FLAME parameter file.
#[derive(Clone, Debug, PartialEq)]
pub struct Dataset {
    /// The dataset's folder.
    pub root: PathBuf,
    /// Training views.
    pub train: Vec<View>,
    /// Novel views of training timesteps.
    pub val: Vec<View>,
    /// Novel timesteps.
    pub test: Vec<View>,
    /// FLAME parameter file per timestep.
    pub flame_params: BTreeMap<usize, PathBuf>,
    /// The built-in source it was captured from, when `visage capture` made it
    /// (it needs no FLAME files).
    pub builtin_source: Option<String>,
    /// What `visage capture --recipe` recorded: the composite whose ground
    /// truth this is (recipe TOML, tone, seams), when it is one.
    pub composite: Option<Value>,
}

impl Dataset {
    /// Reads a dataset folder.
    pub fn load(root: &Path) -> Result<Dataset> {
        if !root.is_dir() {
            return Err(Error::input(format!(
                "{} is not a dataset folder",
                root.display()
            )));
        }
        let mut flame_params = BTreeMap::new();
        let mut builtin_source = None;
        let mut composite = None;
        let mut splits: [Vec<View>; 3] = Default::default();
        for (split, views) in ["train", "val", "test"].iter().zip(&mut splits) {
            let path = root.join(format!("transforms_{split}.json"));
            if !path.exists() && *split != "train" {
                continue; // GaussianAvatars trains without val/test too
            }
            let text = std::fs::read_to_string(&path)
                .map_err(|e| Error::input(format!("cannot read {}: {e}", path.display())))?;
            let doc: Value = serde_json::from_str(&text)
                .map_err(|e| Error::input(format!("{}: not valid JSON ({e})", path.display())))?;
            // The training split decides what the dataset is.
            if let Some(source) = (*split == "train")
                .then(|| doc.get("visage_builtin_head"))
                .flatten()
                .and_then(|b| b.get("source"))
                .and_then(Value::as_str)
            {
                builtin_source = Some(source.to_string());
                composite = doc["visage_builtin_head"].get("composite").cloned();
            }
            let frames = doc
                .get("frames")
                .and_then(Value::as_array)
                .ok_or_else(|| Error::input(format!("{}: no 'frames' list", path.display())))?;
            for (k, frame) in frames.iter().enumerate() {
                let label = |e: String| Error::input(format!("{}: frame {k}: {e}", path.display()));
                let view = read_view(root, &doc, frame).map_err(label)?;
                let flame = string(frame, "flame_param_path").map_err(label)?;
                flame_params
                    .entry(view.timestep)
                    .or_insert_with(|| root.join(flame));
                views.push(view);
            }
        }
        let [train, val, test] = splits;
        if train.is_empty() {
            return Err(Error::input(format!(
                "{}: transforms_train.json has no frames",
                root.display()
            )));
        }
        Ok(Dataset {
            root: root.to_path_buf(),
            train,
            val,
            test,
            flame_params,
            builtin_source,
            composite,
        })
    }
}

/// The head model a dataset trains on: the user's FLAME (model and masks
/// pickles) or, without one, the built-in head, which only a dataset
/// `visage capture` made from it may use.
pub fn head_model(dataset: Option<&Dataset>, flame: Option<(&Path, &Path)>) -> Result<HeadModel> {
    if let Some((model, masks)) = flame {
        return Ok(crate::io::flame::load_flame(model, masks)?);
    }
    if let Some(d) = dataset {
        d.check_builtin_head()?;
    }
    Ok(crate::model::builtin::build_head())
}

impl Dataset {
    /// Refuses the built-in head for a dataset not captured from it.
    pub fn check_builtin_head(&self) -> Result<()> {
        if self.builtin_source.is_none() {
            return Err(Error::input(format!(
                "{} was not captured from the built-in head: give --flame and --masks",
                self.root.display()
            )));
        }
        Ok(())
    }
}

fn string<'a>(frame: &'a Value, key: &str) -> std::result::Result<&'a str, String> {
    frame
        .get(key)
        .and_then(Value::as_str)
        .ok_or_else(|| format!("'{key}' is missing or not a string"))
}

/// A number from the frame, else the top level; None when neither has it.
fn number(frame: &Value, doc: &Value, key: &str) -> std::result::Result<Option<f64>, String> {
    match frame.get(key).or_else(|| doc.get(key)) {
        None => Ok(None),
        Some(v) => v
            .as_f64()
            .filter(|x| x.is_finite())
            .map(Some)
            .ok_or_else(|| format!("'{key}' is not a finite number")),
    }
}

fn read_view(root: &Path, doc: &Value, frame: &Value) -> std::result::Result<View, String> {
    let mut file = string(frame, "file_path")?.to_string();
    if Path::new(&file).extension().is_none() {
        file.push_str(".png");
    }
    let image = root.join(&file);
    if !image.is_file() {
        return Err(format!("image {} does not exist", image.display()));
    }
    let rows = frame
        .get("transform_matrix")
        .and_then(Value::as_array)
        .filter(|r| r.len() == 4)
        .ok_or("'transform_matrix' is not a 4x4 matrix")?;
    let mut c2w = [[0.0; 4]; 4];
    for (r, row) in rows.iter().enumerate() {
        let row = row
            .as_array()
            .filter(|c| c.len() == 4)
            .ok_or("'transform_matrix' is not a 4x4 matrix")?;
        for (c, x) in row.iter().enumerate() {
            c2w[r][c] = x
                .as_f64()
                .filter(|x| x.is_finite())
                .ok_or("'transform_matrix' holds a value that is not a finite number")?;
        }
    }
    let rotation_ok = (0..3).all(|c| {
        let n: f64 = (0..3).map(|r| c2w[r][c] * c2w[r][c]).sum();
        (n - 1.0).abs() < 1e-3
    });
    if !rotation_ok {
        return Err(
            "'transform_matrix' has no rotation in its upper 3x3 (columns are not unit)".into(),
        );
    }
    let size = match (number(frame, doc, "w")?, number(frame, doc, "h")?) {
        (Some(w), Some(h)) => [w as u32, h as u32],
        _ => {
            let (w, h) = image::image_dimensions(&image)
                .map_err(|e| format!("cannot read {}: {e}", image.display()))?;
            [w, h]
        }
    };
    if size[0] == 0 || size[1] == 0 {
        return Err("image size is zero".into());
    }
    let focal = match (number(frame, doc, "fl_x")?, number(frame, doc, "fl_y")?) {
        (Some(fx), Some(fy)) => [fx, fy],
        (Some(fx), None) => [fx, fx],
        _ => {
            let angle = number(frame, doc, "camera_angle_x")?
                .ok_or("no intrinsics: give fl_x (and fl_y) or camera_angle_x")?;
            if !(angle > 0.0 && angle < std::f64::consts::PI) {
                return Err(format!("camera_angle_x {angle} is not an angle in (0, π)"));
            }
            let f = 0.5 * size[0] as f64 / (0.5 * angle).tan();
            [f, f]
        }
    };
    if !(focal[0] > 0.0 && focal[1] > 0.0) {
        return Err("focal lengths must be positive".into());
    }
    let principal = [
        number(frame, doc, "cx")?.unwrap_or(0.5 * size[0] as f64),
        number(frame, doc, "cy")?.unwrap_or(0.5 * size[1] as f64),
    ];
    let index = |key: &str| -> std::result::Result<Option<usize>, String> {
        match frame.get(key) {
            None => Ok(None),
            Some(v) => v
                .as_u64()
                .map(|x| Some(x as usize))
                .ok_or_else(|| format!("'{key}' is not a whole number")),
        }
    };
    let timestep = index("timestep_index")?.ok_or("'timestep_index' is missing")?;
    let camera_index = index("camera_index")?.or(index("camera_id")?).unwrap_or(0);
    let mask = match frame.get("fg_mask_path") {
        None => None,
        Some(v) => {
            let m = root.join(v.as_str().ok_or("'fg_mask_path' is not a string")?);
            if !m.is_file() {
                return Err(format!("mask {} does not exist", m.display()));
            }
            Some(m)
        }
    };
    Ok(View {
        camera: TrainCamera::from_c2w(c2w, focal, principal, size),
        image,
        mask,
        timestep,
        camera_index,
    })
}
