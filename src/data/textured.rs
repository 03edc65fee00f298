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

use doma_formats::textured::{TexturedError, parse_textured};

use crate::io::{InputKind, check_input, read_input, read_named, resolve_named};
use crate::{DomaError, Result};

pub use doma_formats::textured::{Material, Part};

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
        let parsed = parse_textured(&bytes, |name| read_named(path, name, InputKind::Material))
            .map_err(|e| match e {
                TexturedError::Load(e) => e,
                TexturedError::Material { name, reason } => DomaError::Malformed {
                    path: crate::io::folder_of(path).join(name),
                    reason,
                },
                TexturedError::Obj(reason) => DomaError::Malformed {
                    path: path.to_path_buf(),
                    reason,
                },
            })?;
        Ok(TexturedMesh {
            path: path.to_path_buf(),
            parts: parsed.parts,
            materials: parsed.materials,
            mtllibs: parsed.mtllibs,
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
        let libraries = self.mtllibs.iter().map(|m| (m, InputKind::Material));
        let textures = self
            .materials
            .iter()
            .filter_map(|m| m.diffuse_texture.as_ref())
            .map(|t| (t, InputKind::Texture));
        libraries
            .chain(textures)
            .map(|(name, kind)| {
                let from = resolve_named(&self.path, name)?;
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
