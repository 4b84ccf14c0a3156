//! `eval --composite --arrays DIR`: each view's pictures and labels as a
//! numpy `.npz`, so the error can be taken apart pixel by pixel (by region,
//! band, frequency, against each source's own render) without changing the
//! evaluator. One file per view, `{split}_t{timestep}_c{camera}.npz`:
//!
//! - `composite`, `truth`: float32 (H, W, 3), display RGB in [0, 1] on black;
//! - `head`, `band`: int32 (H, W), 1 where the pixel is measured (the head)
//!   or lies in the border band, else 0;
//! - `region`: int32 (H, W), the region shown (`Region::index`, the order
//!   of `region_names` in the file), −1 off the head;
//! - `source`: int32 (H, W), the database index of the source the recipe
//!   assigns there, −1 off the head;
//! - `region_names`: the regions' names, one uint32 code point row each
//!   (numpy: `''.join(map(chr, row)).rstrip('\0')`);
//! - per source the ceiling draws, `ceiling_{name}`,
//!   `ceiling_{name}_truth` and `ceiling_{name}_region`: that source's own
//!   render, its own ground truth and the region its mesh shows (the
//!   ceiling's head is where that region is not −1).

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
    /// Per source the ceiling draws: its name, its own view and the
    /// regions of the model's triangles.
    pub(super) ceilings: Vec<(&'a str, &'a SourceView)>,
    /// Per triangle of the model, its region.
    pub(super) triangle_regions: &'a [Region],
}

/// Makes the folder the arrays go into; a one-line error where it cannot.
pub(super) fn prepare(dir: &Path) -> Result<()> {
    std::fs::create_dir_all(dir).map_err(|e| {
        Error::input(format!(
            "--arrays {}: cannot make the folder: {e}",
            dir.display()
        ))
    })
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
    let flag = |v: &[bool]| map(v.iter().map(|&b| i32::from(b)).collect());
    let region = |r: Option<Region>| r.map_or(-1, |r| r.index() as i32);
    let labels = view.labels;
    let mut arrays: Vec<(String, Vec<u8>)> = vec![
        ("composite".into(), picture(view.composite)),
        ("truth".into(), picture(view.truth)),
        ("head".into(), flag(&labels.head)),
        ("band".into(), flag(&labels.band)),
        (
            "region".into(),
            map(labels.region.iter().map(|&r| region(r)).collect()),
        ),
        (
            "source".into(),
            map(labels
                .source
                .iter()
                .map(|&s| i32::try_from(s).unwrap_or(-1))
                .collect()),
        ),
        ("region_names".into(), region_names()),
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
    let path = dir.join(format!("{stem}.npz"));
    write_npz(&path, &named, false)
        .map_err(|e| Error::input(format!("--arrays {}: {e}", path.display())))
}

/// The regions' names in index order, one row of code points each, padded
/// with zeros to the longest.
fn region_names() -> Vec<u8> {
    let names: Vec<&str> = Region::ALL.iter().map(|r| r.name()).collect();
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
