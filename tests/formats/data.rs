//! Trajectories and the synthetic protocol.

use doma::data::synthetic::{self, Motion, Mt19937};
use doma::data::{Trajectories, normalized_time};

#[test]
fn mt19937_matches_numpy_legacy_seed_0() {
    let mut rng = Mt19937::new(0);
    assert_eq!(rng.next_f64(), 0.5488135039273248);
    assert_eq!(rng.next_f64(), 0.7151893663724195);
    assert_eq!(rng.next_f64(), 0.6027633760716439);
}

#[test]
fn the_reference_points_are_numpy_rand_times_2_minus_1() {
    // numpy: seed(0); p = rand(3000, 3) * 2 - 1; p[0], p[749], p[2999].
    let p = synthetic::uniform_points(0, 3000);
    assert_eq!(
        p[0],
        [0.0976270078546495, 0.43037873274483895, 0.20552675214328775]
    );
    assert_eq!(
        p[749],
        [0.9340110478607333, -0.22486565315291274, 0.3733800596337222]
    );
    assert_eq!(
        p[2999],
        [-0.861697219857154, 0.5161279567099879, 0.8640120032885088]
    );
}

#[test]
fn the_motions_follow_their_schedules() {
    let p = [0.5, -0.25, 0.75];
    let close = |a: [f64; 3], b: [f64; 3]| a.iter().zip(&b).all(|(x, y)| (x - y).abs() < 1e-12);
    // Frame 0 of rotation, scaling's 1.0 never exactly hit: check the ends and a middle frame.
    assert!(close(Motion::Rotation.apply(p, 0, 20), p));
    assert!(close(Motion::Rotation.apply(p, 10, 20), [0.25, 0.5, 0.75])); // 90° about z
    assert!(close(
        Motion::Scaling.apply(p, 0, 20),
        [0.25, -0.125, 0.375]
    ));
    assert!(close(
        Motion::Scaling.apply(p, 19, 20),
        [0.75, -0.375, 1.125]
    ));
    assert!(close(Motion::Shearing.apply(p, 0, 20), p));
    assert!(close(
        Motion::Shearing.apply(p, 19, 20),
        [0.5 + 1.5 * 0.75, -0.25, 0.75]
    ));
    assert!(close(
        Motion::Translation.apply(p, 0, 20),
        [-0.5, -1.25, -0.25]
    ));
    assert!(close(
        Motion::Translation.apply(p, 19, 20),
        [1.5, 0.75, 1.75]
    ));
}

#[test]
fn the_benchmark_split_is_750_and_2250() {
    let seq = synthetic::benchmark_sequence(Motion::Translation, 0).unwrap();
    assert_eq!((seq.train.frames(), seq.train.points()), (20, 750));
    assert_eq!((seq.test.frames(), seq.test.points()), (20, 2250));
    // The canonical frame of translation is the points shifted by −1.
    let p0 = synthetic::uniform_points(0, 3000)[0];
    let first: Vec<f32> = p0.iter().map(|v| (v - 1.0) as f32).collect();
    assert_eq!(&seq.train.frame(0)[..3], first.as_slice());
    let p750 = synthetic::uniform_points(0, 3000)[750];
    assert_eq!(seq.test.frame(0)[0], (p750[0] - 1.0) as f32);
}

#[test]
fn time_is_normalised_to_minus_one_one() {
    assert_eq!(normalized_time(0, 20), -1.0);
    assert_eq!(normalized_time(19, 20), 1.0);
    assert!((normalized_time(5, 11) - 0.0).abs() < 1e-15);
    assert_eq!(normalized_time(0, 1), -1.0);
}

#[test]
fn bad_trajectories_are_refused() {
    assert!(Trajectories::new(0, 3, vec![]).is_err());
    assert!(Trajectories::new(2, 0, vec![]).is_err());
    assert!(Trajectories::new(2, 2, vec![0.0; 11]).is_err());
    let mut v = vec![0.0f32; 12];
    v[7] = f32::NAN;
    let err = Trajectories::new(2, 2, v).unwrap_err().to_string();
    assert!(err.contains("point 0 in frame 1"), "{err}");
    let t = Trajectories::new(1, 2, vec![0.0; 6]).unwrap();
    assert!(t.split_first(2).is_err());
    assert!(t.select_points(&[2]).is_err());
}

#[test]
fn extreme_coordinates_normalise_to_finite_values_or_are_refused() {
    // A frame-0 box from −3·10³⁸ to 3·10³⁸: its width overflows f32, its half does not.
    let big = 3.0e38f32;
    let frame = [-big, 0.0, big, big, -big, 0.0, 0.0, big, -big];
    let t = Trajectories::new(2, 3, [frame, frame].concat()).unwrap();
    let (n, center, scale) = t.normalized().unwrap();
    assert!(scale.is_finite() && center.iter().all(|c| c.is_finite()));
    assert!(
        n.positions()
            .iter()
            .all(|v| v.is_finite() && v.abs() <= 1.0)
    );
    assert!(n.positions().contains(&1.0), "not all zeros");
    // A later frame ~10³⁸ frame-0 boxes away cannot be normalised in f32: refused.
    let tiny = [0.0, 0.0, 0.0, 1e-3, 0.0, 0.0, 0.0, 1e-3, 0.0];
    let far = [big, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0];
    let t = Trajectories::new(2, 3, [tiny, far].concat()).unwrap();
    let err = t.normalized().unwrap_err().to_string();
    assert!(err.contains("frame 1") && err.contains("point 0"), "{err}");
}
