//! Which share of a manifest one process trains: shard I of N takes the
//! subjects at positions I, I+N, I+2N, … (so adding subjects at the end of a
//! manifest moves none already assigned). The shard comes from the command
//! line or from the scheduler: a Slurm job array or a Kubernetes Indexed Job.

use crate::error::{Error, Result};

/// Shard `index` of `count` (0-based).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Shard {
    /// This shard, from 0.
    pub index: usize,
    /// How many shards share the manifest.
    pub count: usize,
}

impl Shard {
    /// The whole manifest in one process.
    pub const ALL: Shard = Shard { index: 0, count: 1 };

    /// Parses `I/N` (`--shard 2/8`).
    pub fn parse(text: &str) -> std::result::Result<Shard, String> {
        let bad = || {
            format!(
                "'{}' is not a shard: write I/N with 0 <= I < N, e.g. 0/4",
                crate::text::printable(text)
            )
        };
        let (i, n) = text.split_once('/').ok_or_else(bad)?;
        let index: usize = i.trim().parse().map_err(|_| bad())?;
        let count: usize = n.trim().parse().map_err(|_| bad())?;
        Shard::new(index, count).map_err(|_| bad())
    }

    /// Shard `index` of `count`, refused when out of range.
    pub fn new(index: usize, count: usize) -> Result<Shard> {
        if count == 0 || index >= count {
            return Err(Error::input(format!(
                "shard {index} of {count} is out of range: shards are 0 to N-1 of N >= 1"
            )));
        }
        Ok(Shard { index, count })
    }

    /// The shard the scheduler gave this process: `SLURM_ARRAY_TASK_ID` of
    /// `SLURM_ARRAY_TASK_COUNT` (an array `--array=0-(N-1)`), else a
    /// Kubernetes Indexed Job's `JOB_COMPLETION_INDEX`; `count` (`--shards`)
    /// overrides the task count and is needed with Kubernetes, which does not
    /// tell a pod the job's completions. No scheduler: the whole manifest.
    pub fn from_env(env: &dyn Fn(&str) -> Option<String>, count: Option<usize>) -> Result<Shard> {
        let number = |name: &str| -> Result<Option<usize>> {
            match env(name) {
                None => Ok(None),
                Some(v) if v.trim().is_empty() => Ok(None),
                Some(v) => v.trim().parse().map(Some).map_err(|_| {
                    Error::input(format!(
                        "{name}='{}' is not a number",
                        crate::text::printable(&v)
                    ))
                }),
            }
        };
        let (index, task_count, source) = if let Some(id) = number("SLURM_ARRAY_TASK_ID")? {
            // The task count is the shard count only for an array 0..N-1 in
            // steps of 1: `--array=1-4`, `--array=0-14:2` or one task
            // resubmitted alone (`--array=2`, "task 2 of 1") need --shards.
            let (min, max, step, tasks) = (
                number("SLURM_ARRAY_TASK_MIN")?,
                number("SLURM_ARRAY_TASK_MAX")?,
                number("SLURM_ARRAY_TASK_STEP")?.unwrap_or(1),
                number("SLURM_ARRAY_TASK_COUNT")?,
            );
            let whole =
                min == Some(0) && step == 1 && tasks.is_some() && max.map(|m| m + 1) == tasks;
            if !whole && count.is_none() {
                return Err(Error::input(format!(
                    "this Slurm array is not 0-(N-1) in steps of 1 (task {id} of tasks {}-{} step {step}): \
                     pass --shards N, or submit --array=0-(N-1)",
                    min.map_or("?".into(), |m| m.to_string()),
                    max.map_or("?".into(), |m| m.to_string()),
                )));
            }
            (id, tasks, "SLURM_ARRAY_TASK_ID")
        } else if let Some(id) = number("JOB_COMPLETION_INDEX")? {
            (id, None, "JOB_COMPLETION_INDEX")
        } else {
            return match count {
                Some(n) => Err(Error::input(format!(
                    "--shards {n} needs a shard index: pass --shard I/{n}, or run in a Slurm array or Kubernetes Indexed Job"
                ))),
                None => Ok(Shard::ALL),
            };
        };
        let Some(count) = count.or(task_count) else {
            return Err(Error::input(format!(
                "{source} is {index} but the number of shards is unknown: pass --shards N"
            )));
        };
        Shard::new(index, count).map_err(|_| {
            Error::input(format!(
                "{source} {index} is outside shards 0 to {}: submit the array as --array=0-{} or pass --shard I/N",
                count.saturating_sub(1),
                count.saturating_sub(1)
            ))
        })
    }

    /// Whether the subject at `position` in the manifest is this shard's.
    pub fn takes(&self, position: usize) -> bool {
        position % self.count == self.index
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

    fn env(pairs: &'static [(&'static str, &'static str)]) -> impl Fn(&str) -> Option<String> {
        move |k| {
            pairs
                .iter()
                .find(|(n, _)| *n == k)
                .map(|(_, v)| v.to_string())
        }
    }

    #[test]
    fn shards_parse_and_refuse_out_of_range() {
        assert_eq!(Shard::parse("2/8"), Ok(Shard { index: 2, count: 8 }));
        for bad in ["8/8", "0/0", "1", "-1/4", "a/b", "1/4/2"] {
            assert!(Shard::parse(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn every_subject_goes_to_exactly_one_shard() {
        for count in 1..6 {
            for position in 0..20 {
                let takers = (0..count)
                    .filter(|&i| Shard::new(i, count).unwrap().takes(position))
                    .count();
                assert_eq!(takers, 1);
            }
        }
    }

    #[test]
    fn the_shard_comes_from_slurm_or_kubernetes() {
        let slurm = env(&[
            ("SLURM_ARRAY_TASK_ID", "3"),
            ("SLURM_ARRAY_TASK_MIN", "0"),
            ("SLURM_ARRAY_TASK_MAX", "3"),
            ("SLURM_ARRAY_TASK_STEP", "1"),
            ("SLURM_ARRAY_TASK_COUNT", "4"),
        ]);
        assert_eq!(
            Shard::from_env(&slurm, None).unwrap(),
            Shard { index: 3, count: 4 }
        );
        let k8s = env(&[("JOB_COMPLETION_INDEX", "1")]);
        assert_eq!(
            Shard::from_env(&k8s, Some(2)).unwrap(),
            Shard { index: 1, count: 2 }
        );
        let e = Shard::from_env(&k8s, None).unwrap_err();
        assert!(e.to_string().contains("--shards"), "{e}");
        assert_eq!(Shard::from_env(&env(&[]), None).unwrap(), Shard::ALL);
        let junk = env(&[("SLURM_ARRAY_TASK_ID", "x")]);
        assert!(Shard::from_env(&junk, None).is_err());
    }

    #[test]
    fn arrays_not_numbered_from_zero_in_steps_of_one_need_the_shard_count() {
        // One task of a four-task array resubmitted alone (--array=2): Slurm
        // says task 2 of 1. Refused, not read as "the whole manifest".
        let alone = env(&[
            ("SLURM_ARRAY_TASK_ID", "2"),
            ("SLURM_ARRAY_TASK_MIN", "2"),
            ("SLURM_ARRAY_TASK_MAX", "2"),
            ("SLURM_ARRAY_TASK_COUNT", "1"),
        ]);
        let e = Shard::from_env(&alone, None).unwrap_err();
        assert_eq!(e.exit_code(), 2);
        assert!(e.to_string().contains("--shards N"), "{e}");
        assert_eq!(
            Shard::from_env(&alone, Some(4)).unwrap(),
            Shard { index: 2, count: 4 }
        );
        // --array=1-4 would never run shard 0; --array=0-14:2 would skip the
        // odd shards: both refused without --shards.
        for (min, max, step, count, id) in [("1", "4", "1", "4", "1"), ("0", "14", "2", "8", "2")] {
            let array = [
                ("SLURM_ARRAY_TASK_ID", id),
                ("SLURM_ARRAY_TASK_MIN", min),
                ("SLURM_ARRAY_TASK_MAX", max),
                ("SLURM_ARRAY_TASK_STEP", step),
                ("SLURM_ARRAY_TASK_COUNT", count),
            ];
            let lookup = move |k: &str| {
                array
                    .iter()
                    .find(|(n, _)| *n == k)
                    .map(|(_, v)| v.to_string())
            };
            assert!(
                Shard::from_env(&lookup, None).is_err(),
                "{min}-{max}:{step}"
            );
        }
        // An index past the given count is refused too.
        let e = Shard::from_env(&alone, Some(2)).unwrap_err();
        assert!(e.to_string().contains("SLURM_ARRAY_TASK_ID 2"), "{e}");
    }
}
