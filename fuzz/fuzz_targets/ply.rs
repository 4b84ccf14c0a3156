//! PLY readers: the generic element reader, standard 3DGS and GaussianAvatars layouts.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = visage::io::ply::read_element(data, "vertex");
    let _ = visage::io::ply::parse_splat_ply(data);
    let _ = visage::io::avatar::parse_bound_ply(data, 10_474);
});
