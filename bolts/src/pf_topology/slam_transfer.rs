//! SLAM particles cross processes with their maps packed by tile: a
//! transfer carries whole only the tiles the receiving task does not
//! already hold from the sending one (see [`crate::slam::transfer`]).
//! Within one process transfers share the maps' tiles, as always.

use serde::{Deserialize, Serialize};
use squall_topology::Incremental;

use crate::geometry::Pose2;
use std::sync::Arc;

use crate::pf_topology::messages::{Reading, Transfer};
use crate::sensor::LaserReading;
use crate::slam::model::SlamParticle;
use crate::slam::transfer::{PackedGrid, Sent, TileStore, pack};

/// A transfer as it crosses: each state's pose and packed map.
#[derive(Debug, Serialize, Deserialize)]
struct PackedTransfer {
    step: u64,
    states: Vec<(u32, Pose2, PackedGrid)>,
    reading: Option<Arc<Reading<LaserReading>>>,
}

impl Incremental for Transfer<SlamParticle, LaserReading> {
    type Sent = Sent;
    type Held = TileStore;

    fn encode_incremental(&self, sent: &mut Sent) -> Result<Vec<u8>, String> {
        let states = self.states.iter().map(|(slot, p)| (*slot, p.pose, pack(&p.map, sent))).collect();
        sent.end_message();
        let packed = PackedTransfer { step: self.step, states, reading: self.reading.clone() };
        postcard::to_stdvec(&packed).map_err(|e| e.to_string())
    }

    fn decode_incremental(bytes: &[u8], held: &mut TileStore) -> Result<Self, String> {
        let packed: PackedTransfer = postcard::from_bytes(bytes).map_err(|e| e.to_string())?;
        let states = packed
            .states
            .into_iter()
            .map(|(slot, pose, map)| Ok((slot, SlamParticle { pose, map: held.unpack(map)? })))
            .collect::<Result<Vec<_>, crate::slam::transfer::UnpackError>>();
        // The sender ended its message whatever it held; so does the store.
        held.end_message();
        Ok(Transfer {
            step: packed.step,
            states: states.map_err(|e| e.to_string())?,
            reading: packed.reading,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::slam::grid::TiledGrid;

    fn particle(x: f64, walls: i64) -> SlamParticle {
        let mut map = TiledGrid::new(0.05, (0.0, 0.0));
        for i in 0..walls {
            map.update((i, 10), |c| c.add_hit(i as f32 * 0.05, 0.5));
        }
        SlamParticle { pose: Pose2::new(x, 0.0, 0.1), map }
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
        assert_eq!(back.states[1].1.pose, parent.pose);
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
}
