//! Finished seam fits kept in a folder (method §7.12), so that a composite
//! fitted once is not fitted again: `study build` fits each avatar into the
//! study's folder and `study run` shows it at once instead of making every
//! participant wait for the fit.
//!
//! A fit is stored under a key that names what its result depends on: the
//! fit's options, the composite's Gaussians and shape, the recipe's sources,
//! weights and post-processing, the head model, the Gaussians and shapes of
//! every source the recipe draws on (the fit's targets are those sources'
//! whole heads) and visage's version. Any change, a retrained source
//! included, gives another key, so a stored fit is never applied to a
//! composite it was not made for.
//! Only the Gaussians the fit changed are stored.

use std::path::{Path, PathBuf};

use crate::avatar::gaussians::GaussianSet;
use crate::compose::engine::{Composite, Engine};
use crate::error::{Error, Result};
use crate::model::head::HeadModel;

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
        // Destructured so that a new option cannot be left out unnoticed.
        let SeamFit {
            iterations,
            size,
            cameras,
            renderer,
        } = *options;
        let mut h = Hashed(blake3::Hasher::new());
        h.u64(u64::from(VERSION));
        h.bytes(env!("CARGO_PKG_VERSION").as_bytes());
        // The code itself (build.rs): another build's fit is not this one's.
        h.bytes(env!("VISAGE_FIT_CODE").as_bytes());
        for n in [iterations, size as usize, cameras] {
            h.u64(n as u64);
        }
        // The option, not the device: `auto` names what the machine has.
        h.bytes(renderer.name().as_bytes());
        let recipe = &composite.recipe;
        h.u64(recipe.base as u64);
        recipe.gaussians.iter().for_each(|&s| h.u64(s as u64));
        for row in &recipe.shape {
            row.iter().for_each(|w| h.bytes(&w.to_le_bytes()));
        }
        h.bytes(format!("{:?}", recipe.post).as_bytes());
        let db = engine.database();
        h.model(&db.model);
        h.vectors(&composite.neutral);
        h.set(&composite.gaussians);
        let mut sources: Vec<usize> = recipe.gaussians.to_vec();
        sources.extend(recipe.shape_sources());
        sources.sort_unstable();
        sources.dedup();
        for s in sources {
            let source = &db.sources[s];
            h.bytes(source.name.as_bytes());
            source.shape.iter().for_each(|x| h.f32(*x));
            for v in &source.static_offset {
                v.to_array().iter().for_each(|x| h.bytes(&x.to_le_bytes()));
            }
            h.set(&source.gaussians);
        }
        FitKey(*h.0.finalize().as_bytes())
    }

    /// The file name the fit is stored under.
    fn file_name(&self) -> String {
        let hex: String = self.0[..8].iter().map(|b| format!("{b:02x}")).collect();
        format!("{hex}.fit")
    }
}

/// A hash fed little-endian values, a buffer at a time.
struct Hashed(blake3::Hasher);

impl Hashed {
    fn bytes(&mut self, bytes: &[u8]) {
        // The length first: two fields never run into each other.
        self.0.update(&(bytes.len() as u64).to_le_bytes());
        self.0.update(bytes);
    }
    fn u64(&mut self, n: u64) {
        self.0.update(&n.to_le_bytes());
    }
    fn f32(&mut self, x: f32) {
        self.0.update(&x.to_le_bytes());
    }
    fn floats(&mut self, floats: impl Iterator<Item = f32>) {
        let buffer: Vec<u8> = floats.flat_map(f32::to_le_bytes).collect();
        self.bytes(&buffer);
    }
    fn vectors(&mut self, vectors: &[glam::Vec3]) {
        self.floats(vectors.iter().flat_map(|v| v.to_array()));
    }
    /// Everything of the head model the fit reads: the mesh, its regions,
    /// the bases and skinning that pose it, the mouth cavity.
    fn model(&mut self, model: &HeadModel) {
        self.vectors(&model.template);
        let triangles: Vec<u8> = model
            .triangles
            .iter()
            .flatten()
            .flat_map(|i| i.to_le_bytes())
            .collect();
        self.bytes(&triangles);
        self.bytes(format!("{:?}", model.triangle_regions).as_bytes());
        let bases = [Some(&model.shape_basis), Some(&model.expression_basis)];
        for basis in bases.into_iter().chain([model.pose_correctives.as_ref()]) {
            let Some(basis) = basis else {
                self.u64(u64::MAX);
                continue;
            };
            self.u64(basis.len() as u64);
            (0..basis.len()).for_each(|k| self.vectors(basis.component(k)));
        }
        self.bytes(format!("{:?}", model.joint_regressor).as_bytes());
        self.floats(model.skin_weights.iter().flatten().copied());
        self.bytes(format!("{:?}", model.mouth_cavity).as_bytes());
    }
    /// Every parameter of a Gaussian set.
    fn set(&mut self, set: &GaussianSet) {
        let GaussianSet {
            binding,
            position,
            rotation,
            log_scale,
            opacity_logit,
            sh_degree,
            sh,
        } = set;
        self.u64(u64::from(*sh_degree));
        self.vectors(position);
        self.floats(rotation.iter().flat_map(|q| q.to_array()));
        self.vectors(log_scale);
        self.floats(opacity_logit.iter().copied());
        self.floats(sh.iter().copied());
        let binding: Vec<u8> = binding.iter().flat_map(|b| b.to_le_bytes()).collect();
        self.bytes(&binding);
    }
}

/// A folder of finished seam fits, one file per key.
#[derive(Clone, Debug)]
pub struct FitStore {
    dir: PathBuf,
    /// Bytes the folder's fits may take; past it the least recently used go.
    limit: Option<u64>,
}

/// What the user's store of fits ([`FitStore::user`]) may take on disk:
/// about 170 composites of the 56-thousand-Gaussian built-in database
/// relit under `post ours` (6 MB each, half their Gaussians fitted for
/// the light), 1,500 of one fitted at its seams alone (0.7 MB).
pub const USER_STORE_LIMIT: u64 = 1 << 30;

impl FitStore {
    /// The store in `dir` (made when the first fit is saved), kept whole.
    pub fn new(dir: impl Into<PathBuf>) -> Self {
        Self {
            dir: dir.into(),
            limit: None,
        }
    }

    /// The user's store, `fits/` of visage's cache folder
    /// ([`crate::io::cache_root`]), where the editor, `compose`, `export` and
    /// `render` keep every fit they finish: a composite fitted once shows at
    /// once the next time. Capped at [`USER_STORE_LIMIT`]: saving a fit
    /// removes the least recently used past it.
    pub fn user() -> Self {
        Self {
            dir: crate::io::cache_root().join("fits"),
            limit: Some(USER_STORE_LIMIT),
        }
    }

    /// The same store with another cap on its size (`None`: none).
    pub fn with_limit(self, limit: Option<u64>) -> Self {
        Self { limit, ..self }
    }

    /// The folder.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// Where the fit of `key` is (or would be) stored.
    pub fn path(&self, key: &FitKey) -> PathBuf {
        self.dir.join(key.file_name())
    }

    /// The fitted Gaussians stored under `key`, applied to `composed` (the
    /// composite's Gaussians as composed), and the fit's report. `None` when
    /// there is none, or the file does not hold exactly a fit of this key for
    /// a set like `composed` (a damaged or foreign file is passed over: the
    /// caller fits again, and saving replaces it).
    pub fn load(&self, key: &FitKey, composed: &GaussianSet) -> Option<(GaussianSet, FitReport)> {
        let path = self.path(key);
        let found = decode(&std::fs::read(&path).ok()?, key, composed)?;
        if self.limit.is_some() {
            // Used now: the last to go when the store is over its size.
            // A store on a read-only disk still serves, so no error counts.
            if let Ok(file) = std::fs::File::options().append(true).open(&path) {
                file.set_modified(std::time::SystemTime::now()).ok();
            }
        }
        Some(found)
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
        let path = self.path(key);
        let partial = self.dir.join(format!(
            "{}.partial.{}",
            key.file_name(),
            std::process::id()
        ));
        let written =
            std::fs::write(&partial, &bytes).and_then(|()| std::fs::rename(&partial, &path));
        if written.is_err() {
            std::fs::remove_file(&partial).ok();
        }
        written.map_err(cannot)?;
        if let Some(limit) = self.limit {
            self.tidy(limit, &path);
        }
        Ok(())
    }

    /// Removes every fit in the folder but those of `keep`, and partial
    /// files a process that died while writing left; returns how many fits
    /// went. A missing folder holds none.
    pub fn remove_all_but(&self, keep: &[FitKey]) -> Result<usize> {
        let cannot = |e: std::io::Error| Error::io("tidy the seam fits in", &self.dir, e);
        let entries = match std::fs::read_dir(&self.dir) {
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(0),
            other => other.map_err(cannot)?,
        };
        let kept: Vec<String> = keep.iter().map(FitKey::file_name).collect();
        let mut removed = 0;
        for entry in entries {
            let entry = entry.map_err(cannot)?;
            let name = entry.file_name().to_string_lossy().into_owned();
            if name.ends_with(".fit") && !kept.contains(&name) {
                std::fs::remove_file(entry.path()).map_err(cannot)?;
                removed += 1;
            } else if abandoned(&entry) {
                std::fs::remove_file(entry.path()).ok();
            }
        }
        Ok(removed)
    }

    /// Removes the least recently used fits until the rest take at most
    /// `limit` bytes (never `keep`, the fit just saved), and partial files
    /// a process that died while writing left behind. Best effort: a file
    /// another process removed first, or one that cannot be removed, is
    /// passed over.
    fn tidy(&self, limit: u64, keep: &Path) {
        let Ok(entries) = std::fs::read_dir(&self.dir) else {
            return;
        };
        let now = std::time::SystemTime::now();
        let mut fits = Vec::new();
        for entry in entries.flatten() {
            let (path, Ok(meta)) = (entry.path(), entry.metadata()) else {
                continue;
            };
            let name = entry.file_name();
            let name = name.to_string_lossy();
            let modified = meta.modified().unwrap_or(now);
            if abandoned(&entry) {
                std::fs::remove_file(&path).ok();
            } else if name.ends_with(".fit") && meta.is_file() {
                fits.push((modified, meta.len(), path));
            }
        }
        let mut total: u64 = fits.iter().map(|f| f.1).sum();
        fits.sort();
        for (_, bytes, path) in fits {
            if total <= limit {
                break;
            }
            if path == keep {
                continue;
            }
            // Removed, or by another process tidying the same store first.
            match std::fs::remove_file(&path) {
                Err(e) if e.kind() != std::io::ErrorKind::NotFound => {}
                _ => total -= bytes,
            }
        }
    }
}

/// Whether a folder entry is a partial fit file whose writer is gone (a
/// process killed while saving; a save takes milliseconds).
fn abandoned(entry: &std::fs::DirEntry) -> bool {
    entry
        .file_name()
        .to_string_lossy()
        .contains(".fit.partial.")
        && !crate::io::cache::writer_alive(&entry.path())
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
    // The fit moves no Gaussian, so places are not stored.
    debug_assert!(composed.position == fitted.position && composed.rotation == fitted.rotation);
    let bits = |v: glam::Vec3| v.to_array().map(f32::to_bits);
    let changed: Vec<usize> = (0..composed.len())
        .filter(|&i| {
            composed.opacity_logit[i].to_bits() != fitted.opacity_logit[i].to_bits()
                || bits(composed.log_scale[i]) != bits(fitted.log_scale[i])
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

/// The fitted set a file holds for `key` over `composed`, or `None` when
/// the file is anything but exactly that.
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

#[cfg(test)]
mod tests {
    use super::*;

    fn set(n: usize, shift: f32) -> GaussianSet {
        let mut s = GaussianSet::with_degree(1);
        s.resize(n, 1);
        for i in 0..n {
            s.binding[i] = i as u32;
            s.opacity_logit[i] = i as f32 + shift;
            s.log_scale[i] = glam::Vec3::splat(-(i as f32) - shift);
        }
        s.sh.iter_mut()
            .enumerate()
            .for_each(|(k, x)| *x = k as f32 * 0.01);
        s
    }

    #[test]
    fn a_file_is_read_back_exactly_and_anything_else_is_refused_without_a_panic() {
        let composed = set(5, 0.0);
        let mut fitted = composed.clone();
        fitted.opacity_logit[1] = 7.5;
        fitted.log_scale[3] = glam::Vec3::new(0.25, -0.0, 1.0);
        fitted.sh[2 * composed.sh_stride()] = -3.0;
        let report = FitReport {
            fitted: 3,
            views: 16,
            mse_before: 0.01,
            mse_after: 0.005,
            on_gpu: false,
        };
        let key = FitKey([7; 32]);
        let bytes = encode(&key, &composed, &fitted, &report);
        let (back, read) = decode(&bytes, &key, &composed).expect("its own file");
        assert_eq!(read, report);
        assert_eq!(back, fitted);
        // Another key, another set's shape, every truncation, every flipped byte.
        assert!(decode(&bytes, &FitKey([8; 32]), &composed).is_none());
        assert!(decode(&bytes, &key, &set(6, 0.0)).is_none());
        for len in 0..bytes.len() {
            assert!(
                decode(&bytes[..len], &key, &composed).is_none(),
                "cut at {len}"
            );
        }
        for at in 0..bytes.len() {
            let mut bad = bytes.clone();
            bad[at] ^= 0x01;
            assert!(decode(&bad, &key, &composed).is_none(), "byte {at} flipped");
        }
        // A file whose hash holds but whose records point outside the set.
        let mut body = bytes[..bytes.len() - 32].to_vec();
        let first_record = 12 + 4 + 32 + 5 * 8 + 8 + 8 + 1;
        body[first_record..first_record + 8].copy_from_slice(&u64::MAX.to_le_bytes());
        let hash = *blake3::hash(&body).as_bytes();
        body.extend_from_slice(&hash);
        assert!(decode(&body, &key, &composed).is_none());
    }

    #[test]
    fn a_capped_store_drops_the_least_recently_used_fits_and_abandoned_partials() {
        let dir = std::env::temp_dir().join(format!("visage-fit-store-cap-{}", std::process::id()));
        std::fs::remove_dir_all(&dir).ok();
        let composed = set(40, 0.0);
        let fitted = set(40, 1.0);
        let report = FitReport {
            fitted: 40,
            ..FitReport::default()
        };
        let one = encode(&FitKey([0; 32]), &composed, &fitted, &report).len() as u64;
        // Room for two fits and a half.
        let store = FitStore::new(&dir).with_limit(Some(2 * one + one / 2));
        let keys = [FitKey([1; 32]), FitKey([2; 32]), FitKey([3; 32])];
        let age = |key: &FitKey, seconds: u64| {
            let file = std::fs::File::options()
                .append(true)
                .open(store.path(key))
                .unwrap();
            let then = std::time::SystemTime::now() - std::time::Duration::from_secs(seconds);
            file.set_modified(then).unwrap();
        };
        store.save(&keys[0], &composed, &fitted, &report).unwrap();
        age(&keys[0], 300);
        store.save(&keys[1], &composed, &fitted, &report).unwrap();
        age(&keys[1], 200);
        // Reading the older fit makes it the more recently used of the two.
        assert!(store.load(&keys[0], &composed).is_some());
        // One left by a process that is gone, one being written by this one.
        let partial = dir.join("0101010101010101.fit.partial.4000000000");
        std::fs::write(&partial, b"half").unwrap();
        let fresh_partial = dir.join(format!(
            "0202020202020202.fit.partial.{}",
            std::process::id()
        ));
        std::fs::write(&fresh_partial, b"half").unwrap();
        store.save(&keys[2], &composed, &fitted, &report).unwrap();
        assert!(store.load(&keys[0], &composed).is_some(), "used last: kept");
        assert!(
            store.load(&keys[1], &composed).is_none(),
            "least recently used: gone"
        );
        assert!(
            store.load(&keys[2], &composed).is_some(),
            "just saved: kept"
        );
        assert!(!partial.exists(), "an abandoned partial file is removed");
        assert!(fresh_partial.exists(), "one being written is left alone");
        // A store kept whole (a study's) never drops a fit.
        let whole = FitStore::new(&dir);
        whole.save(&keys[1], &composed, &fitted, &report).unwrap();
        assert!(keys.iter().all(|k| whole.load(k, &composed).is_some()));
        std::fs::remove_dir_all(&dir).ok();
    }
}
