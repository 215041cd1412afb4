//! Stereo and temporal matching, quad tie points and tracks (issue 4).
