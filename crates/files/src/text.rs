//! Numbers as text.

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
