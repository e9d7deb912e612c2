//! The canonical frame: where a surface sits before anything scale-dependent
//! (Matérn noise, the network, flow matching) sees it.
//!
//! A mesh in the canonical frame has its **axis-aligned bounding box centred
//! at the origin** and its **largest bounding-box extent equal to 1**, the
//! frame of the official Matérn-FM meshes (the Stanford bunny spans
//! `[-0.5, 0.5]` in `x` there). The map into the frame is a similarity
//! without rotation, `p -> scale * p + shift`, a pure function of the
//! bounding box.
//!
//! Why it matters: the Matérn operator `L + tau M` mixes a term in
//! 1 / length² with one in length⁰, so `tau` has units of 1 / length² and the
//! noise is smooth over distances below about `1 / sqrt(tau)` **in mesh
//! units**. The paper's `tau = 100` means "a tenth of the shape's size" only
//! in this frame: on a shape four units across it is speckle, on one a
//! quarter of a unit across it is nearly constant. Putting every training
//! surface in the canonical frame makes `tau` a property of the shape, not of
//! its units. (`matern-normalized` noise adapts `tau` to the mesh instead
//! and needs no frame.)
//!
//! # Example
//! ```
//! use mfm_geometry::frame::CanonicalFrame;
//! use mfm_geometry::procedural;
//! let mesh = procedural::icosphere(2).transformed(7.0, [3.0, -1.0, 2.0]);
//! let frame = CanonicalFrame::of(&mesh).unwrap();
//! let canonical = frame.apply(&mesh);
//! let (lo, hi) = canonical.bounding_box();
//! assert!((hi[0] - lo[0] - 1.0).abs() < 1e-12); // the sphere is 1 across
//! assert!((hi[1] + lo[1]).abs() < 1e-12); // centred
//! let p = mesh.positions()[5];
//! let back = frame.from_canonical(frame.to_canonical(p));
//! assert!((back[2] - p[2]).abs() < 1e-12);
//! ```

use serde::{Deserialize, Serialize};

use crate::mesh::{MeshError, TriMesh};

/// The similarity `p -> scale * p + shift` that takes a surface to the
/// canonical frame (see the [module docs](self)).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct CanonicalFrame {
    /// Scale factor (applied first): `1 / largest bounding-box extent`.
    pub scale: f64,
    /// Shift added after scaling: `-scale * bounding-box centre`.
    pub shift: [f64; 3],
}

impl Default for CanonicalFrame {
    fn default() -> Self {
        Self::identity()
    }
}

impl CanonicalFrame {
    /// The identity map (a surface already in the frame, or a run that
    /// predates frames).
    pub fn identity() -> Self {
        Self {
            scale: 1.0,
            shift: [0.0; 3],
        }
    }

    /// The frame of `mesh`: its bounding-box centre goes to the origin and
    /// its largest extent to 1. `O(V)`.
    ///
    /// # Errors
    /// [`MeshError::ZeroSize`] when the mesh is a single point (every
    /// extent zero).
    pub fn of(mesh: &TriMesh) -> Result<Self, MeshError> {
        Self::of_points(mesh.positions())
    }

    /// The frame of a point set (a shape's positions before it is a mesh):
    /// as [`CanonicalFrame::of`]. `O(n)`.
    ///
    /// # Errors
    /// [`MeshError::ZeroSize`] when every extent is zero (or there are no
    /// points).
    pub fn of_points(points: &[[f64; 3]]) -> Result<Self, MeshError> {
        let (lo, hi) = crate::mesh::bounding_box(points);
        let extent = (0..3).map(|k| hi[k] - lo[k]).fold(0.0f64, f64::max);
        if !(extent.is_finite() && extent > 0.0) {
            return Err(MeshError::ZeroSize { extent });
        }
        let scale = 1.0 / extent;
        let shift = [0, 1, 2].map(|k| -scale * 0.5 * (lo[k] + hi[k]));
        Ok(Self { scale, shift })
    }

    /// Whether this is the identity map.
    pub fn is_identity(&self) -> bool {
        self.scale == 1.0 && self.shift == [0.0; 3]
    }

    /// A point in the frame: `scale * p + shift`.
    pub fn to_canonical(&self, p: [f64; 3]) -> [f64; 3] {
        [0, 1, 2].map(|k| self.scale * p[k] + self.shift[k])
    }

    /// A point of the frame back in the original units: `(q - shift) / scale`.
    pub fn from_canonical(&self, q: [f64; 3]) -> [f64; 3] {
        [0, 1, 2].map(|k| (q[k] - self.shift[k]) / self.scale)
    }

    /// `mesh` moved into the frame (same connectivity).
    pub fn apply(&self, mesh: &TriMesh) -> TriMesh {
        if self.is_identity() {
            mesh.clone()
        } else {
            mesh.transformed(self.scale, self.shift)
        }
    }
}

/// Size and shape class of a surface in its own units: what a sampling mesh
/// is compared with to tell whether it is the training surface (in the same
/// units).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct SurfaceSize {
    /// Largest bounding-box extent.
    pub extent: f64,
    /// Total area.
    pub area: f64,
    /// Euler characteristic `V - E + F` (2 for a sphere, 0 for a torus);
    /// `None` in sizes recorded before it was (they compare size only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub euler: Option<i64>,
    /// Connected components of the faces; `None` as for `euler`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub components: Option<usize>,
}

impl SurfaceSize {
    /// The size of `mesh`. `O(V + F log F)` (the topology's edges).
    pub fn of(mesh: &TriMesh) -> Self {
        let (lo, hi) = mesh.bounding_box();
        let topology = crate::Topology::new(mesh.num_vertices(), mesh.faces());
        Self {
            extent: (0..3).map(|k| hi[k] - lo[k]).fold(0.0f64, f64::max),
            area: mesh.total_area(),
            euler: Some(topology.euler_characteristic()),
            components: Some(topology.face_components().1),
        }
    }

    /// The same surface scaled to a largest extent of 1 (its canonical
    /// frame's size): for comparing shapes whatever their units.
    pub fn normalized(&self) -> Self {
        let e = self.extent.max(f64::MIN_POSITIVE);
        Self {
            extent: 1.0,
            area: self.area / (e * e),
            ..*self
        }
    }

    /// Why `other` does not look like this surface in the same units: one
    /// line per measure (extent, area) whose relative difference exceeds
    /// `tolerance` (e.g. `0.05` for 5%), naming both values, and one for
    /// another Euler characteristic (genus, holes) or another number of
    /// connected components when both sizes know them; empty when all
    /// agree.
    pub fn mismatches(&self, other: &SurfaceSize, tolerance: f64) -> Vec<String> {
        self.mismatches_with(other, tolerance, "the training surface")
    }

    /// [`SurfaceSize::mismatches`] calling this surface `name` ("the
    /// template") in the lines.
    pub fn mismatches_with(&self, other: &SurfaceSize, tolerance: f64, name: &str) -> Vec<String> {
        let mut out = self.size_mismatches(other, tolerance, name);
        if let (Some(mine), Some(theirs)) = (self.euler, other.euler)
            && mine != theirs
        {
            out.push(format!(
                "Euler characteristic {theirs} differs from {name}'s {mine} \
                 (another genus or number of holes)"
            ));
        }
        if let (Some(mine), Some(theirs)) = (self.components, other.components)
            && mine != theirs
        {
            out.push(format!(
                "{theirs} connected components where {name} has {mine}"
            ));
        }
        out
    }

    fn size_mismatches(&self, other: &SurfaceSize, tolerance: f64, name: &str) -> Vec<String> {
        let mut out = Vec::new();
        for (what, mine, theirs) in [
            ("largest bounding-box extent", self.extent, other.extent),
            ("area", self.area, other.area),
        ] {
            let rel = (theirs - mine).abs() / mine.abs().max(f64::MIN_POSITIVE);
            if rel.is_nan() || rel > tolerance {
                out.push(format!(
                    "{what} {} differs from {name}'s {} by {:.0}%",
                    short(theirs),
                    short(mine),
                    100.0 * rel
                ));
            }
        }
        out
    }
}

/// A number with four significant digits.
fn short(x: f64) -> String {
    format!("{x:.4}")
        .trim_end_matches('0')
        .trim_end_matches('.')
        .to_owned()
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use crate::procedural;
    use proptest::prelude::*;

    proptest! {
        #[test]
        fn any_similarity_of_a_mesh_lands_in_one_frame(
            s in 0.01f64..100.0,
            dx in -50.0f64..50.0, dy in -50.0f64..50.0, dz in -50.0f64..50.0,
        ) {
            let base = procedural::blob(2).unwrap();
            let moved = base.transformed(s, [dx, dy, dz]);
            let (a, b) = (CanonicalFrame::of(&base).unwrap(), CanonicalFrame::of(&moved).unwrap());
            let (ca, cb) = (a.apply(&base), b.apply(&moved));
            for (p, q) in ca.positions().iter().zip(cb.positions()) {
                for k in 0..3 {
                    prop_assert!((p[k] - q[k]).abs() < 1e-9);
                }
            }
            let (lo, hi) = cb.bounding_box();
            let extents: Vec<f64> = (0..3).map(|k| hi[k] - lo[k]).collect();
            prop_assert!((extents.iter().cloned().fold(0.0, f64::max) - 1.0).abs() < 1e-12);
            for k in 0..3 {
                prop_assert!((lo[k] + hi[k]).abs() < 1e-9);
            }
            // round trip
            for p in moved.positions().iter().take(20) {
                let back = b.from_canonical(b.to_canonical(*p));
                for k in 0..3 {
                    prop_assert!((back[k] - p[k]).abs() < 1e-9 * (1.0 + p[k].abs()));
                }
            }
        }
    }

    #[test]
    fn a_point_has_no_frame_and_sizes_compare_by_relative_difference() {
        let m = TriMesh::new(vec![[1.0; 3]; 3], vec![[0, 1, 2]]).unwrap();
        assert!(CanonicalFrame::of(&m).is_err());
        let sphere = procedural::icosphere(2);
        let size = SurfaceSize::of(&sphere);
        assert!(size.mismatches(&size, 0.05).is_empty());
        let bigger = SurfaceSize::of(&sphere.transformed(1.1, [0.0; 3]));
        let w = size.mismatches(&bigger, 0.05);
        assert_eq!(w.len(), 2, "{w:?}");
        assert!(w[0].contains("extent") && w[0].contains("10%"), "{w:?}");
        assert!(w[1].contains("area") && w[1].contains("21%"), "{w:?}");
        assert!(size.mismatches(&bigger, 0.25).is_empty());
        // a torus of the sphere's size and area is still another surface
        let torus = procedural::torus(1.0, 0.3, 48, 24).unwrap();
        let t = SurfaceSize::of(&torus);
        let same_size = SurfaceSize {
            extent: size.extent,
            area: size.area,
            ..t
        };
        let w = size.mismatches(&same_size, 0.05);
        assert_eq!(w.len(), 1, "{w:?}");
        assert!(
            w[0].contains("Euler characteristic 0") && w[0].contains("'s 2"),
            "{w:?}"
        );
        // sizes recorded without the topology compare size only
        let old = SurfaceSize {
            euler: None,
            components: None,
            ..size
        };
        assert!(old.mismatches(&same_size, 0.05).is_empty());
        let two = SurfaceSize {
            components: Some(2),
            ..size
        };
        assert!(size.mismatches(&two, 0.05)[0].contains("2 connected components"));
        assert_eq!(size.normalized().extent, 1.0);
    }
}
