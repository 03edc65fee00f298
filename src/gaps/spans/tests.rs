//! The spans' tests: where the gaps are, their lengths, and the spans hidden to measure
//! a fill or to validate a blend.

use super::*;

#[test]
fn gaps_are_the_unobserved_runs_between_the_nearest_observed_frames() {
    let seen = [false, true, false, false, true, false];
    let positions = vec![0f32; 18];
    let tracks = Marked::new(6, 1, &positions, &seen);
    assert_eq!(
        track_gaps(&tracks, 0),
        vec![
            Gap {
                track: 0,
                frames: 0..1,
                before: None,
                after: Some(1)
            },
            Gap {
                track: 0,
                frames: 2..4,
                before: Some(1),
                after: Some(4)
            },
            Gap {
                track: 0,
                frames: 5..6,
                before: Some(4),
                after: None
            },
        ]
    );
    let never = [false; 6];
    assert!(track_gaps(&Marked::new(6, 1, &positions, &never), 0).is_empty());
}

#[test]
fn the_gap_index_finds_each_entry_s_gap() {
    // One track of 40 frames: seen at 0, 4, 30, 39 (gaps of 3, 25 and 8), and one never
    // seen.
    let (t, n) = (40, 2);
    let mut observed = vec![false; t * n];
    for k in [0, 4, 30, 39] {
        observed[k * n] = true;
    }
    let positions = vec![0f32; 3 * t * n];
    let index = GapIndex::new(&Marked::new(t, n, &positions, &observed));
    assert_eq!(index.gap_at(2, 0), Some(1..4));
    assert_eq!(index.len_at(10, 0), Some(25));
    assert_eq!(index.len_at(5, 0), Some(25));
    assert_eq!(index.len_at(29, 0), Some(25));
    assert_eq!(index.len_at(35, 0), Some(8));
    assert_eq!(index.len_at(30, 0), None);
    assert_eq!(index.len_at(0, 0), None);
    assert!((0..t).all(|k| index.len_at(k, 1).is_none()));
}

#[test]
fn validation_spans_are_drawn_by_class_so_that_a_rare_short_gap_gets_its_share() {
    // 20 tracks of 1100 frames: 18 with a gap of 50 frames, 2 with one of 5, none
    // overlapping another. Drawn gap by gap, a 5-frame gap leads one pick in ten, about
    // 5 of the ~47 spans that reach a tenth of the entries; drawn class first, half the
    // picks, about 39 of ~78.
    let (t, n) = (1100usize, 20usize);
    let positions = vec![0f32; 3 * t * n];
    let mut observed = vec![true; t * n];
    for i in 0..n {
        let (start, len) = if i < 18 {
            (20 + 55 * i, 50)
        } else {
            (1040 + 20 * (i - 18), 5)
        };
        for k in start..start + len {
            observed[k * n + i] = false;
        }
    }
    let tracks = Marked::new(t, n, &positions, &observed);
    let short_spans = |spans: &[(usize, usize)]| {
        let set: std::collections::HashSet<_> = spans.iter().copied().collect();
        // A span's first frame: hidden, with its frame before not hidden.
        spans
            .iter()
            .filter(|&&(k, i)| !set.contains(&(k.wrapping_sub(1), i)))
            .filter(|&&(k, i)| (k..k + 6).take_while(|&j| set.contains(&(j, i))).count() <= 5)
            .count()
    };
    let (mut by_gap, mut by_class) = (0, 0);
    for seed in 0..4 {
        by_gap += short_spans(&validation_spans(&tracks, 0.1, seed, |_| 0).unwrap());
        let class = |len: usize| usize::from(len > 16);
        by_class += short_spans(&validation_spans(&tracks, 0.1, seed, class).unwrap());
    }
    assert!(
        by_class > 3 * by_gap && by_gap > 0,
        "{by_class} against {by_gap}"
    );
}

#[test]
fn validation_spans_are_drawn_in_the_tracks_with_gaps_and_leave_the_others_whole() {
    // Ten tracks of 60 frames; tracks 2 and 7 have a gap of 6 frames. The spans fall in
    // those two alone, a tenth of their observations, 6 frames long; without a gap
    // anywhere they fall in every track, 2 to 10 frames long.
    let (t, n) = (60usize, 10usize);
    let positions = vec![0f32; 3 * t * n];
    let mut observed = vec![true; t * n];
    for i in [2, 7] {
        for k in 20..26 {
            observed[k * n + i] = false;
        }
    }
    let tracks = Marked::new(t, n, &positions, &observed);
    let spans = validation_spans(&tracks, 0.1, 3, |_| 0).unwrap();
    assert!(spans.iter().all(|&(_, i)| i == 2 || i == 7), "{spans:?}");
    assert_eq!(spans.len(), (0.1f64 * 2.0 * 54.0).round() as usize);
    // Their gaps are at the same frames: so are the spans (the second cut at the
    // fraction).
    let frames =
        |i: usize| -> Vec<usize> { spans.iter().filter(|s| s.1 == i).map(|s| s.0).collect() };
    let (a, b) = (frames(2), frames(7));
    let (short, long) = if a.len() < b.len() {
        (&a, &b)
    } else {
        (&b, &a)
    };
    assert_eq!((short.len(), long.len()), (5, 6), "{spans:?}");
    assert!(short.iter().all(|k| long.contains(k)), "{spans:?}");
    let all = vec![true; t * n];
    let whole = Marked::new(t, n, &positions, &all);
    let spans = validation_spans(&whole, 0.1, 3, |_| 0).unwrap();
    let touched: std::collections::BTreeSet<usize> = spans.iter().map(|&(_, i)| i).collect();
    assert!(touched.len() > 2, "{touched:?}");
    assert_eq!(spans.len(), 60);
}

#[test]
fn held_out_spans_are_seeded_leave_every_track_seen_and_reach_the_fraction() {
    let (positions, all) = (vec![0f32; 1800], vec![true; 600]);
    let tracks = Marked::new(20, 30, &positions, &all);
    let a = hold_out_spans(&tracks, 0.25, DEFAULT_SPANS, 7).unwrap();
    assert_eq!(a, hold_out_spans(&tracks, 0.25, DEFAULT_SPANS, 7).unwrap());
    assert_ne!(a, hold_out_spans(&tracks, 0.25, DEFAULT_SPANS, 8).unwrap());
    assert_eq!(a.len(), 150);
    let mut left = all.clone();
    for &(k, i) in &a {
        left[k * 30 + i] = false;
    }
    assert!((0..30).all(|i| (0..20).any(|k| left[k * 30 + i])));
    // In spans: most hidden entries have a hidden neighbour in time on their track.
    let set: std::collections::BTreeSet<_> = a.iter().copied().collect();
    let runs = a
        .iter()
        .filter(|&&(k, i)| set.contains(&(k + 1, i)) || (k > 0 && set.contains(&(k - 1, i))))
        .count();
    assert!(runs as f64 > 0.9 * a.len() as f64, "{runs} of {}", a.len());
    // Inside the observations: every track keeps its first and last frame.
    assert!(a.iter().all(|&(k, _)| k > 0 && k < 19));
    assert!(hold_out_spans(&tracks, 1.0, DEFAULT_SPANS, 0).is_err());
    assert!(hold_out_spans(&tracks, 0.2, 0..=3, 0).is_err());
    // Long spans: runs of at least 6 frames, where the track had them.
    let long = hold_out_spans(&tracks, 0.2, 6..=12, 3).unwrap();
    let set: std::collections::BTreeSet<_> = long.iter().copied().collect();
    let starts: Vec<_> = long
        .iter()
        .filter(|&&(k, i)| !set.contains(&(k.wrapping_sub(1), i)))
        .collect();
    assert!(
        starts.len() * 6 <= long.len() + 6,
        "{} spans for {} entries",
        starts.len(),
        long.len()
    );
}
