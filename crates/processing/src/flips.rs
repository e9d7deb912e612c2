//! Random edge flips, to make a triangulation worse on purpose.
//!
//! Flipping the interior edge `ab` shared by `[a, b, c]` and `[b, a, d]`
//! replaces the two faces by `[a, d, c]` and `[d, b, c]`: same vertices, same
//! face count, same topology, another triangulation of (nearly) the same
//! surface. [`random_edge_flips`] visits the interior edges in a random order
//! (`rand_chacha::ChaCha8Rng` seeded with `seed`, so the result is reproducible)
//! and flips those it may, until the requested number is reached.
//!
//! A flip is skipped when
//! - the new edge `cd` already exists (the result would be non-manifold), or
//!   `c == d`;
//! - a new face is (nearly) degenerate: quality `4√3·area / Σ edge²` below
//!   [`MIN_FLIP_QUALITY`] (e.g. three collinear vertices); or its normal deviates by more
//!   than [`MAX_FLIP_NORMAL_DEVIATION_DEGREES`] from the (area-weighted) mean
//!   normal of the two old faces, or the two new normals differ by more than
//!   that angle from each other: this rejects flips across non-convex quads,
//!   which would fold one face over the other, and flips across sharp creases.
//!
//! Each edge of the input is tried at most once; edges created by a flip are
//! not flipped again (that would just undo it).
//!
//! # Example
//! ```
//! use mfm_geometry::procedural;
//! use mfm_processing::flips::{random_edge_flips, FlipAmount};
//! let sphere = procedural::icosphere(3);
//! let out = random_edge_flips(&sphere, FlipAmount::Fraction(0.2), 7);
//! assert_eq!(out.mesh.num_faces(), sphere.num_faces());
//! assert!(out.flips > 0);
//! ```

use std::collections::HashMap;

use rand::SeedableRng;
use rand::seq::SliceRandom;
use rand_chacha::ChaCha8Rng;

use mfm_geometry::mesh::{TriMesh, cross, dot, norm, sub};
use mfm_geometry::topology::Topology;

/// Largest angle, in degrees, between a new face's normal and the mean normal
/// of the faces it replaces (and between the two new normals) for a flip to
/// be accepted.
pub const MAX_FLIP_NORMAL_DEVIATION_DEGREES: f64 = 30.0;

/// Smallest quality `4√3·area / (l0² + l1² + l2²)` (1 for an equilateral
/// triangle) a face created by a flip may have: flips may make thin
/// triangles, but not degenerate ones.
pub const MIN_FLIP_QUALITY: f64 = 0.01;

/// How many edges to flip.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum FlipAmount {
    /// This many flips (at most the number of interior edges).
    Count(usize),
    /// This fraction of the interior edges, clamped to `[0, 1]` (NaN counts
    /// as 0), rounded to the nearest integer.
    Fraction(f64),
}

/// Result of [`random_edge_flips`].
#[derive(Clone, Debug)]
pub struct Flipped {
    /// The mesh after the flips: same vertices (same order), same face count.
    pub mesh: TriMesh,
    /// Number of flips done; below the request when too few edges could be
    /// flipped validly.
    pub flips: usize,
}

#[inline]
fn key(a: u32, b: u32) -> u64 {
    let (lo, hi) = if a < b { (a, b) } else { (b, a) };
    (u64::from(lo) << 32) | u64::from(hi)
}

/// Flips random interior edges of `mesh` (see the [module docs](self)).
///
/// Edges with more than two faces are never flipped, and faces around them
/// are left alone. A consistently oriented manifold stays one, with the same
/// `V`, `F`, Euler characteristic and boundary. Cost: `O(F log F)`.
pub fn random_edge_flips(mesh: &TriMesh, amount: FlipAmount, seed: u64) -> Flipped {
    let topo = Topology::new(mesh.num_vertices(), mesh.faces());
    let mut candidates: Vec<[u32; 2]> = (0..topo.edges().len())
        .filter(|&e| topo.edge_faces(e).len() == 2)
        .map(|e| topo.edges()[e])
        .collect();
    let wanted = match amount {
        FlipAmount::Count(c) => c.min(candidates.len()),
        FlipAmount::Fraction(f) => {
            let f = if f.is_nan() { 0.0 } else { f.clamp(0.0, 1.0) };
            ((f * candidates.len() as f64).round() as usize).min(candidates.len())
        }
    };
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    candidates.shuffle(&mut rng);

    let p = mesh.positions();
    let mut faces = mesh.faces().to_vec();
    // two faces per manifold edge; `u32::MAX` marks a third face (never flipped)
    let mut edge_faces: HashMap<u64, [u32; 2]> = HashMap::with_capacity(topo.edges().len());
    for e in 0..topo.edges().len() {
        let [a, b] = topo.edges()[e];
        let nb = topo.edge_faces(e);
        let slot = match nb {
            [f] => [*f, u32::MAX],
            [f, g] => [*f, *g],
            _ => [u32::MAX, u32::MAX],
        };
        edge_faces.insert(key(a, b), slot);
    }
    let cos_max = MAX_FLIP_NORMAL_DEVIATION_DEGREES.to_radians().cos();
    let normal = |t: [u32; 3]| {
        cross(
            sub(p[t[1] as usize], p[t[0] as usize]),
            sub(p[t[2] as usize], p[t[0] as usize]),
        )
    };
    let quality = |t: [u32; 3], n: [f64; 3]| {
        let s: f64 = (0..3)
            .map(|k| {
                let d = sub(p[t[(k + 1) % 3] as usize], p[t[k] as usize]);
                dot(d, d)
            })
            .sum();
        2.0 * 3.0_f64.sqrt() * norm(n) / s
    };
    let aligned = |x: [f64; 3], y: [f64; 3]| {
        let (lx, ly) = (norm(x), norm(y));
        lx > 0.0 && ly > 0.0 && dot(x, y) >= cos_max * lx * ly
    };

    let mut flips = 0usize;
    for [a, b] in candidates {
        if flips >= wanted {
            break;
        }
        let Some(&[f, g]) = edge_faces.get(&key(a, b)) else {
            continue;
        };
        if f == u32::MAX || g == u32::MAX {
            continue;
        }
        // orient so that f traverses a -> b; g must then traverse b -> a
        let (tf, tg) = (faces[f as usize], faces[g as usize]);
        let pos_in = |t: [u32; 3], v: u32| t.iter().position(|&w| w == v);
        let (Some(ia), Some(ib)) = (pos_in(tf, a), pos_in(tf, b)) else {
            continue;
        };
        let (a, b, ib) = if (ia + 1) % 3 == ib {
            (a, b, ib)
        } else {
            (b, a, ia)
        };
        let (Some(ja), Some(jb)) = (pos_in(tg, a), pos_in(tg, b)) else {
            continue;
        };
        if (jb + 1) % 3 != ja {
            continue; // inconsistently oriented pair: leave it
        }
        let c = tf[(ib + 1) % 3];
        let d = tg[(ja + 1) % 3];
        if c == d || edge_faces.contains_key(&key(c, d)) {
            continue;
        }
        let (nf, ng) = (normal(tf), normal(tg));
        let mean = [nf[0] + ng[0], nf[1] + ng[1], nf[2] + ng[2]];
        let (new_f, new_g) = ([a, d, c], [d, b, c]);
        let (n1, n2) = (normal(new_f), normal(new_g));
        if !(aligned(n1, mean) && aligned(n2, mean) && aligned(n1, n2))
            || quality(new_f, n1) < MIN_FLIP_QUALITY
            || quality(new_g, n2) < MIN_FLIP_QUALITY
        {
            continue;
        }
        faces[f as usize] = new_f;
        faces[g as usize] = new_g;
        edge_faces.remove(&key(a, b));
        edge_faces.insert(key(c, d), [f, g]);
        // edge a-d moved from g to f, edge b-c from f to g
        for (k, from, to) in [(key(a, d), g, f), (key(b, c), f, g)] {
            if let Some(slot) = edge_faces.get_mut(&k) {
                for s in slot.iter_mut() {
                    if *s == from {
                        *s = to;
                    }
                }
            }
        }
        flips += 1;
    }
    // c != d and both differ from a and b, so faces stay valid
    let mesh = TriMesh::new(p.to_vec(), faces).expect("edge flips keep a valid mesh");
    Flipped { mesh, flips }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn flips_a_convex_quad() {
        // square split along 0-2; flipping gives the 1-3 diagonal
        let m = TriMesh::new(
            vec![
                [0.0, 0.0, 0.0],
                [1.0, 0.0, 0.0],
                [1.0, 1.0, 0.0],
                [0.0, 1.0, 0.0],
            ],
            vec![[0, 1, 2], [0, 2, 3]],
        )
        .expect("valid");
        let out = random_edge_flips(&m, FlipAmount::Count(1), 0);
        assert_eq!(out.flips, 1);
        let t = Topology::new(4, out.mesh.faces());
        assert!(t.find_edge(1, 3).is_some());
        assert!(t.find_edge(0, 2).is_none());
        assert!(t.inconsistently_oriented_edges().is_empty());
        for f in 0..2 {
            assert!(mfm_geometry::mesh::triangle_normal(&out.mesh.face_positions(f))[2] > 0.0);
        }
    }

    #[test]
    fn refuses_a_non_convex_quad() {
        // dart: vertex 2 pokes inside, so the 1-3 diagonal would fold
        let m = TriMesh::new(
            vec![
                [0.0, 0.0, 0.0],
                [2.0, -1.0, 0.0],
                [0.5, 0.0, 0.0],
                [2.0, 1.0, 0.0],
            ],
            vec![[0, 1, 2], [0, 2, 3]],
        )
        .expect("valid");
        let out = random_edge_flips(&m, FlipAmount::Count(1), 0);
        assert_eq!(out.flips, 0);
        assert_eq!(out.mesh, m);
    }
}
