//! Reading YAML configuration (robots, scenarios, tasks) with errors that name the file,
//! the key and what was expected.

use serde::de::DeserializeOwned;
use std::path::Path;

/// An error in a configuration file or value.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    /// The file could not be read.
    #[error("{file}: cannot read: {error}")]
    Io {
        /// The file.
        file: String,
        /// What the OS said (in the message, not chained, so that it is said once).
        error: std::io::Error,
    },
    /// The YAML did not parse or did not match the schema (unknown key, wrong type...).
    /// serde_norway's message names the key path, the line and the column.
    #[error("{file}: {message}")]
    Parse {
        /// The file (or the name of the embedded preset).
        file: String,
        /// The parser's message.
        message: String,
    },
    /// A value parsed but is out of range or inconsistent.
    #[error("{file}: `{key}`: {expected}")]
    Invalid {
        /// The file (or the name of the embedded preset).
        file: String,
        /// The dotted path of the offending key.
        key: String,
        /// What was expected, with the allowed range.
        expected: String,
    },
    /// A preset name that is not shipped.
    #[error("unknown {kind} `{name}`; the shipped ones are: {known}")]
    UnknownPreset {
        /// "robot", "scenario"...
        kind: &'static str,
        /// The name asked for.
        name: String,
        /// The names that exist, comma-separated.
        known: String,
    },
}

/// A validation failure before the file name is known; [`Validate`] callers attach it.
#[derive(Debug, Clone, PartialEq)]
pub struct Invalid {
    /// Dotted key path.
    pub key: String,
    /// What was expected.
    pub expected: String,
}

impl Invalid {
    /// A failure at `key`.
    pub fn new(key: impl Into<String>, expected: impl Into<String>) -> Self {
        Self { key: key.into(), expected: expected.into() }
    }

    /// The same failure, nested under `prefix` (`lidar` + `beams` -> `lidar.beams`).
    pub fn under(mut self, prefix: &str) -> Self {
        self.key = if self.key.is_empty() { prefix.to_string() } else { format!("{prefix}.{}", self.key) };
        self
    }

    /// Attach the file name.
    pub fn in_file(self, file: &str) -> ConfigError {
        ConfigError::Invalid { file: file.to_string(), key: self.key, expected: self.expected }
    }
}

/// Semantic checks run after parsing.
pub trait Validate {
    /// Returns the first invalid value found.
    fn validate(&self) -> Result<(), Invalid>;
}

/// Checks `lo <= value <= hi` (inclusive) and that the value is finite.
pub fn check_range(key: &str, value: f32, lo: f32, hi: f32) -> Result<(), Invalid> {
    if value.is_finite() && value >= lo && value <= hi {
        Ok(())
    } else {
        Err(Invalid::new(key, format!("expected a number in [{lo}, {hi}], got {value}")))
    }
}

/// Checks `value > 0` and finite.
pub fn check_positive(key: &str, value: f32) -> Result<(), Invalid> {
    if value.is_finite() && value > 0.0 {
        Ok(())
    } else {
        Err(Invalid::new(key, format!("expected a finite number > 0, got {value}")))
    }
}

/// Checks that a `[min, max]` count range is ordered and at most `max`.
pub fn check_count(key: &str, count: [u32; 2], max: u32) -> Result<(), Invalid> {
    if count[0] <= count[1] && count[1] <= max {
        Ok(())
    } else {
        Err(Invalid::new(key, format!("[min, max] with min <= max <= {max}")))
    }
}

/// Checks that `[lo, hi]` is an ordered, finite interval inside `[min, max]`.
pub fn check_interval(key: &str, v: [f32; 2], min: f32, max: f32) -> Result<(), Invalid> {
    if v[0].is_finite() && v[1].is_finite() && v[0] <= v[1] && v[0] >= min && v[1] <= max {
        Ok(())
    } else {
        Err(Invalid::new(
            key,
            format!("expected [low, high] with {min} <= low <= high <= {max}, got [{}, {}]", v[0], v[1]),
        ))
    }
}

/// Parses `text` (from `file`) as YAML into `T` and validates it.
pub fn from_yaml_str<T: DeserializeOwned + Validate>(file: &str, text: &str) -> Result<T, ConfigError> {
    // Enums are written as one-key maps (`circle: {radius: 0.1}`), the form YAML users know,
    // rather than serde_norway's default YAML tags (`!circle`).
    let de = serde_norway::Deserializer::from_str(text);
    let value: T = serde_norway::with::singleton_map_recursive::deserialize(de)
        .map_err(|e| ConfigError::Parse { file: file.to_string(), message: e.to_string() })?;
    value.validate().map_err(|e| e.in_file(file))?;
    Ok(value)
}

/// Reads and parses a YAML file.
pub fn from_yaml_file<T: DeserializeOwned + Validate>(path: &Path) -> Result<T, ConfigError> {
    let file = path.display().to_string();
    let text = std::fs::read_to_string(path).map_err(|error| ConfigError::Io { file: file.clone(), error })?;
    from_yaml_str(&file, &text)
}

/// Looks `name` up among embedded presets `(name, yaml)`, or, when it names an existing file
/// (has a `.yaml`/`.yml` extension or a path separator), reads that file.
pub fn preset_or_file<T: DeserializeOwned + Validate>(
    kind: &'static str,
    presets: &[(&str, &str)],
    name: &str,
) -> Result<T, ConfigError> {
    if let Some((preset, text)) = presets.iter().find(|(n, _)| *n == name) {
        return from_yaml_str(&format!("<embedded {kind} {preset}>"), text);
    }
    let looks_like_path = name.ends_with(".yaml") || name.ends_with(".yml") || name.contains('/');
    if looks_like_path {
        return from_yaml_file(Path::new(name));
    }
    Err(ConfigError::UnknownPreset {
        kind,
        name: name.to_string(),
        known: presets.iter().map(|(n, _)| *n).collect::<Vec<_>>().join(", "),
    })
}

/// A value as a YAML tree, enums written as one-key maps (the form [`from_yaml_str`] reads).
pub fn to_yaml_value<T: serde::Serialize>(value: &T) -> serde_norway::Value {
    let mut v = serde_norway::with::singleton_map_recursive::serialize(value, serde_norway::value::Serializer)
        .expect("configuration types serialise to YAML");
    shortest_floats(&mut v);
    v
}

/// Writes numbers that are exactly f32 values in f32's shortest form (`0.033`, not
/// `0.032999999821186066`); they read back to the same f32.
fn shortest_floats(v: &mut serde_norway::Value) {
    use serde_norway::Value;
    match v {
        Value::Number(n) => {
            if let Some(f) = n.as_f64().filter(|_| n.is_f64()) {
                let g = f as f32;
                if g as f64 == f {
                    if let Ok(short) = format!("{g}").parse::<f64>() {
                        *v = Value::Number(short.into());
                    }
                }
            }
        }
        Value::Sequence(s) => s.iter_mut().for_each(shortest_floats),
        Value::Mapping(m) => m.iter_mut().for_each(|(_, x)| shortest_floats(x)),
        Value::Tagged(t) => shortest_floats(&mut t.value),
        _ => {}
    }
}

/// A value as YAML text, enums written as one-key maps (the form [`from_yaml_str`] reads).
pub fn to_yaml_string<T: serde::Serialize>(value: &T) -> String {
    serde_norway::to_string(&to_yaml_value(value)).expect("a YAML tree serialises")
}
