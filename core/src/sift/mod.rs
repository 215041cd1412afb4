//! Reduced SIFT over integer buffers (issue 3).
