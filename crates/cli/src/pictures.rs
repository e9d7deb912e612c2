//! Pictures the commands share: a grid of panels on one colour scale.

use anyhow::Result;
use mfm_render::{ColorRange, GridOptions, Panel};
use std::path::Path;

/// Renders `panels` in a grid of `columns` with a title and colour bars
/// and writes it as a PNG.
pub(crate) fn save_grid(
    panels: &[Panel<'_>],
    columns: usize,
    title: &str,
    range: ColorRange,
    path: &Path,
) -> Result<()> {
    let mut opts = GridOptions {
        title: Some(title.to_owned()),
        ..GridOptions::default()
    };
    opts.panel.range = range;
    opts.panel.colorbar = true;
    let img = mfm_render::render_grid(panels, columns, &opts)?;
    mfm_render::save_png(&img, path)?;
    Ok(())
}
