//! The safe pickle reader must never panic, loop or allocate beyond its input.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(v) = visage::io::pickle::parse(data) {
        let _ = v.as_array();
        let _ = v.get("v_template").map(|x| x.as_array());
    }
});
