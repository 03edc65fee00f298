//! OBJ meshes: `v` and `f` records (indices 1-based or negative, optional `/vt/vn` parts;
//! polygons fan-triangulated; every other record skipped), and writing them back with
//! optional `vn` normals. Vertex order is kept: vertex `i` of the file is point `i`.

use crate::Frames;

/// A triangle mesh: vertices `[V, 3]` and 0-based triangles.
#[derive(Clone, Debug, PartialEq)]
pub struct TriMesh {
    /// Vertex positions.
    pub vertices: Vec<[f32; 3]>,
    /// Triangles, 0-based vertex indices, counter-clockwise seen from outside.
    pub faces: Vec<[u32; 3]>,
}

impl TriMesh {
    /// Checks and wraps a mesh: at least one vertex, finite coordinates, every face
    /// index in range.
    pub fn new(vertices: Vec<[f32; 3]>, faces: Vec<[u32; 3]>) -> Result<Self, String> {
        if vertices.is_empty() {
            return Err("the mesh has no vertices".into());
        }
        if let Some(i) = vertices
            .iter()
            .position(|v| v.iter().any(|c| !c.is_finite()))
        {
            return Err(format!("vertex {i} is {:?}, not finite", vertices[i]));
        }
        check_faces(&faces, vertices.len())?;
        Ok(TriMesh { vertices, faces })
    }

    /// The vertices as a flat `[V·3]` slice.
    pub fn flat_vertices(&self) -> &[f32] {
        self.vertices.as_flattened()
    }
}

/// Refuses a face whose index is not below `vertices`.
pub fn check_faces(faces: &[[u32; 3]], vertices: usize) -> Result<(), String> {
    match faces
        .iter()
        .enumerate()
        .find(|(_, f)| f.iter().any(|&i| i as usize >= vertices))
    {
        Some((k, f)) => Err(format!(
            "face {k} {f:?} indexes past the {vertices} vertices"
        )),
        None => Ok(()),
    }
}

/// Parses OBJ text: `v x y z` and `f a b c …` (indices 1-based or negative, with optional
/// `/vt/vn` parts); polygons are fan-triangulated.
pub fn parse_obj(text: &str) -> Result<TriMesh, String> {
    let mut vertices = Vec::new();
    let mut faces = Vec::new();
    for (line_no, line) in text.lines().enumerate() {
        let at = |m: String| format!("line {}: {m}", line_no + 1);
        let mut words = line.split_whitespace();
        match words.next() {
            Some("v") => {
                let mut v = [0f32; 3];
                for c in &mut v {
                    let w = words
                        .next()
                        .ok_or_else(|| at("a vertex needs three coordinates".into()))?;
                    *c = w.parse().map_err(|_| at(format!("bad coordinate {w:?}")))?;
                    if !c.is_finite() {
                        return Err(at(format!("coordinate {w} is not finite")));
                    }
                }
                vertices.push(v);
            }
            Some("f") => {
                let mut corners = Vec::with_capacity(4);
                for w in words {
                    let index = w.split('/').next().unwrap_or_default();
                    let i: i64 = index
                        .parse()
                        .map_err(|_| at(format!("bad face index {w:?}")))?;
                    // 1-based; negative counts back from the last vertex read so far.
                    let resolved = if i > 0 {
                        i - 1
                    } else {
                        vertices.len() as i64 + i
                    };
                    if i == 0 || resolved < 0 || resolved >= u32::MAX as i64 {
                        return Err(at(format!("face index {i} is out of range")));
                    }
                    corners.push(resolved as u32);
                }
                if corners.len() < 3 {
                    return Err(at("a face needs at least three corners".into()));
                }
                for k in 1..corners.len() - 1 {
                    faces.push([corners[0], corners[k], corners[k + 1]]);
                }
            }
            _ => {}
        }
    }
    TriMesh::new(vertices, faces)
}

/// OBJ text of `vertices` and `faces`, with `vn` records (and `f a//a` corners) when
/// `normals` are given.
pub fn encode_obj(
    vertices: &[[f32; 3]],
    faces: &[[u32; 3]],
    normals: Option<&[[f32; 3]]>,
) -> String {
    let mut bytes = Vec::with_capacity(40 * vertices.len() + 30 * faces.len());
    write_obj_to(&mut bytes, vertices, faces, normals).expect("writing to a Vec cannot fail");
    String::from_utf8(bytes).expect("the writer writes ASCII")
}

/// [`encode_obj`] streamed into `w`, so that a mesh of millions of vertices is written
/// without holding its text in memory.
pub fn write_obj_to<W: std::io::Write>(
    mut w: W,
    vertices: &[[f32; 3]],
    faces: &[[u32; 3]],
    normals: Option<&[[f32; 3]]>,
) -> std::io::Result<()> {
    w.write_all(b"# written by doma\n")?;
    for v in vertices {
        writeln!(w, "v {} {} {}", v[0], v[1], v[2])?;
    }
    if let Some(ns) = normals {
        for n in ns {
            writeln!(w, "vn {} {} {}", n[0], n[1], n[2])?;
        }
    }
    for f in faces {
        let [a, b, c] = f.map(|i| i + 1);
        match normals {
            Some(_) => writeln!(w, "f {a}//{a} {b}//{b} {c}//{c}")?,
            None => writeln!(w, "f {a} {b} {c}")?,
        }
    }
    Ok(())
}

/// Why [`stack_frames`] refused a sequence: the 0-based frame at fault and the reason.
#[derive(Clone, Debug, PartialEq)]
pub struct FrameError {
    /// The frame at fault.
    pub frame: usize,
    /// What is wrong with it.
    pub reason: String,
}

/// Stacks OBJ frames with equal vertex counts into `[T, V, 3]` positions (OBJ-sequence
/// loading). Refuses an empty sequence and names the first frame whose count differs.
pub fn stack_frames(meshes: &[TriMesh]) -> Result<Frames, FrameError> {
    let fail = |frame: usize, reason: String| FrameError { frame, reason };
    let first = meshes
        .first()
        .ok_or_else(|| fail(0, "an empty sequence (no frames)".into()))?;
    let mut positions = Vec::with_capacity(meshes.len() * first.vertices.len() * 3);
    for (k, m) in meshes.iter().enumerate() {
        if m.vertices.len() != first.vertices.len() {
            return Err(fail(
                k,
                format!(
                    "{} vertices, but the first frame has {}",
                    m.vertices.len(),
                    first.vertices.len()
                ),
            ));
        }
        positions.extend_from_slice(m.flat_vertices());
    }
    Frames::new(meshes.len(), first.vertices.len(), positions).map_err(|r| fail(0, r))
}

/// Compares file names in natural order: runs of digits by their value, so that `frame_2`
/// comes before `frame_10` (and `frame_002` before `frame_010`, as plain order has it).
pub fn natural_cmp(a: &str, b: &str) -> std::cmp::Ordering {
    use std::cmp::Ordering;
    let (mut a, mut b) = (a.as_bytes(), b.as_bytes());
    loop {
        match (a.first(), b.first()) {
            (None, None) => return Ordering::Equal,
            (None, Some(_)) => return Ordering::Less,
            (Some(_), None) => return Ordering::Greater,
            (Some(x), Some(y)) if x.is_ascii_digit() && y.is_ascii_digit() => {
                let run = |s: &[u8]| s.iter().take_while(|c| c.is_ascii_digit()).count();
                let (na, nb) = (run(a), run(b));
                // Without leading zeros, a longer run is a larger number; equal lengths
                // compare digit by digit. No parse, so no overflow.
                let trim = |s: &[u8]| s.iter().skip_while(|&&c| c == b'0').count();
                let (ta, tb) = (trim(&a[..na]), trim(&b[..nb]));
                let order = ta
                    .cmp(&tb)
                    .then_with(|| a[na - ta..na].cmp(&b[nb - tb..nb]))
                    .then_with(|| na.cmp(&nb));
                if order != Ordering::Equal {
                    return order;
                }
                (a, b) = (&a[na..], &b[nb..]);
            }
            (Some(x), Some(y)) => {
                if x != y {
                    return x.cmp(y);
                }
                (a, b) = (&a[1..], &b[1..]);
            }
        }
    }
}

#[cfg(test)]
mod natural_order_tests {
    use super::natural_cmp;

    #[test]
    fn digits_compare_by_value() {
        let mut names = vec![
            "frame_10.obj",
            "frame_2.obj",
            "frame_1.obj",
            "frame_02b.obj",
        ];
        names.sort_by(|a, b| natural_cmp(a, b));
        assert_eq!(
            names,
            vec![
                "frame_1.obj",
                "frame_2.obj",
                "frame_02b.obj",
                "frame_10.obj"
            ]
        );
        let mut padded = vec!["f_0010", "f_0002", "f_0001"];
        padded.sort_by(|a, b| natural_cmp(a, b));
        assert_eq!(padded, vec!["f_0001", "f_0002", "f_0010"]);
        // A number past u128 still compares.
        assert!(natural_cmp(&"9".repeat(60), &format!("1{}", "0".repeat(60))).is_lt());
    }
}
