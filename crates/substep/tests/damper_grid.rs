//! Issue "Stable by construction": the default ARX phase-lag compensation on a grid of damper
//! tests nobody tuned it for (docs/vst.md, "The damper grid"): dampers 1–5 MN·s/m, delays of
//! half a step to two steps, `k_sub` 1–10, behind a pure delay and behind a second-order
//! actuator with the delay. Against the exact solution of the assembled structure.

use substep::study::vst::grid::{GridActuator, GridRow, GridSettings, counts, damper_grid};

fn table(name: &str, rows: &[GridRow]) {
    println!("{name}: damper [MN·s/m], delay [ms], k_sub: error without / with ARX (ratio)");
    for r in rows {
        println!(
            "  {:>4.1} {:>4.0} {:>3}: {:>10.3e} / {:>10.3e} ({:.3}){}{}",
            r.damper / 1e6,
            r.delay * 1e3,
            r.k_sub,
            r.error_none,
            r.error_arx,
            r.ratio(),
            if r.stable_without() {
                ""
            } else {
                "  uncompensated unstable"
            },
            if r.backed_off { "  supervisor backed off" } else { "" }
        );
    }
    println!("  {:?}", counts(rows));
}

/// Every run whose error against the reference exceeds 100 %, or that ran away, ended as
/// diverged (not completed), compensated or not.
fn no_silent_divergence(rows: &[GridRow]) {
    for r in rows {
        for (err, completed, diverged, what) in [
            (r.error_none, r.completed_none, r.diverged_none, "uncompensated"),
            (r.error_arx, r.completed_arx, r.diverged_arx, "ARX"),
        ] {
            if substep::run::exceeds(err, 1.0) {
                assert!(
                    diverged && !completed,
                    "{what} {} MN·s/m, {} ms, k_sub {}: error {err:e} but diverged = {diverged}, completed = {completed}",
                    r.damper / 1e6,
                    r.delay * 1e3,
                    r.k_sub
                );
            }
            if completed {
                assert!(err <= 1.0, "{what}: completed with an error of {err:e}");
            }
        }
    }
}

fn check(rows: &[GridRow]) {
    no_silent_divergence(rows);
    let c = counts(rows);
    // Never diverges where the uncompensated test is stable.
    assert_eq!(c.diverged_with, 0, "{c:?}");
    // Delays of a step or more: at most 0.7 × the uncompensated error in at least 3/4.
    assert!(4 * c.step_delays_better >= 3 * c.step_delays, "{c:?}");
    for r in rows.iter().filter(|r| r.stable_without()) {
        // At most 1.2 × the uncompensated error — except, as docs/vst.md reports, at half a
        // step of delay with the lighter dampers, where the uncompensated test hardly feels
        // the delay (its error equals the delay-free one) and leading the smooth command costs
        // up to 2.9 × (≤ 2.9 % of the peak).
        let half_step = r.delay < 0.75 * 0.01;
        if half_step && r.damper <= 2.5e6 {
            assert!(r.ratio() <= 3.0 && r.error_arx <= 0.03, "{r:?}");
        } else {
            assert!(r.ratio() <= 1.2, "{r:?}");
        }
    }
}

#[test]
fn arx_compensation_on_the_damper_grid_behind_a_pure_delay() {
    let rows = damper_grid(&GridSettings::full(GridActuator::PureDelay)).unwrap();
    table("pure delay", &rows);
    check(&rows);
    // The issue's own test: 2.5 MN·s/m behind 10 ms, k_sub 1–10 — 7.8 % without, 2·10³¹ % at
    // k_sub = 3 with the compensator as it stood; now at most 0.3 × without.
    for r in rows.iter().filter(|r| r.damper == 2.5e6 && r.delay == 0.01) {
        assert!(r.ratio() < 0.3, "{r:?}");
    }
    // The 5 MN·s/m damper at k_sub = 10 is unstable without compensation: G_cc c/Δτ > 1/2, the
    // sub-step iteration itself diverges, and no compensator can help; those runs end as
    // diverged.
    assert!(rows.iter().any(|r| !r.stable_without()));
}

#[test]
fn arx_compensation_on_the_damper_grid_behind_a_second_order_actuator() {
    let actuator = GridActuator::SecondOrder {
        frequency: 40.0,
        zeta: 0.7,
    };
    let rows = damper_grid(&GridSettings::full(actuator)).unwrap();
    table("second order 40 Hz + delay", &rows);
    check(&rows);
}
