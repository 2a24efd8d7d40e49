//! Zenoh's config errors said for a person: the key and what is wrong, not a Rust debug
//! struct.
//!
//! Zenoh reports a config file's type errors as the `Debug` of a serde error
//! (`JSON error: Message { msg: "invalid type: ...", location: Some(Location { line: 1,
//! column: 100 }) }`), naming neither the key nor the fix. This reads the message and the
//! position back out of it and finds the key: the one an "unknown field" names, or the last key
//! written before the position on its line.

use super::ConfigError;

/// The fix every Zenoh config error points to.
const FIX: &str = "compare with the keys documented in config/zenoh.json5 (and Zenoh's DEFAULT_CONFIG.json5)";

/// A ConfigError for `error`, raised by Zenoh on the config file `origin` whose text is `text`.
pub(super) fn file_error(origin: &str, text: &str, error: &dyn std::fmt::Display) -> ConfigError {
    let raw = crate::bus::without_source_locations(&error.to_string());
    let Some((message, position)) = serde_message(&raw) else {
        return ConfigError::new(origin, "", raw, FIX);
    };
    let key = unknown_field(&message).or_else(|| position.and_then(|(line, column)| key_before(text, line, column)));
    let problem = match position {
        Some((line, column)) => format!("{message} (line {line}, column {column})"),
        None => message,
    };
    ConfigError::new(origin, key.unwrap_or_default(), problem, FIX)
}

/// What Zenoh said was wrong with a value, without the debug struct around it: the serde
/// message, or for a JSON5 syntax error its "expected ..." line.
pub(super) fn message(error: &dyn std::fmt::Display) -> String {
    let raw = crate::bus::without_source_locations(&error.to_string());
    match serde_message(&raw) {
        Some((m, _)) => {
            m.split("\\n").find_map(|l| l.trim().strip_prefix("= ")).map_or_else(|| m.clone(), str::to_string)
        }
        None => raw,
    }
}

/// The `msg` and the (line, column) of `... Message { msg: "...", location: Some(Location {
/// line: L, column: C }) }`.
fn serde_message(raw: &str) -> Option<(String, Option<(usize, usize)>)> {
    let start = raw.find("msg: \"")? + "msg: \"".len();
    let rest = &raw[start..];
    let end = rest.find("\", location:")?;
    let message = rest[..end].replace("\\\"", "\"");
    let number = |after: &str| -> Option<usize> {
        let at = rest.find(after)? + after.len();
        rest[at..].chars().take_while(char::is_ascii_digit).collect::<String>().parse().ok()
    };
    Some((message, number("line: ").zip(number("column: "))))
}

/// The field an "unknown field `x`, expected ..." names.
fn unknown_field(message: &str) -> Option<String> {
    let rest = message.strip_prefix("unknown field `")?;
    Some(rest[..rest.find('`')?].to_string())
}

/// The last key (`name:` or `"name":`) written before `column` on line `line` (both from 1).
fn key_before(text: &str, line: usize, column: usize) -> Option<String> {
    let line = text.lines().nth(line.checked_sub(1)?)?;
    let upto: String = line.chars().take(column.saturating_sub(1)).collect();
    let colon = upto.rfind(':')?;
    let name = upto[..colon].trim_end().trim_end_matches(['"', '\'']);
    let start = name.rfind(|c: char| !(c.is_alphanumeric() || c == '_' || c == '-')).map_or(0, |i| i + 1);
    (start < name.len()).then(|| name[start..].to_string())
}

#[cfg(test)]
mod tests {
    use super::file_error;

    #[test]
    fn a_type_error_names_the_key_and_the_position_not_a_debug_struct() {
        let text = r#"{ mode: "peer", transport: { unicast: { lowlatency: "yes" } } }"#;
        let raw = r#"JSON error: Message { msg: "invalid type: string \"yes\", expected a boolean", location: Some(Location { line: 1, column: 59 }) }"#;
        let e = file_error("config/zenoh.json5", text, &raw);
        assert_eq!(e.key, "lowlatency");
        assert_eq!(e.problem, r#"invalid type: string "yes", expected a boolean (line 1, column 59)"#);
        assert!(!e.to_string().contains("Location {"), "{e}");
    }

    #[test]
    fn a_bad_value_says_what_was_expected() {
        let raw = r#"Json5Err(Message { msg: " --> 1:1\n  |\n1 | yes\n  | ^---\n  |\n  = expected array, boolean, null, number, object, or string", location: Some(Location { line: 1, column: 1 }) })"#;
        assert_eq!(super::message(&raw), "expected array, boolean, null, number, object, or string");
        assert_eq!(super::message(&"plain words"), "plain words");
    }

    #[test]
    fn an_unknown_field_is_the_key_and_other_errors_pass_as_they_are() {
        let raw = r#"JSON error: Message { msg: "unknown field `bogus`, expected one of `id`, `mode`", location: Some(Location { line: 1, column: 17 }) }"#;
        assert_eq!(file_error("f", "{ mode: 'peer', bogus: 1 }", &raw).key, "bogus");
        let other = file_error("f", "", &"some other failure");
        assert_eq!((other.key.as_str(), other.problem.as_str()), ("", "some other failure"));
    }
}
