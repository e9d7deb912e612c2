//! Numbers and messages as text.

/// Formats an `f64` with the shortest digits that parse back to the same
/// value, in plain notation for moderate magnitudes and scientific notation
/// otherwise (so `1e-300` does not become 300 zeros, nor `1e300` 300
/// digits). Used for every number mfm writes as text or shows in a message.
///
/// ```
/// use mfm_files::fmt_f64;
/// assert_eq!(fmt_f64(0.25), "0.25");
/// assert_eq!(fmt_f64(1e300), "1e300");
/// assert_eq!(fmt_f64(-1e-15), "-1e-15");
/// ```
pub fn fmt_f64(x: f64) -> String {
    let a = x.abs();
    if a == 0.0 || (1e-5..1e16).contains(&a) || !x.is_finite() {
        format!("{x}")
    } else {
        format!("{x:e}")
    }
}

/// `text` with control characters (escape sequences, carriage returns,
/// NUL...) shown as Rust escapes, so a message that quotes a file's content
/// cannot drive the terminal it is printed on.
///
/// ```
/// assert_eq!(mfm_files::text::printable("bad \u{1b}[2J\r\n"), "bad \\u{1b}[2J\\r\\n");
/// ```
pub fn printable(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    for c in text.chars() {
        if c.is_control() {
            out.extend(c.escape_default());
        } else {
            out.push(c);
        }
    }
    out
}

/// An error and its causes ([`std::error::Error::source`]) on one line,
/// `outer: inner: ...`, leaving out a cause whose text an outer message
/// already contains (errors such as `path: io error` both show and return
/// their source).
pub fn error_line(e: &(dyn std::error::Error + 'static)) -> String {
    let mut line = String::new();
    let mut cause = Some(e);
    while let Some(c) = cause {
        let text = c.to_string();
        if !line.contains(&text) {
            if !line.is_empty() {
                line.push_str(": ");
            }
            line.push_str(&text);
        }
        cause = c.source();
    }
    line
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn control_characters_are_escaped() {
        assert_eq!(
            printable("bad token \u{1b}[2J here\r\n"),
            "bad token \\u{1b}[2J here\\r\\n"
        );
        assert_eq!(printable("plain · text"), "plain · text");
    }

    #[derive(Debug)]
    struct Chain(&'static str, Option<Box<Chain>>);

    impl std::fmt::Display for Chain {
        fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
            f.write_str(self.0)
        }
    }

    impl std::error::Error for Chain {
        fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
            self.1.as_deref().map(|c| c as _)
        }
    }

    #[test]
    fn a_cause_already_in_its_wrapper_is_printed_once() {
        let io = Chain("No such file", None);
        let e = Chain(
            "loading the dataset",
            Some(Box::new(Chain(
                "/d/manifest.json: No such file",
                Some(Box::new(io)),
            ))),
        );
        assert_eq!(
            error_line(&e),
            "loading the dataset: /d/manifest.json: No such file"
        );
        let e = Chain(
            "outer",
            Some(Box::new(Chain(
                "middle",
                Some(Box::new(Chain("inner", None))),
            ))),
        );
        assert_eq!(error_line(&e), "outer: middle: inner");
    }
}
