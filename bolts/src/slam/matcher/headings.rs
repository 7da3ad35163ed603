//! The climb's beam directions at the headings it keeps coming back to.

use super::scan::Turned;

/// Beam directions at the few headings a climb keeps coming back to, by
/// lattice heading: a turn's candidates are the current heading ± the step,
/// the same two again after every move that only translates, so most are
/// computed once per climb rather than once per turn.
#[derive(Debug, Default)]
pub(super) struct Headings {
    entries: [(Option<i64>, Turned); HEADINGS],
    /// The entry to reuse next.
    next: usize,
}

/// Headings a climb keeps: the current one, the best turn so far and two
/// more.
const HEADINGS: usize = 4;

impl Headings {
    /// Forgets every heading (another climb: another start, scan or grid).
    pub(super) fn forget(&mut self) {
        for entry in &mut self.entries {
            entry.0 = None;
        }
    }

    /// The entry holding the directions at lattice heading `index`, filled
    /// by `fill` if none does, in an entry other than the two in `keep`.
    pub(super) fn slot(&mut self, index: i64, keep: [usize; 2], fill: impl FnOnce(&mut Turned)) -> usize {
        if let Some(found) = self.entries.iter().position(|e| e.0 == Some(index)) {
            return found;
        }
        let mut victim = self.next % HEADINGS;
        while keep.contains(&victim) {
            victim = (victim + 1) % HEADINGS;
        }
        self.next = victim + 1;
        let entry = &mut self.entries[victim];
        entry.0 = Some(index);
        fill(&mut entry.1);
        victim
    }

    /// The directions in entry `slot`.
    pub(super) fn at(&self, slot: usize) -> &Turned {
        &self.entries[slot].1
    }
}

/// A pose on the hill climber's lattice: (x, y, θ) in finest steps from
/// the initial pose.
pub(super) type Lattice = (i64, i64, i64);
