//! Several trials of one deterministic benchmark run, summarised by the best and the median
//! wall time.
//!
//! On a shared machine one trial's wall time swings with other processes' load, so a single
//! trial cannot be compared with a floor. The simulation is deterministic: every trial does
//! exactly the same work, so the fastest trial is the one least disturbed (the closest
//! estimate of the code's own cost) and the median shows how much the others were disturbed.

use std::time::Duration;

use anyhow::{Result, bail};
use cantwin_bus::bench::BenchReport;
use cantwin_bus::bench::limit::LimitReport;
use indicatif::ProgressBar;

/// One trial's report.
pub trait Trial: Copy {
    /// Wall time of the measured part of the run.
    fn wall(&self) -> Duration;

    /// The same report as if the measured part had taken `wall`: every figure derived from
    /// the wall time follows it, the simulation's counts stay.
    fn with_wall(&self, wall: Duration) -> Self;

    /// The counts the simulation produced, by name. A deterministic run produces the same
    /// counts in every trial.
    fn counts(&self) -> Vec<(&'static str, u64)>;
}

impl Trial for BenchReport {
    fn wall(&self) -> Duration {
        self.wall_time
    }

    fn with_wall(&self, wall: Duration) -> Self {
        BenchReport {
            wall_time: wall,
            ..*self
        }
    }

    fn counts(&self) -> Vec<(&'static str, u64)> {
        vec![
            ("delivered frames", self.delivered),
            ("frames received", self.received),
            ("offers", self.offers),
            ("dropped offers", self.dropped_offers),
        ]
    }
}

impl Trial for LimitReport {
    fn wall(&self) -> Duration {
        self.wall_time
    }

    fn with_wall(&self, wall: Duration) -> Self {
        LimitReport {
            wall_time: wall,
            ..*self
        }
    }

    fn counts(&self) -> Vec<(&'static str, u64)> {
        vec![
            ("delivered frames", self.delivered),
            ("frames received", self.received),
        ]
    }
}

/// The trials of one run.
#[derive(Debug, Clone)]
pub struct Trials<R> {
    best: R,
    /// Every trial's wall time, shortest first; never empty.
    walls: Vec<Duration>,
}

impl<R: Trial> Trials<R> {
    /// The trials of the run named `what`, in the order they ran. An error if there are none,
    /// or if a trial's counts differ from the first trial's: the run is meant to be
    /// deterministic, and trials doing different work cannot be compared.
    pub fn new(what: &str, runs: Vec<R>) -> Result<Self> {
        let Some(first) = runs.first() else {
            bail!("{what}: no trial ran");
        };
        let expected = first.counts();
        for (k, run) in runs.iter().enumerate().skip(1) {
            let got = run.counts();
            if got != expected {
                let differences: Vec<String> = got
                    .iter()
                    .zip(&expected)
                    .filter(|(g, e)| g != e)
                    .map(|((name, g), (_, e))| format!("{name} {g} (trial 1: {e})"))
                    .collect();
                bail!(
                    "{what}: trial {} of {} did not repeat trial 1: {}; the simulation is not \
                     deterministic, so its trials cannot be compared",
                    k + 1,
                    runs.len(),
                    differences.join(", ")
                );
            }
        }
        let mut best = *first;
        for run in &runs {
            if run.wall() < best.wall() {
                best = *run;
            }
        }
        let mut walls: Vec<Duration> = runs.iter().map(Trial::wall).collect();
        walls.sort_unstable();
        Ok(Trials { best, walls })
    }

    /// The fastest trial.
    pub fn best(&self) -> R {
        self.best
    }

    /// The report at the median wall time (of an even number of trials, the mean of the two
    /// middle ones).
    pub fn median(&self) -> R {
        let n = self.walls.len();
        let upper = self.walls.get(n / 2).copied();
        let lower = self.walls.get(n.saturating_sub(1) / 2).copied();
        match (lower, upper) {
            (Some(lower), Some(upper)) => self.best.with_wall((lower + upper) / 2),
            _ => self.best,
        }
    }
}

/// Run `trial` `n` times (it gets the trial's number, from 1), showing which trial runs on
/// `spinner` as `label: trial i/n`, and collect the reports.
pub fn run<R: Trial>(
    label: &str,
    n: usize,
    spinner: &ProgressBar,
    mut trial: impl FnMut(usize) -> Result<R>,
) -> Result<Trials<R>> {
    let mut runs = Vec::with_capacity(n);
    for i in 1..=n {
        spinner.set_message(format!("{label}: trial {i}/{n}"));
        runs.push(trial(i)?);
    }
    Trials::new(label, runs)
}

/// A figure of the best trial and of the median one: `best (median median)`, both with
/// `decimals` decimals and followed by `unit`.
pub fn best_median(best: f64, median: f64, decimals: usize, unit: &str) -> String {
    format!("{best:.decimals$}{unit} (median {median:.decimals$}{unit})")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Debug, Clone, Copy, PartialEq)]
    struct Run {
        wall_ms: u64,
        frames: u64,
    }

    impl Trial for Run {
        fn wall(&self) -> Duration {
            Duration::from_millis(self.wall_ms)
        }
        fn with_wall(&self, wall: Duration) -> Self {
            Run {
                wall_ms: wall.as_millis() as u64,
                ..*self
            }
        }
        fn counts(&self) -> Vec<(&'static str, u64)> {
            vec![("frames", self.frames)]
        }
    }

    fn runs(walls: &[u64]) -> Vec<Run> {
        walls
            .iter()
            .map(|&wall_ms| Run { wall_ms, frames: 7 })
            .collect()
    }

    #[test]
    fn the_best_is_the_fastest_trial_and_the_median_the_middle_one() {
        let t = Trials::new("bench x", runs(&[300, 100, 500, 200, 900])).unwrap();
        assert_eq!(t.best().wall_ms, 100);
        assert_eq!(t.median().wall_ms, 300);
        assert_eq!(t.median().frames, 7);
    }

    #[test]
    fn the_median_of_an_even_count_is_the_mean_of_the_middle_two() {
        let t = Trials::new("bench x", runs(&[400, 100, 200, 1000])).unwrap();
        assert_eq!(t.best().wall_ms, 100);
        assert_eq!(t.median().wall_ms, 300);
        let one = Trials::new("bench x", runs(&[250])).unwrap();
        assert_eq!((one.best().wall_ms, one.median().wall_ms), (250, 250));
    }

    #[test]
    fn trials_doing_different_work_are_an_error_naming_the_count() {
        let mut r = runs(&[100, 100, 100]);
        r[2].frames = 8;
        let e = Trials::new("bench x", r).unwrap_err().to_string();
        assert!(
            e.contains("bench x: trial 3 of 3 did not repeat trial 1"),
            "{e}"
        );
        assert!(e.contains("frames 8 (trial 1: 7)"), "{e}");
        assert!(e.contains("not deterministic"), "{e}");
    }

    #[test]
    fn no_trial_is_an_error() {
        let e = Trials::<Run>::new("bench x", Vec::new()).unwrap_err();
        assert!(e.to_string().contains("no trial ran"), "{e}");
    }

    #[test]
    fn best_median_formats_both_figures() {
        assert_eq!(best_median(412.4, 380.0, 0, ""), "412 (median 380)");
        assert_eq!(
            best_median(0.1754, 0.19, 3, " s"),
            "0.175 s (median 0.190 s)"
        );
    }
}
