//! The cache-blocked assembly engine behind [`super`]'s operators.
//!
//! The operators are sums over faces, grouped by vertex (column). The per-face
//! data (cotangents, `1 / l2`, areas) is computed once, in parallel. Then the
//! assembly is *cache-blocked*: the vertices are cut into blocks of `VBLOCK`
//! consecutive indices, and a parallel counting sort lists, for each block, the
//! faces with a corner in it (in increasing face order). Each block is then
//! assembled independently (in parallel, rayon) from its own face list, writing
//! only the columns of its vertices: those slices of the outputs are disjoint
//! (safe Rust, no atomics) and small enough to stay in cache, whatever the
//! vertex order of the mesh. No global sort is needed, the work is `O(V + F)`,
//! and the entries of a column are always summed in increasing face order, so
//! the results are bit-identical for any number of threads and `L_ij`, `L_ji`
//! are equal bit for bit.
//!
//! `L` takes two passes over each block: its pattern (each vertex's neighbours,
//! gathered, sorted and deduplicated; connectivity only), then, once the column
//! pointers are known, its values (each corner adds its two half-cotangents at
//! their place in the column, then each diagonal is set to minus the sum of its
//! column). Temporary memory is kept small on purpose: for large meshes, the
//! first-touch page faults of fresh allocations cost as much as the arithmetic.

use std::ops::Range;

use faer::sparse::{SparseColMat, SymbolicSparseColMat};
use rayon::prelude::*;

use super::{FACE_CHUNK, FaceData};
use crate::mesh::TriMesh;

/// Vertices per block of the cache-blocked assembly.
pub(super) const VBLOCK: usize = 2048;

/// Which operators [`assemble`] builds ([`super::lumped_mass`] alone goes through
/// [`mass_from_areas`]).
#[derive(Clone, Copy)]
pub(super) struct Want {
    pub(super) laplacian: bool,
    pub(super) gradient: bool,
    pub(super) mass: bool,
}

impl Want {
    pub(super) const NONE: Self = Self {
        laplacian: false,
        gradient: false,
        mass: false,
    };
    pub(super) const ALL: Self = Self {
        laplacian: true,
        gradient: true,
        mass: true,
    };
}

pub(super) struct Assembled {
    pub(super) laplacian: Option<SparseColMat<usize, f64>>,
    pub(super) gradient: Option<SparseColMat<usize, f64>>,
    pub(super) mass: Option<Vec<f64>>,
}

/// Splits `0..n` into consecutive ranges of at most `block` elements.
pub(super) fn block_ranges(n: usize, block: usize) -> Vec<Range<usize>> {
    let block = block.max(1);
    (0..n.div_ceil(block))
        .map(|b| b * block..((b + 1) * block).min(n))
        .collect()
}

/// Cuts `data` into consecutive pieces, piece `k` spanning
/// `start(r.start)..start(r.end)` for the `k`-th range `r` (the ranges tile
/// their domain in order, and `start` of the first range is 0).
fn split_ranges<'a, T>(
    mut data: &'a mut [T],
    ranges: &[Range<usize>],
    start: impl Fn(usize) -> usize,
) -> Vec<&'a mut [T]> {
    let mut out = Vec::with_capacity(ranges.len());
    for r in ranges {
        let (head, tail) = std::mem::take(&mut data).split_at_mut(start(r.end) - start(r.start));
        out.push(head);
        data = tail;
    }
    out
}

fn prefix_sum(counts: impl Iterator<Item = usize>) -> Vec<usize> {
    let mut ptr = Vec::with_capacity(counts.size_hint().0 + 1);
    let mut acc = 0usize;
    ptr.push(0);
    for c in counts {
        acc += c;
        ptr.push(acc);
    }
    ptr
}

/// Index type of the per-block face lists: `u32`, or `u64` for meshes with
/// more than `u32::MAX` faces.
trait FaceId: Copy + Default + Send + Sync {
    fn from_usize(f: usize) -> Self;
    fn to_usize(self) -> usize;
}

impl FaceId for u32 {
    #[inline]
    fn from_usize(f: usize) -> Self {
        f as u32
    }
    #[inline]
    fn to_usize(self) -> usize {
        self as usize
    }
}

impl FaceId for u64 {
    #[inline]
    fn from_usize(f: usize) -> Self {
        f as u64
    }
    #[inline]
    fn to_usize(self) -> usize {
        self as usize
    }
}

/// The distinct vertex blocks of a face (`count` of them, in `blocks[..count]`).
#[inline]
fn face_blocks(t: &[u32; 3]) -> ([usize; 3], usize) {
    let b = [
        t[0] as usize / VBLOCK,
        t[1] as usize / VBLOCK,
        t[2] as usize / VBLOCK,
    ];
    let mut out = [b[0], 0, 0];
    let mut count = 1;
    if b[1] != b[0] {
        out[count] = b[1];
        count += 1;
    }
    if b[2] != b[0] && b[2] != b[1] {
        out[count] = b[2];
        count += 1;
    }
    (out, count)
}

/// For each block of `VBLOCK` consecutive vertices, the faces with a corner
/// in it, in increasing order.
struct FaceBuckets<I> {
    ptr: Vec<usize>,
    list: Vec<I>,
}

impl<I: FaceId> FaceBuckets<I> {
    /// A parallel counting sort: chunks of faces count their blocks, then each
    /// chunk writes its faces into its own piece of every block's list.
    fn new(num_vertices: usize, faces: &[[u32; 3]]) -> Self {
        let nb = num_vertices.div_ceil(VBLOCK);
        let chunk = faces
            .len()
            .div_ceil(4 * rayon::current_num_threads())
            .max(FACE_CHUNK);
        let chunks = block_ranges(faces.len(), chunk);
        let counts: Vec<Vec<usize>> = chunks
            .par_iter()
            .map(|r| {
                let mut count = vec![0usize; nb];
                for t in &faces[r.clone()] {
                    let (blocks, k) = face_blocks(t);
                    for &b in &blocks[..k] {
                        count[b] += 1;
                    }
                }
                count
            })
            .collect();
        let ptr = prefix_sum((0..nb).map(|b| counts.iter().map(|c| c[b]).sum()));
        let mut list = vec![I::default(); ptr[nb]];
        // block-major, chunk-minor pieces, regrouped by chunk
        let mut pieces: Vec<Vec<&mut [I]>> =
            (0..chunks.len()).map(|_| Vec::with_capacity(nb)).collect();
        let mut rest: &mut [I] = &mut list;
        for b in 0..nb {
            for (c, count) in counts.iter().enumerate() {
                let (head, tail) = std::mem::take(&mut rest).split_at_mut(count[b]);
                pieces[c].push(head);
                rest = tail;
            }
        }
        chunks.par_iter().zip(pieces).for_each(|(r, mut pieces)| {
            let mut next = vec![0usize; nb];
            for f in r.clone() {
                let (blocks, k) = face_blocks(&faces[f]);
                for &b in &blocks[..k] {
                    pieces[b][next[b]] = I::from_usize(f);
                    next[b] += 1;
                }
            }
        });
        Self { ptr, list }
    }

    fn of(&self, b: usize) -> &[I] {
        &self.list[self.ptr[b]..self.ptr[b + 1]]
    }
}

/// Builds the requested operators (see the comment at the top of this
/// section). `areas` is only read when the mass is wanted.
pub(super) fn assemble(mesh: &TriMesh, data: &[FaceData], areas: &[f64], want: Want) -> Assembled {
    if u32::try_from(mesh.num_faces()).is_ok() {
        assemble_blocked::<u32>(mesh, data, areas, want)
    } else {
        assemble_blocked::<u64>(mesh, data, areas, want)
    }
}

fn assemble_blocked<I: FaceId>(
    mesh: &TriMesh,
    data: &[FaceData],
    areas: &[f64],
    want: Want,
) -> Assembled {
    let faces = mesh.faces();
    let n = mesh.num_vertices();
    let buckets = FaceBuckets::<I>::new(n, faces);
    let blocks = block_ranges(n, VBLOCK);

    // pass 1: per vertex, its corners, how many are corner 2, and (for L) its
    // distinct neighbours, sorted, one list per block
    let mut corners = vec![0u32; n];
    let mut thirds = vec![0u32; n];
    let mut distinct = vec![0u32; n];
    let neighbours: Vec<Vec<u32>> = blocks
        .par_iter()
        .zip(corners.par_chunks_mut(VBLOCK))
        .zip(thirds.par_chunks_mut(VBLOCK))
        .zip(distinct.par_chunks_mut(VBLOCK))
        .enumerate()
        .map(|(b, (((r, corners), thirds), distinct))| {
            let (lo, len) = (r.start, r.len());
            let bucket = buckets.of(b);
            for &f in bucket {
                for (c, &v) in faces[f.to_usize()].iter().enumerate() {
                    let k = (v as usize).wrapping_sub(lo);
                    if k < len {
                        corners[k] += 1;
                        thirds[k] += u32::from(c == 2);
                    }
                }
            }
            if want.laplacian {
                block_neighbours(lo, bucket, faces, corners, distinct)
            } else {
                Vec::new()
            }
        })
        .collect();

    let l_ptr = if want.laplacian {
        prefix_sum(
            corners
                .iter()
                .zip(&distinct)
                .map(|(&c, &m)| if c > 0 { m as usize + 1 } else { 0 }),
        )
    } else {
        vec![0; n + 1]
    };
    let g_ptr = if want.gradient {
        prefix_sum(
            corners
                .iter()
                .zip(&thirds)
                .map(|(&c, &t)| 2 * c as usize - t as usize),
        )
    } else {
        vec![0; n + 1]
    };
    let mut l_rows = vec![0usize; l_ptr[n]];
    let mut l_val = vec![0.0f64; l_ptr[n]];
    let mut g_rows = vec![0usize; g_ptr[n]];
    let mut g_val = vec![0.0f64; g_ptr[n]];
    let mut mass = if want.mass {
        vec![0.0f64; n]
    } else {
        Vec::new()
    };

    // pass 2: values (and the row indices of L), block by block
    let m_start = |v: usize| if want.mass { v } else { 0 };
    let jobs: Vec<_> = blocks
        .iter()
        .cloned()
        .zip(neighbours)
        .zip(split_ranges(&mut l_rows, &blocks, |v| l_ptr[v]))
        .zip(split_ranges(&mut l_val, &blocks, |v| l_ptr[v]))
        .zip(split_ranges(&mut g_rows, &blocks, |v| g_ptr[v]))
        .zip(split_ranges(&mut g_val, &blocks, |v| g_ptr[v]))
        .zip(split_ranges(&mut mass, &blocks, m_start))
        .enumerate()
        .collect();
    jobs.into_par_iter().for_each(
        |(b, ((((((r, neighbours), l_rows), l_val), g_rows), g_val), mass))| {
            let (lo, len) = (r.start, r.len());
            let bucket = buckets.of(b);
            let (l_base, g_base) = (l_ptr[lo], g_ptr[lo]);
            if want.laplacian {
                write_laplacian_rows(r.clone(), &l_ptr, &corners, &neighbours, l_rows);
            }
            // next free slot of each vertex of the block in `g_rows`/`g_val`
            let mut g_next: Vec<usize> = if want.gradient {
                r.clone().map(|v| g_ptr[v] - g_base).collect()
            } else {
                Vec::new()
            };
            for &f in bucket {
                let f = f.to_usize();
                let (t, d) = (&faces[f], &data[f]);
                for c in 0..3 {
                    let v = t[c] as usize;
                    let k = v.wrapping_sub(lo);
                    if k >= len {
                        continue;
                    }
                    let (c1, c2) = ((c + 1) % 3, (c + 2) % 3);
                    if want.laplacian {
                        // edge (c, c1) is opposite corner c2, edge (c, c2) opposite c1
                        let col = l_ptr[v] - l_base..l_ptr[v + 1] - l_base;
                        let (rows, vals) = (&l_rows[col.clone()], &mut l_val[col]);
                        vals[find_row(rows, t[c1] as usize)] -= d.half_cot[c2];
                        vals[find_row(rows, t[c2] as usize)] -= d.half_cot[c1];
                    }
                    if want.gradient {
                        let s = g_next[k];
                        let (g0, g1, gy2) = d.gradients();
                        let g = match c {
                            0 => Some(g0),
                            1 => Some(g1),
                            _ => None,
                        };
                        if let Some([gx, gy]) = g {
                            g_rows[s] = 2 * f;
                            g_val[s] = gx;
                            g_rows[s + 1] = 2 * f + 1;
                            g_val[s + 1] = gy;
                            g_next[k] = s + 2;
                        } else {
                            g_rows[s] = 2 * f + 1;
                            g_val[s] = gy2;
                            g_next[k] = s + 1;
                        }
                    }
                    if want.mass {
                        mass[k] += areas[f];
                    }
                }
            }
            if want.laplacian {
                set_diagonals(r, &l_ptr, l_rows, l_val);
            }
            mass.iter_mut().for_each(|m| *m /= 3.0);
        },
    );

    let laplacian = want.laplacian.then(|| {
        let symbolic = SymbolicSparseColMat::new_checked(n, n, l_ptr, None, l_rows);
        SparseColMat::new(symbolic, l_val)
    });
    let gradient = want.gradient.then(|| {
        let symbolic = SymbolicSparseColMat::new_checked(2 * faces.len(), n, g_ptr, None, g_rows);
        SparseColMat::new(symbolic, g_val)
    });
    Assembled {
        laplacian,
        gradient,
        mass: want.mass.then_some(mass),
    }
}

/// The sorted distinct neighbours of the vertices `lo..lo + corners.len()`,
/// concatenated, from the faces of their block; their counts go to
/// `distinct`.
fn block_neighbours<I: FaceId>(
    lo: usize,
    bucket: &[I],
    faces: &[[u32; 3]],
    corners: &[u32],
    distinct: &mut [u32],
) -> Vec<u32> {
    let len = corners.len();
    // the two other corners of every corner, grouped by vertex
    let start = prefix_sum(corners.iter().map(|&c| 2 * c as usize));
    let mut list = vec![0u32; start[len]];
    let mut next = start[..len].to_vec();
    for &f in bucket {
        let t = &faces[f.to_usize()];
        for c in 0..3 {
            let k = (t[c] as usize).wrapping_sub(lo);
            if k < len {
                let s = next[k];
                list[s] = t[(c + 1) % 3];
                list[s + 1] = t[(c + 2) % 3];
                next[k] = s + 2;
            }
        }
    }
    // sort and deduplicate each vertex's part, compacting to the front
    let mut out = 0;
    for (k, m) in distinct.iter_mut().enumerate() {
        list[start[k]..start[k + 1]].sort_unstable();
        let first = out;
        for i in start[k]..start[k + 1] {
            let x = list[i];
            if out == first || x != list[out - 1] {
                list[out] = x;
                out += 1;
            }
        }
        *m = (out - first) as u32;
    }
    list.truncate(out);
    list.shrink_to_fit();
    list
}

/// Writes the row indices of the columns `r` of `L` (starting at
/// `l_ptr[r.start]` in `rows`): the sorted neighbours with the diagonal in
/// place.
fn write_laplacian_rows(
    r: Range<usize>,
    l_ptr: &[usize],
    corners: &[u32],
    neighbours: &[u32],
    rows: &mut [usize],
) {
    let base = l_ptr[r.start];
    let mut src = 0;
    for v in r.clone() {
        if corners[v] == 0 {
            continue;
        }
        let out = &mut rows[l_ptr[v] - base..l_ptr[v + 1] - base];
        let list = &neighbours[src..src + out.len() - 1];
        src += list.len();
        let below = list.partition_point(|&x| (x as usize) < v);
        for (o, &x) in out[..below].iter_mut().zip(&list[..below]) {
            *o = x as usize;
        }
        out[below] = v;
        for (o, &x) in out[below + 1..].iter_mut().zip(&list[below..]) {
            *o = x as usize;
        }
    }
}

/// The lumped mass from given face areas, block by block like [`assemble`].
pub(super) fn mass_from_areas(mesh: &TriMesh, areas: &[f64]) -> Vec<f64> {
    let (faces, n) = (mesh.faces(), mesh.num_vertices());
    let mut mass = vec![0.0; n];
    if u32::try_from(faces.len()).is_ok() {
        mass_blocked(&FaceBuckets::<u32>::new(n, faces), faces, areas, &mut mass);
    } else {
        mass_blocked(&FaceBuckets::<u64>::new(n, faces), faces, areas, &mut mass);
    }
    mass
}

fn mass_blocked<I: FaceId>(
    buckets: &FaceBuckets<I>,
    faces: &[[u32; 3]],
    areas: &[f64],
    mass: &mut [f64],
) {
    mass.par_chunks_mut(VBLOCK)
        .enumerate()
        .for_each(|(b, mass)| {
            let (lo, len) = (b * VBLOCK, mass.len());
            for &f in buckets.of(b) {
                let f = f.to_usize();
                for &v in &faces[f] {
                    let k = (v as usize).wrapping_sub(lo);
                    if k < len {
                        mass[k] += areas[f];
                    }
                }
            }
            mass.iter_mut().for_each(|m| *m /= 3.0);
        });
}

/// Position of `row` in a sorted column that contains it.
#[inline]
fn find_row(rows: &[usize], row: usize) -> usize {
    if rows.len() <= 16 {
        rows.iter().position(|&r| r == row).unwrap_or(usize::MAX)
    } else {
        rows.binary_search(&row).unwrap_or(usize::MAX)
    }
}

/// Sets `L_vv = -sum_{i != v} L_iv` (summed in row order) for the vertices
/// of `r`, whose rows and values start at `l_ptr[r.start]`.
fn set_diagonals(r: Range<usize>, l_ptr: &[usize], rows: &[usize], vals: &mut [f64]) {
    let base = l_ptr[r.start];
    for v in r {
        let col = l_ptr[v] - base..l_ptr[v + 1] - base;
        let mut sum = 0.0;
        let mut diag = None;
        for k in col {
            if rows[k] == v {
                diag = Some(k);
            } else {
                sum += vals[k];
            }
        }
        if let Some(k) = diag {
            vals[k] = -sum;
        }
    }
}
