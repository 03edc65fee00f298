//! The `.anime` reader never panics, and what it accepts writes back and parses again to
//! the same mesh (offsets are re-derived from the positions, so bytes may differ).
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(mesh) = doma_formats::anime::parse(data) {
        let bytes = doma_formats::anime::encode(&mesh).expect("a parsed mesh encodes");
        let again = doma_formats::anime::parse(&bytes).expect("an encoded mesh parses");
        assert_eq!(again.faces, mesh.faces);
        assert_eq!(again.frames.frames, mesh.frames.frames);
    }
});
