//! Small helpers shared by the text parsers (OBJ, OFF, ASCII PLY).

use super::ReadErrorKind;

/// Lines of a byte buffer as `(1-based line number, bytes)`, without the line
/// terminator (`\n` or `\r\n`). Works on bytes so that non-UTF-8 comments do
/// not stop a parse; only the tokens a parser uses are decoded.
pub(crate) fn lines(bytes: &[u8]) -> impl Iterator<Item = (usize, &[u8])> {
    bytes.split(|&b| b == b'\n').enumerate().map(|(i, l)| {
        let l = l.strip_suffix(b"\r").unwrap_or(l);
        (i + 1, l)
    })
}

/// The part of a line before a `#` comment.
pub(crate) fn strip_comment(line: &[u8]) -> &[u8] {
    match line.iter().position(|&b| b == b'#') {
        Some(i) => &line[..i],
        None => line,
    }
}

/// Whitespace-separated tokens of a line.
pub(crate) fn tokens(line: &[u8]) -> impl Iterator<Item = &[u8]> + Clone {
    line.split(|b| b.is_ascii_whitespace())
        .filter(|t| !t.is_empty())
}

/// A token for an error message: lossy UTF-8, shortened when long.
pub(crate) fn show(token: &[u8]) -> String {
    const MAX: usize = 40;
    let s = String::from_utf8_lossy(token);
    if s.chars().count() > MAX {
        let head: String = s.chars().take(MAX).collect();
        format!("`{head}...`")
    } else {
        format!("`{s}`")
    }
}

/// Parses a token as `T`, or a syntax error naming `what` and the line.
pub(crate) fn parse_token<T: std::str::FromStr>(
    token: Option<&[u8]>,
    what: &str,
    line: usize,
) -> Result<T, ReadErrorKind> {
    let Some(token) = token else {
        return Err(ReadErrorKind::Syntax {
            line,
            message: format!("expected {what}, found the end of the line"),
        });
    };
    std::str::from_utf8(token)
        .ok()
        .and_then(|s| s.parse::<T>().ok())
        .ok_or_else(|| ReadErrorKind::Syntax {
            line,
            message: format!("expected {what}, found {}", show(token)),
        })
}
