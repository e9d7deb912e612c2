//! Branch-free `f32` transcendental functions for the fused kernels.
//!
//! Written so that loops over channels vectorize (no branches, no calls):
//! Cody-Waite range reduction plus short polynomials (the classic Cephes
//! single-precision coefficients), selects instead of branches. Accuracy
//! (checked against `f64` references in the tests): `exp`, `sin`, `cos`,
//! `log1p` on `[0, 1]` within a few `f32` ulps; `erf` within `1.5e-7`
//! absolute (Abramowitz & Stegun 7.1.26). `sin`/`cos` reduce accurately for
//! `|x| < 8192`.

const LOG2E: f32 = std::f32::consts::LOG2_E;
const LN2_HI: f32 = 0.693_359_4;
const LN2_LO: f32 = -2.121_944_4e-4;

/// `e^x`, clamped to the normal range (`x` in `[-87, 88]`).
#[inline(always)]
pub(crate) fn exp(x: f32) -> f32 {
    let x = x.clamp(-87.0, 88.0);
    let n = (x * LOG2E + 0.5).floor();
    let r = x - n * LN2_HI - n * LN2_LO;
    let p = ((((1.987_569_1e-4 * r + 1.398_199_9e-3) * r + 8.333_452e-3) * r + 4.166_579_6e-2) * r
        + 1.666_666_5e-1)
        * r
        + 0.5;
    let y = p * r * r + r + 1.0;
    // 2^n by building the exponent field (n in [-126, 127])
    let scale = f32::from_bits(integer_bits(n).wrapping_add(127) << 23);
    y * scale
}

/// `1.5 * 2^23`: adding it to an integer-valued `f32` of magnitude below
/// `2^22` leaves that integer in the low mantissa bits.
const ROUND_MAGIC: f32 = 12_582_912.0;

/// The integer-valued `x` (`|x| < 2^22`) as the low bits of a `u32`
/// (two's complement for negative `x`). Unlike `x as i32`, whose saturating
/// semantics compile to a scalar compare-and-select per lane, this is an
/// add and a subtraction, so loops using it stay vectorized.
#[inline(always)]
fn integer_bits(x: f32) -> u32 {
    (x + ROUND_MAGIC)
        .to_bits()
        .wrapping_sub(ROUND_MAGIC.to_bits())
}

/// `ln(1 + y)` for `y` in `[0, 1]`, via `2 atanh(y / (2 + y))`.
#[inline(always)]
pub(crate) fn log1p_unit(y: f32) -> f32 {
    let s = y / (2.0 + y);
    let s2 = s * s;
    // 2 (s + s^3/3 + ... + s^13/13); s <= 1/3
    // constants as products: a division by a literal is not turned into a
    // multiplication (it would change the rounding), and divisions are slow
    const C13: f32 = 1.0 / 13.0;
    const C11: f32 = 1.0 / 11.0;
    const C9: f32 = 1.0 / 9.0;
    const C7: f32 = 1.0 / 7.0;
    const C5: f32 = 1.0 / 5.0;
    const C3: f32 = 1.0 / 3.0;
    let p = ((((((s2 * C13 + C11) * s2 + C9) * s2 + C7) * s2 + C5) * s2 + C3) * s2) * s + s;
    2.0 * p
}

/// `softplus(x) = ln(1 + e^x)`, computed as `max(x, 0) + ln(1 + e^-|x|)`.
#[inline(always)]
pub(crate) fn softplus(x: f32) -> f32 {
    x.max(0.0) + log1p_unit(exp(-x.abs()))
}

/// `1 / (1 + e^-x)`.
#[inline(always)]
pub(crate) fn sigmoid(x: f32) -> f32 {
    1.0 / (1.0 + exp(-x))
}

const FOPI: f32 = 1.273_239_5; // 4 / pi
const DP1: f32 = 0.785_156_25;
const DP2: f32 = 2.418_756_5e-4;
const DP3: f32 = 3.774_895e-8;

/// `(sin x, cos x)`.
#[inline(always)]
pub(crate) fn sincos(x: f32) -> (f32, f32) {
    let ax = x.abs().min(8192.0);
    // ax >= 0, so the floor is the truncation
    let j = integer_bits((ax * FOPI).floor()) as i32;
    let j = (j + 1) & !1;
    let y = j as f32;
    let r = ((ax - y * DP1) - y * DP2) - y * DP3;
    let z = r * r;
    let ps = ((-1.951_529_6e-4 * z + 8.332_161e-3) * z - 1.666_665_5e-1) * z * r + r;
    let pc = ((2.443_315_7e-5 * z - 1.388_731_6e-3) * z + 4.166_664_6e-2) * z * z - 0.5 * z + 1.0;
    let q = j & 6;
    let swap = (q & 2) != 0;
    let neg_s = ((q & 4) >> 2) as f32;
    let neg_c = (((q + 2) & 4) >> 2) as f32;
    let (sb, cb) = if swap { (pc, ps) } else { (ps, pc) };
    let sign_x = if x < 0.0 { -1.0 } else { 1.0 };
    (sb * (1.0 - 2.0 * neg_s) * sign_x, cb * (1.0 - 2.0 * neg_c))
}

const FRAC_1_SQRT_2: f32 = std::f32::consts::FRAC_1_SQRT_2;
/// `1 / sqrt(2 pi)`.
const INV_SQRT_2PI: f32 = 0.398_942_3;

/// `(erf(x / sqrt 2), exp(-x^2 / 2))` (Abramowitz & Stegun 7.1.26).
#[inline(always)]
fn erf_scaled(x: f32) -> (f32, f32) {
    let u = x * FRAC_1_SQRT_2;
    let au = u.abs();
    let t = 1.0 / (1.0 + 0.327_591_1 * au);
    let poly = ((((1.061_405_4 * t - 1.453_152) * t + 1.421_413_8) * t - 0.284_496_74) * t
        + 0.254_829_6)
        * t;
    let e = exp(-u * u);
    let y = 1.0 - poly * e;
    (if u < 0.0 { -y } else { y }, e)
}

/// `GELU(x) = x Phi(x)` (the exact, erf-based GELU).
#[inline(always)]
pub(crate) fn gelu(x: f32) -> f32 {
    let (erf, _) = erf_scaled(x);
    0.5 * x * (1.0 + erf)
}

/// `(GELU(x), GELU'(x))`, `GELU'(x) = Phi(x) + x phi(x)`.
#[inline(always)]
pub(crate) fn gelu_with_grad(x: f32) -> (f32, f32) {
    let (erf, e) = erf_scaled(x);
    let cdf = 0.5 * (1.0 + erf);
    (x * cdf, cdf + x * e * INV_SQRT_2PI)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ulps(a: f32, b: f64) -> f64 {
        ((a as f64) - b).abs() / (b.abs().max(f32::MIN_POSITIVE as f64) * f32::EPSILON as f64)
    }

    #[test]
    fn exp_log1p_softplus_sigmoid_are_accurate() {
        for i in -2000..=2000 {
            let x = i as f32 * 0.043;
            assert!(ulps(exp(x), (x as f64).exp()) < 4.0, "exp({x})");
            let sp = (x as f64).exp().ln_1p();
            assert!(
                ((softplus(x) as f64) - sp).abs() <= 4.0 * f32::EPSILON as f64 * sp.max(1e-30),
                "softplus({x})"
            );
            let sg = 1.0 / (1.0 + (-(x as f64)).exp());
            assert!(
                ((sigmoid(x) as f64) - sg).abs() <= 4.0 * f32::EPSILON as f64 * sg,
                "sigmoid({x})"
            );
        }
        for i in 0..=1000 {
            let y = i as f32 / 1000.0;
            assert!(
                ulps(log1p_unit(y), (y as f64).ln_1p()) < 3.0 || y == 0.0,
                "log1p({y})"
            );
        }
        assert_eq!(log1p_unit(0.0), 0.0);
    }

    #[test]
    fn sincos_is_accurate() {
        for i in -20000..=20000 {
            let x = i as f32 * 0.0137;
            let (s, c) = sincos(x);
            let (sr, cr) = (x as f64).sin_cos();
            assert!(((s as f64) - sr).abs() < 2.5e-7, "sin({x}) = {s} vs {sr}");
            assert!(((c as f64) - cr).abs() < 2.5e-7, "cos({x}) = {c} vs {cr}");
        }
    }

    #[test]
    fn gelu_and_its_derivative_match_torch() {
        let xs: Vec<f64> = (-800..=800).map(|i| i as f64 * 0.01).collect();
        let t = tch::Tensor::from_slice(&xs);
        let reference: Vec<f64> = Vec::try_from(t.gelu("none")).unwrap_or_default();
        let grad: Vec<f64> =
            Vec::try_from(t.gelu_backward(&tch::Tensor::ones_like(&t), "none")).unwrap_or_default();
        assert_eq!(reference.len(), xs.len());
        for ((&x, &r), &d) in xs.iter().zip(&reference).zip(&grad) {
            let (g, dg) = gelu_with_grad(x as f32);
            assert!(
                ((g as f64) - r).abs() < 1e-6 * (1.0 + x.abs()),
                "gelu({x}) = {g} vs {r}"
            );
            assert!(
                ((dg as f64) - d).abs() < 1e-6 * (1.0 + x.abs()),
                "gelu'({x}) = {dg} vs {d}"
            );
            assert_eq!(gelu(x as f32), g);
        }
    }
}
