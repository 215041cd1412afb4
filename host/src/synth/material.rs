//! Surface appearance: procedural, deterministic, footprint-filtered albedo
//! and a simple sun + sky lighting. Intensities are linear, about 0..1.
use super::geometry::{Hit, V3};
use super::noise::{band_weight, fast_floor, fbm, periodic, stripe, unit, value2};
use super::path::StreetPath;
use super::photo::{Footprint, Placement};

/// What a primitive looks like.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Material {
    /// Road and sidewalks; texture and markings from the street coordinates
    /// `(s, d)` of the path segment `segment`.
    Ground { segment: u32 },
    /// A building facade; `u0` offsets the horizontal texture coordinate so
    /// neighbouring pieces continue, `brick` selects bricks over plaster.
    Facade {
        seed: u32,
        shade: f32,
        brick: bool,
        window_w: f32,
        window_pitch: f32,
        floor_h: f32,
        u0: f32,
    },
    /// Car body panel.
    Car { seed: u32, shade: f32 },
    /// Car glass (dark, slightly reflective).
    Glass { seed: u32 },
    /// A pole.
    Pole { seed: u32 },
    /// Open ground (grass and soil) from the world coordinates.
    Field { seed: u32 },
    /// A plain roadway (cross streets) from the world coordinates.
    Asphalt { seed: u32 },
    /// Uniform albedo, lit.
    Flat { shade: f32 },
    /// Uniform radiance, unlit (test targets).
    Emissive { value: f32 },
}

/// The sky.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Sky {
    /// Gradient with faint clouds.
    Day { seed: u32 },
    /// Constant radiance (tests).
    Constant(f32),
}

/// Lighting of the scene.
#[derive(Debug, Clone, Copy)]
pub struct Light {
    /// Unit vector towards the sun.
    pub sun: V3,
    pub ambient: f64,
    pub direct: f64,
}

impl Default for Light {
    fn default() -> Self {
        Light {
            sun: V3::new(0.45, -0.35, 0.82).normalize(),
            ambient: 0.45,
            direct: 0.65,
        }
    }
}

/// Context for texturing a hit.
pub struct Surface<'a> {
    pub hit: &'a Hit,
    pub point: V3,
    /// Pixel footprint on the surface, metres.
    pub footprint: f64,
    pub path: Option<&'a StreetPath>,
    /// The street range `[s0, s1)` whose surfaces have no texture (the `hard` scene).
    pub textureless: Option<(f64, f64)>,
    /// The primitive lies in the textureless range.
    pub flat: bool,
    /// Photographs for the facades, when the scene has them.
    pub photos: Option<&'a super::photo::Photos>,
    /// Unit direction of the ray that hit.
    pub ray: V3,
}

/// Radiance of a hit.
pub fn shade(m: &Material, s: &Surface, light: &Light) -> f64 {
    if let Material::Emissive { value } = m {
        return *value as f64;
    }
    let albedo = if s.flat { flat_albedo(m) } else { albedo(m, s) };
    let lambert = s.hit.normal.dot(&light.sun).max(0.0);
    albedo * (light.ambient + light.direct * lambert)
}

fn flat_albedo(m: &Material) -> f64 {
    match m {
        Material::Ground { .. } => 0.33,
        Material::Facade { shade, .. } | Material::Car { shade, .. } | Material::Flat { shade } => {
            *shade as f64
        }
        Material::Glass { .. } => 0.15,
        Material::Pole { .. } => 0.45,
        Material::Field { .. } => 0.3,
        Material::Asphalt { .. } => 0.3,
        Material::Emissive { value } => *value as f64,
    }
}

fn albedo(m: &Material, s: &Surface) -> f64 {
    let fp = s.footprint;
    match *m {
        Material::Ground { segment } => ground(segment, s),
        Material::Facade {
            seed,
            shade,
            brick,
            window_w,
            window_pitch,
            floor_h,
            u0,
        } => {
            let (u, v) = (s.hit.uv[0] + u0 as f64, s.hit.uv[1]);
            if let Some(photos) = s.photos {
                // Each facade its own photograph, scale and place in it; the shade keeps
                // neighbouring buildings apart.
                let grey = photos.sample(&Placement::of(seed), u, v, &facade_footprint(s));
                return (0.1 + 0.9 * grey) * (0.6 + 0.6 * shade as f64);
            }
            facade(
                seed,
                shade as f64,
                brick,
                window_w as f64,
                window_pitch as f64,
                floor_h as f64,
                u,
                v,
                fp,
            )
        }
        Material::Car { seed, shade } => {
            let (u, v) = (s.hit.uv[0], s.hit.uv[1]);
            let grime = fbm(u, v, seed, 0.8, 3, 0.6, fp);
            (shade as f64 * (1.0 + 0.25 * grime)).clamp(0.02, 1.0)
        }
        Material::Glass { seed } => {
            let (u, v) = (s.hit.uv[0], s.hit.uv[1]);
            0.12 + 0.08 * fbm(u, v, seed, 0.6, 4, 0.6, fp)
        }
        Material::Pole { seed } => {
            let (u, v) = (s.hit.uv[0], s.hit.uv[1]);
            0.45 + 0.12 * fbm(u * 4.0, v, seed, 0.5, 3, 0.6, fp)
        }
        Material::Field { seed } => field(seed, s),
        Material::Asphalt { seed } => asphalt(seed, s),
        Material::Flat { shade } => shade as f64,
        Material::Emissive { value } => value as f64,
    }
}

/// Open ground: fields of their own shade tens of metres across, grass and soil
/// from metres down to tufts of a few centimetres.
fn field(seed: u32, s: &Surface) -> f64 {
    let (x, y) = (s.point[0], s.point[1]);
    let fp = s.footprint;
    let fields = fbm(x, y, seed, 60.0, 3, 0.5, fp);
    let soil = fbm(x, y, seed ^ 0x3c, 6.0, 4, 0.6, fp);
    let grass = fbm(x, y, seed ^ 0x5d, 0.8, 6, 0.7, fp);
    let tufts = band_weight(0.03, fp) * value2(x * 33.0, y * 33.0, seed ^ 0x7e);
    (0.27 * (1.0 + 0.3 * fields) * (1.0 + 0.25 * soil) * (1.0 + 0.3 * grass + 0.12 * tufts))
        .clamp(0.03, 1.0)
}

/// A roadway without markings: grain, stones and repair patches.
fn asphalt(seed: u32, s: &Surface) -> f64 {
    let (x, y) = (s.point[0], s.point[1]);
    let fp = s.footprint;
    let stones = band_weight(0.02, fp) * value2(x * 50.0, y * 50.0, seed ^ 0x11);
    let grain = fbm(x, y, seed, 1.5, 5, 0.75, fp) + 0.5 * stones;
    let patch = if value2(x / 7.0, y / 7.0, seed ^ 0x22) > 0.45 {
        0.8
    } else {
        1.0
    };
    0.30 * patch * (1.0 + 0.35 * grain)
}

/// The pixel footprint on a facade (u horizontal, v up): `Surface::footprint` is
/// its geometric mean `minor / sqrt(cos)`; the long axis is the ray's direction
/// within the facade's plane.
fn facade_footprint(s: &Surface) -> Footprint {
    let n = s.hit.normal;
    let cos = s.hit.cos.clamp(0.02, 1.0);
    let in_plane = s.ray - n * n.dot(&s.ray);
    let horizontal = V3::z().cross(&n);
    let (a, b) = (in_plane.dot(&horizontal), in_plane[2]);
    let len = (a * a + b * b).sqrt();
    Footprint {
        minor: s.footprint * cos.sqrt(),
        cos,
        axis: if len > 1e-9 {
            [a / len, b / len]
        } else {
            [1.0, 0.0]
        },
    }
}

/// Road, markings and sidewalks from the street coordinates.
fn ground(segment: u32, s: &Surface) -> f64 {
    let (x, y) = (s.point[0], s.point[1]);
    let fp = s.footprint;
    let Some(path) = s.path else { return 0.33 };
    let (sa, d) = path.local(segment as usize, [x, y]);
    if let Some((a, b)) = s.textureless {
        if sa >= a && sa < b {
            return 0.33;
        }
    }
    let ad = d.abs();
    if ad > 5.0 {
        // Sidewalk: 0.5 m slabs, each with its own shade, grout lines, grain.
        let (gu, gv) = (sa / 0.5, (ad - 5.0) / 0.5);
        let (iu, iv) = (fast_floor(gu), fast_floor(gv));
        let w_slab = band_weight(0.5, fp);
        let slab = 0.5 + 0.1 * (unit(iu, iv, 77) - 0.5) * w_slab;
        let grout_u = periodic(sa + 0.015, 0.03, 0.5, fp);
        let grout_v = periodic(ad - 5.0 + 0.015, 0.03, 0.5, fp);
        let grout = 1.0 - (1.0 - grout_u) * (1.0 - grout_v);
        let grain = fbm(x, y, 91, 1.0, 5, 0.7, fp);
        let kerb = stripe(ad - 5.075, 0.075, fp);
        let base = slab * (1.0 - 0.4 * grout) * (1.0 + 0.25 * grain);
        return base * (1.0 - kerb) + 0.7 * kerb;
    }
    // Asphalt: multi-scale grain, repair patches, tyre darkening.
    // Aggregate: one fine octave (2 cm stones) on top of the band-limited fBm.
    let stones = band_weight(0.02, fp) * value2(x * 50.0, y * 50.0, 17);
    let grain = fbm(x, y, 13, 1.5, 5, 0.75, fp) + 0.5 * stones;
    let patch = value2(x / 7.0, y / 7.0, 29);
    let patch = if patch > 0.45 { 0.8 } else { 1.0 };
    let tyre = 1.0 - 0.08 * (stripe(ad - 1.75 + 0.8, 0.35, fp) + stripe(ad - 1.75 - 0.8, 0.35, fp));
    let mut v = 0.30 * patch * tyre * (1.0 + 0.35 * grain);
    // Markings: dashed centre line (3 m on, 6 m off), solid edge lines, zebra every 90 m.
    let centre = stripe(d, 0.075, fp) * periodic(sa.rem_euclid(9.0), 3.0, 9.0, fp);
    let edge = stripe(ad - 3.5, 0.075, fp);
    let zebra_s = (sa - 45.0).rem_euclid(90.0);
    let zebra = if zebra_s < 4.0 && ad < 3.3 {
        stripe(zebra_s - 2.0, 2.0, fp) * periodic(d + 10.0, 0.5, 1.0, fp)
    } else {
        0.0
    };
    let cover = (centre + edge + zebra).min(1.0);
    if cover > 0.0 {
        let paint = 0.8 + 0.05 * fbm(x, y, 5, 0.3, 4, 0.6, fp);
        v = v * (1.0 - cover) + paint * cover;
    }
    v
}

/// A facade: plaster or bricks, a grid of windows with frames and sills,
/// a ground floor with shop windows, dirt at large scale.
#[allow(clippy::too_many_arguments)]
fn facade(
    seed: u32,
    shade: f64,
    brick: bool,
    win_w: f64,
    pitch: f64,
    floor_h: f64,
    u: f64,
    v: f64,
    fp: f64,
) -> f64 {
    let dirt = fbm(u, v, seed ^ 0x55, 6.0, 3, 0.5, fp);
    let mut wall = shade * (1.0 + 0.18 * dirt);
    if brick {
        // 0.25 x 0.075 m bricks in running bond, mortar lines, per-brick shade.
        let row = fast_floor(v / 0.075) as f64;
        let off = if (row as i64) % 2 == 0 { 0.0 } else { 0.125 };
        let col = fast_floor((u + off) / 0.25) as f64;
        let w = band_weight(0.075, fp);
        let b = (unit(col as i32, row as i32, seed) - 0.5) * 0.35 * w;
        let mortar = 1.0
            - (1.0 - periodic(v, 0.012, 0.075, fp)) * (1.0 - periodic(u + off, 0.012, 0.25, fp));
        wall *= (1.0 + b) * (1.0 - 0.35 * mortar * w.max(0.3));
    } else {
        wall *= 1.0 + 0.2 * fbm(u, v, seed, 1.0, 5, 0.75, fp);
    }
    // Windows: per-floor grid, each window its own glass shade.
    let floor = fast_floor(v / floor_h) as f64;
    let fu = fast_floor(u / pitch) as f64;
    let (wu, wv) = (
        u - fu * pitch - 0.5 * (pitch - win_w),
        v - floor * floor_h - 0.9,
    );
    let win_h = floor_h * 0.5;
    let shop = floor < 1.0;
    let (ww, wh) = if shop {
        (pitch * 0.8, floor_h * 0.65)
    } else {
        (win_w, win_h)
    };
    let wu = if shop {
        u - fu * pitch - 0.1 * pitch
    } else {
        wu
    };
    let wv = if shop { v - 0.3 } else { wv };
    let inside_u = periodic(wu, ww, 1e9, fp);
    let inside_v = periodic(wv, wh, 1e9, fp);
    let frame_u = periodic(wu + 0.08, ww + 0.16, 1e9, fp);
    let frame_v = periodic(wv + 0.08, wh + 0.16, 1e9, fp);
    let glass_shade = 0.08 + 0.3 * unit(fu as i32, floor as i32, seed ^ 0xabc);
    let in_glass = inside_u * inside_v;
    let reflection = if in_glass > 0.0 {
        0.06 * fbm(u, v, seed ^ 0x77, 0.8, 4, 0.6, fp)
    } else {
        0.0
    };
    let glass = glass_shade + reflection;
    let in_frame = (frame_u * frame_v - in_glass).max(0.0);
    // A few windows have bars or curtains: a mid-tone inner pattern.
    let curtain = if unit(fu as i32, floor as i32, seed ^ 0x123) > 0.7 {
        0.25 * periodic(wu, 0.1, 0.3, fp)
    } else {
        0.0
    };
    let frame = 0.85 - 0.5 * shade;
    wall * (1.0 - in_glass - in_frame) + (glass + curtain) * in_glass + frame * in_frame
}

/// Radiance of the sky along unit direction `d`.
pub fn sky(sky: &Sky, d: &V3) -> f64 {
    match sky {
        Sky::Constant(v) => *v as f64,
        Sky::Day { seed } => {
            let elev = d[2].clamp(-1.0, 1.0);
            let base = 0.95 - 0.3 * elev.max(0.0);
            if elev <= 0.01 {
                return base;
            }
            // Clouds on a plane 1 km up; their projection fades near the horizon.
            let k = 1000.0 / elev;
            let c = fbm(d[0] * k, d[1] * k, *seed, 400.0, 4, 0.55, 1.0);
            base * (1.0 + 0.12 * c * (elev * 4.0).min(1.0))
        }
    }
}
