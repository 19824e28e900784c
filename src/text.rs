//! Text helpers shared by the daemon's answers, the recording and the binaries: cutting a
//! client's or a file's text to a bounded size, an error and its causes said once. A leaf.

/// `s` cut to at most `max` bytes on a character boundary, with `…` when cut.
pub fn truncate(s: &str, max: usize) -> String {
    if s.len() <= max {
        return s.to_string();
    }
    let mut end = max;
    while !s.is_char_boundary(end) {
        end -= 1;
    }
    format!("{}…", &s[..end])
}

/// `e` and its causes joined by `": "`, each said once: a cause the text before it already
/// quotes is left out (an error written as `"sim.plant: {0}"`), and one that begins with what
/// the text before it ends with (a context "loading FILE" over "FILE: not found") adds only
/// the rest.
///
/// ```
/// #[derive(Debug, thiserror::Error)]
/// #[error("sim.plant: {0}")]
/// struct Plant(#[from] std::io::Error);
/// let e = Plant(std::io::Error::other("python3: not found"));
/// assert_eq!(pa10::text::error_chain(&e), "sim.plant: python3: not found");
///
/// #[derive(Debug, thiserror::Error)]
/// #[error("loading /data/cal.csv")]
/// struct Loading(#[source] std::io::Error);
/// let e = Loading(std::io::Error::other("/data/cal.csv: not found"));
/// assert_eq!(pa10::text::error_chain(&e), "loading /data/cal.csv: not found");
/// ```
pub fn error_chain(e: &(dyn std::error::Error + 'static)) -> String {
    /// Shortest overlap taken for the same words (a path, a phrase), bytes.
    const MIN_OVERLAP: usize = 4;
    let mut out = e.to_string();
    let mut cause = e.source();
    while let Some(c) = cause {
        let text = c.to_string();
        if !out.contains(&text) {
            let overlap = (MIN_OVERLAP..text.len())
                .rev()
                .find(|&k| text.is_char_boundary(k) && out.ends_with(&text[..k]));
            match overlap {
                Some(k) => out.push_str(&text[k..]),
                None => {
                    out.push_str(": ");
                    out.push_str(&text);
                }
            }
        }
        cause = c.source();
    }
    out
}
