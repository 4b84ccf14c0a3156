//! `eval --composite --arrays DIR`: each view's pictures and labels as a
//! numpy `.npz`, so the error can be taken apart pixel by pixel (by region,
//! band, frequency, against each source's own render) without changing the
//! evaluator. One file per view, `{split}_t{timestep}_c{camera}.npz`:
//!
//! - `composite`, `truth`: float32 (H, W, 3), display RGB on black: the
//!   measured composite (the decomposition's last step) and its ground
//!   truth, as measured (the renderer does not clamp);
//! - `head`, `band`: int32 (H, W), 1 where the pixel is measured (the head)
//!   or lies in the head's border band, else 0;
//! - `region`: int32 (H, W), the region shown (`Region::index`, the order
//!   of `region_names`), −1 off the head;
//! - `source`: int32 (H, W), the database index (the order of
//!   `source_names`) of the source the recipe assigns there, −1 off the
//!   head;
//! - `region_names`, `source_names`: one uint32 code-point row per name,
//!   padded with zeros (numpy: `names.view(f'<U{names.shape[1]}')[:, 0]`);
//!   not a unicode array, which our own npy reader does not take;
//! - per source the ceiling draws, `ceiling_{name}`,
//!   `ceiling_{name}_truth` and `ceiling_{name}_region`: that source's own
//!   render, its own ground truth and the region its mesh shows where the
//!   ceiling measures (−1 elsewhere).
//!
//! An archive of the same view is overwritten; archives of other views
//! already in the folder are left as they are.

use std::path::Path;

use super::pixels::Labels;
use super::tally::SourceView;
use crate::error::{Error, Result};
use crate::io::npy::{write_npy, write_npz, NpyData};
use crate::model::regions::Region;

/// One view's arrays, as [`write`] stores them.
pub(super) struct ViewArrays<'a> {
    /// Image width and height in pixels.
    pub(super) size: [u32; 2],
    /// What each pixel shows.
    pub(super) labels: &'a Labels,
    /// The composite measured (the decomposition's last step).
    pub(super) composite: &'a [f64],
    /// Its ground truth.
    pub(super) truth: &'a [f64],
    /// Per source the ceiling draws: its name and its own view.
    pub(super) ceilings: Vec<(&'a str, &'a SourceView)>,
    /// Per triangle of the model, its region.
    pub(super) triangle_regions: &'a [Region],
    /// Every source of the database, by index (what `source` counts in).
    pub(super) source_names: Vec<&'a str>,
}

/// Makes the folder the arrays go into: an I/O error (exit 4, as for any
/// output that cannot be written) where it cannot.
pub fn prepare(dir: &Path) -> Result<()> {
    std::fs::create_dir_all(dir).map_err(|e| Error::io("create", dir, e))
}

/// Writes `view` as `dir/{stem}.npz` (uncompressed: float pictures hardly
/// compress, and numpy memory-maps what is stored).
pub(super) fn write(dir: &Path, stem: &str, view: &ViewArrays) -> Result<()> {
    let [w, h] = view.size.map(|v| v as usize);
    let picture = |v: &[f64]| {
        let data: Vec<f32> = v.iter().map(|&x| x as f32).collect();
        write_npy(&[h, w, 3], NpyData::F32(&data))
    };
    let map = |v: Vec<i32>| write_npy(&[h, w], NpyData::I32(&v));
    let region = |r: Option<Region>| r.map_or(-1, |r| r.index() as i32);
    let labels = view.labels;
    // The labels give a region and a source wherever a triangle covers a
    // pixel's centre; only the head (where the mask is over half too) is
    // measured, and the archive says what was.
    let head = &labels.head;
    let pixels = 0..head.len();
    let regions = pixels
        .clone()
        .map(|p| {
            if head[p] {
                region(labels.region[p])
            } else {
                -1
            }
        })
        .collect();
    let sources = pixels
        .clone()
        .map(|p| match labels.source[p] {
            s if head[p] && s != u32::MAX => s as i32,
            _ => -1,
        })
        .collect();
    let band = pixels
        .map(|p| i32::from(head[p] && labels.band[p]))
        .collect();
    let region_names: Vec<&str> = Region::ALL.iter().map(|r| r.name()).collect();
    let mut arrays: Vec<(String, Vec<u8>)> = vec![
        ("composite".into(), picture(view.composite)),
        ("truth".into(), picture(view.truth)),
        (
            "head".into(),
            map(head.iter().map(|&b| i32::from(b)).collect()),
        ),
        ("band".into(), map(band)),
        ("region".into(), map(regions)),
        ("source".into(), map(sources)),
        ("region_names".into(), names(&region_names)),
        ("source_names".into(), names(&view.source_names)),
    ];
    for (name, own) in &view.ceilings {
        let shown = own
            .shown
            .iter()
            .map(|t| region(t.and_then(|t| view.triangle_regions.get(t as usize).copied())))
            .collect();
        arrays.push((format!("ceiling_{name}"), picture(&own.image)));
        arrays.push((format!("ceiling_{name}_truth"), picture(&own.goal)));
        arrays.push((format!("ceiling_{name}_region"), map(shown)));
    }
    let (names, bytes): (Vec<String>, Vec<Vec<u8>>) = arrays.into_iter().unzip();
    let named: Vec<(&str, Vec<u8>)> = names.iter().map(String::as_str).zip(bytes).collect();
    Ok(write_npz(&dir.join(format!("{stem}.npz")), &named, false)?)
}

/// `names` in order as an npy array: one row of code points each, padded
/// with zeros to the longest.
fn names(names: &[&str]) -> Vec<u8> {
    let width = names.iter().map(|n| n.chars().count()).max().unwrap_or(0);
    let codes: Vec<u32> = names
        .iter()
        .flat_map(|n| {
            let mut row: Vec<u32> = n.chars().map(|c| c as u32).collect();
            row.resize(width, 0);
            row
        })
        .collect();
    write_npy(&[names.len(), width], NpyData::U32(&codes))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::npy::read_npz;

    /// Two pixels: one on the head, one whose centre a triangle covers but
    /// whose mask is under half — not measured, so not labelled either.
    #[test]
    fn only_the_measured_head_is_labelled() {
        let labels = Labels {
            head: vec![true, false],
            region: vec![Some(Region::Nose), Some(Region::Skin)],
            source: vec![2, 0],
            band: vec![true, true],
            beside: vec![None, None],
        };
        let own = SourceView {
            image: vec![0.25; 6],
            goal: vec![0.5; 6],
            ssim: vec![1.0; 2],
            shown: vec![Some(1), None],
            band: vec![false; 2],
        };
        let regions = [Region::Skin, Region::Nose];
        let view = ViewArrays {
            size: [2, 1],
            labels: &labels,
            composite: &[0.1, 0.2, 0.3, 0.4, 0.5, 0.6],
            truth: &[0.0; 6],
            ceilings: vec![("cleo", &own)],
            triangle_regions: &regions,
            source_names: vec!["ada", "bram", "cleo"],
        };
        let dir = std::env::temp_dir().join(format!("visage-arrays-{}", std::process::id()));
        prepare(&dir).unwrap();
        write(&dir, "train_t0_c1", &view).unwrap();
        let arrays = read_npz(&dir.join("train_t0_c1.npz")).unwrap();
        let nose = Region::Nose.index() as f64;
        assert_eq!(arrays["head"].data, [1.0, 0.0]);
        assert_eq!(arrays["region"].data, [nose, -1.0]);
        assert_eq!(arrays["source"].data, [2.0, -1.0]);
        assert_eq!(arrays["band"].data, [1.0, 0.0]);
        assert_eq!(arrays["composite"].shape, [1, 2, 3]);
        assert!((arrays["composite"].data[5] - 0.6).abs() < 1e-7);
        assert_eq!(arrays["ceiling_cleo_region"].data, [nose, -1.0]);
        assert_eq!(arrays["ceiling_cleo_truth"].data, [0.5; 6]);
        let names = &arrays["source_names"];
        assert_eq!(names.shape, [3, 4]);
        assert_eq!(
            names.data[8..],
            ['c', 'l', 'e', 'o'].map(|c| c as u32 as f64)
        );
        assert_eq!(
            names.data[..4],
            ['a', 'd', 'a', '\0'].map(|c| c as u32 as f64)
        );
        std::fs::remove_dir_all(&dir).ok();
        // A folder under a file cannot be made: an I/O error, not a panic.
        let file = std::env::temp_dir().join(format!("visage-arrays-file-{}", std::process::id()));
        std::fs::write(&file, b"x").unwrap();
        let err = prepare(&file.join("sub")).unwrap_err();
        assert!(matches!(err, Error::Io(_)), "{err}");
        std::fs::remove_file(&file).ok();
    }
}
