//! Branch-free `f32` transcendental functions for the fused kernels.
//!
//! Written so that loops over channels vectorize (no branches, no calls):
//! Cody-Waite range reduction plus short polynomials (the classic Cephes
//! single-precision coefficients), selects instead of branches. Accuracy
//! (checked against `f64` references in the tests): `exp`, `sin`, `cos`,
//! `log1p` on `[0, 1]` within a few `f32` ulps; `erf` within `1.5e-7`
//! absolute (Abramowitz & Stegun 7.1.26). `sin`/`cos` reduce accurately for
//! `|x| < 8192`.
//!
//! Every function is generic over [`MulAdd`]: the AVX2 kernels instantiate
//! them with [`Fused`] (`a * b + c` as one FMA instruction, one rounding:
//! shorter dependency chains in the polynomials), the portable ones with
//! [`Separate`] (a multiplication and an addition, which is what a CPU
//! without FMA can do quickly).

/// How `a * b + c` is evaluated in the polynomials.
pub(crate) trait MulAdd {
    /// `a * b + c`.
    fn mad(a: f32, b: f32, c: f32) -> f32;
}

/// `a * b + c` with one rounding (`f32::mul_add`); only fast where the
/// code is compiled with the `fma` target feature.
#[cfg_attr(not(target_arch = "x86_64"), allow(dead_code))]
pub(crate) struct Fused;

impl MulAdd for Fused {
    #[inline(always)]
    fn mad(a: f32, b: f32, c: f32) -> f32 {
        a.mul_add(b, c)
    }
}

/// `a * b + c` as a multiplication and an addition.
pub(crate) struct Separate;

impl MulAdd for Separate {
    #[inline(always)]
    fn mad(a: f32, b: f32, c: f32) -> f32 {
        a * b + c
    }
}

const LOG2E: f32 = std::f32::consts::LOG2_E;
const LN2_HI: f32 = 0.693_359_4;
const LN2_LO: f32 = -2.121_944_4e-4;

/// `e^x`, clamped to the normal range (`x` in `[-87, 88]`).
#[inline(always)]
pub(crate) fn exp<M: MulAdd>(x: f32) -> f32 {
    let x = x.clamp(-87.0, 88.0);
    let n = M::mad(x, LOG2E, 0.5).floor();
    let r = M::mad(-n, LN2_LO, M::mad(-n, LN2_HI, x));
    let p = M::mad(1.987_569_1e-4, r, 1.398_199_9e-3);
    let p = M::mad(p, r, 8.333_452e-3);
    let p = M::mad(p, r, 4.166_579_6e-2);
    let p = M::mad(p, r, 1.666_666_5e-1);
    let p = M::mad(p, r, 0.5);
    let y = M::mad(p, r * r, r) + 1.0;
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
pub(crate) fn log1p_unit<M: MulAdd>(y: f32) -> f32 {
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
    let p = M::mad(s2, C13, C11);
    let p = M::mad(p, s2, C9);
    let p = M::mad(p, s2, C7);
    let p = M::mad(p, s2, C5);
    let p = M::mad(p, s2, C3);
    2.0 * M::mad(p * s2, s, s)
}

/// `softplus(x) = ln(1 + e^x)`, computed as `max(x, 0) + ln(1 + e^-|x|)`.
#[inline(always)]
pub(crate) fn softplus<M: MulAdd>(x: f32) -> f32 {
    x.max(0.0) + log1p_unit::<M>(exp::<M>(-x.abs()))
}

/// `1 / (1 + e^-x)`.
#[inline(always)]
pub(crate) fn sigmoid<M: MulAdd>(x: f32) -> f32 {
    1.0 / (1.0 + exp::<M>(-x))
}

const FOPI: f32 = 1.273_239_5; // 4 / pi
const DP1: f32 = 0.785_156_25;
const DP2: f32 = 2.418_756_5e-4;
const DP3: f32 = 3.774_895e-8;

/// `(sin x, cos x)`.
#[inline(always)]
pub(crate) fn sincos<M: MulAdd>(x: f32) -> (f32, f32) {
    let ax = x.abs().min(8192.0);
    // ax >= 0, so the floor is the truncation
    let j = integer_bits((ax * FOPI).floor()) as i32;
    let j = (j + 1) & !1;
    let y = j as f32;
    let r = M::mad(-y, DP3, M::mad(-y, DP2, M::mad(-y, DP1, ax)));
    let z = r * r;
    let ps = M::mad(-1.951_529_6e-4, z, 8.332_161e-3);
    let ps = M::mad(ps, z, -1.666_665_5e-1);
    let ps = M::mad(ps * z, r, r);
    let pc = M::mad(2.443_315_7e-5, z, -1.388_731_6e-3);
    let pc = M::mad(pc, z, 4.166_664_6e-2);
    let pc = M::mad(pc * z, z, M::mad(-0.5, z, 1.0));
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
fn erf_scaled<M: MulAdd>(x: f32) -> (f32, f32) {
    let u = x * FRAC_1_SQRT_2;
    let au = u.abs();
    let t = 1.0 / M::mad(0.327_591_1, au, 1.0);
    let poly = M::mad(1.061_405_4, t, -1.453_152);
    let poly = M::mad(poly, t, 1.421_413_8);
    let poly = M::mad(poly, t, -0.284_496_74);
    let poly = M::mad(poly, t, 0.254_829_6);
    let e = exp::<M>(-u * u);
    let y = M::mad(-(poly * t), e, 1.0);
    (if u < 0.0 { -y } else { y }, e)
}

/// `GELU(x) = x Phi(x)` (the exact, erf-based GELU).
#[inline(always)]
pub(crate) fn gelu<M: MulAdd>(x: f32) -> f32 {
    let (erf, _) = erf_scaled::<M>(x);
    0.5 * x * (1.0 + erf)
}

/// `(GELU(x), GELU'(x))`, `GELU'(x) = Phi(x) + x phi(x)`.
#[inline(always)]
pub(crate) fn gelu_with_grad<M: MulAdd>(x: f32) -> (f32, f32) {
    let (erf, e) = erf_scaled::<M>(x);
    let cdf = 0.5 * (1.0 + erf);
    (x * cdf, M::mad(x * e, INV_SQRT_2PI, cdf))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ulps(a: f32, b: f64) -> f64 {
        ((a as f64) - b).abs() / (b.abs().max(f32::MIN_POSITIVE as f64) * f32::EPSILON as f64)
    }

    #[test]
    fn exp_log1p_softplus_sigmoid_are_accurate() {
        accuracy_of_exp_family::<Separate>();
        accuracy_of_exp_family::<Fused>();
    }

    fn accuracy_of_exp_family<M: MulAdd>() {
        for i in -2000..=2000 {
            let x = i as f32 * 0.043;
            assert!(ulps(exp::<M>(x), (x as f64).exp()) < 4.0, "exp({x})");
            let sp = (x as f64).exp().ln_1p();
            assert!(
                ((softplus::<M>(x) as f64) - sp).abs() <= 4.0 * f32::EPSILON as f64 * sp.max(1e-30),
                "softplus({x})"
            );
            let sg = 1.0 / (1.0 + (-(x as f64)).exp());
            assert!(
                ((sigmoid::<M>(x) as f64) - sg).abs() <= 4.0 * f32::EPSILON as f64 * sg,
                "sigmoid({x})"
            );
        }
        for i in 0..=1000 {
            let y = i as f32 / 1000.0;
            assert!(
                ulps(log1p_unit::<M>(y), (y as f64).ln_1p()) < 3.0 || y == 0.0,
                "log1p({y})"
            );
        }
        assert_eq!(log1p_unit::<M>(0.0), 0.0);
    }

    #[test]
    fn sincos_is_accurate() {
        accuracy_of_sincos::<Separate>();
        accuracy_of_sincos::<Fused>();
    }

    fn accuracy_of_sincos<M: MulAdd>() {
        for i in -20000..=20000 {
            let x = i as f32 * 0.0137;
            let (s, c) = sincos::<M>(x);
            let (sr, cr) = (x as f64).sin_cos();
            assert!(((s as f64) - sr).abs() < 2.5e-7, "sin({x}) = {s} vs {sr}");
            assert!(((c as f64) - cr).abs() < 2.5e-7, "cos({x}) = {c} vs {cr}");
        }
    }

    #[test]
    fn gelu_and_its_derivative_match_torch() {
        gelu_matches_torch::<Separate>();
        gelu_matches_torch::<Fused>();
    }

    fn gelu_matches_torch<M: MulAdd>() {
        let xs: Vec<f64> = (-800..=800).map(|i| i as f64 * 0.01).collect();
        let t = tch::Tensor::from_slice(&xs);
        let reference: Vec<f64> = Vec::try_from(t.gelu("none")).unwrap_or_default();
        let grad: Vec<f64> =
            Vec::try_from(t.gelu_backward(&tch::Tensor::ones_like(&t), "none")).unwrap_or_default();
        assert_eq!(reference.len(), xs.len());
        for ((&x, &r), &d) in xs.iter().zip(&reference).zip(&grad) {
            let (g, dg) = gelu_with_grad::<M>(x as f32);
            assert!(
                ((g as f64) - r).abs() < 1e-6 * (1.0 + x.abs()),
                "gelu({x}) = {g} vs {r}"
            );
            assert!(
                ((dg as f64) - d).abs() < 1e-6 * (1.0 + x.abs()),
                "gelu'({x}) = {dg} vs {d}"
            );
            assert_eq!(gelu::<M>(x as f32), g);
        }
    }
}
