//! Deterministic synthetic keypoint scenes with known correspondences, for tests and
//! benchmarks of the matcher (no images needed): 3-D points of a street-like volume,
//! projected through the camera model into each image with position noise; each point
//! has a descriptor built from a shared prototype (repetitive texture) and its own
//! part, perturbed per image; distractor keypoints with random descriptors are mixed in.

use crate::camera::{project_to_pixel, Interior, Pose};
use crate::features::{Descriptor, Keypoint};

/// Marks a distractor keypoint in the id list.
pub const DISTRACTOR: u32 = u32::MAX;

/// splitmix64: a stateless hash, so every value depends only on (seed, id, tag).
pub fn hash(mut x: u64) -> u64 {
    x = x.wrapping_add(0x9E37_79B9_7F4A_7C15);
    x = (x ^ (x >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    x = (x ^ (x >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    x ^ (x >> 31)
}

fn unit(h: u64) -> f64 {
    (h >> 11) as f64 / (1u64 << 53) as f64
}

/// A scene of `points` object points plus per-image distractors.
#[derive(Debug, Clone, Copy)]
pub struct SyntheticScene {
    pub seed: u64,
    pub points: u32,
    /// Distractor keypoints added to each image.
    pub distractors: u32,
    /// Uniform keypoint position noise, +- pixels.
    pub position_noise_px: f32,
    /// Uniform per-image descriptor noise, +- grey levels.
    pub descriptor_noise: u8,
    /// Number of shared descriptor prototypes (fewer = more repetitive texture).
    pub prototypes: u32,
    /// Volume: X in `[-half_width, half_width]`, Y (forward) in `[near, far]`, Z in `[low, high]` (m).
    pub half_width: f64,
    pub near: f64,
    pub far: f64,
    pub low: f64,
    pub high: f64,
}

impl SyntheticScene {
    /// A street-like default: 4000 points from 4 to 60 m, 100 distractors per image.
    pub fn street(seed: u64) -> Self {
        SyntheticScene {
            seed,
            points: 4000,
            distractors: 100,
            position_noise_px: 0.3,
            descriptor_noise: 16,
            prototypes: 16,
            half_width: 14.0,
            near: 4.0,
            far: 60.0,
            low: -1.6,
            high: 6.0,
        }
    }

    fn h(&self, id: u64, tag: u64) -> u64 {
        hash(self.seed ^ hash(id.wrapping_mul(0x100_0000_01B3) ^ hash(tag)))
    }

    /// Object coordinates of point `id` (X right, Y forward, Z up).
    pub fn point(&self, id: u32) -> [f64; 3] {
        let id = id as u64;
        // Uniform in inverse depth: as many far points as near ones, like a street view.
        let inv = 1.0 / self.far + unit(self.h(id, 2)) * (1.0 / self.near - 1.0 / self.far);
        [
            (2.0 * unit(self.h(id, 1)) - 1.0) * self.half_width,
            1.0 / inv,
            self.low + unit(self.h(id, 3)) * (self.high - self.low),
        ]
    }

    /// Descriptor of point `id` as seen in image `tag`.
    pub fn descriptor(&self, id: u32, tag: u64, out: &mut Descriptor) {
        let proto = (id % self.prototypes.max(1)) as u64 + (1 << 40);
        let noise = self.descriptor_noise as i32;
        for (k, o) in out.iter_mut().enumerate() {
            let p = (self.h(proto, 100 + k as u64) % 256) as i32;
            let u = (self.h(id as u64, 100 + k as u64) % 256) as i32;
            let e = if noise > 0 {
                (self.h(id as u64, tag.wrapping_mul(1000) + k as u64) % (2 * noise as u64 + 1))
                    as i32
                    - noise
            } else {
                0
            };
            *o = ((p * 7 + u) / 8 + e).clamp(0, 255) as u8;
        }
    }

    /// Renders the keypoints of one image seen by `cam` at `pose`; `tag` names the image
    /// (it seeds the noise). Writes up to the slices' length; returns the number written.
    /// `ids[i]` is the point of keypoint `i` or [`DISTRACTOR`].
    pub fn render(
        &self,
        pose: &Pose,
        cam: &Interior,
        tag: u64,
        kps: &mut [Keypoint],
        desc: &mut [Descriptor],
        ids: &mut [u32],
    ) -> usize {
        let cap = kps.len().min(desc.len()).min(ids.len());
        let (w, h) = (cam.width_px as f64, cam.height_px as f64);
        let mut n = 0;
        let noise = self.position_noise_px as f64;
        for id in 0..self.points {
            if n == cap {
                break;
            }
            let Ok([c, r]) = project_to_pixel(pose, cam, &self.point(id)) else {
                continue;
            };
            let ec = (2.0 * unit(self.h(id as u64, tag * 7 + 11)) - 1.0) * noise;
            let er = (2.0 * unit(self.h(id as u64, tag * 7 + 12)) - 1.0) * noise;
            let (c, r) = (c + ec, r + er);
            if !(c >= 0.0 && r >= 0.0 && c <= w - 1.0 && r <= h - 1.0) {
                continue;
            }
            kps[n] = keypoint(c as f32, r as f32, 1.6 + (id % 5) as f32);
            self.descriptor(id, tag, &mut desc[n]);
            ids[n] = id;
            n += 1;
        }
        for k in 0..self.distractors as u64 {
            if n == cap {
                break;
            }
            let g = self.h(k + (1 << 50), tag);
            let c = unit(g) * (w - 1.0);
            let r = unit(hash(g)) * (h - 1.0);
            kps[n] = keypoint(c as f32, r as f32, 2.0);
            for (j, o) in desc[n].iter_mut().enumerate() {
                *o = (hash(g ^ (j as u64 + 1)) % 256) as u8;
            }
            ids[n] = DISTRACTOR;
            n += 1;
        }
        // Shuffle so that neither index order nor image order tells the matcher anything.
        for i in (1..n).rev() {
            let j = (self.h(i as u64, tag ^ 0xABCD) % (i as u64 + 1)) as usize;
            kps.swap(i, j);
            desc.swap(i, j);
            ids.swap(i, j);
        }
        n
    }
}

fn keypoint(x: f32, y: f32, sigma: f32) -> Keypoint {
    Keypoint {
        x,
        y,
        sigma,
        orientation: 0.0,
        response: 0.02,
        octave: 0,
        cell: 0,
    }
}
