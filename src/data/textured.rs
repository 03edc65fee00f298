//! A user's own mesh, read as any OBJ is (through `tobj`): polygons triangulated,
//! negative indices, groups and objects, normals, texture coordinates and the material
//! library (`mtllib`/`usemtl`), for `doma warp --mesh` and `doma export --mesh`.
//!
//! Why two OBJ readers: trajectories and the meshes beside `.traj` files need the strict
//! reader of [`super::mesh`], which keeps the file's vertex order (vertex `i` is point `i`)
//! and refuses anything else. A textured mesh for display has UV seams: `tobj` gives each
//! distinct (position, UV, normal) corner its own vertex, which reorders and duplicates
//! positions. That is right for warping and rendering (every copy warps alike) and wrong
//! for matching points, so the strict reader stays for trajectories.

use std::io::Write;
use std::path::{Path, PathBuf};

use crate::io::{InputKind, check_input, read_input, read_named, resolve_named};
use crate::{DomaError, Result};

/// One part of a [`TexturedMesh`] (an `o`/`g` group), with its own vertices.
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
    /// The material's index into [`TexturedMesh::materials`], if any.
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

/// An OBJ with everything a viewer needs to show it textured.
#[derive(Clone, Debug, PartialEq)]
pub struct TexturedMesh {
    /// The file it came from.
    pub path: PathBuf,
    /// Its groups.
    pub parts: Vec<Part>,
    /// The materials of its `mtllib` files.
    pub materials: Vec<Material>,
    /// The `mtllib` names, as written in the file (relative to its folder).
    pub mtllibs: Vec<String>,
}

impl TexturedMesh {
    /// Reads `path` (a regular file, bounded: [`crate::io::read_input`]). A malformed OBJ,
    /// or a `.mtl` that it names and that is missing, malformed, or outside the OBJ's
    /// folder once links are resolved ([`crate::io::read_named`]), is an error naming the
    /// file. Each material's texture is kept relative to the OBJ's folder (it is written
    /// relative to its `.mtl`).
    pub fn read(path: &Path) -> Result<TexturedMesh> {
        let bytes = read_input(path, InputKind::Mesh)?;
        let text = String::from_utf8_lossy(&bytes);
        let malformed = |reason: String| DomaError::Malformed {
            path: path.to_path_buf(),
            reason,
        };
        let mtllibs: Vec<String> = text
            .lines()
            .filter_map(|l| l.trim().strip_prefix("mtllib"))
            .filter(|rest| rest.starts_with(char::is_whitespace))
            .map(|rest| rest.trim().to_string())
            .collect();
        let root = path.parent().unwrap_or(Path::new("."));
        let root = if root.as_os_str().is_empty() {
            Path::new(".")
        } else {
            root
        };
        // tobj asks for each `mtllib`; the first refusal is kept and reported as ours.
        let refused: std::cell::RefCell<Option<DomaError>> = Default::default();
        let load_mtl = |name: &Path| -> tobj::MTLLoadResult {
            let name = name.to_string_lossy();
            let loaded = read_named(root, path, &name, InputKind::Material).and_then(|b| {
                let mtl = root.join(name.as_ref());
                tobj::load_mtl_buf(&mut b.as_slice()).map_err(|e| DomaError::Malformed {
                    path: mtl,
                    reason: format!("not a readable material library: {e}"),
                })
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
                    refused.borrow_mut().get_or_insert(e);
                    Err(tobj::LoadError::OpenFileFailed)
                }
            }
        };
        let (models, materials) =
            tobj::load_obj_buf(&mut bytes.as_slice(), &tobj::GPU_LOAD_OPTIONS, load_mtl)
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
        Ok(TexturedMesh {
            path: path.to_path_buf(),
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

    /// Every vertex of every part, in order (what is warped).
    pub fn positions(&self) -> Vec<[f32; 3]> {
        self.parts
            .iter()
            .flat_map(|p| p.positions.iter().copied())
            .collect()
    }

    /// The vertex count over all parts.
    pub fn vertex_count(&self) -> usize {
        self.parts.iter().map(|p| p.positions.len()).sum()
    }

    /// Writes the mesh with its vertices moved to `positions` (all parts, in order, as
    /// [`TexturedMesh::positions`] lists them) as an OBJ: the `mtllib` lines, then per part
    /// `o`, `v`, `vt`, `vn` (recomputed from the moved vertices), `usemtl` and the faces.
    pub fn write_obj<W: Write>(&self, mut w: W, positions: &[[f32; 3]]) -> std::io::Result<()> {
        assert_eq!(
            positions.len(),
            self.vertex_count(),
            "one position per vertex"
        );
        w.write_all(b"# written by doma\n")?;
        for lib in &self.mtllibs {
            writeln!(w, "mtllib {lib}")?;
        }
        let mut offset = 0usize;
        for part in &self.parts {
            let n = part.positions.len();
            let moved = &positions[offset..offset + n];
            writeln!(
                w,
                "o {}",
                if part.name.is_empty() {
                    "mesh"
                } else {
                    &part.name
                }
            )?;
            for v in moved {
                writeln!(w, "v {} {} {}", v[0], v[1], v[2])?;
            }
            if let Some(uv) = &part.texcoords {
                for t in uv {
                    writeln!(w, "vt {} {}", t[0], t[1])?;
                }
            }
            for nrm in super::mesh::vertex_normals(moved, &part.triangles) {
                writeln!(w, "vn {} {} {}", nrm[0], nrm[1], nrm[2])?;
            }
            if let Some(m) = part.material {
                writeln!(w, "usemtl {}", self.materials[m].name)?;
            }
            for f in &part.triangles {
                let [a, b, c] = f.map(|i| offset + i as usize + 1);
                match part.texcoords {
                    Some(_) => writeln!(w, "f {a}/{a}/{a} {b}/{b}/{b} {c}/{c}/{c}")?,
                    None => writeln!(w, "f {a}//{a} {b}//{b} {c}//{c}")?,
                }
            }
            offset += n;
        }
        Ok(())
    }

    /// The material libraries and the textures they name, each resolved as
    /// [`crate::io::read_named`] resolves it (inside the OBJ's folder, links resolved) and
    /// checked to be a regular file within its bound: `(resolved path, name, kind)`. A
    /// refusal is an error naming the file that names it.
    pub fn material_files(&self) -> Result<Vec<(PathBuf, String, InputKind)>> {
        let root = self.path.parent().unwrap_or(Path::new("."));
        let root = if root.as_os_str().is_empty() {
            Path::new(".")
        } else {
            root
        };
        let libraries = self.mtllibs.iter().map(|m| (m, InputKind::Material));
        let textures = self
            .materials
            .iter()
            .filter_map(|m| m.diffuse_texture.as_ref())
            .map(|t| (t, InputKind::Texture));
        libraries
            .chain(textures)
            .map(|(name, kind)| {
                let (from, _) = resolve_named(root, &self.path, name)?;
                check_input(&from, kind)?;
                Ok((from, name.clone(), kind))
            })
            .collect()
    }

    /// Copies [`TexturedMesh::material_files`] next to frames written into `out`, so that
    /// the frames' `mtllib` lines resolve there.
    pub fn copy_materials(&self, out: &Path) -> Result<()> {
        for (from, name, kind) in self.material_files()? {
            let to = out.join(&name);
            if std::fs::canonicalize(&to).is_ok_and(|t| t == from) {
                continue;
            }
            let bytes = read_input(&from, kind)?;
            if let Some(dir) = to.parent() {
                std::fs::create_dir_all(dir).map_err(|e| DomaError::io(dir, e))?;
            }
            crate::io::write_atomic(&to, &bytes)?;
        }
        Ok(())
    }
}
