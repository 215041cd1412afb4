//! Errors of dataset reading: each names the file and the problem.
use std::path::PathBuf;

#[derive(Debug, thiserror::Error)]
pub enum DatasetError {
    #[error("{dir}: not a dataset: expected calib.txt with image_0/ and image_1/ or image_2/ and image_3/ (KITTI), or left/, right/ and rig.toml")]
    UnknownLayout { dir: PathBuf },
    #[error("{path}: cannot read: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{path}: unreadable image: {problem}")]
    Image { path: PathBuf, problem: String },
    #[error("{path}: line {line}: bad calibration line: {problem}")]
    Calib {
        path: PathBuf,
        line: usize,
        problem: String,
    },
    #[error("{path}: missing calibration row {row}")]
    MissingCalibRow { path: PathBuf, row: &'static str },
    #[error("{path}: {problem}")]
    RigFile { path: PathBuf, problem: String },
    #[error("{path}: {camera} camera: {problem}")]
    BadCamera {
        path: PathBuf,
        camera: &'static str,
        problem: String,
    },
    #[error("{dir}: no images")]
    NoImages { dir: PathBuf },
    #[error("{path}: missing right image for epoch `{epoch}` (looked in {right_dir})")]
    MissingRight {
        path: PathBuf,
        epoch: String,
        right_dir: PathBuf,
    },
    #[error("{path}: right image without a left image for epoch `{epoch}`")]
    MissingLeft { path: PathBuf, epoch: String },
    #[error("{path}: two images for epoch `{epoch}` (the other is {other})")]
    DuplicateEpoch {
        path: PathBuf,
        epoch: String,
        other: PathBuf,
    },
    #[error("{path}: size {got_w}x{got_h} differs from {expected_w}x{expected_h} ({reference})")]
    SizeMismatch {
        path: PathBuf,
        got_w: u32,
        got_h: u32,
        expected_w: u32,
        expected_h: u32,
        reference: String,
    },
    #[error("{path}: line {line}: {problem}")]
    Times {
        path: PathBuf,
        line: usize,
        problem: String,
    },
    /// A line of `gnss.txt` or `odometer.txt`.
    #[error("{path}: line {line}: {problem}")]
    AidingLine {
        path: PathBuf,
        line: usize,
        problem: String,
    },
    #[error("{path}: {found} lines for {expected} epochs")]
    CountMismatch {
        path: PathBuf,
        found: usize,
        expected: usize,
    },
    #[error(transparent)]
    Poses(#[from] crate::poses::PoseError),
}
