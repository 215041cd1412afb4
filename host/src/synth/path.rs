//! The street's centre line: straight and circular segments in the XY plane,
//! with a smooth vertical profile. Arclength `s` is the parameter of everything
//! placed along the street (buildings, cars, the vehicle's trajectory).
use std::f64::consts::PI;

/// One piece of the centre line.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Segment {
    /// Arclength where it starts.
    pub s0: f64,
    pub length: f64,
    /// Signed curvature, 1/m: positive turns right (heading increases).
    pub curvature: f64,
    /// Start point (X, Y).
    pub p0: [f64; 2],
    /// Start heading: forward = (sin h, cos h), so 0 looks along +Y.
    pub heading0: f64,
}

/// A centre-line point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Station {
    pub xy: [f64; 2],
    pub heading: f64,
    /// Height of the road surface, metres.
    pub z: f64,
    /// Grade dz/ds.
    pub grade: f64,
}

impl Station {
    pub fn forward(&self) -> [f64; 2] {
        [self.heading.sin(), self.heading.cos()]
    }
    /// Unit vector to the right of the forward direction.
    pub fn right(&self) -> [f64; 2] {
        [self.heading.cos(), -self.heading.sin()]
    }
    /// The point at lateral offset `d` (positive right), on the road surface.
    pub fn offset(&self, d: f64) -> [f64; 3] {
        let r = self.right();
        [self.xy[0] + d * r[0], self.xy[1] + d * r[1], self.z]
    }
}

/// Grade profile: piecewise-linear grade over arclength (knots `(s, grade)`),
/// integrated to heights on a fine table.
#[derive(Debug, Clone)]
pub struct Profile {
    knots: Vec<(f64, f64)>,
    s_min: f64,
    step: f64,
    heights: Vec<f64>,
}

impl Profile {
    pub fn new(knots: Vec<(f64, f64)>, s_min: f64, s_max: f64) -> Self {
        let step = 0.25;
        let n = ((s_max - s_min) / step).ceil() as usize + 2;
        let mut p = Profile {
            knots,
            s_min,
            step,
            heights: Vec::with_capacity(n),
        };
        let mut z = 0.0;
        for i in 0..n {
            p.heights.push(z);
            let s = s_min + i as f64 * step;
            // Trapezoid rule: exact for a piecewise-linear grade between knots on the table.
            z += 0.5 * step * (p.grade(s) + p.grade(s + step));
        }
        p
    }

    pub fn flat(s_min: f64, s_max: f64) -> Self {
        Profile::new(Vec::new(), s_min, s_max)
    }

    pub fn grade(&self, s: f64) -> f64 {
        let k = &self.knots;
        match k.iter().position(|&(ks, _)| ks > s) {
            None => k.last().map_or(0.0, |l| l.1),
            Some(0) => k[0].1,
            Some(i) => {
                let (s0, g0) = k[i - 1];
                let (s1, g1) = k[i];
                g0 + (g1 - g0) * (s - s0) / (s1 - s0)
            }
        }
    }

    /// Height relative to `s_min`, linear between table entries.
    pub fn height(&self, s: f64) -> f64 {
        let x = ((s - self.s_min) / self.step).clamp(0.0, (self.heights.len() - 2) as f64);
        let i = x.floor() as usize;
        let t = x - i as f64;
        self.heights[i] + (self.heights[i + 1] - self.heights[i]) * t
    }
}

/// The centre line.
#[derive(Debug, Clone)]
pub struct StreetPath {
    pub segments: Vec<Segment>,
    pub profile: Profile,
}

impl StreetPath {
    /// Builds a path from `(length, turn angle)` pieces starting at `s_min`
    /// (turn > 0 is to the right; radius = length / |turn|), starting so that
    /// `s = 0` is at the origin heading +Y.
    pub fn from_pieces(s_min: f64, pieces: &[(f64, f64)], grade_knots: Vec<(f64, f64)>) -> Self {
        // Begin with a straight run from s_min to 0 so the origin is on the path.
        let mut segments = vec![Segment {
            s0: s_min,
            length: -s_min,
            curvature: 0.0,
            p0: [0.0, s_min],
            heading0: 0.0,
        }];
        let mut s = 0.0;
        let mut p = [0.0, 0.0];
        let mut h = 0.0;
        for &(len, turn) in pieces {
            let seg = Segment {
                s0: s,
                length: len,
                curvature: turn / len,
                p0: p,
                heading0: h,
            };
            let end = seg.at(s + len);
            segments.push(seg);
            p = end.0;
            h = end.1;
            s += len;
        }
        let profile = Profile::new(grade_knots, s_min, s + 1.0);
        StreetPath { segments, profile }
    }

    pub fn s_min(&self) -> f64 {
        self.segments[0].s0
    }

    pub fn s_max(&self) -> f64 {
        let l = self.segments.last().expect("a path has segments");
        l.s0 + l.length
    }

    /// Index of the segment containing `s` (clamped to the ends).
    pub fn segment_index(&self, s: f64) -> usize {
        self.segments.iter().rposition(|g| g.s0 <= s).unwrap_or(0)
    }

    pub fn station(&self, s: f64) -> Station {
        let seg = &self.segments[self.segment_index(s)];
        let (xy, heading) = seg.at(s);
        Station {
            xy,
            heading,
            z: self.profile.height(s),
            grade: self.profile.grade(s),
        }
    }

    /// Arclength and lateral offset of a ground point near segment `index`.
    pub fn local(&self, index: usize, p: [f64; 2]) -> (f64, f64) {
        let seg = &self.segments[index.min(self.segments.len() - 1)];
        seg.local(p)
    }
}

impl Segment {
    /// Point and heading at arclength `s` (extrapolates beyond the ends).
    pub fn at(&self, s: f64) -> ([f64; 2], f64) {
        let u = s - self.s0;
        let k = self.curvature;
        let h0 = self.heading0;
        if k.abs() < 1e-12 {
            return ([self.p0[0] + u * h0.sin(), self.p0[1] + u * h0.cos()], h0);
        }
        let h = h0 + k * u;
        (
            [
                self.p0[0] + (h0.cos() - h.cos()) / k,
                self.p0[1] + (h.sin() - h0.sin()) / k,
            ],
            h,
        )
    }

    /// `(s, d)`: arclength and lateral offset (positive right) of a point.
    pub fn local(&self, p: [f64; 2]) -> (f64, f64) {
        let k = self.curvature;
        let h0 = self.heading0;
        let (fx, fy) = (h0.sin(), h0.cos());
        let (rx, ry) = (h0.cos(), -h0.sin());
        let (vx, vy) = (p[0] - self.p0[0], p[1] - self.p0[1]);
        if k.abs() < 1e-12 {
            return (self.s0 + vx * fx + vy * fy, vx * rx + vy * ry);
        }
        // Centre of the arc: p0 + right / k (to the right for k > 0).
        let (cx, cy) = (self.p0[0] + rx / k, self.p0[1] + ry / k);
        let (wx, wy) = (p[0] - cx, p[1] - cy);
        let rho = (wx * wx + wy * wy).sqrt();
        let d = k.signum() * (1.0 / k.abs() - rho);
        // p(h) - c = -(cos h, -sin h) / k  =>  -k (p - c) is along (cos h, -sin h).
        let (ux, uy) = (-k * wx, -k * wy);
        let h = (-uy).atan2(ux);
        let mut dh = h - h0;
        while dh > PI {
            dh -= 2.0 * PI;
        }
        while dh <= -PI {
            dh += 2.0 * PI;
        }
        (self.s0 + dh / k, d)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn arcs_join_and_invert() {
        let path = StreetPath::from_pieces(
            -20.0,
            &[
                (30.0, 0.0),
                (47.0, -PI / 2.0),
                (40.0, 0.0),
                (47.0, PI / 2.0),
            ],
            vec![],
        );
        // Continuity at every joint.
        for w in path.segments.windows(2) {
            let (p, h) = w[0].at(w[1].s0);
            assert!(
                (p[0] - w[1].p0[0]).abs() < 1e-9
                    && (p[1] - w[1].p0[1]).abs() < 1e-9
                    && (h - w[1].heading0).abs() < 1e-12
            );
        }
        // After a left and a right quarter turn the heading is back to 0.
        let end = path.station(path.s_max());
        assert!(end.heading.abs() < 1e-12);
        // (s, d) of offset points come back exactly, on straights and arcs.
        for s in [-10.0, 5.0, 40.0, 60.0, 100.0, 130.0, 150.0] {
            let i = path.segment_index(s);
            let st = path.station(s);
            for d in [-12.0, -3.0, 0.0, 4.5, 20.0] {
                let p = st.offset(d);
                let (s2, d2) = path.local(i, [p[0], p[1]]);
                assert!(
                    (s2 - s).abs() < 1e-9 && (d2 - d).abs() < 1e-9,
                    "s {s} d {d}: {s2} {d2}"
                );
            }
        }
    }

    #[test]
    fn profile_integrates_the_grade() {
        let p = Profile::new(
            vec![(0.0, 0.0), (10.0, 0.02), (50.0, 0.02), (60.0, 0.0)],
            -10.0,
            100.0,
        );
        // Height gained: 0.02 * (40 + 10/2 + 10/2) = 1.0 m.
        assert!((p.height(100.0) - p.height(0.0) - 1.0).abs() < 1e-9);
        assert!((p.grade(30.0) - 0.02).abs() < 1e-15);
    }
}
