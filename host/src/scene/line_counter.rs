//! A buffered reader that knows which line it is in, so that a parser which reads line by line
//! and stops at its first error (tobj's OBJ parser) can be given the line number it does not
//! report itself.

use std::io::{BufRead, BufReader, Read, Result};

/// Wraps a [`BufReader`] and counts the line breaks of the bytes its reader has consumed.
pub struct LineCounter<R> {
    inner: BufReader<R>,
    /// Line breaks consumed so far.
    breaks: usize,
    /// Whether the last byte consumed ended a line (or nothing has been read).
    at_line_start: bool,
}

impl<R: Read> LineCounter<R> {
    /// Counts the lines read from `inner`.
    pub fn new(inner: R) -> Self {
        Self { inner: BufReader::new(inner), breaks: 0, at_line_start: true }
    }

    /// The 1-based number of the line the last consumed byte belongs to: after a line-by-line
    /// reader has read a line, that line's number (0 before anything is read).
    pub fn line(&self) -> usize {
        if self.at_line_start {
            self.breaks
        } else {
            self.breaks + 1
        }
    }
}

impl<R: Read> Read for LineCounter<R> {
    fn read(&mut self, out: &mut [u8]) -> Result<usize> {
        let available = self.fill_buf()?;
        let n = available.len().min(out.len());
        out[..n].copy_from_slice(&available[..n]);
        self.consume(n);
        Ok(n)
    }
}

impl<R: Read> BufRead for LineCounter<R> {
    fn fill_buf(&mut self) -> Result<&[u8]> {
        self.inner.fill_buf()
    }

    fn consume(&mut self, amount: usize) {
        let buffered = self.inner.buffer();
        let consumed = &buffered[..amount.min(buffered.len())];
        self.breaks += consumed.iter().filter(|&&b| b == b'\n').count();
        if let Some(&last) = consumed.last() {
            self.at_line_start = last == b'\n';
        }
        self.inner.consume(amount);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_line_is_that_of_the_last_line_read() {
        let text = "first\nsecond\n\nfourth, no line break";
        let mut reader = LineCounter::new(text.as_bytes());
        assert_eq!(reader.line(), 0, "nothing read yet");
        let mut line = String::new();
        for expected in 1..=4 {
            line.clear();
            assert!(reader.read_line(&mut line).expect("in memory") > 0);
            assert_eq!(reader.line(), expected, "after reading {line:?}");
        }
        line.clear();
        assert_eq!(reader.read_line(&mut line).expect("in memory"), 0, "end of input");
        assert_eq!(reader.line(), 4);
    }

    #[test]
    fn lines_longer_than_the_buffer_and_plain_reads_are_counted() {
        let long = "x".repeat(20_000);
        let text = format!("{long}\n{long}\nlast\n");
        let mut reader = LineCounter::new(text.as_bytes());
        let mut head = [0u8; 100];
        reader.read_exact(&mut head).expect("in memory");
        assert_eq!(reader.line(), 1, "inside the first line");
        let lines: Vec<String> = (&mut reader).lines().map(|l| l.expect("in memory")).collect();
        assert_eq!(lines.len(), 3);
        assert_eq!(reader.line(), 3);
    }
}
