//! SLAM particles cross processes with their maps packed by tile: a
//! transfer carries whole only the tiles the receiving task does not
//! already hold from the sending one (see [`crate::slam::transfer`]).
//! Within one process transfers share the maps' tiles, as always.

use std::sync::Arc;

use serde::{Deserialize, Serialize};
use squall_core::geometry::Pose2;
use squall_core::motion::{MotionSpread, TurnErrorEstimate};
use squall_core::sensor::LaserReading;
use squall_topology::{CodecError, Incremental};

use crate::pf::kinds::messages::{Reading, Transfer};
use crate::slam::model::SlamParticle;
use crate::slam::old_map::MapHistory;
use crate::slam::transfer::{PackedGrid, Sent, TileStore, UnpackError, pack};

/// A transfer as it crosses: each state's pose, packed map and packed
/// snapshots.
#[derive(Debug, Serialize, Deserialize)]
struct PackedTransfer {
    step: u64,
    states: Vec<PackedParticle>,
    reading: Option<Arc<Reading<LaserReading>>>,
}

/// One particle as it crosses: its grids packed in the order map, recent
/// snapshot, old snapshot (a snapshot's tiles shared with the map travel
/// once).
#[derive(Debug, Serialize, Deserialize)]
struct PackedParticle {
    slot: u32,
    pose: Pose2,
    estimate: Pose2,
    map: PackedGrid,
    updates: u64,
    recent: Option<PackedGrid>,
    old: Option<PackedGrid>,
    spread: MotionSpread,
    turns: TurnErrorEstimate,
}

impl PackedParticle {
    fn pack(slot: u32, p: &SlamParticle, sent: &mut Sent) -> Self {
        let map = pack(&p.map, sent);
        let recent = p.history.recent.as_ref().map(|g| pack(g, sent));
        let old = p.history.old.as_ref().map(|g| pack(g, sent));
        PackedParticle {
            slot,
            pose: p.pose,
            estimate: p.estimate,
            map,
            updates: p.history.updates,
            recent,
            old,
            spread: p.spread,
            turns: p.turns,
        }
    }

    fn unpack(self, held: &mut TileStore) -> Result<(u32, SlamParticle), UnpackError> {
        let map = held.unpack(self.map)?;
        let recent = self.recent.map(|g| held.unpack(g)).transpose()?;
        let old = self.old.map(|g| held.unpack(g)).transpose()?;
        let history = MapHistory { updates: self.updates, recent, old };
        Ok((
            self.slot,
            SlamParticle {
                pose: self.pose,
                estimate: self.estimate,
                map,
                history,
                spread: self.spread,
                turns: self.turns,
            },
        ))
    }
}

impl Incremental for Transfer<SlamParticle, LaserReading> {
    type Sent = Sent;
    type Held = TileStore;

    fn encode_incremental(&self, sent: &mut Sent) -> Result<Vec<u8>, CodecError> {
        let states = self.states.iter().map(|(slot, p)| PackedParticle::pack(*slot, p, sent)).collect();
        sent.end_message();
        let packed = PackedTransfer { step: self.step, states, reading: self.reading.clone() };
        postcard::to_stdvec(&packed).map_err(CodecError::new)
    }

    fn decode_incremental(bytes: &[u8], held: &mut TileStore) -> Result<Self, CodecError> {
        let packed: PackedTransfer = postcard::from_bytes(bytes).map_err(CodecError::new)?;
        let states =
            packed.states.into_iter().map(|p| p.unpack(held)).collect::<Result<Vec<_>, UnpackError>>();
        // The sender ended its message whatever it held; so does the store.
        held.end_message();
        Ok(Transfer { step: packed.step, states: states.map_err(CodecError::new)?, reading: packed.reading })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::slam::grid::TiledGrid;
    use squall_core::motion::TurnErrorPrior;

    fn particle(x: f64, walls: i64) -> SlamParticle {
        let mut map = TiledGrid::new(0.05, (0.0, 0.0)).unwrap();
        for i in 0..walls {
            map.update((i, 10), |c| c.add_hit(i as f32 * 0.05, 0.5));
        }
        let spread = MotionSpread {
            turn: [[0.01, 0.0, 0.001], [0.0, 0.02, 0.0], [0.001, 0.0, 0.003]],
            drive: [[0.02, 0.001, 0.0], [0.001, 0.03, 0.0], [0.0, 0.0, 0.004]],
            turned: 0.7,
            driven: 0.3,
        };
        let mut turns = TurnErrorEstimate::default();
        let prior = TurnErrorPrior { turn_error: 0.1, turn: 0.5, resolution: 0.05 };
        turns.observe(0.6, 0.2, 0.04, &prior);
        let (pose, estimate) = (Pose2::new(x, 0.0, 0.1), Pose2::new(x, 0.01, 0.1));
        SlamParticle { pose, estimate, map, history: MapHistory::default(), spread, turns }
    }

    #[test]
    fn a_parent_sent_twice_crosses_whole_once() {
        let (mut sent, mut held) = (Sent::default(), TileStore::default());
        let parent = particle(1.0, 400);
        let first =
            Transfer { step: 3, states: vec![(0, parent.clone()), (5, parent.clone())], reading: None };
        let bytes = first.encode_incremental(&mut sent).unwrap();
        let back = Transfer::<SlamParticle, LaserReading>::decode_incremental(&bytes, &mut held).unwrap();
        assert_eq!(back.step, 3);
        assert_eq!(back.states.iter().map(|s| s.0).collect::<Vec<_>>(), vec![0, 5]);
        assert_eq!((back.states[1].1.pose, back.states[1].1.estimate), (parent.pose, parent.estimate));
        assert_eq!(back.states[1].1.spread, parent.spread);
        assert_eq!(back.states[1].1.turns, parent.turns);
        assert_eq!(back.states[1].1.map.get((7, 10)), parent.map.get((7, 10)));
        let plain = postcard::to_stdvec(&first).unwrap().len();
        // The second state refers to the first's tiles.
        assert!(bytes.len() * 3 < plain * 2, "{} vs {plain}", bytes.len());
        let again = Transfer { step: 4, states: vec![(2, parent)], reading: None };
        let second = again.encode_incremental(&mut sent).unwrap();
        assert!(second.len() * 20 < bytes.len(), "{} vs {}", second.len(), bytes.len());
        assert!(Transfer::<SlamParticle, LaserReading>::decode_incremental(&second, &mut held).is_ok());
        // Another receiver, which holds nothing, cannot resolve it.
        assert!(
            Transfer::<SlamParticle, LaserReading>::decode_incremental(&second, &mut TileStore::default())
                .is_err()
        );
    }

    #[test]
    fn snapshots_cross_with_their_particle_sharing_its_tiles() {
        let mut p = particle(2.0, 400);
        p.history.record(&p.map, 1);
        p.map.update((5, 300), |c| c.add_hit(0.25, 15.0));
        p.history.record(&p.map, 1);
        p.map.update((6, 300), |c| c.add_hit(0.3, 15.0));
        let size = |p: &SlamParticle| {
            let transfer = Transfer { step: 1, states: vec![(4, p.clone())], reading: None };
            let bytes = transfer.encode_incremental(&mut Sent::default()).unwrap();
            (
                bytes.len(),
                Transfer::<SlamParticle, LaserReading>::decode_incremental(&bytes, &mut TileStore::default()),
            )
        };
        let (bytes, back) = size(&p);
        let (_, back) = back.unwrap().states.remove(0);
        assert_eq!(back.history.updates, 2);
        let cell = |g: Option<&TiledGrid>, c| g.map(|g| g.get(c));
        for c in [(5, 300), (6, 300), (7, 10)] {
            assert_eq!(cell(Some(&back.map), c), cell(Some(&p.map), c));
            assert_eq!(cell(back.history.recent.as_ref(), c), cell(p.history.recent.as_ref(), c));
            assert_eq!(cell(back.history.old.as_ref(), c), cell(p.history.old.as_ref(), c));
        }
        let tiles = |p: &SlamParticle| TiledGrid::distinct_tiles(p.grids()).0;
        assert_eq!(tiles(&back), tiles(&p), "the tiles shared stay shared");
        // The snapshots add only the tiles written since them.
        let without = SlamParticle { history: MapHistory::default(), ..p.clone() };
        let (alone, _) = size(&without);
        assert!(bytes * 10 < alone * 13, "{bytes} vs {alone}");
    }
}
