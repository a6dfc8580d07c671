//! Numbers for people: at most a given number of significant digits, exponent notation when a
//! value is very large or very small (a diverged run's 10¹⁵⁰ m prints as `1.523e150`, not as 150
//! digits).

/// `x` with `digits` significant digits (1..=17): plain notation for `1e-3 ≤ |x| < 1e6`, else
/// exponent notation; `0`, `NaN` and `inf` as such.
pub fn sig(x: f64, digits: usize) -> String {
    let digits = digits.clamp(1, 17);
    if x == 0.0 || !x.is_finite() {
        return format!("{x}");
    }
    let magnitude = x.abs().log10().floor() as i32;
    if (-3..6).contains(&magnitude) {
        let decimals = (digits as i32 - 1 - magnitude).max(0) as usize;
        format!("{x:.decimals$}")
    } else {
        format!("{x:.prec$e}", prec = digits - 1)
    }
}

/// A ratio as a percentage with three decimals and the sign `%` (`0.012345` → `1.234 %`), in
/// exponent notation from 10⁴ % on (a diverged run).
pub fn percent(ratio: f64) -> String {
    let p = 100.0 * ratio;
    if p.abs() < 1e4 || !p.is_finite() {
        format!("{p:.3} %")
    } else {
        format!("{p:.3e} %")
    }
}

/// A time rounded to 1 ns, as the CSV files hold it: `i·Δt` without float noise (`19.99`, not
/// `19.990000000000002`).
pub fn round_time(t: f64) -> f64 {
    (t * 1e9).round() / 1e9
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn significant_digits_and_notation() {
        assert_eq!(sig(1.23456, 4), "1.235");
        assert_eq!(sig(123.456, 4), "123.5");
        assert_eq!(sig(0.0123456, 3), "0.0123");
        assert_eq!(sig(-98765.4, 3), "-98765");
        assert_eq!(sig(1.523e151, 4), "1.523e151");
        assert_eq!(sig(3.2e-7, 2), "3.2e-7");
        assert_eq!(sig(0.0, 4), "0");
        assert_eq!(sig(f64::NAN, 4), "NaN");
        assert_eq!(sig(f64::INFINITY, 4), "inf");
        assert_eq!(percent(0.012345), "1.234 %");
        assert_eq!(percent(6.8e33), "6.800e35 %");
        // Never more than the digits asked for, whatever the magnitude.
        for e in -300..300 {
            let s = sig(1.234_567_890_123 * 10f64.powi(e), 12);
            let digits = s
                .split('e')
                .next()
                .unwrap()
                .chars()
                .filter(char::is_ascii_digit)
                .count();
            assert!(digits <= 12 + 3, "{s}");
        }
    }
}
