//! The fill of a run that combines several fits ([`super::super::RunConfig::fits`]): each
//! entry the median of the fits' values. A fit's fill weighs its fillers on a few
//! validation spans per class of gap length; one that chose wrongly there is off by far on
//! a whole class, which a median of three ignores and a mean of two halves.

/// The median of the fits' values of each entry, coordinate by coordinate (of an even
/// count, the mean of the middle two).
pub(super) fn median_of(fits: &[Vec<[f32; 3]>]) -> Vec<[f32; 3]> {
    let k = fits.len();
    let mut column = vec![0.0f32; k];
    (0..fits[0].len())
        .map(|e| {
            std::array::from_fn(|d| {
                for (c, fit) in column.iter_mut().zip(fits) {
                    *c = fit[e][d];
                }
                column.sort_unstable_by(f32::total_cmp);
                if k % 2 == 1 {
                    column[k / 2]
                } else {
                    0.5 * (column[k / 2 - 1] + column[k / 2])
                }
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_fit_is_itself_two_their_mean_three_their_median() {
        let a = vec![[1.0, -2.0, 0.5], [4.0, 4.0, 4.0]];
        let b = vec![[3.0, -4.0, 0.5], [4.0, 5.0, 6.0]];
        // The third fit is far off in the second entry's first coordinate: ignored.
        let c = vec![[2.0, -9.0, 1.5], [400.0, 4.5, 5.0]];
        assert_eq!(median_of(std::slice::from_ref(&a)), a);
        assert_eq!(
            median_of(&[a.clone(), b.clone()]),
            vec![[2.0, -3.0, 0.5], [4.0, 4.5, 5.0]]
        );
        assert_eq!(
            median_of(&[a, b, c]),
            vec![[2.0, -4.0, 0.5], [4.0, 4.5, 5.0]]
        );
    }

    #[test]
    fn four_fits_take_the_mean_of_the_middle_two() {
        let fits: Vec<Vec<[f32; 3]>> = [8.0, 1.0, 2.0, 4.0]
            .iter()
            .map(|&v| vec![[v, -v, 0.0]])
            .collect();
        assert_eq!(median_of(&fits), vec![[3.0, -3.0, 0.0]]);
    }
}
