//! Running statistics of a run for its summary: peaks `max |x|` with their time, and errors
//! against a reference (RMS and peak, normalised by the reference's peak).

use serde::Serialize;

/// A peak `max |x|` and the time it occurred.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct Peak {
    pub max_abs: f64,
    pub t: f64,
}

/// Peaks of one vector quantity, per component.
#[derive(Debug, Clone)]
pub struct PeakTracker(pub Vec<Peak>);

impl PeakTracker {
    pub fn new(n: usize) -> Self {
        Self(vec![Peak::default(); n])
    }
    pub fn update(&mut self, x: &[f64], t: f64) {
        for (p, &v) in self.0.iter_mut().zip(x) {
            if v.abs() > p.max_abs {
                *p = Peak { max_abs: v.abs(), t };
            }
        }
    }
    /// Index and value of the largest peak (the first one of equal peaks).
    pub fn largest(&self) -> (usize, Peak) {
        largest(self.0.iter().copied())
    }
}

/// Index and value of the largest of `peaks` (the first one of equal peaks; `(0, zero)` when
/// every peak is zero or there is none).
pub fn largest(peaks: impl Iterator<Item = Peak>) -> (usize, Peak) {
    peaks.enumerate().fold((0, Peak::default()), |best, (k, p)| {
        if p.max_abs > best.1.max_abs { (k, p) } else { best }
    })
}

/// Errors of a quantity against its reference, per component.
#[derive(Debug, Clone)]
pub struct ErrorTracker {
    sum_sq: Vec<f64>,
    max_err: Vec<f64>,
    max_ref: Vec<f64>,
    count: usize,
}

/// RMS and peak error normalised by the reference peak.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct ErrorStats {
    pub rms_error: f64,
    pub peak_error: f64,
    pub reference_peak: f64,
}

impl ErrorTracker {
    pub fn new(n: usize) -> Self {
        Self {
            sum_sq: vec![0.0; n],
            max_err: vec![0.0; n],
            max_ref: vec![0.0; n],
            count: 0,
        }
    }
    pub fn update(&mut self, x: &[f64], reference: &[f64]) {
        for k in 0..self.sum_sq.len() {
            let e = x[k] - reference[k];
            self.sum_sq[k] += e * e;
            self.max_err[k] = self.max_err[k].max(e.abs());
            self.max_ref[k] = self.max_ref[k].max(reference[k].abs());
        }
        self.count += 1;
    }
    /// The largest error over all components relative to the largest reference peak over all
    /// components (NaN if the reference is identically zero): the divergence measure, which a
    /// component that hardly moves in the reference (a tiny peak, a huge relative error) does not
    /// inflate.
    pub fn overall_peak_error(&self) -> f64 {
        let peak = self.max_ref.iter().fold(0.0, |m: f64, v| m.max(*v));
        let err = self.max_err.iter().fold(0.0, |m: f64, v| m.max(*v));
        if peak > 0.0 { err / peak } else { f64::NAN }
    }

    /// The largest over the components of each one's peak error relative to its own reference
    /// peak (components whose reference stays at zero left out; 0 if none): the summary's
    /// `max_displacement_error` statistic.
    pub fn max_peak_error(&self) -> f64 {
        (0..self.max_err.len())
            .map(|k| self.stats(k).peak_error)
            .filter(|x| x.is_finite())
            .fold(0.0, f64::max)
    }

    /// Normalised errors of component `k` (NaN if the reference is identically zero).
    pub fn stats(&self, k: usize) -> ErrorStats {
        let peak = self.max_ref[k];
        let norm = if peak > 0.0 { peak } else { f64::NAN };
        ErrorStats {
            rms_error: (self.sum_sq[k] / self.count.max(1) as f64).sqrt() / norm,
            peak_error: self.max_err[k] / norm,
            reference_peak: peak,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn peaks_and_errors_of_a_known_series() {
        let mut p = PeakTracker::new(2);
        p.update(&[1.0, -3.0], 0.0);
        p.update(&[-2.0, 1.0], 0.5);
        assert_eq!(p.0[0], Peak { max_abs: 2.0, t: 0.5 });
        assert_eq!(p.largest(), (1, Peak { max_abs: 3.0, t: 0.0 }));
        let mut e = ErrorTracker::new(1);
        e.update(&[1.0], &[2.0]);
        e.update(&[4.0], &[4.0]);
        let s = e.stats(0);
        // errors -1, 0: RMS sqrt(1/2), peak 1, both over the reference peak 4.
        assert_eq!(s.rms_error, 0.5_f64.sqrt() / 4.0);
        assert_eq!(s.peak_error, 0.25);
        assert!(ErrorTracker::new(1).stats(0).peak_error.is_nan());
        // Overall: the largest error over the largest reference peak, whatever the component.
        let mut e = ErrorTracker::new(2);
        e.update(&[1.0, 1e-6], &[2.0, 1e-9]);
        assert!(e.stats(1).peak_error > 900.0);
        assert_eq!(e.overall_peak_error(), 0.5);
    }
}
