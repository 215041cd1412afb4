//! Templates of the left image around its stereo-matched points, so a tie point's
//! current left position can be found by area matching against the very spot observed
//! before (the frames themselves are not kept).
//!
//! Why: the detector places a keypoint slightly differently as the view changes
//! (perspective and scale change of the surface around it), and between epochs that
//! difference is systematic (outward with forward motion), which the adjustment turns
//! into a drift of pitch and scale. Correlating a template puts the current observation
//! on the surface point the template shows; the stereo refinement then carries it to
//! the right image.
//!
//! A tie point's template is its *anchor*: taken once, where the track was first
//! observed, and carried from epoch to epoch while the point's apparent scale stays
//! within [`MAX_ANCHOR_SCALE`] of the anchor's (the template is magnified by the scale
//! before it is correlated). Re-taking the template at each epoch's measured position
//! would let every measurement error move the track over the surface: the observations
//! of one window point would then be of a random walk of surface points (the transfer
//! error grew as `0.17 px x sqrt(epochs)` on the rendered streets), and a window longer
//! than two epochs could add no information. Each template keeps the depth of its point
//! at the anchor epoch, which gives the scale.
//!
//! Each template also remembers what it is a view of ([`PatchInfo`]): its right
//! position at the same epoch and the window point it already is, if any, so the
//! templates the descriptors did not carry on can be found by area alone (`area`).
use crate::budget::{slice_bytes, Arena, ComponentKind, MemoryBudget, OutOfMemory};
use crate::image::ImageView;
use crate::matching::refine::{sample_template, TEMPLATE_LEN};
use bytemuck::{Pod, Zeroable};

/// Fixed-point scale of the stored samples (8 fractional bits of a grey level).
const SCALE: f32 = 256.0;

/// No window point / no tag.
pub const NO_ID: u32 = u32::MAX;

/// What a template shows: the stereo observation it belongs to and its window point.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
pub struct PatchInfo {
    /// Right position (pixels) at the templates' epoch.
    pub right: [f32; 2],
    /// Precision of `right` (pixels; x, y; zero: not measured).
    pub right_sigma: [f32; 2],
    /// Observation tag (track id) of the window point, [`NO_ID`] when there is none.
    pub tag: u32,
    /// Window point, [`NO_ID`] for a stereo match that is not a tie point yet.
    pub point: u32,
}

impl PatchInfo {
    /// A stereo match that is no window point yet.
    pub fn stereo(right: [f32; 2], right_sigma: [f32; 2]) -> Self {
        PatchInfo {
            right,
            right_sigma,
            tag: NO_ID,
            point: NO_ID,
        }
    }
}

/// A template is carried on while its point appears at most this many times larger
/// (or `1 / MAX_ANCHOR_SCALE` smaller) than at its anchor epoch; beyond, it is re-taken.
/// The magnified anchor loses detail against the current image as the scale grows,
/// and the perspective change of an oblique surface, which the magnification ignores,
/// grows with it.
pub const MAX_ANCHOR_SCALE: f32 = 1.3;

/// Templates keyed by the pixel position the matcher reports for them next epoch.
/// Slots persist across epochs (a carried anchor keeps its samples); a round of
/// [`Patches::begin`], [`Patches::keep`] and [`Patches::push`] renews the store.
pub struct Patches<'a> {
    keys: &'a mut [[f32; 2]],
    info: &'a mut [PatchInfo],
    /// Depth of the template's point at its anchor epoch, metres (0: unknown, far).
    depth: &'a mut [f32],
    /// Whether the slot holds a template of the current round.
    live: &'a mut [u8],
    samples: &'a mut [u16],
    /// Slots in use are below `n`; `cursor` is where `push` looks for a free one.
    n: usize,
    cursor: usize,
    half: usize,
    dropped: u32,
    /// Window epoch id of the image the templates come from.
    epoch: Option<u32>,
}

fn side(half: usize) -> usize {
    2 * half + 1
}

impl<'a> Patches<'a> {
    pub fn budget(capacity: usize, half: usize, budget: &mut MemoryBudget) {
        let len = side(half) * side(half);
        budget.add(
            "traverse.patch_keys",
            ComponentKind::Storage,
            slice_bytes::<[f32; 2]>(capacity),
        );
        budget.add(
            "traverse.patch_info",
            ComponentKind::Storage,
            slice_bytes::<PatchInfo>(capacity),
        );
        budget.add(
            "traverse.patch_anchor",
            ComponentKind::Storage,
            slice_bytes::<f32>(capacity) + slice_bytes::<u8>(capacity),
        );
        budget.add(
            "traverse.patches",
            ComponentKind::Storage,
            slice_bytes::<u16>(capacity * len),
        );
    }

    pub fn new(arena: &mut Arena<'a>, capacity: usize, half: usize) -> Result<Self, OutOfMemory> {
        let len = side(half) * side(half);
        Ok(Patches {
            keys: arena.alloc_slice(capacity)?,
            info: arena.alloc_slice(capacity)?,
            depth: arena.alloc_slice(capacity)?,
            live: arena.alloc_slice(capacity)?,
            samples: arena.alloc_slice(capacity * len)?,
            n: 0,
            cursor: 0,
            half,
            dropped: 0,
            epoch: None,
        })
    }

    /// Starts the round of window epoch `epoch`: every template becomes stale until
    /// [`Patches::keep`] carries it on, and [`Patches::push`] fills the stale slots.
    /// `None` (an image that is not in the window) empties the store.
    pub fn begin(&mut self, epoch: Option<u32>) {
        self.live[..self.n].fill(0);
        if epoch.is_none() {
            self.n = 0;
        }
        self.cursor = 0;
        self.dropped = 0;
        self.epoch = epoch;
    }

    /// Carries template `i` of the last round on, now seen at `key` with `info`;
    /// false when there is no such template.
    pub fn keep(&mut self, i: usize, key: [f32; 2], info: PatchInfo) -> bool {
        if i >= self.n {
            return false;
        }
        self.live[i] = 1;
        self.keys[i] = key;
        self.info[i] = info;
        true
    }

    /// Depth of template `i`'s point at its anchor epoch (metres), if known.
    pub fn anchor_depth(&self, i: usize) -> Option<f32> {
        let d = *self.depth[..self.n].get(i)?;
        (self.live[i] != 0 && d > 0.0).then_some(d)
    }

    /// Window epoch id the templates were taken at.
    pub fn epoch(&self) -> Option<u32> {
        self.epoch
    }

    /// Template half-size (pixels).
    pub fn half(&self) -> usize {
        self.half
    }

    pub fn len(&self) -> usize {
        self.n
    }

    /// Templates the store holds at most.
    pub fn capacity(&self) -> usize {
        self.keys.len()
    }

    #[cfg(test)]
    pub fn is_empty(&self) -> bool {
        self.n == 0
    }

    /// Templates that did not fit since the last [`Patches::begin`].
    #[cfg(test)]
    pub fn dropped(&self) -> u32 {
        self.dropped
    }

    /// The first slot [`Patches::push`] may fill: stale or never used.
    fn free_slot(&mut self) -> Option<usize> {
        while self.cursor < self.keys.len() && self.cursor < self.n && self.live[self.cursor] != 0 {
            self.cursor += 1;
        }
        (self.cursor < self.keys.len()).then_some(self.cursor)
    }

    /// Templates carried on or pushed this round.
    pub fn live(&self) -> usize {
        self.live[..self.n].iter().filter(|&&l| l != 0).count()
    }

    /// Whether [`Patches::push`] has a slot left this round.
    pub fn has_room(&mut self) -> bool {
        self.free_slot().is_some()
    }

    /// Anchors a new template around `at` in `img` in a free slot, its point `depth`
    /// metres away (`None`: unknown); false when full or at the border.
    pub fn push(
        &mut self,
        img: &ImageView<'_>,
        at: [f32; 2],
        info: PatchInfo,
        depth: Option<f32>,
    ) -> bool {
        let Some(slot) = self.free_slot() else {
            self.dropped = self.dropped.saturating_add(1);
            return false;
        };
        let mut tpl = [0f32; TEMPLATE_LEN];
        if sample_template(img, at, self.half, &mut tpl).is_err() {
            return false;
        }
        let len = side(self.half) * side(self.half);
        let dst = &mut self.samples[slot * len..(slot + 1) * len];
        for (d, &v) in dst.iter_mut().zip(&tpl[..len]) {
            *d = (v * SCALE + 0.5) as u16;
        }
        self.keys[slot] = at;
        self.info[slot] = info;
        self.depth[slot] = depth.filter(|d| d.is_finite() && *d > 0.0).unwrap_or(0.0);
        self.live[slot] = 1;
        self.n = self.n.max(slot + 1);
        true
    }

    /// Index of the template stored at exactly `key`.
    pub fn index_of(&self, key: [f32; 2]) -> Option<usize> {
        (0..self.n).find(|&i| self.live[i] != 0 && self.keys[i] == key)
    }

    /// The template stored at exactly `key`, expanded into `out`.
    #[cfg(test)]
    pub fn find(&self, key: [f32; 2], out: &mut [f32; TEMPLATE_LEN]) -> bool {
        self.index_of(key).is_some_and(|i| self.template(i, out))
    }

    /// Position (pixels) of template `i` at the last round's epoch.
    pub fn key(&self, i: usize) -> Option<[f32; 2]> {
        (i < self.n && self.live[i] != 0).then(|| self.keys[i])
    }

    /// What template `i` shows.
    pub fn info(&self, i: usize) -> Option<PatchInfo> {
        (i < self.n && self.live[i] != 0).then(|| self.info[i])
    }

    /// Template `i` (as anchored), expanded into `out`; false when there is no such template.
    pub fn template(&self, i: usize, out: &mut [f32; TEMPLATE_LEN]) -> bool {
        if i >= self.n || self.live[i] == 0 {
            return false;
        }
        let len = side(self.half) * side(self.half);
        for (o, &s) in out.iter_mut().zip(&self.samples[i * len..(i + 1) * len]) {
            *o = s as f32 / SCALE;
        }
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stores_and_finds_templates_exactly_at_their_key() {
        let (w, h) = (40usize, 30usize);
        let img: [u8; 1200] = core::array::from_fn(|i| ((i % w) * 5 + (i / w) * 3) as u8);
        let view = ImageView::new(&img, w, h).unwrap();
        let mut store = [0u8; 4096];
        let mut arena = Arena::new(&mut store);
        let mut p = Patches::new(&mut arena, 2, 2).unwrap();
        p.begin(Some(0));
        let info = PatchInfo {
            right: [4.0, 12.5],
            right_sigma: [0.04, 0.0],
            tag: 7,
            point: 3,
        };
        assert!(p.push(&view, [10.25, 12.5], info, Some(12.0)));
        assert!(!p.push(&view, [0.5, 0.5], info, None), "border");
        assert!(p.push(
            &view,
            [20.0, 15.0],
            PatchInfo::stereo([12.0, 15.0], [0.1, 0.0]),
            None
        ));
        assert!(!p.push(&view, [21.0, 15.0], info, None), "full");
        assert_eq!(p.anchor_depth(0), Some(12.0));
        assert_eq!(p.anchor_depth(1), None);
        assert_eq!(p.info(0), Some(info));
        assert_eq!(p.info(1).map(|i| i.point), Some(NO_ID));
        assert_eq!(p.index_of([20.0, 15.0]), Some(1));
        assert_eq!((p.len(), p.dropped()), (2, 1));
        let mut t = [0f32; TEMPLATE_LEN];
        assert!(p.find([10.25, 12.5], &mut t));
        // Centre sample of a 5x5 template: bilinear of the ramp at (10.25, 12.5).
        let expect = 10.25 * 5.0 + 12.5 * 3.0;
        assert!(
            (t[12] - expect).abs() < 1.0 / SCALE,
            "{} vs {expect}",
            t[12]
        );
        assert!(!p.find([10.0, 12.5], &mut t));
    }

    #[test]
    fn a_round_carries_kept_templates_and_fills_the_stale_slots() {
        let (w, h) = (40usize, 30usize);
        let a: [u8; 1200] = core::array::from_fn(|i| ((i % w) * 5 + (i / w) * 3) as u8);
        let b: [u8; 1200] = core::array::from_fn(|i| (200 - (i % w) * 2) as u8);
        let (va, vb) = (
            ImageView::new(&a, w, h).unwrap(),
            ImageView::new(&b, w, h).unwrap(),
        );
        let mut store = [0u8; 4096];
        let mut arena = Arena::new(&mut store);
        let mut p = Patches::new(&mut arena, 2, 2).unwrap();
        p.begin(Some(0));
        assert!(p.push(
            &va,
            [10.0, 10.0],
            PatchInfo::stereo([5.0, 10.0], [0.0; 2]),
            Some(8.0)
        ));
        assert!(p.push(
            &va,
            [20.0, 12.0],
            PatchInfo::stereo([15.0, 12.0], [0.0; 2]),
            Some(9.0)
        ));
        let mut anchor = [0f32; TEMPLATE_LEN];
        assert!(p.template(1, &mut anchor));
        // Next epoch: template 1 is carried on to a new position, slot 0 is re-used.
        p.begin(Some(1));
        assert_eq!(p.key(0), None, "stale until kept");
        assert!(p.keep(1, [22.0, 12.5], PatchInfo::stereo([16.0, 12.5], [0.0; 2])));
        assert!(p.push(
            &vb,
            [30.0, 15.0],
            PatchInfo::stereo([25.0, 15.0], [0.0; 2]),
            None
        ));
        assert!(!p.push(
            &vb,
            [31.0, 15.0],
            PatchInfo::stereo([26.0, 15.0], [0.0; 2]),
            None
        ));
        assert_eq!(p.index_of([22.0, 12.5]), Some(1));
        assert_eq!(p.index_of([30.0, 15.0]), Some(0));
        assert_eq!(p.index_of([20.0, 12.0]), None, "the old key is gone");
        let mut t = [0f32; TEMPLATE_LEN];
        assert!(p.template(1, &mut t));
        assert_eq!(t, anchor, "a carried template keeps its anchor samples");
        assert_eq!(p.anchor_depth(1), Some(9.0));
        // An image outside the window empties the store.
        p.begin(None);
        assert!(p.is_empty() && p.key(1).is_none());
    }
}
