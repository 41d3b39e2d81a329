//! Summary statistics shared by every report the project writes (`visnode bench`, the
//! window's overlay, `balancer simulate`, `backend bench`), so a "p90" means the same
//! everywhere: the linearly interpolated quantile of the sorted values (Hyndman and Fan's
//! type 7, what NumPy and R use by default); with the feature `plots`, the look of every PNG
//! plot ([`plot`]).
#![warn(missing_docs)]

#[cfg(feature = "plots")]
pub mod plot;

use serde::Serialize;

/// The `q` quantile (0 to 1) of `sorted` (ascending), linearly interpolated between the two
/// nearest ranks; 0 for no values.
pub fn quantile(sorted: &[f64], q: f64) -> f64 {
    if sorted.is_empty() {
        return 0.0;
    }
    let at = q.clamp(0.0, 1.0) * (sorted.len() - 1) as f64;
    let (low, high) = (at.floor() as usize, at.ceil() as usize);
    sorted[low] + (sorted[high] - sorted[low]) * (at - low as f64)
}

/// Mean, percentiles and maximum of a sample.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct Stats {
    /// Mean.
    pub mean: f64,
    /// Median.
    pub p50: f64,
    /// 90th percentile.
    pub p90: f64,
    /// 95th percentile.
    pub p95: f64,
    /// 99th percentile.
    pub p99: f64,
    /// Largest.
    pub max: f64,
    /// Sample size.
    pub count: usize,
}

impl Stats {
    /// Statistics of the finite `values` (NaN and infinities are left out; all zero when
    /// none is left).
    pub fn of(values: impl IntoIterator<Item = f64>) -> Stats {
        let mut v: Vec<f64> = values.into_iter().filter(|x| x.is_finite()).collect();
        if v.is_empty() {
            return Stats::default();
        }
        v.sort_by(f64::total_cmp);
        Stats {
            mean: v.iter().sum::<f64>() / v.len() as f64,
            p50: quantile(&v, 0.5),
            p90: quantile(&v, 0.9),
            p95: quantile(&v, 0.95),
            p99: quantile(&v, 0.99),
            max: v[v.len() - 1],
            count: v.len(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quantiles_interpolate_between_ranks() {
        let v = [1.0, 2.0, 3.0, 4.0, 5.0];
        assert_eq!(quantile(&v, 0.0), 1.0);
        assert_eq!(quantile(&v, 0.5), 3.0);
        assert_eq!(quantile(&v, 1.0), 5.0);
        // 0.9 × 4 = 3.6: 60% of the way from 4 to 5.
        assert!((quantile(&v, 0.9) - 4.6).abs() < 1e-12);
        assert_eq!(quantile(&[7.0], 0.3), 7.0);
        assert_eq!(quantile(&[], 0.5), 0.0);
    }

    #[test]
    fn stats_skip_non_finite_values() {
        let stats = Stats::of((1..=11).map(f64::from).chain([f64::NAN, f64::INFINITY]));
        assert_eq!(stats.count, 11);
        assert_eq!(stats.mean, 6.0);
        assert_eq!((stats.p50, stats.p90, stats.max), (6.0, 10.0, 11.0));
        assert!((stats.p99 - 10.9).abs() < 1e-12);
        let one = Stats::of([4.0]);
        assert_eq!((one.p50, one.p90, one.max), (4.0, 4.0, 4.0));
        assert_eq!(Stats::of([]).count, 0);
    }
}
