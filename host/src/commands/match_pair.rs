//! `phototraverse match LEFT RIGHT (--rectified | --rig rig.toml) --out FILE`: the stereo
//! tie points of one pair, one per line `x_left y_left x_right y_right` in COLMAP's
//! pixel convention (top-left image corner at (0, 0): pixel centre + 0.5).
//!
//! Features come from COLMAP text feature files (`--left-features`, `--right-features`,
//! the format `phototraverse features` writes) or, without them, from the core extractor.

use super::features::extract_with;
use crate::dataset::{load_gray, read_rig, GrayImage};
use anyhow::{bail, Context};
use phototraverse_core::budget::Arena;
use phototraverse_core::camera::Interior;
use phototraverse_core::features::{Descriptor, Keypoint};
use phototraverse_core::matching::{
    Features, MatchConfig, Matcher, RefineConfig, StereoFeatures, StereoGeometry, StereoMatch,
    StereoStats,
};
use phototraverse_core::sift::SiftConfig;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

#[derive(clap::Args, Debug, Clone)]
pub struct Args {
    /// Left image.
    pub left: PathBuf,
    /// Right image.
    pub right: PathBuf,
    /// The pair is rectified: search along the same row.
    #[arg(long, conflicts_with = "rig", required_unless_present = "rig")]
    pub rectified: bool,
    /// Calibrated rig (rig.toml, docs/conventions.md): search along the epipolar curve.
    #[arg(long)]
    pub rig: Option<PathBuf>,
    /// Output file (tie points, one per line).
    #[arg(long)]
    pub out: PathBuf,
    /// Smallest disparity x_left - x_right, pixels (--rectified).
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    pub min_disparity: f32,
    /// Largest disparity, pixels (--rectified).
    #[arg(long, default_value_t = 256.0)]
    pub max_disparity: f32,
    /// Row tolerance, pixels (--rectified).
    #[arg(long, default_value_t = 1.0)]
    pub row_tolerance: f32,
    /// Distance to the epipolar curve, pixels (--rig).
    #[arg(long, default_value_t = 2.0)]
    pub epipolar_tolerance: f32,
    /// Depth range along the left ray, metres (--rig); no --max-depth means infinity.
    #[arg(long, default_value_t = 1.0)]
    pub min_depth: f64,
    #[arg(long)]
    pub max_depth: Option<f64>,
    /// Largest squared descriptor distance of a match (u8 descriptors).
    #[arg(long, default_value_t = 120_000)]
    pub max_distance: u32,
    /// Contrast threshold of the extractor (when no feature files are given). The
    /// extractor defaults here are for dense stereo tie points: low contrast, five
    /// levels per octave, a lenient edge test.
    #[arg(long, default_value_t = 0.005)]
    pub contrast: f32,
    /// Detection levels per octave of the extractor.
    #[arg(long, default_value_t = 5)]
    pub levels: usize,
    /// Edge threshold of the extractor.
    #[arg(long, default_value_t = 20.0)]
    pub edge: f32,
    /// Lowe's ratio.
    #[arg(long, default_value_t = 0.8)]
    pub ratio: f32,
    /// Keypoints per image (extracted, or the strongest of the feature files).
    #[arg(long, default_value_t = 4000)]
    pub max_keypoints: usize,
    /// COLMAP text features of the left image (instead of extracting).
    #[arg(long, requires = "right_features")]
    pub left_features: Option<PathBuf>,
    /// COLMAP text features of the right image.
    #[arg(long, requires = "left_features")]
    pub right_features: Option<PathBuf>,
    /// Skip the NCC sub-pixel refinement.
    #[arg(long)]
    pub no_refine: bool,
    /// Smallest NCC peak of a refined match.
    #[arg(long, default_value_t = 0.9)]
    pub min_ncc: f32,
    /// NCC template half-size and search radius, pixels.
    #[arg(long, default_value_t = 3)]
    pub ncc_half: u8,
    #[arg(long, default_value_t = 2)]
    pub ncc_radius: u8,
    /// Left-right NCC check tolerance, pixels (0: off).
    #[arg(long, default_value_t = 0.5)]
    pub back_check: f32,
}

/// Features of one image, in the core's pixel convention.
pub struct ImageFeatures {
    pub keypoints: Vec<Keypoint>,
    pub descriptors: Vec<Descriptor>,
}

/// Reads COLMAP's text feature format: `N 128`, then `X Y SCALE ORIENTATION d1..d128`
/// with X, Y relative to the top-left image corner (converted to pixel centres here).
/// Descriptor values are rounded and clamped to u8.
pub fn read_colmap_features(path: &Path) -> anyhow::Result<ImageFeatures> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    parse_colmap_features(&text).with_context(|| format!("parsing {}", path.display()))
}

pub fn parse_colmap_features(text: &str) -> anyhow::Result<ImageFeatures> {
    let mut lines = text.lines().filter(|l| !l.trim().is_empty());
    let header = lines.next().context("empty feature file")?;
    let mut h = header.split_whitespace();
    let n: usize = h
        .next()
        .context("missing count")?
        .parse()
        .context("bad count")?;
    let dim: usize = h
        .next()
        .context("missing dimension")?
        .parse()
        .context("bad dimension")?;
    if dim != 128 {
        bail!("descriptor dimension {dim}, expected 128");
    }
    let mut out = ImageFeatures {
        keypoints: Vec::with_capacity(n),
        descriptors: Vec::with_capacity(n),
    };
    for (i, line) in lines.enumerate() {
        if i == n {
            bail!("more than the {n} features announced");
        }
        let mut v = line.split_whitespace().map(|t| t.parse::<f64>());
        let mut next = || -> anyhow::Result<f64> {
            let x = v
                .next()
                .with_context(|| format!("feature {i}: too few values"))?;
            let x = x.with_context(|| format!("feature {i}: bad number"))?;
            if !x.is_finite() {
                bail!("feature {i}: non-finite value");
            }
            Ok(x)
        };
        let (x, y, scale, orientation) = (next()?, next()?, next()?, next()?);
        let mut d = [0u8; 128];
        for b in d.iter_mut() {
            *b = next()?.round().clamp(0.0, 255.0) as u8;
        }
        if v.next().is_some() {
            bail!("feature {i}: more than 132 values");
        }
        out.keypoints.push(Keypoint {
            x: (x - 0.5) as f32,
            y: (y - 0.5) as f32,
            sigma: scale as f32,
            orientation: orientation as f32,
            response: 0.0,
            octave: 0,
            cell: 0,
        });
        out.descriptors.push(d);
    }
    if out.keypoints.len() != n {
        bail!("{} features, {n} announced", out.keypoints.len());
    }
    Ok(out)
}

/// Features of an image: from a file when given, else from the core extractor
/// (reduced SIFT with its default settings and `max_keypoints`).
fn features_of(
    file: Option<&Path>,
    image: &GrayImage,
    args: &Args,
) -> anyhow::Result<ImageFeatures> {
    if let Some(f) = file {
        return read_colmap_features(f);
    }
    let (w, h) = (image.width as usize, image.height as usize);
    let cfg = SiftConfig {
        max_width: w,
        max_height: h,
        max_keypoints: args.max_keypoints,
        contrast_threshold: args.contrast,
        levels: args.levels,
        edge_threshold: args.edge,
        pending_capacity: 2 * args.max_keypoints.max(1024),
        ..SiftConfig::default()
    };
    let mut out = ImageFeatures {
        keypoints: Vec::new(),
        descriptors: Vec::new(),
    };
    extract_with(cfg, &image.data, w, h, 1, |set| {
        out.keypoints = set.keypoints().to_vec();
        out.descriptors = set.descriptors().to_vec();
        Ok(())
    })?;
    Ok(out)
}

/// The matcher configuration the arguments describe.
pub fn config_from_args(
    args: &Args,
    width: u32,
    height: u32,
    n: usize,
) -> anyhow::Result<MatchConfig> {
    let stereo = match &args.rig {
        Some(path) => {
            let (rig, _datum) = read_rig(path)?;
            check_format(&rig.left, width, height)?;
            StereoGeometry::Rig {
                rig,
                tolerance_px: args.epipolar_tolerance,
                min_depth_m: args.min_depth,
                max_depth_m: args.max_depth.unwrap_or(f64::INFINITY),
            }
        }
        None => StereoGeometry::Rectified {
            row_tolerance_px: args.row_tolerance,
            min_disparity_px: args.min_disparity,
            max_disparity_px: args.max_disparity,
        },
    };
    let refine = (!args.no_refine).then_some(RefineConfig {
        half_window: args.ncc_half,
        search_radius: args.ncc_radius,
        min_ncc: args.min_ncc,
        rows_only: args.rig.is_none(),
        back_check_px: args.back_check,
    });
    let cfg = MatchConfig {
        stereo,
        ratio: args.ratio,
        max_distance: args.max_distance,
        refine,
        // Dense real images: a wide disparity band holds many candidates.
        max_candidates: 256,
        ..MatchConfig::rectified(width, height, n.max(1), args.max_disparity)
    };
    cfg.validate().map_err(|e| anyhow::anyhow!("{e}"))?;
    Ok(cfg)
}

fn check_format(cam: &Interior, width: u32, height: u32) -> anyhow::Result<()> {
    if cam.width_px != width || cam.height_px != height {
        bail!(
            "rig camera is {}x{}, image is {width}x{height}",
            cam.width_px,
            cam.height_px
        );
    }
    Ok(())
}

/// Keeps the `n` strongest features (by response, then scale) in their original order.
fn strongest(f: ImageFeatures, n: usize) -> ImageFeatures {
    if f.keypoints.len() <= n {
        return f;
    }
    let mut idx: Vec<usize> = (0..f.keypoints.len()).collect();
    idx.sort_by(|&a, &b| {
        let (ka, kb) = (&f.keypoints[a], &f.keypoints[b]);
        kb.response
            .total_cmp(&ka.response)
            .then(kb.sigma.total_cmp(&ka.sigma))
    });
    idx.truncate(n);
    idx.sort_unstable();
    ImageFeatures {
        keypoints: idx.iter().map(|&i| f.keypoints[i]).collect(),
        descriptors: idx.iter().map(|&i| f.descriptors[i]).collect(),
    }
}

/// Matches one pair; returns the matches and the statistics.
pub fn match_images<'i>(
    cfg: MatchConfig,
    left: &ImageFeatures,
    right: &ImageFeatures,
    images: Option<(&'i GrayImage, &'i GrayImage)>,
) -> anyhow::Result<(Vec<StereoMatch>, StereoStats)> {
    let mut storage = vec![0u8; cfg.predicted_bytes()];
    let mut arena = Arena::new(&mut storage);
    let mut matcher = Matcher::new(cfg, &mut arena).map_err(|e| anyhow::anyhow!("{e}"))?;
    let views = match images {
        Some((l, r)) => {
            let view = |g: &'i GrayImage| g.view().map_err(|e| anyhow::anyhow!("{e}"));
            Some((view(l)?, view(r)?))
        }
        None => None,
    };
    let pair = StereoFeatures {
        left: Features::new(&left.keypoints, &left.descriptors),
        right: Features::new(&right.keypoints, &right.descriptors),
    };
    let stats = matcher.match_stereo(pair, views);
    Ok((matcher.stereo_matches(&left.keypoints).collect(), stats))
}

/// Tie point lines in COLMAP's convention (pixel centre + 0.5).
pub fn format_matches(matches: &[StereoMatch]) -> String {
    let mut s = String::with_capacity(matches.len() * 40);
    for m in matches {
        let _ = writeln!(
            s,
            "{:.3} {:.3} {:.3} {:.3}",
            m.left_px[0] + 0.5,
            m.left_px[1] + 0.5,
            m.right_px[0] + 0.5,
            m.right_px[1] + 0.5
        );
    }
    s
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let left_img = load_gray(&args.left)?;
    let right_img = load_gray(&args.right)?;
    if (left_img.width, left_img.height) != (right_img.width, right_img.height) {
        bail!(
            "left image is {}x{}, right image {}x{}",
            left_img.width,
            left_img.height,
            right_img.width,
            right_img.height
        );
    }
    let k = args.max_keypoints;
    let left = strongest(
        features_of(args.left_features.as_deref(), &left_img, &args)?,
        k,
    );
    let right = strongest(
        features_of(args.right_features.as_deref(), &right_img, &args)?,
        k,
    );
    let n = left.keypoints.len().max(right.keypoints.len());
    let cfg = config_from_args(&args, left_img.width, left_img.height, n)?;
    let (matches, stats) = match_images(cfg, &left, &right, Some((&left_img, &right_img)))?;
    std::fs::write(&args.out, format_matches(&matches))
        .with_context(|| format!("writing {}", args.out.display()))?;
    let p = stats.pass;
    eprintln!(
        "match: {} tie points from {} + {} keypoints; removed: {} without candidate, {} too far, \
         {} ambiguous, {} not mutual, {} by NCC ({} refined, {} at the border); {} comparisons",
        matches.len(),
        left.keypoints.len(),
        right.keypoints.len(),
        p.no_candidate,
        p.too_far,
        p.ambiguous,
        p.not_mutual,
        stats.refine_rejected,
        stats.refined,
        stats.refine_border,
        p.comparisons
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn colmap_features_round_trip_the_pixel_convention() {
        let mut text = String::from("2 128\n");
        for (x, y) in [(10.5, 20.5), (0.25, 479.75)] {
            text += &format!("{x} {y} 1.6 0.5");
            for i in 0..128 {
                text += &format!(" {}", i * 2);
            }
            text += "\n";
        }
        let f = parse_colmap_features(&text).unwrap();
        assert_eq!(f.keypoints.len(), 2);
        assert_eq!((f.keypoints[0].x, f.keypoints[0].y), (10.0, 20.0));
        assert_eq!((f.keypoints[1].x, f.keypoints[1].y), (-0.25, 479.25));
        assert_eq!(f.descriptors[0][127], 254);
        let line = format_matches(&[StereoMatch {
            left: 0,
            right: 0,
            left_px: [10.0, 20.0],
            right_px: [3.25, 20.0],
            right_sigma: [0.05; 2],
            distance: 0,
        }]);
        assert_eq!(line, "10.500 20.500 3.750 20.500\n");
    }

    #[test]
    fn colmap_features_reject_malformed_files() {
        for bad in [
            "",
            "x 128\n",
            "1 64\n",
            "2 128\n1 2 3 4",
            "1 128\n1 2 3 4 5\n",
            "0 128\n1 2 3 4\n",
        ] {
            assert!(parse_colmap_features(bad).is_err(), "{bad:?}");
        }
        let mut nan = String::from("1 128\nNaN 1 1 0");
        nan += &" 0".repeat(128);
        assert!(parse_colmap_features(&nan).is_err());
    }

    proptest! {
        #[test]
        fn colmap_parser_never_panics(s in "\\PC{0,400}") {
            let _ = parse_colmap_features(&s);
        }

        #[test]
        fn colmap_parser_reads_what_it_is_given(
            pts in prop::collection::vec((0.0f32..1000.0, 0.0f32..1000.0, 0.5f32..30.0, any::<u8>()), 0..20)
        ) {
            let mut text = format!("{} 128\n", pts.len());
            for (x, y, s, v) in &pts {
                text += &format!("{x} {y} {s} 0");
                text += &format!(" {v}").repeat(128);
                text += "\n";
            }
            let f = parse_colmap_features(&text).unwrap();
            prop_assert_eq!(f.keypoints.len(), pts.len());
            for ((k, d), (x, y, _, v)) in f.keypoints.iter().zip(&f.descriptors).zip(&pts) {
                prop_assert!((k.x - (x - 0.5)).abs() < 1e-3 && (k.y - (y - 0.5)).abs() < 1e-3);
                prop_assert!(d.iter().all(|b| b == v));
            }
        }
    }
}
