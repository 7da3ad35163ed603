//! Map files a robotics user can open: PGM + YAML in the ROS `map_server`
//! convention, and PNG (optionally with the trajectory drawn on it).
//!
//! Pixel values follow `map_saver`: occupied (≥ 65 %) black 0, free
//! (≤ 25 %) white 254, unknown grey 205. Image row 0 is the top of the map.

use std::path::Path;

use squall_topology::fsio::write_atomic;

use crate::geometry::{Pose2, line_cells};
use crate::occupancy::{OccupancyGrid, UNKNOWN};
use crate::{Error, Result};

/// Occupancy (percent) at or above which a cell is drawn occupied.
pub const OCCUPIED_PERCENT: i8 = 65;
/// Occupancy (percent) at or below which a cell is drawn free.
pub const FREE_PERCENT: i8 = 25;

fn pixel(value: i8) -> u8 {
    match value {
        UNKNOWN => 205,
        v if v >= OCCUPIED_PERCENT => 0,
        v if v <= FREE_PERCENT => 254,
        _ => 205,
    }
}

/// Grey pixels, top row first. An error if the grid holds fewer cells
/// than its width × height.
pub fn grey_pixels(grid: &OccupancyGrid) -> Result<Vec<u8>> {
    let Some(size) = grid.width.checked_mul(grid.height).filter(|&n| n <= grid.cells.len()) else {
        return Err(Error::GridShape { width: grid.width, height: grid.height, cells: grid.cells.len() });
    };
    let mut out = Vec::with_capacity(size);
    for row in (0..grid.height).rev() {
        out.extend(grid.cells[row * grid.width..(row + 1) * grid.width].iter().map(|&v| pixel(v)));
    }
    Ok(out)
}

/// Writes `DIR/STEM.pgm` and `DIR/STEM.yaml` (atomically).
pub fn write_pgm_yaml(grid: &OccupancyGrid, dir: &Path, stem: &str) -> Result<()> {
    let mut pgm = format!(
        "P5\n# squall occupancy map, {} m/cell\n{} {}\n255\n",
        grid.resolution, grid.width, grid.height
    )
    .into_bytes();
    pgm.extend(grey_pixels(grid)?);
    write_file(&dir.join(format!("{stem}.pgm")), &pgm)?;
    let yaml = format!(
        "image: {stem}.pgm\nmode: trinary\nresolution: {}\norigin: [{}, {}, 0.0]\nnegate: 0\noccupied_thresh: {}\nfree_thresh: {}\n",
        grid.resolution,
        grid.origin.0,
        grid.origin.1,
        f64::from(OCCUPIED_PERCENT) / 100.0,
        f64::from(FREE_PERCENT) / 100.0,
    );
    write_file(&dir.join(format!("{stem}.yaml")), yaml.as_bytes())
}

/// Writes `bytes` to `path` atomically; an error names the file.
fn write_file(path: &Path, bytes: &[u8]) -> Result<()> {
    write_atomic(path, bytes).map_err(|source| Error::Write { path: path.to_path_buf(), source })
}

/// Encodes the map as PNG; with a trajectory, as RGB with the path drawn
/// in red.
pub fn png_bytes(grid: &OccupancyGrid, trajectory: &[Pose2]) -> Result<Vec<u8>> {
    let grey = grey_pixels(grid)?;
    let (w, h) = (grid.width as u32, grid.height as u32);
    let mut out = Vec::new();
    {
        let mut encoder = png::Encoder::new(&mut out, w, h);
        encoder.set_depth(png::BitDepth::Eight);
        if trajectory.is_empty() {
            encoder.set_color(png::ColorType::Grayscale);
            encoder.write_header()?.write_image_data(&grey)?;
        } else {
            encoder.set_color(png::ColorType::Rgb);
            let mut rgb: Vec<u8> = grey.iter().flat_map(|&g| [g, g, g]).collect();
            draw_path(grid, trajectory, &mut rgb);
            encoder.write_header()?.write_image_data(&rgb)?;
        }
    }
    Ok(out)
}

/// Writes `path` as PNG (atomically).
pub fn write_png(grid: &OccupancyGrid, trajectory: &[Pose2], path: &Path) -> Result<()> {
    let bytes = png_bytes(grid, trajectory)?;
    write_file(path, &bytes)
}

/// Image pixel (column, row from the top) of a world point, if inside.
fn image_pixel(grid: &OccupancyGrid, p: &Pose2) -> Option<(i64, i64)> {
    grid.cell_of(p.x, p.y).map(|(cx, cy)| (cx as i64, (grid.height - 1 - cy) as i64))
}

fn draw_path(grid: &OccupancyGrid, trajectory: &[Pose2], rgb: &mut [u8]) {
    let mut put = |x: i64, y: i64| {
        if x >= 0 && y >= 0 && (x as usize) < grid.width && (y as usize) < grid.height {
            let i = 3 * (y as usize * grid.width + x as usize);
            rgb[i..i + 3].copy_from_slice(&[220, 20, 20]);
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
