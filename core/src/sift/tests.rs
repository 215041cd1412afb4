//! Extractor tests: synthetic images with known structure, memory, determinism, bad input.
