//! A node's failure as its JSON report says it. A node run with `--json` writes its report on
//! stdout when it ends; when it ends on an error, the report is this instead: the error and
//! each cause under it. The launcher reads why a node ended from there, not from the text of
//! its log, which any library's output may interleave; a node that writes no report (any
//! program as a node) is still read from its log's last words.

use serde::{Deserialize, Serialize};

/// The report of a node that ended on an error.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Failure {
    /// What failed, said for a person (`acc: run`).
    pub error: String,
    /// Each cause under it, outermost first.
    #[serde(default)]
    pub causes: Vec<String>,
}

impl Failure {
    /// The error and its causes on one line, `: `-separated.
    pub fn line(&self) -> String {
        std::iter::once(self.error.as_str())
            .chain(self.causes.iter().map(String::as_str))
            .collect::<Vec<_>>()
            .join(": ")
    }

    /// The failure a report holds, or None for a report of a node that ended well (its
    /// statistics), an empty or cut one, or no JSON at all.
    pub fn in_report(report: &[u8]) -> Option<Failure> {
        serde_json::from_slice::<Failure>(report).ok()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_failure_report_is_read_back_and_statistics_are_not_taken_for_one() {
        let f = Failure { error: "acc: run".into(), causes: vec!["settings: jerk_mps3 -1 must be > 0".into()] };
        let report = serde_json::to_vec_pretty(&f).unwrap();
        assert_eq!(Failure::in_report(&report), Some(f.clone()));
        assert_eq!(f.line(), "acc: run: settings: jerk_mps3 -1 must be > 0");
        assert_eq!(Failure::in_report(br#"{"commands": 12, "emergencies": 0}"#), None);
        assert_eq!(Failure::in_report(b""), None);
        assert_eq!(Failure::in_report(br#"{"error": "cut"#), None);
    }
}
