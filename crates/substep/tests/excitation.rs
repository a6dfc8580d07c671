//! Ground motions: records, readers, generators (`substep::excitation`).

use std::f64::consts::PI;
use std::path::PathBuf;
use substep::excitation::{
    Envelope, G, KanaiTajimi, Record, harmonic, kanai_tajimi, parse_at2, parse_single_column, parse_two_column,
    read_at2, read_record, read_single_column, read_two_column, sine_sweep,
};

fn close(a: f64, b: f64, tol: f64) -> bool {
    (a - b).abs() <= tol
}

fn assert_all_close(got: &[f64], want: &[f64], tol: f64) {
    assert_eq!(got.len(), want.len(), "lengths differ: {got:?} vs {want:?}");
    for (i, (g, w)) in got.iter().zip(want).enumerate() {
        assert!(close(*g, *w, tol), "sample {i}: got {g}, want {w}");
    }
}

/// The message of an expected error.
fn err<T: std::fmt::Debug>(r: substep::Result<T>) -> String {
    r.expect_err("expected an error").to_string()
}

fn assert_err<T: std::fmt::Debug>(r: substep::Result<T>, needle: &str) {
    let msg = err(r);
    assert!(msg.contains(needle), "error '{msg}' does not contain '{needle}'");
    assert!(!msg.contains('\n'), "error '{msg}' is not one line");
}

/// A fresh directory for the files of one test.
fn temp_dir(test: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("substep-excitation-{}-{test}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

// ---------------------------------------------------------------------------------------------
// Record

#[test]
fn record_duration_value_at_and_scaling() {
    let r = Record::new(0.1, vec![0.0, 1.0, 3.0, 2.0]).unwrap();
    assert!(close(r.duration(), 0.3, 1e-15));
    assert_eq!(r.pga(), 3.0);
    // Linear interpolation at hand-computed points.
    assert!(close(r.value_at(0.0), 0.0, 1e-15));
    assert!(close(r.value_at(0.05), 0.5, 1e-12));
    assert!(close(r.value_at(0.1), 1.0, 1e-12));
    assert!(close(r.value_at(0.125), 1.5, 1e-12));
    assert!(close(r.value_at(0.25), 2.5, 1e-12));
    // The end of the record (also with rounding in t), then rest.
    assert!(close(r.value_at(0.3), 2.0, 1e-12));
    assert!(close(r.value_at(0.1 + 0.2), 2.0, 1e-12));
    assert_eq!(r.value_at(0.31), 0.0);
    assert_eq!(r.value_at(-0.01), 0.0);
    assert_eq!(r.value_at(f64::INFINITY), 0.0);

    let s = r.scaled(-2.0).unwrap();
    assert_eq!(s.dt, 0.1);
    assert_eq!(s.accel, vec![0.0, -2.0, -6.0, -4.0]);
    assert_err(r.scaled(f64::NAN), "scale factor: must be a finite number, got NaN");

    assert_err(
        Record::new(0.0, vec![1.0]),
        "record.dt: must be a finite number > 0, got 0",
    );
    assert_err(Record::new(0.01, vec![]), "record: no data");
    assert_err(
        Record::new(0.01, vec![0.0, f64::NAN]),
        "record: sample 1: value is not finite",
    );
}

#[test]
fn resample_of_linear_ramp_is_exact() {
    // a_g = 2.5 t on [0, 1] s at dt = 0.01.
    let r = Record::new(0.01, (0..=100).map(|i| 2.5 * i as f64 * 0.01).collect()).unwrap();
    assert!(close(r.duration(), 1.0, 1e-12));

    let fine = r.resample(0.003, None).unwrap();
    assert_eq!(fine.len(), 334); // floor(1/0.003) + 1
    let want: Vec<f64> = (0..334).map(|i| 2.5 * i as f64 * 0.003).collect();
    assert_all_close(&fine, &want, 1e-12);

    // Coarser, with the last point exactly at the end of the record.
    let coarse = r.resample(0.02, None).unwrap();
    assert_eq!(coarse.len(), 51);
    assert!(close(coarse[50], 2.5, 1e-12));
    assert!(close(coarse[17], 2.5 * 0.34, 1e-12));

    // Beyond the end of the record the ground is at rest.
    let longer = r.resample(0.25, Some(1.6)).unwrap();
    assert_all_close(&longer, &[0.0, 0.625, 1.25, 1.875, 2.5, 0.0, 0.0], 1e-12);

    // A shorter duration cuts the record.
    let short = r.resample(0.1, Some(0.35)).unwrap();
    assert_all_close(&short, &[0.0, 0.25, 0.5, 0.75], 1e-12);

    assert_err(r.resample(0.0, None), "resample.dt: must be a finite number > 0, got 0");
    assert_err(
        r.resample(0.01, Some(-1.0)),
        "resample.duration: must be a finite number >= 0",
    );
    assert_err(r.resample(1e-12, Some(1e6)), "samples");
}

#[test]
fn from_samples_uniform_nonuniform_and_late_start() {
    // Uniform spacing is kept.
    let r = Record::from_samples(&[0.0, 0.02, 0.04, 0.06], &[1.0, -1.0, 2.0, 0.5], "s").unwrap();
    assert!(close(r.dt, 0.02, 1e-15));
    assert_eq!(r.accel, vec![1.0, -1.0, 2.0, 0.5]);

    // Non-uniform: resampled to the smallest spacing 0.05 by linear interpolation.
    let r = Record::from_samples(&[0.0, 0.1, 0.15, 0.3], &[0.0, 1.0, 2.0, 0.5], "s").unwrap();
    assert!(close(r.dt, 0.05, 1e-12));
    assert_all_close(&r.accel, &[0.0, 0.5, 1.0, 2.0, 1.5, 1.0, 0.5], 1e-12);

    // First time > 0: a_g rises linearly from (0, 0); uniform if the gap equals the spacing.
    let r = Record::from_samples(&[0.02, 0.04], &[1.0, 2.0], "s").unwrap();
    assert!(close(r.dt, 0.02, 1e-15));
    assert_eq!(r.accel, vec![0.0, 1.0, 2.0]);
    // ... otherwise resampled: spacings 0.03, 0.02 -> dt = 0.02 at t = 0, 0.02, 0.04.
    let r = Record::from_samples(&[0.03, 0.05], &[3.0, 5.0], "s").unwrap();
    assert!(close(r.dt, 0.02, 1e-12));
    assert_all_close(&r.accel, &[0.0, 2.0, 4.0], 1e-12);

    assert_err(Record::from_samples(&[], &[], "s"), "s: no data");
    assert_err(
        Record::from_samples(&[0.0], &[1.0, 2.0], "s"),
        "s: 1 times but 2 values",
    );
    assert_err(
        Record::from_samples(&[0.0, 0.1], &[1.0, f64::NAN], "s"),
        "s: sample 1: value is not finite (NaN)",
    );
    assert_err(
        Record::from_samples(&[0.0, f64::INFINITY], &[1.0, 1.0], "s"),
        "s: sample 1: time is not finite (inf)",
    );
    assert_err(
        Record::from_samples(&[0.0, 0.2, 0.1], &[1.0, 1.0, 1.0], "s"),
        "s: times are not increasing at sample 2 (t = 0.1 after 0.2)",
    );
    assert_err(
        Record::from_samples(&[-0.5, 0.0], &[1.0, 1.0], "s"),
        "s: sample 0: time must be >= 0",
    );
    assert_err(Record::from_samples(&[0.0], &[1.0], "s"), "at least two samples");
}

// ---------------------------------------------------------------------------------------------
// Readers

#[test]
fn parse_two_column_with_headers_comments_and_separators() {
    let text = "Time (s), Acceleration (m/s2)\n\
                # recorded somewhere\n\
                \n\
                0.0, 0.0\n\
                0.01;0.5\n\
                0.02\t-0.25   # trailing comment\n\
                \x20 0.03    1e-1\n\
                0.04 , 2.0D-01\n";
    let r = parse_two_column(text, "ag.csv").unwrap();
    assert!(close(r.dt, 0.01, 1e-15));
    assert_all_close(&r.accel, &[0.0, 0.5, -0.25, 0.1, 0.2], 0.0);
}

#[test]
fn parse_two_column_errors() {
    // Line 17 holds a non-numeric value after the data started.
    let mut text = String::from("t a\n");
    for i in 0..15 {
        text.push_str(&format!("{} 0.1\n", i as f64 * 0.01));
    }
    text.push_str("0.15 abc\n");
    assert_err(
        parse_two_column(&text, "ag.csv"),
        "ag.csv: line 17: cannot parse 'abc' as a number",
    );

    let text = "0 0\n0.01 0\n0.02 0\n0.03 0\n0.04 NaN\n";
    assert_err(
        parse_two_column(text, "ag.csv"),
        "ag.csv: line 5: value is not finite (NaN)",
    );

    assert_err(
        parse_two_column("time accel\n# nothing\n\n", "ag.csv"),
        "ag.csv: no data",
    );
    assert_err(parse_two_column("", "ag.csv"), "ag.csv: no data");

    // Line 8 is t = 0.09, line 9 goes back to 0.08.
    let text = "t a\n0.00 0\n0.01 0\n0.02 0\n0.03 0\n0.04 0\n0.05 0\n0.09 0\n0.08 0\n0.10 0\n";
    assert_err(
        parse_two_column(text, "ag.csv"),
        "ag.csv: times are not increasing at line 9 (t = 0.08 after 0.09)",
    );

    assert_err(
        parse_two_column("0 0\n0.01\n", "ag.csv"),
        "ag.csv: line 2: expected 2 values (t, a_g), found 1",
    );
    assert_err(
        parse_two_column("0 0 1\n", "ag.csv"),
        "ag.csv: line 1: expected 2 values (t, a_g), found 3",
    );
    assert_err(
        parse_two_column("0 0\nx 1\n", "ag.csv"),
        "ag.csv: line 2: cannot parse 'x' as a number",
    );
    assert_err(
        parse_two_column("0 0\n0.1 -inf\n", "ag.csv"),
        "ag.csv: line 2: value is not finite (-inf)",
    );
    assert_err(
        parse_two_column("-1 0\n0 1\n", "ag.csv"),
        "ag.csv: line 1: time must be >= 0",
    );
}

#[test]
fn parse_single_column_several_values_per_line() {
    let text = "single column, dt = 0.02\n1 2 3\n4, 5\n\n6 # last\n";
    let r = parse_single_column(text, 0.02, "ag.txt").unwrap();
    assert_eq!(r.dt, 0.02);
    assert_eq!(r.accel, vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0]);
    assert!(close(r.duration(), 0.1, 1e-15));

    assert_err(
        parse_single_column("1\n", 0.0, "ag.txt"),
        "ag.txt: dt: must be a finite number > 0, got 0",
    );
    assert_err(
        parse_single_column("1\n", f64::NAN, "ag.txt"),
        "ag.txt: dt: must be a finite number > 0",
    );
    assert_err(
        parse_single_column("1 2\n3 abc\n", 0.01, "ag.txt"),
        "ag.txt: line 2: cannot parse 'abc' as a number",
    );
    assert_err(
        parse_single_column("1 2\n3 inf\n", 0.01, "ag.txt"),
        "ag.txt: line 2: value is not finite (inf)",
    );
    assert_err(parse_single_column("header\n# c\n", 0.01, "ag.txt"), "ag.txt: no data");
}

const AT2_SAMPLE: &str = "\
PEER NGA STRONG MOTION DATABASE RECORD
IMPERIAL VALLEY 10/15/79 2316, EL CENTRO ARRAY #6, 230
ACCELERATION TIME SERIES IN UNITS OF G
NPTS=    7, DT=   .0050 SEC
  .1000000E-01  -.2000000E-01   .5000000E-02  0.0000000E+00  -.1234500E+00
  .2500000E+00   1.0000000E-03
";

#[test]
fn parse_at2_converts_g_to_m_per_s2() {
    let r = parse_at2(AT2_SAMPLE, "rec.AT2").unwrap();
    assert_eq!(r.dt, 0.005);
    let want: Vec<f64> = [0.01, -0.02, 0.005, 0.0, -0.12345, 0.25, 0.001]
        .iter()
        .map(|g| g * 9.80665)
        .collect();
    assert_all_close(&r.accel, &want, 1e-12);
    assert_eq!(G, 9.80665);
    assert!(close(r.accel[5], 2.4516625, 1e-12));
    assert!(close(r.duration(), 0.03, 1e-15));

    // Header variants: lowercase and no comma; the old "NPTS, DT" form.
    for line4 in [
        "npts=  7   dt=   .0050 sec",
        "NPTS = 7 DT = 0.005 SEC",
        "   7   .00500   NPTS, DT",
    ] {
        let text = AT2_SAMPLE.replace("NPTS=    7, DT=   .0050 SEC", line4);
        let r = parse_at2(&text, "rec.AT2").unwrap_or_else(|e| panic!("{line4}: {e}"));
        assert_eq!(r.dt, 0.005, "{line4}");
        assert_eq!(r.accel.len(), 7, "{line4}");
    }
}

#[test]
fn parse_at2_errors() {
    // NPTS = 3000 with 2999 values.
    let mut text = String::from("PEER\nEVENT\nACCELERATION TIME SERIES IN UNITS OF G\nNPTS= 3000, DT= .0100 SEC\n");
    for i in 0..2999 {
        text.push_str(&format!("{:15.7E}", 1e-3 * (i % 7) as f64));
        if i % 5 == 4 {
            text.push('\n');
        }
    }
    assert_err(
        parse_at2(&text, "rec.AT2"),
        "rec.AT2: header says NPTS = 3000 but 2999 values were found",
    );
    text.push_str(" 0.0\n");
    let r = parse_at2(&text, "rec.AT2").unwrap();
    assert_eq!(r.accel.len(), 3000);
    assert!(close(r.accel[3], 3e-3 * 9.80665, 1e-15));

    assert_err(
        parse_at2("a\nb\n", "rec.AT2"),
        "rec.AT2: expected 4 header lines (PEER NGA format), the file has only 2 lines",
    );
    let bad = AT2_SAMPLE.replace("NPTS=    7, DT=   .0050 SEC", "NUMBER OF POINTS 7");
    assert_err(
        parse_at2(&bad, "rec.AT2"),
        "rec.AT2: line 4: cannot find NPTS and DT in 'NUMBER OF POINTS 7'",
    );
    let bad = AT2_SAMPLE.replace("DT=   .0050", "DT= 0");
    assert_err(
        parse_at2(&bad, "rec.AT2"),
        "rec.AT2: line 4: DT must be a finite number > 0, got 0",
    );
    let bad = AT2_SAMPLE.replace("NPTS=    7", "NPTS= 7.5");
    assert_err(
        parse_at2(&bad, "rec.AT2"),
        "rec.AT2: line 4: NPTS must be a whole number >= 1, got 7.5",
    );
    let bad = AT2_SAMPLE.replace("1.0000000E-03", "1.0000000E-0x");
    assert_err(
        parse_at2(&bad, "rec.AT2"),
        "rec.AT2: line 6: cannot parse '1.0000000E-0x' as a number",
    );
    let bad = AT2_SAMPLE.replace("  .2500000E+00", "  NaN");
    assert_err(parse_at2(&bad, "rec.AT2"), "rec.AT2: line 6: value is not finite (NaN)");
    let bad = AT2_SAMPLE.replace("ACCELERATION", "VELOCITY");
    assert_err(
        parse_at2(&bad, "rec.AT2"),
        "rec.AT2: line 3: not an acceleration record",
    );
}

#[test]
fn read_files_and_dispatch_by_extension() {
    let dir = temp_dir("read");
    let at2 = dir.join("rec.AT2");
    std::fs::write(&at2, AT2_SAMPLE).unwrap();
    let csv = dir.join("ag.csv");
    std::fs::write(&csv, "t,a\n0,0\n0.01,1.5\n0.02,-0.5\n").unwrap();
    let txt = dir.join("ag.txt");
    std::fs::write(&txt, "0 1.5 -0.5\n").unwrap();

    let from_at2 = read_at2(&at2).unwrap();
    assert_eq!(from_at2, parse_at2(AT2_SAMPLE, "x").unwrap());
    assert_eq!(read_record(&at2, None).unwrap(), from_at2);
    assert_eq!(read_record(&at2, Some(0.005)).unwrap(), from_at2);
    assert_err(
        read_record(&at2, Some(0.01)),
        "rec.AT2: dt = 0.01 s was given but the AT2 header says DT = 0.005 s",
    );

    let two = read_two_column(&csv).unwrap();
    assert!(close(two.dt, 0.01, 1e-15));
    assert_eq!(two.accel, vec![0.0, 1.5, -0.5]);
    assert_eq!(read_record(&csv, None).unwrap(), two);

    let one = read_single_column(&txt, 0.01).unwrap();
    assert_eq!(
        one,
        Record {
            dt: 0.01,
            accel: vec![0.0, 1.5, -0.5]
        }
    );
    assert_eq!(read_record(&txt, Some(0.01)).unwrap(), one);
    // With dt, a .csv is read as a single column: "t,a" is a header, then 6 values.
    assert_eq!(
        read_record(&csv, Some(0.1)).unwrap().accel,
        vec![0.0, 0.0, 0.01, 1.5, 0.02, -0.5]
    );
    // Without dt, a one-value-per-line file is not a two-column file.
    assert_err(
        read_record(&txt, None),
        "ag.txt: line 1: expected 2 values (t, a_g), found 3",
    );

    let missing = dir.join("missing").join("ag.csv");
    for r in [
        read_two_column(&missing),
        read_record(&missing, None),
        read_single_column(&missing, 0.01),
    ] {
        assert_err(r, "ag.csv: cannot read file: No such file or directory (os error 2)");
    }
    assert_err(read_at2(dir.join("none.at2")), "none.at2: cannot read file:");
    assert_err(
        read_single_column(&txt, -1.0),
        "ag.txt: dt: must be a finite number > 0, got -1",
    );
    std::fs::remove_dir_all(&dir).ok();
}

// ---------------------------------------------------------------------------------------------
// Deterministic generators

#[test]
fn harmonic_values() {
    let r = harmonic(2.0, 1.25, 2.0, 0.01).unwrap();
    assert_eq!(r.dt, 0.01);
    assert_eq!(r.accel.len(), 201);
    assert_eq!(r.accel[0], 0.0);
    assert!(close(r.accel[20], 2.0, 1e-12)); // t = 0.2: sin(π/2)
    assert!(close(r.accel[40], 0.0, 1e-12)); // t = 0.4: sin(π)
    assert!(close(r.accel[60], -2.0, 1e-12)); // t = 0.6: sin(3π/2)
    assert!(close(r.accel[7], 2.0 * (2.0 * PI * 1.25 * 0.07).sin(), 1e-12));
    assert!(close(r.accel[7], 1.0449971, 1e-6)); // 2 sin(0.175π)

    assert_err(
        harmonic(1.0, 60.0, 1.0, 0.01),
        "harmonic.frequency_hz: must be below the Nyquist frequency 1/(2 dt) = 50 Hz, got 60",
    );
    assert_err(
        harmonic(1.0, 0.0, 1.0, 0.01),
        "harmonic.frequency_hz: must be a finite number > 0",
    );
    assert_err(
        harmonic(f64::NAN, 1.0, 1.0, 0.01),
        "harmonic.amplitude: must be a finite number, got NaN",
    );
    assert_err(
        harmonic(1.0, 1.0, 0.005, 0.01),
        "harmonic.duration: must be at least dt = 0.01 s",
    );
    assert_err(
        harmonic(1.0, 1.0, -1.0, 0.01),
        "harmonic.duration: must be a finite number > 0",
    );
    assert_err(
        harmonic(1.0, 1.0, 1.0, 0.0),
        "harmonic.dt: must be a finite number > 0, got 0",
    );
    assert_err(harmonic(1.0, 1e-3, 1e9, 1e-3), "needs more than");
}

/// Number of sign changes of `x[i0..i1]`.
fn zero_crossings(x: &[f64]) -> usize {
    x.windows(2).filter(|w| (w[0] < 0.0) != (w[1] < 0.0)).count()
}

#[test]
fn sine_sweep_phase_and_instantaneous_frequency() {
    let (a, f0, f1, t_end, dt) = (1.5, 0.5, 5.0, 20.0, 0.001);
    let r = sine_sweep(a, f0, f1, t_end, dt).unwrap();
    assert_eq!(r.accel.len(), 20001);
    // Closed form at t = 7.3 s: φ = 2π (0.5·7.3 + 4.5·7.3²/40).
    let t = 7.3;
    let phi = 2.0 * PI * (f0 * t + (f1 - f0) * t * t / (2.0 * t_end));
    assert!(close(r.accel[7300], a * phi.sin(), 1e-9));

    // Zero crossings over [9, 13] s: the mean frequency of a linear sweep over a window is the
    // instantaneous frequency at its middle, f(11) = 0.5 + 4.5·11/20 = 2.975 Hz.
    let crossings = zero_crossings(&r.accel[9000..=13000]);
    let cycles = f0 * 4.0 + (f1 - f0) * (13.0f64.powi(2) - 9.0f64.powi(2)) / (2.0 * t_end);
    assert!(
        (crossings as f64 - 2.0 * cycles).abs() <= 1.0,
        "{crossings} vs {}",
        2.0 * cycles
    );
    let f_est = crossings as f64 / (2.0 * 4.0);
    assert!((f_est / 2.975 - 1.0).abs() < 0.05, "f_est = {f_est}");
    // Near the end the frequency is close to f1, near the start close to f0.
    let f_end = zero_crossings(&r.accel[18000..=20000]) as f64 / 4.0; // f(19) = 4.775
    assert!((f_end / 4.775 - 1.0).abs() < 0.06, "f_end = {f_end}");

    // Down-sweep is allowed.
    let down = sine_sweep(1.0, 5.0, 0.5, 20.0, 0.001).unwrap();
    let f_start = zero_crossings(&down.accel[0..=2000]) as f64 / 4.0; // f(1) = 4.775
    assert!((f_start / 4.775 - 1.0).abs() < 0.06, "f_start = {f_start}");

    assert_err(
        sine_sweep(1.0, 0.5, 60.0, 10.0, 0.01),
        "sine_sweep.f1_hz: must be below the Nyquist frequency",
    );
    assert_err(
        sine_sweep(1.0, -0.5, 5.0, 10.0, 0.01),
        "sine_sweep.f0_hz: must be a finite number >= 0, got -0.5",
    );
    assert_err(
        sine_sweep(1.0, 0.5, 5.0, f64::INFINITY, 0.01),
        "sine_sweep.duration: must be a finite number > 0",
    );
}

// ---------------------------------------------------------------------------------------------
// Kanai–Tajimi

fn kt(seed: u64) -> KanaiTajimi {
    KanaiTajimi {
        pga_target: None,
        omega_g: 15.0,
        zeta_g: 0.3,
        duration: 20.0,
        dt: 0.01,
        seed,
        envelope: Envelope::None,
    }
}

#[test]
fn kanai_tajimi_is_reproducible_and_seeded() {
    let a = kanai_tajimi(kt(7)).unwrap();
    let b = kanai_tajimi(kt(7)).unwrap();
    let c = kanai_tajimi(kt(8)).unwrap();
    assert_eq!(a, b);
    assert_eq!(a.accel.len(), 2001);
    assert_eq!(a.dt, 0.01);
    assert_eq!(a.accel[0], 0.0); // the filter starts at rest
    assert!(a.accel.iter().all(|x| x.is_finite()));
    assert_ne!(a.accel, c.accel);
    let differing = a.accel.iter().zip(&c.accel).filter(|(x, y)| x != y).count();
    assert!(differing > 1990, "only {differing} samples differ");
}

#[test]
fn kanai_tajimi_pga_scaling_and_envelope() {
    let base = kanai_tajimi(kt(3)).unwrap();
    let scaled = kanai_tajimi(KanaiTajimi {
        pga_target: Some(3.0),
        ..kt(3)
    })
    .unwrap();
    assert_eq!(scaled.pga(), 3.0);
    // Scaling does not change the shape.
    let factor = 3.0 / base.pga();
    for (s, b) in scaled.accel.iter().zip(&base.accel) {
        assert!(close(*s, factor * b, 1e-12));
    }

    let env = Envelope::Trapezoid { rise: 2.0, hold: 10.0 };
    assert_eq!(env.factor(1.0, 20.0), 0.5);
    assert_eq!(env.factor(7.0, 20.0), 1.0);
    assert_eq!(env.factor(16.0, 20.0), 0.5);
    assert_eq!(env.factor(20.0, 20.0), 0.0);
    assert_eq!(Envelope::None.factor(20.0, 20.0), 1.0);
    let shaped = kanai_tajimi(KanaiTajimi { envelope: env, ..kt(3) }).unwrap();
    // Same noise, multiplied by the envelope: half amplitude at t = 1 s and t = 16 s.
    assert!(close(shaped.accel[100], 0.5 * base.accel[100], 1e-12));
    assert!(close(shaped.accel[700], base.accel[700], 1e-12));
    assert!(close(shaped.accel[1600], 0.5 * base.accel[1600], 1e-12));
    assert_eq!(shaped.accel[2000], 0.0);
    let shaped_scaled = kanai_tajimi(KanaiTajimi {
        envelope: env,
        pga_target: Some(2.0),
        ..kt(3)
    })
    .unwrap();
    assert_eq!(shaped_scaled.pga(), 2.0);

    let bad = |p: KanaiTajimi| kanai_tajimi(p);
    assert_err(
        bad(KanaiTajimi {
            omega_g: 400.0,
            ..kt(1)
        }),
        "kanai_tajimi.omega_g: must be below the Nyquist frequency",
    );
    assert_err(
        bad(KanaiTajimi { omega_g: -1.0, ..kt(1) }),
        "kanai_tajimi.omega_g: must be a finite number > 0, got -1",
    );
    assert_err(
        bad(KanaiTajimi { zeta_g: 0.0, ..kt(1) }),
        "kanai_tajimi.zeta_g: must be a finite number > 0, got 0",
    );
    assert_err(
        bad(KanaiTajimi {
            pga_target: Some(-1.0),
            ..kt(1)
        }),
        "kanai_tajimi.pga_target: must be a finite number > 0",
    );
    assert_err(
        bad(KanaiTajimi { dt: f64::NAN, ..kt(1) }),
        "kanai_tajimi.dt: must be a finite number > 0, got NaN",
    );
    assert_err(
        bad(KanaiTajimi {
            envelope: Envelope::Trapezoid { rise: 15.0, hold: 10.0 },
            ..kt(1)
        }),
        "kanai_tajimi.envelope: rise + hold = 25 s exceeds the duration 20 s",
    );
    assert_err(
        bad(KanaiTajimi {
            envelope: Envelope::Trapezoid { rise: -1.0, hold: 10.0 },
            ..kt(1)
        }),
        "kanai_tajimi.envelope.rise: must be a finite number >= 0, got -1",
    );
}

/// Sample variance of `x`.
fn variance(x: &[f64]) -> f64 {
    let n = x.len() as f64;
    let mean = x.iter().sum::<f64>() / n;
    x.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n
}

#[test]
fn kanai_tajimi_variance_matches_closed_form() {
    // σ² = π S₀ ω_g (1 + 4ζ²) / (2ζ) with S₀ = 1 m²/s³; ω_g dt = 0.075 so the held noise is
    // white up to well beyond the filter's corner frequency.
    for (zeta, seed) in [(0.3, 11), (0.6, 12)] {
        let p = KanaiTajimi {
            zeta_g: zeta,
            duration: 2000.0,
            dt: 0.005,
            ..kt(seed)
        };
        let r = kanai_tajimi(p).unwrap();
        let want = PI * 15.0 * (1.0 + 4.0 * zeta * zeta) / (2.0 * zeta);
        assert!(close(p.stationary_std().powi(2), want, 1e-9));
        let got = variance(&r.accel[2000..]); // skip the start-up transient (10 s)
        assert!((got / want - 1.0).abs() < 0.05, "ζ = {zeta}: variance {got} vs {want}");
    }
}

#[test]
fn kanai_tajimi_spectral_peak_near_omega_g() {
    // Welch estimate: average Hann-windowed periodograms of 512-sample segments (Δf ≈ 0.098 Hz).
    let (omega_g, dt, seg) = (15.0, 0.02, 512);
    let p = KanaiTajimi {
        omega_g,
        zeta_g: 0.3,
        duration: 300.0 * seg as f64 * dt,
        dt,
        ..kt(5)
    };
    let r = kanai_tajimi(p).unwrap();
    let n_bins = 60; // up to 5.9 Hz
    let window: Vec<f64> = (0..seg)
        .map(|i| 0.5 - 0.5 * (2.0 * PI * i as f64 / seg as f64).cos())
        .collect();
    let mut psd = vec![0.0; n_bins];
    for chunk in r.accel[seg..].chunks_exact(seg) {
        for (k, p) in psd.iter_mut().enumerate() {
            let (mut re, mut im) = (0.0, 0.0);
            for (i, (x, w)) in chunk.iter().zip(&window).enumerate() {
                let arg = 2.0 * PI * (k * i) as f64 / seg as f64;
                re += x * w * arg.cos();
                im -= x * w * arg.sin();
            }
            *p += re * re + im * im;
        }
    }
    // Smooth over 5 bins (≈ 0.5 Hz): the top of the KT spectrum is flat (within 6 % over
    // 0.85 ω_g … 0.95 ω_g), so the raw arg-max wanders between neighbouring bins.
    let smooth: Vec<f64> = (0..n_bins)
        .map(|k| {
            if k < 2 || k + 2 >= n_bins {
                0.0
            } else {
                psd[k - 2..=k + 2].iter().sum()
            }
        })
        .collect();
    let k_peak = (1..n_bins).max_by(|&a, &b| smooth[a].total_cmp(&smooth[b])).unwrap();
    let f_peak = k_peak as f64 / (seg as f64 * dt);
    let f_g = omega_g / (2.0 * PI);
    assert!(
        (f_peak / f_g - 1.0).abs() < 0.2,
        "peak at {f_peak} Hz, ω_g/2π = {f_g} Hz"
    );
    // The peak of |H|² = (1 + 4ζ²r²)/((1 − r²)² + 4ζ²r²) lies at r = √(√(1 + 8ζ²) − 1)/(2ζ)
    // = 0.930 for ζ = 0.3, i.e. 2.22 Hz.
    let zeta: f64 = 0.3;
    let r_peak = ((1.0 + 8.0 * zeta * zeta).sqrt() - 1.0).sqrt() / (2.0 * zeta);
    assert!(close(r_peak, 0.9302, 1e-4));
    assert!((f_peak / (r_peak * f_g) - 1.0).abs() < 0.1, "peak at {f_peak} Hz");
    // The spectrum falls off well above the peak and is smaller at low frequency.
    assert!(psd[k_peak] > 5.0 * psd[55], "{} vs {}", psd[k_peak], psd[55]);
    assert!(psd[k_peak] > 2.0 * psd[2], "{} vs {}", psd[k_peak], psd[2]);
}
