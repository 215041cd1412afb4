//! Real photographs as facade textures (`synth --photo-textures PATH[,PATH...]`): the
//! rendered streets then carry the texture statistics of real scenes, where a SIFT
//! odometry does best, instead of the procedural facades.
//!
//! Each photograph becomes a grey mip pyramid (2x2 box averages). A facade wears one of
//! them, chosen by its seed, at 1 to 3 cm per texel (also from the seed), upright,
//! mirrored at its edges so the tiling has no seams, and some facades mirror it
//! left-right. It is filtered over the pixel's footprint: trilinear over the footprint's
//! short axis, several taps along its long axis where the facade is seen obliquely (no
//! aliasing as the surface recedes).
use anyhow::{bail, Context, Result};

/// Size of one photograph texel on a facade, metres: from `TEXEL_M.0` to `TEXEL_M.1`.
pub const TEXEL_M: (f64, f64) = (0.01, 0.03);

/// Levels every photograph's pyramid holds at least (when its size allows): the
/// photograph is cropped to sides that are multiples of `2^EXACT_LEVELS`. Six levels
/// reach 64 texels (0.6 to 2 m) per pixel, beyond the widest footprint of a facade.
const EXACT_LEVELS: u32 = 6;

/// Most taps along the long axis of an oblique footprint (beyond, a coarser level).
const MAX_TAPS: usize = 8;

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

    /// The top-left part whose sides are multiples of `2^EXACT_LEVELS` (or of the
    /// largest power of two a smaller photograph allows), so that many levels halve
    /// it exactly (see [`pyramid`]).
    fn cropped_to_halve(self) -> Level {
        let side = self.w.min(self.h).max(1);
        let largest = 1usize << (usize::BITS - 1 - side.leading_zeros());
        let unit = largest.min(1 << EXACT_LEVELS);
        let (w, h) = (self.w / unit * unit, self.h / unit * unit);
        let data = (0..h)
            .flat_map(|y| self.data[y * self.w..y * self.w + w].iter().copied())
            .collect();
        Level { w, h, data }
    }

    /// The next coarser level (2x2 box average).
    fn halved(&self) -> Level {
        let (w, h) = (self.w / 2, self.h / 2);
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

/// Photographs as mip pyramids.
#[derive(Debug, Clone)]
pub struct Photos {
    pyramids: Vec<Vec<Level>>,
}

/// How one facade wears a photograph.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Placement {
    /// Which photograph (modulo the count).
    pub index: u32,
    /// Texel size on the facade, metres.
    pub texel_m: f64,
    /// Horizontal shift, metres.
    pub shift_m: f64,
    /// Mirrored left-right.
    pub mirrored: bool,
}

impl Placement {
    /// The placement of the facade with this seed.
    pub fn of(seed: u32) -> Placement {
        let h = super::noise::hash3(seed as i32, 17, 0x9e37);
        let t = (h >> 8) as f64 / 16_777_216.0;
        Placement {
            index: seed,
            texel_m: TEXEL_M.0 + (TEXEL_M.1 - TEXEL_M.0) * t,
            shift_m: (seed % 997) as f64 * 0.37,
            mirrored: h & 1 == 1,
        }
    }
}

/// The pixel footprint on a surface: `minor` metres across, stretched to `minor / cos`
/// along the unit direction `axis` (surface coordinates) by the obliquity.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Footprint {
    pub minor: f64,
    pub cos: f64,
    pub axis: [f64; 2],
}

impl Footprint {
    /// A round footprint `size` metres across.
    pub fn round(size: f64) -> Footprint {
        Footprint {
            minor: size,
            cos: 1.0,
            axis: [1.0, 0.0],
        }
    }
}

impl Photos {
    /// The photographs named by `paths`: image files, and every image file of the
    /// directories among them (sorted by name); in grey.
    pub fn load(paths: &[std::path::PathBuf]) -> Result<Photos> {
        let mut files = Vec::new();
        for path in paths {
            if path.is_dir() {
                let entries = std::fs::read_dir(path).with_context(|| {
                    format!("cannot read the photo texture directory {}", path.display())
                })?;
                let mut found: Vec<_> = entries
                    .filter_map(|e| e.ok().map(|e| e.path()))
                    .filter(|p| {
                        p.extension()
                            .and_then(|e| e.to_str())
                            .is_some_and(|e| EXTENSIONS.contains(&e.to_ascii_lowercase().as_str()))
                    })
                    .collect();
                found.sort();
                if found.is_empty() {
                    bail!("{}: no image files for photo textures", path.display());
                }
                files.extend(found);
            } else {
                files.push(path.clone());
            }
        }
        if files.is_empty() {
            bail!("no photographs for photo textures");
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
            pyramids.push(pyramid(Level { w, h, data }.cropped_to_halve()));
        }
        Ok(Photos { pyramids })
    }

    pub fn len(&self) -> usize {
        self.pyramids.len()
    }

    pub fn is_empty(&self) -> bool {
        self.pyramids.is_empty()
    }

    /// Grey value (0..1) of the photograph of `place` at facade coordinates `(u, v)`
    /// metres (v up) over the pixel footprint `fp`.
    pub fn sample(&self, place: &Placement, u: f64, v: f64, fp: &Footprint) -> f64 {
        let levels = &self.pyramids[place.index as usize % self.pyramids.len()];
        let texel = place.texel_m;
        let u = if place.mirrored { -u } else { u } + place.shift_m;
        // Long axis in texels (rows go down, v up; mirroring flips u).
        let cos = fp.cos.clamp(0.02, 1.0);
        let major = fp.minor / cos;
        let taps = ((1.0 / cos).ceil() as usize).clamp(1, MAX_TAPS);
        // Each tap covers major / taps along the long axis and the minor axis across.
        let width = fp.minor.max(major / taps as f64);
        let lod = (width / texel)
            .max(1.0)
            .log2()
            .min((levels.len() - 1) as f64);
        let l0 = lod.floor() as usize;
        let l1 = (l0 + 1).min(levels.len() - 1);
        let t = lod - l0 as f64;
        let (au, av) = (
            if place.mirrored {
                -fp.axis[0]
            } else {
                fp.axis[0]
            },
            fp.axis[1],
        );
        let mut sum = 0.0;
        for i in 0..taps {
            let o = major * ((i as f64 + 0.5) / taps as f64 - 0.5);
            // Upright: the photograph's bottom row stands at v = 0.
            let (x, y) = (
                (u + o * au) / texel,
                levels[0].h as f64 - 0.5 - (v + o * av) / texel,
            );
            let at = |l: usize| {
                let s = (1u64 << l) as f64;
                // Texel centres of level l sit at 2^l (i + 1/2) - 1/2 in level-0 texels.
                levels[l].bilinear((x + 0.5) / s - 0.5, (y + 0.5) / s - 0.5)
            };
            sum += at(l0) * (1.0 - t) + at(l1) * t;
        }
        sum / taps as f64
    }
}

/// The levels that halve `base` exactly. The texture tiles by mirroring, so a level's
/// period is twice its size: a level of an odd size (halved with the odd edge
/// mirrored, `ceil(n / 2)` texels) would repeat every `2 n + 2` texels of the base
/// instead of `2 n`, and be displaced from the finer levels by two texels more at each
/// tile. Blended with a finer level, as the footprint changes with distance, such a
/// displaced copy made the facades slide: a feature's rendered position moved by 0.06
/// px per epoch more than the camera's motion explains in the turns of `photo-curves`.
fn pyramid(base: Level) -> Vec<Level> {
    let mut levels = vec![base];
    while let Some(last) = levels
        .last()
        .filter(|l| l.w > 1 && l.h > 1 && l.w % 2 == 0 && l.h % 2 == 0)
    {
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

    const AT_2CM: Placement = Placement {
        index: 0,
        texel_m: 0.02,
        shift_m: 0.0,
        mirrored: false,
    };
    const T: f64 = 0.02;

    #[test]
    fn texels_are_sampled_exactly_and_mirrored() {
        let p = photos(4, 3, |x, y| (x + 10 * y) as f32 / 100.0);
        let sharp = Footprint::round(0.0);
        // Upright: the bottom row (2) is centred half a texel above the ground, row 1
        // a texel higher (v is up, rows go down).
        let v = p.sample(&AT_2CM, 2.0 * T, 1.5 * T, &sharp);
        assert!((v - 0.12).abs() < 1e-6, "{v}");
        // Mirrored: texel -1 is texel 0, texel 4 is texel 3.
        assert!((p.sample(&AT_2CM, -T, 0.5 * T, &sharp) - 0.20).abs() < 1e-6);
        assert!((p.sample(&AT_2CM, 4.0 * T, 0.5 * T, &sharp) - 0.23).abs() < 1e-6);
        // A facade mirrored left-right reads the photograph from the other side.
        let flipped = Placement {
            mirrored: true,
            ..AT_2CM
        };
        assert_eq!(
            p.sample(&flipped, -2.0 * T, 0.5 * T, &sharp),
            p.sample(&AT_2CM, 2.0 * T, 0.5 * T, &sharp)
        );
    }

    #[test]
    fn a_wide_footprint_averages_the_detail_away() {
        // A one-texel checkerboard: fine detail at level 0, uniform grey at level 1.
        let p = photos(64, 64, |x, y| ((x + y) % 2) as f32);
        let sharp: Vec<f64> = (0..8)
            .map(|i| p.sample(&AT_2CM, i as f64 * T, 0.0, &Footprint::round(0.0)))
            .collect();
        assert!(sharp.iter().any(|&v| v > 0.99) && sharp.iter().any(|&v| v < 0.01));
        for i in 0..8 {
            let v = p.sample(
                &AT_2CM,
                i as f64 * T * 1.37,
                0.3,
                &Footprint::round(2.0 * T),
            );
            assert!((v - 0.5).abs() < 1e-6, "{v}");
        }
    }

    #[test]
    fn an_oblique_footprint_averages_along_its_long_axis_only() {
        // Vertical one-texel stripes: they vary along u only.
        let p = photos(64, 64, |x, _| (x % 2) as f32);
        // Half a texel across, eight times longer along u: the stripes average out.
        let along_u = Footprint {
            minor: 0.5 * T,
            cos: 0.125,
            axis: [1.0, 0.0],
        };
        for i in 0..8 {
            let v = p.sample(&AT_2CM, (10.0 + 0.3 * i as f64) * T, 0.7, &along_u);
            assert!((v - 0.5).abs() < 1e-9, "{v}");
        }
        // The same footprint stretched along v keeps them sharp.
        let along_v = Footprint {
            axis: [0.0, 1.0],
            ..along_u
        };
        let v = p.sample(&AT_2CM, 11.0 * T, 0.7, &along_v);
        assert!((v - 1.0).abs() < 1e-9, "{v}");
    }

    #[test]
    fn every_level_repeats_with_the_photograph() {
        // An odd-sized photograph: cropped so that its levels halve it exactly.
        let (w, h) = (131, 70);
        let data = (0..w * h)
            .map(|i| ((i * 7919) % 251) as f32 / 250.0)
            .collect();
        let p = Photos {
            pyramids: vec![pyramid(Level { w, h, data }.cropped_to_halve())],
        };
        let sizes: Vec<_> = p.pyramids[0].iter().map(|l| (l.w, l.h)).collect();
        assert_eq!(sizes[..3], [(128, 64), (64, 32), (32, 16)]);
        // The tiling (mirrored, so a period of two photographs) is the same at every
        // level: ten periods along u the texture is the same at every footprint.
        let period = 2.0 * 128.0 * T;
        for lod in 0..6 {
            let fp = Footprint::round((1u64 << lod) as f64 * T * 1.2);
            for i in 0..20 {
                let (u, v) = (0.37 * i as f64, 0.41 + 0.05 * i as f64);
                let (a, b) = (
                    p.sample(&AT_2CM, u, v, &fp),
                    p.sample(&AT_2CM, u + 10.0 * period, v, &fp),
                );
                assert!((a - b).abs() < 1e-5, "level {lod}, u {u}: {a} vs {b}");
            }
        }
    }

    #[test]
    fn placements_vary_between_one_and_three_centimetres() {
        let ps: Vec<Placement> = (0..200).map(Placement::of).collect();
        assert!(ps.iter().all(|p| (0.01..=0.03).contains(&p.texel_m)));
        let (lo, hi) = ps.iter().fold((1.0f64, 0.0f64), |a, p| {
            (a.0.min(p.texel_m), a.1.max(p.texel_m))
        });
        assert!(lo < 0.012 && hi > 0.028, "{lo} {hi}");
        let mirrored = ps.iter().filter(|p| p.mirrored).count();
        assert!((60..140).contains(&mirrored), "{mirrored}");
    }

    #[test]
    fn a_directory_without_images_is_refused_by_name() {
        let t = tempfile::tempdir().unwrap();
        let e = Photos::load(&[t.path().to_path_buf()])
            .unwrap_err()
            .to_string();
        assert!(e.contains("no image files"), "{e}");
        assert!(Photos::load(&[t.path().join("missing")]).is_err());
        assert!(Photos::load(&[]).is_err());
    }
}
