//! Templates of the previous epoch's left image around its stereo-matched points, so
//! a tie point's current left position can be found by area matching against the
//! very spot observed before (the frames themselves are not kept).
//!
//! Why: the detector places a keypoint slightly differently as the view changes
//! (perspective and scale change of the surface around it), and between epochs that
//! difference is systematic (outward with forward motion), which the adjustment turns
//! into a drift of pitch and scale. Correlating the previous template puts the current
//! observation on the same surface point; the stereo refinement then carries it to the
//! right image.
use crate::budget::{slice_bytes, Arena, ComponentKind, MemoryBudget, OutOfMemory};
use crate::image::ImageView;
use crate::matching::refine::{sample_template, TEMPLATE_LEN};

/// Fixed-point scale of the stored samples (8 fractional bits of a grey level).
const SCALE: f32 = 256.0;

/// Templates keyed by the pixel position the matcher reports for them next epoch.
pub struct Patches<'a> {
    keys: &'a mut [[f32; 2]],
    samples: &'a mut [u16],
    n: usize,
    half: usize,
    dropped: u32,
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
            "traverse.patches",
            ComponentKind::Storage,
            slice_bytes::<u16>(capacity * len),
        );
    }

    pub fn new(arena: &mut Arena<'a>, capacity: usize, half: usize) -> Result<Self, OutOfMemory> {
        let len = side(half) * side(half);
        Ok(Patches {
            keys: arena.alloc_slice(capacity)?,
            samples: arena.alloc_slice(capacity * len)?,
            n: 0,
            half,
            dropped: 0,
        })
    }

    pub fn clear(&mut self) {
        self.n = 0;
        self.dropped = 0;
    }

    pub fn len(&self) -> usize {
        self.n
    }

    pub fn is_empty(&self) -> bool {
        self.n == 0
    }

    /// Templates that did not fit since the last [`Patches::clear`].
    pub fn dropped(&self) -> u32 {
        self.dropped
    }

    /// Stores the template around `at` in `img`; false when full or at the border.
    pub fn push(&mut self, img: &ImageView<'_>, at: [f32; 2]) -> bool {
        if self.n >= self.keys.len() {
            self.dropped = self.dropped.saturating_add(1);
            return false;
        }
        let mut tpl = [0f32; TEMPLATE_LEN];
        if sample_template(img, at, self.half, &mut tpl).is_err() {
            return false;
        }
        let len = side(self.half) * side(self.half);
        let dst = &mut self.samples[self.n * len..(self.n + 1) * len];
        for (d, &v) in dst.iter_mut().zip(&tpl[..len]) {
            *d = (v * SCALE + 0.5) as u16;
        }
        self.keys[self.n] = at;
        self.n += 1;
        true
    }

    /// The template stored at exactly `key`, expanded into `out`.
    pub fn find(&self, key: [f32; 2], out: &mut [f32; TEMPLATE_LEN]) -> bool {
        let Some(i) = self.keys[..self.n].iter().position(|k| *k == key) else {
            return false;
        };
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
        assert!(p.push(&view, [10.25, 12.5]));
        assert!(!p.push(&view, [0.5, 0.5]), "border");
        assert!(p.push(&view, [20.0, 15.0]));
        assert!(!p.push(&view, [21.0, 15.0]), "full");
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
}
