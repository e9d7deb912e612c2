#![doc = include_str!("../README.md")]

mod camera;
mod colorbar;
mod colormap;
mod colormap_tables;
mod grid;
pub mod plots;
mod raster;
mod text;

use std::path::{Path, PathBuf};

use image::{ImageEncoder, Rgb, RgbImage};
use thiserror::Error;

pub use camera::{Camera, Projection, UpAxis, View};
pub use colorbar::render_colorbar;
pub use colormap::{ColorRange, Colormap};
pub use grid::{GridLayout, GridOptions, Panel, grid_layout, render_grid, save_grid};
pub use text::{GLYPH, draw_text, format_ticks, text_height, text_width};

use mfm_geometry::mesh::TriMesh;

/// Largest accepted image side, in pixels.
pub const MAX_IMAGE_SIDE: u32 = 16384;

/// Largest number of supersamples (`width·height·s²`) one render may use
/// (each costs 8 bytes of visibility buffer).
pub const MAX_SAMPLES: u64 = 1 << 27;

/// Why a picture could not be made or written.
#[derive(Debug, Error)]
pub enum RenderError {
    /// The scalar field does not have one value per vertex.
    #[error("expected one scalar per vertex ({expected} values), found {found}")]
    ScalarCount {
        /// Number of mesh vertices.
        expected: usize,
        /// Number of scalars given.
        found: usize,
    },
    /// A [`ColorRange::Fixed`] (or colorbar range) that is not finite with
    /// `lo <= hi` (`lo < hi` for a colorbar).
    #[error("invalid color range: expected finite lo <= hi, found {lo}..{hi}")]
    InvalidRange {
        /// Lower end given.
        lo: f64,
        /// Upper end given.
        hi: f64,
    },
    /// A render option is out of its valid range.
    #[error("invalid render option `{name}`: expected {expected}, found {found}")]
    InvalidOption {
        /// Field name in [`RenderOptions`] (or the function argument).
        name: &'static str,
        /// The accepted values, in words.
        expected: &'static str,
        /// The value given.
        found: String,
    },
    /// A grid needs panels and columns.
    #[error(
        "a grid needs at least one panel and one column, found {panels} panels and {columns} columns"
    )]
    EmptyGrid {
        /// Number of panels given.
        panels: usize,
        /// Number of columns asked for.
        columns: usize,
    },
    /// One panel of a grid could not be rendered.
    #[error("grid panel {index} ({caption:?}): {source}")]
    Panel {
        /// Panel number (0-based, row-major).
        index: usize,
        /// Its caption.
        caption: String,
        /// What went wrong.
        #[source]
        source: Box<RenderError>,
    },
    /// Writing the file failed.
    #[error("could not write PNG {}: {source}", path.display())]
    Io {
        /// The destination path.
        path: PathBuf,
        /// The I/O error.
        #[source]
        source: std::io::Error,
    },
    /// The path names something that must not be replaced (a folder, a
    /// device, a FIFO).
    #[error("could not write PNG: {0}")]
    Refused(String),
    /// A plot could not be drawn or written.
    #[error("cannot write plot {}: {message}", path.display())]
    Plot {
        /// The output file.
        path: PathBuf,
        /// What failed.
        message: String,
    },
    /// PNG encoding failed.
    #[error("could not encode PNG {}: {source}", path.display())]
    Encode {
        /// The destination path.
        path: PathBuf,
        /// The encoder's error.
        #[source]
        source: image::ImageError,
    },
}

/// How surface normals are chosen for lighting.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Shading {
    /// Area-weighted vertex normals interpolated across each triangle
    /// (default): smooth surfaces look smooth.
    #[default]
    Smooth,
    /// One normal per triangle: facets (and so the triangulation) show.
    Flat,
}

/// A wireframe overlay: every triangle edge drawn as a line of `width`
/// output pixels (anti-aliased by the supersampling), hidden where the
/// surface hides it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Wireframe {
    /// Line color.
    pub color: Rgb<u8>,
    /// Line width in output pixels.
    pub width: f64,
}

impl Default for Wireframe {
    fn default() -> Self {
        Self {
            color: Rgb([40, 40, 40]),
            width: 1.0,
        }
    }
}

/// Everything that controls one picture. Start from
/// `RenderOptions::default()` and override fields.
#[derive(Clone, Debug, PartialEq)]
pub struct RenderOptions {
    /// Image width in pixels, colorbar included (default 512).
    pub width: u32,
    /// Image height in pixels (default 512).
    pub height: u32,
    /// Viewing direction and framing, used when `camera` is `None`.
    pub view: View,
    /// A camera to use as is (e.g. one [`Camera::fit_all`] fitted to several
    /// meshes); `None` fits one to the mesh from `view`.
    pub camera: Option<Camera>,
    /// Colormap for scalars (default [`Colormap::Viridis`]).
    pub colormap: Colormap,
    /// Which values map to the ends of the colormap (default
    /// [`ColorRange::Auto`]).
    pub range: ColorRange,
    /// Reserve a strip at the right of the image for a vertical colorbar
    /// (only drawn when there are scalars). Default off.
    pub colorbar: bool,
    /// Samples per pixel along each axis, `1..=8` (default 2).
    pub supersample: u32,
    /// Smooth (default) or flat normals.
    pub shading: Shading,
    /// Ambient light, `>= 0` (default 0.25).
    pub ambient: f64,
    /// Diffuse headlight strength, `>= 0` (default 0.75).
    pub diffuse: f64,
    /// Optional edge overlay (default none).
    pub wireframe: Option<Wireframe>,
    /// Surface color without scalars (default light gray-blue).
    pub surface_color: Rgb<u8>,
    /// Color of non-finite scalars (default mid gray).
    pub nan_color: Rgb<u8>,
    /// Background (default white).
    pub background: Rgb<u8>,
    /// Color of labels, captions, frames (default near-black).
    pub text_color: Rgb<u8>,
    /// Integer text scale (8x8 glyphs become `8s x 8s`); `None` picks one
    /// from the image's smaller side: 1 below 200 pixels, 2 below 700, 3
    /// below 1200, else 4.
    pub text_scale: Option<u32>,
}

impl Default for RenderOptions {
    fn default() -> Self {
        Self {
            width: 512,
            height: 512,
            view: View::default(),
            camera: None,
            colormap: Colormap::Viridis,
            range: ColorRange::Auto,
            colorbar: false,
            supersample: 2,
            shading: Shading::Smooth,
            ambient: 0.25,
            diffuse: 0.75,
            wireframe: None,
            surface_color: Rgb([178, 192, 214]),
            nan_color: Rgb([128, 128, 128]),
            background: Rgb([255, 255, 255]),
            text_color: Rgb([25, 25, 25]),
            text_scale: None,
        }
    }
}

impl RenderOptions {
    /// The default options at another size.
    pub fn with_size(width: u32, height: u32) -> Self {
        Self {
            width,
            height,
            ..Self::default()
        }
    }

    /// The text scale used for these options (see [`RenderOptions::text_scale`]).
    pub fn resolved_text_scale(&self) -> u32 {
        match self.text_scale {
            Some(s) => s.clamp(1, 64),
            None => match self.width.min(self.height) {
                0..200 => 1,
                200..700 => 2,
                700..1200 => 3,
                _ => 4,
            },
        }
    }

    /// Checks every field; called by the render functions.
    fn validate(&self) -> Result<(), RenderError> {
        check_side("width", self.width)?;
        check_side("height", self.height)?;
        if !(1..=8).contains(&self.supersample) {
            return Err(invalid("supersample", "1..=8", self.supersample));
        }
        let samples =
            u64::from(self.width) * u64::from(self.height) * u64::from(self.supersample).pow(2);
        if samples > MAX_SAMPLES {
            return Err(invalid(
                "supersample",
                "width * height * supersample^2 <= 2^27",
                format!(
                    "{} ({}x{}x{}^2)",
                    samples, self.width, self.height, self.supersample
                ),
            ));
        }
        for (name, v) in [("ambient", self.ambient), ("diffuse", self.diffuse)] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(invalid(name, "a finite value >= 0", v));
            }
        }
        if let Some(w) = self.wireframe {
            if !(w.width.is_finite() && w.width >= 0.0) {
                return Err(invalid("wireframe.width", "a finite value >= 0", w.width));
            }
        }
        if let ColorRange::Fixed(lo, hi) = self.range {
            if !(lo.is_finite() && hi.is_finite() && lo <= hi) {
                return Err(RenderError::InvalidRange { lo, hi });
            }
        }
        Ok(())
    }
}

fn invalid(name: &'static str, expected: &'static str, found: impl ToString) -> RenderError {
    RenderError::InvalidOption {
        name,
        expected,
        found: found.to_string(),
    }
}

/// Checks an image side against `1..=MAX_IMAGE_SIDE`.
pub(crate) fn check_side(name: &'static str, v: u32) -> Result<(), RenderError> {
    if (1..=MAX_IMAGE_SIDE).contains(&v) {
        Ok(())
    } else {
        Err(invalid(name, "1..=16384 pixels", v))
    }
}

/// Renders `mesh` into a `opts.width x opts.height` image, colored by the
/// per-vertex `scalars` if given (see the [module docs](self) for what the
/// picture shows). With `opts.colorbar` and scalars, the right part of the
/// image holds a colorbar and the mesh is fitted into the rest.
///
/// # Errors
/// [`RenderError::ScalarCount`] if `scalars` does not have one value per
/// vertex, [`RenderError::InvalidOption`] / [`RenderError::InvalidRange`]
/// for invalid options.
pub fn render_mesh(
    mesh: &TriMesh,
    scalars: Option<&[f64]>,
    opts: &RenderOptions,
) -> Result<RgbImage, RenderError> {
    opts.validate()?;
    let range = match scalars {
        Some(s) => {
            check_scalars(mesh, s)?;
            Some(opts.range.resolve(s)?)
        }
        None => None,
    };
    let camera = match &opts.camera {
        Some(c) => c.clone(),
        None => Camera::fit(mesh, &opts.view),
    };
    Ok(render_with(
        mesh,
        scalars,
        range,
        &camera,
        opts.colorbar,
        opts,
    ))
}

fn check_scalars(mesh: &TriMesh, s: &[f64]) -> Result<(), RenderError> {
    if s.len() != mesh.num_vertices() {
        return Err(RenderError::ScalarCount {
            expected: mesh.num_vertices(),
            found: s.len(),
        });
    }
    Ok(())
}

/// Renders with everything resolved (options already validated).
fn render_with(
    mesh: &TriMesh,
    scalars: Option<&[f64]>,
    range: Option<(f64, f64)>,
    camera: &Camera,
    colorbar: bool,
    opts: &RenderOptions,
) -> RgbImage {
    let (w, h) = (opts.width, opts.height);
    let field = match (scalars, range) {
        (Some(values), Some((lo, hi))) => Some(raster::Field {
            values,
            lo,
            hi,
            colormap: opts.colormap,
        }),
        _ => None,
    };
    let scale = opts.resolved_text_scale();
    let strip = match (&field, colorbar) {
        (Some(f), true) => colorbar::colorbar_width(f.lo, f.hi, h, scale).min(w - 1),
        _ => 0,
    };
    let surface = raster::render_surface(mesh, field.as_ref(), camera, w - strip, h, opts);
    if strip == 0 {
        return surface;
    }
    let mut img = RgbImage::from_pixel(w, h, opts.background);
    image::imageops::replace(&mut img, &surface, 0, 0);
    if let Some(f) = &field {
        colorbar::draw_colorbar(
            &mut img,
            i64::from(w - strip),
            0,
            h,
            (f.lo, f.hi),
            f.colormap,
            scale,
            opts.text_color,
        );
    }
    img
}

/// Writes `img` as a PNG at `path`, atomically: the data goes to a
/// temporary file in the same directory which is then renamed over `path`,
/// so readers never see a half-written picture. The directory must exist.
/// A folder, device or FIFO at `path` is refused, a symbolic link followed
/// ([`mfm_files::atomic`]).
///
/// # Errors
/// [`RenderError::Io`], [`RenderError::Refused`] or [`RenderError::Encode`],
/// naming `path`.
pub fn save_png(img: &RgbImage, path: impl AsRef<Path>) -> Result<(), RenderError> {
    let path = path.as_ref();
    let mut bytes = Vec::new();
    image::codecs::png::PngEncoder::new(&mut bytes)
        .write_image(
            img.as_raw(),
            img.width(),
            img.height(),
            image::ExtendedColorType::Rgb8,
        )
        .map_err(|source| RenderError::Encode {
            path: path.to_path_buf(),
            source,
        })?;
    mfm_files::write_atomic(path, |w| w.write_all(&bytes)).map_err(|e| match e {
        mfm_files::FileError::Io { path, source } => RenderError::Io { path, source },
        other => RenderError::Refused(other.to_string()),
    })
}
