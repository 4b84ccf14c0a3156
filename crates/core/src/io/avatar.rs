//! GaussianAvatars avatar folders: `point_cloud.ply` (triangle-local Gaussians
//! with `binding_0`) and `flame_param.npz`, read into source avatars and written
//! from composites.
//!
//! `flame_param.npz` holds exactly what GaussianAvatars' `FlameGaussianModel`
//! saves (`np.savez` of its `flame_param` dict after `.float()`), all float32:
//! shape (300,), expr (T,100), rotation / neck_pose / jaw_pose / translation
//! (T,3), eyes_pose (T,6), static_offset (1,V,3) and dynamic_offset (T,V,3),
//! V counting the teeth. Its loader moves every array to torch as it is and
//! indexes `dynamic_offset[[t]]` when it poses frame t, so the key set, dtypes
//! and shapes are the contract (docs/method.md §9.4).

use std::path::Path;

use glam::{DVec3, Vec3};

use super::npy::{read_npz, write_npy, write_npz, NpyData};
use super::pickle::NdArray;
use super::ply::{encode_inria_ply, read_element, InriaRecord, InriaRows};
use crate::avatar::database::SourceAvatar;
use crate::avatar::gaussians::{sh_coefficients, GaussianSet};
use crate::avatar::rebind::rebind_past;
use crate::model::head::{HeadModel, Pose, JOINT_COUNT};
use crate::model::motion::Motion;

/// Shape coefficients GaussianAvatars stores.
pub const SHAPE_PARAMS: usize = 300;
/// Expression coefficients GaussianAvatars stores.
pub const EXPRESSION_PARAMS: usize = 100;

/// Reads the triangle-bound Gaussians of a GaussianAvatars `point_cloud.ply`.
pub fn read_bound_ply(path: &Path, triangles: usize) -> super::Result<GaussianSet> {
    let bytes = super::read_file(path)?;
    parse_bound_ply(&bytes, triangles).map_err(|e| e.in_file(path))
}

/// Parses GaussianAvatars `point_cloud.ply` bytes.
pub fn parse_bound_ply(bytes: &[u8], triangles: usize) -> super::Result<GaussianSet> {
    let c = read_element(bytes, "vertex")?;
    let rows = InriaRows::new(
        &c,
        Some((
            "binding_0",
            "no binding_0 property: this is not a GaussianAvatars point cloud (use --ply for world-space 3DGS files)",
        )),
    )?;
    let mut set = GaussianSet::with_degree(rows.degree);
    set.reserve(c.rows);
    let mut sh = vec![0.0f32; 3 * sh_coefficients(rows.degree)];
    for i in 0..c.rows {
        let b = rows.extra_value(i).expect("binding_0 is required");
        if !(b >= 0.0 && b.fract() == 0.0 && (b as usize) < triangles) {
            return Err(format!(
                "Gaussian {i} is bound to triangle {}, but the mesh has {triangles} triangles",
                crate::text::id_text(b)
            )
            .into());
        }
        let r = rows.decode(i, &mut sh)?;
        set.push(
            b as u32,
            r.position,
            r.rotation,
            r.log_scale,
            r.opacity_logit,
            &sh,
        );
    }
    Ok(set)
}

/// Writes triangle-bound Gaussians as a GaussianAvatars `point_cloud.ply`.
pub fn write_bound_ply(path: &Path, set: &GaussianSet) -> super::Result<()> {
    let out = encode_inria_ply(
        "GaussianAvatars layout, written by visage",
        set.len(),
        set.sh_degree,
        Some("binding_0"),
        |i| InriaRecord {
            position: set.position[i],
            sh: set.sh_of(i),
            opacity_logit: set.opacity_logit[i],
            log_scale: set.log_scale[i],
            rotation: set.rotation[i],
            extra: Some(set.binding[i] as f32),
        },
    );
    super::write_file(path, &out)
}

fn field<'a>(
    arrays: &'a std::collections::BTreeMap<String, NdArray>,
    name: &str,
) -> Result<&'a NdArray, String> {
    let a = arrays
        .get(name)
        .ok_or_else(|| format!("flame_param.npz has no '{name}'"))?;
    if a.data.iter().any(|x| !x.is_finite()) {
        return Err(format!(
            "flame_param.npz '{name}' has NaN or infinite values"
        ));
    }
    Ok(a)
}

/// Rows of a (T, width) array, or an error naming the array.
fn rows(a: &NdArray, name: &str, width: usize) -> Result<Vec<Vec<f32>>, String> {
    if a.shape.len() != 2 || a.shape[1] != width {
        return Err(format!(
            "flame_param.npz '{name}' has shape {:?}, expected (T, {width})",
            a.shape
        ));
    }
    Ok(a.data
        .chunks(width)
        .map(|r| r.iter().map(|&x| x as f32).collect())
        .collect())
}

/// Reads one avatar folder into a source avatar for `model`.
pub fn read_avatar(dir: &Path, name: &str, model: &HeadModel) -> super::Result<SourceAvatar> {
    let ply = dir.join("point_cloud.ply");
    let gaussians = read_bound_ply(&ply, model.triangle_count())?;
    if gaussians.is_empty() {
        // An empty source would leave holes wherever a recipe picks it.
        return Err(format!(
            "{}: holds no Gaussians (an avatar needs at least one)",
            ply.display()
        )
        .into());
    }
    let params = read_flame_params(&dir.join("flame_param.npz"), name, model)?;
    Ok(SourceAvatar {
        name: name.to_string(),
        shape: params.shape,
        static_offset: params.static_offset,
        motion: params.motion,
        gaussians,
        attributes: read_attributes(&dir.join(ATTRIBUTES_FILE))?,
    })
}

/// Optional file in an avatar folder labelling the person, one `key = "value"`
/// per line (for example `skin_tone = "dark"`); visage's own addition to the
/// GaussianAvatars layout, read for study constraints.
pub const ATTRIBUTES_FILE: &str = "attributes.toml";

/// Reads an avatar's labels; a missing file means none.
fn read_attributes(path: &Path) -> super::Result<std::collections::BTreeMap<String, String>> {
    let text = match std::fs::read_to_string(path) {
        Ok(text) => text,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Default::default()),
        Err(e) => return Err(super::FileError::access("read", path, e)),
    };
    let table: toml::Table = toml::from_str(&text)
        .map_err(|e| format!("{}: invalid TOML: {}", path.display(), e.message().trim()))?;
    table
        .into_iter()
        .map(|(key, value)| match value {
            toml::Value::String(v) => Ok((key, v)),
            other => Err(format!(
                "{}: attribute '{key}' must be a string, not {}",
                path.display(),
                other.type_str()
            )
            .into()),
        })
        .collect()
}

/// A `flame_param.npz`'s contents: identity and per-frame expression and pose.
pub struct FlameParams {
    /// Shape coefficients (as many as the model uses).
    pub shape: Vec<f32>,
    /// Static per-vertex offset (zero when the file has none).
    pub static_offset: Vec<DVec3>,
    /// Expression and pose per frame, named `name`.
    pub motion: Motion,
}

/// Reads FLAME parameters as GaussianAvatars stores them (an avatar's
/// `flame_param.npz`, or one timestep of a dataset's `flame_param/`).
pub fn read_flame_params(
    npz_path: &Path,
    name: &str,
    model: &HeadModel,
) -> super::Result<FlameParams> {
    let arrays = read_npz(npz_path)?;
    let label = |e: String| format!("{}: {e}", npz_path.display());
    let shape = field(&arrays, "shape").map_err(label)?;
    if shape.shape.last().copied().unwrap_or(0) < model.shape_basis.len().min(SHAPE_PARAMS)
        && !shape.data.is_empty()
    {
        return Err(label(format!(
            "'shape' has {} coefficients, the model uses {}",
            shape.data.len(),
            model.shape_basis.len()
        ))
        .into());
    }
    let shape_coeffs: Vec<f32> = shape
        .data
        .iter()
        .take(model.shape_basis.len())
        .map(|&x| x as f32)
        .collect();
    let expr = rows(
        field(&arrays, "expr").map_err(label)?,
        "expr",
        EXPRESSION_PARAMS,
    )
    .map_err(label)?;
    let frames = expr.len();
    let three = |n: &str| -> Result<Vec<Vec<f32>>, String> {
        let r = rows(field(&arrays, n)?, n, 3)?;
        if r.len() != frames {
            return Err(format!("'{n}' has {} frames, 'expr' has {frames}", r.len()));
        }
        Ok(r)
    };
    let rotation = three("rotation").map_err(label)?;
    let neck = three("neck_pose").map_err(label)?;
    let jaw = three("jaw_pose").map_err(label)?;
    let translation = three("translation").map_err(label)?;
    let eyes = rows(field(&arrays, "eyes_pose").map_err(label)?, "eyes_pose", 6).map_err(label)?;
    if eyes.len() != frames {
        return Err(label(format!(
            "'eyes_pose' has {} frames, 'expr' has {frames}",
            eyes.len()
        ))
        .into());
    }
    let v = model.file_vertex_count();
    let offsets = match arrays.get("dynamic_offset") {
        Some(d) => read_dynamic_offset(d, frames, v, model.mouth_cavity.as_ref()).map_err(label)?,
        None => Vec::new(),
    };
    let static_offset = match arrays.get("static_offset") {
        None => vec![DVec3::ZERO; v],
        Some(a) => {
            if a.data.iter().any(|x| !x.is_finite()) {
                return Err(label("'static_offset' has NaN or infinite values".into()).into());
            }
            let n = a.data.len() / 3;
            let fits = a.shape.len() == 3 && a.shape[0] == 1 && a.shape[2] == 3;
            if !fits || !(n == v || n + super::flame::TEETH_VERTICES == v) {
                return Err(label(format!(
                    "'static_offset' has shape {:?}, expected (1, {v}, 3)",
                    a.shape
                ))
                .into());
            }
            let mut o: Vec<DVec3> = a
                .data
                .chunks(3)
                .map(|c| DVec3::new(c[0], c[1], c[2]))
                .collect();
            o.resize(v, DVec3::ZERO);
            o
        }
    };
    let mut static_offset = static_offset;
    if let Some(c) = &model.mouth_cavity {
        c.extend_offsets(&mut static_offset);
    }
    let e_len = model.expression_basis.len();
    let v3 = |r: &[f32]| Vec3::new(r[0], r[1], r[2]);
    let poses = (0..frames)
        .map(|t| {
            let mut joints = [Vec3::ZERO; JOINT_COUNT];
            joints[0] = v3(&rotation[t]);
            joints[1] = v3(&neck[t]);
            joints[2] = v3(&jaw[t]);
            joints[3] = v3(&eyes[t][..3]);
            joints[4] = v3(&eyes[t][3..]);
            Pose {
                joints,
                translation: v3(&translation[t]),
            }
        })
        .collect();
    let expression = expr.into_iter().map(|mut r| {
        r.truncate(e_len);
        r
    });
    let motion = Motion {
        name: name.to_string(),
        fps: 25.0,
        expression: expression.collect(),
        poses,
        offsets,
    };
    if motion.frames() == 0 {
        return Err(label("'expr' has no frames".into()).into());
    }
    Ok(FlameParams {
        shape: shape_coeffs,
        static_offset,
        motion,
    })
}

/// Reads a `dynamic_offset` of shape (T, V, 3) or (1, V, 3) (one row for
/// every frame; V with or without the teeth) as per-frame vertex offsets
/// for a model of `model_vertices`: none when it is all zero (as every
/// GaussianAvatars run and VHAP's default tracking leave it), otherwise one
/// row per frame, the teeth padded with zeros and a mouth cavity following
/// its anchors as it does for the static offset.
fn read_dynamic_offset(
    a: &NdArray,
    frames: usize,
    vertices: usize,
    cavity: Option<&crate::model::cavity::MouthCavity>,
) -> Result<Vec<Vec<Vec3>>, String> {
    let n = a.shape.get(1).copied().unwrap_or(0);
    let fits = a.shape.len() == 3
        && a.shape[2] == 3
        && (n == vertices || n + super::flame::TEETH_VERTICES == vertices)
        && (a.shape[0] == frames || a.shape[0] == 1);
    if !fits {
        return Err(format!(
            "'dynamic_offset' has shape {:?}, expected ({frames}, {vertices}, 3)",
            a.shape
        ));
    }
    if let Some(i) = a.data.iter().position(|x| !x.is_finite()) {
        return Err(format!(
            "'dynamic_offset' has NaN or infinite values (frame {}, vertex {})",
            i / (3 * n),
            i / 3 % n
        ));
    }
    if a.data.iter().all(|&x| x == 0.0) {
        return Ok(Vec::new());
    }
    let rows = a.data.chunks(3 * n).map(|row| {
        let mut offsets: Vec<Vec3> = row
            .chunks(3)
            .map(|c| Vec3::new(c[0] as f32, c[1] as f32, c[2] as f32))
            .collect();
        offsets.resize(vertices, Vec3::ZERO);
        if let Some(c) = cavity {
            c.extend_field(&mut offsets);
        }
        offsets
    });
    let rows: Vec<Vec<Vec3>> = rows.collect();
    if rows.len() == frames {
        return Ok(rows);
    }
    // One row for every frame.
    Ok(vec![rows[0].clone(); frames])
}

/// One frame of the parameters GaussianAvatars stores.
pub struct FrameParams {
    /// Expression coefficients (padded to 100 on write).
    pub expression: Vec<f32>,
    /// Joint poses and translation.
    pub pose: Pose,
    /// The frame's vertex offsets (`dynamic_offset`; empty: zero).
    pub offset: Vec<Vec3>,
}

/// What an avatar folder stores besides its Gaussians.
#[derive(Clone, Copy)]
pub struct AvatarParams<'a> {
    /// Shape coefficients (padded to 300).
    pub shape: &'a [f32],
    /// Static per-vertex offset (written as float32, see [`stored_offset`]).
    pub static_offset: &'a [DVec3],
    /// Per-frame expression and pose.
    pub frames: &'a [FrameParams],
}

/// The float32 static offset that reproduces `neutral` from `template` the way
/// a loaded avatar computes its neutral (`template + offset` summed in f64,
/// then rounded to f32; see `HeadModel::neutral`): the f32 nearest to the
/// difference, or a neighbour of it when that one rounds back to `neutral`
/// and the nearest does not. Where no f32 offset reproduces a coordinate
/// exactly the nearest is kept (an error of at most one f32 step).
pub fn stored_offset(template: f32, neutral: f32) -> f32 {
    let reproduces = |o: f32| (template as f64 + o as f64) as f32 == neutral;
    let nearest = (neutral as f64 - template as f64) as f32;
    [nearest, next_f32(nearest, 1), next_f32(nearest, -1)]
        .into_iter()
        .find(|&o| reproduces(o))
        .unwrap_or(nearest)
}

/// The neighbouring f32 above (`step` 1) or below (-1) a finite `x`.
fn next_f32(x: f32, step: i32) -> f32 {
    if x == 0.0 {
        return f32::from_bits(1) * step as f32;
    }
    let up = (x > 0.0) == (step > 0);
    let bits = x.to_bits();
    f32::from_bits(if up { bits + 1 } else { bits - 1 })
}

/// The static offsets an export stores for a composite whose blended neutral is
/// `neutral` (the shape coefficients are zero, the blend lives in the offset).
pub fn neutral_offset(template: &[Vec3], neutral: &[Vec3]) -> Vec<DVec3> {
    template
        .iter()
        .zip(neutral)
        .map(|(t, n)| {
            DVec3::new(
                stored_offset(t.x, n.x) as f64,
                stored_offset(t.y, n.y) as f64,
                stored_offset(t.z, n.z) as f64,
            )
        })
        .collect()
}

/// The neutral mesh an avatar exported with `neutral` has once loaded back:
/// `template + stored offset`, as `HeadModel::neutral` sums it. Composite
/// hashes are taken on this, so a composite and its reloaded export agree.
pub fn neutral_as_stored(template: &[Vec3], neutral: &[Vec3]) -> Vec<Vec3> {
    template
        .iter()
        .zip(neutral_offset(template, neutral))
        .map(|(t, o)| (t.as_dvec3() + o).as_vec3())
        .collect()
}

/// Writes a GaussianAvatars avatar folder for `model`. What only visage's
/// model has stays behind: Gaussians bound to an added mouth cavity are rebound
/// to the nearest triangle the file can name (in place on the avatar's neutral
/// mesh), and offsets stop at the file's vertices.
pub fn write_avatar(
    dir: &Path,
    gaussians: &GaussianSet,
    params: &AvatarParams,
    model: &HeadModel,
) -> super::Result<()> {
    std::fs::create_dir_all(dir).map_err(|e| super::FileError::access("create", dir, e))?;
    let (keep, vertices) = (model.file_triangle_count(), model.file_vertex_count());
    let rebound;
    let gaussians = if gaussians.binding.iter().any(|&b| b as usize >= keep) {
        let neutral = model.neutral(params.shape, Some(params.static_offset));
        rebound = rebind_past(gaussians, &neutral, &model.triangles, keep);
        &rebound
    } else {
        gaussians
    };
    write_bound_ply(&dir.join("point_cloud.ply"), gaussians)?;
    let offset = &params.static_offset[..params.static_offset.len().min(vertices)];
    write_flame_params(
        &dir.join("flame_param.npz"),
        &AvatarParams {
            static_offset: offset,
            ..*params
        },
    )
}

/// Writes FLAME parameters as GaussianAvatars stores them: shape (300),
/// expr (T, 100), rotation / neck_pose / jaw_pose / translation (T, 3),
/// eyes_pose (T, 6), static_offset (1, V, 3), dynamic_offset (T, V, 3)
/// (each frame's offsets for the file's V vertices, zero where it has none).
pub fn write_flame_params(path: &Path, params: &AvatarParams) -> super::Result<()> {
    let frames = params.frames;
    let t = frames.len().max(1);
    let mut expr = vec![0.0f32; t * EXPRESSION_PARAMS];
    let (mut rotation, mut neck, mut jaw, mut eyes, mut translation) =
        (Vec::new(), Vec::new(), Vec::new(), Vec::new(), Vec::new());
    for (k, f) in frames.iter().enumerate() {
        for (j, e) in f.expression.iter().take(EXPRESSION_PARAMS).enumerate() {
            expr[k * EXPRESSION_PARAMS + j] = *e;
        }
        let j = &f.pose.joints;
        rotation.extend(j[0].to_array());
        neck.extend(j[1].to_array());
        jaw.extend(j[2].to_array());
        eyes.extend(j[3].to_array());
        eyes.extend(j[4].to_array());
        translation.extend(f.pose.translation.to_array());
    }
    if frames.is_empty() {
        rotation = vec![0.0; 3];
        neck = vec![0.0; 3];
        jaw = vec![0.0; 3];
        eyes = vec![0.0; 6];
        translation = vec![0.0; 3];
    }
    let offset: Vec<f32> = params
        .static_offset
        .iter()
        .flat_map(|o| o.as_vec3().to_array())
        .collect();
    let v = params.static_offset.len();
    // GaussianAvatars' loader indexes dynamic_offset[[t]] for every frame t;
    // it is zero in every avatar it trains (deflate makes it small on disk).
    let mut dynamic_offset = vec![0.0f32; t * v * 3];
    for (row, f) in dynamic_offset.chunks_mut(v.max(1) * 3).zip(frames) {
        for (out, o) in row.chunks_mut(3).zip(&f.offset) {
            out.copy_from_slice(&o.to_array());
        }
    }
    let mut shape = vec![0.0f32; SHAPE_PARAMS];
    for (s, x) in shape.iter_mut().zip(params.shape) {
        *s = *x;
    }
    let arrays = [
        ("shape", write_npy(&[SHAPE_PARAMS], NpyData::F32(&shape))),
        (
            "expr",
            write_npy(&[t, EXPRESSION_PARAMS], NpyData::F32(&expr)),
        ),
        ("rotation", write_npy(&[t, 3], NpyData::F32(&rotation))),
        ("neck_pose", write_npy(&[t, 3], NpyData::F32(&neck))),
        ("jaw_pose", write_npy(&[t, 3], NpyData::F32(&jaw))),
        ("eyes_pose", write_npy(&[t, 6], NpyData::F32(&eyes))),
        (
            "translation",
            write_npy(&[t, 3], NpyData::F32(&translation)),
        ),
        (
            "static_offset",
            write_npy(&[1, v, 3], NpyData::F32(&offset)),
        ),
        (
            "dynamic_offset",
            write_npy(&[t, v, 3], NpyData::F32(&dynamic_offset)),
        ),
    ];
    let named: Vec<(&str, Vec<u8>)> = arrays.into_iter().collect();
    write_npz(path, &named, true)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn offsets(shape: [usize; 3], value: impl Fn(usize) -> f64) -> NdArray {
        NdArray {
            shape: shape.to_vec(),
            dtype: crate::io::pickle::Dtype::F32,
            data: (0..shape.iter().product()).map(value).collect(),
        }
    }

    /// Per-frame offsets: zero is none, one row serves every frame, rows
    /// without the teeth are padded, and bad shapes and NaN are refused.
    #[test]
    fn dynamic_offsets_read_per_frame() {
        let teeth = crate::io::flame::TEETH_VERTICES;
        let v = teeth + 4;
        let none = read_dynamic_offset(&offsets([3, v, 3], |_| 0.0), 3, v, None).unwrap();
        assert!(none.is_empty());
        let one = read_dynamic_offset(&offsets([1, v, 3], |i| i as f64), 3, v, None).unwrap();
        assert_eq!(one.len(), 3);
        assert!(one.iter().all(|row| row == &one[0]));
        assert_eq!(one[0][1], Vec3::new(3.0, 4.0, 5.0));
        let short = read_dynamic_offset(&offsets([2, 4, 3], |i| i as f64), 2, v, None).unwrap();
        assert_eq!(short[1].len(), v);
        assert_eq!(short[1][0], Vec3::new(12.0, 13.0, 14.0));
        assert_eq!(short[1][v - 1], Vec3::ZERO);
        let e = read_dynamic_offset(&offsets([2, v, 3], |_| 1.0), 3, v, None).unwrap_err();
        assert!(e.contains("expected (3,"), "{e}");
        let nan = offsets([2, v, 3], |i| if i == 3 * v + 4 { f64::NAN } else { 0.0 });
        let e = read_dynamic_offset(&nan, 2, v, None).unwrap_err();
        assert!(e.contains("NaN") && e.contains("frame 1, vertex 1"), "{e}");
    }

    /// One f32 step of `x`.
    fn step(x: f32) -> f32 {
        (next_f32(x.abs(), 1) - x.abs()).max(f32::from_bits(1))
    }

    /// Head-sized coordinates and offsets: the stored offsets are float32
    /// values, almost every neutral comes back bit for bit and none is more
    /// than one f32 step off (f32 cannot always reach it from the template).
    #[test]
    fn stored_offsets_reproduce_head_sized_neutrals() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let (mut exact, total) = (0, 100_000);
        for _ in 0..total {
            let t = rng.random_range(-0.3f32..0.3);
            let n = t + rng.random_range(-0.03f32..0.03);
            let o = neutral_offset(&[Vec3::splat(t)], &[Vec3::splat(n)])[0];
            assert_eq!(o.as_vec3().as_dvec3(), o, "the offsets are float32 values");
            let back = (t as f64 + o.x) as f32;
            assert!((back - n).abs() <= step(n), "template {t:e}, neutral {n:e}");
            exact += (back == n) as usize;
        }
        assert!(exact * 1000 >= total * 995, "{exact} of {total} exact");
    }

    /// Storing is idempotent: what a loaded export stores again is what it
    /// already had — the property that keeps composite hashes equal across an
    /// export and reload — including coordinates that cross zero, tiny and
    /// huge magnitudes and values f32 cannot reach from the template.
    #[test]
    fn storing_a_stored_neutral_changes_nothing() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        for k in 0..200_000 {
            let magnitude = |rng: &mut rand_chacha::ChaCha8Rng| 10f32.powi(rng.random_range(-9..4));
            let t = rng.random_range(-1.0f32..1.0) * magnitude(&mut rng);
            let n = match k % 3 {
                0 => t + rng.random_range(-1.0f32..1.0) * magnitude(&mut rng),
                1 => -t * rng.random_range(0.0f32..2.0),
                _ => rng.random_range(-1.0f32..1.0) * magnitude(&mut rng),
            };
            let once = neutral_as_stored(&[Vec3::splat(t)], &[Vec3::splat(n)])[0].x;
            let twice = neutral_as_stored(&[Vec3::splat(t)], &[Vec3::splat(once)])[0].x;
            assert_eq!(
                once.to_bits(),
                twice.to_bits(),
                "template {t:e}, neutral {n:e}"
            );
            // Off by at most the rounding of the offset (one step of the larger).
            assert!(
                (once - n).abs() <= step(t.abs().max(n.abs())),
                "template {t:e}, neutral {n:e}"
            );
        }
    }
}
