//! Intersection, resection and incremental bundle adjustment (issue 5).
