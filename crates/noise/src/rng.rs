//! Per-stream random numbers: one ChaCha8 stream per (seed, sample, channel).
//!
//! A stream is `ChaCha8Rng::seed_from_u64(seed)` (the 32-byte key expanded
//! from the seed by rand_core's PCG32 filler), switched to the 64-bit stream
//! id `sample` and positioned at word `channel << CHANNEL_SHIFT`. Every
//! (sample, channel) pair therefore reads its own window of the keystream, and
//! what it reads does not depend on the batch it is drawn in, on the number
//! of channels requested, nor on the thread that draws it.
//!
//! `f64` standard normals come from `rand_distr::StandardNormal` (a
//! 256-layer ziggurat using one 64-bit draw per normal, plus rare tail/wedge
//! retries). `f32` normals come from [`fill_normals_f32`], a 128-layer
//! ziggurat of this module that uses one 32-bit word per normal (plus rare
//! retries): half the keystream and no conversion, at `f32` resolution.

use std::sync::OnceLock;

use rand::{Rng, RngCore, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;

/// Each channel owns `2^CHANNEL_SHIFT` 32-bit words of its sample's stream:
/// room for about `2^38` normals, far more than any mesh has vertices.
pub(crate) const CHANNEL_SHIFT: u32 = 40;

/// Largest supported channel count: the word position is a 68-bit number.
pub(crate) const MAX_CHANNELS: usize = 1 << (68 - CHANNEL_SHIFT);

/// The generator for `(seed, sample, channel)`.
pub(crate) fn stream(seed: u64, sample: u64, channel: u64) -> ChaCha8Rng {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    rng.set_stream(sample);
    rng.set_word_pos(u128::from(channel) << CHANNEL_SHIFT);
    rng
}

/// Fills `out` with standard normals from `rng`, in order.
pub(crate) fn fill_normals(rng: &mut ChaCha8Rng, out: &mut [f64]) {
    for x in out {
        *x = rng.sample(StandardNormal);
    }
}

/// Layers of the `f32` ziggurat (7 bits of each word pick one).
const LAYERS: usize = 128;

/// Start of the tail of the 128-layer ziggurat of `exp(-x^2 / 2)`, and the
/// common area of its layers (Marsaglia and Tsang, 2000).
const TAIL_START: f64 = 3.442_619_855_899;
const LAYER_AREA: f64 = 9.912_563_035_262_17e-3;

/// Tables of the `f32` ziggurat, for the density `f(x) = exp(-x^2 / 2)` on
/// `x >= 0`: layer `i` is the strip `f(x_i) <= y < f(x_(i+1))` over
/// `0 <= x < x_i` (`x_1 = r` is where the tail starts, `x_128 = 0`); layer 0
/// is the base strip `0 <= y < f(r)` plus the tail beyond `r`, with the
/// pseudo-width `x_0 = area / f(r)`. All layers have the same area.
struct Ziggurat {
    /// `x_i`, `i = 0 ..= 128`.
    x: [f64; LAYERS + 1],
    /// `f(x_i)`.
    f: [f64; LAYERS + 1],
    /// `x_i / 2^24`: turns a 24-bit integer into a point of layer `i`.
    scale: [f32; LAYERS],
    /// `floor(2^24 x_(i+1) / x_i)`: 24-bit integers below it give a point
    /// under the curve in every case (the fast path).
    accept: [u32; LAYERS],
}

fn density(x: f64) -> f64 {
    (-0.5 * x * x).exp()
}

fn ziggurat() -> &'static Ziggurat {
    static TABLES: OnceLock<Ziggurat> = OnceLock::new();
    TABLES.get_or_init(|| {
        let mut x = [0.0; LAYERS + 1];
        x[0] = LAYER_AREA / density(TAIL_START);
        x[1] = TAIL_START;
        for i in 1..LAYERS - 1 {
            // f(x_(i+1)) = f(x_i) + area / x_i
            x[i + 1] = (-2.0 * (density(x[i]) + LAYER_AREA / x[i]).ln()).sqrt();
        }
        x[LAYERS] = 0.0;
        let f = x.map(density);
        let two24 = f64::from(1u32 << 24);
        let mut scale = [0.0f32; LAYERS];
        let mut accept = [0u32; LAYERS];
        for i in 0..LAYERS {
            scale[i] = (x[i] / two24) as f32;
            accept[i] = (two24 * x[i + 1] / x[i]).floor() as u32;
        }
        Ziggurat {
            x,
            f,
            scale,
            accept,
        }
    })
}

/// A uniform number in `(0, 1)` from one 32-bit word.
fn open_unit(rng: &mut ChaCha8Rng) -> f64 {
    (f64::from(rng.next_u32()) + 0.5) * (1.0 / 4_294_967_296.0)
}

/// One standard normal for a word `w` the fast path rejected (it fell in
/// the wedge of its layer or in the tail); further words come from `extra`.
#[cold]
fn normal_f32_slow(z: &Ziggurat, extra: &mut ChaCha8Rng, mut w: u32) -> f32 {
    loop {
        let i = (w & (LAYERS as u32 - 1)) as usize;
        let negative = w & 0x80 != 0;
        let u = w >> 8;
        let x = f64::from(u) * (z.x[i] / f64::from(1u32 << 24));
        let value = if x < z.x[i + 1] {
            // under the curve (a point the integer threshold rounded away)
            Some(x)
        } else if i == 0 {
            // the tail beyond r (Marsaglia's exponential rejection)
            loop {
                let a = -open_unit(extra).ln() / TAIL_START;
                let b = -open_unit(extra).ln();
                if 2.0 * b > a * a {
                    break Some(TAIL_START + a);
                }
            }
        } else {
            // the wedge: a uniform height in the layer, under f(x) or not
            let y = z.f[i] + open_unit(extra) * (z.f[i + 1] - z.f[i]);
            (y < density(x)).then_some(x)
        };
        if let Some(x) = value {
            let x = x as f32;
            return if negative { -x } else { x };
        }
        w = extra.next_u32();
    }
}

/// Words drawn from the keystream at once by [`fill_normals_f32`].
const WORDS: usize = 128;

/// Fills `out` with standard normals in `f32` for `(seed, sample, channel)`.
///
/// Value `j` is made from word `j` of the channel's window of the stream:
/// bits 0-6 pick a ziggurat layer, bit 7 the sign, bits 8-31 a 24-bit
/// position in the layer, which is the value (`position * x_layer / 2^24`)
/// about 99% of the time. The other ~1% (wedge and tail) take further words
/// from the second half of the channel's window, in order. So value `j`
/// depends only on `(seed, sample, channel, j)` and the values before it, and
/// the common case is a branch-free map over a block of words. Cost: about
/// one keystream word and two table look-ups per value.
pub(crate) fn fill_normals_f32(seed: u64, sample: u64, channel: u64, out: &mut [f32]) {
    let z = ziggurat();
    let mut rng = stream(seed, sample, channel);
    let mut extra: Option<ChaCha8Rng> = None;
    let mut words = [0u32; WORDS];
    for block in out.chunks_mut(WORDS) {
        let words = &mut words[..block.len()];
        rng.fill(words);
        let mut reject = [false; WORDS];
        for ((o, r), &w) in block.iter_mut().zip(reject.iter_mut()).zip(words.iter()) {
            let i = (w & (LAYERS as u32 - 1)) as usize;
            let u = w >> 8;
            // u < 2^24: exact through i32 (a plain vector conversion)
            let x = (u as i32) as f32 * z.scale[i];
            // the sign bit of the word moved to the sign of the float
            *o = f32::from_bits(x.to_bits() | ((w & 0x80) << 24));
            *r = u >= z.accept[i];
        }
        for j in (0..block.len()).filter(|&j| reject[j]) {
            let extra = extra.get_or_insert_with(|| {
                let mut r = stream(seed, sample, channel);
                r.set_word_pos((u128::from(channel) << CHANNEL_SHIFT) + EXTRA_OFFSET);
                r
            });
            block[j] = normal_f32_slow(z, extra, words[j]);
        }
    }
}

/// Where, in a channel's window, the words of the rare `f32` slow path
/// start: the second half (the first holds one word per value).
const EXTRA_OFFSET: u128 = 1 << (CHANNEL_SHIFT - 1);

#[cfg(test)]
mod tests {
    use super::*;

    /// The recursion that builds the layers must close at the peak: the
    /// last layer tops out at `f(0) = 1` (checks the published constants).
    #[test]
    fn ziggurat_layers_close_at_the_peak() {
        let z = ziggurat();
        let top = z.f[LAYERS - 1] + LAYER_AREA / z.x[LAYERS - 1];
        assert!((top - 1.0).abs() < 1e-9, "top of the last layer {top}");
        assert!(z.x.windows(2).all(|w| w[0] > w[1]));
        // base strip plus tail has the layers' area
        assert!((z.x[0] * z.f[1] - LAYER_AREA).abs() < 1e-15);
    }

    /// `Phi(x)` to ~1e-15 by the series `erf` (small `|x|`) or the
    /// continued fraction of `erfc` (large `|x|`).
    fn normal_cdf(x: f64) -> f64 {
        let t = x.abs() / std::f64::consts::SQRT_2;
        let erfc = if t < 2.5 {
            // erf(t) = 2/sqrt(pi) sum (-1)^n t^(2n+1) / (n! (2n+1))
            let (mut term, mut sum, mut n) = (t, t, 0.0);
            while term.abs() > 1e-17 * sum.abs() {
                n += 1.0;
                term *= -t * t / n;
                sum += term / (2.0 * n + 1.0);
            }
            1.0 - 2.0 / std::f64::consts::PI.sqrt() * sum
        } else {
            // erfc(t) = exp(-t^2)/sqrt(pi) / (t + 1/2/(t + 1/(t + 3/2/(t + ...))))
            let mut frac = t;
            for k in (1..60).rev() {
                frac = t + f64::from(k) / 2.0 / frac;
            }
            (-t * t).exp() / std::f64::consts::PI.sqrt() / frac
        };
        if x < 0.0 {
            0.5 * erfc
        } else {
            1.0 - 0.5 * erfc
        }
    }

    #[test]
    fn normal_cdf_matches_known_values() {
        for (x, p) in [
            (0.0, 0.5),
            (1.0, 0.841_344_746_068_542_9),
            (-1.96, 0.024_997_895_148_220_435),
            (3.0, 0.998_650_101_968_369_9),
            (-4.5, 3.397_673_124_730_062e-6),
        ] {
            assert!((normal_cdf(x) - p).abs() < 1e-13, "Phi({x})");
        }
    }

    /// Two million `f32` normals: their empirical CDF is within the
    /// Kolmogorov-Smirnov bound (`1.95 / sqrt(n)`, 0.1% level) of `Phi`, the
    /// tail and the moments match, and the wedge/tail paths were taken.
    #[test]
    fn f32_normals_follow_the_standard_normal_law() {
        let n = 1 << 21;
        let mut v = vec![0.0f32; n];
        fill_normals_f32(5, 2, 1, &mut v);
        let mut sorted: Vec<f64> = v.iter().map(|&x| f64::from(x)).collect();
        sorted.sort_by(f64::total_cmp);
        let nf = n as f64;
        let ks = sorted
            .iter()
            .enumerate()
            .map(|(i, &x)| {
                let p = normal_cdf(x);
                (p - i as f64 / nf)
                    .abs()
                    .max((p - (i + 1) as f64 / nf).abs())
            })
            .fold(0.0, f64::max);
        assert!(ks < 1.95 / nf.sqrt(), "KS distance {ks}");
        let mean = sorted.iter().sum::<f64>() / nf;
        let var = sorted.iter().map(|x| x * x).sum::<f64>() / nf - mean * mean;
        let kurt = sorted.iter().map(|x| x.powi(4)).sum::<f64>() / nf;
        assert!(mean.abs() < 4.0 / nf.sqrt(), "mean {mean}");
        assert!(
            (var - 1.0).abs() < 6.0 * (2.0 / nf).sqrt(),
            "variance {var}"
        );
        assert!(
            (kurt - 3.0).abs() < 6.0 * (96.0 / nf).sqrt(),
            "fourth moment {kurt}"
        );
        // the tail beyond r = 3.44: expected count 2 n (1 - Phi(r)) ~ 1200
        let tail = sorted.iter().filter(|x| x.abs() > TAIL_START).count() as f64;
        let expected = 2.0 * nf * (1.0 - normal_cdf(TAIL_START));
        assert!(
            (tail - expected).abs() < 5.0 * expected.sqrt(),
            "tail {tail} vs {expected}"
        );
        let far = sorted.iter().filter(|x| x.abs() > 4.5).count() as f64;
        let expected = 2.0 * nf * normal_cdf(-4.5);
        assert!(
            (far - expected).abs() < 5.0 * expected.sqrt() + 1.0,
            "far tail {far} vs {expected}"
        );
    }

    #[test]
    fn f32_streams_are_reproducible() {
        let draw = |s, c| {
            let mut v = [0.0f32; 300];
            fill_normals_f32(7, s, c, &mut v);
            v
        };
        assert_eq!(draw(3, 1), draw(3, 1));
        assert_ne!(draw(3, 1), draw(3, 0));
        assert_ne!(draw(3, 1), draw(2, 1));
        // a prefix does not depend on how many values follow
        let mut short = [0.0f32; 17];
        fill_normals_f32(7, 3, 1, &mut short);
        assert_eq!(short[..], draw(3, 1)[..17]);
        // the fast path is exactly the word map, and the slow path runs
        let mut words = [0u32; 300];
        stream(7, 3, 1).fill(&mut words[..]);
        let z = ziggurat();
        let v = draw(3, 1);
        let mut slow = 0;
        for (w, x) in words.iter().zip(v) {
            let (i, u) = ((w & 127) as usize, w >> 8);
            if u < z.accept[i] {
                let sign = if w & 0x80 != 0 { -1.0 } else { 1.0 };
                assert_eq!(x, sign * (u as f32 * z.scale[i]));
            } else {
                slow += 1;
                assert!(x.is_finite() && x.abs() <= 9.0);
            }
        }
        assert!(slow > 0 && slow < 15, "{slow} slow draws of 300");
    }

    #[test]
    fn streams_are_distinct_and_reproducible() {
        let draw = |s, c| {
            let mut v = [0.0; 8];
            fill_normals(&mut stream(7, s, c), &mut v);
            v
        };
        assert_eq!(draw(3, 1), draw(3, 1));
        assert_ne!(draw(3, 1), draw(3, 0));
        assert_ne!(draw(3, 1), draw(4, 1));
        assert_ne!(draw(0, 0), {
            let mut v = [0.0; 8];
            fill_normals(&mut stream(8, 0, 0), &mut v);
            v
        });
    }
}
