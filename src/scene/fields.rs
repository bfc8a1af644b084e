//! Typed, path-tracking access to a TOML table. Every getter records the key
//! as known, so that [`Fields::finish`] can reject the keys nobody asked for,
//! and every failure names the file and the full key path.

use std::cell::RefCell;
use std::path::Path;

use glam::DVec3;
use toml::{Table, Value};

use crate::error::{Error, Result};

/// One TOML table being read, with its key path for error messages.
pub(crate) struct Fields<'a> {
    file: &'a Path,
    path: String,
    table: &'a Table,
    known: RefCell<Vec<&'static str>>,
}

fn type_name(v: &Value) -> &'static str {
    match v {
        Value::String(_) => "a string",
        Value::Integer(_) => "an integer",
        Value::Float(_) => "a number",
        Value::Boolean(_) => "a boolean",
        Value::Datetime(_) => "a date",
        Value::Array(_) => "an array",
        Value::Table(_) => "a table",
    }
}

impl<'a> Fields<'a> {
    /// Reads `value` (found at `path`) as a table.
    pub fn new(file: &'a Path, path: impl Into<String>, value: &'a Value) -> Result<Self> {
        let path = path.into();
        match value {
            Value::Table(table) => Ok(Self::of_table(file, path, table)),
            other => Err(Error::key(
                file,
                path,
                format!("must be a table, found {}", type_name(other)),
            )),
        }
    }

    pub(crate) fn of_table(file: &'a Path, path: impl Into<String>, table: &'a Table) -> Self {
        Fields {
            file,
            path: path.into(),
            table,
            known: RefCell::new(Vec::new()),
        }
    }

    /// The full key path of `key` in this table.
    pub(crate) fn key_path(&self, key: &str) -> String {
        if self.path.is_empty() {
            key.to_string()
        } else {
            format!("{}.{}", self.path, key)
        }
    }

    /// An error at `key` of this table.
    pub fn error(&self, key: &str, message: impl Into<String>) -> Error {
        Error::key(self.file, self.key_path(key), message)
    }

    /// An error about this table as a whole.
    pub(crate) fn table_error(&self, message: impl Into<String>) -> Error {
        Error::key(self.file, self.path.clone(), message)
    }

    /// The raw value at `key`, if present; marks the key as known.
    pub fn get(&self, key: &'static str) -> Option<&'a Value> {
        self.known.borrow_mut().push(key);
        self.table.get(key)
    }

    pub fn has(&self, key: &'static str) -> bool {
        self.table.contains_key(key)
    }

    fn required(&self, key: &'static str) -> Result<&'a Value> {
        self.get(key).ok_or_else(|| self.error(key, "missing"))
    }

    pub(crate) fn opt_str(&self, key: &'static str) -> Result<Option<&'a str>> {
        match self.get(key) {
            None => Ok(None),
            Some(Value::String(s)) => Ok(Some(s.as_str())),
            Some(other) => {
                Err(self.error(key, format!("must be a string, found {}", type_name(other))))
            }
        }
    }

    pub(crate) fn req_str(&self, key: &'static str) -> Result<&'a str> {
        self.required(key)?;
        Ok(self.opt_str(key)?.expect("checked present"))
    }

    pub(crate) fn opt_bool(&self, key: &'static str) -> Result<Option<bool>> {
        match self.get(key) {
            None => Ok(None),
            Some(Value::Boolean(b)) => Ok(Some(*b)),
            Some(other) => Err(self.error(
                key,
                format!("must be true or false, found {}", type_name(other)),
            )),
        }
    }

    /// A finite number (TOML integers are accepted).
    pub(crate) fn opt_f64(&self, key: &'static str) -> Result<Option<f64>> {
        match self.get(key) {
            None => Ok(None),
            Some(v) => number(v).map(Some).map_err(|m| self.error(key, m)),
        }
    }

    pub(crate) fn req_f64(&self, key: &'static str) -> Result<f64> {
        self.required(key)?;
        Ok(self.opt_f64(key)?.expect("checked present"))
    }

    /// A positive whole number.
    pub(crate) fn req_count(&self, key: &'static str) -> Result<u32> {
        match self.required(key)? {
            Value::Integer(i) if *i > 0 && *i <= u32::MAX as i64 => Ok(*i as u32),
            Value::Integer(i) => {
                Err(self.error(key, format!("must be a positive whole number, found {i}")))
            }
            other => Err(self.error(
                key,
                format!("must be a whole number, found {}", type_name(other)),
            )),
        }
    }

    pub(crate) fn opt_vec3(&self, key: &'static str) -> Result<Option<DVec3>> {
        match self.get(key) {
            None => Ok(None),
            Some(v) => vec3(v).map(Some).map_err(|m| self.error(key, m)),
        }
    }

    /// A point or offset in the world, within [`crate::geometry::MAX_COORDINATE`].
    pub(crate) fn opt_place(&self, key: &'static str) -> Result<Option<DVec3>> {
        match self.get(key) {
            None => Ok(None),
            Some(v) => place(v).map(Some).map_err(|m| self.error(key, m)),
        }
    }

    pub(crate) fn req_place(&self, key: &'static str) -> Result<DVec3> {
        self.required(key)?;
        Ok(self.opt_place(key)?.expect("checked present"))
    }

    pub(crate) fn req_vec3(&self, key: &'static str) -> Result<DVec3> {
        self.required(key)?;
        Ok(self.opt_vec3(key)?.expect("checked present"))
    }

    /// A linear RGB triple with no negative component.
    pub(crate) fn req_rgb(&self, key: &'static str) -> Result<DVec3> {
        let rgb = self.req_vec3(key)?;
        if rgb.min_element() < 0.0 {
            return Err(self.error(key, "components must not be negative"));
        }
        Ok(rgb)
    }

    /// A nested table at `key`, if present.
    pub(crate) fn opt_table(&self, key: &'static str) -> Result<Option<Fields<'a>>> {
        match self.get(key) {
            None => Ok(None),
            Some(v) => Fields::new(self.file, self.key_path(key), v).map(Some),
        }
    }

    pub(crate) fn req_table(&self, key: &'static str) -> Result<Fields<'a>> {
        self.required(key)?;
        Ok(self.opt_table(key)?.expect("checked present"))
    }

    /// An array of tables at `key` (`[[key]]` or an inline array), each with its
    /// indexed path `key[i]`. Absent means empty.
    pub fn tables(&self, key: &'static str) -> Result<Vec<Fields<'a>>> {
        match self.get(key) {
            None => Ok(Vec::new()),
            Some(Value::Array(items)) => items
                .iter()
                .enumerate()
                .map(|(i, v)| Fields::new(self.file, format!("{}[{i}]", self.key_path(key)), v))
                .collect(),
            Some(other) => Err(self.error(
                key,
                format!("must be an array of tables, found {}", type_name(other)),
            )),
        }
    }

    /// An array at `key`, if present, with each element's path.
    pub(crate) fn opt_array(&self, key: &'static str) -> Result<Option<Vec<(String, &'a Value)>>> {
        match self.get(key) {
            None => Ok(None),
            Some(Value::Array(items)) => Ok(Some(
                items
                    .iter()
                    .enumerate()
                    .map(|(i, v)| (format!("{}[{i}]", self.key_path(key)), v))
                    .collect(),
            )),
            Some(other) => {
                Err(self.error(key, format!("must be an array, found {}", type_name(other))))
            }
        }
    }

    /// Marks `keys` as known without reading them: keys read only in some
    /// cases (one of several rotations) still belong in an unknown key's
    /// list of what is expected.
    pub(crate) fn allow(&self, keys: &[&'static str]) {
        self.known.borrow_mut().extend_from_slice(keys);
    }

    /// The (key, value) pairs of this table in file order, all marked known:
    /// for tables whose keys are names chosen by the user.
    pub(crate) fn entries(&self) -> Vec<(&'a str, &'a Value)> {
        self.table.iter().map(|(k, v)| (k.as_str(), v)).collect()
    }

    /// Fails on the first key of this table that no getter asked for.
    pub fn finish(&self) -> Result<()> {
        let known = self.known.borrow();
        for key in self.table.keys() {
            if !known.iter().any(|k| k == key) {
                let mut expected: Vec<&str> = known.clone();
                expected.sort_unstable();
                expected.dedup();
                return Err(self.error(
                    key,
                    format!("unknown key (expected one of: {})", expected.join(", ")),
                ));
            }
        }
        Ok(())
    }
}

/// A finite number from a TOML value.
pub(crate) fn number(v: &Value) -> std::result::Result<f64, String> {
    let x = match v {
        Value::Float(f) => *f,
        Value::Integer(i) => *i as f64,
        other => return Err(format!("must be a number, found {}", type_name(other))),
    };
    if x.is_finite() {
        Ok(x)
    } else {
        Err(format!("must be finite, found {x}"))
    }
}

/// A point or offset in the world: three numbers within
/// ±[`crate::geometry::MAX_COORDINATE`] metres.
pub(crate) fn place(v: &Value) -> std::result::Result<DVec3, String> {
    let p = vec3(v)?;
    let max = crate::geometry::MAX_COORDINATE as f64;
    if p.abs().max_element() > max {
        return Err(format!(
            "{} lies beyond ±{max} m: single-precision rays cannot resolve a room there (move the scene near the origin)",
            p.abs().max_element()
        ));
    }
    Ok(p)
}

/// Three finite numbers from a TOML array.
pub(crate) fn vec3(v: &Value) -> std::result::Result<DVec3, String> {
    let Value::Array(items) = v else {
        return Err(format!(
            "must be an array of 3 numbers, found {}",
            type_name(v)
        ));
    };
    if items.len() != 3 {
        return Err(format!(
            "must be an array of 3 numbers, found {} elements",
            items.len()
        ));
    }
    let mut out = [0.0; 3];
    for (o, item) in out.iter_mut().zip(items) {
        *o = number(item)?;
    }
    Ok(DVec3::from_array(out))
}
