//! What a bad configuration value says: which file, which key, what is wrong and how to fix
//! it ([`ConfigError`]), and the same before the file is known ([`Invalid`]).

use std::path::PathBuf;

/// A configuration problem: which file, which key, what is wrong and how to fix it.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{origin}: {}{problem}{}", keyed(.key), fixed(.fix))]
pub struct ConfigError {
    /// The file, or a description of where the value came from (`--cfg`, `built-in defaults`).
    pub origin: String,
    /// Dotted path of the offending key; empty for a syntax error of the whole file.
    pub key: String,
    pub problem: String,
    pub fix: String,
}

/// "key `a.b`: ", or nothing for a problem of the whole file.
fn keyed(key: &str) -> String {
    if key.is_empty() {
        String::new()
    } else {
        format!("key `{key}`: ")
    }
}

/// " (fix: ...)", or nothing when there is no fix to give.
fn fixed(fix: &str) -> String {
    if fix.is_empty() {
        String::new()
    } else {
        format!(" (fix: {fix})")
    }
}

impl ConfigError {
    pub fn new(
        origin: impl Into<String>,
        key: impl Into<String>,
        problem: impl Into<String>,
        fix: impl Into<String>,
    ) -> Self {
        ConfigError { origin: origin.into(), key: key.into(), problem: problem.into(), fix: fix.into() }
    }

    pub fn file(path: &std::path::Path) -> String {
        PathBuf::from(path).display().to_string()
    }
}

/// A value that breaks a rule, found where the file it came from is not known: the dotted
/// key, what is wrong and how to fix it. [`Invalid::at`] names the file and makes it the
/// [`ConfigError`] a person reads. Every check of a settings or scenario value returns it.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("key `{key}`: {problem} (fix: {fix})")]
pub struct Invalid {
    pub key: String,
    pub problem: String,
    pub fix: String,
}

impl Invalid {
    pub fn new(key: impl Into<String>, problem: impl Into<String>, fix: impl Into<String>) -> Self {
        Invalid { key: key.into(), problem: problem.into(), fix: fix.into() }
    }

    /// `Err(Invalid::new(..))`: the shape every check returns its first problem in.
    pub fn err<T>(key: impl Into<String>, problem: impl Into<String>, fix: impl Into<String>) -> Result<T, Invalid> {
        Err(Invalid::new(key, problem, fix))
    }

    /// The same problem, in the file (or other origin) it came from.
    pub fn at(self, origin: impl Into<String>) -> ConfigError {
        ConfigError::new(origin, self.key, self.problem, self.fix)
    }
}

/// Parses JSON5 text into `T`, naming the file (`origin`), the dotted key and `fix` on error.
pub fn parse_json5<T: serde::de::DeserializeOwned>(text: &str, origin: &str, fix: &str) -> Result<T, ConfigError> {
    from_value(parse_json5_value(text, origin)?, origin, fix)
}

/// Parses JSON5 text into a JSON value (syntax errors only).
pub fn parse_json5_value(text: &str, origin: &str) -> Result<serde_json::Value, ConfigError> {
    json5::from_str(text).map_err(|e| {
        ConfigError::new(origin, "", format!("not valid JSON5: {e}"), "fix the syntax at the position given")
    })
}

/// Deserializes a JSON value into `T`, naming the dotted key of the first problem.
pub fn from_value<T: serde::de::DeserializeOwned>(
    value: serde_json::Value,
    origin: &str,
    fix: &str,
) -> Result<T, ConfigError> {
    serde_path_to_error::deserialize(value).map_err(|e| {
        let key = e.path().to_string();
        let key = if key == "." { String::new() } else { key };
        ConfigError::new(origin, key, e.inner().to_string(), fix)
    })
}

/// Lays `over` onto `base`: objects merge key by key, anything else replaces.
pub fn merge_json(base: &mut serde_json::Value, over: serde_json::Value) {
    match (base, over) {
        (serde_json::Value::Object(b), serde_json::Value::Object(o)) => {
            for (k, v) in o {
                match b.get_mut(&k) {
                    Some(slot) => merge_json(slot, v),
                    None => {
                        b.insert(k, v);
                    }
                }
            }
        }
        (slot, v) => *slot = v,
    }
}

/// Settings text laid over built-in defaults (also JSON5): a file needs only the keys it
/// changes. Errors name `origin` (or the defaults' origin for a broken built-in file).
pub fn parse_layered<T: serde::de::DeserializeOwned>(
    defaults: &str,
    defaults_origin: &str,
    text: &str,
    origin: &str,
    fix: &str,
) -> Result<T, ConfigError> {
    let mut value = parse_json5_value(defaults, defaults_origin)?;
    merge_json(&mut value, parse_json5_value(text, origin)?);
    from_value(value, origin, fix)
}

/// A config file's text and its name for error messages.
pub fn read_config(path: &std::path::Path) -> Result<(String, String), ConfigError> {
    let origin = ConfigError::file(path);
    let text = std::fs::read_to_string(path)
        .map_err(|e| ConfigError::new(&origin, "", format!("cannot read: {e}"), "check the path"))?;
    Ok((text, origin))
}
