//! The winner of arbitration among the ports' offers: a four-way tournament tree.
//!
//! Each leaf holds one port's arbitration entry (`key << 32 | port`, `u64::MAX` when it
//! offers nothing), each inner node the least of its four children, so the root is the
//! winner (ISO 11898-1 §10.5: the lowest arbitration field wins; equal keys, which on a real
//! bus would collide, go to the lowest port, as they always have here). Changing an entry
//! walks the path up to the root, taking at each level the least of the four siblings,
//! which are stored together as one group: for 127 ports four levels, where a binary tree
//! has seven. A better entry only lowers ancestors, up to the first that is already lower; a
//! worse one recomputes them, up to the first that keeps its value. O(log n) per change,
//! O(1) to read the winner, no stale entries and no allocation once the ports are attached.

/// No entry: greater than every real one.
pub(crate) const NONE: u64 = u64::MAX;

#[derive(Debug, Clone)]
pub(crate) struct Arbiter {
    /// Leaves: a power of four, at least 1.
    leaves: usize,
    /// The nodes in groups of four siblings: node `k` is `groups[k / 4][k % 4]`, node 1 is
    /// the root, the children of node `k` are nodes `4k..4k + 4` (group `k`), so leaf `i` is
    /// node `leaves + i`. Slots of no node (0, 2, 3 and the gaps between levels) stay
    /// [`NONE`].
    groups: Vec<[u64; 4]>,
}

impl Arbiter {
    pub fn new() -> Self {
        Arbiter {
            leaves: 1,
            groups: vec![[NONE; 4]],
        }
    }

    /// The least entry, [`NONE`] when no port offers anything.
    #[inline]
    pub fn winner(&self) -> u64 {
        self.groups[0][1]
    }

    /// Set port `i`'s entry; returns the one it had.
    #[inline]
    pub fn set(&mut self, i: usize, entry: u64) -> u64 {
        if i >= self.leaves {
            self.grow(i + 1);
        }
        let groups = &mut self.groups[..];
        let mut k = self.leaves + i;
        let Some(leaf) = groups.get_mut(k / 4) else {
            return NONE;
        };
        let old = std::mem::replace(&mut leaf[k % 4], entry);
        if entry < old {
            // A new offer or a better one: each ancestor becomes the lesser of itself and
            // the entry, up to the first that is already at most the entry.
            while k >= 4 {
                k /= 4;
                let Some(group) = groups.get_mut(k / 4) else {
                    return old;
                };
                let node = &mut group[k % 4];
                if *node <= entry {
                    return old;
                }
                *node = entry;
            }
        } else if entry > old {
            // A withdrawn or worse offer: each ancestor is the least of its children again,
            // up to the first that keeps its value.
            let mut least = entry;
            while k >= 4 {
                // The node's own value is carried in `least` and only its three siblings
                // are read, so no level waits for the store of the level below.
                let Some(group) = groups.get(k / 4) else {
                    return old;
                };
                let siblings = group[(k + 1) % 4]
                    .min(group[(k + 2) % 4])
                    .min(group[(k + 3) % 4]);
                least = least.min(siblings);
                k /= 4;
                let Some(group) = groups.get_mut(k / 4) else {
                    return old;
                };
                let node = &mut group[k % 4];
                if *node == least {
                    return old;
                }
                *node = least;
            }
        }
        old
    }

    /// Room for `ports` leaves, keeping the entries.
    fn grow(&mut self, ports: usize) {
        let mut leaves = 1;
        while leaves < ports {
            leaves *= 4;
        }
        let mut nodes = vec![NONE; 2 * leaves.max(2)];
        let old = self.leaves;
        for j in 0..old {
            nodes[leaves + j] = self.groups[(old + j) / 4][(old + j) % 4];
        }
        let mut level = leaves;
        while level > 1 {
            let parents = level / 4;
            for k in parents..2 * parents {
                let c = &nodes[4 * k..4 * k + 4];
                nodes[k] = c[0].min(c[1]).min(c[2].min(c[3]));
            }
            level = parents;
        }
        self.leaves = leaves;
        self.groups = nodes
            .chunks_exact(4)
            .map(|c| [c[0], c[1], c[2], c[3]])
            .collect();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        /// The same with few distinct values, so that entries tie and changes stop early.
        #[test]
        fn the_winner_is_the_least_entry_among_ties(
            changes in proptest::collection::vec((0usize..300, 0u64..6, any::<bool>()), 1..400)
        ) {
            let mut a = Arbiter::new();
            let mut entries = vec![u64::MAX; 300];
            for (i, v, clear) in changes {
                let v = if clear { u64::MAX } else { v };
                prop_assert_eq!(a.set(i, v), entries[i]);
                entries[i] = v;
                prop_assert_eq!(a.winner(), *entries.iter().min().unwrap());
            }
        }

        /// After any sequence of changes the winner is the least entry.
        #[test]
        fn the_winner_is_the_least_entry(
            changes in proptest::collection::vec((0usize..70, any::<u64>(), any::<bool>()), 1..200)
        ) {
            let mut a = Arbiter::new();
            let mut entries = vec![u64::MAX; 70];
            for (i, v, clear) in changes {
                let v = if clear { u64::MAX } else { v };
                prop_assert_eq!(a.set(i, v), entries[i]);
                entries[i] = v;
                prop_assert_eq!(a.winner(), *entries.iter().min().unwrap());
            }
        }
    }

    #[test]
    fn an_empty_arbiter_has_no_winner() {
        let mut a = Arbiter::new();
        assert_eq!(a.winner(), u64::MAX);
        a.set(5, 7);
        a.set(2, 9);
        assert_eq!(a.winner(), 7);
        a.set(5, u64::MAX);
        assert_eq!(a.winner(), 9);
        a.set(2, u64::MAX);
        assert_eq!(a.winner(), u64::MAX);
    }
}
