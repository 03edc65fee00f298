//! The `.npy` and `.npz` readers never panic; an accepted array holds exactly the values
//! its shape asks for, and a member's header, read alone, agrees with the member read whole.
//! Run with `-a` (debug assertions), so that an arithmetic overflow is a crash too.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    use doma_formats::npy::parse_npy;
    use doma_formats::npz::{npz_member_header, npz_members, read_npz_member};
    if let Ok(a) = parse_npy(data) {
        assert_eq!(a.shape.iter().product::<usize>(), a.data.len());
    }
    if let Ok(members) = npz_members(data) {
        for m in &members {
            let header = npz_member_header(data, m);
            if let Ok(a) = read_npz_member(data, m) {
                let h = header.expect("a member that reads has a header");
                assert_eq!(h.shape, a.shape);
                assert_eq!(a.shape.iter().product::<usize>(), a.data.len());
            }
        }
    }
});
