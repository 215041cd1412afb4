//! Reduced SIFT: memory prediction vs measurement, synthetic scenes with known
//! keypoints, determinism, rotation covariance, capacity and bad input.

use phototraverse_core::budget::{Arena, ComponentKind, MemoryBudget};
use phototraverse_core::features::{Descriptor, FeatureSet, Keypoint};
use phototraverse_core::image::{ImageError, ImageView};
use phototraverse_core::sift::{Sift, SiftConfig, SiftError, SiftStats};
use proptest::prelude::*;

struct Run {
    result: Result<SiftStats, SiftError>,
    keypoints: Vec<Keypoint>,
    descriptors: Vec<Descriptor>,
    working_used: usize,
    budget: MemoryBudget,
    total_used: usize,
}

fn run(cfg: SiftConfig, px: &[u8], w: usize, h: usize) -> Run {
    let mut budget = MemoryBudget::new();
    cfg.budget(&mut budget).expect("valid config");
    let mut storage = vec![0u8; budget.total()];
    let mut arena = Arena::new(&mut storage);
    let mut sift = Sift::new(cfg, &mut arena).expect("arena sized by the budget");
    let working_used = arena.used();
    let mut set = FeatureSet::new(&mut arena, cfg.max_keypoints).expect("storage");
    let total_used = arena.used();
    let result = match ImageView::new(px, w, h) {
        Ok(view) => sift.extract(&view, &mut set),
        Err(e) => Err(SiftError::Image(e)),
    };
    Run {
        result,
        keypoints: set.keypoints().to_vec(),
        descriptors: set.descriptors().to_vec(),
        working_used,
        budget,
        total_used,
    }
}

fn cfg(w: usize, h: usize) -> SiftConfig {
    SiftConfig {
        max_width: w,
        max_height: h,
        ..SiftConfig::default()
    }
}

/// A textured test image: smooth pseudo-random blobs of several sizes (deterministic).
fn texture(w: usize, h: usize, seed: u64) -> Vec<u8> {
    let mut s = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
    let mut next = move || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        s
    };
    let mut f = vec![100.0f32; w * h];
    for _ in 0..(w * h / 150) {
        let cx = (next() % w as u64) as f32;
        let cy = (next() % h as u64) as f32;
        let sg = 1.5 + (next() % 60) as f32 / 10.0;
        let a = (next() % 160) as f32 - 80.0;
        let r = (3.0 * sg) as isize;
        for y in (cy as isize - r).max(0)..(cy as isize + r + 1).min(h as isize) {
            for x in (cx as isize - r).max(0)..(cx as isize + r + 1).min(w as isize) {
                let d2 = (x as f32 - cx).powi(2) + (y as f32 - cy).powi(2);
                f[y as usize * w + x as usize] += a * (-d2 / (2.0 * sg * sg)).exp();
            }
        }
    }
    f.iter()
        .map(|v| v.round().clamp(0.0, 255.0) as u8)
        .collect()
}

/// Isolated Gaussian blobs of sigma `sg` on a flat background, centres on a grid.
fn blobs(w: usize, h: usize, step: usize, sg: f32) -> (Vec<u8>, Vec<(f32, f32)>) {
    let mut centres = Vec::new();
    let mut y = step;
    while y + step <= h {
        let mut x = step;
        while x + step <= w {
            // Alternate bright and dark blobs; offset by a fraction to exercise sub-pixel refinement.
            centres.push((x as f32 + 0.3, y as f32 - 0.2));
            x += step;
        }
        y += step;
    }
    let mut px = vec![0u8; w * h];
    for r in 0..h {
        for c in 0..w {
            let mut v = 128.0f32;
            for (i, &(cx, cy)) in centres.iter().enumerate() {
                let d2 = (c as f32 - cx).powi(2) + (r as f32 - cy).powi(2);
                let sign = if i % 2 == 0 { 1.0 } else { -1.0 };
                v += sign * 90.0 * (-d2 / (2.0 * sg * sg)).exp();
            }
            px[r * w + c] = v.round().clamp(0.0, 255.0) as u8;
        }
    }
    (px, centres)
}

#[test]
fn budget_predicts_the_arena_and_stays_under_six_bytes_per_pixel() {
    let c = cfg(640, 480);
    let img = texture(640, 480, 3);
    let r = run(c, &img, 640, 480);
    r.result.expect("extracts");
    let predicted_working = r.budget.total_of(ComponentKind::Working);
    let predicted_total = r.budget.total();
    assert!(
        r.working_used <= predicted_working,
        "{} > {}",
        r.working_used,
        predicted_working
    );
    // Only alignment padding may be unused.
    assert!(
        predicted_working - r.working_used < 64,
        "{} vs {}",
        r.working_used,
        predicted_working
    );
    assert!(r.total_used <= predicted_total && predicted_total - r.total_used < 64);
    assert_eq!(r.budget.total_with_prefix("sift."), predicted_total);
    let per_px = r.working_used as f64 / (640.0 * 480.0);
    assert!(per_px <= 6.0, "working memory {per_px:.2} B/px");
    let storage = r.budget.total_of(ComponentKind::Storage);
    assert!(storage >= 1000 * (24 + 128));
}

#[test]
fn finds_every_blob_at_its_centre() {
    let (img, centres) = blobs(240, 180, 40, 3.0);
    let r = run(
        SiftConfig {
            max_keypoints: 500,
            ..cfg(240, 180)
        },
        &img,
        240,
        180,
    );
    let stats = r.result.unwrap();
    assert_eq!(centres.len(), 15);
    for &(cx, cy) in &centres {
        let best = r
            .keypoints
            .iter()
            .map(|k| ((k.x - cx).powi(2) + (k.y - cy).powi(2)).sqrt())
            .fold(f32::INFINITY, f32::min);
        assert!(
            best < 0.35,
            "blob at ({cx}, {cy}): nearest keypoint {best} px away"
        );
    }
    // A blob of sigma 3 is a DoG extremum near scale sigma*sqrt(2) ~ 4.2.
    for k in &r.keypoints {
        let near = centres
            .iter()
            .any(|&(cx, cy)| ((k.x - cx).powi(2) + (k.y - cy).powi(2)).sqrt() < 1.0);
        if near && k.octave == 1 {
            assert!((k.sigma - 4.24).abs() < 0.8, "blob scale {}", k.sigma);
        }
    }
    assert_eq!(stats.kept, r.keypoints.len());
    assert!(stats.extrema >= centres.len());
}

#[test]
fn output_is_identical_between_runs_and_instances() {
    let img = texture(320, 240, 7);
    let a = run(cfg(320, 240), &img, 320, 240);
    let b = run(cfg(320, 240), &img, 320, 240);
    assert!(!a.keypoints.is_empty());
    assert_eq!(a.result, b.result);
    assert_eq!(
        bytemuck::cast_slice::<Keypoint, u8>(&a.keypoints),
        bytemuck::cast_slice::<Keypoint, u8>(&b.keypoints)
    );
    assert_eq!(a.descriptors, b.descriptors);
    // The same extractor reused on the same image gives the same bytes again.
    let c = cfg(320, 240);
    let mut budget = MemoryBudget::new();
    c.budget(&mut budget).unwrap();
    let mut storage = vec![0u8; budget.total()];
    let mut arena = Arena::new(&mut storage);
    let mut sift = Sift::new(c, &mut arena).unwrap();
    let mut set = FeatureSet::new(&mut arena, c.max_keypoints).unwrap();
    let view = ImageView::new(&img, 320, 240).unwrap();
    let other = texture(320, 240, 8);
    sift.extract(&ImageView::new(&other, 320, 240).unwrap(), &mut set)
        .unwrap();
    sift.extract(&view, &mut set).unwrap();
    assert_eq!(set.descriptors(), &a.descriptors[..]);
}

#[test]
fn rotation_by_ninety_degrees_maps_keypoints_and_descriptors() {
    let (w, h) = (240, 240);
    let img = texture(w, h, 11);
    // Rotate 90 degrees clockwise: (x, y) -> (h - 1 - y, x).
    let mut rot = vec![0u8; w * h];
    for y in 0..h {
        for x in 0..w {
            rot[x * h + (h - 1 - y)] = img[y * w + x];
        }
    }
    let c = SiftConfig {
        max_keypoints: 3000,
        ..cfg(w, h)
    };
    let a = run(c, &img, w, h);
    let b = run(c, &rot, h, w);
    a.result.unwrap();
    b.result.unwrap();
    assert!(a.keypoints.len() > 50, "{}", a.keypoints.len());
    let mut found = 0;
    let mut close = 0;
    for (ka, da) in a.keypoints.iter().zip(&a.descriptors) {
        let (mx, my) = (h as f32 - 1.0 - ka.y, ka.x);
        let best = b
            .keypoints
            .iter()
            .zip(&b.descriptors)
            .filter(|(kb, _)| (kb.x - mx).abs() < 0.3 && (kb.y - my).abs() < 0.3)
            .map(|(kb, db)| {
                let mut dtheta =
                    (kb.orientation - ka.orientation - core::f32::consts::FRAC_PI_2).abs();
                dtheta %= 2.0 * core::f32::consts::PI;
                dtheta = dtheta.min(2.0 * core::f32::consts::PI - dtheta);
                let dist: f32 = da
                    .iter()
                    .zip(db.iter())
                    .map(|(&p, &q)| (p as f32 - q as f32).powi(2))
                    .sum();
                (dtheta, dist.sqrt())
            })
            .fold((f32::INFINITY, f32::INFINITY), |m, v| {
                if v.0 < m.0 {
                    v
                } else {
                    m
                }
            });
        if best.0.is_finite() {
            found += 1;
            // Descriptors have norm 512: a rotated copy stays well within 0.25 of it.
            if best.0 < 0.05 && best.1 < 128.0 {
                close += 1;
            }
        }
    }
    let n = a.keypoints.len();
    assert!(
        found * 10 >= n * 9,
        "{found} of {n} keypoints found after rotation"
    );
    assert!(
        close * 10 >= found * 8,
        "{close} of {found} descriptors match after rotation"
    );
}

#[test]
fn capacity_keeps_strong_keypoints_spread_over_the_grid() {
    let (w, h) = (320, 240);
    let img = texture(w, h, 5);
    let all = run(
        SiftConfig {
            max_keypoints: 5000,
            grid_cols: 4,
            grid_rows: 3,
            ..cfg(w, h)
        },
        &img,
        w,
        h,
    );
    let capped = run(
        SiftConfig {
            max_keypoints: 24,
            grid_cols: 4,
            grid_rows: 3,
            ..cfg(w, h)
        },
        &img,
        w,
        h,
    );
    let s_all = all.result.unwrap();
    let s_cap = capped.result.unwrap();
    assert_eq!(s_all.dropped, 0);
    assert!(all.keypoints.len() > 100);
    assert_eq!(capped.keypoints.len(), 24);
    assert_eq!(s_cap.kept, 24);
    assert_eq!(s_cap.oriented, s_all.oriented);
    assert_eq!(s_cap.dropped, s_cap.oriented - 24);
    // Every cell with at least two candidates keeps two (24 slots, 12 cells).
    let mut per_cell = [0usize; 12];
    let mut cand = [0usize; 12];
    for k in &capped.keypoints {
        per_cell[k.cell as usize] += 1;
    }
    for k in &all.keypoints {
        cand[k.cell as usize] += 1;
    }
    for i in 0..12 {
        assert!(
            per_cell[i] >= cand[i].min(2),
            "cell {i}: {} kept of {}",
            per_cell[i],
            cand[i]
        );
    }
    // Within a cell, what was kept is at least as strong as the cell's median candidate.
    for k in &capped.keypoints {
        let mut r: Vec<f32> = all
            .keypoints
            .iter()
            .filter(|a| a.cell == k.cell)
            .map(|a| a.response)
            .collect();
        r.sort_by(|a, b| b.total_cmp(a));
        assert!(
            k.response >= r[r.len() / 2],
            "weak keypoint kept in cell {}",
            k.cell
        );
    }
}

#[test]
fn fine_octave_adds_small_scale_keypoints_deterministically() {
    let img = texture(320, 240, 9);
    let base = SiftConfig {
        max_keypoints: 5000,
        ..cfg(320, 240)
    };
    let fine = SiftConfig {
        fine_octave: true,
        ..base
    };
    let a = run(base, &img, 320, 240);
    let b = run(fine, &img, 320, 240);
    let c = run(fine, &img, 320, 240);
    let (sa, sb) = (a.result.unwrap(), b.result.unwrap());
    assert_eq!(sb.octaves, sa.octaves + 1);
    assert!(b.keypoints.len() > a.keypoints.len());
    // Octave 0 keeps refined layers >= 0.5 (sigma >= 1.6 * 2^(1/6) ~ 1.796); the fine octave reaches below.
    let small = b.keypoints.iter().filter(|k| k.sigma < 1.79).count();
    assert!(small > 0 && a.keypoints.iter().all(|k| k.sigma >= 1.79));
    assert_eq!(b.descriptors, c.descriptors);
    // Same buffers: the fine octave fits the regular rings.
    assert_eq!(a.budget.total(), b.budget.total());
    assert!(b.total_used <= b.budget.total());
}

#[test]
fn upright_mode_has_zero_orientation() {
    let img = texture(200, 150, 2);
    let r = run(
        SiftConfig {
            upright: true,
            ..cfg(200, 150)
        },
        &img,
        200,
        150,
    );
    let s = r.result.unwrap();
    assert!(!r.keypoints.is_empty());
    assert!(r.keypoints.iter().all(|k| k.orientation == 0.0));
    assert_eq!(s.oriented, s.refined - s.pending_dropped);
}

#[test]
fn full_pending_queue_counts_what_it_drops() {
    let img = texture(200, 150, 4);
    let r = run(
        SiftConfig {
            pending_capacity: 2,
            ..cfg(200, 150)
        },
        &img,
        200,
        150,
    );
    let s = r.result.unwrap();
    assert!(s.pending_dropped > 0);
    assert!(!r.keypoints.is_empty());
}

#[test]
fn bad_images_give_errors_or_nothing() {
    let c = cfg(64, 48);
    // Empty and too large are refused.
    assert_eq!(
        run(c, &[], 0, 0).result.unwrap_err(),
        SiftError::Image(ImageError::Empty)
    );
    let big = vec![7u8; 65 * 48];
    assert!(matches!(
        run(c, &big, 65, 48).result,
        Err(SiftError::Image(ImageError::TooLarge { .. }))
    ));
    // 1x1, constant, saturated: zero features.
    for (px, w, h) in [
        (vec![9u8], 1, 1),
        (vec![128u8; 64 * 48], 64, 48),
        (vec![255u8; 64 * 48], 64, 48),
    ] {
        let r = run(c, &px, w, h);
        assert_eq!(r.result.unwrap().kept, 0);
        assert!(r.keypoints.is_empty());
    }
    // Bad configurations are named.
    let mut b = MemoryBudget::new();
    assert!(matches!(
        SiftConfig { levels: 0, ..c }.budget(&mut b),
        Err(SiftError::BadConfig(_))
    ));
    assert!(matches!(
        SiftConfig {
            sigma0: f32::NAN,
            ..c
        }
        .budget(&mut b),
        Err(SiftError::BadConfig(_))
    ));
    // A short arena is an error, not a panic.
    let mut small = [0u8; 100];
    let mut arena = Arena::new(&mut small);
    assert!(matches!(
        Sift::new(c, &mut arena),
        Err(SiftError::OutOfMemory(_))
    ));
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 48, ..ProptestConfig::default() })]

    #[test]
    fn never_panics_on_any_size_or_content(
        w in 1usize..72, h in 1usize..56, seed in any::<u64>(), kind in 0u8..4, cap in 1usize..40,
        fine in any::<bool>(), upright in any::<bool>(),
    ) {
        let px: Vec<u8> = match kind {
            0 => texture(w, h, seed),
            1 => {
                let mut s = seed | 1;
                (0..w * h).map(|_| { s ^= s << 13; s ^= s >> 7; s ^= s << 17; s as u8 }).collect()
            }
            2 => vec![(seed % 256) as u8; w * h],
            _ => (0..w * h).map(|i| if (i + seed as usize).is_multiple_of(3) { 255 } else { 0 }).collect(),
        };
        let c = SiftConfig { max_width: 64, max_height: 48, max_keypoints: cap, grid_cols: 3, grid_rows: 2, fine_octave: fine, upright, ..SiftConfig::default() };
        let r = run(c, &px, w, h);
        if w > 64 || h > 48 {
            prop_assert!(matches!(r.result, Err(SiftError::Image(ImageError::TooLarge { .. }))), "image over capacity accepted");
        } else {
            let s = r.result.unwrap();
            prop_assert!(r.keypoints.len() <= cap);
            prop_assert_eq!(s.kept, r.keypoints.len());
            for k in &r.keypoints {
                prop_assert!(k.x >= 0.0 && k.x <= (w - 1) as f32 && k.y >= 0.0 && k.y <= (h - 1) as f32);
                prop_assert!(k.sigma > 0.0 && k.orientation >= 0.0 && k.orientation < 2.0 * core::f32::consts::PI);
                prop_assert!((k.cell as usize) < 6);
            }
            if kind == 2 {
                prop_assert_eq!(s.kept, 0);
            }
        }
    }
}

/// The configuration measured against the SIFT benchmark's bars (bench/sift/README.md).
fn bar_config(w: usize, h: usize) -> SiftConfig {
    SiftConfig {
        fine_octave: true,
        input_sigma: 0.0,
        grid_cols: 1,
        grid_rows: 1,
        soft_orientation: true,
        descriptor_grid: 8,
        orientation_stride_sigma: 2.0,
        orientation_radius: 3.0,
        max_keypoints: 3000,
        ..cfg(w, h)
    }
}

#[test]
fn bar_configuration_is_deterministic_and_uses_the_predicted_memory() {
    let img = texture(320, 240, 11);
    let a = run(bar_config(320, 240), &img, 320, 240);
    let b = run(bar_config(320, 240), &img, 320, 240);
    let stats = a.result.unwrap();
    assert_eq!(a.result, b.result);
    assert!(stats.kept > 0);
    assert_eq!(
        bytemuck::cast_slice::<Keypoint, u8>(&a.keypoints),
        bytemuck::cast_slice::<Keypoint, u8>(&b.keypoints)
    );
    assert_eq!(a.descriptors, b.descriptors);
    // The arena holds what the budget predicts, under 6 bytes per pixel at 640x480.
    assert!(a.working_used <= a.budget.total_of(ComponentKind::Working));
    assert!(a.working_used + 64 >= a.budget.total_of(ComponentKind::Working));
    assert!(a.total_used <= a.budget.total());
    let mut vga = MemoryBudget::new();
    bar_config(640, 480).budget(&mut vga).unwrap();
    assert!(vga.total_of(ComponentKind::Working) as f64 / (640.0 * 480.0) <= 6.0);
    // A sparser grid gives other descriptors than the default 20x20 one.
    let dense = run(
        SiftConfig {
            descriptor_grid: 20,
            ..bar_config(320, 240)
        },
        &img,
        320,
        240,
    );
    assert_eq!(
        bytemuck::cast_slice::<Keypoint, u8>(&dense.keypoints),
        bytemuck::cast_slice::<Keypoint, u8>(&a.keypoints)
    );
    assert_ne!(dense.descriptors, a.descriptors);
}

#[test]
fn descriptor_grid_and_orientation_window_are_checked() {
    for (grid, radius, stride, ok) in [
        (8, 3.0, 2.0, true),
        (4, 1.0, 0.5, true),
        (20, 4.5, 3.0, true),
        (0, 3.0, 2.0, false),
        (6, 3.0, 2.0, false),
        (24, 3.0, 2.0, false),
        (8, 0.5, 2.0, false),
        (8, 5.0, 2.0, false),
        (8, f32::NAN, 2.0, false),
        (8, 3.0, 0.0, false),
        (8, 3.0, f32::INFINITY, false),
    ] {
        let c = SiftConfig {
            descriptor_grid: grid,
            orientation_radius: radius,
            orientation_stride_sigma: stride,
            ..cfg(64, 48)
        };
        assert_eq!(
            c.validate().is_ok(),
            ok,
            "grid {grid} radius {radius} stride {stride}"
        );
    }
}
