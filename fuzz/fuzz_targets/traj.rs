//! The `.traj` reader never panics, and what it accepts writes back to the same bytes.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(frames) = doma_formats::traj::parse(data) {
        let bytes = doma_formats::traj::encode(&frames).expect("parsed counts fit");
        assert_eq!(bytes, data);
    }
});
