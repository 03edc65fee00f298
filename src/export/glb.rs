//! The glTF document and its binary container: buffers and accessors, a primitive per
//! part with a morph target per frame, and the animation of the morph weights.

use std::path::Path;

use gltf_json as json;
use json::validation::{Checked::Valid, USize64};

use crate::data::mesh::vertex_normals;
use crate::data::textured::{Material, Part, TexturedMesh};
use crate::io::{InputKind, read_named};
use crate::{DomaError, Result};

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
        mesh: &Path,
        vertex_colors: bool,
    ) -> Result<json::Index<json::Material>> {
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
        let texture = match material.and_then(|m| m.diffuse_texture.as_deref()) {
            Some(t) => self.texture(mesh, t)?,
            None => None,
        };
        if let Some(texture) = texture {
            m.pbr_metallic_roughness.base_color_texture = Some(json::texture::Info {
                index: texture,
                tex_coord: 0,
                extensions: None,
                extras: Default::default(),
            });
            m.pbr_metallic_roughness.base_color_factor =
                json::material::PbrBaseColorFactor([1.0; 4]);
        }
        Ok(self.root.push(m))
    }

    /// Embeds a PNG or JPEG texture (by its magic bytes; other formats are left out),
    /// named relative to the mesh's folder and read only from inside it
    /// ([`crate::io::read_named`]); a missing or refused texture is an error.
    fn texture(&mut self, mesh: &Path, name: &str) -> Result<Option<json::Index<json::Texture>>> {
        let bytes = read_named(mesh, name, InputKind::Texture)?;
        let mime = if bytes.starts_with(b"\x89PNG\r\n\x1a\n") {
            "image/png"
        } else if bytes.starts_with(&[0xFF, 0xD8, 0xFF]) {
            "image/jpeg"
        } else {
            return Ok(None);
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
        Ok(Some(self.root.push(json::Texture {
            name: None,
            sampler: Some(sampler),
            source: image,
            extensions: None,
            extras: Default::default(),
        })))
    }
}

/// The `.glb` of `shape` moving through `frames` (each `[V, 3]` over all parts, in the
/// data's units): one primitive per part with a morph target per frame
/// ([`part_primitive`]), one node, and the animation of its weights ([`morph_animation`]).
/// With `observed` (`[T][V]`, the run's own points of masked data), each frame's vertex
/// colours are `colors` (or grey) where observed and [`FILLED`] where the field fills the
/// point, through `COLOR_0` morph targets beside the positions.
pub(super) fn build_glb(
    shape: &TexturedMesh,
    frames: &[Vec<[f32; 3]>],
    colors: Option<&[[f32; 3]]>,
    observed: Option<&[Vec<bool>]>,
    fps: f32,
) -> Result<Vec<u8>> {
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
    let mut primitives = Vec::new();
    let mut color_targets = Vec::new();
    let mut offset = 0;
    for part in &shape.parts {
        let material = part.material.map(|m| &shape.materials[m]);
        let n = part.positions.len();
        let frame_colors = observed.map(|obs| colors_per_frame(obs, colors, offset..offset + n));
        let colors = match &frame_colors {
            Some(fc) => Some(&fc[0][..]),
            None => colors.map(|c| &c[offset..offset + n]),
        };
        primitives.push(part_primitive(
            &mut b,
            part,
            offset,
            frames,
            colors,
            material,
            &shape.path,
        )?);
        // glTF's morph targets may carry COLOR_n (spec 2.0.1); gltf-json's type has no
        // field for it, so the accessors are added to the document below.
        color_targets.push(frame_colors.map(|fc| color_morph_targets(&mut b, &fc)));
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
        morph_animation(&mut b, node, t, fps);
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
    let bad = |e: serde_json::Error| {
        DomaError::InvalidData(format!("cannot serialise the glTF document: {e}"))
    };
    let mut doc = serde_json::to_value(&b.root).map_err(bad)?;
    for (p, targets) in color_targets.iter().enumerate() {
        let Some(targets) = targets else { continue };
        for (k, &accessor) in targets.iter().enumerate() {
            doc["meshes"][0]["primitives"][p]["targets"][k]["COLOR_0"] = accessor.into();
        }
    }
    let text = serde_json::to_string(&doc).map_err(bad)?;
    glb(text.into_bytes(), b.bin)
}

/// Per frame, the colour of each vertex in `range`: its base colour (`colors`, or
/// [`OBSERVED`]) where observed, [`FILLED`] where the field fills it.
fn colors_per_frame(
    observed: &[Vec<bool>],
    colors: Option<&[[f32; 3]]>,
    range: std::ops::Range<usize>,
) -> Vec<Vec<[f32; 3]>> {
    observed
        .iter()
        .map(|seen| {
            range
                .clone()
                .map(|i| match (seen[i], colors) {
                    (false, _) => FILLED,
                    (true, Some(c)) => c[i],
                    (true, None) => OBSERVED,
                })
                .collect()
        })
        .collect()
}

/// The accessors of each frame's colours as morph-target deltas from frame 0's.
fn color_morph_targets(b: &mut Builder, frame_colors: &[Vec<[f32; 3]>]) -> Vec<usize> {
    frame_colors
        .iter()
        .map(|c| {
            let delta: Vec<f32> = c
                .iter()
                .zip(&frame_colors[0])
                .flat_map(|(a, o)| [a[0] - o[0], a[1] - o[1], a[2] - o[2]])
                .collect();
            b.floats(&delta, 3, json::accessor::Type::Vec3, false, None)
                .value()
        })
        .collect()
}

/// The vertex colour of an observed point when nothing else colours it.
const OBSERVED: [f32; 3] = [0.75, 0.75, 0.78];

/// The vertex colour of a point the field fills (the viewer's too).
pub const FILLED: [f32; 3] = [0.85, 0.3, 0.85];

/// One part of the shape as a primitive: its first frame's positions (and normals, UVs,
/// colours) as the base, and one morph target per frame holding the displacements from
/// it. The part's vertices are `offset..offset + n` of each frame.
fn part_primitive(
    b: &mut Builder,
    part: &Part,
    offset: usize,
    frames: &[Vec<[f32; 3]>],
    colors: Option<&[[f32; 3]]>,
    material: Option<&Material>,
    mesh: &Path,
) -> Result<json::mesh::Primitive> {
    use json::accessor::Type;
    use json::buffer::Target;
    let n = part.positions.len();
    let slice = |f: &Vec<[f32; 3]>| f[offset..offset + n].to_vec();
    let base = slice(&frames[0]);
    let points = part.triangles.is_empty();
    // glTF's normals are unit vectors: a vertex on no triangle (or on degenerate ones
    // alone) faces +z rather than having none.
    let normals_of = |v: &[[f32; 3]]| {
        let mut n = vertex_normals(v, &part.triangles);
        for v in &mut n {
            if !v.iter().map(|c| c * c).sum::<f32>().is_normal() {
                *v = [0.0, 0.0, 1.0];
            }
        }
        n
    };
    let base_normals = (!points).then(|| normals_of(&base));
    let vec3 = |b: &mut Builder, v: &[f32], bounds: bool| {
        b.floats(v, 3, Type::Vec3, bounds, Some(Target::ArrayBuffer))
    };
    let mut attributes = std::collections::BTreeMap::new();
    attributes.insert(
        Valid(json::mesh::Semantic::Positions),
        vec3(b, base.as_flattened(), true),
    );
    if let Some(nrm) = &base_normals {
        attributes.insert(
            Valid(json::mesh::Semantic::Normals),
            vec3(b, nrm.as_flattened(), false),
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
            vec3(b, c.as_flattened(), false),
        );
    }
    let difference = |a: &[[f32; 3]], o: &[[f32; 3]]| -> Vec<f32> {
        a.iter()
            .zip(o)
            .flat_map(|(a, o)| [a[0] - o[0], a[1] - o[1], a[2] - o[2]])
            .collect()
    };
    let mut targets = Vec::with_capacity(frames.len());
    for frame in frames {
        let moved = slice(frame);
        let positions = Some(vec3(b, &difference(&moved, &base), true));
        let normals = base_normals
            .as_ref()
            .map(|bn| vec3(b, &difference(&normals_of(&moved), bn), false));
        targets.push(json::mesh::MorphTarget {
            positions,
            normals,
            tangents: None,
        });
    }
    let indices = (!points).then(|| b.indices(&part.triangles));
    let material = b.material(material, mesh, colors.is_some())?;
    Ok(json::mesh::Primitive {
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
    })
}

/// The animation of `node`'s `t` morph weights: keyframe `k` at `k / fps` seconds is
/// one-hot on target `k`, linearly interpolated in between.
fn morph_animation(b: &mut Builder, node: json::Index<json::Node>, t: usize, fps: f32) {
    use json::accessor::Type;
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

/// The GLB's total, JSON-chunk and binary-chunk lengths for chunks of these (padded)
/// sizes, each a `u32`, or an error when any is 4 GiB or more.
fn glb_lengths(json: usize, bin: usize) -> Result<[u32; 3]> {
    let total = (12 + 8 + 8usize).saturating_add(json).saturating_add(bin);
    let fit = |n: usize| {
        u32::try_from(n).map_err(|_| {
            DomaError::InvalidData(format!(
                "the glTF would be {total} bytes; a .glb holds less than 4 GiB (fewer frames or \
                 vertices, or --frames, make it fit)"
            ))
        })
    };
    Ok([fit(total)?, fit(json)?, fit(bin)?])
}

/// The GLB container (glTF 2.0 §4.4): a 12-byte header, the JSON chunk padded with spaces
/// and the binary chunk padded with zeros, each to 4 bytes. Its lengths are 32-bit: a scene
/// of 4 GiB or more is refused rather than written with wrapped lengths.
fn glb(mut json: Vec<u8>, bin: Vec<u8>) -> Result<Vec<u8>> {
    while !json.len().is_multiple_of(4) {
        json.push(b' ');
    }
    let [total32, json32, bin32] = glb_lengths(json.len(), bin.len())?;
    let mut out = Vec::with_capacity(total32 as usize);
    out.extend_from_slice(b"glTF");
    out.extend_from_slice(&2u32.to_le_bytes());
    out.extend_from_slice(&total32.to_le_bytes());
    out.extend_from_slice(&json32.to_le_bytes());
    out.extend_from_slice(b"JSON");
    out.extend_from_slice(&json);
    out.extend_from_slice(&bin32.to_le_bytes());
    out.extend_from_slice(b"BIN\0");
    out.extend_from_slice(&bin);
    Ok(out)
}

#[cfg(test)]
mod tests;
