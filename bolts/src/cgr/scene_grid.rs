//! Observable scenes precomputed on a grid (thesis §4.2.2, Fig. 6.4): for
//! every cell, the walls visible from its centre (and, next to a wall,
//! from its neighbours' centres); localization then looks
//! the scene up instead of ray casting per particle. Built in parallel and
//! cached to a file named by a hash of the map and the grid settings.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use squall_core::geometry::Real;
use squall_core::linemap::LineMap;
use squall_core::visibility::{distance_to_segment, observable_scene};
use squall_topology::hash::Fnv1a;

/// Bumped whenever the file layout or the scene algorithm changes.
const FORMAT: u64 = 3;

pub use crate::error::SceneCacheError;

/// Visible walls for every cell of a grid over the map.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SceneGrid {
    key: u64,
    origin: (Real, Real),
    cell: Real,
    range: Real,
    width: usize,
    height: usize,
    /// Cell i's walls are `lines[offsets[i]..offsets[i + 1]]`.
    offsets: Vec<u32>,
    lines: Vec<u32>,
}

impl SceneGrid {
    /// The grid's width and height in cells over `map` at `cell` metres,
    /// and the bytes building it takes before any wall is listed: a
    /// scene list header per cell while the rows are computed, and an
    /// offset per cell. (The walls listed add to that; near walls, the
    /// 3 × 3 unions several times a cell's own.) Sizes saturate rather
    /// than overflow, for any map.
    pub fn size_before_scenes(map: &LineMap, cell: Real) -> (usize, usize, f64) {
        let (x0, y0, x1, y1) = map.bounds();
        // `as` saturates: an extent of 1e300 cells is usize::MAX.
        let width = (((x1 - x0) / cell).ceil() as usize).max(1);
        let height = (((y1 - y0) / cell).ceil() as usize).max(1);
        let per_cell = (std::mem::size_of::<Vec<u32>>() + std::mem::size_of::<u32>()) as f64;
        (width, height, width as f64 * height as f64 * per_cell)
    }

    /// Computes the scene at every cell centre of a `cell`-metre grid over
    /// the map's bounding box, walls up to `range` metres, on `threads`
    /// threads; a cell within 1.5 cells of a wall keeps the union of its
    /// 3 × 3 block's scenes.
    /// An error if `cell` or `range` is not a positive number of metres.
    pub fn build(map: &LineMap, cell: Real, range: Real, threads: usize) -> crate::Result<Self> {
        crate::error::positive("cell", cell)?;
        crate::error::positive("range", range)?;
        let (width, height, _) = Self::size_before_scenes(map, cell);
        if width.saturating_mul(height) >= u32::MAX as usize {
            return Err(crate::Error::Setting(format!(
                "a scene grid of {width} × {height} cells of {cell} m has more cells than its index \
                 counts (2³²): raise cell"
            )));
        }
        let (x0, y0, _, _) = map.bounds();
        let threads = threads.clamp(1, height);
        let rows_per = height.div_ceil(threads);
        let centre_of = |i: usize, j: usize| (x0 + (i as Real + 0.5) * cell, y0 + (j as Real + 0.5) * cell);
        // A signal during the build (seconds on a large map) ends it: the
        // rows left are not computed and the build is an error.
        let stop = squall_topology::runtime::process_stop();
        let row_scenes = |rows: std::ops::Range<usize>| -> Vec<Vec<u32>> {
            let mut out = Vec::with_capacity(rows.len() * width);
            for j in rows {
                if stop.is_made() {
                    break;
                }
                for i in 0..width {
                    let mut ids: Vec<u32> =
                        observable_scene(map, centre_of(i, j), range).iter().map(|v| v.line).collect();
                    ids.sort_unstable();
                    ids.dedup();
                    out.push(ids);
                }
            }
            out
        };
        let chunks: Vec<Vec<Vec<u32>>> = std::thread::scope(|s| {
            let handles: Vec<_> = (0..threads)
                .map(|t| {
                    let rows = (t * rows_per).min(height)..((t + 1) * rows_per).min(height);
                    s.spawn(move || row_scenes(rows))
                })
                .collect();
            handles.into_iter().map(|h| h.join().expect("a scene thread panicked")).collect()
        });
        let centres: Vec<Vec<u32>> = chunks.into_iter().flatten().collect();
        if centres.len() < width * height {
            return Err(crate::Error::Setting(
                "stopped (Ctrl-C or SIGTERM) while observable scenes were built".into(),
            ));
        }
        // A cell next to a wall keeps what its own and its eight
        // neighbours' centres see: a robot beside a door jamb, whose cell
        // centre lies across the wall, still finds the walls of its own
        // room. Walls a neighbour sees behind an occluder cost a little
        // time, not accuracy (a point matches the first wall its ray
        // meets); cells in the open keep their own scene.
        let near = 1.5 * cell;
        let mut offsets = Vec::with_capacity(width * height + 1);
        let mut lines = Vec::new();
        let mut ids = Vec::new();
        offsets.push(0);
        for j in 0..height {
            for i in 0..width {
                ids.clear();
                let own = &centres[j * width + i];
                let centre = centre_of(i, j);
                let by_a_wall = own.iter().any(|&l| {
                    let w = &map.walls[l as usize];
                    distance_to_segment(centre, w.a, w.b) < near
                });
                if !by_a_wall {
                    lines.extend_from_slice(own);
                    offsets.push(offset(lines.len())?);
                    continue;
                }
                for nj in j.saturating_sub(1)..(j + 2).min(height) {
                    for ni in i.saturating_sub(1)..(i + 2).min(width) {
                        ids.extend_from_slice(&centres[nj * width + ni]);
                    }
                }
                ids.sort_unstable();
                ids.dedup();
                lines.extend_from_slice(&ids);
                offsets.push(offset(lines.len())?);
            }
        }
        Ok(SceneGrid {
            key: Self::key(map, cell, range),
            origin: (x0, y0),
            cell,
            range,
            width,
            height,
            offsets,
            lines,
        })
    }

    /// A hash of the map and the grid settings, stable across runs and
    /// builds (FNV-1a over the numbers' bits).
    pub fn key(map: &LineMap, cell: Real, range: Real) -> u64 {
        let mut h = Fnv1a::new();
        h.write_u64(FORMAT);
        h.write_u64(cell.to_bits());
        h.write_u64(range.to_bits());
        for w in &map.walls {
            for v in [w.a.0, w.a.1, w.b.0, w.b.1] {
                h.write_u64(v.to_bits());
            }
        }
        h.value()
    }

    /// The cache file for these settings in `dir`.
    pub fn cache_path(dir: &Path, map: &LineMap, cell: Real, range: Real) -> PathBuf {
        dir.join(format!("scenes-{:016x}.bin", Self::key(map, cell, range)))
    }

    /// The grid from the cache in `dir` if it holds one for this map and
    /// these settings (a damaged or stale file is rebuilt), else built and
    /// written there (atomically). Returns whether it was built.
    pub fn load_or_build(
        map: &LineMap,
        cell: Real,
        range: Real,
        threads: usize,
        dir: &Path,
    ) -> crate::Result<(Self, bool)> {
        let path = Self::cache_path(dir, map, cell, range);
        if let Ok(bytes) = std::fs::read(&path) {
            if let Ok(grid) = postcard::from_bytes::<SceneGrid>(&bytes)
                && grid.key == Self::key(map, cell, range)
                && grid.offsets.len() == grid.width * grid.height + 1
            {
                return Ok((grid, false));
            }
            tracing::warn!("{}: not a usable scene cache; rebuilding it", path.display());
        }
        let grid = Self::build(map, cell, range, threads)?;
        let bytes = postcard::to_allocvec(&grid).expect("a scene grid serializes");
        let io = |source| SceneCacheError::Io { path: path.clone(), source };
        std::fs::create_dir_all(dir).map_err(io)?;
        squall_topology::fsio::write_atomic(&path, &bytes).map_err(io)?;
        Ok((grid, true))
    }

    /// The walls visible from the cell containing (`x`, `y`); `None`
    /// outside the grid.
    pub fn lines_at(&self, x: Real, y: Real) -> Option<&[u32]> {
        let i = ((x - self.origin.0) / self.cell).floor();
        let j = ((y - self.origin.1) / self.cell).floor();
        if i < 0.0 || j < 0.0 || i >= self.width as Real || j >= self.height as Real {
            return None;
        }
        let c = j as usize * self.width + i as usize;
        Some(&self.lines[self.offsets[c] as usize..self.offsets[c + 1] as usize])
    }

    /// Cells wide and high.
    pub fn size(&self) -> (usize, usize) {
        (self.width, self.height)
    }

    /// Wall ids stored in all (the grid's memory is about 4 bytes each).
    pub fn entries(&self) -> usize {
        self.lines.len()
    }
}

/// The offset of a cell's list in the wall ids, which the grid stores as
/// `u32`: an error past 2³² ids (hundreds of millions of cells, each
/// seeing many walls) rather than a wrapped index.
fn offset(len: usize) -> crate::Result<u32> {
    u32::try_from(len).map_err(|_| {
        crate::Error::Setting(format!(
            "the scene grid lists {len} wall ids, past the 2³² its index counts: raise cell"
        ))
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn room() -> LineMap {
        LineMap::parse("room", "0,0,10,0\n10,0,10,10\n10,10,0,10\n0,10,0,0\n4,6,6,6\n").unwrap()
    }

    #[test]
    fn the_grid_holds_each_cells_scene() {
        let map = room();
        let grid = SceneGrid::build(&map, 0.5, 20.0, 2).unwrap();
        assert_eq!(grid.size(), (20, 20));
        // Cells in the open keep their centre's scene; the last, in a
        // corner, is by a wall and keeps its 3 × 3 block's.
        for (x, y, by_a_wall) in [(5.0, 2.0, false), (1.2, 8.7, false), (5.1, 8.0, false), (9.9, 0.1, true)] {
            let (i, j) = ((x / 0.5_f64).floor() as i64, (y / 0.5_f64).floor() as i64);
            let mut want: Vec<u32> = Vec::new();
            let reach = i64::from(by_a_wall);
            for (ni, nj) in
                (i - reach..=i + reach).flat_map(|ni| (j - reach..=j + reach).map(move |nj| (ni, nj)))
            {
                if (0..20).contains(&ni) && (0..20).contains(&nj) {
                    let centre = ((ni as Real + 0.5) * 0.5, (nj as Real + 0.5) * 0.5);
                    want.extend(observable_scene(&map, centre, 20.0).iter().map(|v| v.line));
                }
            }
            want.sort_unstable();
            want.dedup();
            assert_eq!(grid.lines_at(x, y).unwrap(), &want[..], "at ({x}, {y})");
        }
        // Above the pillar the bottom wall is partly hidden but visible;
        // every wall is seen from somewhere.
        assert_eq!(grid.lines_at(5.0, 8.0).unwrap(), &[0, 1, 2, 3, 4]);
        assert_eq!(grid.lines_at(-1.0, 5.0), None);
        assert_eq!(SceneGrid::build(&map, 0.5, 20.0, 1).unwrap(), grid, "threads do not change the grid");
    }

    #[test]
    fn a_robot_in_a_doorway_beside_its_cell_centre_sees_its_own_room() {
        // Two rooms, the wall between them at x = 5.2 with a door from
        // y = 4 to 6.
        let map = LineMap::parse(
            "rooms",
            "0,0,10,0\n10,0,10,10\n10,10,0,10\n0,10,0,0\n5.2,0,5.2,4\n5.2,6,5.2,10\n",
        )
        .unwrap();
        let grid = SceneGrid::build(&map, 0.5, 20.0, 2).unwrap();
        // At (5.1, 3.9), left of the wall beside the jamb, the cell's
        // centre (5.25, 3.75) is right of the wall, in the other room; the
        // left room's far wall (x = 0) must still be in the scene.
        let centre_only: Vec<u32> =
            observable_scene(&map, (5.25, 3.75), 20.0).iter().map(|v| v.line).collect();
        assert!(!centre_only.contains(&3), "the case arises: {centre_only:?}");
        let seen = grid.lines_at(5.1, 3.9).unwrap();
        assert!(seen.contains(&3) && seen.contains(&1), "both rooms' far walls: {seen:?}");
    }

    #[test]
    fn the_cache_is_written_once_and_keyed_by_the_map() {
        let dir = tempfile::tempdir().unwrap();
        let map = room();
        let (built, fresh) = SceneGrid::load_or_build(&map, 1.0, 8.0, 2, dir.path()).unwrap();
        assert!(fresh);
        let (loaded, fresh) = SceneGrid::load_or_build(&map, 1.0, 8.0, 2, dir.path()).unwrap();
        assert!(!fresh && loaded == built);
        let mut moved = map.clone();
        moved.walls[4].a.0 = 3.0;
        assert_ne!(SceneGrid::key(&moved, 1.0, 8.0), SceneGrid::key(&map, 1.0, 8.0));
        let path = SceneGrid::cache_path(dir.path(), &map, 1.0, 8.0);
        std::fs::write(&path, b"garbage").unwrap();
        let (rebuilt, fresh) = SceneGrid::load_or_build(&map, 1.0, 8.0, 2, dir.path()).unwrap();
        assert!(fresh && rebuilt == built, "a damaged cache is rebuilt");
    }
}
