//! Any OBJ for display, with its material libraries, parsed through `tobj`: polygons
//! triangulated, negative indices, groups and objects, normals, texture coordinates and
//! the `mtllib`/`usemtl` materials. The caller reads each material library (it decides
//! where files may come from); this module only parses bytes, so that it can be fuzzed.
//!
//! `tobj` gives each distinct (position, UV, normal) corner its own vertex, which is right
//! for warping and rendering and wrong for matching points: trajectories use the strict
//! reader of [`crate::obj`].

use std::path::Path;

/// One part of a [`Textured`] mesh (an `o`/`g` group), with its own vertices.
#[derive(Clone, Debug, PartialEq)]
pub struct Part {
    /// The group's name.
    pub name: String,
    /// Positions, `[V, 3]`.
    pub positions: Vec<[f32; 3]>,
    /// Texture coordinates per vertex, if the file has them.
    pub texcoords: Option<Vec<[f32; 2]>>,
    /// Triangles (indices into this part's vertices).
    pub triangles: Vec<[u32; 3]>,
    /// The material's index into [`Textured::materials`], if any.
    pub material: Option<usize>,
}

/// A material of the OBJ's material library, as far as doma carries it.
#[derive(Clone, Debug, PartialEq)]
pub struct Material {
    /// Its `newmtl` name (what `usemtl` refers to).
    pub name: String,
    /// `Kd`, the diffuse colour.
    pub diffuse: Option<[f32; 3]>,
    /// `map_Kd`, the diffuse texture, relative to the OBJ's folder (the `.mtl` writes it
    /// relative to itself).
    pub diffuse_texture: Option<String>,
}

/// A parsed OBJ: its parts, the materials of its libraries, and the `mtllib` names as
/// written.
#[derive(Clone, Debug, PartialEq)]
pub struct Textured {
    /// Its groups, each with vertices.
    pub parts: Vec<Part>,
    /// The materials of its `mtllib` files, in order.
    pub materials: Vec<Material>,
    /// The `mtllib` names, as written in the file (relative to its folder).
    pub mtllibs: Vec<String>,
}

/// Why an OBJ was not read.
#[derive(Debug, PartialEq)]
pub enum TexturedError<E> {
    /// The caller's loader refused a material library.
    Load(E),
    /// The material library `name` (as the OBJ writes it) does not parse.
    Material {
        /// Its name.
        name: String,
        /// What is wrong.
        reason: String,
    },
    /// The OBJ itself is malformed.
    Obj(String),
}

/// Refuses what `tobj` 4.0 would panic on in a material library: a colour (`Ka`, `Kd`,
/// `Ks`, `Ke`) with fewer than three values (found by fuzzing).
fn check_mtl(bytes: &[u8]) -> Result<(), String> {
    for (i, line) in String::from_utf8_lossy(bytes).lines().enumerate() {
        let mut words = line.split_whitespace();
        if let Some(key @ ("Ka" | "Kd" | "Ks" | "Ke")) = words.next()
            && words.count() < 3
        {
            return Err(format!("line {}: `{key}` needs three numbers", i + 1));
        }
    }
    Ok(())
}

/// Refuses a face (`f`, `l`, `p`) whose position, UV or normal index does not name an
/// element declared before it (1-based, or negative from the last): `tobj` 4.0 computes
/// with such indices unchecked, which overflows (found by fuzzing with overflow checks).
fn check_obj(text: &str) -> Result<(), String> {
    let mut counts = [0i64; 3];
    for (i, line) in text.lines().enumerate() {
        let mut words = line.split_whitespace();
        match words.next() {
            Some("v") => counts[0] += 1,
            Some("vt") => counts[1] += 1,
            Some("vn") => counts[2] += 1,
            Some("f" | "l" | "p") => {
                for corner in words {
                    for (k, index) in corner.split('/').take(3).enumerate() {
                        let Ok(index) = index.parse::<i64>() else {
                            continue;
                        };
                        if index == 0 || index.unsigned_abs() > counts[k].unsigned_abs() {
                            let kind = ["vertex", "texture coordinate", "normal"][k];
                            return Err(format!(
                                "line {}: face index {index} names no {kind} declared before it",
                                i + 1
                            ));
                        }
                    }
                }
            }
            _ => {}
        }
    }
    Ok(())
}

/// Parses an OBJ's bytes. `load_mtl` is handed each `mtllib` name as written and returns
/// the library's bytes, or why it cannot; every library named is loaded, and the first
/// refusal is returned. A texture (`map_Kd`) is returned relative to the OBJ's folder (the
/// library writes it relative to itself).
pub fn parse_textured<E>(
    obj: &[u8],
    load_mtl: impl Fn(&str) -> Result<Vec<u8>, E>,
) -> Result<Textured, TexturedError<E>> {
    let text = String::from_utf8_lossy(obj);
    let malformed = |reason: String| TexturedError::Obj(reason);
    check_obj(&text).map_err(malformed)?;
    let mtllibs: Vec<String> = text
        .lines()
        .filter_map(|l| l.trim().strip_prefix("mtllib"))
        .filter(|rest| rest.starts_with(char::is_whitespace))
        .map(|rest| rest.trim().to_string())
        .collect();
    // tobj asks for each `mtllib`; the first refusal is kept and returned as the caller's.
    let refused: std::cell::RefCell<Option<TexturedError<E>>> = std::cell::RefCell::new(None);
    let loader = |name: &Path| -> tobj::MTLLoadResult {
        let name = name.to_string_lossy();
        let loaded = load_mtl(&name).map_err(TexturedError::Load).and_then(|b| {
            let bad = |reason: String| TexturedError::Material {
                name: name.to_string(),
                reason,
            };
            check_mtl(&b).map_err(bad)?;
            tobj::load_mtl_buf(&mut b.as_slice())
                .map_err(|e| bad(format!("not a readable material library: {e}")))
        });
        match loaded {
            Ok((mut materials, names)) => {
                // A texture is named relative to its `.mtl`; keep it relative to the OBJ.
                let dir = Path::new(name.as_ref()).parent().unwrap_or(Path::new(""));
                for m in &mut materials {
                    if let Some(t) = &m.diffuse_texture {
                        m.diffuse_texture = Some(dir.join(t).to_string_lossy().into_owned());
                    }
                }
                Ok((materials, names))
            }
            Err(e) => {
                let mut first = refused.borrow_mut();
                if first.is_none() {
                    *first = Some(e);
                }
                Err(tobj::LoadError::OpenFileFailed)
            }
        }
    };
    let (models, materials) = tobj::load_obj_buf(&mut &obj[..], &tobj::GPU_LOAD_OPTIONS, loader)
        .map_err(|e| malformed(format!("not a readable OBJ: {e}")))?;
    if let Some(e) = refused.into_inner() {
        return Err(e);
    }
    let materials = match materials {
        Ok(m) => m,
        Err(_) if mtllibs.is_empty() => Vec::new(),
        Err(e) => return Err(malformed(format!("its materials: {e}"))),
    };
    let mut parts = Vec::with_capacity(models.len());
    for model in models {
        let m = model.mesh;
        let positions: Vec<[f32; 3]> = m
            .positions
            .chunks_exact(3)
            .map(|c| [c[0], c[1], c[2]])
            .collect();
        if let Some(i) = positions
            .iter()
            .position(|p| p.iter().any(|c| !c.is_finite()))
        {
            return Err(malformed(format!(
                "group `{}`: vertex {i} has a coordinate that is not finite",
                model.name
            )));
        }
        let texcoords = (!m.texcoords.is_empty()).then(|| {
            m.texcoords
                .chunks_exact(2)
                .map(|c| [c[0], c[1]])
                .collect::<Vec<_>>()
        });
        if texcoords
            .as_ref()
            .is_some_and(|t| t.len() != positions.len())
        {
            return Err(malformed(format!(
                "group `{}`: texture coordinates do not match the vertices",
                model.name
            )));
        }
        let triangles: Vec<[u32; 3]> = m
            .indices
            .chunks_exact(3)
            .map(|c| [c[0], c[1], c[2]])
            .collect();
        if triangles
            .iter()
            .flatten()
            .any(|&i| i as usize >= positions.len())
        {
            return Err(malformed(format!(
                "group `{}`: a face refers to a vertex that does not exist",
                model.name
            )));
        }
        if positions.is_empty() {
            continue;
        }
        parts.push(Part {
            name: model.name,
            positions,
            texcoords,
            triangles,
            material: m.material_id.filter(|&i| i < materials.len()),
        });
    }
    if parts.is_empty() {
        let vertices = text
            .lines()
            .filter(|l| l.trim_start().starts_with("v "))
            .count();
        return Err(malformed(if vertices == 0 {
            "no vertices".into()
        } else {
            format!("{vertices} vertices but no faces; a mesh needs faces")
        }));
    }
    Ok(Textured {
        parts,
        materials: materials
            .into_iter()
            .map(|m| Material {
                name: m.name,
                diffuse: m.diffuse,
                diffuse_texture: m.diffuse_texture,
            })
            .collect(),
        mtllibs,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn no_library(name: &str) -> Result<Vec<u8>, String> {
        Err(format!("{name}: no library here"))
    }

    #[test]
    fn a_quad_with_uvs_is_two_triangles_and_a_library_names_its_texture() {
        let obj = b"mtllib sub/m.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n\
                    vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nusemtl m\nf 1/1 2/2 3/3 4/4\n";
        let mesh = parse_textured(obj, |name| {
            assert_eq!(name, "sub/m.mtl");
            Ok::<_, String>(b"newmtl m\nKd 1 0.5 0\nmap_Kd t.png\n".to_vec())
        })
        .unwrap();
        assert_eq!(mesh.parts.len(), 1);
        assert_eq!(mesh.parts[0].triangles.len(), 2);
        assert_eq!(mesh.parts[0].material, Some(0));
        assert_eq!(mesh.materials[0].diffuse, Some([1.0, 0.5, 0.0]));
        assert_eq!(
            mesh.materials[0].diffuse_texture.as_deref(),
            Some("sub/t.png")
        );
        assert_eq!(mesh.mtllibs, ["sub/m.mtl"]);
    }

    #[test]
    fn the_loaders_refusal_and_bad_files_are_errors_not_panics() {
        let tri = b"mtllib a.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n";
        assert_eq!(
            parse_textured(tri, no_library),
            Err(TexturedError::Load("a.mtl: no library here".into()))
        );
        let bare = b"v 0 0 0\nv 1 0 0\nv 0 1 0\n";
        assert!(matches!(
            parse_textured(bare, no_library),
            Err(TexturedError::Obj(r)) if r.contains("3 vertices but no faces")
        ));
        // `Kd` with two values panicked inside tobj 4.0.5 (found by the fuzz target).
        let short = parse_textured(tri, |_| Ok::<_, String>(b"newmtl a\nKd 1 0\n".to_vec()));
        assert!(matches!(
            short,
            Err(TexturedError::Material { name, reason }) if name == "a.mtl" && reason.contains("line 2")
        ));
        // A UV index far before the first overflowed inside tobj 4.0.5 (fuzzing).
        let far = b"v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nf 1/-31 2/1 3/1\n";
        assert!(matches!(
            parse_textured(far, no_library),
            Err(TexturedError::Obj(r)) if r.contains("line 5") && r.contains("texture coordinate")
        ));
        let out_of_range = b"v 0 0 0\nv 1 0 0\nf 1 2 9\n";
        assert!(matches!(
            parse_textured(out_of_range, no_library),
            Err(TexturedError::Obj(_))
        ));
    }
}
