//! `phototraverse features IMAGE --out FILE`: reduced SIFT of one image in COLMAP's
//! text format (docs/conventions.md, "Outputs"), timed without file input and output.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{bail, Context};
use phototraverse_core::budget::{Arena, ComponentKind, MemoryBudget};
use phototraverse_core::features::FeatureSet;
use phototraverse_core::image::ImageView;
use phototraverse_core::sift::{Gradient, Sift, SiftConfig, SiftStats};

#[derive(clap::Args, Debug)]
pub struct Args {
    /// Input image (png, jpg, pgm, ...); converted to 8-bit gray.
    pub image: PathBuf,
    /// Output feature file (COLMAP text format).
    #[arg(long)]
    pub out: PathBuf,
    /// Keypoints kept at most.
    #[arg(long, default_value_t = 1000)]
    pub max_keypoints: usize,
    /// Octaves at most.
    #[arg(long, default_value_t = 6)]
    pub octaves: usize,
    /// Detection levels per octave.
    #[arg(long, default_value_t = 3)]
    pub levels: usize,
    /// Contrast threshold (grey levels / 255, divided by the levels).
    #[arg(long, default_value_t = 0.04)]
    pub contrast: f32,
    /// Edge threshold (ratio of principal curvatures).
    #[arg(long, default_value_t = 10.0)]
    pub edge: f32,
    /// Blur of the first level of each octave (octave pixels).
    #[arg(long, default_value_t = 1.6)]
    pub sigma0: f32,
    /// Blur assumed in the input image (pixels).
    #[arg(long, default_value_t = 0.5)]
    pub input_sigma: f32,
    /// Spreading grid as COLSxROWS.
    #[arg(long, default_value = "8x6")]
    pub grid: String,
    /// Upright keypoints (orientation 0).
    #[arg(long)]
    pub upright: bool,
    /// Add the fine octave (input resolution at half blur): about 3x more keypoints at
    /// small scales, like OpenCV's doubled first octave, at about 2-3x the time.
    #[arg(long)]
    pub fine_octave: bool,
    /// Gradient operator of orientations and descriptors in the regular octaves:
    /// central, scharr or farid.
    #[arg(long, default_value = "central")]
    pub gradient: String,
    /// Gradient operator in the fine octave.
    #[arg(long, default_value = "central")]
    pub fine_gradient: String,
    /// Orientation votes split between the two nearest histogram bins.
    #[arg(long)]
    pub soft_orientation: bool,
    /// Descriptor samples along each axis of the grid over bins -1..4 (multiple of 4, 4-20).
    #[arg(long, default_value_t = 20)]
    pub descriptor_grid: usize,
    /// Orientation windows sampled every other pixel from this octave-relative scale up.
    #[arg(long, default_value_t = 3.0)]
    pub orientation_stride_sigma: f32,
    /// Orientation window radius in keypoint sigmas (1-4.5).
    #[arg(long, default_value_t = 4.5)]
    pub orientation_radius: f32,
    /// Extract this many times and report the median time.
    #[arg(long, default_value_t = 1)]
    pub repeat: usize,
    /// Print a JSON line with counts, timing and memory instead of text.
    #[arg(long)]
    pub json: bool,
}

/// Result of one timed extraction.
pub struct Extraction {
    pub stats: SiftStats,
    pub millis: f64,
    /// Fastest of the repeats (least disturbed by other load).
    pub millis_min: f64,
    pub working_bytes: usize,
    pub predicted_working: usize,
    pub width: usize,
    pub height: usize,
}

/// Loads an image as 8-bit gray: (pixels, width, height).
pub fn load_gray(path: &Path) -> anyhow::Result<(Vec<u8>, usize, usize)> {
    let img = image::open(path).with_context(|| format!("reading {}", path.display()))?;
    let gray = img.to_luma8();
    let (w, h) = (gray.width() as usize, gray.height() as usize);
    Ok((gray.into_raw(), w, h))
}

/// Parses a gradient operator name.
pub fn parse_gradient(s: &str) -> anyhow::Result<Gradient> {
    Ok(match s {
        "central" => Gradient::Central,
        "scharr" => Gradient::Scharr,
        "farid" => Gradient::Farid,
        other => bail!("gradient must be central, scharr or farid, not {other}"),
    })
}

/// Parses `COLSxROWS`.
pub fn parse_grid(s: &str) -> anyhow::Result<(usize, usize)> {
    let (a, b) = s.split_once(['x', 'X']).context("grid must be COLSxROWS")?;
    Ok((a.trim().parse()?, b.trim().parse()?))
}

impl Args {
    /// The extractor configuration for an image of `w` x `h`.
    pub fn config(&self, w: usize, h: usize) -> anyhow::Result<SiftConfig> {
        let (grid_cols, grid_rows) = parse_grid(&self.grid)?;
        Ok(SiftConfig {
            max_width: w,
            max_height: h,
            octaves: self.octaves,
            levels: self.levels,
            contrast_threshold: self.contrast,
            edge_threshold: self.edge,
            sigma0: self.sigma0,
            input_sigma: self.input_sigma,
            max_keypoints: self.max_keypoints,
            grid_cols,
            grid_rows,
            upright: self.upright,
            fine_octave: self.fine_octave,
            gradient: parse_gradient(&self.gradient)?,
            fine_gradient: parse_gradient(&self.fine_gradient)?,
            soft_orientation: self.soft_orientation,
            descriptor_grid: self.descriptor_grid,
            orientation_stride_sigma: self.orientation_stride_sigma,
            orientation_radius: self.orientation_radius,
            ..SiftConfig::default()
        })
    }
}

/// Runs the extractor `repeat` times on one image and writes the features with `write`.
pub fn extract_with(
    cfg: SiftConfig,
    pixels: &[u8],
    w: usize,
    h: usize,
    repeat: usize,
    write: impl FnOnce(&FeatureSet) -> anyhow::Result<()>,
) -> anyhow::Result<Extraction> {
    let mut budget = MemoryBudget::new();
    cfg.budget(&mut budget)
        .map_err(|e| anyhow::anyhow!("{e}"))?;
    let predicted_working = budget.total_of(ComponentKind::Working);
    let mut storage = vec![0u8; budget.total()];
    let mut arena = Arena::new(&mut storage);
    let mut sift = Sift::new(cfg, &mut arena).map_err(|e| anyhow::anyhow!("{e}"))?;
    let working_bytes = arena.used();
    let mut set =
        FeatureSet::new(&mut arena, cfg.max_keypoints).map_err(|e| anyhow::anyhow!("{e}"))?;
    let view = ImageView::new(pixels, w, h).map_err(|e| anyhow::anyhow!("{e}"))?;
    let mut times = Vec::new();
    let mut stats = SiftStats::default();
    for _ in 0..repeat.max(1) {
        let t0 = Instant::now();
        stats = sift
            .extract(&view, &mut set)
            .map_err(|e| anyhow::anyhow!("{e}"))?;
        times.push(t0.elapsed().as_secs_f64() * 1e3);
    }
    times.sort_by(|a, b| a.total_cmp(b));
    write(&set)?;
    Ok(Extraction {
        stats,
        millis: times[times.len() / 2],
        millis_min: times[0],
        working_bytes,
        predicted_working,
        width: w,
        height: h,
    })
}

/// Writes COLMAP's text feature format: `N 128`, then `X Y SCALE ORIENTATION d1..d128`,
/// X, Y with the top-left image corner at (0, 0).
pub fn write_colmap(set: &FeatureSet, out: &mut impl Write) -> std::io::Result<()> {
    writeln!(out, "{} 128", set.len())?;
    for (k, d) in set.keypoints().iter().zip(set.descriptors()) {
        write!(
            out,
            "{:.4} {:.4} {:.4} {:.6}",
            k.x + 0.5,
            k.y + 0.5,
            k.sigma,
            k.orientation
        )?;
        for v in d.iter() {
            write!(out, " {v}")?;
        }
        writeln!(out)?;
    }
    Ok(())
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let (pixels, w, h) = load_gray(&args.image)?;
    if w == 0 || h == 0 {
        bail!("{} is empty", args.image.display());
    }
    let cfg = args.config(w, h)?;
    let out_path = args.out.clone();
    let ex = extract_with(cfg, &pixels, w, h, args.repeat, |set| {
        let file = std::fs::File::create(&out_path)
            .with_context(|| format!("creating {}", out_path.display()))?;
        let mut buf = std::io::BufWriter::new(file);
        write_colmap(set, &mut buf)?;
        buf.flush()?;
        Ok(())
    })?;
    let px = (w * h) as f64;
    if args.json {
        let s = ex.stats;
        println!(
            "{}",
            serde_json::json!({
                "image": args.image.display().to_string(),
                "width": w, "height": h,
                "features": s.kept, "extrema": s.extrema, "refined": s.refined,
                "unstable": s.unstable, "low_contrast": s.low_contrast, "edge": s.edge,
                "oriented": s.oriented, "dropped": s.dropped, "pending_dropped": s.pending_dropped,
                "octaves": s.octaves,
                "millis": ex.millis,
                "millis_min": ex.millis_min,
                "working_bytes": ex.working_bytes,
                "predicted_working_bytes": ex.predicted_working,
                "working_bytes_per_pixel": ex.working_bytes as f64 / px,
            })
        );
    } else {
        let s = ex.stats;
        println!(
            "{} features ({} extrema, {} refined, {} oriented, {} dropped) in {:.2} ms; working memory {} B = {:.2} B/px",
            s.kept,
            s.extrema,
            s.refined,
            s.oriented,
            s.dropped,
            ex.millis,
            ex.working_bytes,
            ex.working_bytes as f64 / px
        );
    }
    Ok(())
}
