//! Ray-casting renderer: per pixel, `Interior::pixel_to_corrected` gives the
//! ray `M^T (xc, yc, -f)`; the nearest primitive is shaded with its
//! footprint-filtered texture.
//!
//! Speed: primitives are clipped against the near plane, projected (in
//! corrected photo-coordinates, where a convex polygon stays convex) and
//! binned into 8x8-pixel tiles, sorted by their nearest depth so a pixel
//! stops at the first candidate farther than its current hit. One ray per
//! pixel finds the visible primitive; pixels whose neighbours see another
//! primitive (silhouettes) are re-rendered with `edge_ss x edge_ss` rays.
//! Texture is area-filtered analytically, so interiors need no supersampling.
use super::geometry::V3;
use super::material::{shade, sky, Surface};
use super::scene::{Primitive, Scene};
use phototraverse_core::camera::{Interior, Pose};
use rayon::prelude::*;

const TILE: usize = 8;
/// Near plane, metres.
const NEAR: f64 = 0.05;
const SKY_ID: u32 = u32::MAX;

/// Renderer settings.
#[derive(Debug, Clone, Copy)]
pub struct RenderSettings {
    /// Rays per side on silhouette pixels (1 = no supersampling).
    pub edge_ss: u32,
    /// Primitives farther than this (metres) are not drawn.
    pub max_distance: f64,
    /// Also compute depth.
    pub depth: bool,
}

impl Default for RenderSettings {
    fn default() -> Self {
        RenderSettings {
            edge_ss: 3,
            max_distance: 400.0,
            depth: true,
        }
    }
}

/// A rendered image.
#[derive(Debug, Clone)]
pub struct Rendered {
    pub width: usize,
    pub height: usize,
    /// Linear radiance, row-major.
    pub radiance: Vec<f32>,
    /// Distance along the camera's -z axis at each pixel centre, metres
    /// (`f32::INFINITY` for sky); empty unless requested.
    pub depth: Vec<f32>,
    /// Pixels that were supersampled.
    pub edge_pixels: usize,
    /// Pixels whose centre sees one of the `extra` primitives (moving objects).
    pub moving_pixels: usize,
}

struct Frame<'a> {
    scene: &'a Scene,
    prims: Vec<&'a Primitive>,
    cam: &'a Interior,
    /// Camera to object rotation `M^T`.
    mt: nalgebra::Matrix3<f64>,
    origin: V3,
    /// Angular size of a pixel (rad), for footprints.
    pixel_angle: f64,
    tiles_x: usize,
    /// Candidate primitive indices per tile, nearest first.
    bins: Vec<Vec<u32>>,
    /// Nearest depth of each primitive in `prims`.
    near: Vec<f64>,
    /// Index in `prims` of the first of the `extra` primitives.
    first_extra: u32,
}

/// Renders `scene` plus `extra` primitives (moving objects) from `pose` with camera `cam`.
pub fn render(
    scene: &Scene,
    extra: &[Primitive],
    cam: &Interior,
    pose: &Pose,
    settings: &RenderSettings,
) -> Rendered {
    let (w, h) = (cam.width_px as usize, cam.height_px as usize);
    let frame = Frame::new(scene, extra, cam, pose, settings);
    let mut radiance = vec![0.0f32; w * h];
    let mut ids = vec![SKY_ID; w * h];
    let mut depth = vec![f32::INFINITY; w * h];

    // Pass 1: one ray per pixel centre.
    let moving_pixels = radiance
        .par_chunks_mut(w)
        .zip(ids.par_chunks_mut(w))
        .zip(depth.par_chunks_mut(w))
        .enumerate()
        .map(|(r, ((rad, id), dep))| {
            let mut moving = 0;
            for c in 0..w {
                let (v, pid, z) = frame.sample(c as f64, r as f64, 1.0);
                rad[c] = v as f32;
                id[c] = if pid == SKY_ID {
                    SKY_ID
                } else {
                    moving += usize::from(pid >= frame.first_extra);
                    frame.prims[pid as usize].group
                };
                dep[c] = z as f32;
            }
            moving
        })
        .sum();
    if !settings.depth {
        depth = Vec::new();
    }
    // Pass 2: silhouettes (the object changes between neighbours) get n x n rays.
    let n = settings.edge_ss.max(1) as usize;
    let mut edge_pixels = 0;
    if n > 1 {
        let ids = &ids;
        edge_pixels = radiance
            .par_chunks_mut(w)
            .enumerate()
            .map(|(r, rad)| {
                let mut count = 0;
                for c in 0..w {
                    let me = ids[r * w + c];
                    let differs = (c > 0 && ids[r * w + c - 1] != me)
                        || (c + 1 < w && ids[r * w + c + 1] != me)
                        || (r > 0 && ids[(r - 1) * w + c] != me)
                        || (r + 1 < h && ids[(r + 1) * w + c] != me);
                    if !differs {
                        continue;
                    }
                    count += 1;
                    let mut acc = 0.0;
                    for i in 0..n {
                        for j in 0..n {
                            let dc = (j as f64 + 0.5) / n as f64 - 0.5;
                            let dr = (i as f64 + 0.5) / n as f64 - 0.5;
                            acc += frame.sample(c as f64 + dc, r as f64 + dr, n as f64).0;
                        }
                    }
                    rad[c] = (acc / (n * n) as f64) as f32;
                }
                count
            })
            .sum();
    }
    Rendered {
        width: w,
        height: h,
        radiance,
        depth,
        edge_pixels,
        moving_pixels,
    }
}

impl<'a> Frame<'a> {
    fn new(
        scene: &'a Scene,
        extra: &'a [Primitive],
        cam: &'a Interior,
        pose: &Pose,
        settings: &RenderSettings,
    ) -> Self {
        let m = pose.rotation();
        let origin = pose.centre_vec();
        let (w, h) = (cam.width_px as usize, cam.height_px as usize);
        let tiles_x = w.div_ceil(TILE);
        let tiles_y = h.div_ceil(TILE);
        // Tile extents in corrected photo-coordinates (pixel corners along the tile border).
        let mut tile_box = vec![[f64::MAX, f64::MAX, f64::MIN, f64::MIN]; tiles_x * tiles_y];
        for (t, bx) in tile_box.iter_mut().enumerate() {
            let (tx, ty) = (t % tiles_x, t / tiles_x);
            let c0 = (tx * TILE) as f64 - 0.5;
            let c1 = (((tx + 1) * TILE).min(w)) as f64 - 0.5;
            let r0 = (ty * TILE) as f64 - 0.5;
            let r1 = (((ty + 1) * TILE).min(h)) as f64 - 0.5;
            let mut add = |c: f64, r: f64| {
                let [x, y] = cam.pixel_to_corrected(c, r);
                bx[0] = bx[0].min(x);
                bx[1] = bx[1].min(y);
                bx[2] = bx[2].max(x);
                bx[3] = bx[3].max(y);
            };
            let steps = TILE;
            for k in 0..=steps {
                let a = k as f64 / steps as f64;
                add(c0 + (c1 - c0) * a, r0);
                add(c0 + (c1 - c0) * a, r1);
                add(c0, r0 + (r1 - r0) * a);
                add(c1, r0 + (r1 - r0) * a);
            }
            // Distortion curvature between samples: a small margin (one pixel).
            let mx = cam.pixel_size_mm[0];
            let my = cam.pixel_size_mm[1];
            bx[0] -= mx;
            bx[1] -= my;
            bx[2] += mx;
            bx[3] += my;
        }
        let image_box = tile_box
            .iter()
            .fold([f64::MAX, f64::MAX, f64::MIN, f64::MIN], |a, b| {
                [
                    a[0].min(b[0]),
                    a[1].min(b[1]),
                    a[2].max(b[2]),
                    a[3].max(b[3]),
                ]
            });

        // Extents of each tile column (x) and row (y) over the whole image.
        let mut col_ext = vec![[f64::MAX, f64::MIN]; tiles_x];
        let mut row_ext = vec![[f64::MAX, f64::MIN]; tiles_y];
        for (t, b) in tile_box.iter().enumerate() {
            let (tx, ty) = (t % tiles_x, t / tiles_x);
            col_ext[tx] = [col_ext[tx][0].min(b[0]), col_ext[tx][1].max(b[2])];
            row_ext[ty] = [row_ext[ty][0].min(b[1]), row_ext[ty][1].max(b[3])];
        }
        let f = cam.focal_mm;
        let mut prims = Vec::new();
        let mut near = Vec::new();
        let mut bins: Vec<Vec<u32>> = vec![Vec::new(); tiles_x * tiles_y];
        let mut hull = Vec::with_capacity(8);
        let mut proj: Vec<[f64; 2]> = Vec::with_capacity(16);
        let mut first_extra = None;
        for (n, p) in scene.prims.iter().chain(extra.iter()).enumerate() {
            if n == scene.prims.len() {
                first_extra = Some(prims.len() as u32);
            }
            let edges = p.shape.hull(&mut hull);
            // Camera frame: depth is -w.
            let cam_pts: Vec<V3> = hull.iter().map(|q| m * (q - origin)).collect();
            let depth_min = cam_pts.iter().map(|q| -q[2]).fold(f64::MAX, f64::min);
            let depth_max = cam_pts.iter().map(|q| -q[2]).fold(f64::MIN, f64::max);
            if depth_max < NEAR || depth_min > settings.max_distance {
                continue;
            }
            proj.clear();
            let project = |q: &V3| [-f * q[0] / q[2], -f * q[1] / q[2]];
            for q in &cam_pts {
                if -q[2] >= NEAR {
                    proj.push(project(q));
                }
            }
            // Near-plane crossings of the hull's edges bound the clipped part.
            for &(a, b) in edges {
                let (qa, qb) = (cam_pts[a as usize], cam_pts[b as usize]);
                let (da, db) = (-qa[2] - NEAR, -qb[2] - NEAR);
                if (da < 0.0) != (db < 0.0) {
                    let t = da / (da - db);
                    proj.push(project(&(qa + (qb - qa) * t)));
                }
            }
            let mut bb = [f64::MAX, f64::MAX, f64::MIN, f64::MIN];
            for q in &proj {
                bb = [
                    bb[0].min(q[0]),
                    bb[1].min(q[1]),
                    bb[2].max(q[0]),
                    bb[3].max(q[1]),
                ];
            }
            if bb[2] < image_box[0]
                || bb[0] > image_box[2]
                || bb[3] < image_box[1]
                || bb[1] > image_box[3]
            {
                continue;
            }
            let index = prims.len() as u32;
            prims.push(p);
            near.push(depth_min.max(0.0));
            // Tile columns and rows whose extents can overlap, then the exact test.
            let cols = col_ext
                .iter()
                .enumerate()
                .filter(|(_, e)| bb[2] >= e[0] && bb[0] <= e[1])
                .map(|(i, _)| i);
            let (c0, c1) = cols.fold((usize::MAX, 0), |a, i| (a.0.min(i), a.1.max(i)));
            let rows = row_ext
                .iter()
                .enumerate()
                .filter(|(_, e)| bb[3] >= e[0] && bb[1] <= e[1])
                .map(|(i, _)| i);
            let (r0, r1) = rows.fold((usize::MAX, 0), |a, i| (a.0.min(i), a.1.max(i)));
            if c0 == usize::MAX || r0 == usize::MAX {
                continue;
            }
            for ty in r0..=r1 {
                for tx in c0..=c1 {
                    let t = ty * tiles_x + tx;
                    let tb = &tile_box[t];
                    if bb[2] >= tb[0] && bb[0] <= tb[2] && bb[3] >= tb[1] && bb[1] <= tb[3] {
                        bins[t].push(index);
                    }
                }
            }
        }
        for bin in &mut bins {
            bin.sort_by(|a, b| near[*a as usize].total_cmp(&near[*b as usize]));
        }
        let pixel_angle = cam.pixel_size_mm[0].max(cam.pixel_size_mm[1]) / f;
        Frame {
            scene,
            prims,
            cam,
            mt: m.transpose(),
            origin,
            pixel_angle,
            tiles_x,
            bins,
            near,
            first_extra: first_extra.unwrap_or(u32::MAX),
        }
    }

    /// Radiance, primitive id and depth along the ray through pixel `(c, r)`;
    /// `ss` rays per pixel side shrink the texture footprint accordingly.
    #[inline]
    fn sample(&self, c: f64, r: f64, ss: f64) -> (f64, u32, f64) {
        let [xc, yc] = self.cam.pixel_to_corrected(c, r);
        let dir_cam = V3::new(xc, yc, -self.cam.focal_mm);
        let norm = dir_cam.norm();
        let d = self.mt * (dir_cam / norm);
        let tc = ((c + 0.5).max(0.0) as usize / TILE).min(self.tiles_x - 1);
        let tr = ((r + 0.5).max(0.0) as usize / TILE).min(self.bins.len() / self.tiles_x - 1);
        let mut best_t = f64::INFINITY;
        let mut best = None;
        for &i in &self.bins[tr * self.tiles_x + tc] {
            // Along a unit ray, t >= depth: nothing farther can be nearer.
            if self.near[i as usize] > best_t {
                break;
            }
            if let Some(hit) = self.prims[i as usize]
                .shape
                .intersect(&self.origin, &d, best_t)
            {
                best_t = hit.t;
                best = Some((i, hit));
            }
        }
        let Some((i, hit)) = best else {
            return (sky(&self.scene.sky, &d), SKY_ID, f64::INFINITY);
        };
        let p = self.prims[i as usize];
        // Footprint: pixel size at distance t, stretched by obliquity (geometric mean of the axes).
        let footprint =
            hit.t * self.pixel_angle * (norm / self.cam.focal_mm) / hit.cos.max(0.02).sqrt() / ss;
        let surface = Surface {
            hit: &hit,
            point: self.origin + d * hit.t,
            footprint,
            path: self.scene.path.as_ref(),
            textureless: self.scene.textureless,
            flat: p.flat,
            photos: self.scene.photos.as_deref(),
            ray: d,
        };
        let depth = hit.t * self.cam.focal_mm / norm;
        (shade(&p.material, &surface, &self.scene.light), i, depth)
    }
}
