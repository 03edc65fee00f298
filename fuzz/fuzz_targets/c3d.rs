//! The C3D reader never panics, and what it accepts writes back (when the format can hold
//! it) to a file that reads as the same points: positions bit for bit, the same entries
//! present, the same labels, frames, rate and units.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    use doma_formats::c3d::{encode, parse};
    if let Ok(c) = parse(data) {
        assert_eq!(c.positions.len(), 3 * c.frames * c.points);
        assert_eq!(c.labels.len(), c.points);
        if let Ok(bytes) = encode(&c) {
            let back = parse(&bytes).expect("an encoded file parses");
            let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(&back.positions), bits(&c.positions));
            assert_eq!(back.present(), c.present());
            assert_eq!(back.cameras, c.cameras);
            assert_eq!(back.labels, c.labels);
            assert_eq!(
                (back.frames, back.points, back.first_frame, back.rate.to_bits()),
                (c.frames, c.points, c.first_frame, c.rate.to_bits())
            );
            assert_eq!(back.scale.abs().to_bits(), c.scale.abs().to_bits());
            assert_eq!(back.units, c.units);
        }
    }
});
