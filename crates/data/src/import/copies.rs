//! Copies and near copies among imported signals, found while they stream
//! by: each signal leaves only a sketch ([`SKETCH`] random projections),
//! and pairs are compared by their sketches at the end.
//!
//! Distance: the RMS over vertices of the per-vertex difference (its norm
//! over the channels), `d(x, y) = sqrt(sum_v |x_v - y_v|^2 / V)`, as the
//! vertices are given (no centring: a copy is a copy in place). Two
//! signals are near copies when `d` is below [`COPY_TOLERANCE`] times a
//! scale: the template's bounding-box diagonal for positions, the larger
//! of the two signals' RMS values otherwise. Frames exported twice, or
//! rounded differently on the way (the shared horse gallop repeats its
//! 24-frame cycle with differences of 1e-6 of the diagonal), are near
//! copies; neighbouring frames of a capture (1e-3 of the diagonal and more
//! in the shared sequences) are not.
//!
//! The sketch of `x` is `s_k = r_k . x` with `r_k` a fixed vector of
//! `+-1 / sqrt(V)` entries, so `E[|s(x) - s(y)|^2] = SKETCH d(x, y)^2`,
//! and `d` is estimated as `|s(x) - s(y)| / sqrt(SKETCH)` (a chi
//! distribution with 16 degrees of freedom around the truth): a pair at
//! half the tolerance is missed with odds of 1e-7, one at three times it
//! is taken for a copy with odds of 4e-6, at ten times 4e-14.

/// Near copies: an RMS vertex distance below this fraction of the scale
/// (see the [module docs](self)).
pub const COPY_TOLERANCE: f64 = 1e-4;

/// Random projections a signal is sketched by.
pub const SKETCH: usize = 16;

/// The sketches of the signals seen so far.
#[derive(Debug)]
pub(crate) struct CopyFinder {
    /// `SKETCH` projection vectors of `len` values each, `+-1 / sqrt(V)`.
    projections: Vec<f32>,
    len: usize,
    vertices: usize,
    /// The fixed scale of position signals (the template's diagonal);
    /// `None`: each signal's own RMS value.
    scale: Option<f64>,
    seen: Vec<Sketch>,
}

#[derive(Debug)]
struct Sketch {
    index: usize,
    values: [f64; SKETCH],
    scale: f64,
}

impl CopyFinder {
    /// A finder for signals of `vertices x channels` values; `diagonal`:
    /// the scale of position signals (`None` for other signals).
    pub(crate) fn new(vertices: usize, channels: usize, diagonal: Option<f64>) -> Self {
        let len = vertices * channels;
        let unit = 1.0 / (vertices.max(1) as f32).sqrt();
        let mut state = 0x6d66_6d5f_636f_7079_u64; // fixed: the same sketches every run
        let mut projections = Vec::with_capacity(SKETCH * len);
        while projections.len() < SKETCH * len {
            let bits = splitmix64(&mut state);
            let take = (SKETCH * len - projections.len()).min(64);
            projections.extend((0..take).map(|b| if bits >> b & 1 == 1 { unit } else { -unit }));
        }
        Self {
            projections,
            len,
            vertices,
            scale: diagonal,
            seen: Vec::new(),
        }
    }

    /// Notes signal `index` by its sketch ([`CopyFinder::sketch`], which
    /// may run on other threads).
    pub(crate) fn push(&mut self, index: usize, (values, scale): ([f64; SKETCH], f64)) {
        self.seen.push(Sketch {
            index,
            values,
            scale,
        });
    }

    /// The sketch of `signal` (`vertices x channels` values, vertex-major)
    /// and its scale.
    pub(crate) fn sketch(&self, signal: &[f32]) -> ([f64; SKETCH], f64) {
        let mut values = [0.0f64; SKETCH];
        for (value, r) in values
            .iter_mut()
            .zip(self.projections.chunks_exact(self.len))
        {
            *value = signal
                .iter()
                .zip(r)
                .map(|(&x, &r)| f64::from(x) * f64::from(r))
                .sum();
        }
        let scale = self.scale.unwrap_or_else(|| {
            let sum: f64 = signal.iter().map(|&x| f64::from(x) * f64::from(x)).sum();
            (sum / self.vertices.max(1) as f64).sqrt()
        });
        (values, scale)
    }

    /// Every pair of near copies as `(later, earlier)` input indices,
    /// sorted. Sorting by the first projection bounds the comparisons to
    /// the pairs within the tolerance of each other in that projection.
    pub(crate) fn pairs(&self) -> Vec<(usize, usize)> {
        let root = (SKETCH as f64).sqrt();
        let widest = self.seen.iter().map(|s| s.scale).fold(0.0, f64::max);
        let window = root * COPY_TOLERANCE * widest;
        let mut order: Vec<&Sketch> = self.seen.iter().collect();
        order.sort_by(|a, b| a.values[0].total_cmp(&b.values[0]));
        let mut out = Vec::new();
        for (k, a) in order.iter().enumerate() {
            for b in order[k + 1..]
                .iter()
                .take_while(|b| b.values[0] - a.values[0] <= window)
            {
                let squared: f64 = a
                    .values
                    .iter()
                    .zip(&b.values)
                    .map(|(x, y)| (x - y) * (x - y))
                    .sum();
                if squared.sqrt() / root <= COPY_TOLERANCE * a.scale.max(b.scale) {
                    out.push((a.index.max(b.index), a.index.min(b.index)));
                }
            }
        }
        out.sort_unstable();
        out
    }
}

/// The next value of the splitmix64 sequence.
fn splitmix64(state: &mut u64) -> u64 {
    *state = state.wrapping_add(0x9e37_79b9_7f4a_7c15);
    let mut z = *state;
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

#[cfg(test)]
mod tests {
    use super::*;

    impl CopyFinder {
        fn add(&mut self, index: usize, signal: &[f32]) {
            let sketch = self.sketch(signal);
            self.push(index, sketch);
        }
    }

    /// A signal of `v` vertices, 3 channels, from `seed`, values in [-1, 1].
    fn signal(v: usize, seed: u64) -> Vec<f32> {
        let mut s = seed;
        (0..3 * v)
            .map(|_| (splitmix64(&mut s) >> 11) as f32 / (1u64 << 53) as f32 * 2.0 - 1.0)
            .collect()
    }

    /// `x` moved by `d` (RMS vertex distance) along a fixed direction.
    fn moved(x: &[f32], d: f64) -> Vec<f32> {
        let step = (d / 3f64.sqrt()) as f32;
        x.iter()
            .enumerate()
            .map(|(i, &a)| a + if i % 2 == 0 { step } else { -step })
            .collect()
    }

    #[test]
    fn copies_and_near_copies_are_found_and_distinct_signals_are_not() {
        let v = 2000;
        let mut finder = CopyFinder::new(v, 3, Some(1.0));
        let a = signal(v, 1);
        let b = signal(v, 2);
        finder.add(0, &a);
        finder.add(1, &b);
        finder.add(2, &a); // an exact copy
        finder.add(3, &moved(&b, 0.5 * COPY_TOLERANCE)); // a near copy
        finder.add(4, &moved(&a, 10.0 * COPY_TOLERANCE)); // a neighbour, not a copy
        finder.add(5, &moved(&a, 1e-2)); // far
        assert_eq!(finder.pairs(), vec![(2, 0), (3, 1)]);
    }

    #[test]
    fn other_signals_are_judged_against_their_own_size() {
        let v = 500;
        let a = signal(v, 3);
        let small: Vec<f32> = a.iter().map(|x| x * 1e-3).collect();
        let mut finder = CopyFinder::new(v, 3, None);
        finder.add(0, &small);
        // 0.5 tolerance of the small signal's size: a near copy
        finder.add(1, &moved(&small, 0.5e-3 * COPY_TOLERANCE));
        // a signal 1000 times larger: far from both
        finder.add(2, &a);
        assert_eq!(finder.pairs(), vec![(1, 0)]);
        // all-zero signals are copies of each other
        let mut zeros = CopyFinder::new(v, 1, None);
        zeros.add(0, &vec![0.0; v]);
        zeros.add(1, &vec![0.0; v]);
        assert_eq!(zeros.pairs(), vec![(1, 0)]);
    }
}
