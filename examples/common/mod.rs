//! Helpers shared by the examples (not an example itself).

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};

/// Sorted `*.<ext>` files of `dir`.
pub fn list(dir: &Path, ext: &str) -> Result<Vec<PathBuf>> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
        .with_context(|| format!("cannot list {}", dir.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| {
            p.extension()
                .and_then(|e| e.to_str())
                .is_some_and(|e| e.eq_ignore_ascii_case(ext))
        })
        .collect();
    files.sort();
    Ok(files)
}
