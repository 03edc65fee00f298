//! A material library never panics the display-mesh reader: the input is the library that
//! a one-triangle OBJ names. An accepted mesh's material index exists, and a texture name
//! comes back below the library's folder, or absolute as written (which the containment
//! check of doma's reader then refuses).
#![no_main]
use libfuzzer_sys::fuzz_target;

const OBJ: &[u8] = b"mtllib lib/m.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl m\nf 1 2 3\n";

fuzz_target!(|data: &[u8]| {
    let loader = |name: &str| {
        assert_eq!(name, "lib/m.mtl");
        Ok::<_, ()>(data.to_vec())
    };
    if let Ok(mesh) = doma_formats::textured::parse_textured(OBJ, loader) {
        for part in &mesh.parts {
            if let Some(m) = part.material {
                assert!(m < mesh.materials.len());
            }
        }
        for m in &mesh.materials {
            if let Some(t) = &m.diffuse_texture {
                assert!(
                    t.starts_with("lib") || std::path::Path::new(t).has_root(),
                    "{t}"
                );
            }
        }
    }
});
