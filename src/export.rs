//! `doma export`: the fitted motion as one binary glTF 2.0 file (`.glb`), built with
//! `gltf-json`.
//!
//! The motion is stored as **morph targets**, one per frame, played by one animation on
//! the mesh's morph weights with linear interpolation between one-hot weight vectors (so
//! the shape between two keyframes is the linear blend of the two warped frames). glTF has
//! no other way to move vertices independently: skinning needs a skeleton, and a DOMA field
//! has none (every point has its own `(A, u)`). Morph targets play in Blender (imported as
//! shape keys with their animation) and in three.js-based viewers (`AnimationMixer`;
//! three.js binds morph targets as textures under WebGL 2, so their number is not capped).
//! Each target carries position and normal displacements; the base shape is the first
//! exported frame.
//!
//! The canonical shape is a user's mesh (`--mesh`, read with its UVs and materials, a
//! diffuse PNG/JPEG texture embedded), else the run's own first frame with its faces, else
//! the run's points (a `POINTS` primitive). `color_by_error` adds vertex colours: each
//! vertex's mean end-point error over the frames, on a blue-to-red ramp (the vertices
//! must then be the run's points, in order).

use std::path::Path;

use burn::tensor::Device;
use gltf_json as json;
use json::validation::{Checked::Valid, USize64};

use crate::data::mesh::{as_points, read_obj, vertex_normals};
use crate::data::textured::{Material, Part, TexturedMesh};
use crate::run::{OpenRun, RunDir};
use crate::{DomaError, Result};

/// What to export.
#[derive(Clone, Debug, Default)]
pub struct ExportOptions {
    /// The frames (default: all of the run's).
    pub frames: Option<std::ops::Range<usize>>,
    /// Colour the vertices by their mean EPE over the frames.
    pub color_by_error: bool,
    /// Keyframes per second of the animation (default 24).
    pub fps: Option<f32>,
}

/// What was written.
#[derive(Clone, Debug, PartialEq)]
pub struct ExportSummary {
    /// Vertices of the exported shape.
    pub vertices: usize,
    /// Triangles (0 for a point cloud).
    pub triangles: usize,
    /// Frames, one morph target each.
    pub frames: usize,
    /// Bytes of the `.glb`.
    pub bytes: usize,
}

/// Exports the fitted motion of the run in `run` to `out` (a `.glb`, written atomically).
pub fn export_gltf(
    run: &RunDir,
    mesh: Option<&Path>,
    out: &Path,
    options: &ExportOptions,
    device: &Device,
) -> Result<ExportSummary> {
    crate::io::check_writable(out)?;
    let OpenRun {
        config,
        field,
        data: own,
        frames: range,
    } = run.open(options.frames.clone(), device)?;
    let total = own.trajectories.frames();
    let to_data =
        |p: [f32; 3]| -> [f32; 3] { std::array::from_fn(|c| p[c] * own.scale + own.center[c]) };
    let to_norm =
        |p: [f32; 3]| -> [f32; 3] { std::array::from_fn(|c| (p[c] - own.center[c]) / own.scale) };
    // The shape, in the data's units, and whether its vertices are the run's points.
    let (shape, are_points) = match mesh {
        Some(path) if options.color_by_error => {
            let strict = read_obj(path)?;
            if strict.vertices.len() != own.trajectories.points() {
                return Err(DomaError::Malformed {
                    path: path.to_path_buf(),
                    reason: format!(
                        "{} vertices, but the run's data has {} points: colouring by error needs one vertex per point, in order",
                        strict.vertices.len(),
                        own.trajectories.points()
                    ),
                });
            }
            (single_part(strict.vertices, strict.faces, path), true)
        }
        Some(path) => (TexturedMesh::read(path)?, false),
        None => {
            let vertices: Vec<[f32; 3]> = as_points(own.trajectories.frame(0))
                .into_iter()
                .map(to_data)
                .collect();
            let faces = own.faces.clone().unwrap_or_default();
            (single_part(vertices, faces, &config.data), true)
        }
    };
    let canonical: Vec<[f32; 3]> = shape.positions().into_iter().map(to_norm).collect();
    let mut frames: Vec<Vec<[f32; 3]>> = Vec::with_capacity(range.len());
    let mut error_sum = vec![0f64; canonical.len()];
    crate::warp::warp_frames(&field, &canonical, range.clone(), total, device, |k, y| {
        if let Some(v) = y.iter().position(|p| p.iter().any(|c| !c.is_finite())) {
            return Err(DomaError::InvalidData(format!(
                "frame {k}: vertex {v} warps to a non-finite position"
            )));
        }
        if options.color_by_error && are_points {
            let truth = own.trajectories.frame(k);
            for (i, p) in y.iter().enumerate() {
                error_sum[i] += (0..3)
                    .map(|c| (p[c] as f64 - truth[3 * i + c] as f64).abs())
                    .sum::<f64>();
            }
        }
        frames.push(y.into_iter().map(to_data).collect());
        Ok(())
    })?;
    let colors = (options.color_by_error && are_points).then(|| {
        let mean: Vec<f64> = error_sum.iter().map(|e| e / frames.len() as f64).collect();
        let max = mean.iter().copied().fold(0.0, f64::max).max(1e-12);
        mean.iter()
            .map(|&e| {
                let [r, g, b] = crate::plot::ramp(e / max);
                [r as f32 / 255.0, g as f32 / 255.0, b as f32 / 255.0]
            })
            .collect::<Vec<[f32; 3]>>()
    });
    let fps = options.fps.unwrap_or(24.0);
    if !(fps.is_finite() && fps > 0.0) {
        return Err(DomaError::InvalidConfig(format!(
            "{fps} frames per second must be positive"
        )));
    }
    let glb = build_glb(&shape, &frames, colors.as_deref(), fps)?;
    crate::io::write_atomic(out, &glb)?;
    Ok(ExportSummary {
        vertices: canonical.len(),
        triangles: shape.parts.iter().map(|p| p.triangles.len()).sum(),
        frames: frames.len(),
        bytes: glb.len(),
    })
}

fn single_part(positions: Vec<[f32; 3]>, triangles: Vec<[u32; 3]>, path: &Path) -> TexturedMesh {
    TexturedMesh {
        path: path.to_path_buf(),
        parts: vec![Part {
            name: "mesh".into(),
            positions,
            texcoords: None,
            triangles,
            material: None,
        }],
        materials: Vec::new(),
        mtllibs: Vec::new(),
    }
}

/// The binary buffer being filled and the accessors that describe it.
struct Builder {
    root: json::Root,
    bin: Vec<u8>,
}

impl Builder {
    /// Appends `bytes` as a buffer view (4-byte aligned).
    fn view(
        &mut self,
        bytes: &[u8],
        target: Option<json::buffer::Target>,
    ) -> json::Index<json::buffer::View> {
        while !self.bin.len().is_multiple_of(4) {
            self.bin.push(0);
        }
        let offset = self.bin.len();
        self.bin.extend_from_slice(bytes);
        self.root.push(json::buffer::View {
            buffer: json::Index::new(0),
            byte_length: USize64::from(bytes.len()),
            byte_offset: Some(USize64::from(offset)),
            byte_stride: None,
            name: None,
            target: target.map(Valid),
            extensions: None,
            extras: Default::default(),
        })
    }

    /// An accessor over `values` (`n` components each); `bounds` adds its min and max.
    fn floats(
        &mut self,
        values: &[f32],
        n: usize,
        type_: json::accessor::Type,
        bounds: bool,
        target: Option<json::buffer::Target>,
    ) -> json::Index<json::Accessor> {
        let view = self.view(bytemuck::cast_slice(values), target);
        let (min, max) = if bounds {
            let mut lo = vec![f32::INFINITY; n];
            let mut hi = vec![f32::NEG_INFINITY; n];
            for v in values.chunks_exact(n) {
                for c in 0..n {
                    lo[c] = lo[c].min(v[c]);
                    hi[c] = hi[c].max(v[c]);
                }
            }
            (Some(json::Value::from(lo)), Some(json::Value::from(hi)))
        } else {
            (None, None)
        };
        self.root.push(json::Accessor {
            buffer_view: Some(view),
            byte_offset: None,
            count: USize64::from(values.len() / n),
            component_type: Valid(json::accessor::GenericComponentType(
                json::accessor::ComponentType::F32,
            )),
            extensions: None,
            extras: Default::default(),
            type_: Valid(type_),
            min,
            max,
            name: None,
            normalized: false,
            sparse: None,
        })
    }

    fn indices(&mut self, triangles: &[[u32; 3]]) -> json::Index<json::Accessor> {
        let flat: &[u32] = triangles.as_flattened();
        let view = self.view(
            bytemuck::cast_slice(flat),
            Some(json::buffer::Target::ElementArrayBuffer),
        );
        self.root.push(json::Accessor {
            buffer_view: Some(view),
            byte_offset: None,
            count: USize64::from(flat.len()),
            component_type: Valid(json::accessor::GenericComponentType(
                json::accessor::ComponentType::U32,
            )),
            extensions: None,
            extras: Default::default(),
            type_: Valid(json::accessor::Type::Scalar),
            min: None,
            max: None,
            name: None,
            normalized: false,
            sparse: None,
        })
    }

    fn material(
        &mut self,
        material: Option<&Material>,
        base: &Path,
        vertex_colors: bool,
    ) -> json::Index<json::Material> {
        let mut m = json::Material {
            double_sided: true,
            ..Default::default()
        };
        m.name = material.map(|m| m.name.clone());
        m.pbr_metallic_roughness.metallic_factor = json::material::StrengthFactor(0.0);
        m.pbr_metallic_roughness.roughness_factor = json::material::StrengthFactor(0.9);
        let kd = material
            .and_then(|m| m.diffuse)
            .filter(|_| !vertex_colors)
            .unwrap_or([0.8, 0.8, 0.8]);
        m.pbr_metallic_roughness.base_color_factor =
            json::material::PbrBaseColorFactor([kd[0], kd[1], kd[2], 1.0]);
        if vertex_colors {
            m.pbr_metallic_roughness.base_color_factor =
                json::material::PbrBaseColorFactor([1.0; 4]);
        }
        if let Some(texture) = material
            .and_then(|m| m.diffuse_texture.as_deref())
            .and_then(|t| self.texture(base, t))
        {
            m.pbr_metallic_roughness.base_color_texture = Some(json::texture::Info {
                index: texture,
                tex_coord: 0,
                extensions: None,
                extras: Default::default(),
            });
            m.pbr_metallic_roughness.base_color_factor =
                json::material::PbrBaseColorFactor([1.0; 4]);
        }
        self.root.push(m)
    }

    /// Embeds a PNG or JPEG texture (by its magic bytes); other files are left out.
    fn texture(&mut self, base: &Path, name: &str) -> Option<json::Index<json::Texture>> {
        let bytes = std::fs::read(base.join(name)).ok()?;
        let mime = if bytes.starts_with(b"\x89PNG\r\n\x1a\n") {
            "image/png"
        } else if bytes.starts_with(&[0xFF, 0xD8, 0xFF]) {
            "image/jpeg"
        } else {
            return None;
        };
        let view = self.view(&bytes, None);
        let image = self.root.push(json::Image {
            buffer_view: Some(view),
            mime_type: Some(json::image::MimeType(mime.into())),
            name: Some(name.into()),
            uri: None,
            extensions: None,
            extras: Default::default(),
        });
        let sampler = self.root.push(json::texture::Sampler::default());
        Some(self.root.push(json::Texture {
            name: None,
            sampler: Some(sampler),
            source: image,
            extensions: None,
            extras: Default::default(),
        }))
    }
}

/// The `.glb` of `shape` moving through `frames` (each `[V, 3]` over all parts, in the
/// data's units).
fn build_glb(
    shape: &TexturedMesh,
    frames: &[Vec<[f32; 3]>],
    colors: Option<&[[f32; 3]]>,
    fps: f32,
) -> Result<Vec<u8>> {
    use json::accessor::Type;
    use json::buffer::Target;
    let mut b = Builder {
        root: json::Root {
            asset: json::Asset {
                generator: Some(format!("doma {}", env!("CARGO_PKG_VERSION"))),
                version: "2.0".into(),
                ..Default::default()
            },
            ..Default::default()
        },
        bin: Vec::new(),
    };
    let base_dir = shape.path.parent().unwrap_or(Path::new(".")).to_path_buf();
    let mut primitives = Vec::new();
    let mut offset = 0;
    for part in &shape.parts {
        let n = part.positions.len();
        let slice = |f: &Vec<[f32; 3]>| f[offset..offset + n].to_vec();
        let base = slice(&frames[0]);
        let points = part.triangles.is_empty();
        let normals_of = |v: &[[f32; 3]]| vertex_normals(v, &part.triangles);
        let base_normals = (!points).then(|| normals_of(&base));
        let mut attributes = std::collections::BTreeMap::new();
        attributes.insert(
            Valid(json::mesh::Semantic::Positions),
            b.floats(
                base.as_flattened(),
                3,
                Type::Vec3,
                true,
                Some(Target::ArrayBuffer),
            ),
        );
        if let Some(nrm) = &base_normals {
            attributes.insert(
                Valid(json::mesh::Semantic::Normals),
                b.floats(
                    nrm.as_flattened(),
                    3,
                    Type::Vec3,
                    false,
                    Some(Target::ArrayBuffer),
                ),
            );
        }
        if let Some(uv) = &part.texcoords {
            // OBJ's v runs up, glTF's down.
            let flipped: Vec<f32> = uv.iter().flat_map(|t| [t[0], 1.0 - t[1]]).collect();
            attributes.insert(
                Valid(json::mesh::Semantic::TexCoords(0)),
                b.floats(&flipped, 2, Type::Vec2, false, Some(Target::ArrayBuffer)),
            );
        }
        if let Some(c) = colors {
            attributes.insert(
                Valid(json::mesh::Semantic::Colors(0)),
                b.floats(
                    c[offset..offset + n].as_flattened(),
                    3,
                    Type::Vec3,
                    false,
                    Some(Target::ArrayBuffer),
                ),
            );
        }
        let mut targets = Vec::with_capacity(frames.len());
        for frame in frames {
            let moved = slice(frame);
            let dp: Vec<f32> = moved
                .iter()
                .zip(&base)
                .flat_map(|(a, o)| [a[0] - o[0], a[1] - o[1], a[2] - o[2]])
                .collect();
            let positions = Some(b.floats(&dp, 3, Type::Vec3, true, Some(Target::ArrayBuffer)));
            let normals = base_normals.as_ref().map(|bn| {
                let dn: Vec<f32> = normals_of(&moved)
                    .iter()
                    .zip(bn)
                    .flat_map(|(a, o)| [a[0] - o[0], a[1] - o[1], a[2] - o[2]])
                    .collect();
                b.floats(&dn, 3, Type::Vec3, false, Some(Target::ArrayBuffer))
            });
            targets.push(json::mesh::MorphTarget {
                positions,
                normals,
                tangents: None,
            });
        }
        let indices = (!points).then(|| b.indices(&part.triangles));
        let material = b.material(
            part.material.map(|m| &shape.materials[m]),
            &base_dir,
            colors.is_some(),
        );
        primitives.push(json::mesh::Primitive {
            attributes,
            extensions: None,
            extras: Default::default(),
            indices,
            material: Some(material),
            mode: Valid(if points {
                json::mesh::Mode::Points
            } else {
                json::mesh::Mode::Triangles
            }),
            targets: Some(targets),
        });
        offset += n;
    }
    let t = frames.len();
    let mesh = b.root.push(json::Mesh {
        extensions: None,
        extras: Default::default(),
        name: Some("doma motion".into()),
        primitives,
        weights: Some(vec![0.0; t]),
    });
    let node = b.root.push(json::Node {
        mesh: Some(mesh),
        name: Some("doma motion".into()),
        ..Default::default()
    });
    let scene = b.root.push(json::Scene {
        extensions: None,
        extras: Default::default(),
        name: None,
        nodes: vec![node],
    });
    b.root.scene = Some(scene);
    if t > 1 {
        let times: Vec<f32> = (0..t).map(|k| k as f32 / fps).collect();
        let input = b.floats(&times, 1, Type::Scalar, true, None);
        let mut weights = vec![0f32; t * t];
        for k in 0..t {
            weights[k * t + k] = 1.0;
        }
        let output = b.floats(&weights, 1, Type::Scalar, false, None);
        let sampler = json::animation::Sampler {
            extensions: None,
            extras: Default::default(),
            input,
            interpolation: Valid(json::animation::Interpolation::Linear),
            output,
        };
        b.root.push(json::Animation {
            extensions: None,
            extras: Default::default(),
            channels: vec![json::animation::Channel {
                sampler: json::Index::new(0),
                target: json::animation::Target {
                    extensions: None,
                    extras: Default::default(),
                    node,
                    path: Valid(json::animation::Property::MorphTargetWeights),
                },
                extensions: None,
                extras: Default::default(),
            }],
            name: Some("motion".into()),
            samplers: vec![sampler],
        });
    }
    while !b.bin.len().is_multiple_of(4) {
        b.bin.push(0);
    }
    b.root.push(json::Buffer {
        byte_length: USize64::from(b.bin.len()),
        name: None,
        uri: None,
        extensions: None,
        extras: Default::default(),
    });
    let text = json::serialize::to_string(&b.root)
        .map_err(|e| DomaError::InvalidData(format!("cannot serialise the glTF document: {e}")))?;
    Ok(glb(text.into_bytes(), b.bin))
}

/// The GLB container (glTF 2.0 §4.4): a 12-byte header, the JSON chunk padded with spaces
/// and the binary chunk padded with zeros, each to 4 bytes.
fn glb(mut json: Vec<u8>, bin: Vec<u8>) -> Vec<u8> {
    while !json.len().is_multiple_of(4) {
        json.push(b' ');
    }
    let total = 12 + 8 + json.len() + 8 + bin.len();
    let mut out = Vec::with_capacity(total);
    out.extend_from_slice(b"glTF");
    out.extend_from_slice(&2u32.to_le_bytes());
    out.extend_from_slice(&(total as u32).to_le_bytes());
    out.extend_from_slice(&(json.len() as u32).to_le_bytes());
    out.extend_from_slice(b"JSON");
    out.extend_from_slice(&json);
    out.extend_from_slice(&(bin.len() as u32).to_le_bytes());
    out.extend_from_slice(b"BIN\0");
    out.extend_from_slice(&bin);
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_glb_has_the_header_and_both_chunks_aligned() {
        let out = glb(b"{\"a\":1}".to_vec(), vec![1, 2, 3, 4]);
        assert_eq!(&out[..4], b"glTF");
        assert_eq!(
            u32::from_le_bytes(out[8..12].try_into().unwrap()) as usize,
            out.len()
        );
        let json_len = u32::from_le_bytes(out[12..16].try_into().unwrap()) as usize;
        assert_eq!(json_len % 4, 0);
        assert_eq!(&out[20..20 + 7], b"{\"a\":1}");
        assert_eq!(&out[20 + json_len + 4..20 + json_len + 8], b"BIN\0");
    }

    #[test]
    fn the_document_lists_one_target_per_frame_and_one_hot_weights() {
        let shape = single_part(
            vec![[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
            vec![[0, 1, 2]],
            Path::new("x.obj"),
        );
        let frames: Vec<Vec<[f32; 3]>> = (0..3)
            .map(|k| {
                shape
                    .positions()
                    .iter()
                    .map(|p| [p[0] + k as f32, p[1], p[2]])
                    .collect()
            })
            .collect();
        let bytes = build_glb(&shape, &frames, None, 10.0).unwrap();
        let json_len = u32::from_le_bytes(bytes[12..16].try_into().unwrap()) as usize;
        let doc: serde_json::Value = serde_json::from_slice(&bytes[20..20 + json_len]).unwrap();
        assert_eq!(
            doc["meshes"][0]["primitives"][0]["targets"]
                .as_array()
                .unwrap()
                .len(),
            3
        );
        assert_eq!(doc["meshes"][0]["weights"].as_array().unwrap().len(), 3);
        let channel = &doc["animations"][0]["channels"][0]["target"];
        assert_eq!(channel["path"], "weights");
        // Frame 2's target moves every vertex by +2 in x: its POSITION bounds say so.
        let target = doc["meshes"][0]["primitives"][0]["targets"][2]["POSITION"]
            .as_u64()
            .unwrap();
        assert_eq!(doc["accessors"][target as usize]["min"][0], 2.0);
        assert_eq!(doc["accessors"][target as usize]["max"][0], 2.0);
        // The keyframe times: 0, 0.1, 0.2 s.
        let input = doc["animations"][0]["samplers"][0]["input"]
            .as_u64()
            .unwrap();
        let max = doc["accessors"][input as usize]["max"][0].as_f64().unwrap();
        assert!((max - 0.2).abs() < 1e-6);
    }
}
