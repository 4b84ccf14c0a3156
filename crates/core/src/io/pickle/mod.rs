//! A safe reader for the subset of Python pickles that FLAME model and mask
//! files use: dicts, lists, tuples, strings, numbers, numpy arrays (any byte
//! order, C or Fortran order), scipy.sparse csc/csr matrices and chumpy `Ch`
//! wrappers, from Python 2 (latin-1 strings) or 3 pickles, protocols 0-5.
//!
//! It never executes anything: `GLOBAL`/`STACK_GLOBAL` resolve only to the
//! constructors listed in [`ALLOWED_GLOBALS`], interpreted here as data
//! builders; any other global is an error naming it. Allocations are bounded by
//! the input size (every element comes from at least one input byte, and arrays
//! must match the bytes that carry them).
//!
//! The reader is three steps, one file each: `machine.rs` runs the pickle's
//! opcodes over a heap of shared objects, `builders.rs` turns the few Python
//! constructors it may name into data, and `value.rs` holds what comes out;
//! `escapes.rs` decodes protocol 0's text forms for the first two.

mod builders;
mod escapes;
mod machine;
mod value;

pub use builders::ALLOWED_GLOBALS;
pub use machine::parse;
pub use value::{Dtype, NdArray, SparseMatrix, Value};

/// Reads a pickle file.
pub fn read(path: &std::path::Path) -> super::Result<Value> {
    let data = super::read_file(path)?;
    parse(&data).map_err(|e| e.in_file(path))
}

#[cfg(test)]
mod tests;
