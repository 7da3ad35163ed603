//! What can go wrong in squall-core: reading a text file of numbers or a
//! depth image, and writing a map. One type, so that a caller combining
//! several of these can use `?` throughout; the parsers of text files keep
//! their own [`TextFileError`], which converts into it.

use std::path::PathBuf;

use crate::textfile::TextFileError;

/// An error of squall-core. Its text names the file (and, for text files,
/// the line) and says what was expected.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// A numeric text file (line map, TUM trajectory, relations) could not
    /// be read or holds a malformed line.
    #[error(transparent)]
    TextFile(#[from] TextFileError),
    /// A depth image could not be opened. (Image errors name the file as
    /// text-file errors do, at line 0: the whole file.)
    #[error("{path}:0: cannot open: {source}")]
    ImageOpen {
        /// The file.
        path: String,
        /// Why.
        source: std::io::Error,
    },
    /// A depth image file is not a PNG.
    #[error("{path}:0: not a PNG: {source}")]
    NotPng {
        /// The file.
        path: String,
        /// What the PNG decoder said.
        source: png::DecodingError,
    },
    /// A depth image is a PNG, but not the 16-bit greyscale of depths in
    /// millimetres.
    #[error("{path}:0: expected a 16-bit greyscale depth image, found {bit_depth:?} {color_type:?}")]
    DepthFormat {
        /// The file.
        path: String,
        /// Its bit depth.
        bit_depth: png::BitDepth,
        /// Its colour type.
        color_type: png::ColorType,
    },
    /// A depth image whose pixels would not fit in memory.
    #[error("{path}:0: image too large")]
    ImageTooLarge {
        /// The file.
        path: String,
    },
    /// A depth image's pixels do not decode (a truncated or corrupt file).
    #[error("{path}:0: cannot decode: {source}")]
    ImageDecode {
        /// The file.
        path: String,
        /// What the PNG decoder said.
        source: png::DecodingError,
    },
    /// An occupancy grid whose cells do not fill its width × height, so it
    /// cannot be drawn.
    #[error("an occupancy grid of {width} × {height} cells holds {cells}")]
    GridShape {
        /// Cells per row.
        width: usize,
        /// Rows.
        height: usize,
        /// Cells it holds.
        cells: usize,
    },
    /// A building's inside cannot be found from its line map (see
    /// [`crate::interior`]).
    #[error("a building's inside: {0}")]
    Interior(String),
    /// A map could not be encoded as PNG.
    #[error(transparent)]
    PngEncode(#[from] png::EncodingError),
    /// A map file could not be written (a full disk, a file-size limit):
    /// the file and the system's reason.
    #[error("{}: cannot write: {source}", path.display())]
    Write {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
}

/// A result whose error is squall-core's [`Error`].
pub type Result<T, E = Error> = std::result::Result<T, E>;
