//! Viewing: where the camera looks from, and how a mesh is fitted to the image.
//!
//! A [`View`] is the user's wish (azimuth, elevation, up axis, projection,
//! how much of the image the mesh should fill); a [`Camera`] is that wish
//! fitted to concrete geometry by [`Camera::fit`] or [`Camera::fit_all`].
//!
//! ## Conventions
//! - With [`UpAxis::Y`] (the default, most scanned meshes such as the bunny are
//!   y-up) the camera orbits the `y` axis: azimuth 0 and elevation 0 look from
//!   `+z` towards `-z` with `+x` to the right; positive azimuth turns the
//!   camera counter-clockwise seen from above (towards `+x`), positive
//!   elevation raises it (towards `+y`).
//! - [`UpAxis::Z`] is the same rig rotated so that `+z` is up: azimuth 0 looks
//!   from `-y` towards `+y` (the "front" view of z-up modelling tools).
//! - Elevation is clamped to `[-90, 90]` degrees; at `±90` the camera looks
//!   straight down/up and the image's right direction is still set by the
//!   azimuth, so top views are well defined.
//! - The camera is fitted so that the projected vertices (not just the
//!   bounding box) span `fill` of the image along the tighter direction,
//!   centred. The fit is resolution-independent: the same camera maps into
//!   images of any size.

use mfm_geometry::mesh::{TriMesh, add, cross, dot, norm, scale, sub};

/// Which world axis points up in the image.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum UpAxis {
    /// `+y` is up (default; scanned meshes such as the bunny).
    #[default]
    Y,
    /// `+z` is up (CAD and many procedural meshes).
    Z,
}

/// How 3D points are projected onto the image plane.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub enum Projection {
    /// Parallel projection (default): sizes do not depend on depth.
    #[default]
    Orthographic,
    /// Pinhole camera whose field of view just contains the mesh's bounding
    /// sphere at `fov_deg` degrees (clamped to `[1, 120]`); smaller angles
    /// mean a more distant camera and weaker perspective.
    Perspective {
        /// Full field-of-view angle in degrees.
        fov_deg: f64,
    },
}

/// Viewing parameters, before fitting to a mesh.
///
/// The default is a three-quarter view (azimuth 30°, elevation 20°), `+y` up,
/// orthographic, the mesh filling 85% of the image.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct View {
    /// Rotation of the camera about the up axis, in degrees.
    pub azimuth_deg: f64,
    /// Height of the camera above the horizontal plane, in degrees
    /// (clamped to `[-90, 90]`).
    pub elevation_deg: f64,
    /// World axis shown pointing up.
    pub up: UpAxis,
    /// Orthographic or perspective.
    pub projection: Projection,
    /// Fraction of the image (along its tighter direction) that the mesh
    /// spans, clamped to `[0.05, 1]`.
    pub fill: f64,
}

impl Default for View {
    fn default() -> Self {
        Self {
            azimuth_deg: 30.0,
            elevation_deg: 20.0,
            up: UpAxis::Y,
            projection: Projection::Orthographic,
            fill: 0.85,
        }
    }
}

impl View {
    /// The view straight along `-forward`: azimuth 0, elevation 0, keeping
    /// the other settings of `self` (for y-up: looking from `+z`).
    pub fn front(self) -> Self {
        Self {
            azimuth_deg: 0.0,
            elevation_deg: 0.0,
            ..self
        }
    }
}

/// A camera fitted to some geometry: an orthonormal frame, a projection and
/// the image-plane window that maps onto the picture.
///
/// Build it with [`Camera::fit`] (one mesh) or [`Camera::fit_all`] (several
/// meshes sharing one camera, e.g. the frames of a deformation). Pass it in
/// [`RenderOptions::camera`](super::RenderOptions::camera) to reuse it.
#[derive(Clone, Debug, PartialEq)]
pub struct Camera {
    view: View,
    /// Point the camera looks at (bounding-box centre of the fitted geometry).
    target: [f64; 3],
    /// Image right, image up and viewing direction (into the screen).
    right: [f64; 3],
    up: [f64; 3],
    forward: [f64; 3],
    /// Distance from the eye to `target` (perspective only; 0 otherwise).
    distance: f64,
    /// Centre and size of the fitted window in image-plane units.
    window_center: [f64; 2],
    window_size: [f64; 2],
}

/// Maps a direction given in the y-up rig to the world for `up`.
fn to_world(up: UpAxis, v: [f64; 3]) -> [f64; 3] {
    match up {
        UpAxis::Y => v,
        // rotation by +90 degrees about x: y -> z, z -> -y
        UpAxis::Z => [v[0], -v[2], v[1]],
    }
}

impl Camera {
    /// Fits a camera for `view` to one mesh. Cost: `O(V)`.
    ///
    /// A mesh whose vertices all coincide (or are otherwise tiny compared to
    /// their distance from the origin) gets a window of unit size, so it
    /// renders as a dot instead of dividing by zero.
    pub fn fit(mesh: &TriMesh, view: &View) -> Self {
        Self::fit_points(&[mesh.positions()], view)
    }

    /// Fits one camera for `view` to several meshes together, so that all of
    /// them fit in the image when rendered with it (same scale, same
    /// framing). An empty list gives a camera for the unit cube. Cost:
    /// `O(sum V)`.
    pub fn fit_all(meshes: &[&TriMesh], view: &View) -> Self {
        let sets: Vec<&[[f64; 3]]> = meshes.iter().map(|m| m.positions()).collect();
        Self::fit_points(&sets, view)
    }

    /// Fits a camera for `view` to point sets (e.g. mesh vertices). Cost:
    /// `O(total points)`. Non-finite points are ignored.
    pub fn fit_points(sets: &[&[[f64; 3]]], view: &View) -> Self {
        let mut view = *view;
        view.elevation_deg = clamp_or(view.elevation_deg, -90.0, 90.0, 0.0);
        view.azimuth_deg = clamp_or(view.azimuth_deg, -1e6, 1e6, 0.0);
        view.fill = clamp_or(view.fill, 0.05, 1.0, 0.85);
        if let Projection::Perspective { fov_deg } = view.projection {
            view.projection = Projection::Perspective {
                fov_deg: clamp_or(fov_deg, 1.0, 120.0, 30.0),
            };
        }

        let points = || {
            sets.iter()
                .flat_map(|s| s.iter())
                .filter(|p| p.iter().all(|c| c.is_finite()))
        };
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        for p in points() {
            for k in 0..3 {
                lo[k] = lo[k].min(p[k]);
                hi[k] = hi[k].max(p[k]);
            }
        }
        if lo[0] > hi[0] {
            // no points: frame the unit cube
            lo = [-0.5; 3];
            hi = [0.5; 3];
        }
        let target = scale(add(lo, hi), 0.5);
        let magnitude = lo
            .iter()
            .chain(hi.iter())
            .fold(0.0f64, |m, c| m.max(c.abs()));
        // below this the geometry is a single point as far as f64 can tell
        let tiny = 1e-12 * (1.0 + magnitude);
        let mut radius = 0.5 * norm(sub(hi, lo));
        if radius <= tiny {
            radius = 1.0;
        }

        let (az, el) = (
            view.azimuth_deg.to_radians(),
            view.elevation_deg.to_radians(),
        );
        // eye direction (from the target towards the eye) and image right, in
        // the y-up rig; right is the derivative of the eye direction in
        // azimuth, which stays defined at the poles
        let eye_dir = [az.sin() * el.cos(), el.sin(), az.cos() * el.cos()];
        let right_rig = [az.cos(), 0.0, -az.sin()];
        let forward = to_world(view.up, scale(eye_dir, -1.0));
        let right = to_world(view.up, right_rig);
        let up = cross(right, forward);
        let up = scale(up, 1.0 / norm(up));

        let distance = match view.projection {
            Projection::Orthographic => 0.0,
            Projection::Perspective { fov_deg } => radius / (0.5 * fov_deg.to_radians()).sin(),
        };
        let mut camera = Self {
            view,
            target,
            right,
            up,
            forward,
            distance,
            window_center: [0.0, 0.0],
            window_size: [1.0, 1.0],
        };

        let mut plo = [f64::INFINITY; 2];
        let mut phi = [f64::NEG_INFINITY; 2];
        for p in points() {
            if let Some([u, v, _]) = camera.to_plane(*p) {
                plo = [plo[0].min(u), plo[1].min(v)];
                phi = [phi[0].max(u), phi[1].max(v)];
            }
        }
        if plo[0] <= phi[0] {
            let size = [phi[0] - plo[0], phi[1] - plo[1]];
            let largest = size[0].max(size[1]);
            let tiny_plane = match view.projection {
                Projection::Orthographic => tiny,
                Projection::Perspective { .. } => tiny / camera.distance,
            };
            camera.window_center = [0.5 * (plo[0] + phi[0]), 0.5 * (plo[1] + phi[1])];
            camera.window_size = if largest <= tiny_plane {
                [1.0, 1.0]
            } else {
                // a segment seen side-on has one zero extent: keep it finite
                [size[0].max(1e-9 * largest), size[1].max(1e-9 * largest)]
            };
        }
        camera
    }

    /// The (clamped) view this camera was fitted for.
    pub fn view(&self) -> &View {
        &self.view
    }

    /// Unit viewing direction, from the eye into the scene (for perspective,
    /// the direction of the optical axis).
    pub fn forward(&self) -> [f64; 3] {
        self.forward
    }

    /// Unit world direction shown pointing right in the image.
    pub fn right(&self) -> [f64; 3] {
        self.right
    }

    /// Unit world direction shown pointing up in the image.
    pub fn up(&self) -> [f64; 3] {
        self.up
    }

    /// Image-plane coordinates `(u, v)` and depth of a point, or `None` for a
    /// perspective camera when the point is not in front of the eye.
    /// Orthographic depth is signed distance along `forward` from the
    /// target; perspective depth is distance along `forward` from the eye.
    pub(crate) fn to_plane(&self, p: [f64; 3]) -> Option<[f64; 3]> {
        let q = sub(p, self.target);
        let (u, v, d) = (dot(q, self.right), dot(q, self.up), dot(q, self.forward));
        if self.distance > 0.0 {
            let depth = d + self.distance;
            if depth <= 1e-6 * self.distance {
                return None;
            }
            Some([u / depth, v / depth, depth])
        } else {
            Some([u, v, d])
        }
    }

    /// Centre of the fitted window in image-plane units.
    pub(crate) fn window_center(&self) -> [f64; 2] {
        self.window_center
    }

    /// Whether depths come from a perspective projection.
    pub(crate) fn is_perspective(&self) -> bool {
        self.distance > 0.0
    }

    /// Pixels per image-plane unit and the pixel position of the window
    /// centre, for a `width x height` image.
    pub(crate) fn pixel_mapping(&self, width: f64, height: f64) -> (f64, [f64; 2]) {
        let k = self.view.fill * (width / self.window_size[0]).min(height / self.window_size[1]);
        (k, [0.5 * width, 0.5 * height])
    }

    /// Projects a world point into a `width x height` image: `[x, y, depth]`
    /// with `x` to the right and `y` down in pixel units (pixel `(i, j)`
    /// covers `[i, i+1) x [j, j+1)`), depth as in the camera's projection
    /// (larger is farther). `None` when the point is behind a perspective
    /// camera. Cost: `O(1)`.
    pub fn project(&self, p: [f64; 3], width: u32, height: u32) -> Option<[f64; 3]> {
        let (k, c) = self.pixel_mapping(f64::from(width), f64::from(height));
        let [u, v, d] = self.to_plane(p)?;
        Some([
            c[0] + (u - self.window_center[0]) * k,
            c[1] - (v - self.window_center[1]) * k,
            d,
        ])
    }
}

/// `x` clamped to `[lo, hi]`, or `fallback` when `x` is not finite.
fn clamp_or(x: f64, lo: f64, hi: f64, fallback: f64) -> f64 {
    if x.is_finite() {
        x.clamp(lo, hi)
    } else {
        fallback
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cube_points() -> Vec<[f64; 3]> {
        let mut p = Vec::new();
        for x in [-1.0, 1.0] {
            for y in [-1.0, 1.0] {
                for z in [-1.0, 1.0] {
                    p.push([x, y, z]);
                }
            }
        }
        p
    }

    #[test]
    fn front_view_y_up_looks_down_minus_z() {
        let pts = cube_points();
        let cam = Camera::fit_points(&[&pts], &View::default().front());
        let close = |a: [f64; 3], b: [f64; 3]| norm(sub(a, b)) < 1e-12;
        assert!(close(cam.forward(), [0.0, 0.0, -1.0]));
        assert!(close(cam.right(), [1.0, 0.0, 0.0]));
        assert!(close(cam.up(), [0.0, 1.0, 0.0]));
        // +x lands right of centre, +y above it (smaller pixel y)
        let c = cam.project([0.0; 3], 100, 100).expect("in view");
        let px = cam.project([1.0, 0.0, 0.0], 100, 100).expect("in view");
        let py = cam.project([0.0, 1.0, 0.0], 100, 100).expect("in view");
        assert!((c[0] - 50.0).abs() < 1e-9 && (c[1] - 50.0).abs() < 1e-9);
        assert!((px[0] - (50.0 + 42.5)).abs() < 1e-9);
        assert!((py[1] - (50.0 - 42.5)).abs() < 1e-9);
    }

    #[test]
    fn z_up_front_view_looks_along_plus_y() {
        let pts = cube_points();
        let view = View {
            up: UpAxis::Z,
            ..View::default().front()
        };
        let cam = Camera::fit_points(&[&pts], &view);
        assert!(norm(sub(cam.forward(), [0.0, 1.0, 0.0])) < 1e-12);
        assert!(norm(sub(cam.up(), [0.0, 0.0, 1.0])) < 1e-12);
        assert!(norm(sub(cam.right(), [1.0, 0.0, 0.0])) < 1e-12);
    }

    #[test]
    fn top_view_is_well_defined() {
        let pts = cube_points();
        let view = View {
            azimuth_deg: 0.0,
            elevation_deg: 90.0,
            ..View::default()
        };
        let cam = Camera::fit_points(&[&pts], &view);
        assert!(norm(sub(cam.forward(), [0.0, -1.0, 0.0])) < 1e-12);
        assert!(cam.up().iter().all(|c| c.is_finite()));
        assert!((norm(cam.up()) - 1.0).abs() < 1e-12);
        assert!(dot(cam.up(), cam.forward()).abs() < 1e-12);
    }

    #[test]
    fn perspective_points_are_in_front_and_fill_the_window() {
        let pts = cube_points();
        let view = View {
            projection: Projection::Perspective { fov_deg: 40.0 },
            ..View::default()
        };
        let cam = Camera::fit_points(&[&pts], &view);
        let proj: Vec<[f64; 3]> = pts
            .iter()
            .map(|p| cam.project(*p, 200, 100).expect("in front"))
            .collect();
        let (xmin, xmax) = proj
            .iter()
            .fold((f64::MAX, f64::MIN), |(a, b), p| (a.min(p[0]), b.max(p[0])));
        let (ymin, ymax) = proj
            .iter()
            .fold((f64::MAX, f64::MIN), |(a, b), p| (a.min(p[1]), b.max(p[1])));
        // the tighter direction (height 100) is filled to 85%, centred
        assert!(((ymax - ymin) - 85.0).abs() < 1e-6, "{ymin} {ymax}");
        assert!(((xmin + xmax) / 2.0 - 100.0).abs() < 1e-6);
        assert!(xmax - xmin < 200.0);
        assert!(proj.iter().all(|p| p[2] > 0.0));
    }

    #[test]
    fn coincident_points_give_a_finite_camera() {
        let pts = vec![[3.0, 3.0, 3.0]; 4];
        for projection in [
            Projection::Orthographic,
            Projection::Perspective { fov_deg: 30.0 },
        ] {
            let view = View {
                projection,
                ..View::default()
            };
            let cam = Camera::fit_points(&[&pts], &view);
            let p = cam.project(pts[0], 64, 64).expect("in view");
            assert!((p[0] - 32.0).abs() < 1e-9 && (p[1] - 32.0).abs() < 1e-9);
        }
        let cam = Camera::fit_points(&[], &View::default());
        assert!(cam.project([0.0; 3], 10, 10).is_some());
    }
}
