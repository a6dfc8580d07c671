//! Study metrics: numbers taken from a run's summary (`summary.json`, docs/config.md).
//!
//! A metric is a built-in name (the largest value over the DOFs or coupling DOFs of a summary
//! quantity) or a dotted path into the summary (`reference.dofs.0.rms_error`,
//! `engineering.peak_base_shear_N.peak`); arrays are indexed by a number. A metric the run
//! does not have (a monolithic run has no tracking) is NaN.

use serde_json::Value;

/// One metric of a study.
#[derive(Debug, Clone, PartialEq)]
pub struct Metric {
    name: String,
    kind: Kind,
}

#[derive(Debug, Clone, PartialEq)]
enum Kind {
    /// Largest `field` (a dotted path inside each entry) over the array at `array`.
    MaxOver { array: &'static str, field: &'static str },
    /// A dotted path into the summary.
    Path(String),
}

/// The built-in metrics: name, array in the summary, field of each entry, description.
pub const BUILT_IN: &[(&str, &str, &str, &str)] = &[
    (
        "max_displacement_error",
        "reference.dofs",
        "peak_error",
        "largest max|u − u_ref| / max|u_ref| over the DOFs",
    ),
    (
        "rms_displacement_error",
        "reference.dofs",
        "rms_error",
        "largest RMS(u − u_ref) / max|u_ref| over the DOFs",
    ),
    (
        "nrms_displacement_error",
        "reference.dofs",
        "nrms_error",
        "largest std(u − u_ref) / std(u_ref) over the DOFs",
    ),
    (
        "max_force_error",
        "reference.coupling",
        "force.peak_error",
        "largest max|f_c − f_ref| / max|f_ref| over the coupling DOFs",
    ),
    (
        "rms_force_error",
        "reference.coupling",
        "force.rms_error",
        "largest RMS(f_c − f_ref) / max|f_ref| over the coupling DOFs",
    ),
    (
        "tracking_delay",
        "tracking",
        "delay_s",
        "largest lag of the measured displacement behind the command [s]",
    ),
    (
        "tracking_nrms",
        "tracking",
        "nrms_error",
        "largest std(x_m − d) / std(d) over the coupling DOFs",
    ),
    (
        "tracking_peak",
        "tracking",
        "peak_error",
        "largest max|x_m − d| / max|d| over the coupling DOFs",
    ),
    (
        "peak_displacement",
        "peaks",
        "u.max_abs",
        "largest |u| over the DOFs [m]",
    ),
    ("peak_velocity", "peaks", "v.max_abs", "largest |v| over the DOFs [m/s]"),
    (
        "peak_acceleration",
        "peaks",
        "a.max_abs",
        "largest |a| (relative) over the DOFs [m/s²]",
    ),
    (
        "peak_coupling_force",
        "coupling_peaks",
        "force.max_abs",
        "largest |f_c| over the coupling DOFs [N]",
    ),
    (
        "peak_error_force",
        "coupling_peaks",
        "error_force.max_abs",
        "largest |f_e| over the coupling DOFs [N]",
    ),
];

impl Metric {
    /// A built-in name or a dotted summary path (letters, digits, `_` and `.`).
    pub fn parse(name: &str) -> Result<Self, String> {
        if let Some(&(_, array, field, _)) = BUILT_IN.iter().find(|b| b.0 == name) {
            return Ok(Self {
                name: name.to_string(),
                kind: Kind::MaxOver { array, field },
            });
        }
        let valid = !name.is_empty()
            && name
                .split('.')
                .all(|s| !s.is_empty() && s.chars().all(|c| c.is_ascii_alphanumeric() || c == '_'));
        if !valid || (!name.contains('.') && !TOP_LEVEL_NUMBERS.contains(&name)) {
            let names: Vec<&str> = BUILT_IN.iter().map(|b| b.0).collect();
            return Err(format!(
                "unknown metric `{name}`: use one of {} or a dotted path into summary.json \
                 (e.g. reference.dofs.0.rms_error)",
                names.join(", ")
            ));
        }
        Ok(Self {
            name: name.to_string(),
            kind: Kind::Path(name.to_string()),
        })
    }

    pub fn name(&self) -> &str {
        &self.name
    }

    /// The metric's unit for axis labels: `s`, `m`, `m/s²`, `N` for the built-ins that have
    /// one, `–` for the ratios (errors relative to the reference's peak), and for a summary
    /// path the unit its last key names (`…_N`, `…_m`, `…_s`, `…_m_s2`); empty when unknown.
    pub fn unit(&self) -> &'static str {
        match &self.kind {
            Kind::MaxOver { .. } => match self.name.as_str() {
                "tracking_delay" => "s",
                "peak_displacement" => "m",
                "peak_acceleration" => "m/s²",
                "peak_coupling_force" | "peak_error_force" => "N",
                _ => "–",
            },
            Kind::Path(p) => {
                let last = p
                    .split('.')
                    .rev()
                    .find(|k| k.parse::<usize>().is_err() && *k != "peak")
                    .unwrap_or("");
                if last.ends_with("_m_s2") {
                    "m/s²"
                } else if last.ends_with("_N") {
                    "N"
                } else if last.ends_with("_m") {
                    "m"
                } else if last.ends_with("_s") || last == "delay_s" {
                    "s"
                } else if last.ends_with("error") || last.ends_with("nrms") {
                    "–"
                } else {
                    ""
                }
            }
        }
    }

    /// The metric of a run summary; NaN when the summary does not have it.
    pub fn value(&self, summary: &Value) -> f64 {
        match &self.kind {
            Kind::Path(p) => path(summary, p).and_then(number).unwrap_or(f64::NAN),
            Kind::MaxOver { array, field } => match path(summary, array).and_then(Value::as_array) {
                Some(entries) if !entries.is_empty() => entries
                    .iter()
                    .map(|e| path(e, field).and_then(number).unwrap_or(f64::NAN))
                    // NaN wins: a DOF without the value makes the maximum unknown.
                    .fold(f64::NEG_INFINITY, |m, x| {
                        if x.is_nan() || m.is_nan() { f64::NAN } else { m.max(x) }
                    }),
                _ => f64::NAN,
            },
        }
    }
}

/// Top-level numbers of the summary accepted as metric names without a dot.
const TOP_LEVEL_NUMBERS: &[&str] = &["steps_done", "wall_time_s", "us_per_step", "duration", "dt", "steps"];

fn path<'a>(v: &'a Value, p: &str) -> Option<&'a Value> {
    p.split('.').try_fold(v, |node, seg| match node {
        Value::Object(m) => m.get(seg),
        Value::Array(a) => seg.parse::<usize>().ok().and_then(|i| a.get(i)),
        _ => None,
    })
}

fn number(v: &Value) -> Option<f64> {
    match v {
        Value::Bool(b) => Some(f64::from(u8::from(*b))),
        other => other.as_f64(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    fn summary() -> Value {
        json!({
            "completed": true,
            "steps_done": 100,
            "peaks": [
                {"dof": 1, "u": {"max_abs": 0.02, "t": 1.0}},
                {"dof": 2, "u": {"max_abs": 0.05, "t": 2.0}},
            ],
            "reference": {
                "dofs": [{"dof": 1, "peak_error": 0.01, "rms_error": 0.004}, {"dof": 2, "peak_error": 0.03, "rms_error": 0.002}],
                "coupling": [{"dof": 1, "force": {"peak_error": 0.2, "rms_error": 0.1}}],
            },
            "tracking": [{"dof": 1, "delay_s": null, "nrms_error": 0.5}],
        })
    }

    #[test]
    fn built_ins_take_the_largest_entry() {
        let s = summary();
        let v = |n: &str| Metric::parse(n).unwrap().value(&s);
        assert_eq!(v("max_displacement_error"), 0.03);
        assert_eq!(v("rms_displacement_error"), 0.004);
        assert_eq!(v("max_force_error"), 0.2);
        assert_eq!(v("peak_displacement"), 0.05);
        assert_eq!(v("tracking_nrms"), 0.5);
        assert!(v("tracking_delay").is_nan(), "null delay");
        assert!(v("peak_coupling_force").is_nan(), "no coupling peaks");
        assert_eq!(v("reference.dofs.1.rms_error"), 0.002);
        assert_eq!(v("steps_done"), 100.0);
        assert!(v("completed.x").is_nan(), "a path through a bool");
    }

    #[test]
    fn unknown_names_are_refused_with_the_choices() {
        let e = Metric::parse("max_error").unwrap_err();
        assert!(
            e.starts_with("unknown metric `max_error`: use one of max_displacement_error"),
            "{e}"
        );
        assert!(Metric::parse("reference..x").is_err());
    }
}
