//! Acceptance filters: a node receives only the identifiers it asked for, like a real CAN
//! controller (and like SocketCAN's `can_filter`: `received_id & mask == id & mask`).

use crate::id::Id;

/// One acceptance filter: an identifier, a mask over its bits, and which formats it matches.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Filter {
    id: u32,
    mask: u32,
    /// `Some(true)`: only extended, `Some(false)`: only standard, `None`: both formats.
    extended: Option<bool>,
}

impl Filter {
    /// Accepts every frame.
    pub const ACCEPT_ALL: Filter = Filter {
        id: 0,
        mask: 0,
        extended: None,
    };

    /// Accepts exactly this identifier (in its format).
    pub const fn exact(id: Id) -> Filter {
        Filter {
            id: id.as_raw(),
            mask: if id.is_extended() { 0x1FFF_FFFF } else { 0x7FF },
            extended: Some(id.is_extended()),
        }
    }

    /// Accepts identifiers of `id`'s format whose bits under `mask` equal `id`'s.
    pub const fn masked(id: Id, mask: u32) -> Filter {
        Filter {
            id: id.as_raw() & mask,
            mask,
            extended: Some(id.is_extended()),
        }
    }

    /// Accepts standard identifiers in `first..=last` when the range is aligned to a power of
    /// two (as CANopen's function-code ranges are); otherwise use several filters.
    pub fn standard_range(first: u16, last: u16) -> Option<Filter> {
        let span = u32::from(last.checked_sub(first)?) + 1;
        if !span.is_power_of_two() || u32::from(first) % span != 0 || last > 0x7FF {
            return None;
        }
        Some(Filter {
            id: u32::from(first),
            mask: 0x7FF & !(span - 1),
            extended: Some(false),
        })
    }

    /// Whether a frame with this identifier passes.
    #[inline]
    pub const fn matches(&self, id: Id) -> bool {
        let fmt_ok = match self.extended {
            None => true,
            Some(ext) => ext == id.is_extended(),
        };
        fmt_ok && (id.as_raw() & self.mask) == (self.id & self.mask)
    }
}

/// A set of filters: a frame passes when any filter matches. The empty set passes nothing.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct FilterSet {
    filters: Vec<Filter>,
}

impl FilterSet {
    /// A set that passes every frame.
    pub fn accept_all() -> Self {
        FilterSet {
            filters: vec![Filter::ACCEPT_ALL],
        }
    }

    /// A set that passes nothing (add filters to open it).
    pub const fn new() -> Self {
        FilterSet {
            filters: Vec::new(),
        }
    }

    /// Add a filter.
    pub fn push(&mut self, filter: Filter) {
        if !self.filters.contains(&filter) {
            self.filters.push(filter);
        }
    }

    /// Remove every filter.
    pub fn clear(&mut self) {
        self.filters.clear();
    }

    /// The filters.
    pub fn filters(&self) -> &[Filter] {
        &self.filters
    }

    /// Whether a frame with this identifier passes.
    #[inline]
    pub fn matches(&self, id: Id) -> bool {
        self.filters.iter().any(|f| f.matches(id))
    }
}

impl FromIterator<Filter> for FilterSet {
    fn from_iter<T: IntoIterator<Item = Filter>>(iter: T) -> Self {
        let mut set = FilterSet::new();
        for f in iter {
            set.push(f);
        }
        set
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn s(raw: u16) -> Id {
        Id::standard(raw).unwrap()
    }

    #[test]
    fn exact_and_masked() {
        let f = Filter::exact(s(0x181));
        assert!(f.matches(s(0x181)));
        assert!(!f.matches(s(0x182)));
        assert!(
            !f.matches(Id::extended(0x181).unwrap()),
            "format must match"
        );
        let nmt_and_sync = Filter::masked(s(0x000), 0x77F);
        assert!(nmt_and_sync.matches(s(0x000)));
        assert!(nmt_and_sync.matches(s(0x080)));
        assert!(!nmt_and_sync.matches(s(0x081)));
    }

    #[test]
    fn ranges() {
        let f = Filter::standard_range(0x700, 0x77F).unwrap();
        assert!(f.matches(s(0x700)) && f.matches(s(0x77F)));
        assert!(!f.matches(s(0x6FF)) && !f.matches(s(0x780)));
        assert!(Filter::standard_range(0x701, 0x77F).is_none());
    }

    #[test]
    fn sets() {
        let set: FilterSet = [Filter::exact(s(1)), Filter::exact(s(2))]
            .into_iter()
            .collect();
        assert!(set.matches(s(2)) && !set.matches(s(3)));
        assert!(!FilterSet::new().matches(s(1)));
        assert!(FilterSet::accept_all().matches(Id::extended(7).unwrap()));
    }
}
