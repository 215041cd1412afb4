//! Area correlation: NCC refinement to sub-pixel, the motion check, magnified and
//! recentred templates.
use super::*;

/// A grey image of `w x h` as a view (the tests' images are valid by construction).
fn view(img: &[u8], w: usize, h: usize) -> ImageView<'_> {
    ImageView::new(img, w, h).unwrap()
}

/// A sum of sines `(amplitude, x frequency, y frequency, phase)` around grey 128,
/// sampled at a horizontal shift.
fn sines(w: usize, h: usize, shift: f64, waves: &[(f64, f64, f64, f64)]) -> Vec<u8> {
    let mut img = vec![0u8; w * h];
    for r in 0..h {
        for c in 0..w {
            let (x, y) = (c as f64 + shift, r as f64);
            let v = waves.iter().fold(128.0, |v, &(a, fx, fy, ph)| {
                v + a * libm::sin(fx * x + fy * y + ph)
            });
            img[r * w + c] = v.round().clamp(0.0, 255.0) as u8;
        }
    }
    img
}

/// A textured image, sampled at a horizontal shift.
fn texture(w: usize, h: usize, shift: f64) -> Vec<u8> {
    let waves = [
        (40.0, 0.31, 0.17, 0.0),
        (35.0, 0.13, -0.29, 1.0),
        (25.0, 0.53, 0.41, 2.0),
    ];
    sines(w, h, shift, &waves)
}

/// Smoothed pseudo-random grey levels (3 x 3 box over white noise), sampled `shift`
/// whole pixels (at most 62) to the right: a texture that repeats nowhere.
fn noise(w: usize, h: usize, shift: usize) -> Vec<u8> {
    let wide = w + 64;
    let mut state = 0x2545_f491_4f6c_dd1du64;
    let raw: Vec<f64> = (0..wide * (h + 2))
        .map(|_| {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 56) as f64
        })
        .collect();
    let mut img = vec![0u8; w * h];
    for r in 0..h {
        for c in 0..w {
            let mut v = 0.0;
            for dr in 0..3 {
                for dc in 0..3 {
                    v += raw[(r + dr) * wide + c + shift + dc];
                }
            }
            img[r * w + c] = (v / 9.0).round() as u8;
        }
    }
    img
}

/// A texture of broad features (a photograph magnified on a near facade).
fn broad_texture(w: usize, h: usize, shift: f64) -> Vec<u8> {
    let waves = [
        (50.0, 0.16, 0.09, 0.0),
        (40.0, 0.07, -0.15, 1.0),
        (20.0, 0.23, 0.12, 2.0),
    ];
    sines(w, h, shift, &waves)
}

#[test]
fn ncc_refinement_recovers_subpixel_disparity() {
    let (w, h) = (120, 60);
    let left = texture(w, h, 0.0);
    // right(c) = left(c + 10.37): the match of left x is right x - 10.37.
    let right = texture(w, h, 10.37);
    let (li, ri) = (view(&left, w, h), view(&right, w, h));
    let cfg = RefineConfig {
        min_ncc: 0.9,
        ..Default::default()
    };
    for x in [40.0f32, 55.3, 70.8] {
        let start = [x - 10.0, 30.0]; // a keypoint 0.37 px off
        let found = refine_match(&mut Correlator::new(), &li, &ri, [x, 30.0], start, &cfg).unwrap();
        let (p, score) = (found.at, found.score);
        assert!(score > 0.95);
        assert!(
            (p[0] - (x - 10.37)).abs() < 0.08,
            "{} vs {}",
            p[0],
            x - 10.37
        );
        assert_eq!(p[1], 30.0);
    }
    // Flat image, border, peak beyond the search radius.
    let flat = vec![100u8; w * h];
    let fi = view(&flat, w, h);
    assert_eq!(
        refine_match(
            &mut Correlator::new(),
            &fi,
            &ri,
            [50.0, 30.0],
            [40.0, 30.0],
            &cfg
        ),
        Err(refine::RefineError::Flat)
    );
    assert_eq!(
        refine_match(
            &mut Correlator::new(),
            &li,
            &ri,
            [2.0, 30.0],
            [1.0, 30.0],
            &cfg
        ),
        Err(refine::RefineError::Border)
    );
    assert!(refine_match(
        &mut Correlator::new(),
        &li,
        &ri,
        [50.0, 30.0],
        [45.0, 30.0],
        &cfg
    )
    .is_err());
    assert_eq!(
        refine_match(
            &mut Correlator::new(),
            &li,
            &ri,
            [f32::NAN, 30.0],
            [45.0, 30.0],
            &cfg
        ),
        Err(refine::RefineError::Border)
    );
}

#[test]
fn row_search_finds_the_disparity_and_refuses_a_repeated_texture() {
    use refine::TEMPLATE_LEN;
    use refine::{
        refine_checked, sample_template, search_line, Correlator, LineSegment, RefineError,
    };
    let row = |x: f32, range| LineSegment::row([x, 30.0], range);
    let (w, h) = (240, 60);
    let left = texture(w, h, 0.0);
    // right(c) = left(c + 23.6): the match of left x is right x - 23.6.
    let right = texture(w, h, 23.6);
    let (li, ri) = (view(&left, w, h), view(&right, w, h));
    let cfg = RefineConfig::default();
    let accept = (cfg.min_ncc, 0.8);
    let mut tpl = [0f32; TEMPLATE_LEN];
    let template = |img: &ImageView, at: [f32; 2], tpl: &mut [f32; TEMPLATE_LEN]| {
        sample_template(img, at, 4, tpl).unwrap();
    };
    // Whole runs; one that starts past the image's left edge (its first 45 positions
    // cut); one whose match lies in the last chunk, moved back to end the run; one near
    // the right edge (as near as the refinement's back check allows).
    for (x, range) in [
        (120.0f32, (0, 100)),
        (151.3, (0, 100)),
        (200.8, (0, 100)),
        (60.0, (0, 100)),
        (120.0, (20, 60)),
        (228.0, (0, 100)),
    ] {
        template(&li, [x, 30.0], &mut tpl);
        let guess = search_line(&tpl, 4, &ri, row(x, range), accept).unwrap();
        // Whole-pixel disparity: within half a pixel, and the refinement gets the rest.
        assert!((guess[0] - (x - 23.6)).abs() <= 0.5, "{guess:?} at {x}");
        assert_eq!(guess[1], 30.0);
        // The refinement's own error on this texture reaches 0.1 px at x = 60.
        let p = refine_checked(&mut Correlator::new(), &li, &ri, [x, 30.0], guess, &cfg)
            .unwrap()
            .at;
        assert!((p[0] - (x - 23.6)).abs() < 0.12, "{p:?} at {x}");
    }
    // A sloping line (a general rig): the match 23.6 px left and 2.36 px up.
    let waves = |sx: f64, sy: f64| {
        [
            (40.0, 0.31, 0.17, 0.0),
            (35.0, 0.13, -0.29, 1.0),
            (25.0, 0.53, 0.41, 2.0),
        ]
        .map(|(a, fx, fy, ph): (f64, f64, f64, f64)| (a, fx, fy, ph + fx * sx + fy * sy))
    };
    let (gl, gr) = (
        sines(w, h, 0.0, &waves(0.0, 0.0)),
        sines(w, h, 0.0, &waves(23.6, 2.36)),
    );
    let (gli, gri) = (view(&gl, w, h), view(&gr, w, h));
    let free = RefineConfig {
        rows_only: false,
        ..cfg
    };
    for x in [120.0f32, 151.3] {
        template(&gli, [x, 30.0], &mut tpl);
        let line = LineSegment::between([x - 80.0, 22.0], [x, 30.0]).unwrap();
        assert!(
            (line.slope - 0.1).abs() < 1e-6 && line.steps == 81,
            "{line:?}"
        );
        let guess = search_line(&tpl, 4, &gri, line, accept).unwrap();
        assert!((guess[0] - (x - 23.6)).abs() <= 0.5, "{guess:?} at {x}");
        assert!((guess[1] - 27.64).abs() <= 0.05, "{guess:?} at {x}");
        // The two-axis refinement is a single fit, without the row's re-centring: up to
        // 0.35 px across the row on this texture.
        let p = refine_checked(&mut Correlator::new(), &gli, &gri, [x, 30.0], guess, &free)
            .unwrap()
            .at;
        assert!(
            (p[0] - (x - 23.6)).abs() < 0.1 && (p[1] - 27.64).abs() < 0.4,
            "{p:?}"
        );
    }
    // Lines the search does not follow: too steep, or running from far to near.
    assert!(LineSegment::between([100.0, 10.0], [150.0, 30.0]).is_none());
    assert!(LineSegment::between([150.0, 30.0], [100.0, 30.0]).is_none());
    // On a texture that does not repeat, the true disparity outside the range leaves
    // no peak that passes.
    let (nl, nr) = (noise(w, h, 0), noise(w, h, 23));
    let (nli, nri) = (view(&nl, w, h), view(&nr, w, h));
    for x in [120.0f32, 150.0, 200.0] {
        template(&nli, [x, 30.0], &mut tpl);
        let found = search_line(&tpl, 4, &nri, row(x, (0, 100)), accept).unwrap();
        assert!((found[0] - (x - 23.0)).abs() < 0.01, "{found:?} at {x}");
        let r = search_line(&tpl, 4, &nri, row(x, (30, 100)), accept);
        assert!(r.is_err(), "{r:?} at {x}");
        // The match at the range's end: it may lie beyond it.
        let r = search_line(&tpl, 4, &nri, row(x, (23, 100)), accept);
        assert_eq!(r, Err(RefineError::PeakOnEdge), "at {x}");
    }
    // A segment longer than the search keeps its far end; ends that are not finite
    // give none.
    let long = LineSegment::between([-5000.0, 30.0], [150.0, 30.0]).unwrap();
    assert_eq!(long.steps, refine::MAX_LINE_STEPS);
    assert_eq!(
        long.start,
        [150.0 - (refine::MAX_LINE_STEPS - 1) as f32, 30.0]
    );
    assert!(LineSegment::between([f32::NEG_INFINITY, 30.0], [150.0, 30.0]).is_none());
    assert!(LineSegment::between([10.0, 30.0], [f32::NAN, 30.0]).is_none());
    assert_eq!(
        LineSegment::row([150.0, 30.0], (usize::MAX, usize::MAX)).steps,
        1
    );
    // Too near the left border for the range to hold a chunk of positions.
    template(&li, [12.0, 30.0], &mut tpl);
    assert_eq!(
        search_line(&tpl, 4, &ri, row(12.0, (0, 100)), accept),
        Err(RefineError::Border)
    );
    // Stripes that repeat every 12 pixels along the row: every period correlates alike.
    let stripes = |shift| {
        sines(
            w,
            h,
            shift,
            &[(60.0, 2.0 * core::f64::consts::PI / 12.0, 0.05, 0.0)],
        )
    };
    let (sl, sr) = (stripes(0.0), stripes(23.6));
    let (sli, sri) = (view(&sl, w, h), view(&sr, w, h));
    template(&sli, [150.0, 30.0], &mut tpl);
    assert_eq!(
        search_line(&tpl, 4, &sri, row(150.0, (0, 100)), accept),
        Err(RefineError::Ambiguous)
    );
    // A flat template, and one that appears nowhere in the right image.
    let flat = vec![90u8; w * h];
    template(&view(&flat, w, h), [150.0, 30.0], &mut tpl);
    assert_eq!(
        search_line(&tpl, 4, &ri, row(150.0, (0, 100)), accept),
        Err(RefineError::Flat)
    );
    let other = broad_texture(w, h, 0.0);
    template(&view(&other, w, h), [150.0, 30.0], &mut tpl);
    assert!(search_line(&tpl, 4, &ri, row(150.0, (0, 100)), (0.95, 0.8)).is_err());
}

#[test]
fn motion_check_removes_consistent_wrong_loops() {
    // Quads that close their loop but were matched to a neighbour in both current images
    // (a repeated window) are found by the rigid-motion check; the true ones all stay.
    let rig = rectified_rig();
    let prev = pose_at(0.0);
    let cur = Pose::from_degrees(90.3, 0.1, -0.2, [0.05, 0.9, 0.01]);
    let scene = SyntheticScene::street(51);
    let mut obs = Vec::new();
    for id in 0..400 {
        let p = scene.point(id);
        let px = |pose: &Pose, cam: &Interior| project_to_pixel(pose, cam, &p).ok();
        let v = [
            px(&prev, &rig.left),
            px(&rig.right_pose(&prev), &rig.right),
            px(&cur, &rig.left),
            px(&rig.right_pose(&cur), &rig.right),
        ];
        if let [Some(a), Some(b), Some(c), Some(d)] = v {
            obs.push([a, b, c, d].map(|q| [q[0] as f32, q[1] as f32]));
        }
    }
    let n = obs.len();
    let mut wrong = 0;
    for (i, o) in obs.iter_mut().enumerate() {
        if i % 10 == 3 {
            // Both current observations shifted together: the stereo loop still closes.
            o[2][0] += 9.0;
            o[3][0] += 9.0;
            wrong += 1;
        }
    }
    motion::to_corrected(&rig, &mut obs);
    let mut pts = vec![[0.0f64; 3]; 2 * n];
    let mut inlier = vec![0u8; n];
    let cfg = motion::MotionCheckConfig::default();
    let m = motion::check_motion(&rig, &cfg, &obs, &mut pts, &mut inlier, 1).expect("enough quads");
    for (i, &f) in inlier.iter().enumerate() {
        assert_eq!(f == 1, i % 10 != 3, "quad {i}");
    }
    assert_eq!(inlier.iter().filter(|&&f| f == 0).count(), wrong);
    // The motion found is the true one (in the previous camera frame).
    let truth = relative_motion(&prev, &cur);
    let t_true = -(truth.rotation() * truth.centre_vec());
    assert!((m.t - t_true).norm() < 0.05, "{} vs {}", m.t, t_true);
    // Too few quads: no verdict, everything kept.
    let mut few = vec![0u8; 5];
    let cfg = motion::MotionCheckConfig {
        min_quads: 8,
        ..cfg
    };
    assert!(motion::check_motion(&rig, &cfg, &obs[..5], &mut pts, &mut few, 1).is_none());
    assert!(few.iter().all(|&f| f == 1));
}

#[test]
fn magnified_template_keeps_its_centre_and_scales_a_ramp() {
    use super::refine::{magnify_template, TEMPLATE_LEN};
    let h = 4usize;
    let n = 2 * h + 1;
    let mut tpl = [0f32; TEMPLATE_LEN];
    for v in 0..n {
        for u in 0..n {
            tpl[v * n + u] = 3.0 * u as f32 + 7.0 * v as f32;
        }
    }
    let mut out = [0f32; TEMPLATE_LEN];
    assert!(magnify_template(&tpl, h, 1.0, &mut out));
    assert_eq!(out[..n * n], tpl[..n * n]);
    assert!(magnify_template(&tpl, h, 2.0, &mut out));
    let centre = h * n + h;
    assert!((out[centre] - tpl[centre]).abs() < 1e-4);
    // Twice as large: half the slope on each axis, around the same centre.
    assert!((out[centre + 1] - out[centre] - 1.5).abs() < 1e-4);
    assert!((out[centre + n] - out[centre] - 3.5).abs() < 1e-4);
    // Shrinking would read outside the template: refused.
    assert!(!magnify_template(&tpl, h, 0.9, &mut out));
    assert!(!magnify_template(&tpl, 0, 1.5, &mut out));
}

/// A 120 x 60 pair of `tex` in which left (60, 30) is at right (49.63, 30)
/// (right(c) = left(c + 10.37)), and the left template (half-size 4) around (60, 30).
fn shifted_pair(
    tex: fn(usize, usize, f64) -> Vec<u8>,
) -> (Vec<u8>, Vec<u8>, [f32; refine::TEMPLATE_LEN]) {
    let (left, right) = (tex(120, 60, 0.0), tex(120, 60, 10.37));
    let mut tpl = [0f32; refine::TEMPLATE_LEN];
    refine::sample_template(&view(&left, 120, 60), [60.0, 30.0], 4, &mut tpl).unwrap();
    (left, right, tpl)
}

#[test]
fn a_recentred_correlation_does_not_lean_towards_its_start() {
    let (w, h) = (120, 60);
    let (_, right, tpl) = shifted_pair(broad_texture);
    let ri = view(&right, w, h);
    // The same match searched from starts a fraction of a pixel either side of it.
    let spread = |f: &dyn Fn([f32; 2]) -> [f32; 2]| {
        let xs: std::vec::Vec<f32> = (-4..=4)
            .map(|i| f([49.63 + 0.1 * i as f32, 30.0])[0])
            .collect();
        let (lo, hi) = xs
            .iter()
            .fold((f32::MAX, f32::MIN), |a, &x| (a.0.min(x), a.1.max(x)));
        hi - lo
    };
    let single = spread(&|s| {
        refine::Correlator::new()
            .correlate(&tpl, 4, &ri, s, (2, 0), 0.9)
            .unwrap()
            .at
    });
    let centred = spread(&|s| {
        let found = refine::Correlator::new()
            .correlate(&tpl, 4, &ri, s, (2, 0), 0.9)
            .unwrap();
        refine::Correlator::new()
            .recentre(&tpl, 4, &ri, found, (1, 0), 0.9)
            .at
    });
    // Measured: 0.032 px from the single fit, 0.002 px re-centred.
    assert!(single > 0.02, "single fit: {single} px");
    assert!(centred < 0.005, "re-centred: {centred} px");
}

#[test]
fn a_converging_rigs_stereo_match_does_not_lean_towards_its_start() {
    let (w, h) = (120, 60);
    let (left, right, tpl) = shifted_pair(texture);
    let (li, ri) = (view(&left, w, h), view(&right, w, h));
    // A converging rig's search: both axes, then the left-right check.
    let cfg = RefineConfig {
        min_ncc: 0.9,
        rows_only: false,
        ..Default::default()
    };
    let range = |r: (f32, f32), x: f32| (r.0.min(x), r.1.max(x));
    let empty = (f32::MAX, f32::MIN);
    let (mut single, mut xs, mut ys) = (empty, empty, empty);
    for i in -4..=4 {
        for j in [-0.3f32, 0.0, 0.3] {
            let start = [49.63 + 0.1 * i as f32, 30.0 + j];
            let fit = Correlator::new()
                .correlate(&tpl, 4, &ri, start, (2, 2), 0.9)
                .unwrap();
            single = range(single, fit.at[0]);
            let p =
                refine::refine_checked(&mut Correlator::new(), &li, &ri, [60.0, 30.0], start, &cfg)
                    .unwrap()
                    .at;
            (xs, ys) = (range(xs, p[0]), range(ys, p[1]));
        }
    }
    // Measured: the single fits from 49.21 to 49.87, the returned positions within
    // 0.005 px of each other and 0.041 px of the truth (least squares' own error on
    // this texture, the same from every start: `bench/traverse/README.md`).
    assert!(single.1 - single.0 > 0.3, "single fits {single:?}");
    assert!(xs.1 - xs.0 < 0.005 && ys.1 - ys.0 < 0.005, "{xs:?} {ys:?}");
    let off = (xs.0 - 49.63).abs().max((xs.1 - 49.63).abs());
    let off = off.max((ys.0 - 30.0).abs()).max((ys.1 - 30.0).abs());
    assert!(off < 0.05, "{off} px from the truth");
}

/// `correlate` (lanes of offsets summed side by side) against a window-by-window NCC in
/// f64 with the same sub-pixel parabola: the same peak, the same position.
#[test]
fn correlate_agrees_with_a_direct_ncc_at_every_search_size() {
    let (w, h) = (120usize, 80usize);
    let img: Vec<u8> = (0..w * h)
        .map(|i| {
            let (x, y) = ((i % w) as f64, (i / w) as f64);
            (128.0 + 60.0 * (0.31 * x + 0.17 * y).sin() + 40.0 * (0.23 * y - 0.11 * x).cos()) as u8
        })
        .collect();
    let iv = ImageView::new(&img, w, h).unwrap();
    let bil = |x: f64, y: f64| {
        let (c, r) = (x.floor() as usize, y.floor() as usize);
        let (fx, fy) = (x - c as f64, y - r as f64);
        let p = |cc: usize, rr: usize| img[rr * w + cc] as f64;
        (p(c, r) * (1.0 - fx) + p(c + 1, r) * fx) * (1.0 - fy)
            + (p(c, r + 1) * (1.0 - fx) + p(c + 1, r + 1) * fx) * fy
    };
    // Starts off the template's position (60.3, 40.2), so most peaks are off centre.
    let cases = [
        (4usize, (1usize, 0usize), [60.1f32, 40.2f32]),
        (4, (2, 2), [61.2, 39.4]),
        (3, (4, 4), [62.4, 38.9]),
        (7, (3, 1), [58.5, 40.0]),
    ];
    for (half, (rx, ry), start) in cases {
        let mut tpl = [0f32; refine::TEMPLATE_LEN];
        refine::sample_template(&iv, [60.3, 40.2], half, &mut tpl).unwrap();
        let n = 2 * half + 1;
        let t: Vec<f64> = tpl[..n * n].iter().map(|&v| v as f64).collect();
        let tm = t.iter().sum::<f64>() / t.len() as f64;
        let ncc = |ox: f64, oy: f64| {
            let s: Vec<f64> = (0..n * n)
                .map(|k| {
                    let (u, v) = ((k % n) as f64, (k / n) as f64);
                    bil(
                        start[0] as f64 + ox + u - half as f64,
                        start[1] as f64 + oy + v - half as f64,
                    )
                })
                .collect();
            let sm = s.iter().sum::<f64>() / s.len() as f64;
            let cross: f64 = s.iter().zip(&t).map(|(a, b)| (a - sm) * (b - tm)).sum();
            let ss: f64 = s.iter().map(|a| (a - sm) * (a - sm)).sum();
            let tt: f64 = t.iter().map(|b| (b - tm) * (b - tm)).sum();
            cross / (ss * tt).sqrt()
        };
        let (mut best, mut at) = (f64::MIN, (0i32, 0i32));
        for oy in -(ry as i32)..=ry as i32 {
            for ox in -(rx as i32)..=rx as i32 {
                let v = ncc(ox as f64, oy as f64);
                if v > best {
                    (best, at) = (v, (ox, oy));
                }
            }
        }
        let vertex = |a: f64, b: f64, c: f64| (0.5 * (a - c) / (a - 2.0 * b + c)).clamp(-0.5, 0.5);
        let (bx, by) = (at.0 as f64, at.1 as f64);
        let dx = vertex(ncc(bx - 1.0, by), best, ncc(bx + 1.0, by));
        let dy = if ry > 0 {
            vertex(ncc(bx, by - 1.0), best, ncc(bx, by + 1.0))
        } else {
            0.0
        };
        let found = refine::Correlator::new()
            .correlate(&tpl, half, &iv, start, (rx, ry), 0.5)
            .unwrap();
        let (p, peak) = (found.at, found.score);
        let what = std::format!("half {half}, radius ({rx}, {ry})");
        assert!(
            (peak as f64 - best).abs() < 1e-4,
            "{what}: peak {peak} vs {best}"
        );
        assert!(
            (p[0] as f64 - (start[0] as f64 + bx + dx)).abs() < 2e-3,
            "{what}: x {}",
            p[0]
        );
        assert!(
            (p[1] as f64 - (start[1] as f64 + by + dy)).abs() < 2e-3,
            "{what}: y {}",
            p[1]
        );
    }
}

/// The precision a peak reports ([`refine::Peak`]) follows what limits the match: it
/// grows with the noise of the searched image and with the breadth of the texture, and
/// the measured errors grow with it.
#[test]
fn a_peak_reports_the_precision_of_its_match() {
    let (w, h) = (120, 60);
    // Noise of about `amp` grey levels on the right image.
    let noisy = |img: &[u8], amp: f64| -> std::vec::Vec<u8> {
        let mut state = 0x9e37_79b9_7f4a_7c15u64;
        img.iter()
            .map(|&v| {
                state ^= state << 13;
                state ^= state >> 7;
                state ^= state << 17;
                let n = ((state >> 40) as f64 / (1u64 << 24) as f64 - 0.5) * 2.0 * amp;
                (v as f64 + n).round().clamp(0.0, 255.0) as u8
            })
            .collect()
    };
    // Mean reported sigma and RMS error (x) over matches of a texture whose right
    // image is the left shifted by 10.37 px, searched along the row.
    let measure = |make: &dyn Fn(f64) -> std::vec::Vec<u8>, amp: f64| -> (f32, f32) {
        let left = make(0.0);
        let right = noisy(&make(10.37), amp);
        let (li, ri) = (view(&left, w, h), view(&right, w, h));
        let (mut sigma, mut err2, mut n) = (0f32, 0f32, 0f32);
        for i in 0..40 {
            let (x, y) = (30.0 + 1.5 * i as f32, 20.0 + (i % 4) as f32 * 5.0);
            let mut tpl = [0f32; refine::TEMPLATE_LEN];
            refine::sample_template(&li, [x, y], 4, &mut tpl).unwrap();
            let Ok(p) =
                refine::Correlator::new().correlate(&tpl, 4, &ri, [x - 10.0, y], (2, 0), 0.5)
            else {
                continue;
            };
            assert!(p.sigma[0].is_finite() && p.sigma[0] > 0.0, "{p:?}");
            sigma += p.sigma[0];
            err2 += (p.at[0] - (x - 10.37)).powi(2);
            n += 1.0;
        }
        assert!(n >= 30.0, "{n} of 40 matched");
        (sigma / n, libm::sqrtf(err2 / n))
    };
    let fine = |s: f64| texture(w, h, s);
    let broad = |s: f64| broad_texture(w, h, s);
    let (clean, clean_err) = measure(&fine, 0.0);
    let (noisy_fine, noisy_err) = measure(&fine, 12.0);
    let (noisy_broad, noisy_broad_err) = measure(&broad, 12.0);
    // Measured: sigma 0.030, 0.058 and 0.160 px; errors 0.041, 0.089 and 0.615 px.
    assert!(
        noisy_fine > 1.5 * clean,
        "noise: {clean} -> {noisy_fine} px"
    );
    assert!(
        noisy_broad > 2.0 * noisy_fine,
        "breadth: {noisy_fine} -> {noisy_broad} px"
    );
    assert!(
        noisy_err > 1.5 * clean_err && noisy_broad_err > 2.0 * noisy_err,
        "errors {clean_err} {noisy_err} {noisy_broad_err} px"
    );
    for (s, e) in [
        (clean, clean_err),
        (noisy_fine, noisy_err),
        (noisy_broad, noisy_broad_err),
    ] {
        assert!(
            e > 0.5 * s && e < 5.0 * s,
            "error {e} px against sigma {s} px"
        );
    }
    // A search along the row measures x only: y takes its value.
    let (left, right) = (texture(w, h, 0.0), texture(w, h, 10.37));
    let (li, ri) = (view(&left, w, h), view(&right, w, h));
    let mut tpl = [0f32; refine::TEMPLATE_LEN];
    refine::sample_template(&li, [60.0, 30.0], 4, &mut tpl).unwrap();
    let p = refine::Correlator::new()
        .correlate(&tpl, 4, &ri, [50.0, 30.0], (2, 0), 0.5)
        .unwrap();
    assert!(p.sigma[0] > 0.0 && p.sigma[1] == p.sigma[0], "{p:?}");
}

/// The template is sampled with each column's and row's bilinear weights computed once;
/// the samples are the per-sample bilinear interpolation's to the bit, also where the
/// coordinates cross a power of two (127.x to 128.x: there the fractions of the columns
/// differ in their last bits).
#[test]
fn template_samples_are_the_bilinear_interpolation_to_the_bit() {
    let (w, h) = (300usize, 200usize);
    let img: Vec<u8> = (0..w * h)
        .map(|i| ((i * 7919 + (i / w) * 31) % 251) as u8)
        .collect();
    let iv = view(&img, w, h);
    let reference = |x: f32, y: f32| {
        let (c, r) = (x as usize, y as usize);
        let (fx, fy) = (x - c as f32, y - r as f32);
        let p = |c: usize, r: usize| img[r * w + c] as f32;
        let top = p(c, r) * (1.0 - fx) + p(c + 1, r) * fx;
        let bot = p(c, r + 1) * (1.0 - fx) + p(c + 1, r + 1) * fx;
        top * (1.0 - fy) + bot * fy
    };
    for (at, half) in [
        ([127.731f32, 63.917f32], 4usize),
        ([255.6031, 127.7013], 7),
        ([40.5, 30.25], 3),
        ([100.0, 100.0], 1),
    ] {
        let mut tpl = [0f32; refine::TEMPLATE_LEN];
        refine::sample_template(&iv, at, half, &mut tpl).unwrap();
        let n = 2 * half + 1;
        for v in 0..n {
            for u in 0..n {
                let x = at[0] + u as f32 - half as f32;
                let y = at[1] + v as f32 - half as f32;
                assert_eq!(
                    tpl[v * n + u].to_bits(),
                    reference(x, y).to_bits(),
                    "at {at:?}, sample ({u}, {v})"
                );
            }
        }
    }
}

/// A smooth random texture for [`sines`]: 16 waves of amplitude 12 grey levels, random
/// directions and phases, frequencies up to `band` radians per pixel on each axis (`seed`
/// draws them).
fn random_waves(band: f64, seed: u64) -> Vec<(f64, f64, f64, f64)> {
    let mut rng = crate::testkit::Rng(seed);
    (0..16)
        .map(|_| {
            let fx = rng.uniform(-band, band);
            let fy = rng.uniform(-band, band);
            (12.0, fx, fy, rng.uniform(0.0, 6.3))
        })
        .collect()
}

/// The re-centred parabola leans by a texture's own amount: its peak is not a parabola,
/// and the lean is the same wherever the match falls, so it does not average out over a
/// track; it is a disparity error the window takes for scale (on a rendered street,
/// -0.025 px on the points 20 to 30 m away and steps 0.07 % too long). Least squares
/// along the row has no such lean. The lean of one texture is its mean error over ten
/// positions a tenth of a pixel apart; measured over sixteen textures, its RMS is
/// 0.062 px re-centred and 0.014 px by least squares.
#[test]
fn a_rectified_rigs_stereo_match_does_not_lean_with_its_texture() {
    let (w, h) = (120, 60);
    let cfg = RefineConfig {
        min_ncc: 0.5,
        rows_only: true,
        ..Default::default()
    };
    let lean = |waves: &[(f64, f64, f64, f64)]| {
        let left = sines(w, h, 0.0, waves);
        let li = view(&left, w, h);
        let errors = (0..10).map(|i| {
            // Left (60, 30) is at right (xr, 30).
            let xr = 49.0 + 0.1 * i as f64;
            let right = sines(w, h, 60.0 - xr, waves);
            let ri = view(&right, w, h);
            let start = [xr.round() as f32 + 0.3, 30.0];
            let found =
                refine::refine_checked(&mut Correlator::new(), &li, &ri, [60.0, 30.0], start, &cfg);
            found.unwrap().at[0] as f64 - xr
        });
        errors.sum::<f64>() / 10.0
    };
    let leans: Vec<f64> = (1..=8u64)
        .flat_map(|seed| [0.5, 0.9].map(|band| lean(&random_waves(band, seed))))
        .collect();
    let rms = libm::sqrt(leans.iter().map(|l| l * l).sum::<f64>() / leans.len() as f64);
    assert!(rms < 0.03, "RMS lean {rms:.3} px: {leans:?}");
}
