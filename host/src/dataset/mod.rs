//! Stereo datasets on disk: the KITTI odometry layout and the photogrammetric
//! `rig.toml` layout of docs/conventions.md, "Dataset layouts".
//!
//! [`Dataset::open`] detects the layout, reads the calibration, pairs the left
//! and right images epoch by epoch and checks every image header, so a
//! malformed dataset fails at once with an error naming the file and the
//! problem rather than in the middle of a run.
pub mod aiding;
pub mod calibration;
mod error;
mod image;
pub mod kitti;
pub mod rigfile;

pub use error::DatasetError;
pub use image::{image_size, load_gray, to_gray8, GrayImage};
pub use rigfile::{default_datum, read_rig, read_rig_file, rig_toml_text, write_rig, RigFile};

use crate::poses::{read_poses, KittiPose};
use phototraverse_core::camera::{Pose, Rig};
use phototraverse_core::traverse::CalibrationPrecision;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// File name of the optional ground truth of a dataset (KITTI pose format).
pub const GT_FILE: &str = "gt_poses.txt";
/// File name of the optional epoch times (one number per line, seconds).
pub const TIMES_FILE: &str = "times.txt";

/// Image file extensions a dataset may use.
const IMAGE_EXTENSIONS: &[&str] = &[
    "png", "jpg", "jpeg", "pgm", "ppm", "pnm", "bmp", "tif", "tiff",
];

/// How to open a dataset; `Default` takes what the layout finds.
#[derive(Debug, Clone, Default)]
pub struct OpenOptions {
    /// KITTI: the cameras (left, right), `(0, 1)` the grey pair or `(2, 3)` the colour
    /// one; by default the grey pair when `image_0/` and `image_1/` are there, else the
    /// colour pair.
    pub kitti_cameras: Option<(usize, usize)>,
    /// Ground-truth poses (KITTI format) instead of the dataset's `gt_poses.txt` or, in
    /// a KITTI tree, `poses/NN.txt` beside `sequences/NN`.
    pub ground_truth: Option<PathBuf>,
}

/// Which layout a dataset uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Layout {
    /// `image_0/`, `image_1/`, `calib.txt`.
    Kitti,
    /// `left/`, `right/`, `rig.toml` (or seed-style `E001`/`D001` files).
    Rig,
}

/// One synchronized stereo pair.
#[derive(Debug, Clone, PartialEq)]
pub struct Epoch {
    /// The name shared by the pair (e.g. `000012`, or `012` for `E012`/`D012`).
    pub name: String,
    pub left: PathBuf,
    pub right: PathBuf,
    /// Time from `times.txt`, seconds.
    pub time: Option<f64>,
}

/// An opened dataset.
#[derive(Debug, Clone)]
pub struct Dataset {
    pub dir: PathBuf,
    pub layout: Layout,
    /// The calibrated rig (photo units: mm for rig.toml, pixels for KITTI).
    pub rig: Rig,
    /// The datum: the left camera at epoch 0 (rig.toml `[datum]`, default omega 90 deg).
    pub datum: Pose,
    /// The calibration's stated precision (rig.toml `[precision]`; KITTI:
    /// [`kitti::CALIBRATION_PRECISION`]).
    pub precision: CalibrationPrecision,
    /// Epochs in order.
    pub epochs: Vec<Epoch>,
    /// Ground truth of the left camera, one pose per epoch ([`Dataset::open_with`]).
    pub ground_truth: Option<Vec<KittiPose>>,
    /// KITTI: the left camera's centre in camera 0's frame (m; 0 for the grey pair), by
    /// which camera-0 ground truth is moved to the left camera.
    pub kitti_left_centre: [f64; 3],
    /// GNSS fixes (`gnss.txt`, or `gnss_geodetic.txt` converted), in time order; empty
    /// without either file.
    pub gnss: Vec<aiding::GnssFix>,
    /// The `[gnss]` table (rig.toml or gnss.toml): georeference and lever arm.
    pub gnss_setup: aiding::GnssSetup,
    /// Time spans without GNSS (`run --gnss-outage`): no fix, not even interpolated.
    pub gnss_outages: Vec<(f64, f64)>,
    /// Odometer readings (`odometer.txt`), in time order; empty without the file.
    pub odometer: Vec<aiding::OdometerReading>,
}

impl Dataset {
    /// Opens `dir`, detecting its layout.
    pub fn open(dir: &Path) -> Result<Dataset, DatasetError> {
        Self::open_with(dir, &OpenOptions::default())
    }

    /// Opens `dir` with `opts`, detecting its layout.
    pub fn open_with(dir: &Path, opts: &OpenOptions) -> Result<Dataset, DatasetError> {
        let kitti_images = ["image_0", "image_2"].iter().any(|d| dir.join(d).is_dir());
        let mut ds = if dir.join("calib.txt").is_file() && kitti_images {
            Self::open_kitti(dir, opts.kitti_cameras)?
        } else if dir.join("rig.toml").is_file() {
            Self::open_rig(dir)?
        } else {
            return Err(DatasetError::UnknownLayout {
                dir: dir.to_path_buf(),
            });
        };
        ds.ground_truth = ds.read_ground_truth(opts.ground_truth.as_deref())?;
        Ok(ds)
    }

    fn open_kitti(dir: &Path, cameras: Option<(usize, usize)>) -> Result<Dataset, DatasetError> {
        let calib_path = dir.join("calib.txt");
        let text = read_text(&calib_path)?;
        let grey = dir.join("image_0").is_dir() && dir.join("image_1").is_dir();
        let pair = cameras.unwrap_or(if grey { (0, 1) } else { (2, 3) });
        let rows = kitti::parse_calib(&text, &calib_path)?;
        let (p0, p1) = kitti::pair_rows(&rows, pair, &calib_path)?;
        let image_dir = |c: usize| dir.join(format!("image_{c}"));
        let (left_dir, right_dir) = (image_dir(pair.0), image_dir(pair.1));
        let pairs = pair_images(
            &list_images(&left_dir)?,
            &list_images(&right_dir)?,
            &right_dir,
        )?;
        let first = pairs.first().ok_or_else(|| DatasetError::NoImages {
            dir: left_dir.clone(),
        })?;
        let (w, h) = image_size(&first.1)?;
        let reference = format!("size of {}", first.1.display());
        check_sizes(&pairs, (w, h), (w, h), &reference)?;
        let rig = kitti::rig_from_calib(&p0, &p1, w, h, &calib_path)?;
        let file = RigFile {
            rig,
            datum: default_datum(),
            precision: kitti::CALIBRATION_PRECISION,
            gnss: None,
        };
        let mut ds = Self::finish(dir, Layout::Kitti, file, pairs)?;
        ds.kitti_left_centre = kitti::centre_in_camera0(&p0);
        Ok(ds)
    }

    fn open_rig(dir: &Path) -> Result<Dataset, DatasetError> {
        let file = read_rig_file(&dir.join("rig.toml"))?;
        let rig = file.rig;
        let (left_dir, right_dir) = (dir.join("left"), dir.join("right"));
        let pairs = if left_dir.is_dir() || right_dir.is_dir() {
            pair_images(
                &list_images(&left_dir)?,
                &list_images(&right_dir)?,
                &right_dir,
            )?
        } else {
            // Seed-style: E001.jpg (esquerda, left) and D001.jpg (direita, right) side by side.
            let all = list_images(dir)?;
            let pick = |prefix: char| -> Vec<PathBuf> {
                all.iter()
                    .filter(|p| stem(p).starts_with([prefix, prefix.to_ascii_lowercase()]))
                    .cloned()
                    .collect()
            };
            pair_images(&pick('E'), &pick('D'), dir)?
        };
        if pairs.is_empty() {
            return Err(DatasetError::NoImages { dir: left_dir });
        }
        let size = |c: &phototraverse_core::camera::Interior| (c.width_px, c.height_px);
        check_sizes(&pairs, size(&rig.left), size(&rig.right), "rig.toml")?;
        Self::finish(dir, Layout::Rig, file, pairs)
    }

    fn finish(
        dir: &Path,
        layout: Layout,
        file: RigFile,
        pairs: Vec<(String, PathBuf, PathBuf)>,
    ) -> Result<Dataset, DatasetError> {
        let times_path = dir.join(TIMES_FILE);
        let times = if times_path.is_file() {
            Some(read_times(&times_path, pairs.len())?)
        } else {
            None
        };
        let optional = |name: &str| Some(dir.join(name)).filter(|p| p.is_file());
        let gnss_setup = match (file.gnss, optional(aiding::GNSS_SETUP_FILE)) {
            (Some(_), Some(p)) => {
                return Err(DatasetError::RigFile {
                    path: p,
                    problem: "the [gnss] table is in rig.toml too: keep one".into(),
                })
            }
            (Some(g), None) => g,
            (None, Some(p)) => aiding::GnssSetup::read(&p)?,
            (None, None) => aiding::GnssSetup::default(),
        };
        let gnss = match (
            optional(aiding::GNSS_FILE),
            optional(aiding::GNSS_GEODETIC_FILE),
        ) {
            (Some(p), Some(_)) => {
                return Err(DatasetError::AidingLine {
                    path: p,
                    line: 0,
                    problem: format!("{} is there too: keep one", aiding::GNSS_GEODETIC_FILE),
                })
            }
            (Some(p), None) => aiding::read_gnss(&p)?,
            (None, Some(p)) => aiding::read_gnss_geodetic(&p, &gnss_setup)?,
            (None, None) => Vec::new(),
        };
        let odometer = match optional(aiding::ODOMETER_FILE) {
            Some(p) => aiding::read_odometer(&p)?,
            None => Vec::new(),
        };
        let epochs = pairs
            .into_iter()
            .enumerate()
            .map(|(i, (name, left, right))| Epoch {
                name,
                left,
                right,
                time: times.as_ref().map(|t| t[i]),
            })
            .collect();
        Ok(Dataset {
            dir: dir.to_path_buf(),
            layout,
            rig: file.rig,
            datum: file.datum,
            precision: file.precision,
            epochs,
            ground_truth: None,
            kitti_left_centre: [0.0; 3],
            gnss,
            gnss_setup,
            gnss_outages: Vec::new(),
            odometer,
        })
    }

    /// The ground truth: `given`, else `gt_poses.txt`, else in a KITTI tree
    /// `sequences/NN/../../poses/NN.txt`; `None` without any. KITTI's poses are camera
    /// 0's: with the colour pair they are moved to camera 2 (its offset in `calib.txt`).
    fn read_ground_truth(
        &self,
        given: Option<&Path>,
    ) -> Result<Option<Vec<KittiPose>>, DatasetError> {
        let kitti_tree = || {
            let name = self.dir.file_name()?;
            let poses = self.dir.parent()?.parent()?.join("poses");
            Some(poses.join(name).with_extension("txt"))
        };
        let path = match given {
            Some(p) => p.to_path_buf(),
            None => match [Some(self.dir.join(GT_FILE)), kitti_tree()]
                .into_iter()
                .flatten()
                .find(|p| p.is_file())
            {
                Some(p) => p,
                None => return Ok(None),
            },
        };
        let gt = read_poses(&path)?;
        if gt.len() != self.epochs.len() {
            return Err(DatasetError::CountMismatch {
                path,
                found: gt.len(),
                expected: self.epochs.len(),
            });
        }
        Ok(Some(
            gt.iter().map(|p| self.moved_to_left_camera(p)).collect(),
        ))
    }

    /// A camera-0 pose (KITTI) as the left camera's: the rectified cameras share the
    /// rotation, so only the centre moves, by `R c - c` with `c` the left camera's
    /// centre in camera 0's frame (0 for camera 0 itself).
    fn moved_to_left_camera(&self, p: &KittiPose) -> KittiPose {
        let c = self.kitti_left_centre;
        let mut out = *p;
        for (r, row) in out.iter_mut().enumerate() {
            row[3] += (0..3).map(|k| p[r][k] * c[k]).sum::<f64>() - c[r];
        }
        out
    }

    /// The time of epoch `i`, seconds: `times.txt`'s, or `i` without it (one second an
    /// epoch: the motion prediction only needs ratios).
    pub fn time_of(&self, i: usize) -> f64 {
        self.epochs.get(i).and_then(|e| e.time).unwrap_or(i as f64)
    }

    pub fn len(&self) -> usize {
        self.epochs.len()
    }

    pub fn is_empty(&self) -> bool {
        self.epochs.is_empty()
    }

    /// Loads the left and right images of epoch `i` as 8-bit gray.
    pub fn load_pair(&self, i: usize) -> Result<(GrayImage, GrayImage), DatasetError> {
        let Some(e) = self.epochs.get(i) else {
            return Err(DatasetError::NoImages {
                dir: self.dir.clone(),
            });
        };
        Ok((load_gray(&e.left)?, load_gray(&e.right)?))
    }
}

fn read_text(path: &Path) -> Result<String, DatasetError> {
    std::fs::read_to_string(path).map_err(|source| DatasetError::Io {
        path: path.to_path_buf(),
        source,
    })
}

fn stem(p: &Path) -> String {
    p.file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default()
}

/// Image files of a directory, sorted by name.
fn list_images(dir: &Path) -> Result<Vec<PathBuf>, DatasetError> {
    let entries = std::fs::read_dir(dir).map_err(|source| DatasetError::Io {
        path: dir.to_path_buf(),
        source,
    })?;
    let mut files = Vec::new();
    for entry in entries {
        let path = entry
            .map_err(|source| DatasetError::Io {
                path: dir.to_path_buf(),
                source,
            })?
            .path();
        let ext = path
            .extension()
            .map(|e| e.to_string_lossy().to_ascii_lowercase())
            .unwrap_or_default();
        if path.is_file() && IMAGE_EXTENSIONS.contains(&ext.as_str()) {
            files.push(path);
        }
    }
    files.sort();
    Ok(files)
}

/// The epoch key of an image name: its last run of digits (`000012` -> `000012`,
/// `E012` -> `012`, `left_0012` -> `0012`), or the whole stem when it has none.
pub fn epoch_key(path: &Path) -> String {
    let s = stem(path);
    let bytes = s.as_bytes();
    let end = bytes
        .iter()
        .rposition(|b| b.is_ascii_digit())
        .map(|i| i + 1);
    match end {
        Some(end) => {
            let start = bytes[..end]
                .iter()
                .rposition(|b| !b.is_ascii_digit())
                .map_or(0, |i| i + 1);
            s[start..end].to_string()
        }
        None => s,
    }
}

/// Pairs left and right images by epoch key, in left-name order.
fn pair_images(
    left: &[PathBuf],
    right: &[PathBuf],
    right_dir: &Path,
) -> Result<Vec<(String, PathBuf, PathBuf)>, DatasetError> {
    let mut rights: BTreeMap<String, PathBuf> = BTreeMap::new();
    for r in right {
        let key = epoch_key(r);
        if let Some(other) = rights.insert(key.clone(), r.clone()) {
            return Err(DatasetError::DuplicateEpoch {
                path: r.clone(),
                epoch: key,
                other,
            });
        }
    }
    let mut seen: BTreeMap<String, PathBuf> = BTreeMap::new();
    let mut pairs = Vec::with_capacity(left.len());
    for l in left {
        let key = epoch_key(l);
        if let Some(other) = seen.insert(key.clone(), l.clone()) {
            return Err(DatasetError::DuplicateEpoch {
                path: l.clone(),
                epoch: key,
                other,
            });
        }
        let Some(r) = rights.remove(&key) else {
            return Err(DatasetError::MissingRight {
                path: l.clone(),
                epoch: key,
                right_dir: right_dir.to_path_buf(),
            });
        };
        pairs.push((key, l.clone(), r));
    }
    if let Some((key, path)) = rights.into_iter().next() {
        return Err(DatasetError::MissingLeft { path, epoch: key });
    }
    Ok(pairs)
}

/// Every image header must give the expected size.
fn check_sizes(
    pairs: &[(String, PathBuf, PathBuf)],
    left: (u32, u32),
    right: (u32, u32),
    reference: &str,
) -> Result<(), DatasetError> {
    for (_, l, r) in pairs {
        for (path, (ew, eh)) in [(l, left), (r, right)] {
            // An image whose header cannot be read is left to `load_pair`: a corrupt
            // frame costs its epoch (predicted, flagged), not the whole run.
            let Ok((w, h)) = image_size(path) else {
                continue;
            };
            if (w, h) != (ew, eh) {
                return Err(DatasetError::SizeMismatch {
                    path: path.clone(),
                    got_w: w,
                    got_h: h,
                    expected_w: ew,
                    expected_h: eh,
                    reference: reference.to_string(),
                });
            }
        }
    }
    Ok(())
}

/// `times.txt`: one time per line, as many as epochs.
fn read_times(path: &Path, expected: usize) -> Result<Vec<f64>, DatasetError> {
    let text = read_text(path)?;
    let mut times = Vec::with_capacity(expected);
    for (i, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() {
            continue;
        }
        let bad = |problem: String| DatasetError::Times {
            path: path.to_path_buf(),
            line: i + 1,
            problem,
        };
        let v: f64 = line
            .parse()
            .map_err(|_| bad(format!("`{line}` is not a number")))?;
        // The traverse's motion model and velocity constraint divide by the time
        // between epochs: it must be a finite, increasing clock.
        if !v.is_finite() || v < 0.0 {
            return Err(bad(format!("`{line}` is not a time (finite seconds >= 0)")));
        }
        if let Some(&prev) = times.last() {
            if v <= prev {
                return Err(bad(format!(
                    "{v} s is not after the previous epoch's {prev} s (times must increase)"
                )));
            }
        }
        times.push(v);
    }
    if times.len() != expected {
        return Err(DatasetError::CountMismatch {
            path: path.to_path_buf(),
            found: times.len(),
            expected,
        });
    }
    Ok(times)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn times_must_be_finite_and_increasing() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("times.txt");
        let read = |text: &str| {
            std::fs::write(&path, text).unwrap();
            read_times(&path, text.lines().count()).map_err(|e| e.to_string())
        };
        assert_eq!(read("0\n0.1\n0.25\n").unwrap(), vec![0.0, 0.1, 0.25]);
        for (text, line, says) in [
            ("0\nNaN\n", 2, "not a time"),
            ("-0.1\n0\n", 1, "not a time"),
            ("0\ninf\n", 2, "not a time"),
            ("0\n0.1\n0.1\n", 3, "not after the previous"),
            ("0.2\n0.1\n", 2, "not after the previous"),
        ] {
            let e = read(text).unwrap_err();
            assert!(
                e.contains(&format!("line {line}")) && e.contains(says),
                "{text:?}: {e}"
            );
        }
    }

    #[test]
    fn epoch_keys() {
        assert_eq!(epoch_key(Path::new("a/000012.png")), "000012");
        assert_eq!(epoch_key(Path::new("E012.jpg")), "012");
        assert_eq!(epoch_key(Path::new("D012.JPG")), "012");
        assert_eq!(epoch_key(Path::new("left_0012_v2x.png")), "2");
        assert_eq!(epoch_key(Path::new("abc.png")), "abc");
    }
}
