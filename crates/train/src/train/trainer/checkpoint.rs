//! The trainer's checkpoint: everything a resumed run needs to continue
//! exactly where a run stopped — parameters, optimiser moments,
//! densification statistics, the view order and the random generator's
//! position — as an `.npz` numpy reads, every array named once in
//! [`Array`].

use std::path::Path;

use super::{Groups, TrainOptions, Trainer};
use crate::error::{Error, Result};
use crate::io::npy::{read_npz, write_npy, write_npz, NpyData};
use crate::io::pickle::NdArray;
use crate::model::head::HeadModel;
use crate::train::dataset::Dataset;
use crate::train::model::{Trainable, SH_STRIDE};
use crate::train::project::Geometry;

/// The checkpoint's arrays, in the order they are written.
#[derive(Clone, Copy)]
enum Array {
    /// Each Gaussian's triangle (u32, n).
    Binding,
    /// Position, log-scale and rotation (f64, n × 10).
    Geometry,
    /// Opacity before the sigmoid (f64, n).
    OpacityLogit,
    /// SH coefficients (f64, n × 48).
    Sh,
    /// Summed view-space gradient norms (f64, n).
    GradAccum,
    /// Steps each Gaussian was drawn since the last densification (u32, n).
    GradCount,
    /// Largest screen radius since then (f64, n).
    MaxRadius,
    /// Views left in this epoch's order (u32).
    Order,
    /// The random generator's word position (u32 × 4, low word first).
    RngWord,
    /// The seed (u32 × 2, low word first).
    Seed,
    /// Step, iterations, SH degree, opacity reset done, training views (f64 × 5).
    Scalars,
    /// The triangles trained on (u32).
    TrianglesKept,
}

impl Array {
    /// Every array, in the order they are written.
    const ALL: [Array; 12] = [
        Array::Binding,
        Array::Geometry,
        Array::OpacityLogit,
        Array::Sh,
        Array::GradAccum,
        Array::GradCount,
        Array::MaxRadius,
        Array::Order,
        Array::RngWord,
        Array::Seed,
        Array::Scalars,
        Array::TrianglesKept,
    ];

    /// The array's name in the `.npz`.
    fn name(self) -> &'static str {
        match self {
            Array::Binding => "binding",
            Array::Geometry => "geometry",
            Array::OpacityLogit => "opacity_logit",
            Array::Sh => "sh",
            Array::GradAccum => "grad_accum",
            Array::GradCount => "grad_count",
            Array::MaxRadius => "max_radius",
            Array::Order => "order",
            Array::RngWord => "rng_word",
            Array::Seed => "seed",
            Array::Scalars => "scalars",
            Array::TrianglesKept => "triangles_kept",
        }
    }
}

/// The parts of one Adam group's state, each an array named
/// `adam_{group}_{part}`.
const ADAM_PARTS: [&str; 3] = ["m", "v", "t"];

fn adam_name(group: &str, part: &str) -> String {
    format!("adam_{group}_{part}")
}

/// Entries of [`Array::Scalars`].
const SCALARS: usize = 5;

/// `x` as `k` little-endian 32-bit words.
fn words(x: u128, k: usize) -> Vec<u32> {
    (0..k).map(|i| (x >> (32 * i)) as u32).collect()
}

/// Words written by [`words`] read back.
fn from_words(words: &[f64]) -> u128 {
    words
        .iter()
        .enumerate()
        .fold(0u128, |acc, (i, &w)| acc | (w as u128) << (32 * i))
}

impl Trainer {
    /// Writes the checkpoint to a temporary name and renames it, so a crash
    /// while writing leaves the previous checkpoint.
    pub fn save_checkpoint(&mut self, path: &Path) -> Result<()> {
        let mut arrays: Vec<(String, Vec<u8>)> = Array::ALL
            .iter()
            .map(|&a| (a.name().to_string(), self.array(a)))
            .collect();
        for (group, adam) in Groups::NAMES.iter().zip(self.groups.all()) {
            let (m, v, t) = adam.state();
            let parts = [
                write_npy(&[m.len()], NpyData::F64(m)),
                write_npy(&[v.len()], NpyData::F64(v)),
                write_npy(&[1], NpyData::I32(&[t])),
            ];
            for (part, bytes) in ADAM_PARTS.iter().zip(parts) {
                arrays.push((adam_name(group, part), bytes));
            }
        }
        let named: Vec<(&str, Vec<u8>)> = arrays
            .iter()
            .map(|(k, v)| (k.as_str(), v.clone()))
            .collect();
        let partial = path.with_extension("npz.partial");
        write_npz(&partial, &named, false)?;
        std::fs::rename(&partial, path).map_err(|e| Error::io("write", path, e))
    }

    /// One array of the checkpoint, as `.npy` bytes.
    fn array(&self, array: Array) -> Vec<u8> {
        let m = &self.model;
        let n = m.len();
        match array {
            Array::Binding => write_npy(&[n], NpyData::U32(&m.binding)),
            Array::Geometry => {
                let geometry: Vec<f64> = m
                    .geometry
                    .iter()
                    .flat_map(|g| g.position.into_iter().chain(g.log_scale).chain(g.rotation))
                    .collect();
                write_npy(&[n, 10], NpyData::F64(&geometry))
            }
            Array::OpacityLogit => write_npy(&[n], NpyData::F64(&m.opacity_logit)),
            Array::Sh => write_npy(&[n, SH_STRIDE], NpyData::F64(&m.sh)),
            Array::GradAccum => write_npy(&[n], NpyData::F64(&self.grad_accum)),
            Array::GradCount => write_npy(&[n], NpyData::U32(&self.grad_count)),
            Array::MaxRadius => write_npy(&[n], NpyData::F64(&self.max_radius)),
            Array::Order => {
                let order: Vec<u32> = self.order.iter().map(|&o| o as u32).collect();
                write_npy(&[order.len()], NpyData::U32(&order))
            }
            Array::RngWord => write_npy(&[4], NpyData::U32(&words(self.rng.get_word_pos(), 4))),
            Array::Seed => write_npy(&[2], NpyData::U32(&words(self.options.seed as u128, 2))),
            Array::Scalars => {
                let scalars: [f64; SCALARS] = [
                    self.step as f64,
                    self.options.iterations as f64,
                    m.sh_degree as f64,
                    self.reset_done as u8 as f64,
                    self.targets.len() as f64,
                ];
                write_npy(&[SCALARS], NpyData::F64(&scalars))
            }
            Array::TrianglesKept => {
                write_npy(&[self.subset.len()], NpyData::U32(&self.subset.kept))
            }
        }
    }

    /// A trainer continuing from a checkpoint of a run on the same dataset
    /// (its seed and iteration count are the checkpoint's).
    pub fn resume(
        dataset: &Dataset,
        head: HeadModel,
        options: TrainOptions,
        path: &Path,
    ) -> Result<Self> {
        let arrays = Checkpoint {
            arrays: read_npz(path)?,
            path,
        };
        let scalars = arrays.get(Array::Scalars)?;
        let seed_words = arrays.get(Array::Seed)?;
        if scalars.len() != SCALARS || seed_words.len() != 2 {
            return Err(arrays.error("not a visage checkpoint (bad scalars)"));
        }
        let options = TrainOptions {
            iterations: scalars[1] as usize,
            seed: from_words(&seed_words) as u64,
            ..options
        };
        let mut trainer = Trainer::new(dataset, head, options)?;
        if scalars[4] as usize != trainer.targets.len() {
            return Err(arrays.error(&format!(
                "was made on a dataset of {} training views, this one has {}",
                scalars[4],
                trainer.targets.len()
            )));
        }
        let kept: Vec<u32> = arrays.get_u32(Array::TrianglesKept)?;
        if kept != trainer.subset.kept {
            return Err(arrays.error(&format!(
                "trained on {} triangles, this run keeps {}: give the same --cull-backfaces",
                kept.len(),
                trainer.subset.len()
            )));
        }
        trainer.model = arrays.model(trainer.subset.len(), (scalars[2] as u8).min(3))?;
        let n = trainer.model.len();
        trainer.step = scalars[0] as usize;
        trainer.reset_done = scalars[3] != 0.0;
        trainer.grad_accum = arrays.get(Array::GradAccum)?;
        trainer.grad_count = arrays.get_u32(Array::GradCount)?;
        trainer.max_radius = arrays.get(Array::MaxRadius)?;
        trainer.order = arrays
            .get(Array::Order)?
            .iter()
            .map(|&o| o as usize)
            .collect();
        let statistics = [
            trainer.grad_accum.len(),
            trainer.grad_count.len(),
            trainer.max_radius.len(),
        ];
        if trainer.order.iter().any(|&o| o >= trainer.targets.len())
            || statistics.iter().any(|&l| l != n)
        {
            return Err(arrays.error("training statistics do not fit the parameters"));
        }
        trainer
            .rng
            .set_word_pos(from_words(&arrays.get(Array::RngWord)?));
        for (group, adam) in Groups::NAMES.iter().zip(trainer.groups.all()) {
            let [m, v, t] = ADAM_PARTS.map(|part| arrays.get_named(&adam_name(group, part)));
            adam.restore(m?, v?, t?.first().copied().unwrap_or(0.0) as i32, n)
                .map_err(|e| arrays.error(&e))?;
        }
        Ok(trainer)
    }
}

/// A checkpoint's arrays as read, with the file's name for errors.
struct Checkpoint<'a> {
    arrays: std::collections::BTreeMap<String, NdArray>,
    path: &'a Path,
}

impl Checkpoint<'_> {
    fn error(&self, what: &str) -> Error {
        Error::input(format!("{}: {what}", self.path.display()))
    }

    fn get_named(&self, name: &str) -> Result<Vec<f64>> {
        self.arrays
            .get(name)
            .map(|a| a.data.clone())
            .ok_or_else(|| self.error(&format!("not a visage checkpoint (no '{name}')")))
    }

    fn get(&self, array: Array) -> Result<Vec<f64>> {
        self.get_named(array.name())
    }

    fn get_u32(&self, array: Array) -> Result<Vec<u32>> {
        Ok(self.get(array)?.iter().map(|&x| x as u32).collect())
    }

    /// The parameters, checked to fit together and `triangles`, and finite.
    fn model(&self, triangles: usize, sh_degree: u8) -> Result<Trainable> {
        let binding = self.get_u32(Array::Binding)?;
        let n = binding.len();
        let geometry = self.get(Array::Geometry)?;
        let sh = self.get(Array::Sh)?;
        let opacity = self.get(Array::OpacityLogit)?;
        let sizes_fit = geometry.len() == n * 10
            && sh.len() == n * SH_STRIDE
            && opacity.len() == n
            && binding.iter().all(|&b| (b as usize) < triangles)
            && geometry
                .iter()
                .chain(&sh)
                .chain(&opacity)
                .all(|x| x.is_finite());
        if !sizes_fit {
            return Err(
                self.error("parameters do not fit together or this head model (or are not finite)")
            );
        }
        Ok(Trainable {
            binding,
            geometry: geometry
                .chunks(10)
                .map(|c| Geometry {
                    position: [c[0], c[1], c[2]],
                    log_scale: [c[3], c[4], c[5]],
                    rotation: [c[6], c[7], c[8], c[9]],
                })
                .collect(),
            opacity_logit: opacity,
            sh,
            sh_degree,
        })
    }
}
