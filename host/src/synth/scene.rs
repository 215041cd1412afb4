//! A renderable scene: primitives with materials, a sky and the light; and the
//! street corridor built along a [`StreetPath`].
use super::geometry::{Shape, V3};
use super::material::{Light, Material, Sky};
use super::path::StreetPath;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// A shape with its appearance.
#[derive(Debug, Clone, PartialEq)]
pub struct Primitive {
    pub shape: Shape,
    pub material: Material,
    /// Drawn without texture (inside the textureless stretch).
    pub flat: bool,
    /// Object the primitive belongs to: pieces of one surface share it, so the
    /// renderer supersamples only where the object changes (silhouettes).
    pub group: u32,
}

/// Everything the renderer needs besides the camera.
#[derive(Debug, Clone)]
pub struct Scene {
    pub prims: Vec<Primitive>,
    pub sky: Sky,
    pub light: Light,
    pub path: Option<StreetPath>,
    pub textureless: Option<(f64, f64)>,
    /// Photographs that texture the facades instead of the procedural ones.
    pub photos: Option<std::sync::Arc<super::photo::Photos>>,
}

impl Scene {
    /// An empty scene with a constant sky (for tests and targets).
    pub fn empty(sky: f32) -> Scene {
        Scene {
            prims: Vec::new(),
            sky: Sky::Constant(sky),
            light: Light::default(),
            path: None,
            textureless: None,
            photos: None,
        }
    }
}

/// How the street is furnished.
#[derive(Debug, Clone)]
pub struct StreetStyle {
    /// Half width of the ground strip, metres (must stay below the smallest turn radius).
    pub ground_half_width: f64,
    /// Facade distance from the centre line, metres (plus up to 1.5 m).
    pub facade_offset: f64,
    pub gap_probability: f64,
    pub car_probability: f64,
    pub back_wall_offset: f64,
    pub textureless: Option<(f64, f64)>,
}

impl Default for StreetStyle {
    fn default() -> Self {
        StreetStyle {
            ground_half_width: 27.0,
            facade_offset: 9.0,
            gap_probability: 0.3,
            car_probability: 0.55,
            back_wall_offset: 24.0,
            textureless: None,
        }
    }
}

fn v3(p: [f64; 3]) -> V3 {
    V3::new(p[0], p[1], p[2])
}

/// Builds the street corridor along `path`, deterministic for `seed`.
pub fn build_street(path: StreetPath, style: &StreetStyle, seed: u64) -> Scene {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut prims = Vec::new();
    let (s_min, s_max) = (path.s_min(), path.s_max());
    let in_flat = |a: f64, b: f64| style.textureless.is_some_and(|(x, y)| b > x && a < y);
    ground(&path, style, &mut prims);
    let mut next_group = 1u32;
    for side in [-1.0, 1.0] {
        let start = prims.len();
        buildings(&path, style, side, &mut rng, &mut prims, &in_flat);
        back_walls(&path, style, side, &mut rng, &mut prims, &in_flat);
        // Each wall is its own object, except the pieces of one facade (same material).
        let mut last: Option<Material> = None;
        for p in &mut prims[start..] {
            if last != Some(p.material) {
                next_group += 1;
            }
            last = Some(p.material);
            p.group = next_group;
        }
        // Parked cars in 6.5 m slots, poles every 18..30 m.
        let mut s = s_min + rng.gen_range(0.0..6.0);
        while s < s_max - 5.0 {
            if rng.gen_bool(style.car_probability) {
                let shade = rng.gen_range(0.1..0.85) as f32;
                let flat = in_flat(s - 3.0, s + 3.0);
                next_group += 2;
                car(
                    &path,
                    s,
                    side * 4.2,
                    shade,
                    rng.gen(),
                    flat,
                    next_group,
                    &mut prims,
                );
            }
            s += 6.5 + rng.gen_range(0.0..1.5);
        }
        let mut s = s_min + rng.gen_range(0.0..15.0);
        while s < s_max {
            let st = path.station(s);
            let p = st.offset(side * 6.2);
            let flat = in_flat(s - 1.0, s + 1.0);
            prims.push(Primitive {
                shape: Shape::Cylinder {
                    centre: [p[0], p[1]],
                    z0: p[2] - 0.5,
                    z1: p[2] + rng.gen_range(5.5..8.0),
                    radius: rng.gen_range(0.07..0.13),
                },
                material: Material::Pole { seed: rng.gen() },
                flat,
                group: next_group,
            });
            next_group += 1;
            s += rng.gen_range(18.0..30.0);
        }
    }
    // End walls close the corridor so the far end never shows an empty horizon.
    for (s, sign) in [(s_min, 1.0), (s_max, -1.0)] {
        let st = path.station(s);
        let w = style.back_wall_offset + 2.0;
        let (a, b) = (st.offset(-w), st.offset(w));
        let _ = sign;
        prims.push(Primitive {
            shape: Shape::polygon(
                &[
                    v3(a) - V3::z() * 2.0,
                    v3(b) - V3::z() * 2.0,
                    v3(b) + V3::z() * 25.0,
                    v3(a) + V3::z() * 25.0,
                ],
                Some(V3::z()),
            ),
            material: Material::Facade {
                seed: rng.gen(),
                shade: 0.5,
                brick: false,
                window_w: 1.2,
                window_pitch: 3.0,
                floor_h: 3.2,
                u0: 0.0,
            },
            flat: false,
            group: next_group,
        });
        next_group += 1;
    }
    Scene {
        prims,
        sky: Sky::Day { seed: rng.gen() },
        light: Light::default(),
        path: Some(path),
        textureless: style.textureless,
        photos: None,
    }
}

/// Ground strips 2 m long: a planar quad on straights, two triangles on arcs
/// (the strip is level across, so its four corners are coplanar only when the
/// cross sections are parallel).
fn ground(path: &StreetPath, style: &StreetStyle, prims: &mut Vec<Primitive>) {
    let w = style.ground_half_width;
    let mut s = path.s_min();
    while s < path.s_max() - 1e-9 {
        let e = (s + 2.0).min(path.s_max());
        let i = path.segment_index(0.5 * (s + e));
        let (a, b) = (path.station(s), path.station(e));
        let (p0, p1, p2, p3) = (
            v3(a.offset(-w)),
            v3(a.offset(w)),
            v3(b.offset(w)),
            v3(b.offset(-w)),
        );
        let material = Material::Ground { segment: i as u32 };
        if path.segments[i].curvature == 0.0 {
            prims.push(Primitive {
                shape: Shape::polygon(&[p0, p1, p2, p3], None),
                material,
                flat: false,
                group: 0,
            });
        } else {
            prims.push(Primitive {
                shape: Shape::polygon(&[p0, p1, p2], None),
                material,
                flat: false,
                group: 0,
            });
            prims.push(Primitive {
                shape: Shape::polygon(&[p0, p2, p3], None),
                material,
                flat: false,
                group: 0,
            });
        }
        s = e;
    }
}

type FlatFn<'a> = dyn Fn(f64, f64) -> bool + 'a;

/// A vertical wall between two ground points, from below the ground to `height` above.
fn wall(a: [f64; 3], b: [f64; 3], height: f64, material: Material, flat: bool) -> Primitive {
    let z0 = a[2].min(b[2]) - 1.0;
    let z1 = a[2].max(b[2]) + height;
    let (a0, b0) = (V3::new(a[0], a[1], z0), V3::new(b[0], b[1], z0));
    let (a1, b1) = (V3::new(a[0], a[1], z1), V3::new(b[0], b[1], z1));
    Primitive {
        shape: Shape::polygon(&[a0, b0, b1, a1], Some(V3::z())),
        material,
        flat,
        group: 0,
    }
}

fn facade_material(rng: &mut ChaCha8Rng, u0: f64) -> Material {
    Material::Facade {
        seed: rng.gen(),
        shade: rng.gen_range(0.3..0.8) as f32,
        brick: rng.gen_bool(0.4),
        window_w: rng.gen_range(0.9..1.6) as f32,
        window_pitch: rng.gen_range(2.4..3.6) as f32,
        floor_h: rng.gen_range(2.9..3.6) as f32,
        u0: u0 as f32,
    }
}

/// Facades along one side (`side` = -1 left, +1 right) with gaps showing side walls.
fn buildings(
    path: &StreetPath,
    style: &StreetStyle,
    side: f64,
    rng: &mut ChaCha8Rng,
    prims: &mut Vec<Primitive>,
    flat: &FlatFn,
) {
    let mut s = path.s_min();
    while s < path.s_max() {
        if rng.gen_bool(style.gap_probability) {
            s += rng.gen_range(3.0..8.0);
            continue;
        }
        let e = (s + rng.gen_range(6.0..16.0)).min(path.s_max());
        let d = side * (style.facade_offset + rng.gen_range(0.0..1.5));
        let height = rng.gen_range(6.0..20.0);
        let u_start = rng.gen_range(0.0..100.0);
        let material = facade_material(rng, u_start);
        let fl = flat(s, e);
        // Long buildings on arcs are split so the facade stays near the curve.
        let pieces = ((e - s) / 6.0).ceil().max(1.0) as usize;
        let mut u0 = 0.0;
        for k in 0..pieces {
            let (a, b) = (
                s + (e - s) * k as f64 / pieces as f64,
                s + (e - s) * (k + 1) as f64 / pieces as f64,
            );
            let (pa, pb) = (path.station(a).offset(d), path.station(b).offset(d));
            // Facades are drawn left to right as seen from the street.
            let (p, q) = if side > 0.0 { (pa, pb) } else { (pb, pa) };
            let mut m = material;
            if let Material::Facade { u0: ref mut u, .. } = m {
                *u += u0 as f32;
            }
            prims.push(wall(p, q, height, m, fl));
            u0 += ((pb[0] - pa[0]).powi(2) + (pb[1] - pa[1]).powi(2)).sqrt();
        }
        // Side walls at both ends, 8 m deep, seen through gaps.
        for (at, u) in [(s, 3.0), (e, 7.0)] {
            let st = path.station(at);
            let (p, q) = (st.offset(d), st.offset(d + side * 8.0));
            prims.push(wall(p, q, height, facade_material(rng, u), fl));
        }
        s = e;
    }
}

/// A second row of walls behind the facades (closes the view through gaps).
fn back_walls(
    path: &StreetPath,
    style: &StreetStyle,
    side: f64,
    rng: &mut ChaCha8Rng,
    prims: &mut Vec<Primitive>,
    flat: &FlatFn,
) {
    let mut s = path.s_min();
    let d = side * style.back_wall_offset;
    while s < path.s_max() {
        let e = (s + 8.0).min(path.s_max());
        let (pa, pb) = (path.station(s).offset(d), path.station(e).offset(d));
        let (p, q) = if side > 0.0 { (pa, pb) } else { (pb, pa) };
        prims.push(wall(
            p,
            q,
            rng.gen_range(10.0..22.0),
            facade_material(rng, s),
            flat(s, e),
        ));
        s = e;
    }
}

/// Axis-aligned (in the street frame) box faces: 4 sides and the top.
#[allow(clippy::too_many_arguments)]
pub fn box_faces(
    centre: [f64; 3],
    heading: f64,
    len: f64,
    width: f64,
    z: (f64, f64),
    material: Material,
    flat: bool,
    group: u32,
    out: &mut Vec<Primitive>,
) {
    let (z0, z1) = z;
    let f = V3::new(heading.sin(), heading.cos(), 0.0) * (0.5 * len);
    let r = V3::new(heading.cos(), -heading.sin(), 0.0) * (0.5 * width);
    let c = V3::new(centre[0], centre[1], 0.0);
    let corners = [c - f - r, c + f - r, c + f + r, c - f + r];
    let up = |p: V3, z: f64| V3::new(p[0], p[1], z);
    for i in 0..4 {
        let (a, b) = (corners[i], corners[(i + 1) % 4]);
        out.push(Primitive {
            shape: Shape::polygon(&[up(a, z0), up(b, z0), up(b, z1), up(a, z1)], Some(V3::z())),
            material,
            flat,
            group,
        });
    }
    let top: Vec<V3> = corners.iter().map(|p| up(*p, z1)).collect();
    out.push(Primitive {
        shape: Shape::polygon(&top, None),
        material,
        flat,
        group,
    });
}

/// A car: a body box and a cabin box with glass, at street position `s`,
/// offset `d`; its boxes get groups `group` and `group + 1`.
#[allow(clippy::too_many_arguments)]
pub fn car(
    path: &StreetPath,
    s: f64,
    d: f64,
    shade: f32,
    seed: u32,
    flat: bool,
    group: u32,
    out: &mut Vec<Primitive>,
) {
    let st = path.station(s);
    let p = st.offset(d);
    let z = p[2];
    box_faces(
        p,
        st.heading,
        4.3,
        1.8,
        (z + 0.2, z + 0.95),
        Material::Car { seed, shade },
        flat,
        group,
        out,
    );
    let cab = st.offset(d);
    let back = [
        cab[0] - 0.2 * st.forward()[0],
        cab[1] - 0.2 * st.forward()[1],
        z,
    ];
    box_faces(
        back,
        st.heading,
        2.3,
        1.6,
        (z + 0.95, z + 1.45),
        Material::Glass { seed },
        flat,
        group + 1,
        out,
    );
}
