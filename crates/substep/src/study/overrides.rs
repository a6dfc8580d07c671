//! Dotted-key overrides of a parsed test definition: `substructure.actuator.delay = 0.01` sets
//! that key in the TOML tree before it is validated, so a study can vary any config key the
//! way a user would edit the file. A numeric segment indexes an array of tables
//! (`substructure.specimen.0.stiffness` is the first `[[substructure.specimen]]`).

use crate::error::{Error, Result};
use toml::Value;

/// Set `key` (dotted path) in `root` to `value`. Missing tables on the way are created (a
/// study may switch on a section the base does not have); a segment that meets a value that is
/// not a table or array, or an array index out of range, is an error naming the key. Whether
/// the key exists in the config schema is for the config parser to say.
pub fn set(root: &mut Value, key: &str, value: Value) -> Result<()> {
    let segments: Vec<&str> = key.split('.').collect();
    if segments.iter().any(|s| s.is_empty()) {
        return Err(Error::invalid(key, "empty segment in the override key"));
    }
    let (last, path) = segments.split_last().expect("split yields at least one segment");
    let mut node = root;
    for (depth, seg) in path.iter().enumerate() {
        let so_far = segments[..=depth].join(".");
        node = match node {
            Value::Table(t) => t
                .entry(seg.to_string())
                .or_insert_with(|| Value::Table(toml::Table::new())),
            Value::Array(a) => index(a, seg, &so_far)?,
            other => {
                return Err(Error::invalid(
                    key,
                    format!(
                        "`{}` is a {}, not a table",
                        segments[..depth].join("."),
                        other.type_str()
                    ),
                ));
            }
        };
    }
    match node {
        Value::Table(t) => {
            t.insert(last.to_string(), value);
        }
        Value::Array(a) => *index(a, last, key)? = value,
        other => {
            return Err(Error::invalid(
                key,
                format!("`{}` is a {}, not a table", path.join("."), other.type_str()),
            ));
        }
    }
    Ok(())
}

/// The value at `key` in `root`, if there is one.
pub fn get<'a>(root: &'a Value, key: &str) -> Option<&'a Value> {
    key.split('.').try_fold(root, |node, seg| match node {
        Value::Table(t) => t.get(seg),
        Value::Array(a) => seg.parse::<usize>().ok().and_then(|i| a.get(i)),
        _ => None,
    })
}

fn index<'a>(a: &'a mut [Value], seg: &str, key: &str) -> Result<&'a mut Value> {
    let n = a.len();
    let i: usize = seg
        .parse()
        .map_err(|_| Error::invalid(key, format!("`{seg}` indexes an array of {n}: give a number 0..{n}")))?;
    a.get_mut(i)
        .ok_or_else(|| Error::invalid(key, format!("index {i} is out of range (the array has {n} entries)")))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn base() -> Value {
        toml::from_str(
            "[structure.sdof]\nmass = 1.0\n[[substructure.specimen]]\nstiffness = 2.0\n\
             [[substructure.specimen]]\nstiffness = 3.0\n",
        )
        .unwrap()
    }

    #[test]
    fn sets_nested_keys_array_entries_and_new_tables() {
        let mut v = base();
        set(&mut v, "structure.sdof.mass", Value::Float(5.0)).unwrap();
        set(&mut v, "substructure.specimen.1.stiffness", Value::Float(7.0)).unwrap();
        set(&mut v, "substructure.actuator.delay", Value::Float(0.01)).unwrap();
        assert_eq!(get(&v, "structure.sdof.mass"), Some(&Value::Float(5.0)));
        assert_eq!(get(&v, "substructure.specimen.0.stiffness"), Some(&Value::Float(2.0)));
        assert_eq!(get(&v, "substructure.specimen.1.stiffness"), Some(&Value::Float(7.0)));
        assert_eq!(get(&v, "substructure.actuator.delay"), Some(&Value::Float(0.01)));
    }

    #[test]
    fn refuses_paths_through_values_and_bad_indices() {
        let mut v = base();
        let e = set(&mut v, "structure.sdof.mass.value", Value::Float(1.0)).unwrap_err();
        assert_eq!(
            e.to_string(),
            "structure.sdof.mass.value: `structure.sdof.mass` is a float, not a table"
        );
        let e = set(&mut v, "substructure.specimen.2.stiffness", Value::Float(1.0)).unwrap_err();
        assert_eq!(
            e.to_string(),
            "substructure.specimen.2: index 2 is out of range (the array has 2 entries)"
        );
        let e = set(&mut v, "substructure..x", Value::Float(1.0)).unwrap_err();
        assert!(e.to_string().contains("empty segment"), "{e}");
    }
}
