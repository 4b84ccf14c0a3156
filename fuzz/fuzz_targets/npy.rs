//! .npy and .npz readers: bounded, no panics.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = visage::io::npy::parse_npy(data);
    let _ = visage::io::npy::parse_npz(data);
});
