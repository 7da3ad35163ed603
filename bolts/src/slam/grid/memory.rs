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
    pub fn distinct_tiles<'a>(grids: impl IntoIterator<Item = &'a TiledGrid>) -> (usize, usize) {
        let mut seen = std::collections::HashSet::<_, BuildAddressHasher>::default();
        let mut bytes = 0;
        for g in grids {
            for t in g.tiles.iter().flatten() {
                if seen.insert(Arc::as_ptr(t)) {
                    bytes += t.bytes();
                }
            }
        }
        (seen.len(), bytes)
    }
}
