//! Memory as a product feature: a predicted [`MemoryBudget`] and the [`Arena`]
//! that carves working buffers from caller storage and measures what was used.
//!
//! Each stage offers a `budget(config, &mut MemoryBudget)` that adds its
//! components (predicted bytes, alignment padding included) and an
//! `init(config, &mut Arena)` that takes exactly those buffers; the arena's
//! high-water mark is the measured figure reported next to the prediction.

use bytemuck::Pod;
use core::mem::{align_of, size_of};

/// Bytes that a slice of `n` values of `T` takes in an [`Arena`], worst-case
/// alignment padding included.
pub const fn slice_bytes<T>(n: usize) -> usize {
    n * size_of::<T>() + align_of::<T>() - 1
}

/// The arena ran out of storage.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct OutOfMemory {
    /// Bytes asked for (padding included).
    pub requested: usize,
    /// Bytes still free in the arena.
    pub available: usize,
}

impl core::fmt::Display for OutOfMemory {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(
            f,
            "arena exhausted: {} bytes requested, {} free",
            self.requested, self.available
        )
    }
}

/// The stages whose carves an [`Arena`] counts apart: the measured side of a
/// [`MemoryBudget`], whose components are named `"<prefix>.<buffer>"`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Stage {
    /// The firmware's own buffers (the frames).
    Firmware,
    Sift,
    /// The keypoints and descriptors of the images.
    Features,
    Match,
    Adjust,
    Traverse,
}

impl Stage {
    pub const ALL: [Stage; 6] = [
        Stage::Firmware,
        Stage::Sift,
        Stage::Features,
        Stage::Match,
        Stage::Adjust,
        Stage::Traverse,
    ];

    /// The prefix of the stage's budget components (without the dot).
    pub const fn prefix(self) -> &'static str {
        match self {
            Stage::Firmware => "firmware",
            Stage::Sift => "sift",
            Stage::Features => "features",
            Stage::Match => "match",
            Stage::Adjust => "adjust",
            Stage::Traverse => "traverse",
        }
    }

    /// The stage a budget component belongs to, by its name's prefix.
    pub fn of_component(name: &str) -> Option<Stage> {
        Stage::ALL.into_iter().find(|s| {
            name.strip_prefix(s.prefix())
                .is_some_and(|rest| rest.starts_with('.'))
        })
    }

    const fn index(self) -> usize {
        self as usize
    }
}

/// Bytes carved per [`Stage`], in the order of [`Stage::ALL`].
pub type CarvedBytes = [usize; Stage::ALL.len()];

/// A bump allocator over one caller-provided byte slice. Never frees singly;
/// [`Arena::used`] is the measured high-water mark of everything carved, and
/// [`Arena::carved`] the same bytes by the [`Stage`] that carved them.
pub struct Arena<'a> {
    free: &'a mut [u8],
    capacity: usize,
    stage: Stage,
    carved: CarvedBytes,
}

impl<'a> Arena<'a> {
    /// An arena whose carves count under [`Stage::Firmware`] until [`Arena::stage`] says otherwise.
    pub fn new(storage: &'a mut [u8]) -> Self {
        let capacity = storage.len();
        Arena {
            free: storage,
            capacity,
            stage: Stage::Firmware,
            carved: [0; Stage::ALL.len()],
        }
    }

    /// Counts the carves that follow under `stage`. The builder of a pipeline sets it
    /// before each stage's constructor, so a stage need not know how it is counted.
    pub fn stage(&mut self, stage: Stage) {
        self.stage = stage;
    }

    /// Bytes carved so far per stage (padding included).
    pub fn carved(&self) -> CarvedBytes {
        self.carved
    }

    /// A zeroed slice of `n` values of `T`, aligned for `T`.
    pub fn alloc_slice<T: Pod>(&mut self, n: usize) -> Result<&'a mut [T], OutOfMemory> {
        let pad = self.free.as_ptr().align_offset(align_of::<T>());
        let bytes = n
            .checked_mul(size_of::<T>())
            .and_then(|b| b.checked_add(pad));
        let available = self.free.len();
        let requested = bytes.unwrap_or(usize::MAX);
        if pad == usize::MAX || requested > available {
            return Err(OutOfMemory {
                requested,
                available,
            });
        }
        let free = core::mem::take(&mut self.free);
        let (head, tail) = free.split_at_mut(requested);
        self.free = tail;
        self.carved[self.stage.index()] += requested;
        let body = &mut head[pad..];
        body.fill(0);
        // Alignment and length were established above, so the cast cannot fail.
        bytemuck::try_cast_slice_mut(body).map_err(|_| OutOfMemory {
            requested,
            available,
        })
    }

    /// Bytes carved so far (padding included): the measured working memory.
    pub fn used(&self) -> usize {
        self.capacity - self.free.len()
    }

    /// Bytes still free.
    pub fn remaining(&self) -> usize {
        self.free.len()
    }

    pub fn capacity(&self) -> usize {
        self.capacity
    }
}

/// Most components a budget lists.
pub const MAX_COMPONENTS: usize = 48;

/// One named line of a budget.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Component {
    /// Stage and buffer, for example `"sift.gauss_rings"`.
    pub name: &'static str,
    /// Bytes predicted from the configuration.
    pub bytes: usize,
    /// What the component is: working memory or persistent storage.
    pub kind: ComponentKind,
}

/// Whether a component is scratch for one stage or state kept across epochs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ComponentKind {
    /// Frame buffers holding the input images.
    Frame,
    /// Scratch a stage needs only while it runs.
    Working,
    /// Results and state that live across stages or epochs (keypoints, tracks, window).
    Storage,
}

/// The bytes a configuration needs, component by component, known before anything runs.
#[derive(Debug, Clone, Default)]
pub struct MemoryBudget {
    components: heapless::Vec<Component, MAX_COMPONENTS>,
    /// Components that did not fit in the list (their bytes still count in the total).
    overflow_bytes: usize,
}

impl MemoryBudget {
    pub fn new() -> Self {
        Self::default()
    }

    /// Adds a component; beyond [`MAX_COMPONENTS`] lines its bytes are summed under overflow.
    pub fn add(&mut self, name: &'static str, kind: ComponentKind, bytes: usize) {
        if self
            .components
            .push(Component { name, bytes, kind })
            .is_err()
        {
            self.overflow_bytes = self.overflow_bytes.saturating_add(bytes);
        }
    }

    pub fn components(&self) -> &[Component] {
        &self.components
    }

    /// Total predicted bytes.
    pub fn total(&self) -> usize {
        // Saturating: a total past the address space is refused like any too large.
        self.components
            .iter()
            .fold(self.overflow_bytes, |a, c| a.saturating_add(c.bytes))
    }

    /// Total predicted bytes of one kind.
    pub fn total_of(&self, kind: ComponentKind) -> usize {
        self.components
            .iter()
            .filter(|c| c.kind == kind)
            .map(|c| c.bytes)
            .sum()
    }

    /// Total predicted bytes of the components of `stage` ([`Stage::of_component`]):
    /// what the [`Arena`] should carve for it, less padding it does not need.
    pub fn total_of_stage(&self, stage: Stage) -> usize {
        self.components
            .iter()
            .filter(|c| Stage::of_component(c.name) == Some(stage))
            .map(|c| c.bytes)
            .sum()
    }

    /// Total predicted bytes of the components whose name starts with `prefix`.
    pub fn total_with_prefix(&self, prefix: &str) -> usize {
        self.components
            .iter()
            .filter(|c| c.name.starts_with(prefix))
            .map(|c| c.bytes)
            .sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn arena_aligns_and_measures() {
        let mut storage = [0xAAu8; 256];
        let mut arena = Arena::new(&mut storage);
        let a: &mut [u8] = arena.alloc_slice(3).unwrap();
        assert_eq!(a, &[0, 0, 0]);
        let b: &mut [u32] = arena.alloc_slice(4).unwrap();
        assert_eq!(b.as_ptr() as usize % align_of::<u32>(), 0);
        b[3] = 7;
        assert!(arena.used() <= slice_bytes::<u8>(3) + slice_bytes::<u32>(4));
        assert!(arena.used() >= 3 + 16);
    }

    #[test]
    fn arena_counts_each_stage_apart() {
        let mut storage = [0u8; 256];
        let mut arena = Arena::new(&mut storage);
        arena.alloc_slice::<u8>(5).unwrap();
        arena.stage(Stage::Adjust);
        arena.alloc_slice::<u64>(3).unwrap();
        arena.stage(Stage::Sift);
        arena.alloc_slice::<u8>(7).unwrap();
        let c = arena.carved();
        assert_eq!(c[Stage::Firmware as usize], 5);
        // The u64 slice starts at the next multiple of its alignment: padding counts.
        assert!((24..=24 + 7).contains(&c[Stage::Adjust as usize]), "{c:?}");
        assert_eq!(c[Stage::Sift as usize], 7);
        assert_eq!(c.iter().sum::<usize>(), arena.used());
        // A failed request counts nowhere.
        assert!(arena.alloc_slice::<u8>(1000).is_err());
        assert_eq!(arena.carved(), c);
    }

    #[test]
    fn arena_refuses_what_does_not_fit() {
        let mut storage = [0u8; 16];
        let mut arena = Arena::new(&mut storage);
        let err = arena.alloc_slice::<u64>(100).unwrap_err();
        assert!(err.requested >= 800);
        assert_eq!(
            arena.alloc_slice::<u64>(usize::MAX).unwrap_err().available,
            16
        );
        // Nothing was consumed by the failed requests.
        assert!(arena.alloc_slice::<u8>(8).is_ok());
    }

    #[test]
    fn budget_sums_by_kind_and_prefix() {
        let mut b = MemoryBudget::new();
        b.add("sift.rings", ComponentKind::Working, 100);
        b.add("sift.keypoints", ComponentKind::Storage, 50);
        b.add("frames", ComponentKind::Frame, 7);
        assert_eq!(b.total(), 157);
        assert_eq!(b.total_of(ComponentKind::Working), 100);
        assert_eq!(b.total_with_prefix("sift."), 150);
        assert_eq!(b.total_of_stage(Stage::Sift), 150);
        assert_eq!(b.total_of_stage(Stage::Firmware), 0);
        assert_eq!(Stage::of_component("frames"), None);
        assert_eq!(Stage::of_component("siftx.rings"), None);
        assert_eq!(Stage::of_component("match.grid"), Some(Stage::Match));
    }
}
