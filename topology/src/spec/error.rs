//! Errors in topology files, each with file, line and component.

use std::fmt;
use std::sync::Arc;

/// A component's role, named in errors.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Role {
    /// A source.
    Spout,
    /// A processing step.
    Bolt,
}

impl fmt::Display for Role {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Role::Spout => "spout",
            Role::Bolt => "bolt",
        })
    }
}

/// One problem in a topology, located in its file.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SpecError {
    /// The file (or `<string>`), as given.
    pub file: Arc<str>,
    /// 1-based line.
    pub line: usize,
    /// The component the problem is in, if any.
    pub component: Option<(Role, String)>,
    /// What is wrong and what was expected.
    pub message: String,
}

impl fmt::Display for SpecError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}:{}: ", self.file, self.line)?;
        if let Some((role, name)) = &self.component {
            write!(f, "{role} \"{}\": ", clipped(name))?;
        }
        f.write_str(&clipped(&self.message))
    }
}

/// The most characters of a name or message an error shows: a
/// megabyte-long token (a pasted file, a runaway string) is cut, with how
/// much was left out.
const SHOWN: usize = 400;

/// Of those, the characters kept from the end, where a message says
/// whose value it was (`in `particles``).
const SHOWN_TAIL: usize = 100;

/// `text`, its middle cut out past [`SHOWN`] characters.
fn clipped(text: &str) -> std::borrow::Cow<'_, str> {
    let chars = text.chars().count();
    if chars <= SHOWN {
        return text.into();
    }
    let head_end = text.char_indices().nth(SHOWN - SHOWN_TAIL).map_or(text.len(), |(at, _)| at);
    let tail_start = text.char_indices().nth(chars - SHOWN_TAIL).map_or(text.len(), |(at, _)| at);
    let left_out = tail_start - head_end;
    format!("{}… ({left_out} more bytes) …{}", &text[..head_end], &text[tail_start..]).into()
}

/// Every problem found in a topology (validation does not stop at the first).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub struct SpecErrors(pub Vec<SpecError>);

impl fmt::Display for SpecErrors {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for (i, e) in self.0.iter().enumerate() {
            if i > 0 {
                writeln!(f)?;
            }
            write!(f, "{e}")?;
        }
        Ok(())
    }
}

impl From<SpecError> for SpecErrors {
    fn from(e: SpecError) -> Self {
        SpecErrors(vec![e])
    }
}

/// Maps byte offsets of a topology file to lines, and builds its errors.
#[derive(Debug, Clone)]
pub(crate) struct SourceText {
    pub(crate) file: Arc<str>,
    line_starts: Vec<usize>,
}

impl SourceText {
    pub(crate) fn new(file: &str, text: &str) -> Self {
        let mut line_starts = vec![0];
        line_starts.extend(text.match_indices('\n').map(|(i, _)| i + 1));
        SourceText { file: file.into(), line_starts }
    }

    /// 1-based line of a byte offset.
    pub(crate) fn line(&self, offset: usize) -> usize {
        self.line_starts.partition_point(|&start| start <= offset)
    }

    pub(crate) fn error(
        &self,
        offset: usize,
        component: Option<(Role, &str)>,
        message: impl Into<String>,
    ) -> SpecError {
        self.error_at_line(self.line(offset), component, message)
    }

    pub(crate) fn error_at_line(
        &self,
        line: usize,
        component: Option<(Role, &str)>,
        message: impl Into<String>,
    ) -> SpecError {
        SpecError {
            file: self.file.clone(),
            line,
            component: component.map(|(r, n)| (r, n.to_string())),
            message: message.into(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lines_are_one_based() {
        let s = SourceText::new("t.toml", "a\nbb\n\nc");
        assert_eq!(s.line(0), 1);
        assert_eq!(s.line(1), 1);
        assert_eq!(s.line(2), 2);
        assert_eq!(s.line(5), 3);
        assert_eq!(s.line(6), 4);
    }
}
