//! A dataset's timesteps posed on the head model: each timestep's FLAME
//! parameters read once and turned into vertices and triangle frames, the
//! identity the avatar is exported with, the training cameras' extent, and
//! the training arc the hole metrics look along.

use std::collections::BTreeMap;

use glam::{DVec3, Vec3};

use super::dataset::{Dataset, View};
use super::project::TrainCamera;
use crate::avatar::binding::{triangle_frames, TriangleFrame};
use crate::error::{Error, Result};
use crate::io::avatar::{read_flame_params, FlameParams, FrameParams};
use crate::model::head::HeadModel;

/// The training arc as hole metrics see it: the head posed at the first
/// training timestep and every training camera of that timestep, images
/// scaled to at most `side` pixels.
pub fn training_arc(
    dataset: &Dataset,
    head: &HeadModel,
    side: u32,
) -> Result<(Vec<Vec3>, Vec<TrainCamera>)> {
    let first = dataset
        .train
        .iter()
        .map(|v| v.timestep)
        .min()
        .ok_or_else(|| Error::input(format!("{} has no training views", dataset.root.display())))?;
    let posed = posed_vertices(&timestep_params(dataset, head, first)?, head);
    let cameras = dataset
        .train
        .iter()
        .filter(|v| v.timestep == first)
        .map(|v| super::hole_metrics::at_most(&v.camera, side))
        .collect();
    Ok((posed, cameras))
}

/// Every timestep the dataset names, posed: vertices per timestep, the
/// identity and the FLAME parameters of each.
#[allow(clippy::type_complexity)]
pub fn pose_timesteps(
    dataset: &Dataset,
    head: &HeadModel,
) -> Result<(
    BTreeMap<usize, Vec<Vec3>>,
    (Vec<f32>, Vec<glam::DVec3>),
    Vec<FrameParams>,
)> {
    let mut posed = BTreeMap::new();
    let mut identity = None;
    let mut flame_frames = Vec::new();
    for (&t, path) in &dataset.flame_params {
        let params = read_flame_params(path, "dataset", head)?;
        posed.insert(t, posed_vertices(&params, head));
        let (expression, pose) = params.motion.frame(0);
        flame_frames.push(FrameParams {
            expression: expression.to_vec(),
            pose: *pose,
            offset: params.motion.frame_offset(0).unwrap_or_default().to_vec(),
        });
        identity.get_or_insert((params.shape.clone(), params.static_offset.clone()));
    }
    let identity =
        identity.ok_or_else(|| Error::input("the dataset names no FLAME parameter files"))?;
    Ok((posed, identity, flame_frames))
}

/// 1.1 × the largest distance of a training camera from their mean (3DGS's
/// `cameras_extent`, the unit of the position learning rate and the
/// densification sizes).
pub fn camera_extent(views: &[View]) -> f64 {
    let eyes: Vec<DVec3> = views.iter().map(|v| DVec3::from(v.camera.eye)).collect();
    let mean = eyes.iter().copied().sum::<DVec3>() / eyes.len().max(1) as f64;
    1.1 * eyes
        .iter()
        .map(|e| (*e - mean).length())
        .fold(0.0, f64::max)
        .max(1e-3)
}

/// One timestep's FLAME parameters, read from the dataset.
pub fn timestep_params(
    dataset: &Dataset,
    head: &HeadModel,
    timestep: usize,
) -> Result<FlameParams> {
    let path = dataset
        .flame_params
        .get(&timestep)
        .ok_or_else(|| Error::input(format!("timestep {timestep} has no FLAME parameters")))?;
    Ok(read_flame_params(path, "dataset", head)?)
}

/// The posed vertices of one timestep's FLAME parameters.
pub fn posed_vertices(params: &FlameParams, head: &HeadModel) -> Vec<Vec3> {
    let (expression, pose) = params.motion.frame(0);
    let neutral = head.neutral(&params.shape, Some(&params.static_offset));
    let mut posed = Vec::with_capacity(neutral.len());
    let offset = params.motion.frame_offset(0);
    head.pose_offset(&neutral, expression, pose, offset, &mut posed);
    posed
}

/// The triangle frames of one timestep's FLAME parameters.
fn pose(params: &FlameParams, head: &HeadModel) -> Vec<TriangleFrame> {
    triangle_frames(&posed_vertices(params, head), &head.triangles)
}

/// Triangle frames for every timestep `views` show, each read and posed once.
pub fn timestep_frames(
    dataset: &Dataset,
    head: &HeadModel,
    views: &[View],
) -> Result<BTreeMap<usize, Vec<TriangleFrame>>> {
    let mut frames = BTreeMap::new();
    for view in views {
        if frames.contains_key(&view.timestep) {
            continue;
        }
        let params = timestep_params(dataset, head, view.timestep)?;
        frames.insert(view.timestep, pose(&params, head));
    }
    Ok(frames)
}
