//! PLY files: a general reader (binary little/big endian and ASCII, any scalar
//! property type, list properties skipped) whose allocations are bounded by the
//! file size, and the standard 3D Gaussian Splatting layout (INRIA): x y z,
//! nx ny nz, f_dc_0..2, f_rest_* (channel-major), opacity (logit), scale_0..2
//! (log), rot_0..3 (w x y z), plus GaussianAvatars' binding_0.

use std::collections::HashMap;
use std::io::Write;
use std::path::Path;

use glam::{Quat, Vec3};

use crate::avatar::gaussians::{logit, sh_coefficients, sh_degree_for, sigmoid};
use crate::scene::splats::SplatScene;

/// Storage format of a PLY body.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PlyFormat {
    /// Whitespace-separated text.
    Ascii,
    /// Binary little endian.
    BinaryLittleEndian,
    /// Binary big endian.
    BinaryBigEndian,
}

/// Scalar types of PLY properties.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ScalarType {
    /// i8
    Char,
    /// u8
    UChar,
    /// i16
    Short,
    /// u16
    UShort,
    /// i32
    Int,
    /// u32
    UInt,
    /// f32
    Float,
    /// f64
    Double,
}

impl ScalarType {
    fn parse(name: &str) -> Option<Self> {
        Some(match name {
            "char" | "int8" => Self::Char,
            "uchar" | "uint8" => Self::UChar,
            "short" | "int16" => Self::Short,
            "ushort" | "uint16" => Self::UShort,
            "int" | "int32" => Self::Int,
            "uint" | "uint32" => Self::UInt,
            "float" | "float32" => Self::Float,
            "double" | "float64" => Self::Double,
            _ => return None,
        })
    }

    fn size(self) -> usize {
        match self {
            Self::Char | Self::UChar => 1,
            Self::Short | Self::UShort => 2,
            Self::Int | Self::UInt | Self::Float => 4,
            Self::Double => 8,
        }
    }

    fn decode(self, bytes: &[u8], big: bool) -> f64 {
        macro_rules! num {
            ($t:ty, $n:expr) => {{
                let mut a = [0u8; $n];
                a.copy_from_slice(&bytes[..$n]);
                (if big {
                    <$t>::from_be_bytes(a)
                } else {
                    <$t>::from_le_bytes(a)
                }) as f64
            }};
        }
        match self {
            Self::Char => bytes[0] as i8 as f64,
            Self::UChar => bytes[0] as f64,
            Self::Short => num!(i16, 2),
            Self::UShort => num!(u16, 2),
            Self::Int => num!(i32, 4),
            Self::UInt => num!(u32, 4),
            Self::Float => num!(f32, 4),
            Self::Double => num!(f64, 8),
        }
    }
}

/// One property of an element.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Property {
    /// Name.
    pub name: String,
    /// Scalar type, or for lists the item type.
    pub ty: ScalarType,
    /// For list properties, the type of the length prefix.
    pub list_count: Option<ScalarType>,
}

/// One element declaration.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Element {
    /// Name.
    pub name: String,
    /// Number of rows.
    pub count: usize,
    /// Properties in file order.
    pub properties: Vec<Property>,
}

/// The scalar columns of one element, as f64.
#[derive(Clone, Debug, Default)]
pub struct Columns {
    /// Row count.
    pub rows: usize,
    columns: HashMap<String, Vec<f64>>,
    /// Names of the element's list properties, to tell "wrong type" from "missing".
    lists: Vec<String>,
}

impl Columns {
    /// A column by name.
    pub fn get(&self, name: &str) -> Option<&[f64]> {
        self.columns.get(name).map(Vec::as_slice)
    }

    /// A required column, or an error naming it.
    pub fn require(&self, name: &str) -> Result<&[f64], String> {
        self.get(name).ok_or_else(|| {
            if self.lists.iter().any(|l| l == name) {
                format!("PLY property '{name}' is a list; a number was expected")
            } else {
                format!("PLY vertex element has no '{name}' property")
            }
        })
    }
}

/// Most header bytes accepted before `end_header`.
pub(crate) const MAX_HEADER: usize = 1 << 20;

/// Parses the header; returns format, elements and the body offset.
pub fn parse_header(bytes: &[u8]) -> super::Result<(PlyFormat, Vec<Element>, usize)> {
    if !bytes.starts_with(b"ply\n") && !bytes.starts_with(b"ply\r\n") {
        return Err("not a PLY file (it does not start with 'ply')".into());
    }
    let window = &bytes[..bytes.len().min(MAX_HEADER)];
    let end = find(window, b"end_header")
        .ok_or("PLY header has no 'end_header' within its first 1 MiB")?;
    let mut body = end + b"end_header".len();
    if window.get(body) == Some(&b'\r') {
        body += 1;
    }
    if window.get(body) != Some(&b'\n') {
        return Err("PLY 'end_header' is not followed by a newline".into());
    }
    body += 1;
    let text = std::str::from_utf8(&bytes[..end]).map_err(|_| "PLY header is not text")?;
    let mut format = None;
    let mut elements: Vec<Element> = Vec::new();
    for (n, line) in text.lines().enumerate().skip(1) {
        let words: Vec<&str> = line.split_whitespace().collect();
        let bad = || format!("PLY header line {}: cannot parse '{}'", n + 1, line.trim());
        match words.as_slice() {
            [] | ["comment", ..] | ["obj_info", ..] => {}
            ["format", kind, _version] => {
                format = Some(match *kind {
                    "ascii" => PlyFormat::Ascii,
                    "binary_little_endian" => PlyFormat::BinaryLittleEndian,
                    "binary_big_endian" => PlyFormat::BinaryBigEndian,
                    _ => return Err(format!("PLY format '{kind}' is not supported").into()),
                })
            }
            ["element", name, count] => elements.push(Element {
                name: name.to_string(),
                count: count.parse().map_err(|_| bad())?,
                properties: Vec::new(),
            }),
            ["property", "list", count_ty, item_ty, name] => {
                let e = elements.last_mut().ok_or_else(bad)?;
                e.properties.push(Property {
                    name: name.to_string(),
                    ty: ScalarType::parse(item_ty).ok_or_else(bad)?,
                    list_count: Some(ScalarType::parse(count_ty).ok_or_else(bad)?),
                });
            }
            ["property", ty, name] => {
                let e = elements.last_mut().ok_or_else(bad)?;
                e.properties.push(Property {
                    name: name.to_string(),
                    ty: ScalarType::parse(ty)
                        .ok_or_else(|| format!("PLY property '{name}' has unknown type '{ty}'"))?,
                    list_count: None,
                });
            }
            _ => return Err(bad().into()),
        }
    }
    let format = format.ok_or("PLY header has no 'format' line")?;
    Ok((format, elements, body))
}

fn find(haystack: &[u8], needle: &[u8]) -> Option<usize> {
    haystack.windows(needle.len()).position(|w| w == needle)
}

/// Reads the scalar columns of element `wanted` (list properties are skipped).
/// Allocation is bounded by the file size: a header that claims more rows than
/// the body can hold is an error.
pub fn read_element(bytes: &[u8], wanted: &str) -> super::Result<Columns> {
    let (format, elements, body) = parse_header(bytes)?;
    let data = &bytes[body..];
    let mut cursor = 0usize;
    let mut text_tokens = if format == PlyFormat::Ascii {
        Some(
            std::str::from_utf8(data)
                .map_err(|_| "ASCII PLY body is not text")?
                .split_ascii_whitespace(),
        )
    } else {
        None
    };
    for element in &elements {
        let scalar_row: usize = element
            .properties
            .iter()
            .filter(|p| p.list_count.is_none())
            .map(|p| p.ty.size())
            .sum();
        // Binary rows need at least their scalar bytes, text rows 2 bytes a value.
        let min_row = if format == PlyFormat::Ascii {
            2 * element.properties.len().max(1)
        } else {
            scalar_row.max(1)
        };
        if element.count > data.len().saturating_sub(cursor) / min_row {
            return Err(format!(
                "PLY header claims {} {} rows, more than the file's {} bytes can hold",
                element.count,
                crate::text::printable(&element.name),
                bytes.len()
            )
            .into());
        }
        let keep = element.name == wanted;
        let mut columns: Vec<Vec<f64>> = if keep {
            element
                .properties
                .iter()
                .map(|p| {
                    if p.list_count.is_none() {
                        Vec::with_capacity(element.count)
                    } else {
                        Vec::new()
                    }
                })
                .collect()
        } else {
            Vec::new()
        };
        let big = format == PlyFormat::BinaryBigEndian;
        for row in 0..element.count {
            for (k, p) in element.properties.iter().enumerate() {
                let truncated = || {
                    format!(
                        "PLY body ends inside {} row {row}",
                        crate::text::printable(&element.name)
                    )
                };
                let items = match (p.list_count, &mut text_tokens) {
                    (Some(count_ty), None) => {
                        let b = data
                            .get(cursor..cursor + count_ty.size())
                            .ok_or_else(truncated)?;
                        cursor += count_ty.size();
                        let n = count_ty.decode(b, big);
                        if !(0.0..=1e7).contains(&n) {
                            return Err(
                                format!("PLY list '{}' has invalid length {n}", p.name).into()
                            );
                        }
                        cursor = cursor
                            .checked_add(n as usize * p.ty.size())
                            .filter(|&c| c <= data.len())
                            .ok_or_else(truncated)?;
                        continue;
                    }
                    (Some(_), Some(tokens)) => {
                        let n: usize = tokens
                            .next()
                            .ok_or_else(truncated)?
                            .parse()
                            .map_err(|_| truncated())?;
                        for _ in 0..n {
                            tokens.next().ok_or_else(truncated)?;
                        }
                        continue;
                    }
                    (None, None) => {
                        let b = data
                            .get(cursor..cursor + p.ty.size())
                            .ok_or_else(truncated)?;
                        cursor += p.ty.size();
                        p.ty.decode(b, big)
                    }
                    (None, Some(tokens)) => {
                        let t = tokens.next().ok_or_else(truncated)?;
                        t.parse::<f64>().map_err(|_| {
                            format!(
                                "PLY value '{}' of '{}' is not a number",
                                crate::text::printable(t),
                                p.name
                            )
                        })?
                    }
                };
                if keep {
                    columns[k].push(items);
                }
            }
        }
        if keep {
            let mut out = Columns {
                rows: element.count,
                columns: HashMap::new(),
                lists: Vec::new(),
            };
            for (p, c) in element.properties.iter().zip(columns) {
                if p.list_count.is_none() {
                    out.columns.insert(p.name.clone(), c);
                } else {
                    out.lists.push(crate::text::printable(&p.name));
                }
            }
            return Ok(out);
        }
    }
    Err(format!("PLY file has no '{wanted}' element").into())
}

/// Number of `f_rest_*` properties and the SH degree they imply.
fn sh_layout(columns: &Columns) -> Result<(usize, u8), String> {
    let rest = (0..)
        .take_while(|k| columns.get(&format!("f_rest_{k}")).is_some())
        .count();
    if rest % 3 != 0 {
        return Err(format!(
            "PLY has {rest} f_rest properties; expected a multiple of 3"
        ));
    }
    let degree = sh_degree_for(1 + rest / 3)
        .ok_or_else(|| format!("PLY has {rest} f_rest properties, which is no SH degree 0-3"))?;
    Ok((rest, degree))
}

/// Reads a standard 3DGS PLY (world space) into a scene. NaN or infinite values
/// are rejected with the row that has them.
pub fn read_splat_ply(path: &Path) -> super::Result<SplatScene> {
    read_splat_ply_with(path, &|_, _| {})
}

/// [`read_splat_ply`], telling `progress` how far it got (bytes of the file).
pub fn read_splat_ply_with(path: &Path, progress: super::Progress) -> super::Result<SplatScene> {
    if let Some(scene) = super::ply_stream::read_fast(path, progress)? {
        return Ok(scene);
    }
    let bytes = super::read_file(path)?;
    parse_splat_ply(&bytes).map_err(|e| e.in_file(path))
}

/// Parses standard 3DGS PLY bytes into a scene (SuperSplat's compressed
/// layout included).
pub fn parse_splat_ply(bytes: &[u8]) -> super::Result<SplatScene> {
    let (_, elements, _) = parse_header(bytes)?;
    if super::compressed_ply::is_compressed(&elements) {
        return Ok(super::compressed_ply::parse_compressed_ply(bytes)?);
    }
    let c = read_element(bytes, "vertex")?;
    let rows = InriaRows::new(&c, None)?;
    let mut scene = SplatScene::with_degree(rows.degree);
    let mut sh = vec![0.0f32; 3 * sh_coefficients(rows.degree)];
    for i in 0..c.rows {
        let r = rows.decode(i, &mut sh)?;
        scene.push(
            r.position,
            r.rotation,
            r.log_scale.exp(),
            sigmoid(r.opacity_logit),
            &sh,
        );
    }
    Ok(scene)
}

/// The INRIA-layout columns of a vertex element, decoded row by row — the one
/// decoder of 3DGS rows that world-space scenes and GaussianAvatars point
/// clouds share.
pub struct InriaRows<'a> {
    /// SH degree, from the count of `f_rest_*` properties.
    pub degree: u8,
    position: [&'a [f64]; 3],
    dc: [&'a [f64]; 3],
    rest: Vec<&'a [f64]>,
    opacity: &'a [f64],
    scale: [&'a [f64]; 3],
    rotation: [&'a [f64]; 4],
    extra: Option<&'a [f64]>,
}

impl<'a> InriaRows<'a> {
    /// Finds the columns; `extra` names one more required property (e.g.
    /// `binding_0`), with the error to give when it is missing.
    pub fn new(c: &'a Columns, extra: Option<(&str, &str)>) -> Result<Self, String> {
        let (rest, degree) = sh_layout(c)?;
        let col = |n: &str| c.require(n);
        let extra = match extra {
            Some((name, missing)) => Some(c.require(name).map_err(|_| missing.to_string())?),
            None => None,
        };
        Ok(Self {
            degree,
            position: [col("x")?, col("y")?, col("z")?],
            dc: [col("f_dc_0")?, col("f_dc_1")?, col("f_dc_2")?],
            rest: (0..rest)
                .map(|k| c.get(&format!("f_rest_{k}")).expect("counted by sh_layout"))
                .collect(),
            opacity: col("opacity")?,
            scale: [col("scale_0")?, col("scale_1")?, col("scale_2")?],
            rotation: [col("rot_0")?, col("rot_1")?, col("rot_2")?, col("rot_3")?],
            extra,
        })
    }

    /// Row `i`. Its SH coefficients (coefficient-major) go into `sh`, so the
    /// record's own `sh` is empty; NaN or infinite values are an error naming
    /// the row.
    pub fn decode(&self, i: usize, sh: &mut [f32]) -> Result<InriaRecord<'static>, String> {
        let per_channel = self.rest.len() / 3;
        for ch in 0..3 {
            sh[ch] = self.dc[ch][i] as f32;
            for k in 0..per_channel {
                sh[(k + 1) * 3 + ch] = self.rest[ch * per_channel + k][i] as f32;
            }
        }
        let f = |col: &[f64]| col[i];
        let values = [
            f(self.position[0]),
            f(self.position[1]),
            f(self.position[2]),
            f(self.opacity),
            f(self.scale[0]),
            f(self.scale[1]),
            f(self.scale[2]),
            f(self.rotation[0]),
            f(self.rotation[1]),
            f(self.rotation[2]),
            f(self.rotation[3]),
        ];
        if values.iter().any(|v| !v.is_finite()) || sh.iter().any(|v| !v.is_finite()) {
            return Err(format!("Gaussian {i} has a NaN or infinite value"));
        }
        let v3 = |c: [&[f64]; 3]| Vec3::new(c[0][i] as f32, c[1][i] as f32, c[2][i] as f32);
        Ok(InriaRecord {
            position: v3(self.position),
            sh: &[],
            opacity_logit: self.opacity[i] as f32,
            log_scale: v3(self.scale),
            // Files store w x y z.
            rotation: Quat::from_xyzw(
                self.rotation[1][i] as f32,
                self.rotation[2][i] as f32,
                self.rotation[3][i] as f32,
                self.rotation[0][i] as f32,
            ),
            extra: self.extra.map(|e| e[i] as f32),
        })
    }

    /// The extra column's value in row `i` as read (f64, before any rounding).
    pub fn extra_value(&self, i: usize) -> Option<f64> {
        self.extra.map(|e| e[i])
    }
}

/// One Gaussian in the units of the INRIA layout.
pub struct InriaRecord<'a> {
    /// Centre.
    pub position: Vec3,
    /// SH coefficients, coefficient-major (`3 × coefficients`).
    pub sh: &'a [f32],
    /// Opacity before the sigmoid.
    pub opacity_logit: f32,
    /// Natural log of the scales.
    pub log_scale: Vec3,
    /// Rotation, written w x y z.
    pub rotation: Quat,
    /// The value of the extra property, when the file has one.
    pub extra: Option<f32>,
}

/// Encodes `count` Gaussians as a binary little-endian PLY in the INRIA layout
/// (f_rest channel-major), with `extra` appended as one more float property
/// (GaussianAvatars' `binding_0`).
pub fn encode_inria_ply<'a>(
    comment: &str,
    count: usize,
    sh_degree: u8,
    extra: Option<&str>,
    record: impl Fn(usize) -> InriaRecord<'a>,
) -> Vec<u8> {
    let header = inria_header(comment, count, sh_degree, extra);
    let row = inria_row_bytes(sh_degree, extra.is_some());
    let mut out = Vec::with_capacity(header.len() + count * row);
    out.extend_from_slice(header.as_bytes());
    for i in 0..count {
        encode_inria_row(&mut out, sh_degree, &record(i));
    }
    out
}

/// The header of an INRIA-layout PLY of `count` rows.
fn inria_header(comment: &str, count: usize, sh_degree: u8, extra: Option<&str>) -> String {
    let rest = 3 * (sh_coefficients(sh_degree) - 1);
    let mut names: Vec<String> = [
        "x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2",
    ]
    .map(String::from)
    .to_vec();
    names.extend((0..rest).map(|k| format!("f_rest_{k}")));
    names.extend(
        [
            "opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3",
        ]
        .map(String::from),
    );
    names.extend(extra.map(String::from));
    let mut header = format!(
        "ply\nformat binary_little_endian 1.0\ncomment {comment}\nelement vertex {count}\n"
    );
    for n in &names {
        header += &format!("property float {n}\n");
    }
    header + "end_header\n"
}

/// Bytes of one INRIA-layout row.
fn inria_row_bytes(sh_degree: u8, extra: bool) -> usize {
    4 * (17 + 3 * (sh_coefficients(sh_degree) - 1) + usize::from(extra))
}

/// Appends one row (f_rest channel-major, as INRIA's trainer writes it).
fn encode_inria_row(out: &mut Vec<u8>, sh_degree: u8, r: &InriaRecord) {
    let coefficients = sh_coefficients(sh_degree);
    let mut put = |v: f32| out.extend_from_slice(&v.to_le_bytes());
    let p = r.position;
    [p.x, p.y, p.z, 0.0, 0.0, 0.0]
        .into_iter()
        .for_each(&mut put);
    (0..3).for_each(|ch| put(r.sh[ch]));
    for ch in 0..3 {
        for k in 1..coefficients {
            put(r.sh[k * 3 + ch]);
        }
    }
    put(r.opacity_logit);
    let s = r.log_scale;
    [s.x, s.y, s.z].into_iter().for_each(&mut put);
    let q = r.rotation;
    [q.w, q.x, q.y, q.z].into_iter().for_each(&mut put);
    if let Some(v) = r.extra {
        put(v);
    }
}

/// Writes `count` rows as an INRIA-layout PLY without holding them: each
/// item is encoded (through `record`) as `rows` yields it, through a buffer,
/// into `PATH.partial`, renamed to `path` once complete (a killed run leaves
/// no half file under the name). `rows` must yield at least `count` items.
pub fn write_inria_ply_stream<T>(
    path: &Path,
    comment: &str,
    count: usize,
    sh_degree: u8,
    rows: impl Iterator<Item = T>,
    record: impl for<'b> Fn(&'b T) -> InriaRecord<'b>,
) -> super::Result<()> {
    let partial = path.with_extension(match path.extension() {
        Some(e) => format!("{}.partial", e.to_string_lossy()),
        None => "partial".into(),
    });
    let access = |e| super::FileError::access("write", &partial, e);
    let file = std::fs::File::create(&partial).map_err(access)?;
    let mut writer = std::io::BufWriter::with_capacity(1 << 20, file);
    writer
        .write_all(inria_header(comment, count, sh_degree, None).as_bytes())
        .map_err(access)?;
    let mut row = Vec::with_capacity(inria_row_bytes(sh_degree, false));
    let mut written = 0usize;
    for item in rows.take(count) {
        row.clear();
        encode_inria_row(&mut row, sh_degree, &record(&item));
        writer.write_all(&row).map_err(access)?;
        written += 1;
    }
    assert_eq!(written, count, "the rows ran out before the count");
    writer
        .into_inner()
        .map_err(|e| access(e.into_error()))?
        .sync_all()
        .map_err(access)?;
    std::fs::rename(&partial, path).map_err(|e| super::FileError::access("write", path, e))
}

/// Writes a scene as a standard 3DGS PLY (binary little endian), readable by any
/// splat viewer.
pub fn write_splat_ply(path: &Path, scene: &SplatScene) -> super::Result<()> {
    let out = encode_inria_ply(
        "written by visage",
        scene.len(),
        scene.sh_degree,
        None,
        |i| InriaRecord {
            position: scene.position[i],
            sh: scene.sh_of(i),
            opacity_logit: logit(scene.opacity[i]),
            log_scale: scene.scale[i].max(Vec3::splat(1e-30)).ln(),
            rotation: scene.rotation[i],
            extra: None,
        },
    );
    let mut file =
        std::fs::File::create(path).map_err(|e| super::FileError::access("write", path, e))?;
    file.write_all(&out)
        .map_err(|e| super::FileError::access("write", path, e))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scene(degree: u8) -> SplatScene {
        let mut s = SplatScene::with_degree(degree);
        let stride = 3 * sh_coefficients(degree);
        for i in 0..5 {
            let sh: Vec<f32> = (0..stride).map(|k| (k + i) as f32 * 0.01).collect();
            s.push(
                Vec3::new(i as f32, -0.5, 0.25),
                Quat::from_rotation_y(0.3 * i as f32),
                Vec3::new(0.01, 0.02, 0.03),
                0.8,
                &sh,
            );
        }
        s
    }

    #[test]
    fn write_then_read_round_trips_for_each_degree() {
        for degree in 0..=3 {
            let s = scene(degree);
            let path = std::env::temp_dir()
                .join(format!("visage-ply-{}-{degree}.ply", std::process::id()));
            write_splat_ply(&path, &s).unwrap();
            let back = read_splat_ply(&path).unwrap();
            std::fs::remove_file(&path).ok();
            assert_eq!(back.sh_degree, degree);
            assert_eq!(back.len(), s.len());
            for i in 0..s.len() {
                assert!(back.position[i].abs_diff_eq(s.position[i], 1e-6));
                assert!(back.scale[i].abs_diff_eq(s.scale[i], 1e-6));
                assert!((back.opacity[i] - s.opacity[i]).abs() < 1e-5);
                assert!(back.rotation[i].dot(s.rotation[i]).abs() > 1.0 - 1e-6);
                for (a, b) in back.sh_of(i).iter().zip(s.sh_of(i)) {
                    assert!((a - b).abs() < 1e-6);
                }
            }
        }
    }

    #[test]
    fn ascii_and_big_endian_bodies_parse() {
        let ascii = b"ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty uchar red\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n1.5 7\n-2 255\n3 0 1 1\n";
        let c = read_element(ascii, "vertex").unwrap();
        assert_eq!(c.get("x").unwrap(), &[1.5, -2.0]);
        assert_eq!(c.get("red").unwrap(), &[7.0, 255.0]);
        let mut big = b"ply\nformat binary_big_endian 1.0\nelement vertex 1\nproperty double x\nproperty short y\nend_header\n".to_vec();
        big.extend_from_slice(&2.5f64.to_be_bytes());
        big.extend_from_slice(&(-3i16).to_be_bytes());
        let c = read_element(&big, "vertex").unwrap();
        assert_eq!(c.get("x").unwrap(), &[2.5]);
        assert_eq!(c.get("y").unwrap(), &[-3.0]);
    }

    #[test]
    fn absurd_counts_and_truncation_are_errors() {
        let absurd = b"ply\nformat binary_little_endian 1.0\nelement vertex 4000000000\nproperty float x\nend_header\n\0\0\0\0";
        assert!(read_element(absurd, "vertex")
            .unwrap_err()
            .to_string()
            .contains("more than the file"));
        let short = b"ply\nformat binary_little_endian 1.0\nelement vertex 2\nproperty float x\nproperty float y\nend_header\n\0\0\0\0\0\0\0\0\0\0";
        assert!(read_element(short, "vertex").is_err());
        assert!(read_element(b"plx\n", "vertex")
            .unwrap_err()
            .to_string()
            .contains("not a PLY"));
        let no_end = b"ply\nformat ascii 1.0\nelement vertex 1\n";
        assert!(read_element(no_end, "vertex")
            .unwrap_err()
            .to_string()
            .contains("end_header"));
    }

    #[test]
    fn wrongly_typed_and_missing_properties_are_named() {
        let list_x = b"ply\nformat ascii 1.0\nelement vertex 1\nproperty list uchar float x\nproperty float y\nproperty float z\nend_header\n2 1 2 3 4\n";
        let c = read_element(list_x, "vertex").unwrap();
        assert!(c
            .require("x")
            .unwrap_err()
            .to_string()
            .contains("'x' is a list"));
        assert!(c
            .require("w")
            .unwrap_err()
            .to_string()
            .contains("no 'w' property"));
        assert!(parse_splat_ply(list_x)
            .unwrap_err()
            .to_string()
            .contains("'x' is a list"));
        let bad_type =
            b"ply\nformat ascii 1.0\nelement vertex 1\nproperty quaternion x\nend_header\n1\n";
        assert!(read_element(bad_type, "vertex").is_err());
        let nan = b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\nproperty float f_dc_0\nproperty float f_dc_1\nproperty float f_dc_2\nproperty float opacity\nproperty float scale_0\nproperty float scale_1\nproperty float scale_2\nproperty float rot_0\nproperty float rot_1\nproperty float rot_2\nproperty float rot_3\nend_header\n0 0 nan 0 0 0 0 0 0 0 1 0 0 0\n";
        assert!(parse_splat_ply(nan)
            .unwrap_err()
            .to_string()
            .contains("NaN"));
    }
}
