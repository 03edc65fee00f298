use super::*;
use crate::export::single_part;

#[test]
fn a_scene_of_4_gib_is_refused_not_wrapped() {
    assert_eq!(glb_lengths(8, 4).unwrap(), [40, 8, 4]);
    let four_gib = 1usize << 32;
    assert!(glb_lengths(8, four_gib).is_err());
    assert!(
        glb_lengths(8, four_gib - 28).is_err(),
        "the total crosses 4 GiB"
    );
    assert!(glb_lengths(8, four_gib - 37).is_ok());
}

#[test]
fn a_glb_has_the_header_and_both_chunks_aligned() {
    let out = glb(b"{\"a\":1}".to_vec(), vec![1, 2, 3, 4]).unwrap();
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
    let bytes = build_glb(&shape, &frames, None, None, 10.0).unwrap();
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
