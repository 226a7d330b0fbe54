//! The JSON-lines filter loop shared by the commands that answer one line at a time.

use std::io::{BufRead, Read, Write};

/// What `--help` says about the stream, for every filter command.
pub const STREAM_HELP: &str = "Reads JSON lines on stdin and writes one answer line per input line, \
flushed as soon as it is computed (a script may write a line and wait for its answer). Blank lines get \
no answer. A bad line (not JSON, not UTF-8, out of range, longer than 8 MiB, or a result that is not \
finite) gets {\"error\": \"...\"} and the stream goes on.";

/// The longest input line a stream reads (8 MiB: a 500 x 500 problem, the largest Lemke's method takes,
/// is about 6 MiB of JSON); the rest of a longer line is skipped unread into memory and the line answered
/// with an error.
pub const MAX_LINE: usize = 8 << 20;

/// Read `input` line by line, skip blank lines, and write `answer(line)` or `{"error": message}` per
/// line to `output`, flushing after each; a bad line (not UTF-8 included) never stops the stream, and a
/// reader that goes away (a closed pipe) ends it quietly.
pub fn filter_with(
    input: impl BufRead,
    output: impl Write,
    mut answer: impl FnMut(&str) -> Result<String, String>,
) -> anyhow::Result<()> {
    let mut input = input;
    let mut out = output;
    let mut buf = Vec::new();
    for number in 1usize.. {
        buf.clear();
        if input
            .by_ref()
            .take(MAX_LINE as u64 + 1)
            .read_until(b'\n', &mut buf)?
            == 0
        {
            break;
        }
        let too_long = buf.len() > MAX_LINE && buf.last() != Some(&b'\n');
        if too_long {
            // Skip the rest of the line a buffer at a time, never holding more than one.
            loop {
                let chunk = input.fill_buf()?;
                if chunk.is_empty() {
                    break;
                }
                match chunk.iter().position(|&b| b == b'\n') {
                    Some(end) => {
                        input.consume(end + 1);
                        break;
                    }
                    None => {
                        let len = chunk.len();
                        input.consume(len);
                    }
                }
            }
        }
        let reply = match std::str::from_utf8(&buf) {
            _ if too_long => Err(format!(
                "line {number} is longer than {MAX_LINE} bytes (8 MiB, the stream's limit)"
            )),
            Ok(line) if line.trim().is_empty() => continue,
            Ok(line) => answer(line.trim_end_matches(['\n', '\r'])),
            Err(e) => Err(format!(
                "line {number} is not UTF-8 (invalid byte at offset {})",
                e.valid_up_to()
            )),
        };
        let text = match reply {
            Ok(json) => json,
            Err(message) => serde_json::json!({ "error": message }).to_string(),
        };
        match writeln!(out, "{text}").and_then(|()| out.flush()) {
            Ok(()) => {}
            Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => return Ok(()),
            Err(e) => return Err(e.into()),
        }
    }
    Ok(())
}

/// `value` as one JSON line, or an error naming the first entry that is not finite (JSON has no NaN or
/// infinity; serialised, they would read as `null`). The answers have no optional `null` fields.
pub fn finite_line(value: &impl serde::Serialize) -> Result<String, String> {
    fn first_null(v: &serde_json::Value, path: &mut String) -> bool {
        match v {
            serde_json::Value::Null => true,
            serde_json::Value::Array(items) => items.iter().enumerate().any(|(i, item)| {
                let len = path.len();
                path.push_str(&format!("[{i}]"));
                let found = first_null(item, path);
                if !found {
                    path.truncate(len);
                }
                found
            }),
            serde_json::Value::Object(fields) => fields.iter().any(|(k, item)| {
                let len = path.len();
                if !path.is_empty() {
                    path.push('.');
                }
                path.push_str(k);
                let found = first_null(item, path);
                if !found {
                    path.truncate(len);
                }
                found
            }),
            _ => false,
        }
    }
    let v = serde_json::to_value(value).map_err(|e| e.to_string())?;
    let mut path = String::new();
    if first_null(&v, &mut path) {
        return Err(format!(
            "the result is not finite ({path}): the input is outside the range this command \
             computes reliably"
        ));
    }
    // Written from the value itself, to keep its fields in their declared order.
    serde_json::to_string(value).map_err(|e| e.to_string())
}

/// [`filter_with`] on stdin and stdout.
pub fn filter(answer: impl FnMut(&str) -> Result<String, String>) -> anyhow::Result<()> {
    filter_with(std::io::stdin().lock(), std::io::stdout().lock(), answer)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_line_gets_its_answer_and_a_line_that_is_not_utf8_gets_an_error() {
        let input: &[u8] = b"a\n\n  \nb\xff\xfe\r\nc\r\nlast";
        let mut out = Vec::new();
        filter_with(input, &mut out, |line| {
            if line == "c" {
                Err("bad c".into())
            } else {
                Ok(format!("\"{line}\""))
            }
        })
        .unwrap();
        let lines: Vec<&str> = std::str::from_utf8(&out).unwrap().lines().collect();
        assert_eq!(lines.len(), 4, "{lines:?}");
        assert_eq!(lines[0], "\"a\"");
        assert!(lines[1].contains("line 4 is not UTF-8"), "{}", lines[1]);
        assert_eq!(lines[2], r#"{"error":"bad c"}"#);
        assert_eq!(lines[3], "\"last\"");
    }

    #[test]
    fn a_line_past_the_limit_gets_an_error_and_the_next_line_its_answer() {
        let mut input = vec![b'['; MAX_LINE + 1000];
        input.extend_from_slice(b"\nnext\n");
        let mut out = Vec::new();
        filter_with(&input[..], &mut out, |line| {
            Ok(format!("\"{}\"", line.len()))
        })
        .unwrap();
        let lines: Vec<&str> = std::str::from_utf8(&out).unwrap().lines().collect();
        assert_eq!(lines.len(), 2, "{}", lines.len());
        assert!(lines[0].contains("longer than"), "{}", lines[0]);
        assert_eq!(lines[1], "\"4\"");
    }

    /// A writer that records how many lines had been flushed when each answer was asked for.
    struct Counting<'a> {
        written: Vec<u8>,
        flushed: &'a std::cell::Cell<usize>,
    }

    impl Write for Counting<'_> {
        fn write(&mut self, b: &[u8]) -> std::io::Result<usize> {
            self.written.extend_from_slice(b);
            Ok(b.len())
        }
        fn flush(&mut self) -> std::io::Result<()> {
            self.flushed
                .set(self.written.iter().filter(|&&c| c == b'\n').count());
            Ok(())
        }
    }

    #[test]
    fn each_answer_is_flushed_before_the_next_line_is_read() {
        let flushed = std::cell::Cell::new(0);
        let out = Counting {
            written: Vec::new(),
            flushed: &flushed,
        };
        let mut seen = Vec::new();
        filter_with(&b"1\n2\n3\n"[..], out, |line| {
            seen.push(flushed.get());
            Ok(line.to_string())
        })
        .unwrap();
        assert_eq!(seen, [0, 1, 2]);
        assert_eq!(flushed.get(), 3);
    }

    #[test]
    fn a_result_that_is_not_finite_is_an_error_naming_the_entry() {
        #[derive(serde::Serialize)]
        struct A {
            ok: f64,
            x: Vec<f64>,
        }
        let good = finite_line(&A {
            ok: 1.0,
            x: vec![2.0, 3.0],
        })
        .unwrap();
        assert_eq!(good, r#"{"ok":1.0,"x":[2.0,3.0]}"#);
        let bad = finite_line(&A {
            ok: 1.0,
            x: vec![2.0, f64::INFINITY],
        })
        .unwrap_err();
        assert!(bad.contains("(x[1])"), "{bad}");
    }

    #[test]
    fn a_closed_reader_ends_the_stream_quietly() {
        struct Closed;
        impl Write for Closed {
            fn write(&mut self, _: &[u8]) -> std::io::Result<usize> {
                Err(std::io::ErrorKind::BrokenPipe.into())
            }
            fn flush(&mut self) -> std::io::Result<()> {
                Ok(())
            }
        }
        filter_with(&b"1\n2\n"[..], Closed, |l| Ok(l.to_string())).unwrap();
    }
}
