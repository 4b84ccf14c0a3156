//! `visage capture`: a multi-view video dataset in GaussianAvatars' layout
//! (what VHAP writes for NeRSemble) made from a built-in source — ground truth
//! drawn from an *opaque*, textured version of the procedural head (a
//! z-buffered mesh rasteriser with the source's procedural skin, hair, lip,
//! eye and brow textures under its baked light; not its Gaussians), from a
//! NeRSemble-like rig, over frames of a built-in motion, with foreground
//! masks. Deterministic from the database's seed.

use std::path::Path;

use glam::Vec3;
use serde_json::{json, Value};

use super::project::TrainCamera;
use super::sitter::{Sitter, SurfacePoint};
use crate::avatar::database::Database;
use crate::avatar::synthetic::{cavity_occlusion, vertex_normals};
use crate::error::{Error, Result};
use crate::io::avatar::{write_flame_params, AvatarParams, FrameParams};
use crate::model::head::HeadModel;
use crate::render::image::RgbImage;

/// Supersampling per axis (antialiased images and soft mask edges).
const SUPERSAMPLE: u32 = 3;
/// Distance of the rig's cameras from the head, metres.
const RIG_RADIUS: f64 = 1.0;
/// Vertical field of view of the rig's cameras, degrees.
const RIG_FOV: f64 = 22.0;
/// The point the rig looks at (the head's centre, as the study camera).
const RIG_TARGET: [f64; 3] = [0.0, -0.025, 0.0];

/// What to capture.
#[derive(Clone, Debug, PartialEq)]
pub struct CaptureOptions {
    /// Source avatar of the built-in database.
    pub source: String,
    /// Image size.
    pub size: [u32; 2],
    /// Training cameras.
    pub cameras: usize,
    /// Frames (timesteps) sampled evenly from the motion.
    pub frames: usize,
    /// Built-in motion.
    pub motion: String,
    /// A full ring of cameras instead of the frontal arc.
    pub ring: bool,
}

/// A camera at yaw/pitch (degrees) on the rig's sphere.
fn rig_camera(yaw: f64, pitch: f64, size: [u32; 2]) -> TrainCamera {
    let (y, p) = (yaw.to_radians(), pitch.to_radians());
    let target = glam::DVec3::from(RIG_TARGET);
    let eye = target + RIG_RADIUS * glam::DVec3::new(y.sin() * p.cos(), p.sin(), y.cos() * p.cos());
    let back = (eye - target).normalize();
    let right = glam::DVec3::Y.cross(back).normalize();
    let up = back.cross(right);
    let c2w = [
        [right.x, up.x, back.x, eye.x],
        [right.y, up.y, back.y, eye.y],
        [right.z, up.z, back.z, eye.z],
        [0.0, 0.0, 0.0, 1.0],
    ];
    let focal = 0.5 * size[1] as f64 / (0.5 * RIG_FOV.to_radians()).tan();
    TrainCamera::from_c2w(
        c2w,
        [focal, focal],
        [0.5 * size[0] as f64, 0.5 * size[1] as f64],
        size,
    )
}

/// The training rig: `count` cameras on a frontal arc (±60° yaw, two rows of
/// pitch, as NeRSemble's) or a full ring, and one held-out camera between
/// them for novel views.
pub fn rig(count: usize, ring: bool, size: [u32; 2]) -> (Vec<TrainCamera>, TrainCamera) {
    let columns = count.div_ceil(2).max(1);
    let cameras = (0..count)
        .map(|k| {
            let (column, row) = (k % columns, k / columns);
            let t = if columns == 1 {
                0.5
            } else {
                column as f64 / (columns - 1) as f64
            };
            let yaw = if ring {
                360.0 * column as f64 / columns as f64 + 15.0 * row as f64
            } else {
                -60.0 + 120.0 * t
            };
            let pitch = if row == 0 { -8.0 } else { 12.0 };
            rig_camera(yaw, pitch, size)
        })
        .collect();
    let step = if ring { 360.0 } else { 120.0 } / columns.max(2) as f64;
    (cameras, rig_camera(0.5 * step + 3.0, 2.0, size))
}

/// A sitter's surface as the capture draws it: per-vertex normals and
/// ambient occlusion of its neutral, interpolated over the posed mesh. Also
/// what evaluations draw ground truth with at any pose and camera.
pub struct Surface<'a> {
    model: &'a HeadModel,
    sitter: &'a Sitter,
    normals: Vec<Vec3>,
    occlusion: Vec<f32>,
}

impl<'a> Surface<'a> {
    /// The surface of `sitter` on `model`.
    pub fn new(model: &'a HeadModel, sitter: &'a Sitter) -> Self {
        let neutral = sitter.neutral(model);
        let normals = vertex_normals(&neutral, &model.triangles);
        let occlusion = cavity_occlusion(&neutral, &normals, &model.triangles);
        Self {
            model,
            sitter,
            normals,
            occlusion,
        }
    }

    /// Draws the posed mesh: a premultiplied RGB image on black and its
    /// coverage mask, antialiased by supersampling.
    pub fn draw(&self, posed: &[Vec3], camera: &TrainCamera) -> (RgbImage, Vec<u8>) {
        let [w, h] = camera.size;
        let (sw, sh) = (w * SUPERSAMPLE, h * SUPERSAMPLE);
        let mut fine = *camera;
        fine.size = [sw, sh];
        fine.focal = camera.focal.map(|f| f * SUPERSAMPLE as f64);
        fine.principal = camera.principal.map(|c| c * SUPERSAMPLE as f64);
        let hits = rasterize(posed, &self.model.triangles, &fine);
        let mut image = RgbImage::new(w, h, [0, 0, 0]);
        let mut mask = vec![0u8; (w * h) as usize];
        let samples = (SUPERSAMPLE * SUPERSAMPLE) as f32;
        for y in 0..h {
            for x in 0..w {
                let mut sum = [0.0f32; 3];
                let mut covered = 0.0f32;
                for sy in 0..SUPERSAMPLE {
                    for sx in 0..SUPERSAMPLE {
                        let k = ((y * SUPERSAMPLE + sy) * sw + x * SUPERSAMPLE + sx) as usize;
                        if let Some((t, b, _)) = hits[k] {
                            let rgb = self.shade(t, b);
                            for ch in 0..3 {
                                sum[ch] += rgb[ch];
                            }
                            covered += 1.0;
                        }
                    }
                }
                let p = (y * w + x) as usize;
                for (out, total) in image.pixels[p * 3..p * 3 + 3].iter_mut().zip(sum) {
                    *out = (total / samples * 255.0).round() as u8;
                }
                mask[p] = (covered / samples * 255.0).round() as u8;
            }
        }
        (image, mask)
    }

    fn shade(&self, triangle: u32, bary: [f32; 3]) -> [f32; 3] {
        let tri = self.model.triangles[triangle as usize];
        let mix3 = |v: &dyn Fn(usize) -> Vec3| -> Vec3 {
            (0..3).map(|k| bary[k] * v(tri[k] as usize)).sum()
        };
        let texel = mix3(&|i| self.model.template[i]);
        let normal = mix3(&|i| self.normals[i]).normalize_or(Vec3::Z);
        let occlusion: f32 = (0..3)
            .map(|k| bary[k] * self.occlusion[tri[k] as usize])
            .sum();
        let point = SurfacePoint {
            triangle,
            vertices: tri,
            bary,
            texel,
            normal,
            occlusion,
        };
        self.sitter.shade(self.model, &point)
    }
}

/// For each pixel centre, the nearest triangle of the mesh (z-buffered), or
/// `None` where the mesh does not cover it: which surface a pixel shows.
pub fn visible_triangles(
    vertices: &[Vec3],
    triangles: &[[u32; 3]],
    camera: &TrainCamera,
) -> Vec<Option<u32>> {
    rasterize(vertices, triangles, camera)
        .into_iter()
        .map(|hit| hit.map(|(t, _, _)| t))
        .collect()
}

/// For each pixel centre, the view depth of the nearest surface of the mesh
/// (∞ where it does not cover the pixel).
pub fn surface_depth(vertices: &[Vec3], triangles: &[[u32; 3]], camera: &TrainCamera) -> Vec<f64> {
    rasterize(vertices, triangles, camera)
        .into_iter()
        .map(|hit| hit.map_or(f64::INFINITY, |(_, _, z)| z))
        .collect()
}

/// A world point's continuous pixel position (x right, y down; pixel
/// centres at half-integers) and view depth, `[x, y, depth]`; `None` in
/// front of the near plane.
pub fn pixel_of(camera: &TrainCamera, point: glam::DVec3) -> Option<[f64; 3]> {
    let v = point.to_array();
    let r = &camera.rotation;
    let p: [f64; 3] = std::array::from_fn(|i| {
        r[i][0] * v[0] + r[i][1] * v[1] + r[i][2] * v[2] + camera.translation[i]
    });
    let depth = -p[2];
    (depth > camera.clip[0]).then(|| {
        [
            camera.principal[0] + camera.focal[0] * p[0] / depth,
            camera.principal[1] - camera.focal[1] * p[1] / depth,
            depth,
        ]
    })
}

/// For each pixel centre, the nearest triangle, its perspective-correct
/// barycentric coordinates and its view depth.
pub fn rasterize(
    vertices: &[Vec3],
    triangles: &[[u32; 3]],
    camera: &TrainCamera,
) -> Vec<Option<(u32, [f32; 3], f64)>> {
    let [w, h] = camera.size;
    let projected: Vec<Option<[f64; 3]>> = vertices
        .iter()
        .map(|v| pixel_of(camera, v.as_dvec3()))
        .collect();
    let mut depth = vec![f64::INFINITY; (w * h) as usize];
    let mut hits = vec![None; (w * h) as usize];
    for (t, tri) in triangles.iter().enumerate() {
        let [Some(a), Some(b), Some(c)] = tri.map(|i| projected[i as usize]) else {
            continue;
        };
        let area = edge(a, b, c);
        if area.abs() < 1e-12 {
            continue;
        }
        let x0 = a[0].min(b[0]).min(c[0]).floor().max(0.0) as u32;
        let x1 = a[0].max(b[0]).max(c[0]).ceil().min(w as f64 - 1.0);
        let y0 = a[1].min(b[1]).min(c[1]).floor().max(0.0) as u32;
        let y1 = a[1].max(b[1]).max(c[1]).ceil().min(h as f64 - 1.0);
        if x1 < 0.0 || y1 < 0.0 {
            continue;
        }
        for y in y0..=y1 as u32 {
            for x in x0..=x1 as u32 {
                let p = [x as f64 + 0.5, y as f64 + 0.5, 0.0];
                let screen = [
                    edge(b, c, p) / area,
                    edge(c, a, p) / area,
                    edge(a, b, p) / area,
                ];
                if screen.iter().any(|&s| s < 0.0) {
                    continue;
                }
                // Perspective-correct: weights over depth, renormalised.
                let inv = [screen[0] / a[2], screen[1] / b[2], screen[2] / c[2]];
                let sum = inv[0] + inv[1] + inv[2];
                let z = 1.0 / sum;
                let k = (y * w + x) as usize;
                if z < depth[k] {
                    depth[k] = z;
                    hits[k] = Some((t as u32, inv.map(|v| (v / sum) as f32), z));
                }
            }
        }
    }
    hits
}

fn edge(a: [f64; 3], b: [f64; 3], p: [f64; 3]) -> f64 {
    (b[0] - a[0]) * (p[1] - a[1]) - (b[1] - a[1]) * (p[0] - a[0])
}

/// The position of `name` among `names`, or an error listing them.
fn find(names: &[&str], name: &str, what: &str) -> Result<usize> {
    names.iter().position(|n| *n == name).ok_or_else(|| {
        Error::input(format!(
            "unknown {what} '{}' ({what}s: {})",
            crate::text::printable(name),
            names.join(", ")
        ))
    })
}

/// What a capture wrote.
#[derive(Clone, Debug, PartialEq)]
pub struct CaptureSummary {
    /// Images written (all splits).
    pub images: usize,
    /// Timesteps.
    pub timesteps: usize,
}

/// Writes the dataset of built-in source `options.source` into `out`.
/// `progress` hears (images done, images in all).
pub fn capture(
    db: &Database,
    options: &CaptureOptions,
    out: &Path,
    progress: &dyn Fn(u64, u64),
) -> Result<CaptureSummary> {
    let source_names: Vec<&str> = db.sources.iter().map(|s| s.name.as_str()).collect();
    let source = find(&source_names, &options.source, "source")?;
    capture_sitter(db, options, &Sitter::source(db, source), out, progress)
}

/// Writes the dataset of `sitter` into `out` (`options.source` is not read).
pub fn capture_sitter(
    db: &Database,
    options: &CaptureOptions,
    sitter: &Sitter,
    out: &Path,
    progress: &dyn Fn(u64, u64),
) -> Result<CaptureSummary> {
    let motion_names: Vec<&str> = db.motions.iter().map(|m| m.name.as_str()).collect();
    let motion = &db.motions[find(&motion_names, &options.motion, "motion")?];
    if options.cameras == 0 || options.frames == 0 {
        return Err(Error::input("--cameras and --frames must be at least 1"));
    }
    let model = &db.model;
    let surface = Surface::new(model, sitter);
    for dir in ["images", "fg_masks", "flame_param"] {
        let d = out.join(dir);
        std::fs::create_dir_all(&d).map_err(|e| Error::io("create", &d, e))?;
    }
    let (cameras, held_out) = rig(options.cameras, options.ring, options.size);
    let timesteps: Vec<usize> = (0..options.frames)
        .map(|k| k * motion.frames() / options.frames)
        .collect();
    // Novel expressions: the last fifth of the timesteps (at least one when
    // there are two or more) are seen only in the test split.
    let test_from = if options.frames >= 2 {
        options.frames - (options.frames / 5).max(1)
    } else {
        options.frames
    };
    let test_cameras: Vec<usize> = (0..cameras.len()).step_by(4).collect();
    let mut splits: [Vec<Value>; 3] = Default::default();
    let total = (test_from * (cameras.len() + 1)
        + (options.frames - test_from) * test_cameras.len()) as u64;
    let mut done = 0u64;
    let neutral = model.neutral(&sitter.shape, Some(&sitter.static_offset));
    for (t, &frame) in timesteps.iter().enumerate() {
        let (expression, pose) = motion.frame(frame);
        let offset = motion.frame_offset(frame);
        let mut posed = Vec::with_capacity(neutral.len());
        model.pose_offset(&neutral, expression, pose, offset, &mut posed);
        let flame_path = format!("flame_param/{t:05}.npz");
        write_flame_params(
            &out.join(&flame_path),
            &AvatarParams {
                shape: &sitter.shape,
                static_offset: &sitter.static_offset,
                frames: &[FrameParams {
                    expression: expression.to_vec(),
                    pose: *pose,
                    offset: offset.unwrap_or_default().to_vec(),
                }],
            },
        )?;
        let mut views: Vec<(usize, usize, &TrainCamera)> = Vec::new();
        if t < test_from {
            views.extend(cameras.iter().enumerate().map(|(c, cam)| (0, c, cam)));
            views.push((1, cameras.len(), &held_out));
        } else {
            views.extend(test_cameras.iter().map(|&c| (2, c, &cameras[c])));
        }
        for (split, c, camera) in views {
            let (image, mask) = surface.draw(&posed, camera);
            let name = format!("{t:05}_{c:02}.png");
            let image_path = out.join("images").join(&name);
            image.save_png(&image_path)?;
            let mask_path = out.join("fg_masks").join(&name);
            image::save_buffer(
                &mask_path,
                &mask,
                camera.size[0],
                camera.size[1],
                image::ExtendedColorType::L8,
            )
            .map_err(|e| Error::io("write", &mask_path, e))?;
            splits[split].push(json!({
                "file_path": format!("images/{name}"),
                "fg_mask_path": format!("fg_masks/{name}"),
                "flame_param_path": flame_path,
                "transform_matrix": camera.c2w(),
                "timestep_index": t,
                "camera_index": c,
                "camera_id": c,
                "fl_x": camera.focal[0],
                "fl_y": camera.focal[1],
                "cx": camera.principal[0],
                "cy": camera.principal[1],
                "w": camera.size[0],
                "h": camera.size[1],
                "camera_angle_x": 2.0 * (0.5 * camera.size[0] as f64 / camera.focal[0]).atan(),
            }));
            done += 1;
            progress(done, total);
        }
    }
    let [w, h] = options.size;
    let focal = cameras[0].focal;
    let mut builtin = json!({
        "source": sitter.name,
        "motion": motion.name,
        "seed_note": "captured from visage's built-in database; train it without FLAME files",
    });
    if let Some(note) = &sitter.note {
        builtin["composite"] = note.clone();
    }
    for (split, frames) in ["train", "val", "test"].iter().zip(splits) {
        let doc = json!({
            "camera_angle_x": 2.0 * (0.5 * w as f64 / focal[0]).atan(),
            "fl_x": focal[0],
            "fl_y": focal[1],
            "cx": 0.5 * w as f64,
            "cy": 0.5 * h as f64,
            "w": w,
            "h": h,
            "visage_builtin_head": builtin,
            "frames": frames,
        });
        let path = out.join(format!("transforms_{split}.json"));
        std::fs::write(&path, serde_json::to_string_pretty(&doc).expect("json"))
            .map_err(|e| Error::io("write", &path, e))?;
    }
    // GaussianAvatars recognises a dynamic-head dataset by this file.
    write_flame_params(
        &out.join("canonical_flame_param.npz"),
        &AvatarParams {
            shape: &sitter.shape,
            static_offset: &sitter.static_offset,
            frames: &[],
        },
    )?;
    Ok(CaptureSummary {
        images: done as usize,
        timesteps: timesteps.len(),
    })
}
