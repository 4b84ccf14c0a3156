//! Finished seam fits kept in a folder (method §7.12), so that a composite
//! fitted once is not fitted again: `study build` fits each avatar into the
//! study's folder and `study run` shows it at once instead of making every
//! participant wait for the fit.
//!
//! A fit is stored under a key that names everything its result depends on:
//! the fit's options, the composite's Gaussians and shape, the recipe's
//! sources, weights and post-processing, and the Gaussians and shapes of
//! every source the recipe draws on (the fit's targets are those sources'
//! whole heads). Any change, a retrained source included, gives another key,
//! so a stored fit is never applied to a composite it was not made for.
//! Only the Gaussians the fit changed are stored.

use std::path::{Path, PathBuf};

use crate::avatar::gaussians::GaussianSet;
use crate::compose::engine::{Composite, Engine};
use crate::error::{Error, Result};

use super::seam_fit::{FitReport, SeamFit};

/// The first bytes of a stored fit.
const MAGIC: &[u8; 12] = b"VISAGE-FIT\0\0";
/// Bumped whenever the same inputs would fit to another result (the fit's
/// method changed), so older files are passed over rather than applied.
const VERSION: u32 = 1;

/// What a stored fit is looked up by: a BLAKE3 hash of its inputs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FitKey([u8; 32]);

impl FitKey {
    /// The key of fitting `composite` (on `engine`) under `options`.
    pub fn of(engine: &Engine, composite: &Composite, options: &SeamFit) -> FitKey {
        let mut bytes = Vec::new();
        bytes.extend_from_slice(&VERSION.to_le_bytes());
        for n in [options.iterations, options.size as usize, options.cameras] {
            bytes.extend_from_slice(&(n as u64).to_le_bytes());
        }
        bytes.extend_from_slice(options.renderer.name().as_bytes());
        let recipe = &composite.recipe;
        bytes.extend_from_slice(&(recipe.base as u64).to_le_bytes());
        for &s in &recipe.gaussians {
            bytes.extend_from_slice(&(s as u64).to_le_bytes());
        }
        for row in &recipe.shape {
            row.iter()
                .for_each(|w| bytes.extend_from_slice(&w.to_le_bytes()));
        }
        bytes.extend_from_slice(format!("{:?}", recipe.post).as_bytes());
        let db = engine.database();
        let model = &db.model;
        model
            .template
            .iter()
            .flat_map(|v| v.to_array())
            .for_each(|x| bytes.extend_from_slice(&x.to_le_bytes()));
        bytes.extend_from_slice(&(model.triangles.len() as u64).to_le_bytes());
        composite
            .neutral
            .iter()
            .flat_map(|v| v.to_array())
            .for_each(|x| bytes.extend_from_slice(&x.to_le_bytes()));
        set_bytes(&composite.gaussians, &mut bytes);
        let mut sources: Vec<usize> = recipe.gaussians.to_vec();
        sources.extend(recipe.shape_sources());
        sources.sort_unstable();
        sources.dedup();
        for s in sources {
            let source = &db.sources[s];
            bytes.extend_from_slice(source.name.as_bytes());
            bytes.push(0);
            source
                .shape
                .iter()
                .for_each(|x| bytes.extend_from_slice(&x.to_le_bytes()));
            source
                .static_offset
                .iter()
                .flat_map(|v| v.to_array())
                .for_each(|x| bytes.extend_from_slice(&x.to_le_bytes()));
            set_bytes(&source.gaussians, &mut bytes);
        }
        FitKey(*blake3::hash(&bytes).as_bytes())
    }

    /// The file name the fit is stored under.
    fn file_name(&self) -> String {
        let hex: String = self.0[..8].iter().map(|b| format!("{b:02x}")).collect();
        format!("{hex}.fit")
    }
}

/// Every parameter of a Gaussian set, little-endian.
fn set_bytes(set: &GaussianSet, bytes: &mut Vec<u8>) {
    bytes.push(set.sh_degree);
    bytes.extend_from_slice(&(set.len() as u64).to_le_bytes());
    let floats = set
        .position
        .iter()
        .flat_map(|v| v.to_array())
        .chain(set.rotation.iter().flat_map(|q| q.to_array()))
        .chain(set.log_scale.iter().flat_map(|v| v.to_array()))
        .chain(set.opacity_logit.iter().copied())
        .chain(set.sh.iter().copied());
    for x in floats {
        bytes.extend_from_slice(&x.to_le_bytes());
    }
    for b in &set.binding {
        bytes.extend_from_slice(&b.to_le_bytes());
    }
}

/// A folder of finished seam fits, one file per key.
#[derive(Clone, Debug)]
pub struct FitStore {
    dir: PathBuf,
}

impl FitStore {
    /// The store in `dir` (made when the first fit is saved).
    pub fn new(dir: impl Into<PathBuf>) -> Self {
        Self { dir: dir.into() }
    }

    /// The folder.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// Whether a fit is stored under `key` (not whether it will load).
    pub fn contains(&self, key: &FitKey) -> bool {
        self.dir.join(key.file_name()).is_file()
    }

    /// The fitted Gaussians stored under `key`, applied to `composed` (the
    /// composite's Gaussians as composed), and the fit's report. `None` when
    /// there is none, or the file does not hold exactly a fit of this key for
    /// a set like `composed` (a damaged or foreign file is passed over: the
    /// caller fits again, and saving replaces it).
    pub fn load(&self, key: &FitKey, composed: &GaussianSet) -> Option<(GaussianSet, FitReport)> {
        let bytes = std::fs::read(self.dir.join(key.file_name())).ok()?;
        decode(&bytes, key, composed)
    }

    /// Stores the fit of `composed` to `fitted` under `key`: the Gaussians
    /// that differ and the report. Written to a file of its own first and
    /// renamed, so a reader never sees half a fit.
    pub fn save(
        &self,
        key: &FitKey,
        composed: &GaussianSet,
        fitted: &GaussianSet,
        report: &FitReport,
    ) -> Result<()> {
        let bytes = encode(key, composed, fitted, report);
        let cannot = |e: std::io::Error| Error::io("store the seam fit in", &self.dir, e);
        std::fs::create_dir_all(&self.dir).map_err(cannot)?;
        let path = self.dir.join(key.file_name());
        let partial = self.dir.join(format!(
            "{}.partial.{}",
            key.file_name(),
            std::process::id()
        ));
        std::fs::write(&partial, &bytes).map_err(cannot)?;
        std::fs::rename(&partial, &path).map_err(cannot)
    }
}

/// Floats stored per changed Gaussian beside its index: opacity logit, log
/// scale, SH.
fn record_floats(stride: usize) -> usize {
    1 + 3 + stride
}

fn encode(
    key: &FitKey,
    composed: &GaussianSet,
    fitted: &GaussianSet,
    report: &FitReport,
) -> Vec<u8> {
    let stride = composed.sh_stride();
    let changed: Vec<usize> = (0..composed.len())
        .filter(|&i| {
            composed.opacity_logit[i].to_bits() != fitted.opacity_logit[i].to_bits()
                || composed.log_scale[i] != fitted.log_scale[i]
                || composed.sh[i * stride..(i + 1) * stride]
                    .iter()
                    .zip(&fitted.sh[i * stride..(i + 1) * stride])
                    .any(|(a, b)| a.to_bits() != b.to_bits())
        })
        .collect();
    let mut out = Vec::new();
    out.extend_from_slice(MAGIC);
    out.extend_from_slice(&VERSION.to_le_bytes());
    out.extend_from_slice(&key.0);
    for n in [
        composed.len(),
        stride,
        changed.len(),
        report.fitted,
        report.views,
    ] {
        out.extend_from_slice(&(n as u64).to_le_bytes());
    }
    out.extend_from_slice(&report.mse_before.to_le_bytes());
    out.extend_from_slice(&report.mse_after.to_le_bytes());
    out.push(u8::from(report.on_gpu));
    for i in changed {
        out.extend_from_slice(&(i as u64).to_le_bytes());
        let floats = std::iter::once(fitted.opacity_logit[i])
            .chain(fitted.log_scale[i].to_array())
            .chain(fitted.sh[i * stride..(i + 1) * stride].iter().copied());
        for x in floats {
            out.extend_from_slice(&x.to_le_bytes());
        }
    }
    let check = blake3::hash(&out);
    out.extend_from_slice(check.as_bytes());
    out
}

/// Reads little-endian values off the front of a byte slice.
struct Reader<'a>(&'a [u8]);

impl Reader<'_> {
    fn take<const N: usize>(&mut self) -> Option<[u8; N]> {
        let (head, rest) = self.0.split_first_chunk::<N>()?;
        self.0 = rest;
        Some(*head)
    }
    fn u64(&mut self) -> Option<usize> {
        usize::try_from(u64::from_le_bytes(self.take()?)).ok()
    }
    fn f32(&mut self) -> Option<f32> {
        Some(f32::from_le_bytes(self.take()?))
    }
    fn f64(&mut self) -> Option<f64> {
        Some(f64::from_le_bytes(self.take()?))
    }
}

fn decode(bytes: &[u8], key: &FitKey, composed: &GaussianSet) -> Option<(GaussianSet, FitReport)> {
    let (body, check) = bytes.split_at_checked(bytes.len().checked_sub(32)?)?;
    if blake3::hash(body).as_bytes() != check {
        return None;
    }
    let mut r = Reader(body);
    if &r.take::<12>()? != MAGIC || u32::from_le_bytes(r.take()?) != VERSION {
        return None;
    }
    if r.take::<32>()? != key.0 {
        return None;
    }
    let stride = composed.sh_stride();
    if r.u64()? != composed.len() || r.u64()? != stride {
        return None;
    }
    let changed = r.u64()?;
    let report = FitReport {
        fitted: r.u64()?,
        views: r.u64()?,
        mse_before: r.f64()?,
        mse_after: r.f64()?,
        on_gpu: r.take::<1>()?[0] != 0,
    };
    let record = 8 + 4 * record_floats(stride);
    if r.0.len() != changed.checked_mul(record)? {
        return None;
    }
    let mut out = composed.clone();
    for _ in 0..changed {
        let i = r.u64()?;
        if i >= out.len() {
            return None;
        }
        out.opacity_logit[i] = r.f32()?;
        out.log_scale[i] = glam::Vec3::new(r.f32()?, r.f32()?, r.f32()?);
        for k in 0..stride {
            out.sh[i * stride + k] = r.f32()?;
        }
    }
    Some((out, report))
}
