//! Real photographs as facade textures (`synth --photo-textures DIR`): the rendered
//! streets then carry the texture statistics of real scenes, where a SIFT odometry does
//! best, instead of the procedural facades.
//!
//! Each photograph becomes a grey mip pyramid (2x2 box averages); a facade samples one
//! of them, chosen by its seed, at [`TEXEL_M`] per texel, mirrored at the edges so the
//! tiling has no seams, with trilinear filtering over the pixel's footprint (no
//! aliasing as the surface recedes).
use anyhow::{bail, Context, Result};
use std::path::Path;

/// Size of one photograph texel on a facade, metres (the middle of 1-3 cm).
pub const TEXEL_M: f64 = 0.02;

/// Image files taken from the directory.
const EXTENSIONS: &[&str] = &["png", "jpg", "jpeg", "pgm", "ppm", "bmp", "tif", "tiff"];

/// One level of a pyramid: grey values 0..1, row by row.
#[derive(Debug, Clone)]
struct Level {
    w: usize,
    h: usize,
    data: Vec<f32>,
}

impl Level {
    /// The value at whole texel `(x, y)`, mirrored outside the image.
    fn at(&self, x: i64, y: i64) -> f32 {
        let m = |v: i64, n: usize| {
            let n = n as i64;
            let p = v.rem_euclid(2 * n);
            (if p < n { p } else { 2 * n - 1 - p }) as usize
        };
        self.data[m(y, self.h) * self.w + m(x, self.w)]
    }

    /// Bilinear value at texel coordinates (texel centres at integers).
    fn bilinear(&self, x: f64, y: f64) -> f64 {
        let (x0, y0) = (x.floor(), y.floor());
        let (fx, fy) = (x - x0, y - y0);
        let (ix, iy) = (x0 as i64, y0 as i64);
        let top = self.at(ix, iy) as f64 * (1.0 - fx) + self.at(ix + 1, iy) as f64 * fx;
        let bot = self.at(ix, iy + 1) as f64 * (1.0 - fx) + self.at(ix + 1, iy + 1) as f64 * fx;
        top * (1.0 - fy) + bot * fy
    }

    /// The next coarser level (2x2 box average, odd edges mirrored).
    fn halved(&self) -> Level {
        let (w, h) = (self.w.div_ceil(2), self.h.div_ceil(2));
        let mut data = Vec::with_capacity(w * h);
        for y in 0..h as i64 {
            for x in 0..w as i64 {
                let s = self.at(2 * x, 2 * y)
                    + self.at(2 * x + 1, 2 * y)
                    + self.at(2 * x, 2 * y + 1)
                    + self.at(2 * x + 1, 2 * y + 1);
                data.push(0.25 * s);
            }
        }
        Level { w, h, data }
    }
}

/// The photographs of a directory as mip pyramids.
#[derive(Debug, Clone)]
pub struct Photos {
    pyramids: Vec<Vec<Level>>,
}

impl Photos {
    /// Every image file of `dir` (sorted by name), in grey.
    pub fn load(dir: &Path) -> Result<Photos> {
        let entries = std::fs::read_dir(dir).with_context(|| {
            format!("cannot read the photo texture directory {}", dir.display())
        })?;
        let mut files: Vec<_> = entries
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| {
                p.extension()
                    .and_then(|e| e.to_str())
                    .is_some_and(|e| EXTENSIONS.contains(&e.to_ascii_lowercase().as_str()))
            })
            .collect();
        files.sort();
        if files.is_empty() {
            bail!("{}: no image files for photo textures", dir.display());
        }
        let mut pyramids = Vec::new();
        for f in &files {
            let img = image::open(f)
                .with_context(|| format!("cannot read the photo texture {}", f.display()))?
                .into_luma8();
            let (w, h) = (img.width() as usize, img.height() as usize);
            if w < 2 || h < 2 {
                bail!("{}: a photo texture needs at least 2x2 pixels", f.display());
            }
            let data = img.as_raw().iter().map(|&v| v as f32 / 255.0).collect();
            pyramids.push(pyramid(Level { w, h, data }));
        }
        Ok(Photos { pyramids })
    }

    pub fn len(&self) -> usize {
        self.pyramids.len()
    }

    pub fn is_empty(&self) -> bool {
        self.pyramids.is_empty()
    }

    /// Grey value (0..1) of photograph `index` (modulo the count) at facade coordinates
    /// `(u, v)` metres (v up), for a pixel footprint of `footprint` metres.
    pub fn sample(&self, index: u32, u: f64, v: f64, footprint: f64) -> f64 {
        let levels = &self.pyramids[index as usize % self.pyramids.len()];
        // Upright: the photograph's bottom row stands on the ground (v = 0).
        let (x, y) = (u / TEXEL_M, levels[0].h as f64 - 0.5 - v / TEXEL_M);
        // Mip level: texels per pixel footprint, log2.
        let lod = (footprint / TEXEL_M)
            .max(1.0)
            .log2()
            .min((levels.len() - 1) as f64);
        let l0 = lod.floor() as usize;
        let l1 = (l0 + 1).min(levels.len() - 1);
        let t = lod - l0 as f64;
        let at = |l: usize| {
            let s = (1u64 << l) as f64;
            // Texel centres of level l sit at 2^l (i + 1/2) - 1/2 in level-0 texels.
            levels[l].bilinear((x + 0.5) / s - 0.5, (y + 0.5) / s - 0.5)
        };
        at(l0) * (1.0 - t) + at(l1) * t
    }
}

fn pyramid(base: Level) -> Vec<Level> {
    let mut levels = vec![base];
    while let Some(last) = levels.last().filter(|l| l.w > 1 || l.h > 1) {
        let next = last.halved();
        levels.push(next);
    }
    levels
}

#[cfg(test)]
mod tests {
    use super::*;

    fn photos(w: usize, h: usize, f: impl Fn(usize, usize) -> f32) -> Photos {
        let data = (0..w * h).map(|i| f(i % w, i / w)).collect();
        Photos {
            pyramids: vec![pyramid(Level { w, h, data })],
        }
    }

    #[test]
    fn texels_are_sampled_exactly_and_mirrored() {
        let p = photos(4, 3, |x, y| (x + 10 * y) as f32 / 100.0);
        // Upright: the bottom row (2) is centred half a texel above the ground, row 1
        // a texel higher (v is up, rows go down).
        let v = p.sample(0, 2.0 * TEXEL_M, 1.5 * TEXEL_M, 0.0);
        assert!((v - 0.12).abs() < 1e-6, "{v}");
        // Mirrored: texel -1 is texel 0, texel 4 is texel 3.
        assert!((p.sample(0, -TEXEL_M, 0.5 * TEXEL_M, 0.0) - 0.20).abs() < 1e-6);
        assert!((p.sample(0, 4.0 * TEXEL_M, 0.5 * TEXEL_M, 0.0) - 0.23).abs() < 1e-6);
    }

    #[test]
    fn a_wide_footprint_averages_the_detail_away() {
        // A one-texel checkerboard: fine detail at level 0, uniform grey at level 1.
        let p = photos(64, 64, |x, y| ((x + y) % 2) as f32);
        let sharp: Vec<f64> = (0..8)
            .map(|i| p.sample(0, i as f64 * TEXEL_M, 0.0, 0.0))
            .collect();
        assert!(sharp.iter().any(|&v| v > 0.99) && sharp.iter().any(|&v| v < 0.01));
        for i in 0..8 {
            let v = p.sample(0, i as f64 * TEXEL_M * 1.37, 0.3, 2.0 * TEXEL_M);
            assert!((v - 0.5).abs() < 1e-6, "{v}");
        }
    }

    #[test]
    fn a_directory_without_images_is_refused_by_name() {
        let t = tempfile::tempdir().unwrap();
        let e = Photos::load(t.path()).unwrap_err().to_string();
        assert!(e.contains("no image files"), "{e}");
        assert!(Photos::load(&t.path().join("missing")).is_err());
    }
}
