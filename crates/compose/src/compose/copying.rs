//! Copying a composite's own Gaussians (every region's, from the source its
//! group shows): each corrected, cross-faded, relit and blended across
//! colour seams, in chunks on all threads. Each chunk writes its own range of
//! the preallocated set and each thread keeps its own seam cache, so the
//! result is the same on any number of threads.

use std::borrow::Cow;

use glam::Vec3;
use rayon::prelude::*;

use super::base_skin::SkinShare;
use super::colour::apply_gain;
use super::correction::Correction;
use super::recipe::Membership;
use super::reshape::ReshapedSources;
use super::seam_colours::{ColourKey, LocalColour, SeamColours, SourceTables};
use super::smoothing::split_opacity;
use crate::avatar::gaussians::{logit, sigmoid, GaussianSet};
use crate::model::regions::Region;

/// Copies every region's own Gaussians into `set` (sized for them), in
/// chunks on all threads: each corrected, cross-faded, relit and blended
/// across colour seams as `copying` says. The chunks' findings, in order.
pub fn copy_own(
    sources: &impl SourceTables,
    copying: &CopyOwn,
    set: &mut GaussianSet,
) -> Vec<ChunkCopied> {
    let mut chunks = Vec::new();
    for (b, block) in copying.blocks.iter().enumerate() {
        for (c, indices) in block.indices.chunks(COPY_CHUNK).enumerate() {
            chunks.push((b, indices, block.start + c * COPY_CHUNK));
        }
    }
    let ends: Vec<usize> = chunks.iter().map(|&(_, ind, at)| at + ind.len()).collect();
    let ranges = set.ranges_mut(&ends);
    chunks
        .into_par_iter()
        .zip(ranges)
        .map_init(
            || copying.seams.map(SeamColours::cache),
            |cache, ((b, indices, start), mut range)| {
                let mut copied = ChunkCopied {
                    block: b,
                    gain_sum: Vec3::ZERO,
                    at_seams: Vec::new(),
                    colours_made: Vec::new(),
                };
                let block = &copying.blocks[b];
                let f = block.source;
                let src = sources.gaussians(f);
                let placed = sources.counted_triangles(copying.membership, f);
                // The base's skin is the base's: no seam runs through it.
                let of_base = block.skin.is_some_and(|s| s.of_base);
                let seams = copying.seams.filter(|_| !of_base);
                for (at, &i) in (start..).zip(indices) {
                    let t = placed[i as usize];
                    let share = block.skin.map_or(1.0, |s| s.of(i, t));
                    let exponent = copying.own_exponent[t as usize] * share;
                    let opacity = OpacityEdit::Split(exponent).apply(src.opacity_logit[i as usize]);
                    range.set_from(at, src, i as usize, opacity);
                    if let Some(reshaped) = copying.reshaped.and_then(|r| r.placed(f, i)) {
                        range.set_placement(at, *reshaped);
                    }
                    let sh = range.sh_of_mut(at);
                    let gain = block.correction.gain(i as usize);
                    if gain != Vec3::ONE {
                        apply_gain(sh, gain);
                    }
                    copied.gain_sum += gain;
                    relight_sh(sh, copying.relight, f, i);
                    if let (Some(seams), Some(cache)) = (seams, cache.as_mut()) {
                        if seams.blend(sources, cache, f, i, sh) {
                            copied.at_seams.push(at as u32);
                        }
                    }
                }
                if let Some(cache) = cache.as_mut() {
                    copied.colours_made = cache.take_made();
                }
                copied
            },
        )
        .collect()
}

/// Gaussians one task copies when a composite's own Gaussians are copied in
/// parallel: large enough that a task's start-up and its seam cache are
/// paid back, small enough that two cores share a region.
pub const COPY_CHUNK: usize = 4096;

/// One region's own Gaussians as a composite copies them.
pub struct OwnBlock<'e> {
    /// The region.
    pub region: Region,
    /// The source it shows.
    pub source: usize,
    /// The source's Gaussians counted for the region (under `skin =
    /// "base"`, those that show).
    pub indices: Cow<'e, [u32]>,
    /// Their colour correction.
    pub correction: Correction,
    /// Where the first lands in the composite.
    pub start: usize,
    /// The share of its opacity each Gaussian keeps under `skin = "base"`
    /// (all where `None`).
    pub skin: Option<SkinShare<'e>>,
}

/// How a composite's own Gaussians are copied.
pub struct CopyOwn<'e> {
    /// Every region's, in the composite's order.
    pub blocks: &'e [OwnBlock<'e>],
    /// The membership the blocks follow.
    pub membership: Membership,
    /// Per triangle: the cross-fade's opacity exponent of own Gaussians
    /// counted for it (1 where it keeps them whole).
    pub own_exponent: &'e [f32],
    /// The colour seams, under `smoothing = "blend"`.
    pub seams: Option<&'e SeamColours<'e>>,
    /// Per source, per Gaussian: its relighting gain (empty where not relit).
    pub relight: &'e [Vec<Vec3>],
    /// The sources' Gaussians reshaped to the composite's shape, made for
    /// every one copied, where they follow it (`deform = "affine"`,
    /// `anchor = "nearest"`).
    pub reshaped: Option<&'e ReshapedSources>,
}

/// What copying one chunk found beside the Gaussians themselves.
pub struct ChunkCopied {
    /// The chunk's block in [`CopyOwn::blocks`].
    pub block: usize,
    /// The sum of its Gaussians' colour gains.
    pub gain_sum: Vec3,
    /// Its Gaussians near another source's triangles.
    pub at_seams: Vec<u32>,
    /// The seams' local colours it made, for the composite to keep.
    pub colours_made: Vec<(ColourKey, LocalColour)>,
}

/// Relights the SH `sh` of Gaussian `i` of source `f` by its gain in `gains`
/// (`shading = "relit"`, docs/method.md §7.10); nothing when the source has
/// none (not relit, or no light fitted). Done as each Gaussian is copied in,
/// while its colour is in the cache.
pub fn relight_sh(sh: &mut [f32], gains: &[Vec<Vec3>], f: usize, i: u32) {
    let gain = gains
        .get(f)
        .and_then(|g| g.get(i as usize))
        .copied()
        .unwrap_or(Vec3::ONE);
    if gain != Vec3::ONE {
        // The DC coefficients only: the baked diffuse light lives there, the
        // view-dependent bands stay as trained (a few percent of a skin
        // Gaussian's colour; scaling them too cost as much again as an edit).
        apply_gain(&mut sh[..3], gain);
    }
}

/// How a copied Gaussian's opacity changes.
#[derive(Clone, Copy, Debug)]
pub enum OpacityEdit {
    /// α' = 1 − (1 − α)^e (1 leaves it unchanged).
    Split(f32),
    /// α' = s·α.
    Scale(f32),
}

impl OpacityEdit {
    /// The edited opacity logit of a Gaussian whose logit is `logit`.
    pub fn apply(self, logit_in: f32) -> f32 {
        match self {
            OpacityEdit::Split(e) if e >= 1.0 => logit_in,
            OpacityEdit::Split(e) => logit(split_opacity(sigmoid(logit_in), e)),
            OpacityEdit::Scale(s) => logit(sigmoid(logit_in) * s),
        }
    }
}
