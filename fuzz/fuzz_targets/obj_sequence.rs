//! OBJ-sequence loading never panics: the input is split at NUL bytes into frames, each
//! parsed as OBJ text, then stacked; an accepted sequence has one finite position per
//! vertex and frame, and every face indexes a vertex.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let mut meshes = Vec::new();
    for part in data.split(|&b| b == 0) {
        let Ok(text) = std::str::from_utf8(part) else { return };
        match doma_formats::obj::parse_obj(text) {
            Ok(m) => meshes.push(m),
            Err(_) => return,
        }
    }
    if let Ok(frames) = doma_formats::obj::stack_frames(&meshes) {
        assert_eq!(frames.positions.len(), 3 * frames.frames * frames.points);
        assert!(frames.positions.iter().all(|v| v.is_finite()));
        for m in &meshes {
            assert!(m.faces.iter().flatten().all(|&i| (i as usize) < m.vertices.len()));
        }
    }
});
