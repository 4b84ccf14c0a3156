//! Test fixtures in the real formats, made from the built-in head: a FLAME-layout
//! model pickle (numpy arrays, a chumpy `shapedirs`, a scipy csc `J_regressor`),
//! a masks pickle with FLAME's mask names, and GaussianAvatars avatar folders
//! (`point_cloud.ply` + `flame_param.npz`). Loading them exercises the whole
//! real-data path: pickle → FLAME model → GaussianAvatars teeth → regions →
//! avatars → composites → exports. `visage fixtures DIR` writes them.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use glam::Vec3;

use super::avatar::{write_avatar, AvatarParams, FrameParams, SHAPE_PARAMS};
use super::flame::{load_flame, FLAME_SHAPE_COMPONENTS};
use super::pickle_write::{to_pickle, PyObj};
use crate::avatar::synthetic::{builtin_database, SyntheticOptions};
use crate::model::builtin::build_head;
use crate::model::head::{HeadModel, JOINT_COUNT};
use crate::model::motion::{builtin_motion, BUILTIN_MOTIONS};
use crate::model::regions::Region;

/// Where the fixture files went.
#[derive(Clone, Debug)]
pub struct FixturePaths {
    /// The FLAME-layout model pickle.
    pub model: PathBuf,
    /// The masks pickle.
    pub masks: PathBuf,
    /// The folder of avatar folders (a `--db DIR`).
    pub avatars: PathBuf,
}

/// `model` without the triangles whose region `drop` names (and the vertices
/// only they used), and where each kept vertex went (`u32::MAX`: removed).
fn without(model: &HeadModel, drop: impl Fn(Region) -> bool) -> (HeadModel, Vec<u32>) {
    let keep_tri: Vec<bool> = model.triangle_regions.iter().map(|r| !drop(*r)).collect();
    let mut used = vec![false; model.vertex_count()];
    for (t, k) in model.triangles.iter().zip(&keep_tri) {
        if *k {
            t.iter().for_each(|&v| used[v as usize] = true);
        }
    }
    let mut remap = vec![u32::MAX; used.len()];
    let mut next = 0u32;
    for (i, u) in used.iter().enumerate() {
        if *u {
            remap[i] = next;
            next += 1;
        }
    }
    let pick = |f: &[Vec3]| -> Vec<Vec3> {
        f.iter()
            .zip(&used)
            .filter(|(_, u)| **u)
            .map(|(v, _)| *v)
            .collect()
    };
    let basis = |b: &crate::model::head::Basis| {
        let mut out = crate::model::head::Basis::new(next as usize);
        for k in 0..b.len() {
            out.push(b.names()[k].clone(), pick(b.component(k)));
        }
        out
    };
    let kept = HeadModel {
        template: pick(&model.template),
        triangles: model
            .triangles
            .iter()
            .zip(&keep_tri)
            .filter(|(_, k)| **k)
            .map(|(t, _)| t.map(|v| remap[v as usize]))
            .collect(),
        triangle_regions: model
            .triangle_regions
            .iter()
            .zip(&keep_tri)
            .filter(|(_, k)| **k)
            .map(|(r, _)| *r)
            .collect(),
        shape_basis: basis(&model.shape_basis),
        expression_basis: basis(&model.expression_basis),
        joint_regressor: model.joint_regressor.clone().map(|row| {
            row.into_iter()
                .filter(|(v, _)| used[*v as usize])
                .map(|(v, w)| (remap[v as usize], w))
                .collect()
        }),
        skin_weights: model
            .skin_weights
            .iter()
            .zip(&used)
            .filter(|(_, u)| **u)
            .map(|(w, _)| *w)
            .collect(),
        pose_correctives: None,
        mouth_cavity: None,
    };
    (kept, remap)
}

/// The built-in head without its own tooth rows (the FLAME loader adds
/// GaussianAvatars' teeth instead).
fn without_teeth(model: &HeadModel) -> HeadModel {
    without(model, |r| {
        matches!(r, Region::TeethUpper | Region::TeethLower)
    })
    .0
}

/// FLAME mask names for the built-in regions.
fn mask_name(r: Region) -> Option<&'static str> {
    Some(match r {
        Region::Skin => "face",
        Region::Hair => "scalp",
        Region::Neck => "neck",
        Region::Boundary => "boundary",
        Region::Nose => "nose",
        Region::Lips | Region::LipsInside => "lips",
        Region::LeftEyeRegion => "left_eye_region",
        Region::RightEyeRegion => "right_eye_region",
        Region::LeftEyeball => "left_eyeball",
        Region::RightEyeball => "right_eyeball",
        Region::LeftEar => "left_ear",
        Region::RightEar => "right_ear",
        _ => return None,
    })
}

/// Vertex masks of a model from its regions, plus the mouth-slit rings as the
/// lip rings the teeth hang from.
fn masks_of(model: &HeadModel) -> BTreeMap<String, Vec<i64>> {
    let mut masks: BTreeMap<String, Vec<i64>> = BTreeMap::new();
    let mut outside = vec![false; model.vertex_count()];
    let mut inside = vec![false; model.vertex_count()];
    for (t, r) in model.triangles.iter().zip(&model.triangle_regions) {
        for &v in t {
            if let Some(name) = mask_name(*r) {
                masks.entry(name.to_string()).or_default().push(v as i64);
            }
            if *r == Region::LipsInside {
                inside[v as usize] = true;
            } else {
                outside[v as usize] = true;
            }
        }
    }
    for ids in masks.values_mut() {
        ids.sort_unstable();
        ids.dedup();
    }
    // The slit's margin: where the mouth cavity meets the face, 15 above and 15 below.
    let mut margin: Vec<u32> = (0..model.vertex_count() as u32)
        .filter(|&v| outside[v as usize] && inside[v as usize])
        .collect();
    margin.sort_by(|a, b| {
        model.template[*a as usize]
            .x
            .total_cmp(&model.template[*b as usize].x)
    });
    // Sorted by x, the margin comes in upper/lower pairs at (nearly) the same x.
    let y = |v: u32| model.template[v as usize].y;
    let (upper, lower): (Vec<u32>, Vec<u32>) = margin
        .chunks(2)
        .filter(|p| p.len() == 2)
        .map(|p| {
            if y(p[0]) > y(p[1]) {
                (p[0], p[1])
            } else {
                (p[1], p[0])
            }
        })
        .unzip();
    if upper.len() == 15 && lower.len() == 15 {
        masks.insert(
            "lip_outside_ring_upper".into(),
            upper.iter().map(|&v| v as i64).collect(),
        );
        masks.insert(
            "lip_outside_ring_lower".into(),
            lower.iter().map(|&v| v as i64).collect(),
        );
    }
    masks
}

/// Writes the FLAME-layout model pickle of `model` (shape components at 0..26,
/// expressions from component 300 on, as FLAME lays them out).
fn write_model(path: &Path, model: &HeadModel) -> super::Result<()> {
    let v = model.vertex_count();
    let template: Vec<f64> = model
        .template
        .iter()
        .flat_map(|p| p.to_array().map(|x| x as f64))
        .collect();
    let faces: Vec<u32> = model.triangles.iter().flatten().copied().collect();
    let components = FLAME_SHAPE_COMPONENTS + model.expression_basis.len();
    let mut shapedirs = vec![0.0f32; v * 3 * components];
    let mut put = |k: usize, field: &[Vec3]| {
        for (i, d) in field.iter().enumerate() {
            for c in 0..3 {
                shapedirs[(i * 3 + c) * components + k] = d[c];
            }
        }
    };
    for k in 0..model.shape_basis.len().min(FLAME_SHAPE_COMPONENTS) {
        put(k, model.shape_basis.component(k));
    }
    for k in 0..model.expression_basis.len() {
        put(
            FLAME_SHAPE_COMPONENTS + k,
            model.expression_basis.component(k),
        );
    }
    let posedirs = vec![0.0f32; v * 3 * (JOINT_COUNT - 1) * 9];
    let weights: Vec<f64> = model
        .skin_weights
        .iter()
        .flat_map(|w| w.map(|x| x as f64))
        .collect();
    // J_regressor as csc (5 × V): column v lists the joints it contributes to.
    let mut by_column: Vec<Vec<(i32, f64)>> = vec![Vec::new(); v];
    for (j, row) in model.joint_regressor.iter().enumerate() {
        for &(vert, w) in row {
            by_column[vert as usize].push((j as i32, w as f64));
        }
    }
    let (mut data, mut indices, mut indptr) = (Vec::new(), Vec::new(), vec![0i32]);
    for col in &by_column {
        for &(j, w) in col {
            indices.push(j);
            data.push(w);
        }
        indptr.push(indices.len() as i32);
    }
    let kintree: Vec<i64> = vec![4_294_967_295, 0, 1, 1, 1, 0, 1, 2, 3, 4];
    let dict = PyObj::Dict(vec![
        ("v_template", PyObj::F64(vec![v, 3], &template)),
        ("f", PyObj::U32(vec![model.triangle_count(), 3], &faces)),
        (
            "shapedirs",
            PyObj::Chumpy(Box::new(PyObj::F32(vec![v, 3, components], &shapedirs))),
        ),
        ("posedirs", PyObj::F32(vec![v, 3, 36], &posedirs)),
        (
            "J_regressor",
            PyObj::Csc((JOINT_COUNT, v), &data, &indices, &indptr),
        ),
        ("kintree_table", PyObj::I64(vec![2, JOINT_COUNT], &kintree)),
        ("weights", PyObj::F64(vec![v, JOINT_COUNT], &weights)),
        ("bs_style", PyObj::Str("lbs")),
        ("bs_type", PyObj::Str("lrotmin")),
    ]);
    super::write_file(path, &to_pickle(&dict))
}

/// The mouth of the fixture model.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FixtureMouth {
    /// The built-in head's mouth pocket stays: the model is closed at the lips.
    Pocket,
    /// The pocket is cut away, leaving the lips' inner rim open as FLAME's is,
    /// so the loader adds its own cavity.
    Open,
}

/// Writes the fixtures into `dir`: `flame/model.pkl`, `flame/masks.pkl` and
/// `avatars/<name>/` for `sources` synthetic people.
pub fn write_fixtures(
    dir: &Path,
    sources: usize,
    gaussians_per_avatar: usize,
    seed: u64,
) -> super::Result<FixturePaths> {
    write_fixtures_with(
        dir,
        sources,
        gaussians_per_avatar,
        seed,
        FixtureMouth::Pocket,
    )
}

/// [`write_fixtures`] with a choice of mouth.
pub fn write_fixtures_with(
    dir: &Path,
    sources: usize,
    gaussians_per_avatar: usize,
    seed: u64,
    mouth: FixtureMouth,
) -> super::Result<FixturePaths> {
    let flame_dir = dir.join("flame");
    let avatars = dir.join("avatars");
    for d in [&flame_dir, &avatars] {
        std::fs::create_dir_all(d).map_err(|e| super::FileError::access("create", d, e))?;
    }
    let closed = without_teeth(&build_head());
    // The lip rings come from where the pocket meets the lips, so the masks are
    // found on the closed model and carried over to the open one.
    let mut masks = masks_of(&closed);
    let base = match mouth {
        FixtureMouth::Pocket => closed,
        FixtureMouth::Open => {
            let (open, remap) = without(&closed, |r| r == Region::LipsInside);
            for ids in masks.values_mut() {
                *ids = ids
                    .iter()
                    .map(|&v| remap[v as usize])
                    .filter(|&v| v != u32::MAX)
                    .map(i64::from)
                    .collect();
            }
            open
        }
    };
    let paths = FixturePaths {
        model: flame_dir.join("model.pkl"),
        masks: flame_dir.join("masks.pkl"),
        avatars: avatars.clone(),
    };
    write_model(&paths.model, &base)?;
    let mask_objs: Vec<(String, Vec<i64>)> = masks.into_iter().collect();
    let dict = PyObj::Dict(
        mask_objs
            .iter()
            .map(|(k, v)| (k.as_str(), PyObj::I64(vec![v.len()], v)))
            .collect(),
    );
    std::fs::write(&paths.masks, to_pickle(&dict))
        .map_err(|e| super::FileError::access("write", &paths.masks, e))?;
    // Avatars on the model as visage loads it (with GaussianAvatars' teeth).
    let model = load_flame(&paths.model, &paths.masks)?;
    let db = builtin_database(
        model,
        SyntheticOptions {
            seed,
            sources,
            gaussians_per_avatar,
        },
    )?;
    // FLAME files carry no component names: drive the expressions by the built-in
    // names, whose components the model pickle lays out from index 300 in order.
    let names = build_head().expression_basis.names().to_vec();
    for (i, s) in db.sources.iter().enumerate() {
        let motion = builtin_motion(
            BUILTIN_MOTIONS[i % BUILTIN_MOTIONS.len()],
            &names,
            i as u64 + 1,
        )
        .expect("built-in motion");
        let frames: Vec<FrameParams> = (0..motion.frames())
            .map(|k| {
                let (e, p) = motion.frame(k);
                FrameParams {
                    expression: e.to_vec(),
                    pose: *p,
                    offset: Vec::new(),
                }
            })
            .collect();
        let mut shape = vec![0.0f32; SHAPE_PARAMS];
        for (d, x) in shape.iter_mut().zip(&s.shape) {
            *d = *x;
        }
        write_avatar(
            &avatars.join(&s.name),
            &s.gaussians,
            &AvatarParams {
                shape: &shape,
                static_offset: &s.static_offset,
                frames: &frames,
            },
            &db.model,
        )?;
    }
    Ok(paths)
}
