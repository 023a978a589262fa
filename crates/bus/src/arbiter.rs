//! The winner of arbitration among the ports' offers: a tournament tree.
//!
//! Each leaf holds one port's arbitration entry (`key << 32 | port`, `u64::MAX` when it
//! offers nothing), each inner node the least of its two children, so the root is the
//! winner (ISO 11898-1 §10.5: the lowest arbitration field wins; equal keys, which on a real
//! bus would collide, go to the lowest port, as they always have here). Changing an entry
//! walks up one path and stops where a node keeps its value: O(log n) per change, O(1) to
//! read the winner, no stale entries and no allocation once the ports are attached.

#[derive(Debug, Clone)]
pub(crate) struct Arbiter {
    /// Leaves: a power of two, at least 1.
    leaves: usize,
    /// `tree[1]` is the root; leaf `i` is `tree[leaves + i]`; `tree[0]` is unused.
    tree: Vec<u64>,
}

impl Arbiter {
    pub fn new() -> Self {
        Arbiter {
            leaves: 1,
            tree: vec![u64::MAX; 2],
        }
    }

    /// The least entry, `u64::MAX` when no port offers anything.
    #[inline]
    pub fn winner(&self) -> u64 {
        self.tree[1]
    }

    /// Set port `i`'s entry.
    #[inline]
    pub fn set(&mut self, i: usize, entry: u64) {
        if i >= self.leaves {
            self.grow(i + 1);
        }
        let mut k = self.leaves + i;
        self.tree[k] = entry;
        while k > 1 {
            let sibling = self.tree[k ^ 1];
            let least = self.tree[k].min(sibling);
            k /= 2;
            if self.tree[k] == least {
                break;
            }
            self.tree[k] = least;
        }
    }

    /// Room for `ports` leaves, keeping the entries.
    fn grow(&mut self, ports: usize) {
        let leaves = ports.next_power_of_two();
        let mut tree = vec![u64::MAX; 2 * leaves];
        tree[leaves..leaves + self.leaves].copy_from_slice(&self.tree[self.leaves..]);
        for k in (1..leaves).rev() {
            tree[k] = tree[2 * k].min(tree[2 * k + 1]);
        }
        self.leaves = leaves;
        self.tree = tree;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        /// After any sequence of changes the winner is the least entry.
        #[test]
        fn the_winner_is_the_least_entry(
            changes in proptest::collection::vec((0usize..70, any::<u64>(), any::<bool>()), 1..200)
        ) {
            let mut a = Arbiter::new();
            let mut entries = vec![u64::MAX; 70];
            for (i, v, clear) in changes {
                let v = if clear { u64::MAX } else { v };
                a.set(i, v);
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
