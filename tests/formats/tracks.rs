//! Tracker output: PointOdyssey and TAPVid-3D `.npz` files made from a shipped mesh by the
//! simulated tracker (`doma::data::tracker`), read back with their masks; every refusal
//! names the file and the key; a hidden entry's stored value changes nothing.

use crate::common;

use std::path::Path;

use doma::data::layout::{CoordFrame, Layout, TrackFile, read_npz_tracks};
use doma::data::sequence::{HoldOut, LoadOptions, load_sequence_with};
use doma::data::tracker::TrackerView;
use doma_formats::npy::NpyValues;
use doma_formats::npy::f32_to_f16;
use doma_formats::npz::encode_npz_values;

/// The faerie's "wave" clip as a tracker sees it.
fn view() -> TrackerView {
    common::faerie_tracker_view(112..123).0
}

fn read(path: &Path, file: &TrackFile) -> doma::Result<doma::data::tracks::Tracks> {
    read_npz_tracks(path, file)
}

#[test]
fn the_simulated_tracker_hides_back_faces_spans_and_late_starts() {
    let v = view();
    let (t, n) = (v.truth.frames(), v.truth.points());
    let observed = v.observed();
    let hidden = observed.iter().filter(|&&o| !o).count();
    // Roughly half of a closed mesh faces away from a camera.
    assert!(
        hidden > t * n / 4 && hidden < 3 * t * n / 4,
        "{hidden} of {}",
        t * n
    );
    let late = (0..n).filter(|&i| !v.valid[i]).count();
    assert!(late > 0 && late < n / 2, "{late} late tracks");
}

#[test]
fn pointodyssey_round_trips_with_its_mask_frames_and_hidden_count() {
    let v = view();
    let dir = common::scratch("doma-po");
    let path = dir.join("anno.npz");
    v.write(&path, Layout::PointOdyssey).unwrap();
    let tracks = read(&path, &TrackFile::default()).unwrap();
    assert_eq!(
        (tracks.frames(), tracks.points()),
        (v.truth.frames(), v.truth.points())
    );
    assert_eq!(tracks.observed(), &v.observed()[..]);
    // World frame, rounded to halves.
    let half = |x: f32| {
        doma_formats::npy::parse_npy(&doma_formats::npy::encode_npy_values(
            &[1],
            NpyValues::F16(&[x]),
        ))
        .unwrap()
        .data[0]
    };
    for (a, b) in tracks.positions().iter().zip(v.truth.positions()) {
        assert_eq!(*a, half(*b));
    }
    // Valid but hidden entries count with --count-hidden.
    let counted = read(
        &path,
        &TrackFile {
            count_hidden: true,
            ..TrackFile::default()
        },
    )
    .unwrap();
    assert_eq!(counted.observed(), &v.valid[..]);
    // The camera frame applies the extrinsics.
    let camera = read(
        &path,
        &TrackFile {
            frame: Some(CoordFrame::Camera),
            ..TrackFile::default()
        },
    )
    .unwrap();
    let expected = v.camera_positions();
    for (a, b) in camera.positions().iter().zip(&expected) {
        assert!((a - b).abs() < 0.1, "{a} vs {b}");
    }
}

#[test]
fn tapvid3d_round_trips_in_its_camera_frame_exactly() {
    let v = view();
    let dir = common::scratch("doma-tv");
    let path = dir.join("clip.npz");
    v.write(&path, Layout::TapVid3d).unwrap();
    let tracks = read(&path, &TrackFile::default()).unwrap();
    assert_eq!(tracks.positions(), &v.camera_positions()[..]);
    assert_eq!(tracks.observed(), &v.observed()[..]);
    // Forcing the other layout names the key it lacks.
    let err = read(
        &path,
        &TrackFile {
            layout: Some(Layout::PointOdyssey),
            ..TrackFile::default()
        },
    )
    .unwrap_err()
    .to_string();
    assert!(
        err.contains("clip.npz") && err.contains("trajs_3d"),
        "{err}"
    );
    for (file, flag) in [
        (
            TrackFile {
                frame: Some(CoordFrame::World),
                ..TrackFile::default()
            },
            "--frame world",
        ),
        (
            TrackFile {
                count_hidden: true,
                ..TrackFile::default()
            },
            "--count-hidden",
        ),
    ] {
        let err = read(&path, &file).unwrap_err().to_string();
        assert!(err.contains(flag) && err.contains("clip.npz"), "{err}");
    }
}

#[test]
fn the_masked_layout_round_trips_exactly_and_refuses_a_frame() {
    let v = view();
    let dir = common::scratch("doma-masked");
    let path = dir.join("tracks.npz");
    v.write(&path, Layout::Masked).unwrap();
    let tracks = read(&path, &TrackFile::default()).unwrap();
    assert_eq!(tracks.positions(), v.truth.positions());
    assert_eq!(tracks.observed(), &v.observed()[..]);
    let err = read(
        &path,
        &TrackFile {
            frame: Some(CoordFrame::Camera),
            ..TrackFile::default()
        },
    )
    .unwrap_err()
    .to_string();
    assert!(
        err.contains("--frame") && err.contains("tracks.npz") && err.contains("masked"),
        "{err}"
    );
}

/// A PointOdyssey-like archive of 2 frames × 3 tracks with the given members replaced.
fn archive(path: &Path, trajs: &[f32], visibs: (&[usize], &[bool]), drop: Option<&str>) {
    let valids = [true; 6];
    let members: Vec<(&str, &[usize], NpyValues)> = vec![
        ("trajs_3d", &[2, 3, 3], NpyValues::F16(trajs)),
        ("visibs", visibs.0, NpyValues::Bool(visibs.1)),
        ("valids", &[2, 3], NpyValues::Bool(&valids)),
    ];
    let kept: Vec<_> = members.into_iter().filter(|m| Some(m.0) != drop).collect();
    std::fs::write(path, encode_npz_values(&kept)).unwrap();
}

#[test]
fn bad_tracker_files_are_refused_naming_the_file_and_the_key() {
    let dir = common::scratch("doma-bad-tracks");
    let path = dir.join("anno.npz");
    let trajs: Vec<f32> = (0..18).map(|i| i as f32).collect();
    let seen = [true; 6];
    let check = |needles: &[&str]| {
        let err = read(&path, &TrackFile::default()).unwrap_err().to_string();
        assert!(err.contains("anno.npz"), "{err}");
        for n in needles {
            assert!(err.contains(n), "{err} lacks {n}");
        }
    };
    archive(&path, &trajs, (&[2, 3], &seen), Some("visibs"));
    check(&["no key \"visibs\""]);
    archive(&path, &trajs, (&[3, 2], &seen), None);
    check(&["visibs has shape [3, 2]", "[2, 3]"]);
    // A coordinate past f16's range is stored as infinity: refused where observed...
    let mut big = trajs.clone();
    big[4] = 1e6;
    assert_eq!(f32_to_f16(1e6), 0x7c00);
    archive(&path, &big, (&[2, 3], &seen), None);
    check(&["trajs_3d", "point 1 of frame 0", "inf", "f16"]);
    // ... and ignored where hidden.
    let mut hidden = seen;
    hidden[1] = false;
    archive(&path, &big, (&[2, 3], &hidden), None);
    assert!(read(&path, &TrackFile::default()).is_ok());
    // A NaN in a seen frame's extrinsics is named as such, not blamed on trajs_3d.
    let mut identity = [0f32; 32];
    for k in 0..2 {
        for d in 0..4 {
            identity[16 * k + 5 * d] = 1.0;
        }
    }
    let mut extrinsics = identity;
    extrinsics[16 + 7] = f32::NAN;
    let with_extrinsics = |extrinsics: &[f32]| {
        std::fs::write(
            &path,
            encode_npz_values(&[
                ("trajs_3d", &[2, 3, 3], NpyValues::F16(&trajs)),
                ("visibs", &[2, 3], NpyValues::Bool(&seen)),
                ("valids", &[2, 3], NpyValues::Bool(&seen)),
                ("extrinsics", &[2, 4, 4], NpyValues::F32(extrinsics)),
            ]),
        )
        .unwrap()
    };
    with_extrinsics(&extrinsics);
    let camera = TrackFile {
        frame: Some(CoordFrame::Camera),
        ..TrackFile::default()
    };
    let err = read(&path, &camera).unwrap_err().to_string();
    assert!(
        err.contains("anno.npz") && err.contains("extrinsics[1, 1, 3] is NaN"),
        "{err}"
    );
    assert!(!err.contains("trajs_3d"), "{err}");
    // Finite entries that take a finite point past the f32 range are named too: the
    // entry whose product overflowed, else the largest term of a sum that did.
    for (entries, needles) in [
        (
            [(0, 3e38f32)].as_slice(),
            ["extrinsics[0, 0, 0] = 3e38", "point 1 of frame 0"],
        ),
        (
            [(5, 2e38), (6, 0.9e38)].as_slice(),
            ["extrinsics[0, 1, 1] = 2e38", "point 0 of frame 0"],
        ),
    ] {
        let mut extrinsics = identity;
        for &(i, v) in entries {
            extrinsics[i] = v;
        }
        with_extrinsics(&extrinsics);
        let err = read(&path, &camera).unwrap_err().to_string();
        assert!(err.contains("anno.npz"), "{err}");
        for n in needles {
            assert!(err.contains(n), "{err} lacks {n}");
        }
        assert!(!err.contains("trajs_3d"), "{err}");
    }
}

#[test]
fn a_never_observed_track_is_refused_with_its_count_or_dropped_and_recorded() {
    let dir = common::scratch("doma-never");
    let path = dir.join("anno.npz");
    let trajs: Vec<f32> = (0..18).map(|i| (i % 7) as f32).collect();
    // Track 1 is seen in neither frame.
    let seen = [true, false, true, true, false, true];
    archive(&path, &trajs, (&[2, 3], &seen), None);
    let err = load_sequence_with(&path, &LoadOptions::default())
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("anno.npz") && err.contains("1 of the 3 tracks") && err.contains("track 1"),
        "{err}"
    );
    let options = LoadOptions {
        drop_unobserved: true,
        ..LoadOptions::default()
    };
    let seq = load_sequence_with(&path, &options).unwrap();
    assert_eq!(seq.kept, Some(vec![0, 2]));
    assert_eq!(seq.trajectories.points(), 2);
}

#[test]
fn a_hidden_entry_s_stored_value_changes_nothing() {
    let v = view();
    let dir = common::scratch("doma-honour");
    let (a, b) = (dir.join("a.npz"), dir.join("b.npz"));
    v.write(&a, Layout::TapVid3d).unwrap();
    // The same file with every hidden entry's coordinates replaced by NaN or garbage.
    let observed = v.observed();
    let mut xyz = v.camera_positions();
    for (e, o) in observed.iter().enumerate() {
        if !o {
            xyz[3 * e] = if e % 2 == 0 { f32::NAN } else { 1e30 };
        }
    }
    let (t, n) = (v.truth.frames(), v.truth.points());
    std::fs::write(
        &b,
        encode_npz_values(&[
            ("tracks_XYZ", &[t, n, 3], NpyValues::F32(&xyz)),
            ("visibility", &[t, n], NpyValues::Bool(&observed)),
        ]),
    )
    .unwrap();
    let options = LoadOptions {
        drop_unobserved: true,
        hold_out: Some(HoldOut {
            fraction: 0.2,
            spans: doma::gaps::spans::DEFAULT_SPANS,
            seed: 4,
        }),
        ..LoadOptions::default()
    };
    let (sa, sb) = (
        load_sequence_with(&a, &options).unwrap(),
        load_sequence_with(&b, &options).unwrap(),
    );
    assert_eq!(sa.trajectories, sb.trajectories);
    assert_eq!((sa.center, sa.scale), (sb.center, sb.scale));
    assert_eq!(sa.held_out, sb.held_out);
    assert!(sa.trajectories.positions().iter().all(|x| x.is_finite()));
}

#[test]
fn blind_validation_hides_spans_from_the_fit_and_keeps_their_truth() {
    let v = view();
    let dir = common::scratch("doma-blind");
    let path = dir.join("a.npz");
    v.write(&path, Layout::TapVid3d).unwrap();
    let plain = LoadOptions {
        drop_unobserved: true,
        ..LoadOptions::default()
    };
    let with_blind = LoadOptions {
        blind_validation: Some(3),
        ..plain.clone()
    };
    let sp = load_sequence_with(&path, &plain).unwrap();
    let sb = load_sequence_with(&path, &with_blind).unwrap();
    assert!(sp.blind.is_none());
    let blind = sb.blind.expect("tracks with gaps get blind spans");
    let (p, b) = (&sp.trajectories, &sb.trajectories);
    let n = p.points();
    let (po, bo) = (p.observed().unwrap(), b.observed().unwrap());
    let seen = po.iter().filter(|&&o| o).count();
    assert_eq!(
        bo.iter().filter(|&&o| o).count(),
        seen - blind.entries.len()
    );
    // A tenth of the observations of the tracks with an interior gap, and only there.
    let t = p.frames();
    let interior = |i: usize| {
        let seen_at: Vec<usize> = (0..t).filter(|&k| po[k * n + i]).collect();
        seen_at.windows(2).any(|w| w[1] > w[0] + 1)
    };
    let gapped: Vec<usize> = (0..n).filter(|&i| interior(i)).collect();
    assert!(!gapped.is_empty() && gapped.len() < n);
    assert!(blind.entries.iter().all(|&(_, i)| interior(i)));
    let theirs: usize = gapped
        .iter()
        .map(|&i| (0..t).filter(|&k| po[k * n + i]).count())
        .sum();
    let share = blind.entries.len() as f64 / theirs as f64;
    assert!((0.09..=0.11).contains(&share), "{share}");
    for (&(k, i), truth) in blind.entries.iter().zip(&blind.truth) {
        assert!(po[k * n + i] && !bo[k * n + i], "({k}, {i})");
        // The same input position, each in its own load's normalisation.
        for (c, &v) in truth.iter().enumerate() {
            let input = p.positions()[3 * (k * n + i) + c] * sp.scale + sp.center[c];
            let kept = v * sb.scale + sb.center[c];
            assert!(
                (input - kept).abs() <= 1e-4 * input.abs().max(1.0),
                "{input} {kept}"
            );
        }
    }
    // The same seed draws the same spans; complete tracks get none.
    assert_eq!(
        load_sequence_with(&path, &with_blind).unwrap().blind,
        Some(blind)
    );
    let other = common::scratch("doma-blind-complete");
    let complete = other.join("c.npy");
    let (t, m) = (v.truth.frames(), v.truth.points());
    doma::data::npy::write_npy(&complete, &[t, m, 3], &v.camera_positions()).unwrap();
    let options = LoadOptions {
        blind_validation: Some(3),
        ..LoadOptions::default()
    };
    assert!(
        load_sequence_with(&complete, &options)
            .unwrap()
            .blind
            .is_none()
    );
}

#[test]
fn confidence_weights_are_read_from_their_key_and_checked_where_observed() {
    let dir = common::scratch("doma-confidence");
    let path = dir.join("clip.npz");
    let xyz: Vec<f32> = (0..18).map(|i| i as f32).collect();
    let write = |conf: &[f32], shape: &[usize]| {
        std::fs::write(
            &path,
            encode_npz_values(&[
                ("tracks_XYZ", &[2, 3, 3], NpyValues::F32(&xyz)),
                (
                    "visibility",
                    &[2, 3],
                    NpyValues::Bool(&[true, true, true, true, false, true]),
                ),
                ("conf", shape, NpyValues::F32(conf)),
            ]),
        )
        .unwrap();
    };
    let file = TrackFile {
        confidence: Some("conf".into()),
        ..TrackFile::default()
    };
    // The unobserved entry's NaN is never read (stored as 0).
    write(&[1.0, 0.5, 2.0, 0.0, f32::NAN, 1.0], &[2, 3]);
    let tracks = read(&path, &file).unwrap();
    assert_eq!(tracks.weights(), Some(&[1.0, 0.5, 2.0, 0.0, 0.0, 1.0][..]));
    write(&[1.0, -0.5, 2.0, 0.0, 1.0, 1.0], &[2, 3]);
    let err = read(&path, &file).unwrap_err().to_string();
    assert!(
        err.contains("clip.npz") && err.contains("conf") && err.contains("point 1 in frame 0"),
        "{err}"
    );
    write(&[1.0; 6], &[6]);
    let err = read(&path, &file).unwrap_err().to_string();
    assert!(err.contains("conf has shape [6]"), "{err}");
    let err = read(
        &path,
        &TrackFile {
            confidence: Some("nope".into()),
            ..TrackFile::default()
        },
    )
    .unwrap_err()
    .to_string();
    assert!(err.contains("no key \"nope\""), "{err}");
}

#[test]
fn a_visibility_is_read_by_its_dtype_and_odd_codes_are_refused() {
    let dir = common::scratch("doma-visibility");
    let (t, n) = (2, 3);
    let positions: Vec<f32> = (0..t * n * 3).map(|v| v as f32).collect();
    let write = |name: &str, visibility: NpyValues| {
        let path = dir.join(name);
        std::fs::write(
            &path,
            encode_npz_values(&[
                ("tracks_XYZ", &[t, n, 3], NpyValues::F32(&positions)),
                ("visibility", &[t, n], visibility),
            ]),
        )
        .unwrap();
        path
    };
    let observed = |path: &Path, threshold: Option<f64>| {
        let file = TrackFile {
            visibility_threshold: threshold,
            ..TrackFile::default()
        };
        read(path, &file).map(|tr| tr.observed().to_vec())
    };
    // A probability (CoTracker-like): observed from 0.5, or from the threshold given.
    let probabilities = write("p.npz", NpyValues::F32(&[0.3, 0.9, 0.5, 1.0, 0.0, 0.49]));
    assert_eq!(
        observed(&probabilities, None).unwrap(),
        [false, true, true, true, false, false]
    );
    assert_eq!(
        observed(&probabilities, Some(0.25)).unwrap(),
        [true, true, true, true, false, true]
    );
    // Integers 0 and 1 are a mask; any other code, and a NaN, is refused naming the entry.
    let codes = write("i.npz", NpyValues::I64(&[1, 0, 1, 1, 1, 1]));
    assert_eq!(
        observed(&codes, None).unwrap(),
        [true, false, true, true, true, true]
    );
    for (name, values, entry) in [
        (
            "two.npz",
            NpyValues::I64(&[1, 2, 1, 1, 1, 1]),
            "visibility[0, 1]",
        ),
        (
            "minus.npz",
            NpyValues::I64(&[1, 1, 1, 1, -1, 1]),
            "visibility[1, 1]",
        ),
        (
            "nan.npz",
            NpyValues::F32(&[1.0, 1.0, f32::NAN, 1.0, 1.0, 1.0]),
            "visibility[0, 2]",
        ),
        (
            "big.npz",
            NpyValues::F32(&[1.0, 1.0, 1.0, 1.5, 1.0, 1.0]),
            "visibility[1, 0]",
        ),
    ] {
        let path = write(name, values);
        match observed(&path, None) {
            Err(doma::DomaError::Malformed { path: p, reason }) => {
                assert_eq!(p, path);
                assert!(reason.contains(entry), "{name}: {reason}");
            }
            other => panic!("{name}: {other:?}"),
        }
    }
    // A threshold outside (0, 1] is refused naming the flag.
    let e = observed(&probabilities, Some(0.0)).unwrap_err().to_string();
    assert!(e.contains("--visibility-threshold"), "{e}");
}
