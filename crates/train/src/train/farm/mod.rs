//! A database built across many machines: a manifest of subjects
//! ([`manifest`]), split into shards a scheduler runs in parallel
//! ([`shard`]: Slurm job arrays, Kubernetes Indexed Jobs), each subject
//! trained under a lock that survives no crash ([`lock`]) into a work area and
//! published by rename ([`folder`], [`run`]), and the progress of it all read
//! without disturbing it ([`status`]). No service of our own: the shared
//! file system is the only meeting point.

pub mod folder;
pub mod lock;
pub mod manifest;
pub mod run;
pub mod shard;
pub mod status;
