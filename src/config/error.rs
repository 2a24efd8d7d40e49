use std::fmt;
use std::path::PathBuf;

/// A configuration problem: which file, which key, what is wrong and how to fix it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ConfigError {
    /// The file, or a description of where the value came from (`--cfg`, `built-in defaults`).
    pub origin: String,
    /// Dotted path of the offending key; empty for a syntax error of the whole file.
    pub key: String,
    pub problem: String,
    pub fix: String,
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

impl fmt::Display for ConfigError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.key.is_empty() {
            write!(f, "{}: {}", self.origin, self.problem)?;
        } else {
            write!(f, "{}: key `{}`: {}", self.origin, self.key, self.problem)?;
        }
        if !self.fix.is_empty() {
            write!(f, " (fix: {})", self.fix)?;
        }
        Ok(())
    }
}

impl std::error::Error for ConfigError {}
