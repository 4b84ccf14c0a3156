//! File formats: pickles, npy/npz, PLY, OBJ, FLAME models and masks,
//! GaussianAvatars avatar folders, folder databases and the fixtures generator.

pub mod avatar;
pub mod fixtures;
pub mod flame;
pub mod folder;
pub mod npy;
pub mod obj;
pub mod pickle;
pub mod pickle_write;
pub mod ply;
