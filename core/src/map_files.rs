//! Map files a robotics user can open: PGM + YAML in the ROS `map_server`
//! convention, and PNG (optionally with the trajectory drawn on it).
//!
//! Pixel values follow `map_saver`: occupied (≥ 65 %) black 0, free
//! (≤ 25 %) white 254, unknown grey 205. Image row 0 is the top of the map.
//! The YAML's thresholds are the ones ROS 1 `map_saver` and slam_toolbox
//! write (free 0.196, occupied 0.65, trinary), under which nav2's
//! `map_server` reads those three greys back as free, occupied and unknown.

use std::io::Write;
use std::path::Path;

use squall_topology::fsio::{write_atomic, write_atomic_with};

use crate::geometry::{Pose2, line_cells};
use crate::occupancy::{OccupancyGrid, UNKNOWN};
use crate::{Error, Result};

/// Occupancy (percent) at or above which a cell is drawn occupied.
pub const OCCUPIED_PERCENT: i8 = 65;
/// Occupancy (percent) at or below which a cell is drawn free.
pub const FREE_PERCENT: i8 = 25;

/// `free_thresh` of the YAML. `map_server` reads a pixel of grey `g` as
/// occupancy `1 − g/255` and calls it free below this: white 254 reads
/// 0.004 (free), the unknown grey 205 reads 0.19608, just above, so it
/// stays unknown. With 0.25 (the drawing threshold) every unknown cell
/// would load as free and a planner would route through unmapped space.
pub const YAML_FREE_THRESH: f64 = 0.196;
/// `occupied_thresh` of the YAML: black 0 reads 1.0, above it.
pub const YAML_OCCUPIED_THRESH: f64 = 0.65;

fn pixel(value: i8) -> u8 {
    match value {
        UNKNOWN => 205,
        v if v >= OCCUPIED_PERCENT => 0,
        v if v <= FREE_PERCENT => 254,
        _ => 205,
    }
}

/// An error unless the grid holds its width × height cells.
fn check_shape(grid: &OccupancyGrid) -> Result<()> {
    match grid.width.checked_mul(grid.height) {
        Some(size) if size <= grid.cells.len() => Ok(()),
        _ => Err(Error::GridShape { width: grid.width, height: grid.height, cells: grid.cells.len() }),
    }
}

/// The grey pixels of image row `row` (row 0 is the top of the map); the
/// grid's shape must have been checked.
fn grey_row(grid: &OccupancyGrid, row: usize) -> impl Iterator<Item = u8> + '_ {
    let map_row = grid.height - 1 - row;
    grid.cells[map_row * grid.width..(map_row + 1) * grid.width].iter().map(|&v| pixel(v))
}

/// Writes `DIR/STEM.pgm` and `DIR/STEM.yaml` (atomically). The image is
/// streamed a row at a time: a large map is never held twice in memory.
pub fn write_pgm_yaml(grid: &OccupancyGrid, dir: &Path, stem: &str) -> Result<()> {
    check_shape(grid)?;
    let path = dir.join(format!("{stem}.pgm"));
    write_atomic_with(&path, |out| {
        write!(
            out,
            "P5\n# squall occupancy map, {} m/cell\n{} {}\n255\n",
            grid.resolution, grid.width, grid.height
        )?;
        let mut row = Vec::with_capacity(grid.width);
        for y in 0..grid.height {
            row.clear();
            row.extend(grey_row(grid, y));
            out.write_all(&row)?;
        }
        Ok(())
    })
    .map_err(|source| Error::Write { path: path.clone(), source })?;
    let yaml = format!(
        "image: {stem}.pgm\nmode: trinary\nresolution: {}\norigin: [{}, {}, 0.0]\nnegate: 0\noccupied_thresh: {}\nfree_thresh: {}\n",
        grid.resolution, grid.origin.0, grid.origin.1, YAML_OCCUPIED_THRESH, YAML_FREE_THRESH,
    );
    let path = dir.join(format!("{stem}.yaml"));
    write_atomic(&path, yaml.as_bytes()).map_err(|source| Error::Write { path, source })
}

/// Colour of the trajectory drawn on the PNG.
const PATH_RGB: [u8; 3] = [220, 20, 20];

/// Encodes the map as PNG into `out`, a row at a time; with a trajectory,
/// as RGB with the path drawn in red.
pub fn encode_png<W: Write>(grid: &OccupancyGrid, trajectory: &[Pose2], out: W) -> Result<()> {
    check_shape(grid)?;
    let rgb = !trajectory.is_empty();
    let mut encoder = png::Encoder::new(out, grid.width as u32, grid.height as u32);
    encoder.set_depth(png::BitDepth::Eight);
    encoder.set_color(if rgb { png::ColorType::Rgb } else { png::ColorType::Grayscale });
    let mut writer = encoder.write_header()?;
    let mut stream = writer.stream_writer()?;
    let path = path_pixels(grid, trajectory);
    let mut path = path.iter().peekable();
    let mut row = Vec::with_capacity(grid.width * if rgb { 3 } else { 1 });
    for y in 0..grid.height {
        row.clear();
        if rgb {
            row.extend(grey_row(grid, y).flat_map(|g| [g, g, g]));
            while let Some(&(_, x)) = path.next_if(|&&(py, _)| py == y) {
                row[3 * x..3 * x + 3].copy_from_slice(&PATH_RGB);
            }
        } else {
            row.extend(grey_row(grid, y));
        }
        stream.write_all(&row).map_err(png::EncodingError::from)?;
    }
    stream.finish()?;
    Ok(())
}

/// The map as PNG bytes (see [`encode_png`]).
pub fn png_bytes(grid: &OccupancyGrid, trajectory: &[Pose2]) -> Result<Vec<u8>> {
    let mut out = Vec::new();
    encode_png(grid, trajectory, &mut out)?;
    Ok(out)
}

/// Writes `path` as PNG (atomically), streamed a row at a time.
pub fn write_png(grid: &OccupancyGrid, trajectory: &[Pose2], path: &Path) -> Result<()> {
    // Checked here too, before any file is made, so that a grid short of
    // cells is reported as such and not as a failed write.
    check_shape(grid)?;
    write_atomic_with(path, |out| match encode_png(grid, trajectory, out) {
        Err(Error::PngEncode(png::EncodingError::IoError(e))) => Err(e),
        other => other.map_err(std::io::Error::other),
    })
    .map_err(|source| Error::Write { path: path.to_path_buf(), source })
}

/// Image pixel (column, row from the top) of a world point, if inside.
fn image_pixel(grid: &OccupancyGrid, p: &Pose2) -> Option<(i64, i64)> {
    grid.cell_of(p.x, p.y).map(|(cx, cy)| (cx as i64, (grid.height - 1 - cy) as i64))
}

/// The image pixels (row, column) the trajectory's segments cross,
/// sorted, each once.
fn path_pixels(grid: &OccupancyGrid, trajectory: &[Pose2]) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    let mut put = |x: i64, y: i64| {
        if x >= 0 && y >= 0 && (x as usize) < grid.width && (y as usize) < grid.height {
            out.push((y as usize, x as usize));
        }
    };
    let pixels: Vec<Option<(i64, i64)>> = trajectory.iter().map(|p| image_pixel(grid, p)).collect();
    for w in pixels.windows(2) {
        if let (Some(a), Some(b)) = (w[0], w[1]) {
            line_cells(a, b, |(x, y)| put(x, y));
        }
    }
    if let Some(Some((x, y))) = pixels.first() {
        put(*x, *y);
    }
    out.sort_unstable();
    out.dedup();
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// 4 × 3 grid, 0.5 m cells: bottom row occupied, top-left free.
    fn grid() -> OccupancyGrid {
        let mut g = OccupancyGrid::unknown(4, 3, 0.5, (-1.0, 2.0));
        for x in 0..4 {
            g.set(x, 0, 100);
        }
        g.set(0, 2, 0);
        g.set(1, 2, 50);
        g
    }

    #[test]
    fn pgm_and_yaml_follow_map_server() {
        let dir = tempfile::tempdir().unwrap();
        write_pgm_yaml(&grid(), dir.path(), "map").unwrap();
        let pgm = std::fs::read(dir.path().join("map.pgm")).unwrap();
        let header_end = pgm.len() - 12;
        assert!(String::from_utf8_lossy(&pgm[..header_end]).ends_with("4 3\n255\n"));
        // Top image row = top map row (y = 2): free, unknown (50 %), unknown, unknown.
        assert_eq!(&pgm[header_end..], &[254, 205, 205, 205, 205, 205, 205, 205, 0, 0, 0, 0]);
        let yaml = std::fs::read_to_string(dir.path().join("map.yaml")).unwrap();
        assert!(yaml.contains("image: map.pgm\n") && yaml.contains("resolution: 0.5\n"), "{yaml}");
        assert!(yaml.contains("origin: [-1, 2, 0.0]\n"), "{yaml}");
    }

    #[test]
    fn a_grid_short_of_cells_is_an_error() {
        let mut g = grid();
        g.cells.truncate(11);
        let e = png_bytes(&g, &[]).unwrap_err();
        assert_eq!(e.to_string(), "an occupancy grid of 4 × 3 cells holds 11");
        let dir = tempfile::tempdir().unwrap();
        assert!(matches!(write_pgm_yaml(&g, dir.path(), "map"), Err(Error::GridShape { cells: 11, .. })));
        assert!(!dir.path().join("map.pgm").exists());
    }

    #[test]
    fn png_draws_the_trajectory_in_red() {
        let g = grid();
        let path = [Pose2::new(-0.9, 2.9, 0.0), Pose2::new(0.9, 2.9, 0.0)];
        let bytes = png_bytes(&g, &path).unwrap();
        let decoder = png::Decoder::new(std::io::Cursor::new(bytes));
        let mut reader = decoder.read_info().unwrap();
        let mut buf = vec![0; reader.output_buffer_size().unwrap()];
        let info = reader.next_frame(&mut buf).unwrap();
        assert_eq!((info.width, info.height, info.color_type), (4, 3, png::ColorType::Rgb));
        // World y = 2.9 is map row 1, image row 1; x from −0.9 to 0.9 spans columns 0..=3.
        for x in 0..4 {
            assert_eq!(&buf[3 * (4 + x)..3 * (4 + x) + 3], &[220, 20, 20], "column {x}");
        }
        assert_eq!(&buf[3 * 8..3 * 8 + 3], &[0, 0, 0], "the bottom row is a wall");
    }
}
