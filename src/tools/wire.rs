//! `slipstream wire-examples` and `wire-check` (hidden): the Rust encoder's example payloads
//! and its decoder as an oracle, for the test that holds docs/wire-format.md to the code and
//! for other implementations of that document (tests/python/test_wire.py).

use std::process::ExitCode;

use anyhow::Result;

/// `wire-examples`: every message kind's example encoding, as JSON (for the wire doc's test).
pub fn examples() -> Result<ExitCode> {
    let all: Vec<_> = crate::msg::examples()
        .into_iter()
        .map(|(kind, bytes)| serde_json::json!({ "kind": kind.name(), "hex": crate::msg::hex_lines(&bytes).replace('\n', " ") }))
        .collect();
    println!("{}", serde_json::to_string_pretty(&all)?);
    Ok(ExitCode::SUCCESS)
}

/// `wire-check`: decodes each hex line of stdin, printing its kind or why it is refused.
pub fn check() -> Result<ExitCode> {
    use std::io::BufRead;
    for line in std::io::stdin().lock().lines() {
        let line = line?;
        let bytes: Result<Vec<u8>, _> =
            (0..line.len()).step_by(2).map(|i| u8::from_str_radix(line.get(i..i + 2).unwrap_or("zz"), 16)).collect();
        let verdict = match bytes.map(|b| crate::msg::decode_json(&b)) {
            Ok(Ok((kind, _, _))) => serde_json::json!({ "kind": kind.name() }),
            Ok(Err(e)) => serde_json::json!({ "error": e.to_string() }),
            Err(_) => serde_json::json!({ "error": format!("not hex: {line}") }),
        };
        println!("{verdict}");
    }
    Ok(ExitCode::SUCCESS)
}
