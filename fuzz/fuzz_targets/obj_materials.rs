//! An OBJ with its material libraries never panics the display-mesh reader: the input is
//! split at the first NUL into the OBJ and the bytes every `mtllib` it names reads as.
//! An accepted mesh has finite vertices, faces that index its part's vertices, one UV per
//! vertex when it has UVs, and materials that exist.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let (obj, mtl) = match data.iter().position(|&b| b == 0) {
        Some(at) => (&data[..at], &data[at + 1..]),
        None => (data, &[][..]),
    };
    let loader = |_: &str| Ok::<_, ()>(mtl.to_vec());
    if let Ok(mesh) = doma_formats::textured::parse_textured(obj, loader) {
        check(&mesh);
    }
});

fn check(mesh: &doma_formats::textured::Textured) {
    assert!(!mesh.parts.is_empty());
    for part in &mesh.parts {
        assert!(part.positions.iter().flatten().all(|c| c.is_finite()));
        let n = part.positions.len();
        assert!(part.triangles.iter().flatten().all(|&i| (i as usize) < n));
        if let Some(uv) = &part.texcoords {
            assert_eq!(uv.len(), n);
        }
        if let Some(m) = part.material {
            assert!(m < mesh.materials.len());
        }
    }
}
