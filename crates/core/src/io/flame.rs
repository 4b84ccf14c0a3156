//! The user's FLAME model (`flame2023.pkl` or `generic_model.pkl`) and masks
//! (`FLAME_masks.pkl`) → a [`HeadModel`] with GaussianAvatars' teeth appended,
//! a mouth cavity after them when the lips' rim is open (`model::cavity`; files
//! never see it), and the 18 regions derived from the masks.
//!
//! **Teeth** (so real GaussianAvatars bindings line up): 120 vertices and 168
//! triangles after the FLAME mesh (5023 → 5143 vertices, 9976 → 10144 triangles),
//! built from the two 15-vertex outer lip rings exactly as GaussianAvatars does:
//! with d = mean distance between the rings, the middle row sits halfway between
//! them at their mean height and 1.5 d behind; edges are ±0.1 d from it (the lower
//! row also 0.4 d further back), roots 2 d above/below the edges, a back copy of
//! both rows d behind. Vertex order: upper root, lower root, upper edge, lower
//! edge, upper root back, upper edge back, lower root back, lower edge back (15
//! each). Each tooth row is three strips of 14 quads (front, back, bottom), each
//! quad two triangles whose diagonal mirrors at the midline. Teeth copy the mean
//! shape directions of the two lip rings (shape components only), have no
//! expression, pose correctives or joint-regressor weight, and are skinned fully
//! to the neck (upper) and jaw (lower).
//!
//! **Regions** — a triangle is in a mask when at least two of its vertices are
//! (all three for eyeballs); the first rule that matches wins:
//! teeth → teeth_upper / teeth_lower; cavity → lips_inside; left/right_eyeball; left/right_ear;
//! lips → lips_inside when its centroid lies behind the outer lip rings by more
//! than 0.3 d, else lips; nose; left/right_eye_region; boundary; neck;
//! scalp → hair; face or forehead → skin; an unassigned triangle within two
//! eyeball radii of an eyeball centre → that side's eye_socket; anything else →
//! remainder.

use std::collections::HashSet;
use std::path::Path;

use glam::Vec3;

use super::pickle::{self, NdArray, Value};
use crate::model::head::{Basis, HeadModel, RegressorRow, JOINT_COUNT};
use crate::model::open_mouth::with_mouth_cavity;
use crate::model::regions::Region;

/// Outer lip ring vertex ids of FLAME's topology (upper, lower; left to right),
/// the rings GaussianAvatars builds its teeth from.
pub const FLAME_LIP_RING_UPPER: [u32; 15] = [
    1713, 1715, 1716, 1735, 1696, 1694, 1657, 3543, 2774, 2811, 2813, 2850, 2833, 2832, 2830,
];
/// Lower outer lip ring of FLAME's topology.
pub const FLAME_LIP_RING_LOWER: [u32; 15] = [
    1576, 1577, 1773, 1774, 1795, 1802, 1865, 3503, 2948, 2905, 2898, 2881, 2880, 2713, 2712,
];
/// FLAME's vertex count without teeth.
pub const FLAME_VERTICES: usize = 5023;
/// Vertices the teeth add.
pub const TEETH_VERTICES: usize = 120;
/// Triangles the teeth add.
pub const TEETH_TRIANGLES: usize = 168;
/// Shape components FLAME files carry before the expression components.
pub const FLAME_SHAPE_COMPONENTS: usize = 300;

fn array(dict: &Value, key: &str, file: &str) -> Result<NdArray, String> {
    dict.get(key)
        .ok_or_else(|| format!("{file} has no '{key}'"))?
        .as_array()
        .map_err(|e| format!("{file} '{key}': {e}"))
}

fn check_shape(a: &NdArray, want: &[Option<usize>], what: &str) -> Result<(), String> {
    let ok = a.shape.len() == want.len()
        && a.shape
            .iter()
            .zip(want)
            .all(|(s, w)| w.is_none_or(|w| *s == w));
    if !ok {
        let want: Vec<String> = want
            .iter()
            .map(|w| w.map_or("N".to_string(), |w| w.to_string()))
            .collect();
        return Err(format!(
            "{what} has shape {:?}, expected ({})",
            a.shape,
            want.join(", ")
        ));
    }
    if a.data.iter().any(|x| !x.is_finite()) {
        return Err(format!("{what} has NaN or infinite values"));
    }
    Ok(())
}

fn index(x: f64, limit: usize, what: &str) -> Result<u32, String> {
    if x >= 0.0 && x.fract() == 0.0 && (x as usize) < limit {
        Ok(x as u32)
    } else {
        Err(format!(
            "{what} refers to vertex {}, but there are {limit}",
            crate::text::id_text(x)
        ))
    }
}

/// Vertex masks by name (FLAME_masks.pkl layout: name → vertex indices).
pub type Masks = Vec<(String, Vec<u32>)>;

/// Reads a masks pickle.
pub fn read_masks(path: &Path, vertices: usize) -> super::Result<Masks> {
    let file = path.display().to_string();
    let value = pickle::read(path)?;
    let Value::Dict(items) = value else {
        return Err(format!("{file} is not a dict of vertex masks").into());
    };
    let mut out = Vec::new();
    for (k, v) in items {
        let Value::Str(name) = k else { continue };
        let a = v
            .as_array()
            .map_err(|e| format!("{file} mask '{}': {e}", crate::text::printable(&name)))?;
        let ids = a
            .data
            .iter()
            .map(|&x| {
                index(
                    x,
                    vertices,
                    &format!("{file} mask '{}'", crate::text::printable(&name)),
                )
            })
            .collect::<Result<Vec<_>, _>>()?;
        out.push((name, ids));
    }
    Ok(out)
}

fn mask<'a>(masks: &'a Masks, name: &str) -> Option<&'a [u32]> {
    masks
        .iter()
        .find(|(n, _)| n == name)
        .map(|(_, v)| v.as_slice())
}

/// Loads a FLAME model and masks and builds the head model (teeth appended).
pub fn load_flame(model_path: &Path, masks_path: &Path) -> super::Result<HeadModel> {
    let file = model_path.display().to_string();
    let dict = pickle::read(model_path)?;
    let template = array(&dict, "v_template", &file)?;
    check_shape(&template, &[None, Some(3)], &format!("{file} 'v_template'"))?;
    let n = template.shape[0];
    let faces = array(&dict, "f", &file)?;
    check_shape(&faces, &[None, Some(3)], &format!("{file} 'f'"))?;
    let shapedirs = array(&dict, "shapedirs", &file)?;
    check_shape(
        &shapedirs,
        &[Some(n), Some(3), None],
        &format!("{file} 'shapedirs'"),
    )?;
    let weights = array(&dict, "weights", &file)?;
    check_shape(
        &weights,
        &[Some(n), Some(JOINT_COUNT)],
        &format!("{file} 'weights'"),
    )?;
    let regressor = array(&dict, "J_regressor", &file)?;
    check_shape(
        &regressor,
        &[Some(JOINT_COUNT), Some(n)],
        &format!("{file} 'J_regressor'"),
    )?;
    let kintree = array(&dict, "kintree_table", &file)?;
    if kintree.shape != [2, JOINT_COUNT] || kintree.data[1..JOINT_COUNT] != [0.0, 1.0, 1.0, 1.0] {
        return Err(format!(
            "{file} 'kintree_table' is not FLAME's skeleton (global, neck, jaw, eyes)"
        )
        .into());
    }
    let posedirs = match dict.get("posedirs") {
        Some(v) => {
            let p = v
                .as_array()
                .map_err(|e| format!("{file} 'posedirs': {e}"))?;
            check_shape(
                &p,
                &[Some(n), Some(3), Some((JOINT_COUNT - 1) * 9)],
                &format!("{file} 'posedirs'"),
            )?;
            Some(p)
        }
        None => None,
    };
    let masks = read_masks(masks_path, n)?;

    let vertex = |i: usize| {
        Vec3::new(
            template.data[3 * i] as f32,
            template.data[3 * i + 1] as f32,
            template.data[3 * i + 2] as f32,
        )
    };
    let mut positions: Vec<Vec3> = (0..n).map(vertex).collect();
    let mut triangles: Vec<[u32; 3]> = faces
        .data
        .chunks(3)
        .map(|f| {
            Ok([
                index(f[0], n, &file)?,
                index(f[1], n, &file)?,
                index(f[2], n, &file)?,
            ])
        })
        .collect::<Result<_, String>>()?;
    let flame_triangles = triangles.len();

    let (ring_up, ring_lo) = lip_rings(&masks, n)?;
    let teeth = build_teeth(&positions, &ring_up, &ring_lo);
    positions.extend(&teeth.positions);
    triangles.extend(teeth.triangles.iter().map(|t| t.map(|i| i + n as u32)));
    let total = positions.len();

    let components = shapedirs.shape[2];
    let shape_count = components.min(FLAME_SHAPE_COMPONENTS);
    let field = |k: usize, teeth_value: &dyn Fn(usize) -> Vec3| -> Vec<Vec3> {
        let mut f: Vec<Vec3> = (0..n)
            .map(|v| {
                let at = |c: usize| shapedirs.data[(v * 3 + c) * components + k] as f32;
                Vec3::new(at(0), at(1), at(2))
            })
            .collect();
        f.extend((0..TEETH_VERTICES).map(teeth_value));
        f
    };
    let mut shape_basis = Basis::new(total);
    for k in 0..shape_count {
        let lip_mean = |j: usize| {
            let at = |v: u32| {
                let b = (v as usize * 3) * components + k;
                Vec3::new(
                    shapedirs.data[b] as f32,
                    shapedirs.data[b + components] as f32,
                    shapedirs.data[b + 2 * components] as f32,
                )
            };
            let j = j % 15;
            0.5 * (at(ring_up[j]) + at(ring_lo[j]))
        };
        shape_basis.push(format!("shape{k:03}"), field(k, &lip_mean));
    }
    let mut expression_basis = Basis::new(total);
    for k in shape_count..components {
        expression_basis.push(
            format!("expression{:03}", k - shape_count),
            field(k, &|_| Vec3::ZERO),
        );
    }
    let pose_correctives = posedirs.map(|p| {
        let mut b = Basis::new(total);
        for k in 0..(JOINT_COUNT - 1) * 9 {
            let mut f: Vec<Vec3> = (0..n)
                .map(|v| {
                    let at = |c: usize| p.data[(v * 3 + c) * 36 + k] as f32;
                    Vec3::new(at(0), at(1), at(2))
                })
                .collect();
            f.resize(total, Vec3::ZERO);
            b.push(format!("pose{k:02}"), f);
        }
        b
    });
    let joint_regressor: [RegressorRow; JOINT_COUNT] = std::array::from_fn(|j| {
        (0..n)
            .filter_map(|v| {
                let w = regressor.data[j * n + v];
                (w != 0.0).then_some((v as u32, w as f32))
            })
            .collect()
    });
    let mut skin_weights: Vec<[f32; JOINT_COUNT]> = (0..n)
        .map(|v| std::array::from_fn(|j| weights.data[v * JOINT_COUNT + j] as f32))
        .collect();
    for t in 0..TEETH_VERTICES {
        let upper = teeth.upper[t];
        let mut w = [0.0; JOINT_COUNT];
        w[if upper { 1 } else { 2 }] = 1.0;
        skin_weights.push(w);
    }
    let triangle_regions = assign_regions(
        &positions,
        &triangles,
        flame_triangles,
        &masks,
        &ring_up,
        &ring_lo,
    )?;
    let lips: HashSet<u32> = mask(&masks, "lips")
        .map(|m| m.iter().copied().collect())
        .unwrap_or_default();
    let head = HeadModel {
        template: positions,
        triangles,
        triangle_regions,
        shape_basis,
        expression_basis,
        joint_regressor,
        skin_weights,
        pose_correctives,
        mouth_cavity: None,
    };
    // FLAME's lips end at an open rim: hang a cavity from it.
    Ok(with_mouth_cavity(head, |v| {
        (v as usize) < n && lips.contains(&v)
    }))
}

/// The outer lip rings: from the masks file when it has them, else FLAME's ids.
fn lip_rings(masks: &Masks, vertices: usize) -> Result<(Vec<u32>, Vec<u32>), String> {
    match (mask(masks, "lip_outside_ring_upper"), mask(masks, "lip_outside_ring_lower")) {
        (Some(u), Some(l)) if u.len() == 15 && l.len() == 15 => Ok((u.to_vec(), l.to_vec())),
        (Some(_), Some(_)) => Err("the lip_outside_ring masks must have 15 vertices each".into()),
        _ if vertices == FLAME_VERTICES => Ok((FLAME_LIP_RING_UPPER.to_vec(), FLAME_LIP_RING_LOWER.to_vec())),
        _ => Err(format!(
            "cannot place the teeth: the masks have no lip_outside_ring_upper/lower and the model has {vertices} vertices, not FLAME's {FLAME_VERTICES}"
        )),
    }
}

/// Teeth geometry in model-local indices (0..120).
pub struct Teeth {
    /// Vertex positions.
    pub positions: Vec<Vec3>,
    /// Triangles (upper row first).
    pub triangles: Vec<[u32; 3]>,
    /// Whether each vertex belongs to the upper row.
    pub upper: Vec<bool>,
}

/// One quad strip of 14 quads between rows `a` and `b` (15 vertices each).
/// `reversed` flips the winding; `swapped` exchanges the diagonals of the two halves.
fn strip(a: u32, b: u32, reversed: bool, swapped: bool) -> Vec<[u32; 3]> {
    let mut out = Vec::with_capacity(28);
    for j in 0..14u32 {
        let (a0, a1, b0, b1) = (a + j, a + j + 1, b + j, b + j + 1);
        let left = (j < 7) != swapped;
        let pair = if left {
            [[a0, b1, b0], [a0, a1, b1]]
        } else {
            [[a0, a1, b0], [a1, b1, b0]]
        };
        for t in pair {
            out.push(if reversed { [t[0], t[2], t[1]] } else { t });
        }
    }
    out
}

/// Builds GaussianAvatars' teeth from the outer lip rings (see the module docs).
pub fn build_teeth(positions: &[Vec3], ring_up: &[u32], ring_lo: &[u32]) -> Teeth {
    let up: Vec<Vec3> = ring_up.iter().map(|&i| positions[i as usize]).collect();
    let lo: Vec<Vec3> = ring_lo.iter().map(|&i| positions[i as usize]).collect();
    let d = up
        .iter()
        .zip(&lo)
        .map(|(a, b)| (*a - *b).length())
        .sum::<f32>()
        / up.len() as f32;
    let mut middle: Vec<Vec3> = up.iter().zip(&lo).map(|(a, b)| 0.5 * (*a + *b)).collect();
    let mean_y = middle.iter().map(|m| m.y).sum::<f32>() / middle.len() as f32;
    for m in &mut middle {
        m.y = mean_y;
        m.z -= d * 1.5;
    }
    let y = Vec3::new(0.0, d, 0.0);
    let z = Vec3::new(0.0, 0.0, d);
    let upper_edge: Vec<Vec3> = middle.iter().map(|m| *m + 0.1 * y).collect();
    let upper_root: Vec<Vec3> = upper_edge.iter().map(|e| *e + 2.0 * y).collect();
    let lower_edge: Vec<Vec3> = middle.iter().map(|m| *m - 0.1 * y - 0.4 * z).collect();
    let lower_root: Vec<Vec3> = lower_edge.iter().map(|e| *e - 2.0 * y).collect();
    let back = |row: &[Vec3]| -> Vec<Vec3> { row.iter().map(|p| *p - z).collect() };
    let rows = [
        (upper_root.clone(), true),
        (lower_root.clone(), false),
        (upper_edge.clone(), true),
        (lower_edge.clone(), false),
        (back(&upper_root), true),
        (back(&upper_edge), true),
        (back(&lower_root), false),
        (back(&lower_edge), false),
    ];
    let mut positions = Vec::with_capacity(TEETH_VERTICES);
    let mut upper = Vec::with_capacity(TEETH_VERTICES);
    for (row, is_upper) in &rows {
        positions.extend(row);
        upper.extend(std::iter::repeat_n(*is_upper, row.len()));
    }
    // Row starts: upper root 0, lower root 15, upper edge 30, lower edge 45,
    // upper root back 60, upper edge back 75, lower root back 90, lower edge back 105.
    let mut triangles = Vec::with_capacity(TEETH_TRIANGLES);
    triangles.extend(strip(0, 30, false, false)); // upper front
    triangles.extend(strip(60, 75, true, false)); // upper back
    triangles.extend(strip(75, 30, true, true)); // upper bottom
    triangles.extend(strip(45, 15, false, true)); // lower front
    triangles.extend(strip(90, 105, false, false)); // lower back
    triangles.extend(strip(105, 45, false, true)); // lower bottom
    Teeth {
        positions,
        triangles,
        upper,
    }
}

fn assign_regions(
    positions: &[Vec3],
    triangles: &[[u32; 3]],
    flame_triangles: usize,
    masks: &Masks,
    ring_up: &[u32],
    ring_lo: &[u32],
) -> Result<Vec<Region>, String> {
    let set = |name: &str| -> HashSet<u32> {
        mask(masks, name)
            .map(|m| m.iter().copied().collect())
            .unwrap_or_default()
    };
    let sets: Vec<(&str, HashSet<u32>)> = [
        "left_eyeball",
        "right_eyeball",
        "left_ear",
        "right_ear",
        "lips",
        "nose",
        "left_eye_region",
        "right_eye_region",
        "boundary",
        "neck",
        "scalp",
        "face",
        "forehead",
    ]
    .iter()
    .map(|n| (*n, set(n)))
    .collect();
    let get = |n: &str| &sets.iter().find(|(k, _)| *k == n).expect("listed").1;
    let count = |t: &[u32; 3], n: &str| t.iter().filter(|v| get(n).contains(v)).count();
    let ring: Vec<Vec3> = ring_up
        .iter()
        .chain(ring_lo)
        .map(|&i| positions[i as usize])
        .collect();
    let ring_z = ring.iter().map(|p| p.z).sum::<f32>() / ring.len() as f32;
    let d = ring_up
        .iter()
        .zip(ring_lo)
        .map(|(a, b)| (positions[*a as usize] - positions[*b as usize]).length())
        .sum::<f32>()
        / 15.0;
    let centre = |n: &str| -> Option<(Vec3, f32)> {
        let s = get(n);
        if s.is_empty() {
            return None;
        }
        let c = s.iter().map(|&v| positions[v as usize]).sum::<Vec3>() / s.len() as f32;
        let r = s
            .iter()
            .map(|&v| (positions[v as usize] - c).length())
            .sum::<f32>()
            / s.len() as f32;
        Some((c, r))
    };
    let eyes = [
        (centre("left_eyeball"), Region::LeftEyeSocket),
        (centre("right_eyeball"), Region::RightEyeSocket),
    ];
    let mut out = Vec::with_capacity(triangles.len());
    for (k, t) in triangles.iter().enumerate() {
        if k >= flame_triangles {
            out.push(if k - flame_triangles < TEETH_TRIANGLES / 2 {
                Region::TeethUpper
            } else {
                Region::TeethLower
            });
            continue;
        }
        let c = t.iter().map(|&i| positions[i as usize]).sum::<Vec3>() / 3.0;
        let major = |n: &str| count(t, n) >= 2;
        let region = if count(t, "left_eyeball") == 3 {
            Region::LeftEyeball
        } else if count(t, "right_eyeball") == 3 {
            Region::RightEyeball
        } else if major("left_ear") {
            Region::LeftEar
        } else if major("right_ear") {
            Region::RightEar
        } else if major("lips") {
            if c.z < ring_z - 0.3 * d {
                Region::LipsInside
            } else {
                Region::Lips
            }
        } else if major("nose") {
            Region::Nose
        } else if major("left_eye_region") {
            Region::LeftEyeRegion
        } else if major("right_eye_region") {
            Region::RightEyeRegion
        } else if major("boundary") {
            Region::Boundary
        } else if major("neck") {
            Region::Neck
        } else if major("scalp") {
            Region::Hair
        } else if major("face") || major("forehead") {
            Region::Skin
        } else {
            eyes.iter()
                .filter_map(|(e, r)| e.map(|(ec, er)| ((c - ec).length() / er.max(1e-9), *r)))
                .filter(|(dist, _)| *dist < 2.0)
                .min_by(|a, b| a.0.total_cmp(&b.0))
                .map_or(Region::Remainder, |(_, r)| r)
        };
        out.push(region);
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Writes a tiny FLAME-layout model (3 vertices, one triangle) with `edit`
    /// applied to its entries, loads it, and returns the error.
    fn load_error(
        edit: impl Fn(&mut Vec<(&'static str, crate::io::pickle_write::PyObj<'static>)>),
    ) -> String {
        use crate::io::pickle_write::{to_pickle, PyObj};
        static TEMPLATE: [f64; 9] = [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0];
        static FACES: [u32; 3] = [0, 1, 2];
        static SHAPEDIRS: [f32; 9] = [0.0; 9];
        static WEIGHTS: [f64; 15] = [
            1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0,
        ];
        static KINTREE: [i64; 10] = [4_294_967_295, 0, 1, 1, 1, 0, 1, 2, 3, 4];
        static DATA: [f64; 0] = [];
        static INDICES: [i32; 0] = [];
        static INDPTR: [i32; 4] = [0, 0, 0, 0];
        let mut entries = vec![
            ("v_template", PyObj::F64(vec![3, 3], &TEMPLATE)),
            ("f", PyObj::U32(vec![1, 3], &FACES)),
            ("shapedirs", PyObj::F32(vec![3, 3, 1], &SHAPEDIRS)),
            ("weights", PyObj::F64(vec![3, 5], &WEIGHTS)),
            ("J_regressor", PyObj::Csc((5, 3), &DATA, &INDICES, &INDPTR)),
            ("kintree_table", PyObj::I64(vec![2, 5], &KINTREE)),
        ];
        edit(&mut entries);
        let bytes = to_pickle(&PyObj::Dict(entries));
        let dir = std::env::temp_dir().join(format!(
            "visage-flame-{}-{}",
            std::process::id(),
            blake3::hash(&bytes).to_hex()
        ));
        std::fs::create_dir_all(&dir).unwrap();
        let model = dir.join("model.pkl");
        std::fs::write(&model, bytes).unwrap();
        let masks = dir.join("masks.pkl");
        std::fs::write(&masks, to_pickle(&PyObj::Dict(vec![]))).unwrap();
        let Err(e) = load_flame(&model, &masks) else {
            panic!("the model must be refused")
        };
        std::fs::remove_dir_all(&dir).ok();
        e.to_string()
    }

    #[test]
    fn broken_models_are_refused_with_the_key_named() {
        let e = load_error(|m| m.retain(|(k, _)| *k != "shapedirs"));
        assert!(e.contains("has no 'shapedirs'"), "{e}");
        static FLAT: [f64; 6] = [0.0; 6];
        let e = load_error(|m| m[0].1 = crate::io::pickle_write::PyObj::F64(vec![3, 2], &FLAT));
        assert!(
            e.contains("'v_template' has shape [3, 2], expected (N, 3)"),
            "{e}"
        );
        static NAN: [f64; 9] = [0.0, 0.0, f64::NAN, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0];
        let e = load_error(|m| m[0].1 = crate::io::pickle_write::PyObj::F64(vec![3, 3], &NAN));
        assert!(e.contains("NaN"), "{e}");
        static WIDE: [f32; 12] = [0.0; 12];
        let e = load_error(|m| m[2].1 = crate::io::pickle_write::PyObj::F32(vec![4, 3, 1], &WIDE));
        assert!(
            e.contains("'shapedirs' has shape [4, 3, 1], expected (3, 3, N)"),
            "{e}"
        );
        static OUT_OF_RANGE: [u32; 3] = [0, 1, 7];
        let e =
            load_error(|m| m[1].1 = crate::io::pickle_write::PyObj::U32(vec![1, 3], &OUT_OF_RANGE));
        assert!(e.contains("7"), "{e}");
        let e = load_error(|m| m[5].1 = crate::io::pickle_write::PyObj::Str("tree"));
        assert!(e.contains("kintree_table"), "{e}");
    }

    #[test]
    fn teeth_topology_matches_gaussian_avatars() {
        let positions: Vec<Vec3> = (0..30)
            .map(|i| {
                Vec3::new(
                    i as f32 % 15.0 * 0.01,
                    if i < 15 { 0.01 } else { -0.01 },
                    0.1,
                )
            })
            .collect();
        let up: Vec<u32> = (0..15).collect();
        let lo: Vec<u32> = (15..30).collect();
        let t = build_teeth(&positions, &up, &lo);
        assert_eq!(t.positions.len(), TEETH_VERTICES);
        assert_eq!(t.triangles.len(), TEETH_TRIANGLES);
        // Spot checks against GaussianAvatars' published face list.
        assert_eq!(t.triangles[0], [0, 31, 30]);
        assert_eq!(t.triangles[1], [0, 1, 31]);
        assert_eq!(t.triangles[14], [7, 8, 37]);
        assert_eq!(t.triangles[15], [8, 38, 37]);
        assert_eq!(t.triangles[28], [60, 75, 76]);
        assert_eq!(t.triangles[42], [67, 82, 68]);
        assert_eq!(t.triangles[43], [68, 82, 83]);
        assert_eq!(t.triangles[56], [75, 30, 76]);
        assert_eq!(t.triangles[70], [82, 37, 38]);
        assert_eq!(t.triangles[84], [45, 46, 15]);
        assert_eq!(t.triangles[98], [52, 23, 22]);
        assert_eq!(t.triangles[112], [90, 106, 105]);
        assert_eq!(t.triangles[126], [97, 98, 112]);
        assert_eq!(t.triangles[140], [105, 106, 45]);
        assert_eq!(t.triangles[154], [112, 53, 52]);
        assert_eq!(t.triangles[167], [118, 119, 59]);
        // Geometry: d = 0.02, middle 1.5 d behind the rings; roots 2 d from the edges.
        assert!((t.positions[30].z - (0.1 - 0.03)).abs() < 1e-6);
        assert!((t.positions[0].y - t.positions[30].y - 0.04).abs() < 1e-6);
        assert!((t.positions[60].z - t.positions[0].z + 0.02).abs() < 1e-6);
        assert!(t.upper[..15].iter().all(|u| *u) && !t.upper[15]);
    }
}
