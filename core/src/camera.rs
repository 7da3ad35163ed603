//! The depth camera model: pinhole intrinsics, where the camera sits on the
//! robot, and the frames it produces (16-bit millimetre images, with the
//! odometry at their instant).

use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::geometry::{Pose2, Real};
use crate::{Error, Result};

/// A pinhole camera: focal lengths and principal point, pixels.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Intrinsics {
    /// Horizontal focal length.
    pub fx: Real,
    /// Vertical focal length.
    pub fy: Real,
    /// Principal point, column.
    pub cx: Real,
    /// Principal point, row.
    pub cy: Real,
}

impl Intrinsics {
    /// The RealSense D435 depth stream aligned to colour, 640 × 480 (the
    /// shared data's frames).
    pub const D435: Intrinsics = Intrinsics { fx: 615.0, fy: 615.0, cx: 320.0, cy: 240.0 };
}

/// A 16-bit depth image in millimetres (0: no data), row-major.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct DepthImage {
    /// Pixels per row.
    pub width: usize,
    /// Rows.
    pub height: usize,
    /// Depth per pixel, millimetres.
    pub depth_mm: Vec<u16>,
}

impl DepthImage {
    /// Reads a 16-bit greyscale PNG (millimetres).
    pub fn load_png(path: &Path) -> Result<Self> {
        let name = || path.display().to_string();
        let file = std::fs::File::open(path).map_err(|source| Error::ImageOpen { path: name(), source })?;
        let mut reader = png::Decoder::new(std::io::BufReader::new(file))
            .read_info()
            .map_err(|source| Error::NotPng { path: name(), source })?;
        let info = reader.info();
        if info.bit_depth != png::BitDepth::Sixteen || info.color_type != png::ColorType::Grayscale {
            return Err(Error::DepthFormat {
                path: name(),
                bit_depth: info.bit_depth,
                color_type: info.color_type,
            });
        }
        let (width, height) = (info.width as usize, info.height as usize);
        let mut buf =
            vec![0; reader.output_buffer_size().ok_or_else(|| Error::ImageTooLarge { path: name() })?];
        reader.next_frame(&mut buf).map_err(|source| Error::ImageDecode { path: name(), source })?;
        let depth_mm =
            buf.chunks_exact(2).take(width * height).map(|b| u16::from_be_bytes([b[0], b[1]])).collect();
        Ok(DepthImage { width, height, depth_mm })
    }

    /// The camera-frame point of pixel (`row`, `col`) (x right, y down,
    /// z forward, metres), if it has depth.
    ///
    /// # Panics
    ///
    /// If the pixel lies outside the image, as slice indexing does: pixel
    /// loops run over the image's own rows and columns.
    #[inline]
    pub fn point(&self, row: usize, col: usize, k: &Intrinsics) -> Option<[f32; 3]> {
        let d = self.depth_mm[row * self.width + col];
        (d != 0).then(|| {
            let z = f32::from(d) * 1e-3;
            [((col as Real - k.cx) / k.fx) as f32 * z, ((row as Real - k.cy) / k.fy) as f32 * z, z]
        })
    }
}

/// Where a depth camera sits on the robot.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct CameraMount {
    /// Forward of the robot's origin, metres.
    pub x: Real,
    /// Left of it, metres.
    pub y: Real,
    /// Height above the floor, metres.
    pub height: Real,
    /// Downward pitch, radians.
    pub tilt: Real,
    /// Heading relative to the robot, radians.
    pub yaw: Real,
}

/// A depth frame with the odometry at its instant.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct DepthFrame {
    /// Seconds.
    pub stamp: f64,
    /// The odometry pose then.
    pub odometry: Pose2,
    /// The image.
    pub image: DepthImage,
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A one-row greyscale PNG of `depth` bits holding `samples`.
    fn png_file(dir: &Path, name: &str, depth: png::BitDepth, samples: &[u8]) -> std::path::PathBuf {
        let path = dir.join(name);
        let per_pixel = if depth == png::BitDepth::Sixteen { 2 } else { 1 };
        let mut encoder =
            png::Encoder::new(std::fs::File::create(&path).unwrap(), (samples.len() / per_pixel) as u32, 1);
        encoder.set_color(png::ColorType::Grayscale);
        encoder.set_depth(depth);
        encoder.write_header().unwrap().write_image_data(samples).unwrap();
        path
    }

    #[test]
    fn depth_pngs_load_and_other_files_say_why_not() {
        let dir = tempfile::tempdir().unwrap();
        let good = png_file(dir.path(), "d.png", png::BitDepth::Sixteen, &[0x03, 0xe8, 0, 0]);
        let image = DepthImage::load_png(&good).unwrap();
        assert_eq!((image.width, image.height, image.depth_mm), (2, 1, vec![1000, 0]));

        let name = |f: &str| dir.path().join(f).display().to_string();
        let missing = DepthImage::load_png(&dir.path().join("none.png")).unwrap_err().to_string();
        assert!(missing.starts_with(&format!("{}:0: cannot open: ", name("none.png"))), "{missing}");
        std::fs::write(dir.path().join("t.png"), "not an image").unwrap();
        let text = DepthImage::load_png(&dir.path().join("t.png")).unwrap_err().to_string();
        assert!(text.starts_with(&format!("{}:0: not a PNG: ", name("t.png"))), "{text}");
        let grey = png_file(dir.path(), "g.png", png::BitDepth::Eight, &[1, 2]);
        assert_eq!(
            DepthImage::load_png(&grey).unwrap_err().to_string(),
            format!("{}:0: expected a 16-bit greyscale depth image, found Eight Grayscale", name("g.png"))
        );
    }
}
