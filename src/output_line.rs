//! One line of a bench's or a report's output: a JSON object with `--json`, else a table row.

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
