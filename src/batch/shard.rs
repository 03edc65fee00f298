//! Which part of a batch one process runs. Fits are independent, so a dataset is spread
//! over a cluster's job array: shard `I` of `N` runs entries `I, I + N, I + 2N, …`.
//! The index comes from `--shard I/N`, or from the scheduler's environment:
//!
//! | scheduler | index | count |
//! |---|---|---|
//! | Slurm job array (`sbatch --array=0-7`) | `SLURM_ARRAY_TASK_ID` (minus `SLURM_ARRAY_TASK_MIN`, over `SLURM_ARRAY_TASK_STEP`) | `SLURM_ARRAY_TASK_COUNT` |
//! | Kubernetes Indexed Job | `JOB_COMPLETION_INDEX` | `--shard-count N` (the Job's `completions`; Kubernetes does not export it) |
//!
//! With none of them, the one process runs every entry (`0/1`).

use serde::{Deserialize, Serialize};

use crate::{DomaError, Result};

/// Shard `index` of `count`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Shard {
    /// 0-based, below `count`.
    pub index: usize,
    /// At least 1.
    pub count: usize,
}

impl Shard {
    /// The whole batch in one process.
    pub const ALL: Shard = Shard { index: 0, count: 1 };

    /// Shard `index` of `count`, checked.
    pub fn new(index: usize, count: usize) -> Result<Shard> {
        if count == 0 || index >= count {
            return Err(DomaError::Usage(format!(
                "shard {index}/{count}: the index must be below the count, and the count at least 1"
            )));
        }
        Ok(Shard { index, count })
    }

    /// Parses `I/N` (the clap value parser of `--shard`).
    pub fn parse(s: &str) -> std::result::Result<Shard, String> {
        let (i, n) = s
            .split_once('/')
            .ok_or_else(|| format!("`{s}` is not I/N (e.g. 0/4)"))?;
        let num = |v: &str| {
            v.trim()
                .parse::<usize>()
                .map_err(|_| format!("`{s}`: `{v}` is not a whole number"))
        };
        Shard::new(num(i)?, num(n)?).map_err(|e| e.to_string())
    }

    /// The shard that the environment (`var`) names, if any: Slurm's job-array variables,
    /// or Kubernetes' `JOB_COMPLETION_INDEX` with `count` (from `--shard-count`).
    pub fn from_env(
        var: impl Fn(&str) -> Option<String>,
        count: Option<usize>,
    ) -> Result<Option<Shard>> {
        let number = |name: &str| -> Result<Option<usize>> {
            match var(name) {
                None => Ok(None),
                Some(v) => v.trim().parse().map(Some).map_err(|_| {
                    DomaError::Usage(format!("${name} = `{v}` is not a whole number"))
                }),
            }
        };
        if let Some(id) = number("SLURM_ARRAY_TASK_ID")? {
            let min = number("SLURM_ARRAY_TASK_MIN")?.unwrap_or(0);
            let step = number("SLURM_ARRAY_TASK_STEP")?.unwrap_or(1).max(1);
            let n = match count {
                Some(n) => n,
                None => number("SLURM_ARRAY_TASK_COUNT")?.ok_or_else(|| {
                    DomaError::Usage(
                        "$SLURM_ARRAY_TASK_ID is set but $SLURM_ARRAY_TASK_COUNT is not: give --shard-count".into(),
                    )
                })?,
            };
            let offset = id.checked_sub(min).ok_or_else(|| {
                DomaError::Usage(format!(
                    "$SLURM_ARRAY_TASK_ID {id} is below $SLURM_ARRAY_TASK_MIN {min}"
                ))
            })?;
            return Shard::new(offset / step, n).map(Some).map_err(|e| {
                DomaError::Usage(format!(
                    "from $SLURM_ARRAY_TASK_ID {id} (min {min}, step {step}) and {}: {e}",
                    if count.is_some() {
                        "--shard-count".to_string()
                    } else {
                        format!("$SLURM_ARRAY_TASK_COUNT {n}")
                    }
                ))
            });
        }
        if let Some(index) = number("JOB_COMPLETION_INDEX")? {
            let n = count.ok_or_else(|| {
                DomaError::Usage(
                    "$JOB_COMPLETION_INDEX is set: give the Job's completions as --shard-count N"
                        .into(),
                )
            })?;
            return Shard::new(index, n).map(Some).map_err(|e| {
                DomaError::Usage(format!(
                    "from $JOB_COMPLETION_INDEX {index} and --shard-count {n}: {e}"
                ))
            });
        }
        Ok(None)
    }

    /// Whether entry `i` of the batch is this shard's.
    pub fn owns(&self, i: usize) -> bool {
        i % self.count == self.index
    }
}

impl std::fmt::Display for Shard {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}/{}", self.index, self.count)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn env<'a>(pairs: &'a [(&'a str, &'a str)]) -> impl Fn(&str) -> Option<String> + 'a {
        move |k| {
            pairs
                .iter()
                .find(|(name, _)| *name == k)
                .map(|(_, v)| v.to_string())
        }
    }

    #[test]
    fn i_of_n_parses_and_is_checked() {
        assert_eq!(Shard::parse("2/5"), Ok(Shard { index: 2, count: 5 }));
        for bad in ["5/5", "1/0", "1", "a/2", "-1/2"] {
            assert!(Shard::parse(bad).is_err(), "{bad}");
        }
        let s = Shard::parse("1/3").unwrap();
        let mine: Vec<usize> = (0..8).filter(|&i| s.owns(i)).collect();
        assert_eq!(mine, [1, 4, 7]);
    }

    #[test]
    fn an_index_out_of_range_says_which_variables_gave_it() {
        let slurm = env(&[
            ("SLURM_ARRAY_TASK_ID", "9"),
            ("SLURM_ARRAY_TASK_COUNT", "4"),
        ]);
        let err = Shard::from_env(slurm, None).unwrap_err().to_string();
        assert!(
            err.contains("$SLURM_ARRAY_TASK_ID 9") && err.contains("$SLURM_ARRAY_TASK_COUNT 4"),
            "{err}"
        );
        let k8s = env(&[("JOB_COMPLETION_INDEX", "5")]);
        let err = Shard::from_env(k8s, Some(2)).unwrap_err().to_string();
        assert!(
            err.contains("$JOB_COMPLETION_INDEX 5") && err.contains("--shard-count 2"),
            "{err}"
        );
    }

    #[test]
    fn slurm_and_kubernetes_name_the_shard() {
        let none = Shard::from_env(env(&[]), None).unwrap();
        assert_eq!(none, None);
        let slurm = env(&[
            ("SLURM_ARRAY_TASK_ID", "3"),
            ("SLURM_ARRAY_TASK_COUNT", "4"),
        ]);
        assert_eq!(
            Shard::from_env(slurm, None).unwrap(),
            Some(Shard { index: 3, count: 4 })
        );
        // `--array=1-4`: ids 1..=4 are shards 0..=3.
        let based = env(&[
            ("SLURM_ARRAY_TASK_ID", "1"),
            ("SLURM_ARRAY_TASK_MIN", "1"),
            ("SLURM_ARRAY_TASK_COUNT", "4"),
        ]);
        assert_eq!(
            Shard::from_env(based, None).unwrap(),
            Some(Shard { index: 0, count: 4 })
        );
        // `--array=0-6:2`: ids 0, 2, 4, 6 are shards 0..=3.
        let stepped = env(&[
            ("SLURM_ARRAY_TASK_ID", "4"),
            ("SLURM_ARRAY_TASK_STEP", "2"),
            ("SLURM_ARRAY_TASK_COUNT", "4"),
        ]);
        assert_eq!(
            Shard::from_env(stepped, None).unwrap(),
            Some(Shard { index: 2, count: 4 })
        );
        let k8s = env(&[("JOB_COMPLETION_INDEX", "2")]);
        assert_eq!(
            Shard::from_env(&k8s, Some(3)).unwrap(),
            Some(Shard { index: 2, count: 3 })
        );
        let err = Shard::from_env(&k8s, None).unwrap_err().to_string();
        assert!(err.contains("--shard-count"), "{err}");
        let bad = env(&[("JOB_COMPLETION_INDEX", "x")]);
        assert!(Shard::from_env(bad, Some(2)).is_err());
        let over = env(&[("JOB_COMPLETION_INDEX", "3")]);
        assert!(Shard::from_env(over, Some(3)).is_err());
    }
}
