//! Scene readers: the generic PLY element reader, the standard 3DGS and
//! GaussianAvatars PLY layouts, SuperSplat's compressed PLY, `.splat` and SPZ.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = visage::io::ply::read_element(data, "vertex");
    let _ = visage::io::ply::parse_splat_ply(data);
    let _ = visage::io::avatar::parse_bound_ply(data, 10_474);
    let _ = visage::io::compressed_ply::parse_compressed_ply(data);
    let _ = visage::io::splat::parse_splat(data);
    let _ = visage::io::spz::parse_spz(data);
});
