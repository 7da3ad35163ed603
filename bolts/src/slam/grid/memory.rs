//! What grids' tiles cost: the tiles a grid adds to others, and the
//! distinct tiles over many grids (shared tiles counted once).

use std::sync::Arc;

use super::TiledGrid;
use super::tile::Tile;

/// Hashes tile addresses for [`TiledGrid::distinct_tiles`], which runs
/// every reading over every particle's tiles: an address is unique already,
/// so a multiplication and a fold spread it (with SipHash, the default,
/// hashing took about 4% of a whole ACES run, `perf`; with this, 1.8%).
#[derive(Debug, Default)]
struct AddressHasher(u64);

impl std::hash::Hasher for AddressHasher {
    fn finish(&self) -> u64 {
        self.0 ^ (self.0 >> 29)
    }

    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.write_usize(b as usize ^ self.0 as usize);
        }
    }

    fn write_usize(&mut self, n: usize) {
        self.0 = (n as u64).wrapping_mul(squall_topology::hash::GOLDEN_GAMMA);
    }
}

type BuildAddressHasher = std::hash::BuildHasherDefault<AddressHasher>;

impl TiledGrid {
    /// Tiles cloned by copy-on-write since the last call.
    pub fn take_clone_count(&mut self) -> u64 {
        std::mem::take(&mut self.clones)
    }

    /// Tiles this grid holds (shared or not).
    pub fn tile_count(&self) -> usize {
        self.tiles.iter().filter(|t| t.is_some()).count()
    }

    /// Bytes of the tiles this grid holds (shared or not).
    pub fn bytes(&self) -> usize {
        self.tiles.iter().flatten().map(|t| t.bytes()).sum()
    }

    /// Tiles of this grid that none of `others` holds in the same place:
    /// what it adds to them when it is their copy or they are its (a copy
    /// keeps each shared tile in its place). Unlike
    /// [`Self::distinct_tiles`], no hashing: cheap enough per particle.
    fn tiles_beyond<'a>(&'a self, others: &'a [&TiledGrid]) -> impl Iterator<Item = &'a Tile> + 'a {
        let held_by = |o: &TiledGrid, key: (i64, i64), tile: &Arc<Tile>| {
            o.slot(key).and_then(|i| o.tiles[i].as_ref()).is_some_and(|t| Arc::ptr_eq(t, tile))
        };
        self.tiles.iter().enumerate().filter_map(move |(slot, tile)| {
            let tile = tile.as_ref()?;
            let key = (
                self.tile_min.0 + (slot % self.tiles_wide) as i64,
                self.tile_min.1 + (slot / self.tiles_wide) as i64,
            );
            (!others.iter().any(|o| held_by(o, key, tile))).then_some(&**tile)
        })
    }

    /// How many tiles [`Self::tiles_beyond`] `others`.
    pub fn count_beyond(&self, others: &[&TiledGrid]) -> usize {
        self.tiles_beyond(others).count()
    }

    /// The bytes of the tiles [`Self::tiles_beyond`] `others`.
    pub fn bytes_beyond(&self, others: &[&TiledGrid]) -> usize {
        self.tiles_beyond(others).map(Tile::bytes).sum()
    }

    /// Distinct tiles over several grids (shared tiles counted once), and
    /// their bytes: the memory the maps really take.
    ///
    /// Runs every reading over every particle's map and snapshots, which
    /// share most tiles, each in its place (a copy keeps a shared tile
    /// where it was). So a tile that is one of the last [`REMEMBERED`]
    /// seen in its place was counted already and skips the hash set
    /// (half the hashing of a whole ACES run, callgrind). The count is
    /// exact either way: a tile held in two places, as a transfer between
    /// processes may leave one, is hashed in both and counted once.
    pub fn distinct_tiles<'a>(grids: impl IntoIterator<Item = &'a TiledGrid>) -> (usize, usize) {
        let grids: Vec<&TiledGrid> = grids.into_iter().filter(|g| !g.tiles.is_empty()).collect();
        let mut seen = std::collections::HashSet::<_, BuildAddressHasher>::default();
        let mut bytes = 0;
        let mut count = |tile: &Arc<Tile>| {
            if seen.insert(Arc::as_ptr(tile)) {
                bytes += tile.bytes();
            }
        };
        match Places::spanning(&grids) {
            Some(places) => {
                let mut last = vec![[std::ptr::null::<Tile>(); REMEMBERED]; places.wide * places.high];
                for g in &grids {
                    for (row, tiles) in g.tiles.chunks_exact(g.tiles_wide).enumerate() {
                        let start = places.row_start(g, row);
                        for (place, tile) in last[start..start + g.tiles_wide].iter_mut().zip(tiles) {
                            let Some(tile) = tile else { continue };
                            if !place.contains(&Arc::as_ptr(tile)) {
                                place.rotate_right(1);
                                place[0] = Arc::as_ptr(tile);
                                count(tile);
                            }
                        }
                    }
                }
            }
            None => grids.iter().flat_map(|g| g.tiles.iter().flatten()).for_each(&mut count),
        }
        (seen.len(), bytes)
    }
}

/// Tiles [`TiledGrid::distinct_tiles`] remembers per place: a particle's
/// map and its two snapshots, and one more.
const REMEMBERED: usize = 4;

/// The tile places (keys) spanned by several grids' indices, as one dense
/// row-major box.
struct Places {
    min: (i64, i64),
    wide: usize,
    high: usize,
}

impl Places {
    /// The box spanning every grid's index; `None` if it would hold many
    /// more places than the indices together (grids far apart), where a
    /// box is not worth its memory.
    fn spanning(grids: &[&TiledGrid]) -> Option<Places> {
        let first = grids.first()?;
        let (mut min, mut max) = (first.tile_min, first.tile_min);
        let mut slots = 0usize;
        for g in grids {
            let last = (g.tile_min.0 + g.tiles_wide as i64 - 1, g.tile_min.1 + g.tiles_high as i64 - 1);
            min = (min.0.min(g.tile_min.0), min.1.min(g.tile_min.1));
            max = (max.0.max(last.0), max.1.max(last.1));
            slots = slots.saturating_add(g.tiles.len());
        }
        let side = |lo: i64, hi: i64| usize::try_from(hi.checked_sub(lo)?.checked_add(1)?).ok();
        let (wide, high) = (side(min.0, max.0)?, side(min.1, max.1)?);
        wide.checked_mul(high).filter(|&area| area <= slots.saturating_mul(2)).map(|_| Places {
            min,
            wide,
            high,
        })
    }

    /// The box index of the first place of row `row` of `g`'s index.
    fn row_start(&self, g: &TiledGrid, row: usize) -> usize {
        let (x, y) = (g.tile_min.0 - self.min.0, g.tile_min.1 - self.min.1 + row as i64);
        y as usize * self.wide + x as usize
    }
}
