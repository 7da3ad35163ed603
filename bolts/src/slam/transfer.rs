//! Moving maps between processes without resending what the receiver
//! holds: tiles are addressed by their content's digest, the sender
//! remembers which digests each receiver has, and a packed map carries
//! only the tiles the receiver lacks, referring to the rest. Particles
//! resampled from one parent share most of their tiles, and a map sent
//! again after a reading differs only in the tiles the reading touched.
//!
//! Both records are bounded the same way: after each message (a
//! [`Sent::end_message`] on one side, [`TileStore::end_message`] on the
//! other), tiles not referred to in the last [`KEEP_MESSAGES`] messages are
//! forgotten. Messages between one sender and one receiver arrive in
//! order, so both sides forget the same tiles at the same message.

use std::collections::HashMap;
use std::sync::Arc;

use serde::{Deserialize, Serialize};

use crate::slam::grid::{GridWire, Tile, TiledGrid};

/// A tile in a packed map.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub(crate) enum PackedTile {
    /// No tile here.
    Empty,
    /// A tile the receiver holds, by digest.
    Held(u128),
    /// A tile sent whole.
    Whole(Arc<Tile>),
}

/// A map as sent to one receiver.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(transparent)]
pub struct PackedGrid(GridWire<PackedTile>);

impl PackedGrid {
    /// Tiles sent whole.
    pub fn whole_tiles(&self) -> usize {
        self.0.tiles.iter().filter(|t| matches!(t, PackedTile::Whole(_))).count()
    }

    /// Tiles sent by reference.
    pub fn held_tiles(&self) -> usize {
        self.0.tiles.iter().filter(|t| matches!(t, PackedTile::Held(_))).count()
    }
}

/// Why a packed map could not be unpacked.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum UnpackError {
    /// It refers to a tile this store does not hold (evicted, or the
    /// sender's record is wrong): ask for the map again, whole.
    #[error("the map refers to tile {0:032x}, which is not held here")]
    MissingTile(u128),
    /// The map is damaged.
    #[error("damaged map: {0}")]
    Invalid(#[from] crate::slam::grid::GridWireError),
}

/// Messages a tile is remembered for after it was last referred to.
pub(crate) const KEEP_MESSAGES: u64 = 4;

/// What a sender knows one receiver holds: each digest with the message
/// that last referred to it.
#[derive(Debug, Default)]
pub struct Sent {
    held: HashMap<u128, u64>,
    message: u64,
}

impl Sent {
    /// Forgets everything (the receiver restarted or lost its store).
    pub fn forget(&mut self) {
        self.held.clear();
    }

    /// Ends a message: forgets the tiles the receiver forgets now.
    pub fn end_message(&mut self) {
        self.message += 1;
        let message = self.message;
        self.held.retain(|_, last| *last + KEEP_MESSAGES > message);
    }

    /// Tiles remembered.
    pub fn len(&self) -> usize {
        self.held.len()
    }

    /// Whether no tile is remembered.
    pub fn is_empty(&self) -> bool {
        self.held.is_empty()
    }
}

/// Packs `grid` for the receiver that `sent` describes, and records the
/// tiles it will hold.
pub(crate) fn pack(grid: &TiledGrid, sent: &mut Sent) -> PackedGrid {
    let message = sent.message;
    PackedGrid(GridWire::from(grid.clone()).map_tiles(|tile| match tile {
        None => PackedTile::Empty,
        Some(tile) => {
            let digest = tile.digest();
            match sent.held.insert(digest, message) {
                None => PackedTile::Whole(tile),
                Some(_) => PackedTile::Held(digest),
            }
        }
    }))
}

/// The tiles a receiver holds from one sender, by digest, each with the
/// message that last referred to it.
#[derive(Debug, Default)]
pub struct TileStore {
    tiles: HashMap<u128, (Arc<Tile>, u64)>,
    message: u64,
}

impl TileStore {
    /// Tiles held.
    pub fn len(&self) -> usize {
        self.tiles.len()
    }

    /// Whether no tile is held.
    pub fn is_empty(&self) -> bool {
        self.tiles.is_empty()
    }

    /// Ends a message: forgets what the sender forgets now.
    pub fn end_message(&mut self) {
        self.message += 1;
        let message = self.message;
        self.tiles.retain(|_, (_, last)| *last + KEEP_MESSAGES > message);
    }

    /// The map back from its packed form, keeping the tiles it brought.
    pub fn unpack(&mut self, packed: PackedGrid) -> Result<TiledGrid, UnpackError> {
        let message = self.message;
        let wire = packed.0.try_map_tiles(|tile| match tile {
            PackedTile::Empty => Ok::<_, UnpackError>(None),
            PackedTile::Held(digest) => {
                let (tile, last) = self.tiles.get_mut(&digest).ok_or(UnpackError::MissingTile(digest))?;
                *last = message;
                Ok(Some(tile.clone()))
            }
            PackedTile::Whole(tile) => {
                let entry = self.tiles.entry(tile.digest()).or_insert((tile, message));
                entry.1 = message;
                Ok(Some(entry.0.clone()))
            }
        })?;
        TiledGrid::try_from(wire).map_err(UnpackError::Invalid)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A corridor 8 m long mapped with a wall on each side.
    fn corridor() -> TiledGrid {
        let mut g = TiledGrid::new(0.05, (0.0, 0.0)).unwrap();
        for x in 0..160 {
            for y in [-20, 20] {
                g.update((x, y), |c| c.add_hit(x as f32 * 0.05, y as f32 * 0.05));
            }
            for y in -19..20 {
                g.update((x, y), |c| c.visits += 1);
            }
        }
        g
    }

    fn same_cells(a: &TiledGrid, b: &TiledGrid) -> bool {
        (-5..170).all(|x| (-25..25).all(|y| a.get((x, y)) == b.get((x, y))))
    }

    fn bytes(p: &PackedGrid) -> usize {
        postcard::to_stdvec(p).unwrap().len()
    }

    #[test]
    fn a_map_sent_again_carries_only_the_tiles_that_changed() {
        let (mut sent, mut store) = (Sent::default(), TileStore::default());
        let mut map = corridor();
        let first = pack(&map, &mut sent);
        let tiles = first.whole_tiles();
        assert!(tiles >= 10, "{tiles} tiles");
        let first_bytes = bytes(&first);
        let received = store.unpack(first).unwrap();
        assert!(same_cells(&received, &map));
        // A reading touches one tile; a copy (a resampled sibling) shares all.
        map.update((3, 3), |c| c.add_hit(0.15, 0.15));
        let sibling = map.clone();
        let second = pack(&map, &mut sent);
        assert_eq!((second.whole_tiles(), second.held_tiles()), (1, tiles - 1));
        let third = pack(&sibling, &mut sent);
        assert_eq!((third.whole_tiles(), third.held_tiles()), (0, tiles));
        assert!(bytes(&second) * 5 < first_bytes, "{} vs {first_bytes} bytes", bytes(&second));
        eprintln!(
            "{tiles} tiles: {first_bytes} bytes whole, {} after one tile changed, {} for a sibling",
            bytes(&second),
            bytes(&third)
        );
        let (again, sibling_again) = (store.unpack(second).unwrap(), store.unpack(third).unwrap());
        assert!(same_cells(&again, &map) && same_cells(&sibling_again, &sibling));
        assert_eq!(store.len(), tiles + 1);
    }

    #[test]
    fn a_write_changes_the_digest_and_unknown_references_are_refused() {
        let mut map = corridor();
        let mut sent = Sent::default();
        let before = pack(&map, &mut sent);
        map.update((3, 3), |c| c.visits += 1);
        let after = pack(&map, &mut sent);
        assert_eq!(after.whole_tiles(), 1, "the written tile has a new digest");
        // A receiver that never got the first map cannot resolve the second.
        let mut fresh = TileStore::default();
        assert!(matches!(fresh.unpack(after), Err(UnpackError::MissingTile(_))));
        // A damaged whole tile is refused like any damaged map.
        let mut damaged = before;
        let tile = damaged.0.tiles.iter_mut().find_map(|t| match t {
            PackedTile::Whole(t) => Some(t),
            _ => None,
        });
        let mut broken: Tile = postcard::from_bytes(&postcard::to_stdvec(&**tile.unwrap()).unwrap()).unwrap();
        let mut wire: serde_json::Value = serde_json::to_value(&broken).unwrap();
        wire["walls"][0] = serde_json::json!(u32::MAX);
        broken = serde_json::from_value(wire).unwrap();
        *damaged.0.tiles.iter_mut().find(|t| matches!(t, PackedTile::Whole(_))).unwrap() =
            PackedTile::Whole(Arc::new(broken));
        assert!(matches!(TileStore::default().unpack(damaged), Err(UnpackError::Invalid(_))));
    }

    #[test]
    fn sender_and_receiver_forget_the_same_tiles_at_the_same_message() {
        let (mut sent, mut store) = (Sent::default(), TileStore::default());
        let map = corridor();
        let mut other = TiledGrid::new(0.05, (0.0, 0.0)).unwrap();
        other.update((500, 500), |c| c.add_hit(25.0, 25.0));
        let first = pack(&map, &mut sent);
        let tiles = first.whole_tiles();
        store.unpack(first).unwrap();
        sent.end_message();
        store.end_message();
        // Messages that do not refer to the corridor's tiles: after
        // KEEP_MESSAGES of them both sides have let them go.
        for _ in 0..KEEP_MESSAGES {
            store.unpack(pack(&other, &mut sent)).unwrap();
            sent.end_message();
            store.end_message();
        }
        assert_eq!((sent.len(), store.len()), (1, 1), "only the other map's tile is kept");
        let again = pack(&map, &mut sent);
        assert_eq!(again.whole_tiles(), tiles, "forgotten tiles are sent whole again");
        assert!(same_cells(&store.unpack(again).unwrap(), &map));
    }
}
