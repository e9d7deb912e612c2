//! Grids of panels: several meshes (or one mesh with several fields) side by
//! side, each with a caption, under an optional title, optionally on one
//! shared color scale with one colorbar.
//!
//! See [`render_grid`] for the layout.

use image::RgbImage;

use super::camera::Camera;
use super::colorbar::{colorbar_width, draw_colorbar};
use super::text::{GLYPH, draw_text, text_height, text_width};
use super::{ColorRange, RenderError, RenderOptions, check_scalars, render_with};
use mfm_geometry::mesh::TriMesh;

/// One cell of a grid: a mesh, optional per-vertex scalars and a caption.
#[derive(Clone, Debug)]
pub struct Panel<'a> {
    /// The mesh to draw.
    pub mesh: &'a TriMesh,
    /// Per-vertex scalars, or `None` for a plain shaded surface.
    pub scalars: Option<&'a [f64]>,
    /// Text under the panel (may be empty; `\n` for several lines).
    pub caption: String,
}

impl<'a> Panel<'a> {
    /// A panel from its parts.
    pub fn new(mesh: &'a TriMesh, scalars: Option<&'a [f64]>, caption: impl Into<String>) -> Self {
        Self {
            mesh,
            scalars,
            caption: caption.into(),
        }
    }
}

/// Options of [`render_grid`].
#[derive(Clone, Debug, PartialEq)]
pub struct GridOptions {
    /// Options of every panel: its size (`width x height`, default 256x256),
    /// view, colormap, range, colorbar, ... The text scale of captions and
    /// of the shared colorbar is `panel.resolved_text_scale()`.
    pub panel: RenderOptions,
    /// Title drawn above the grid (one size larger than captions when it
    /// fits).
    pub title: Option<String>,
    /// Resolve `panel.range` over all panels' scalars together, so equal
    /// values get equal colors everywhere; with `panel.colorbar`, draw one
    /// colorbar right of the grid instead of one per panel. Default on.
    pub shared_range: bool,
    /// Fit one camera to all meshes together ([`Camera::fit_all`]) so they
    /// are drawn at one scale, instead of each filling its panel. Ignored
    /// when `panel.camera` is set. Default off.
    pub shared_camera: bool,
}

impl Default for GridOptions {
    fn default() -> Self {
        Self {
            panel: RenderOptions::with_size(256, 256),
            title: None,
            shared_range: true,
            shared_camera: false,
        }
    }
}

/// Sizes of a grid picture, in pixels.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct GridLayout {
    /// Number of columns.
    pub columns: u32,
    /// Number of rows, `ceil(panels / columns)`.
    pub rows: u32,
    /// Cell width (= panel width).
    pub cell_width: u32,
    /// Cell height: panel height plus `caption_height`.
    pub cell_height: u32,
    /// Height of the caption band under each panel (0 without captions).
    pub caption_height: u32,
    /// Height of the title band (0 without a title).
    pub title_height: u32,
    /// Width of the shared colorbar strip (0 without one).
    pub colorbar_width: u32,
    /// Whole picture: `columns·cell_width + colorbar_width`.
    pub width: u32,
    /// Whole picture: `title_height + rows·cell_height`.
    pub height: u32,
}

/// Padding above and below a line of text at scale `s`.
fn text_pad(s: u32) -> u32 {
    2 * s + 2
}

/// Largest scale `<= preferred` at which `text` fits in `width` (at least
/// 1), and the text, its lines cut to fit with a trailing `..` if even
/// scale 1 is too wide.
fn fit_text(text: &str, preferred: u32, width: u32) -> (u32, String) {
    if let Some(s) = (1..=preferred.max(1))
        .rev()
        .find(|&s| text_width(text, s) <= width)
    {
        return (s, text.to_string());
    }
    let max_chars = (width / GLYPH) as usize;
    let lines: Vec<String> = text
        .split('\n')
        .map(|line| {
            if line.chars().count() <= max_chars {
                line.to_string()
            } else {
                let keep = max_chars.saturating_sub(2);
                let mut cut: String = line.chars().take(keep).collect();
                cut.push_str(&"..".chars().take(max_chars - keep).collect::<String>());
                cut
            }
        })
        .collect();
    (1, lines.join("\n"))
}

/// Everything [`render_grid`] decides before drawing.
struct Plan {
    layout: GridLayout,
    /// Shared `(lo, hi)` when the range is shared and some panel has scalars.
    shared: Option<(f64, f64)>,
    text_scale: u32,
    title_scale: u32,
}

fn plan(panels: &[Panel<'_>], columns: usize, opts: &GridOptions) -> Result<Plan, RenderError> {
    if panels.is_empty() || columns == 0 {
        return Err(RenderError::EmptyGrid {
            panels: panels.len(),
            columns,
        });
    }
    opts.panel.validate()?;
    for (index, p) in panels.iter().enumerate() {
        if let Some(s) = p.scalars {
            check_scalars(p.mesh, s).map_err(|e| panel_error(index, p, e))?;
        }
    }
    let too_large = |what: &str| RenderError::InvalidOption {
        name: "columns",
        expected: "a grid of at most 16384x16384 pixels",
        found: format!("{what} with {columns} columns of {} panels", panels.len()),
    };
    let columns_u32 = u32::try_from(columns).map_err(|_| too_large("too many columns"))?;
    let rows =
        u32::try_from(panels.len().div_ceil(columns)).map_err(|_| too_large("too many rows"))?;

    let s = opts.panel.resolved_text_scale();
    let (pw, ph) = (opts.panel.width, opts.panel.height);
    let caption_lines = panels
        .iter()
        .filter(|p| !p.caption.is_empty())
        .map(|p| p.caption.split('\n').count())
        .max();
    let caption_height = caption_lines.map_or(0, |lines| {
        let probe = vec!["x"; lines].join("\n");
        text_height(&probe, s) + 2 * text_pad(s)
    });

    let fields: Vec<&[f64]> = panels.iter().filter_map(|p| p.scalars).collect();
    let shared = if opts.shared_range && !fields.is_empty() {
        Some(opts.panel.range.resolve_all(&fields)?)
    } else {
        None
    };
    let cell_height = ph.saturating_add(caption_height);
    let grid_height = rows.saturating_mul(cell_height);
    let colorbar = match shared {
        Some((lo, hi)) if opts.panel.colorbar => colorbar_width(lo, hi, grid_height, s),
        _ => 0,
    };
    let width = columns_u32
        .checked_mul(pw)
        .and_then(|w| w.checked_add(colorbar))
        .filter(|&w| w <= super::MAX_IMAGE_SIDE)
        .ok_or_else(|| too_large("too wide"))?;
    let (title_scale, title_height) = match &opts.title {
        Some(t) => {
            let ts = fit_text(t, s + 1, width).0;
            (ts, text_height(t, ts) + 2 * text_pad(ts))
        }
        None => (s, 0),
    };
    let height = grid_height
        .checked_add(title_height)
        .filter(|&h| h <= super::MAX_IMAGE_SIDE)
        .ok_or_else(|| too_large("too tall"))?;
    Ok(Plan {
        layout: GridLayout {
            columns: columns_u32,
            rows,
            cell_width: pw,
            cell_height,
            caption_height,
            title_height,
            colorbar_width: colorbar,
            width,
            height,
        },
        shared,
        text_scale: s,
        title_scale,
    })
}

fn panel_error(index: usize, p: &Panel<'_>, e: RenderError) -> RenderError {
    RenderError::Panel {
        index,
        caption: p.caption.clone(),
        source: Box::new(e),
    }
}

/// The sizes [`render_grid`] would produce, without rendering. Cost:
/// `O(total scalars)` (to resolve a shared range, which sets the colorbar
/// labels' width).
///
/// # Errors
/// As [`render_grid`].
pub fn grid_layout(
    panels: &[Panel<'_>],
    columns: usize,
    opts: &GridOptions,
) -> Result<GridLayout, RenderError> {
    plan(panels, columns, opts).map(|p| p.layout)
}

/// Renders `panels` row-major into a grid of `columns` columns ([`grid_layout`]
/// gives the sizes without rendering). Captions are centred under their
/// panel, drawn at a smaller text scale if too wide, and cut short (ending
/// in `..`) if too wide even at scale 1; the title likewise. Cost: the sum
/// of the panel renders.
///
/// Layout, row-major, `rows = ceil(panels / columns)`:
/// ```text
/// +--------------------------------------------+
/// |                   title                    |  title band (if a title)
/// +-------------+-------------+-----------+----+
/// |   panel 0   |   panel 1   |  panel 2  | cb |  each cell: the panel image
/// |  caption 0  |  caption 1  | caption 2 |    |  over a caption band (if any
/// +-------------+-------------+-----------+    |  caption is non-empty)
/// |   panel 3   |   ...                   |    |
/// ```
/// The shared colorbar strip `cb` (only with a shared range, `colorbar` set
/// in the panel options and at least one panel with scalars) spans the rows.
///
/// # Errors
/// [`RenderError::EmptyGrid`] without panels or columns,
/// [`RenderError::Panel`] naming the panel whose scalars do not match its
/// mesh, [`RenderError::InvalidOption`] / [`RenderError::InvalidRange`] for
/// invalid options or a grid larger than
/// [`MAX_IMAGE_SIDE`](super::MAX_IMAGE_SIDE) on a side.
///
/// # Example
/// ```
/// use mfm_geometry::procedural;
/// use mfm_render::{render_grid, GridOptions, Panel, RenderOptions};
/// let sphere = procedural::icosphere(1);
/// let x: Vec<f64> = sphere.positions().iter().map(|p| p[0]).collect();
/// let y: Vec<f64> = sphere.positions().iter().map(|p| p[1]).collect();
/// let panels = [Panel::new(&sphere, Some(&x), "x"), Panel::new(&sphere, Some(&y), "y")];
/// let opts = GridOptions { panel: RenderOptions::with_size(64, 64), ..GridOptions::default() };
/// let img = render_grid(&panels, 2, &opts).unwrap();
/// assert_eq!(img.width(), 128);
/// ```
pub fn render_grid(
    panels: &[Panel<'_>],
    columns: usize,
    opts: &GridOptions,
) -> Result<RgbImage, RenderError> {
    let plan = plan(panels, columns, opts)?;
    let l = plan.layout;
    let panel_opts = &opts.panel;
    let camera = match (&panel_opts.camera, opts.shared_camera) {
        (Some(c), _) => Some(c.clone()),
        (None, true) => {
            let meshes: Vec<&TriMesh> = panels.iter().map(|p| p.mesh).collect();
            Some(Camera::fit_all(&meshes, &panel_opts.view))
        }
        (None, false) => None,
    };
    let mut img = RgbImage::from_pixel(l.width, l.height, panel_opts.background);
    let s = plan.text_scale;

    if let Some(title) = &opts.title {
        let (_, title) = fit_text(title, plan.title_scale, l.width);
        let title = title.as_str();
        let x = (i64::from(l.width) - i64::from(text_width(title, plan.title_scale))) / 2;
        let y = i64::from(text_pad(plan.title_scale));
        draw_text(
            &mut img,
            x.max(0),
            y,
            title,
            plan.title_scale,
            panel_opts.text_color,
        );
    }

    for (index, p) in panels.iter().enumerate() {
        let range = match (p.scalars, plan.shared) {
            (Some(_), Some(r)) => Some(r),
            (Some(values), None) => Some(
                panel_opts
                    .range
                    .resolve(values)
                    .map_err(|e| panel_error(index, p, e))?,
            ),
            (None, _) => None,
        };
        let own_camera;
        let cam = match &camera {
            Some(c) => c,
            None => {
                own_camera = Camera::fit(p.mesh, &panel_opts.view);
                &own_camera
            }
        };
        let own_colorbar = panel_opts.colorbar && plan.shared.is_none();
        let tile = render_with(p.mesh, p.scalars, range, cam, own_colorbar, panel_opts);
        // index < rows * columns, both of which fit in u32
        let (col, row) = ((index % columns) as u32, (index / columns) as u32);
        let x0 = col * l.cell_width;
        let y0 = l.title_height + row * l.cell_height;
        image::imageops::replace(&mut img, &tile, i64::from(x0), i64::from(y0));
        if !p.caption.is_empty() {
            let (cs, caption) = fit_text(&p.caption, s, l.cell_width);
            let tw = i64::from(text_width(&caption, cs));
            let x = i64::from(x0) + ((i64::from(l.cell_width) - tw) / 2).max(0);
            let y = i64::from(y0 + panel_opts.height + text_pad(s))
                + i64::from(text_height(&caption, s) - text_height(&caption, cs)) / 2;
            draw_text(&mut img, x, y, &caption, cs, panel_opts.text_color);
        }
    }

    if let (Some(range), true) = (plan.shared, l.colorbar_width > 0) {
        draw_colorbar(
            &mut img,
            i64::from(l.columns * l.cell_width),
            i64::from(l.title_height),
            l.rows * l.cell_height,
            range,
            panel_opts.colormap,
            s,
            panel_opts.text_color,
        );
    }
    Ok(img)
}

/// Renders `panels` in a grid of `columns` under `title`, with one colour
/// bar per panel on the colour scale `range`, and writes it as a PNG
/// ([`crate::save_png`]): the one picture the mfm commands draw of a set of
/// signals or shapes.
///
/// # Errors
/// Those of [`render_grid`] and [`crate::save_png`].
pub fn save_grid(
    panels: &[Panel<'_>],
    columns: usize,
    title: &str,
    range: ColorRange,
    path: impl AsRef<std::path::Path>,
) -> Result<(), RenderError> {
    let mut opts = GridOptions {
        title: Some(title.to_owned()),
        ..GridOptions::default()
    };
    opts.panel.range = range;
    opts.panel.colorbar = true;
    let img = render_grid(panels, columns, &opts)?;
    crate::save_png(&img, path)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn text_is_shrunk_then_cut_to_fit() {
        assert_eq!(fit_text("abcd", 3, 100), (3, "abcd".to_string()));
        assert_eq!(fit_text("abcd", 3, 64), (2, "abcd".to_string()));
        assert_eq!(fit_text("abcdefgh", 2, 40), (1, "abc..".to_string()));
        assert_eq!(
            fit_text("ab\nabcdefgh", 1, 40),
            (1, "ab\nabc..".to_string())
        );
        assert_eq!(fit_text("abc", 1, 8), (1, ".".to_string()));
        assert_eq!(fit_text("abc", 1, 0), (1, String::new()));
    }
}
