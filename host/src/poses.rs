//! KITTI pose text files: one pose per line, the 12 numbers of the 3x4 matrix
//! `[R | t]` row by row (docs/conventions.md, "KITTI output"). Shared by `synth`
//! (ground truth), `run` (estimates) and `eval`.
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// A KITTI pose, row-major 3x4.
pub type KittiPose = [[f64; 4]; 3];

/// The identity pose (the first pose of every KITTI trajectory).
pub const IDENTITY: KittiPose = [
    [1.0, 0.0, 0.0, 0.0],
    [0.0, 1.0, 0.0, 0.0],
    [0.0, 0.0, 1.0, 0.0],
];

/// Why a pose file could not be read or written.
#[derive(Debug, thiserror::Error)]
pub enum PoseError {
    // The I/O error is part of the text and deliberately not a `source`: an `{:#}`
    // chain would print it twice.
    #[error("{path}: cannot read or write: {error}")]
    Io {
        path: PathBuf,
        error: std::io::Error,
    },
    #[error("{path}: line {line}: {problem}")]
    Line {
        path: PathBuf,
        line: usize,
        problem: String,
    },
}

/// Parses KITTI pose text. `path` only names the source in errors. Empty
/// lines and lines starting with `#` are skipped.
pub fn parse_poses(text: &str, path: &Path) -> Result<Vec<KittiPose>, PoseError> {
    let mut poses = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let bad = |problem: String| PoseError::Line {
            path: path.to_path_buf(),
            line: i + 1,
            problem,
        };
        let mut values = [0.0f64; 12];
        let mut n = 0;
        for token in line.split_whitespace() {
            if n == 12 {
                return Err(bad("more than 12 numbers".into()));
            }
            let v: f64 = token
                .parse()
                .map_err(|_| bad(format!("`{token}` is not a number")))?;
            if !v.is_finite() {
                return Err(bad(format!("`{token}` is not finite")));
            }
            values[n] = v;
            n += 1;
        }
        if n != 12 {
            return Err(bad(format!("expected 12 numbers, found {n}")));
        }
        let mut pose = [[0.0; 4]; 3];
        for (k, v) in values.iter().enumerate() {
            pose[k / 4][k % 4] = *v;
        }
        poses.push(pose);
    }
    Ok(poses)
}

/// Reads a KITTI pose file.
pub fn read_poses(path: &Path) -> Result<Vec<KittiPose>, PoseError> {
    let text = std::fs::read_to_string(path).map_err(|error| PoseError::Io {
        path: path.to_path_buf(),
        error,
    })?;
    parse_poses(&text, path)
}

/// One pose as a KITTI text line (no newline), full `f64` round-trip precision.
pub fn format_pose(pose: &KittiPose) -> String {
    let mut s = String::with_capacity(12 * 24);
    for (k, v) in pose.iter().flatten().enumerate() {
        if k > 0 {
            s.push(' ');
        }
        // `{:e}` prints the shortest representation that parses back exactly.
        let _ = write!(s, "{v:e}");
    }
    s
}

/// Writes a KITTI pose file, one line per pose.
pub fn write_poses(path: &Path, poses: &[KittiPose]) -> Result<(), PoseError> {
    let mut text = String::with_capacity(poses.len() * 300);
    for p in poses {
        text.push_str(&format_pose(p));
        text.push('\n');
    }
    std::fs::write(path, text).map_err(|error| PoseError::Io {
        path: path.to_path_buf(),
        error,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_is_exact() {
        let p: KittiPose = [
            [0.1, -0.2, 1.0 / 3.0, 12.5],
            [1e-17, 0.99, -0.0, -3.25e3],
            [f64::MIN_POSITIVE, 7.0, 8.0, 9.0],
        ];
        let text = format!(
            "{}\n\n# comment\n{}\n",
            format_pose(&IDENTITY),
            format_pose(&p)
        );
        let back = parse_poses(&text, Path::new("x")).unwrap();
        assert_eq!(back, vec![IDENTITY, p]);
    }

    #[test]
    fn errors_name_the_line() {
        let err = parse_poses("1 0 0 0 0 1 0 0 0 0 1 0\n1 2 3\n", Path::new("gt.txt")).unwrap_err();
        let msg = err.to_string();
        assert!(
            msg.contains("gt.txt") && msg.contains("line 2") && msg.contains("found 3"),
            "{msg}"
        );
        let err = parse_poses("1 0 0 0 0 1 0 x 0 0 1 0\n", Path::new("gt.txt")).unwrap_err();
        assert!(err.to_string().contains("`x` is not a number"));
        let err = parse_poses("1 0 0 0 0 1 0 0 0 0 1 0 5\n", Path::new("gt.txt")).unwrap_err();
        assert!(err.to_string().contains("more than 12"));
        let err = parse_poses("1 0 0 0 0 1 0 0 0 0 1 NaN\n", Path::new("gt.txt")).unwrap_err();
        assert!(err.to_string().contains("not finite"));
    }
}
