//! Scene primitives and their ray intersections.
use nalgebra::Vector3;

pub type V3 = Vector3<f64>;

/// Smallest ray parameter accepted as a hit (metres).
pub const T_MIN: f64 = 1e-6;

/// A shape in object space.
#[derive(Debug, Clone, PartialEq)]
pub enum Shape {
    /// Planar convex polygon of 3 or 4 vertices, stored in its plane basis.
    Polygon {
        origin: V3,
        e1: V3,
        e2: V3,
        normal: V3,
        /// Vertices in `(e1, e2)` coordinates, counter-clockwise.
        verts: [[f64; 2]; 4],
        count: u8,
    },
    /// Vertical cylinder (no caps).
    Cylinder {
        centre: [f64; 2],
        z0: f64,
        z1: f64,
        radius: f64,
    },
    /// Flat disc.
    Disc { centre: V3, normal: V3, radius: f64 },
}

/// Where a ray hit a shape.
#[derive(Debug, Clone, Copy)]
pub struct Hit {
    pub t: f64,
    /// Surface coordinates: polygon `(e1, e2)`; cylinder `(arc length, z)`; disc `(x, y)` in its plane.
    pub uv: [f64; 2],
    /// Unit normal facing the ray origin.
    pub normal: V3,
    /// Cosine between the ray and the normal (for the texture footprint).
    pub cos: f64,
}

impl Shape {
    /// A planar polygon through `points` (3 or 4, convex, coplanar), with `e1`
    /// along the first edge unless `up` is given (then `e2` is the projection
    /// of `up`, which keeps facade texture upright).
    pub fn polygon(points: &[V3], up: Option<V3>) -> Shape {
        let n = points.len().clamp(3, 4);
        let origin = points[0];
        let normal = (points[1] - points[0])
            .cross(&(points[n - 1] - points[0]))
            .normalize();
        let (e1, e2) = match up {
            Some(u) => {
                let e2 = (u - normal * normal.dot(&u)).normalize();
                (e2.cross(&normal), e2)
            }
            None => {
                let e1 = (points[1] - points[0]).normalize();
                (e1, normal.cross(&e1))
            }
        };
        let mut verts = [[0.0; 2]; 4];
        for (i, p) in points.iter().take(n).enumerate() {
            let r = p - origin;
            verts[i] = [r.dot(&e1), r.dot(&e2)];
        }
        // Counter-clockwise in (e1, e2) for the inside test.
        let mut area = 0.0;
        for i in 0..n {
            let (a, b) = (verts[i], verts[(i + 1) % n]);
            area += a[0] * b[1] - b[0] * a[1];
        }
        if area < 0.0 {
            verts[..n].reverse();
        }
        Shape::Polygon {
            origin,
            e1,
            e2,
            normal,
            verts,
            count: n as u8,
        }
    }

    /// Nearest intersection with `t` in `(T_MIN, t_max)`.
    #[inline]
    pub fn intersect(&self, o: &V3, d: &V3, t_max: f64) -> Option<Hit> {
        match self {
            Shape::Polygon {
                origin,
                e1,
                e2,
                normal,
                verts,
                count,
            } => {
                let denom = normal.dot(d);
                if denom.abs() < 1e-12 {
                    return None;
                }
                let t = normal.dot(&(origin - o)) / denom;
                if !(t > T_MIN && t < t_max) {
                    return None;
                }
                let r = o + d * t - origin;
                let (a, b) = (r.dot(e1), r.dot(e2));
                let n = *count as usize;
                for i in 0..n {
                    let p = verts[i];
                    let q = verts[if i + 1 == n { 0 } else { i + 1 }];
                    if (q[0] - p[0]) * (b - p[1]) - (q[1] - p[1]) * (a - p[0]) < 0.0 {
                        return None;
                    }
                }
                let facing = if denom < 0.0 { *normal } else { -normal };
                Some(Hit {
                    t,
                    uv: [a, b],
                    normal: facing,
                    cos: denom.abs(),
                })
            }
            Shape::Cylinder {
                centre,
                z0,
                z1,
                radius,
            } => {
                let (ox, oy) = (o[0] - centre[0], o[1] - centre[1]);
                let a = d[0] * d[0] + d[1] * d[1];
                if a < 1e-12 {
                    return None;
                }
                let b = ox * d[0] + oy * d[1];
                let c = ox * ox + oy * oy - radius * radius;
                let disc = b * b - a * c;
                if disc < 0.0 || c < 0.0 {
                    // Miss, or the origin is inside (never seen from outside).
                    return None;
                }
                let t = (-b - disc.sqrt()) / a;
                if !(t > T_MIN && t < t_max) {
                    return None;
                }
                let z = o[2] + t * d[2];
                if z < *z0 || z > *z1 {
                    return None;
                }
                let (hx, hy) = (ox + t * d[0], oy + t * d[1]);
                let normal = V3::new(hx / radius, hy / radius, 0.0);
                let angle = hy.atan2(hx);
                Some(Hit {
                    t,
                    uv: [angle * radius, z],
                    normal,
                    cos: normal.dot(d).abs(),
                })
            }
            Shape::Disc {
                centre,
                normal,
                radius,
            } => {
                let denom = normal.dot(d);
                if denom.abs() < 1e-12 {
                    return None;
                }
                let t = normal.dot(&(centre - o)) / denom;
                if !(t > T_MIN && t < t_max) {
                    return None;
                }
                let r = o + d * t - centre;
                if r.norm_squared() > radius * radius {
                    return None;
                }
                let facing = if denom < 0.0 { *normal } else { -normal };
                Some(Hit {
                    t,
                    uv: [r[0], r[1]],
                    normal: facing,
                    cos: denom.abs(),
                })
            }
        }
    }

    /// Points whose convex hull contains the shape, and the hull's edges (for
    /// clipping against the camera's near plane when binning).
    pub fn hull(&self, out: &mut Vec<V3>) -> &'static [(u8, u8)] {
        out.clear();
        match self {
            Shape::Polygon {
                origin,
                e1,
                e2,
                verts,
                count,
                ..
            } => {
                for v in &verts[..*count as usize] {
                    out.push(origin + e1 * v[0] + e2 * v[1]);
                }
                if *count == 3 {
                    &[(0, 1), (1, 2), (2, 0)]
                } else {
                    &[(0, 1), (1, 2), (2, 3), (3, 0)]
                }
            }
            Shape::Cylinder {
                centre,
                z0,
                z1,
                radius,
            } => {
                for z in [*z0, *z1] {
                    for (sx, sy) in [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)] {
                        out.push(V3::new(centre[0] + sx * radius, centre[1] + sy * radius, z));
                    }
                }
                BOX_EDGES
            }
            Shape::Disc {
                centre,
                normal,
                radius,
            } => {
                let a = if normal[0].abs() < 0.9 {
                    V3::x()
                } else {
                    V3::y()
                };
                let u = normal.cross(&a).normalize() * *radius;
                let v = normal.cross(&u);
                for (su, sv) in [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)] {
                    out.push(centre + u * su + v * sv);
                }
                &[(0, 1), (1, 2), (2, 3), (3, 0)]
            }
        }
    }
}

const BOX_EDGES: &[(u8, u8)] = &[
    (0, 1),
    (1, 2),
    (2, 3),
    (3, 0),
    (4, 5),
    (5, 6),
    (6, 7),
    (7, 4),
    (0, 4),
    (1, 5),
    (2, 6),
    (3, 7),
];

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn polygon_hits_inside_only() {
        let quad = Shape::polygon(
            &[
                V3::new(0.0, 5.0, 0.0),
                V3::new(2.0, 5.0, 0.0),
                V3::new(2.0, 5.0, 2.0),
                V3::new(0.0, 5.0, 2.0),
            ],
            Some(V3::z()),
        );
        let o = V3::new(1.0, 0.0, 1.0);
        let h = quad.intersect(&o, &V3::y(), 1e9).unwrap();
        assert!((h.t - 5.0).abs() < 1e-12 && h.normal.dot(&V3::y()) < 0.0);
        assert!(quad
            .intersect(&V3::new(3.0, 0.0, 1.0), &V3::y(), 1e9)
            .is_none());
        assert!(quad.intersect(&o, &V3::y(), 4.0).is_none());
        // Upright texture basis: e2 is +Z.
        if let Shape::Polygon { e2, .. } = &quad {
            assert!((e2 - V3::z()).norm() < 1e-12);
        }
    }

    #[test]
    fn cylinder_and_disc() {
        let c = Shape::Cylinder {
            centre: [0.0, 10.0],
            z0: 0.0,
            z1: 5.0,
            radius: 0.5,
        };
        let h = c.intersect(&V3::new(0.0, 0.0, 1.0), &V3::y(), 1e9).unwrap();
        assert!((h.t - 9.5).abs() < 1e-12);
        assert!(c
            .intersect(&V3::new(0.0, 0.0, 6.0), &V3::y(), 1e9)
            .is_none());
        let d = Shape::Disc {
            centre: V3::new(0.0, 10.0, 0.0),
            normal: V3::y(),
            radius: 0.1,
        };
        assert!(d.intersect(&V3::zeros(), &V3::y(), 1e9).is_some());
        assert!(d
            .intersect(&V3::new(0.2, 0.0, 0.0), &V3::y(), 1e9)
            .is_none());
    }
}
