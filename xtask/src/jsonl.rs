//! The JSON-lines filter loop shared by the commands that answer one line at a time.

use std::io::{BufRead, Write};

/// Read stdin line by line, skip blank lines, and write `answer(line)` or `{"error": message}` per line;
/// a bad line never stops the stream.
pub fn filter(mut answer: impl FnMut(&str) -> Result<String, String>) -> anyhow::Result<()> {
    let stdin = std::io::stdin();
    let mut out = std::io::BufWriter::new(std::io::stdout().lock());
    for line in stdin.lock().lines() {
        let line = line?;
        if line.trim().is_empty() {
            continue;
        }
        match answer(&line) {
            Ok(json) => writeln!(out, "{json}")?,
            Err(message) => writeln!(out, "{}", serde_json::json!({ "error": message }))?,
        }
    }
    out.flush()?;
    Ok(())
}
