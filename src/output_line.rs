//! One line of a bench's or a report's output: a JSON object with `--json`, else a table row; and
//! [`warn`], a line on standard error that cannot panic.

/// A line a bench or report emits, printable as one JSON object or as a table row.
pub trait OutputLine {
    /// The line as one JSON object.
    fn json(&self) -> String;
    /// The line as a human-readable table row.
    fn row(&self) -> String;
    /// The line as `--json` asks: [`Self::json`] if `json`, else [`Self::row`].
    fn text(&self, json: bool) -> String {
        if json {
            self.json()
        } else {
            self.row()
        }
    }
}

/// `value` as one JSON object: what [`OutputLine::json`] prints for the plain structs of the
/// benches and reports (empty should serialization fail, which their fields cannot make it).
pub fn json_object(value: &impl serde::Serialize) -> String {
    serde_json::to_string(value).unwrap_or_default()
}

/// Writes `message` and a newline to standard error, dropping it if stderr is closed or full:
/// `eprintln!` panics there ("failed printing to stderr"), which ended a render with exit status
/// 101 before its results were printed (`2>/dev/full`). A warning or note is not worth the job.
pub fn warn(message: &str) {
    use std::io::Write;
    let _ = writeln!(std::io::stderr().lock(), "{message}");
}
