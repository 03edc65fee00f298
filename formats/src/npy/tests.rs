use super::*;

#[test]
fn a_header_with_two_entries_of_one_key_is_refused() {
    // NumPy's `ast.literal_eval` keeps the second shape, (2,); a first-match reader
    // would take (1,).
    let header = "{'descr': '<f4', 'fortran_order': False, 'shape': (1,), 'shape': (2,), }\n";
    let mut bytes = b"\x93NUMPY\x01\x00".to_vec();
    bytes.extend_from_slice(&(header.len() as u16).to_le_bytes());
    bytes.extend_from_slice(header.as_bytes());
    bytes.extend_from_slice(&[0; 8]);
    let e = parse_npy(&bytes).unwrap_err();
    assert!(e.contains("2 'shape' entries"), "{e}");
}

#[test]
fn a_non_ascii_dtype_is_refused_not_a_panic() {
    // Found by `cargo fuzz run npy`: the kind character was 'ě' (two bytes).
    let header = "{'descr': '\u{11b}4', 'fortran_order': False, 'shape': (1,), }\n";
    let mut bytes = b"\x93NUMPY\x01\x00".to_vec();
    bytes.extend_from_slice(&(header.len() as u16).to_le_bytes());
    bytes.extend_from_slice(header.as_bytes());
    bytes.extend_from_slice(&[0; 4]);
    assert!(parse_npy(&bytes).unwrap_err().contains("unsupported dtype"));
}

#[test]
fn fortran_order_is_transposed() {
    // [[1, 2, 3], [4, 5, 6]] stored column-major.
    let c = fortran_to_c(&[1.0, 4.0, 2.0, 5.0, 3.0, 6.0], &[2, 3]);
    assert_eq!(c, vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0]);
}

/// A `.npy` of `descr` and `shape` holding `payload`.
fn npy(descr: &str, shape: &str, payload: &[u8]) -> Vec<u8> {
    let header = format!("{{'descr': '{descr}', 'fortran_order': False, 'shape': {shape}, }}\n");
    let mut bytes = b"\x93NUMPY\x01\x00".to_vec();
    bytes.extend_from_slice(&(header.len() as u16).to_le_bytes());
    bytes.extend_from_slice(header.as_bytes());
    bytes.extend_from_slice(payload);
    bytes
}

#[test]
fn halves_are_read_exactly_with_their_infinities() {
    // 1, -2, 0.5, the largest half, the smallest subnormal, +inf.
    let halves: [u16; 6] = [0x3C00, 0xC000, 0x3800, 0x7BFF, 0x0001, 0x7C00];
    let payload: Vec<u8> = halves.iter().flat_map(|h| h.to_le_bytes()).collect();
    let a = parse_npy(&npy("<f2", "(6,)", &payload)).unwrap();
    assert_eq!(a.data[..4], [1.0, -2.0, 0.5, 65504.0]);
    assert_eq!(a.data[4], 2f32.powi(-24));
    assert_eq!(a.data[5], f32::INFINITY);
    let big: Vec<u8> = halves.iter().flat_map(|h| h.to_be_bytes()).collect();
    assert_eq!(parse_npy(&npy(">f2", "(6,)", &big)).unwrap().data, a.data);
    assert!(f16_to_f32(0x7E00).is_nan());
    assert_eq!(f16_to_f32(0x8001), -(2f32.powi(-24)));
}

#[test]
fn halves_round_to_nearest_even_and_round_trip() {
    // Hand-computed bits: 1, −2, 65504 (the largest), 65520 (rounds up to inf), 2⁻²⁴
    // (the smallest subnormal), 2⁻²⁶ (rounds to 0), 1 + 2⁻¹¹ (a tie: to even, 1),
    // 1 + 3·2⁻¹¹ (a tie: to even, 1 + 2⁻⁹), 3·2⁻²⁵ (a subnormal tie: to 2·2⁻²⁴).
    let cases: [(f32, u16); 9] = [
        (1.0, 0x3C00),
        (-2.0, 0xC000),
        (65504.0, 0x7BFF),
        (65520.0, 0x7C00),
        (2f32.powi(-24), 0x0001),
        (2f32.powi(-26), 0x0000),
        (1.0 + 2f32.powi(-11), 0x3C00),
        (1.0 + 3.0 * 2f32.powi(-11), 0x3C02),
        (3.0 * 2f32.powi(-25), 0x0002),
    ];
    for (x, bits) in cases {
        assert_eq!(f32_to_f16(x), bits, "{x}");
    }
    assert_eq!(f32_to_f16(f32::NEG_INFINITY), 0xFC00);
    assert!(f16_to_f32(f32_to_f16(f32::NAN)).is_nan());
    // Every finite half survives f16 → f32 → f16.
    for h in (0..=0xffffu16).filter(|h| h & 0x7c00 != 0x7c00) {
        assert_eq!(f32_to_f16(f16_to_f32(h)), h, "{h:#06x}");
    }
    let values = [0.5f32, -3.25, 1e-3];
    let bytes = encode_npy_values(&[3], NpyValues::F16(&values));
    let back = parse_npy(&bytes).unwrap().data;
    for (a, b) in back.iter().zip(values) {
        assert!((a - b).abs() <= b.abs() * 2f32.powi(-11), "{a} vs {b}");
    }
}

#[test]
fn bools_and_integers_round_trip() {
    let mask = [true, false, false, true, true, false];
    let a = parse_npy(&encode_npy_values(&[2, 3], NpyValues::Bool(&mask))).unwrap();
    assert_eq!(a.data, vec![1.0, 0.0, 0.0, 1.0, 1.0, 0.0]);
    let ints = [0i64, 7, -3];
    let a = parse_npy(&encode_npy_values(&[3], NpyValues::I64(&ints))).unwrap();
    assert_eq!(a.data, vec![0.0, 7.0, -3.0]);
}

#[test]
fn bools_are_zero_or_one() {
    let a = parse_npy(&npy("|b1", "(2, 2)", &[0, 1, 2, 0])).unwrap();
    assert_eq!((a.shape, a.data), (vec![2, 2], vec![0.0, 1.0, 1.0, 0.0]));
    assert!(parse_npy(&npy("|b2", "(1,)", &[0, 0])).is_err());
}

#[test]
fn signed_integers_are_sign_extended() {
    assert_eq!(Dtype::Int(2).value(&(-3i16).to_le_bytes()), -3.0);
    assert_eq!(Dtype::Uint(2).value(&(65533u16).to_le_bytes()), 65533.0);
}
