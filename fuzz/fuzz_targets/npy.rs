//! The `.npy` and `.npz` readers never panic; an accepted array holds exactly the values
//! its shape asks for.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(a) = doma_formats::npy::parse_npy(data) {
        assert_eq!(a.shape.iter().product::<usize>(), a.data.len());
    }
    if let Ok(members) = doma_formats::npy::parse_npz(data) {
        for (_, a) in members {
            assert_eq!(a.shape.iter().product::<usize>(), a.data.len());
        }
    }
});
