//! Text files of numbers, one record per line (TUM trajectories, relation
//! files, line maps): parsed with errors that name the file and line.

/// A problem reading a numeric text file.
#[derive(Debug, thiserror::Error)]
pub enum TextFileError {
    /// The file could not be read.
    #[error("{path}: cannot read: {source}")]
    Io {
        /// The file.
        path: String,
        /// Why.
        source: std::io::Error,
    },
    /// A line is malformed.
    #[error("{path}:{line}: {message}")]
    Bad {
        /// The file.
        path: String,
        /// 1-based line.
        line: usize,
        /// What was expected.
        message: String,
    },
}

/// Reads a whole file as text.
pub fn read(path: &std::path::Path) -> Result<(String, String), TextFileError> {
    let name = path.display().to_string();
    std::fs::read_to_string(path)
        .map(|text| (name.clone(), text))
        .map_err(|source| TextFileError::Io { path: name, source })
}

/// The records of `text`: each non-blank line not starting with `#`, split
/// at whitespace (and commas when `commas`), must hold exactly `fields`
/// finite numbers (`layout` names them in the error). Returns (1-based line,
/// numbers) pairs.
pub fn numeric_lines(
    path: &str,
    text: &str,
    fields: usize,
    layout: &str,
    commas: bool,
) -> Result<Vec<(usize, Vec<f64>)>, TextFileError> {
    let mut out = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let bad = |message: String| TextFileError::Bad { path: path.to_string(), line: i + 1, message };
        let values: Vec<f64> = line
            .split(|c: char| c.is_ascii_whitespace() || (commas && c == ','))
            .filter(|f| !f.is_empty())
            .map(|f| match f.parse::<f64>() {
                Ok(v) if v.is_finite() => Ok(v),
                _ => Err(bad(format!("expected a number, found \"{f}\""))),
            })
            .collect::<Result<_, _>>()?;
        if values.len() != fields {
            return Err(bad(format!("expected {fields} fields ({layout}), found {}", values.len())));
        }
        out.push((i + 1, values));
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reports_the_line_and_what_was_expected() {
        let ok = numeric_lines("f", "# c\n\n1 2\n3,4\n", 2, "a b", true).unwrap();
        assert_eq!(ok, vec![(3, vec![1.0, 2.0]), (4, vec![3.0, 4.0])]);
        let e = numeric_lines("f", "1 2\n3,4\n", 2, "a b", false).unwrap_err();
        assert_eq!(e.to_string(), "f:2: expected a number, found \"3,4\"");
        let e = numeric_lines("f", "1 2 3\n", 2, "a b", false).unwrap_err();
        assert_eq!(e.to_string(), "f:1: expected 2 fields (a b), found 3");
        let e = numeric_lines("f", "1 inf\n", 2, "a b", false).unwrap_err();
        assert_eq!(e.to_string(), "f:1: expected a number, found \"inf\"");
    }
}
