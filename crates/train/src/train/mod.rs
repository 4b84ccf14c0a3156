//! Making source avatars: a GaussianAvatars-style trainer. This layer holds
//! the differentiable renderer — dual-number geometry ([`dual`], [`project`]),
//! a tile rasteriser with its backward pass ([`raster`]: `cpu` in f64,
//! `gpu` on wgpu) and the parameter
//! bookkeeping that joins them ([`model`]). It sits above `render` because it
//! shares the renderers' numerics (projection constants, SH basis) and is
//! checked against them.

pub mod adam;
pub mod capture;
pub mod composite_eval;
pub mod dataset;
pub mod dual;
pub mod farm;
pub mod fit_store;
pub mod hole_metrics;
pub mod holes;
pub mod loss;
pub mod model;
pub mod posing;
pub mod project;
pub mod raster;
mod seam_base_detail;
pub mod seam_fit;
mod seam_light;
mod seam_own_shape;
#[cfg(test)]
mod seam_test_people;
mod seam_wholes;
pub mod sitter;
pub mod target;
pub mod trainer;
