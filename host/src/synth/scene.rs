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
    /// Stretches furnished otherwise (narrow, open, cross streets); the rest is default.
    pub zones: Vec<Zone>,
}

/// A stretch `[s0, s1)` of the street furnished otherwise than the style's default.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Zone {
    pub s0: f64,
    pub s1: f64,
    pub kind: ZoneKind,
}

/// How a [`Zone`] is furnished.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ZoneKind {
    /// A narrow street: facades `facade` m from the centre line (plus up to 1 m), back
    /// walls at `back` m, few gaps; no parked cars or poles.
    Narrow { facade: f64, back: f64 },
    /// Open country: road and verge to `verge` m, fields beyond to `field` m, no facades,
    /// back walls or parked cars; distant buildings and masts `near`..`far` m from the
    /// centre line.
    Open {
        verge: f64,
        field: f64,
        near: f64,
        far: f64,
    },
    /// A cross street: no facades, back walls, parked cars or poles here; its roadway
    /// runs `length` m to each side between walls and ends at a wall.
    Crossing { length: f64 },
}

impl StreetStyle {
    /// The zone at arclength `s`, if any.
    pub fn zone_at(&self, s: f64) -> Option<ZoneKind> {
        self.zones
            .iter()
            .find(|z| s >= z.s0 && s < z.s1)
            .map(|z| z.kind)
    }

    /// The first zone boundary after `s`, or `end`.
    fn boundary_after(&self, s: f64, end: f64) -> f64 {
        self.zones
            .iter()
            .flat_map(|z| [z.s0, z.s1])
            .filter(|&b| b > s)
            .fold(end, f64::min)
    }

    /// No zone overlaps `[a, b]` (parked cars and poles stand only there; open
    /// country keeps its poles).
    fn plain(&self, a: f64, b: f64, poles: bool) -> bool {
        !self
            .zones
            .iter()
            .any(|z| b > z.s0 && a < z.s1 && !(poles && matches!(z.kind, ZoneKind::Open { .. })))
    }

    /// Half width of the corridor the street occupies at `s` (ground, walls, cross
    /// streets): other parts of the scene keep out of it.
    pub fn corridor(&self, s: f64) -> f64 {
        match self.zone_at(s) {
            None => self
                .ground_half_width
                .max(self.back_wall_offset + 1.0)
                .max(self.facade_offset + 10.5),
            Some(ZoneKind::Narrow { facade, back }) => {
                self.ground_half_width.max(back + 1.0).max(facade + 10.0)
            }
            Some(ZoneKind::Open { verge, .. }) => verge.max(7.0),
            Some(ZoneKind::Crossing { length }) => length + 1.0,
        }
    }
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
            zones: Vec::new(),
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
            if rng.gen_bool(style.car_probability) && style.plain(s - 3.5, s + 3.5, false) {
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
            if style.plain(s - 1.0, s + 1.0, true) {
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
            }
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
    let sky = Sky::Day { seed: rng.gen() };
    if !style.zones.is_empty() {
        zone_extras(&path, style, seed, next_group, &mut prims);
    }
    Scene {
        prims,
        sky,
        light: Light::default(),
        path: Some(path),
        textureless: style.textureless,
        photos: None,
    }
}

/// Ground strips 2 m long: a planar quad on straights, two triangles on arcs
/// (the strip is level across, so its four corners are coplanar only when the
/// cross sections are parallel).
///
/// Open zones narrow the strip to their verge (fields continue it, [`zone_extras`]);
/// on an arc tighter than the strip, its inner side stops a metre short of the centre
/// of the turn.
fn ground(path: &StreetPath, style: &StreetStyle, prims: &mut Vec<Primitive>) {
    let mut s = path.s_min();
    while s < path.s_max() - 1e-9 {
        let e = (s + 2.0).min(path.s_max());
        let i = path.segment_index(0.5 * (s + e));
        let w = match style.zone_at(0.5 * (s + e)) {
            Some(ZoneKind::Open { verge, .. }) => verge,
            _ => style.ground_half_width,
        };
        let (wl, wr) = inner_clamped(path.segments[i].curvature, w, w);
        let (a, b) = (path.station(s), path.station(e));
        let (p0, p1, p2, p3) = (
            v3(a.offset(-wl)),
            v3(a.offset(wr)),
            v3(b.offset(wr)),
            v3(b.offset(-wl)),
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
        let zone = style.zone_at(s);
        let (offset, spread, gaps) = match zone {
            None => (style.facade_offset, 1.5, style.gap_probability),
            Some(ZoneKind::Narrow { facade, .. }) => (facade, 1.0, 0.5 * style.gap_probability),
            Some(ZoneKind::Open { .. } | ZoneKind::Crossing { .. }) => {
                s = style.boundary_after(s, path.s_max());
                continue;
            }
        };
        if rng.gen_bool(gaps) {
            s += rng.gen_range(3.0..8.0);
            continue;
        }
        let e = (s + rng.gen_range(6.0..16.0)).min(style.boundary_after(s, path.s_max()));
        let d = side * (offset + rng.gen_range(0.0..spread));
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
    while s < path.s_max() {
        let d = side
            * match style.zone_at(s) {
                None => style.back_wall_offset,
                Some(ZoneKind::Narrow { back, .. }) => back,
                Some(ZoneKind::Open { .. } | ZoneKind::Crossing { .. }) => {
                    s = style.boundary_after(s, path.s_max());
                    continue;
                }
            };
        let e = (s + 8.0).min(style.boundary_after(s, path.s_max()));
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
    vehicle(
        VehicleKind::Car,
        st.offset(d),
        st.heading,
        shade,
        seed,
        flat,
        group,
        out,
    );
}

/// What a vehicle looks like.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum VehicleKind {
    /// 4.3 x 1.8 m, 1.45 m high: a body and a glass cabin.
    Car,
    /// 5.2 x 2.0 m, 2.4 m high: a body, a cargo box and a windscreen.
    Van,
    /// 11 x 2.5 m, 3.2 m high: a body, a band of windows and a roof.
    Bus,
}

impl VehicleKind {
    /// Length, width and height, metres.
    pub fn size(self) -> [f64; 3] {
        match self {
            VehicleKind::Car => [4.3, 1.8, 1.45],
            VehicleKind::Van => [5.2, 2.0, 2.4],
            VehicleKind::Bus => [11.0, 2.5, 3.2],
        }
    }
}

/// A vehicle standing on the ground point `p` facing `heading` (forward = (sin h,
/// cos h)); its boxes get groups `group`, `group + 1` (glass) and `group + 2`.
#[allow(clippy::too_many_arguments)]
pub fn vehicle(
    kind: VehicleKind,
    p: [f64; 3],
    heading: f64,
    shade: f32,
    seed: u32,
    flat: bool,
    group: u32,
    out: &mut Vec<Primitive>,
) {
    let z = p[2];
    // A point `along` metres ahead of the vehicle's centre.
    let at = |along: f64| {
        [
            p[0] + along * heading.sin(),
            p[1] + along * heading.cos(),
            z,
        ]
    };
    let body = Material::Car { seed, shade };
    let glass = Material::Glass { seed };
    match kind {
        VehicleKind::Car => {
            box_faces(
                p,
                heading,
                4.3,
                1.8,
                (z + 0.2, z + 0.95),
                body,
                flat,
                group,
                out,
            );
            box_faces(
                at(-0.2),
                heading,
                2.3,
                1.6,
                (z + 0.95, z + 1.45),
                glass,
                flat,
                group + 1,
                out,
            );
        }
        VehicleKind::Van => {
            box_faces(
                p,
                heading,
                5.2,
                2.0,
                (z + 0.3, z + 1.1),
                body,
                flat,
                group,
                out,
            );
            let cargo = Material::Car {
                seed: seed ^ 0x5a5a,
                shade: (shade * 1.15).min(0.9),
            };
            box_faces(
                at(-0.7),
                heading,
                3.6,
                1.95,
                (z + 1.1, z + 2.4),
                cargo,
                flat,
                group + 2,
                out,
            );
            box_faces(
                at(1.5),
                heading,
                0.8,
                1.9,
                (z + 1.1, z + 2.2),
                glass,
                flat,
                group + 1,
                out,
            );
        }
        VehicleKind::Bus => {
            box_faces(
                p,
                heading,
                11.0,
                2.5,
                (z + 0.35, z + 1.3),
                body,
                flat,
                group,
                out,
            );
            box_faces(
                p,
                heading,
                10.9,
                2.45,
                (z + 1.3, z + 2.5),
                glass,
                flat,
                group + 1,
                out,
            );
            let roof = Material::Car {
                seed: seed ^ 0x7777,
                shade: (shade * 0.9).max(0.1),
            };
            box_faces(
                p,
                heading,
                11.0,
                2.5,
                (z + 2.5, z + 3.2),
                roof,
                flat,
                group + 2,
                out,
            );
        }
    }
}

/// `(left, right)` half widths of a strip on a segment of `curvature`: on an arc
/// tighter than the strip, the inner side stops a metre short of the centre of the turn.
fn inner_clamped(curvature: f64, left: f64, right: f64) -> (f64, f64) {
    if curvature == 0.0 {
        return (left, right);
    }
    let inner = 1.0 / curvature.abs() - 1.0;
    if curvature > 0.0 {
        (left, right.min(inner))
    } else {
        (left.min(inner), right)
    }
}

/// Group of the fields (one object: the renderer supersamples where they meet the road).
const FIELD_GROUP: u32 = u32::MAX - 2;

/// Where the street lies: short strips across the centre line every metre, each as
/// wide as the corridor there, so fields and distant objects of one stretch keep off
/// the street's other stretches.
struct Keepout {
    /// `(s, centre, forward, corridor half width)`.
    strips: Vec<(f64, [f64; 2], [f64; 2], f64)>,
}

impl Keepout {
    fn new(path: &StreetPath, style: &StreetStyle) -> Self {
        let mut strips = Vec::new();
        let mut s = path.s_min();
        while s <= path.s_max() {
            let st = path.station(s);
            strips.push((s, st.xy, st.forward(), style.corridor(s)));
            s += 1.0;
        }
        Keepout { strips }
    }

    /// Whether `p` lies within `margin` of the corridor outside the stretch `[s0, s1)`.
    fn blocked(&self, p: [f64; 2], margin: f64, (s0, s1): (f64, f64)) -> bool {
        self.strips.iter().any(|&(s, c, f, w)| {
            if s >= s0 && s < s1 {
                return false;
            }
            let (dx, dy) = (p[0] - c[0], p[1] - c[1]);
            let along = dx * f[0] + dy * f[1];
            let across = dx * f[1] - dy * f[0];
            along.abs() < 0.75 + margin && across.abs() < w + margin
        })
    }
}

/// What the zones add to the street: fields and distant buildings and masts in open
/// country, roadways and walls of cross streets. Their own random stream (from
/// `seed`), so the rest of the street does not depend on them.
fn zone_extras(
    path: &StreetPath,
    style: &StreetStyle,
    seed: u64,
    mut next_group: u32,
    prims: &mut Vec<Primitive>,
) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x7a6f_6e65);
    let keepout = Keepout::new(path, style);
    for zone in &style.zones {
        let own = (zone.s0, zone.s1);
        match zone.kind {
            ZoneKind::Open {
                verge,
                field,
                near,
                far,
            } => {
                // Fields: 2 m strips from the verge out as far as the street's other
                // stretches allow (checked every 4 m).
                let field_seed: u32 = rng.gen();
                let mut s = zone.s0.max(path.s_min());
                while s < zone.s1.min(path.s_max()) - 1e-9 {
                    let e = (s + 2.0).min(zone.s1).min(path.s_max());
                    let i = path.segment_index(0.5 * (s + e));
                    let (a, b) = (path.station(s), path.station(e));
                    let (wl, wr) = inner_clamped(path.segments[i].curvature, field, field);
                    for (side, limit) in [(-1.0, wl), (1.0, wr)] {
                        let mut w = verge;
                        while w + 4.0 <= limit {
                            let blocked = [a, b].iter().any(|st| {
                                let q = st.offset(side * (w + 4.0));
                                keepout.blocked([q[0], q[1]], 1.0, own)
                            });
                            if blocked {
                                break;
                            }
                            w += 4.0;
                        }
                        if w <= verge {
                            continue;
                        }
                        let quad = [
                            v3(a.offset(side * verge)),
                            v3(a.offset(side * w)),
                            v3(b.offset(side * w)),
                            v3(b.offset(side * verge)),
                        ];
                        // A quad on straights, two triangles on arcs (as the ground).
                        let pieces: &[&[usize]] = if path.segments[i].curvature == 0.0 {
                            &[&[0, 1, 2, 3]]
                        } else {
                            &[&[0, 1, 2], &[0, 2, 3]]
                        };
                        for piece in pieces {
                            let points: Vec<V3> = piece.iter().map(|&j| quad[j]).collect();
                            prims.push(Primitive {
                                shape: Shape::polygon(&points, None),
                                material: Material::Field { seed: field_seed },
                                flat: false,
                                group: FIELD_GROUP,
                            });
                        }
                    }
                    s = e;
                }
                // Distant buildings (boxes turned a little off the street) and masts.
                for side in [-1.0, 1.0] {
                    let mut s = zone.s0 + rng.gen_range(0.0..20.0);
                    while s < zone.s1 {
                        let st = path.station(s);
                        let len: f64 = rng.gen_range(8.0..30.0);
                        let depth: f64 = rng.gen_range(8.0..20.0);
                        let half_diag = 0.5 * (len * len + depth * depth).sqrt();
                        let d = side
                            * rng.gen_range(
                                (near + half_diag)..(far + half_diag).max(near + half_diag + 1.0),
                            );
                        let turn = rng.gen_range(-0.4..0.4);
                        let height = rng.gen_range(5.0..12.0) + 0.15 * d.abs();
                        let material = facade_material(&mut rng, 0.0);
                        let c = st.offset(d);
                        let h = st.heading + turn;
                        let (f, r) = ([h.sin(), h.cos()], [h.cos(), -h.sin()]);
                        let free = (-2..=2).all(|i| {
                            (-2..=2).all(|j| {
                                let (u, v) = (0.25 * i as f64 * len, 0.25 * j as f64 * depth);
                                let q = [c[0] + u * f[0] + v * r[0], c[1] + u * f[1] + v * r[1]];
                                !keepout.blocked(q, 4.0, own)
                            })
                        });
                        if free {
                            next_group += 1;
                            box_faces(
                                c,
                                h,
                                len,
                                depth,
                                (c[2] - 2.0, c[2] + height),
                                material,
                                false,
                                next_group,
                                prims,
                            );
                        }
                        s += len + rng.gen_range(10.0..40.0);
                    }
                    let mut s = zone.s0 + rng.gen_range(0.0..30.0);
                    while s < zone.s1 {
                        let d = side * rng.gen_range(12.0..near.max(13.0));
                        let p = path.station(s).offset(d);
                        let (z1, radius, pole_seed) = (
                            rng.gen_range(12.0..25.0),
                            rng.gen_range(0.2..0.4),
                            rng.gen(),
                        );
                        if !keepout.blocked([p[0], p[1]], 2.0, own) {
                            next_group += 1;
                            prims.push(Primitive {
                                shape: Shape::Cylinder {
                                    centre: [p[0], p[1]],
                                    z0: p[2] - 0.5,
                                    z1: p[2] + z1,
                                    radius,
                                },
                                material: Material::Pole { seed: pole_seed },
                                flat: false,
                                group: next_group,
                            });
                        }
                        s += rng.gen_range(35.0..70.0);
                    }
                }
            }
            ZoneKind::Crossing { length } => {
                let (a, b) = (path.station(zone.s0), path.station(zone.s1));
                let gw = style.ground_half_width;
                let road_seed: u32 = rng.gen();
                for side in [-1.0, 1.0] {
                    // The cross street's roadway beyond the ground strip.
                    prims.push(Primitive {
                        shape: Shape::polygon(
                            &[
                                v3(a.offset(side * gw)),
                                v3(a.offset(side * length)),
                                v3(b.offset(side * length)),
                                v3(b.offset(side * gw)),
                            ],
                            None,
                        ),
                        material: Material::Asphalt { seed: road_seed },
                        flat: false,
                        group: 0,
                    });
                    // Walls along it (just inside the crossing, in front of the side
                    // walls of the buildings at its corners) and across its end.
                    let (ia, ib) = (path.station(zone.s0 + 0.3), path.station(zone.s1 - 0.3));
                    for st in [ia, ib] {
                        let (p, q) = (
                            st.offset(side * style.facade_offset),
                            st.offset(side * length),
                        );
                        let height = rng.gen_range(8.0..20.0);
                        let m = facade_material(&mut rng, 0.0);
                        next_group += 1;
                        let mut w = wall(p, q, height, m, false);
                        w.group = next_group;
                        prims.push(w);
                    }
                    let (p, q) = (
                        path.station(zone.s0 - 2.0).offset(side * length),
                        path.station(zone.s1 + 2.0).offset(side * length),
                    );
                    let height = rng.gen_range(10.0..20.0);
                    let m = facade_material(&mut rng, 0.0);
                    next_group += 1;
                    let mut w = wall(p, q, height, m, false);
                    w.group = next_group;
                    prims.push(w);
                }
            }
            ZoneKind::Narrow { .. } => {}
        }
    }
}
