use super::*;

#[test]
fn the_fillers_keep_their_order_and_every_spelling_reads_back() {
    // The order is the blend's: its weights are written by name, but a tie goes to the
    // earlier filler, so a reordering would change fills.
    let names: Vec<&str> = Filler::ALL.iter().map(|f| f.name()).collect();
    assert_eq!(
        names,
        [
            "field_fill",
            "spline",
            "neighbours",
            "iterative_pca",
            "linear",
            "field_fill_framewise",
            "pattern",
            "rigid_body",
            "kalman",
            "gloersen",
            "segment",
            "chain",
            "relational",
            "field_chain",
            "field_segment",
        ]
    );
    for (i, f) in Filler::ALL.into_iter().enumerate() {
        assert_eq!(f.index(), i);
        assert_eq!(Filler::from_name(f.name()), Some(f));
        assert_eq!(Filler::from_name(f.flag()), Some(f));
        assert!(!f.flag().contains('_'), "{}", f.flag());
        for old in f.former_names() {
            assert_eq!(Filler::from_name(old), Some(f));
        }
    }
    assert_eq!(Filler::from_name("rigid-body"), Some(Filler::RigidBody));
    assert_eq!(Filler::from_name("rigid_body"), Some(Filler::RigidBody));
    assert_eq!(Filler::from_name("rigid body"), None);
    assert!(Filler::parse("x").unwrap_err().contains("rigid-body"));
}

/// Three markers of a rigid body and a fourth bending away from them inside its gap.
fn bending() -> (usize, usize, Vec<f32>, Vec<bool>) {
    let (t, n) = (30, 4);
    let mut positions = Vec::new();
    for k in 0..t {
        let x = 0.1 * k as f32;
        let bend = 0.3 * (std::f32::consts::PI * k as f32 / (t - 1) as f32).sin();
        for p in [
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.5, 0.5, bend],
        ] {
            positions.extend([p[0] + x, p[1], p[2]]);
        }
    }
    let mut observed = vec![true; t * n];
    for k in 8..22 {
        observed[k * n + 3] = false;
    }
    (t, n, positions, observed)
}

#[test]
fn beside_an_exact_field_the_donors_fill_is_the_field_and_beside_a_still_one_the_donors() {
    let (t, n, truth, observed) = bending();
    let marked = Marked::new(t, n, &truth, &observed);
    let entries: Vec<(usize, usize)> = (8..22).map(|k| (k, 3)).collect();
    // An exact field: the donors' fill of the field is their fill of the observations,
    // so what is added is the field's own motion there: the truth.
    let exact = FieldPrediction::new(n, &truth, &truth[..3 * n], &observed);
    let sources = Sources::new(marked, &exact);
    for donor in [Filler::Chain, Filler::Segment] {
        for (p, &(k, i)) in sources.field_beside(donor, &entries).iter().zip(&entries) {
            let want = marked.at(k, i);
            assert!(
                (0..3).all(|c| (p[c] - want[c]).abs() < 1e-5),
                "{donor:?} {k}"
            );
        }
    }
    // A field that moves every track rigidly with the body (no bend): it adds nothing
    // to the chain fill, whose donors move the same way.
    let rigid: Vec<f32> = (0..t * n)
        .flat_map(|e| {
            let (k, i) = (e / n, e % n);
            let p = [
                [0.0, 0.0, 0.0],
                [1.0, 0.0, 0.0],
                [0.0, 1.0, 0.0],
                [0.5, 0.5, 0.0],
            ][i];
            [p[0] + 0.1 * k as f32, p[1], p[2]]
        })
        .collect();
    let still = FieldPrediction::new(n, &rigid, &rigid[..3 * n], &observed);
    let sources = Sources::new(marked, &still);
    let chain = marked.chain(&entries);
    for (p, q) in sources
        .field_beside(Filler::Chain, &entries)
        .iter()
        .zip(&chain)
    {
        assert!((0..3).all(|c| (p[c] - q[c]).abs() < 1e-5), "{p:?} {q:?}");
    }
}
