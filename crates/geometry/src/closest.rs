//! Closest points on a triangle mesh: where a point lands on a surface, as a
//! face and the barycentric weights of its corners.
//!
//! This is what carries data from a template mesh to another triangulation of
//! the same surface: each vertex of the other mesh is located on the
//! template's surface ([`SurfaceLocator::closest`]), and any per-vertex
//! signal of the template (a scalar, or the positions of a deformed copy with
//! the same faces) is then interpolated linearly at the located points
//! ([`SurfacePoint::interpolate`], [`SurfacePoint::position`]). libigl calls
//! the query `point_mesh_squared_distance`.
//!
//! - [`closest_point_on_triangle`]: one point against one triangle, by the
//!   Voronoi regions of the triangle (3 corners, 3 edges, the interior).
//!   Faces of (almost) zero area, whose interior region is not defined, are
//!   treated as their three edges; weights are always `>= 0` and sum to 1.
//! - [`SurfaceLocator`]: a bounding-volume hierarchy over a mesh's faces
//!   (axis-aligned boxes, median splits), built in `O(F log F)`; each query
//!   costs `O(log F)` for points near the surface, up to `O(F)` for points
//!   equidistant from many faces (the centre of a sphere).
//! - [`closest_points`]: builds a locator and answers a batch of queries.
//!
//! Conventions: the answer is the closest point over *all* faces, exactly as
//! brute force with [`closest_point_on_triangle`] on every face would find
//! it (the hierarchy only skips boxes that cannot hold a face as close, with
//! a margin for round-off); among faces at the same squared distance the
//! lowest face index wins. A batch query ([`SurfaceLocator::closest_all`]) runs
//! in parallel (rayon) and gives the same answer whatever the thread count.
//! A point on the surface (a vertex, an edge midpoint, a point of a face) is
//! located at squared distance zero up to round-off, with weights that
//! reproduce it to round-off.
//!
//! # Example
//! ```
//! use mfm_geometry::closest::SurfaceLocator;
//! use mfm_geometry::{procedural, subdivide};
//!
//! let template = procedural::icosphere(2);
//! let locator = SurfaceLocator::new(&template);
//!
//! // A point above the sphere lands on it, at about distance 1.
//! let point = locator.closest([0.0, 0.0, 2.0]);
//! assert!((point.squared_distance.sqrt() - 1.0).abs() < 0.05);
//! let [x, y, z] = point.position(&template);
//! assert!((z - 1.0).abs() < 0.05 && x.abs() < 0.05 && y.abs() < 0.05);
//!
//! // Another triangulation of the same surface: every vertex of a midpoint
//! // subdivision lies on the template, so a vertex signal of the template
//! // (here the height z) is carried to it exactly.
//! let refined = subdivide::midpoint(&template).unwrap();
//! let heights: Vec<f64> = template.positions().iter().map(|p| p[2]).collect();
//! let located = locator.closest_all(refined.positions());
//! for (point, vertex) in located.iter().zip(refined.positions()) {
//!     assert!(point.squared_distance < 1e-24);
//!     let height = point.interpolate(&template, &heights).unwrap();
//!     assert!((height - vertex[2]).abs() < 1e-12);
//! }
//! ```

use rayon::prelude::*;

use crate::mesh::{MeshError, TriMesh, cross, dot, sub};

/// A point of a mesh's surface, found as the closest point to a query: a face,
/// the barycentric weights of its three corners (each `>= 0`, summing to 1 up
/// to round-off), and the squared distance from the query to the point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SurfacePoint {
    /// The face (index into [`TriMesh::faces`]).
    pub face: usize,
    /// Weights of the face's corners, in the face's vertex order.
    pub weights: [f64; 3],
    /// Squared Euclidean distance from the query to [`Self::position`].
    pub squared_distance: f64,
}

impl SurfacePoint {
    /// The three vertices of the face, in the order of [`Self::weights`].
    ///
    /// # Panics
    /// If [`Self::face`] is not a face of `mesh` (a point located on a mesh
    /// with other faces).
    pub fn vertices(&self, mesh: &TriMesh) -> [u32; 3] {
        mesh.faces()[self.face]
    }

    /// The point's position on `mesh`: the weighted sum of its face's corners.
    ///
    /// `mesh` is the located mesh or any mesh with the same faces, e.g. a
    /// deformed copy of it, whose corresponding point this then is.
    ///
    /// # Panics
    /// If [`Self::face`] is not a face of `mesh`.
    pub fn position(&self, mesh: &TriMesh) -> [f64; 3] {
        weighted_sum(self.weights, &mesh.face_positions(self.face))
    }

    /// Interpolates a per-vertex value linearly at the point: the weighted
    /// sum of the values at the face's corners.
    ///
    /// # Errors
    /// [`MeshError::VertexCountMismatch`] unless there is one value per
    /// vertex of `mesh`.
    ///
    /// # Panics
    /// If [`Self::face`] is not a face of `mesh`.
    pub fn interpolate(&self, mesh: &TriMesh, values: &[f64]) -> Result<f64, MeshError> {
        if values.len() != mesh.num_vertices() {
            return Err(MeshError::VertexCountMismatch {
                expected: mesh.num_vertices(),
                found: values.len(),
            });
        }
        let [a, b, c] = self.vertices(mesh);
        let [wa, wb, wc] = self.weights;
        Ok(wa * values[a as usize] + wb * values[b as usize] + wc * values[c as usize])
    }
}

/// The closest point of one triangle to a query: the barycentric weights of
/// the triangle's corners and the squared distance.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TrianglePoint {
    /// Weights of the corners (each `>= 0`, summing to 1 up to round-off).
    pub weights: [f64; 3],
    /// Squared distance from the query to the weighted sum of the corners.
    pub squared_distance: f64,
}

/// A face is treated as its three edges when its height over its longest
/// edge is at most this (`|n|² <= ratio² · longest⁴`, with `|n|` twice
/// its area): its interior region is then too thin to be classified
/// reliably, and the edges are at most that far from any of its points.
const DEGENERATE_HEIGHT_RATIO: f64 = 1e-12;

/// The closest point of the triangle `corners` to `point`, with barycentric
/// weights of the corners.
///
/// The query is classified into the Voronoi regions of the triangle: near a
/// corner (that corner), beyond an edge (the orthogonal projection onto that
/// edge), or over the interior (the orthogonal projection onto the plane,
/// with weights proportional to the signed areas of the sub-triangles
/// opposite each corner). A triangle whose height is at most `1e-12` of its
/// longest edge (collinear or coincident corners) has no usable interior and
/// is handled as its three edges. The weights are never NaN for finite
/// input, never negative, and sum to 1 up to round-off; the squared distance
/// is measured to the point the weights give, so the two always agree.
///
/// Cost: `O(1)`.
///
/// # Example
/// ```
/// use mfm_geometry::closest::closest_point_on_triangle;
/// let triangle = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
/// // above the interior: the projection onto the plane
/// let inside = closest_point_on_triangle([0.25, 0.25, 2.0], &triangle);
/// assert_eq!(inside.weights, [0.5, 0.25, 0.25]);
/// assert_eq!(inside.squared_distance, 4.0);
/// // beyond the corner at the origin: the corner itself
/// let corner = closest_point_on_triangle([-1.0, -1.0, 0.0], &triangle);
/// assert_eq!(corner.weights, [1.0, 0.0, 0.0]);
/// assert_eq!(corner.squared_distance, 2.0);
/// ```
pub fn closest_point_on_triangle(point: [f64; 3], corners: &[[f64; 3]; 3]) -> TrianglePoint {
    let weights = closest_weights(point, corners);
    TrianglePoint {
        weights,
        squared_distance: squared_length(sub(point, weighted_sum(weights, corners))),
    }
}

/// Barycentric weights of the closest point (see
/// [`closest_point_on_triangle`]).
fn closest_weights(point: [f64; 3], corners: &[[f64; 3]; 3]) -> [f64; 3] {
    let [a, b, c] = *corners;
    let ab = sub(b, a);
    let ac = sub(c, a);
    let bc = sub(c, b);
    let normal = cross(ab, ac);
    let longest_squared = squared_length(ab)
        .max(squared_length(ac))
        .max(squared_length(bc));
    let threshold = DEGENERATE_HEIGHT_RATIO * longest_squared;
    if squared_length(normal) <= threshold * threshold {
        return closest_weights_on_edges(point, corners);
    }

    let ap = sub(point, a);
    let bp = sub(point, b);
    let cp = sub(point, c);

    // Corner regions: the query is behind both edges leaving the corner.
    let ab_ap = dot(ab, ap);
    let ac_ap = dot(ac, ap);
    if ab_ap <= 0.0 && ac_ap <= 0.0 {
        return [1.0, 0.0, 0.0];
    }
    let ab_bp = dot(ab, bp);
    let bc_bp = dot(bc, bp);
    if ab_bp >= 0.0 && bc_bp <= 0.0 {
        return [0.0, 1.0, 0.0];
    }
    let ac_cp = dot(ac, cp);
    let bc_cp = dot(bc, cp);
    if ac_cp >= 0.0 && bc_cp >= 0.0 {
        return [0.0, 0.0, 1.0];
    }

    // Twice the signed areas (times |n|) of the sub-triangles opposite each
    // corner; their sum is |n|² and each is the numerator of that corner's
    // barycentric coordinate of the projection onto the plane.
    let area_opposite_a = dot(normal, cross(bp, cp));
    let area_opposite_b = dot(normal, cross(cp, ap));
    let area_opposite_c = dot(normal, cross(ap, bp));

    // Edge regions: the query is outside the edge and between the two
    // planes through its ends orthogonal to it.
    if area_opposite_c <= 0.0 && ab_ap >= 0.0 && ab_bp <= 0.0 {
        let t = fraction(ab_ap, ab_ap - ab_bp);
        return [1.0 - t, t, 0.0];
    }
    if area_opposite_a <= 0.0 && bc_bp >= 0.0 && bc_cp <= 0.0 {
        let t = fraction(bc_bp, bc_bp - bc_cp);
        return [0.0, 1.0 - t, t];
    }
    // along the edge from c to a: `ca = -ac`
    let ca_cp = -ac_cp;
    let ca_ap = -ac_ap;
    if area_opposite_b <= 0.0 && ca_cp >= 0.0 && ca_ap <= 0.0 {
        let t = fraction(ca_cp, ca_cp - ca_ap);
        return [t, 0.0, 1.0 - t];
    }

    // Interior region. In exact arithmetic every area is positive here; if
    // round-off says otherwise, the query sits on a region boundary and the
    // closest point of the edges is the answer up to round-off.
    if area_opposite_a > 0.0 && area_opposite_b > 0.0 && area_opposite_c > 0.0 {
        let total = area_opposite_a + area_opposite_b + area_opposite_c;
        return [
            area_opposite_a / total,
            area_opposite_b / total,
            area_opposite_c / total,
        ];
    }
    closest_weights_on_edges(point, corners)
}

/// Weights of the closest point of the triangle's three edges (segments
/// `ab`, `bc`, `ca`; the first wins a tie). Valid for any triangle,
/// including one with coincident corners.
fn closest_weights_on_edges(point: [f64; 3], corners: &[[f64; 3]; 3]) -> [f64; 3] {
    let mut best_weights = [1.0, 0.0, 0.0];
    let mut best_distance = f64::INFINITY;
    for (start, end) in [(0, 1), (1, 2), (2, 0)] {
        let along = sub(corners[end], corners[start]);
        let t = fraction(
            dot(along, sub(point, corners[start])),
            squared_length(along),
        );
        let mut weights = [0.0; 3];
        weights[start] = 1.0 - t;
        weights[end] = t;
        let distance = squared_length(sub(point, weighted_sum(weights, corners)));
        if distance < best_distance {
            best_distance = distance;
            best_weights = weights;
        }
    }
    best_weights
}

/// `numerator / denominator` clamped to `[0, 1]`; 0 when the denominator is
/// not positive (a zero-length edge) or the ratio is NaN.
#[inline]
fn fraction(numerator: f64, denominator: f64) -> f64 {
    if denominator > 0.0 {
        let ratio = numerator / denominator;
        if ratio >= 1.0 {
            1.0
        } else if ratio > 0.0 {
            ratio
        } else {
            0.0
        }
    } else {
        0.0
    }
}

/// `w0·p0 + w1·p1 + w2·p2`: the one formula for a point from weights, shared
/// by the distance computation and [`SurfacePoint::position`].
#[inline]
fn weighted_sum(weights: [f64; 3], corners: &[[f64; 3]; 3]) -> [f64; 3] {
    let [wa, wb, wc] = weights;
    let [a, b, c] = corners;
    [
        wa * a[0] + wb * b[0] + wc * c[0],
        wa * a[1] + wb * b[1] + wc * c[1],
        wa * a[2] + wb * b[2] + wc * c[2],
    ]
}

#[inline]
fn squared_length(v: [f64; 3]) -> f64 {
    dot(v, v)
}

/// Most faces in a leaf of the hierarchy.
const LEAF_SIZE: usize = 4;

/// Relative margin (of the largest coordinate magnitude involved) by which a
/// box must be farther than the best face found so far to be skipped. It
/// covers the round-off of a face's computed distance (its closest point can
/// land a few ulps outside its box), so skipping never changes the answer.
const PRUNING_MARGIN: f64 = 64.0 * f64::EPSILON;

/// A node of the hierarchy: a box and either a range of faces (a leaf,
/// `count > 0`) or two children (`count == 0`: the first child is the next
/// node, the second is node `first`).
#[derive(Clone, Copy, Debug)]
struct Node {
    lower: [f64; 3],
    upper: [f64; 3],
    first: usize,
    count: usize,
}

/// A bounding-volume hierarchy over a mesh's faces that finds the closest
/// point of the surface to any query point.
///
/// It holds a copy of the face corners in the order of the leaves (80 bytes
/// per face with its index) and the tree (about `F / 2` nodes of 64 bytes),
/// and no reference to the mesh: the located [`SurfacePoint`]s are read on
/// the mesh, or on any mesh with the same faces.
///
/// # Example
/// ```
/// use mfm_geometry::closest::SurfaceLocator;
/// let grid = mfm_geometry::procedural::plane_grid(4, 4, 2.0, 2.0).unwrap();
/// let locator = SurfaceLocator::new(&grid);
/// let point = locator.closest([0.3, -0.2, 0.5]);
/// assert!((point.squared_distance - 0.25).abs() < 1e-15);
/// let [x, y, z] = point.position(&grid);
/// assert!((x - 0.3).abs() < 1e-15 && (y + 0.2).abs() < 1e-15 && z == 0.0);
/// ```
#[derive(Clone, Debug)]
pub struct SurfaceLocator {
    nodes: Vec<Node>,
    /// Corner positions of the faces, in leaf order.
    triangles: Vec<[[f64; 3]; 3]>,
    /// Mesh face index of each entry of `triangles`.
    face_indices: Vec<usize>,
    /// Largest coordinate magnitude of the mesh, for the pruning margin.
    largest_coordinate: f64,
}

impl SurfaceLocator {
    /// Builds the hierarchy over every face of `mesh`: faces are split at the
    /// median of their centroids along the longest axis of the centroids'
    /// box, down to leaves of at most 4 faces. A [`TriMesh`] always has a
    /// face, so this cannot fail.
    ///
    /// Cost: `O(F log F)` time, `O(F)` memory.
    pub fn new(mesh: &TriMesh) -> Self {
        let num_faces = mesh.num_faces();
        let triangles_by_face: Vec<[[f64; 3]; 3]> =
            (0..num_faces).map(|f| mesh.face_positions(f)).collect();
        let centroids: Vec<[f64; 3]> = triangles_by_face
            .iter()
            .map(|[a, b, c]| {
                [
                    (a[0] + b[0] + c[0]) / 3.0,
                    (a[1] + b[1] + c[1]) / 3.0,
                    (a[2] + b[2] + c[2]) / 3.0,
                ]
            })
            .collect();
        let mut order: Vec<usize> = (0..num_faces).collect();
        let mut nodes = Vec::with_capacity(2 * num_faces.div_ceil(LEAF_SIZE));
        build_subtree(&mut nodes, &mut order, 0, &triangles_by_face, &centroids);
        let triangles = order.iter().map(|&f| triangles_by_face[f]).collect();
        let largest_coordinate = mesh
            .positions()
            .iter()
            .flatten()
            .fold(0.0_f64, |largest, c| largest.max(c.abs()));
        Self {
            nodes,
            triangles,
            face_indices: order,
            largest_coordinate,
        }
    }

    /// Number of faces the hierarchy covers.
    pub fn num_faces(&self) -> usize {
        self.triangles.len()
    }

    /// The closest point of the surface to `point` (over all faces; among
    /// faces at the same squared distance, the lowest index).
    ///
    /// A query with a NaN or infinite coordinate has no closest point: it
    /// gets face 0, weights `[1, 0, 0]` and a NaN squared distance. (So does
    /// every query on a mesh whose every face has a non-finite corner, which
    /// only [`TriMesh::transformed`] can make; faces with a non-finite corner
    /// are otherwise never the answer.)
    ///
    /// Cost: `O(log F)` for a query near the surface; more when many faces
    /// are almost equally close.
    pub fn closest(&self, point: [f64; 3]) -> SurfacePoint {
        if point.iter().any(|c| !c.is_finite()) {
            return NO_CLOSEST_POINT;
        }
        let largest = point
            .iter()
            .fold(self.largest_coordinate, |largest, c| largest.max(c.abs()));
        let margin = PRUNING_MARGIN * largest;

        let mut best = Best {
            face: usize::MAX,
            weights: [1.0, 0.0, 0.0],
            squared_distance: f64::INFINITY,
            skip_beyond: f64::INFINITY,
        };
        // Subtrees put aside for later, with their boxes' squared distances.
        let mut pending: Vec<(usize, f64)> = Vec::with_capacity(64);
        let mut node_index = 0usize;
        loop {
            let node = &self.nodes[node_index];
            let mut next = None;
            if node.count > 0 {
                for slot in node.first..node.first + node.count {
                    best.offer(
                        self.face_indices[slot],
                        closest_point_on_triangle(point, &self.triangles[slot]),
                        margin,
                    );
                }
            } else {
                let near = node_index + 1;
                let far = node.first;
                let near_distance = box_squared_distance(&self.nodes[near], point);
                let far_distance = box_squared_distance(&self.nodes[far], point);
                let (near, far, near_distance, far_distance) = if far_distance < near_distance {
                    (far, near, far_distance, near_distance)
                } else {
                    (near, far, near_distance, far_distance)
                };
                if near_distance <= best.skip_beyond {
                    next = Some(near);
                    if far_distance <= best.skip_beyond {
                        pending.push((far, far_distance));
                    }
                } else if far_distance <= best.skip_beyond {
                    next = Some(far);
                }
            }
            node_index = match next {
                Some(index) => index,
                None => loop {
                    match pending.pop() {
                        Some((index, distance)) => {
                            if distance <= best.skip_beyond {
                                break index;
                            }
                        }
                        None => return best.into_surface_point(),
                    }
                },
            };
        }
    }

    /// [`Self::closest`] for every point, in parallel (rayon), in the order
    /// of `points`; the answers do not depend on the thread count.
    ///
    /// Cost: `O(n log F)` for points near the surface.
    pub fn closest_all(&self, points: &[[f64; 3]]) -> Vec<SurfacePoint> {
        points
            .par_iter()
            .with_min_len(256)
            .map(|&point| self.closest(point))
            .collect()
    }
}

/// The closest point of `mesh`'s surface to each of `points`: builds a
/// [`SurfaceLocator`] and calls [`SurfaceLocator::closest_all`].
///
/// Cost: `O(F log F + n log F)`.
///
/// # Example
/// ```
/// let mesh = mfm_geometry::procedural::icosphere(1);
/// let located = mfm_geometry::closest::closest_points(&mesh, mesh.positions());
/// assert!(located.iter().all(|p| p.squared_distance == 0.0));
/// ```
pub fn closest_points(mesh: &TriMesh, points: &[[f64; 3]]) -> Vec<SurfacePoint> {
    SurfaceLocator::new(mesh).closest_all(points)
}

/// The answer when there is no closest point: a non-finite query, or a mesh
/// whose every face has a non-finite corner (which only
/// [`TriMesh::transformed`] with a non-finite scale or shift can make).
const NO_CLOSEST_POINT: SurfacePoint = SurfacePoint {
    face: 0,
    weights: [1.0, 0.0, 0.0],
    squared_distance: f64::NAN,
};

/// The best face found so far during a query.
struct Best {
    /// `usize::MAX` until a face has been offered.
    face: usize,
    weights: [f64; 3],
    squared_distance: f64,
    /// Boxes farther than this (squared) cannot hold a face as close as the
    /// best one, even with round-off: `(distance + margin)²`.
    skip_beyond: f64,
}

impl Best {
    #[inline]
    fn offer(&mut self, face: usize, candidate: TrianglePoint, margin: f64) {
        let closer = candidate.squared_distance < self.squared_distance
            || (candidate.squared_distance == self.squared_distance && face < self.face);
        if closer {
            self.face = face;
            self.weights = candidate.weights;
            self.squared_distance = candidate.squared_distance;
            let reach = candidate.squared_distance.sqrt() + margin;
            self.skip_beyond = reach * reach;
        }
    }

    fn into_surface_point(self) -> SurfacePoint {
        if self.face == usize::MAX {
            return NO_CLOSEST_POINT;
        }
        SurfacePoint {
            face: self.face,
            weights: self.weights,
            squared_distance: self.squared_distance,
        }
    }
}

/// Squared distance from `point` to the node's box (0 inside).
#[inline]
fn box_squared_distance(node: &Node, point: [f64; 3]) -> f64 {
    let mut total = 0.0;
    for ((&coordinate, &lower), &upper) in point.iter().zip(&node.lower).zip(&node.upper) {
        let gap = if coordinate < lower {
            lower - coordinate
        } else if coordinate > upper {
            coordinate - upper
        } else {
            0.0
        };
        total += gap * gap;
    }
    total
}

/// Appends the subtree over the faces `order` (whose first entry is at leaf
/// position `offset`) to `nodes`, depth first, and reorders `order` into leaf
/// order.
fn build_subtree(
    nodes: &mut Vec<Node>,
    order: &mut [usize],
    offset: usize,
    triangles: &[[[f64; 3]; 3]],
    centroids: &[[f64; 3]],
) {
    let mut lower = [f64::INFINITY; 3];
    let mut upper = [f64::NEG_INFINITY; 3];
    let mut centroid_lower = [f64::INFINITY; 3];
    let mut centroid_upper = [f64::NEG_INFINITY; 3];
    for &f in order.iter() {
        for corner in &triangles[f] {
            for axis in 0..3 {
                lower[axis] = lower[axis].min(corner[axis]);
                upper[axis] = upper[axis].max(corner[axis]);
            }
        }
        let centroid = centroids[f];
        for axis in 0..3 {
            centroid_lower[axis] = centroid_lower[axis].min(centroid[axis]);
            centroid_upper[axis] = centroid_upper[axis].max(centroid[axis]);
        }
    }
    let index = nodes.len();
    nodes.push(Node {
        lower,
        upper,
        first: offset,
        count: order.len(),
    });
    if order.len() <= LEAF_SIZE {
        return;
    }

    let extent = |axis: usize| centroid_upper[axis] - centroid_lower[axis];
    let mut split_axis = 0;
    for axis in 1..3 {
        if extent(axis) > extent(split_axis) {
            split_axis = axis;
        }
    }
    // Median by (centroid coordinate, face index): a total order, so the
    // tree does not depend on how the selection breaks ties.
    let middle = order.len() / 2;
    order.select_nth_unstable_by(middle, |&f, &g| {
        centroids[f][split_axis]
            .total_cmp(&centroids[g][split_axis])
            .then(f.cmp(&g))
    });
    let (left, right) = order.split_at_mut(middle);
    build_subtree(nodes, left, offset, triangles, centroids);
    let second_child = nodes.len();
    build_subtree(nodes, right, offset + middle, triangles, centroids);
    nodes[index].first = second_child;
    nodes[index].count = 0;
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fraction_is_clamped_and_never_nan() {
        assert_eq!(fraction(1.0, 0.0), 0.0);
        assert_eq!(fraction(0.0, 0.0), 0.0);
        assert_eq!(fraction(2.0, 1.0), 1.0);
        assert_eq!(fraction(-1.0, 1.0), 0.0);
        assert_eq!(fraction(f64::NAN, 1.0), 0.0);
        assert_eq!(fraction(1.0, 4.0), 0.25);
    }

    #[test]
    fn leaves_cover_every_face_once() {
        let mesh = crate::procedural::icosphere(2);
        let locator = SurfaceLocator::new(&mesh);
        let mut seen = vec![0u32; mesh.num_faces()];
        for node in locator.nodes.iter().filter(|n| n.count > 0) {
            assert!(node.count <= LEAF_SIZE);
            for slot in node.first..node.first + node.count {
                seen[locator.face_indices[slot]] += 1;
            }
        }
        assert!(seen.iter().all(|&n| n == 1));
    }
}
