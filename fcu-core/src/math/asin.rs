//! The arcsine of an f32 in single precision only, bit for bit `libm::asinf`.
//!
//! libm's `asinf` evaluates its result for 0.5 ≤ |x| < 1 in double precision:
//! `π/2 − 2·(s + s·r(z))` with `z = (1 − |x|)/2` and `s = √z` as doubles. The Cortex-M4's FPU
//! is single precision only, so that one expression brings the library's double add, multiply,
//! conversions and square root (about 2.4 KB) into a firmware that computes nothing else in
//! double. Here the same expression is carried as pairs of f32 (error-free sums and products,
//! about 48 bits), and the final rounding to f32 is decided exactly, with the last, tiny terms
//! breaking what would otherwise look like a tie. A test compares every f32 in that range (16.8
//! million values) with libm's result: all are equal. Elsewhere the computation is libm's own,
//! in f32 as there.
//!
//! The rational approximation `r` and its coefficients are FreeBSD's (msun `e_asinf.c`, which
//! libm ports), under this notice: "Copyright (C) 1993 by Sun Microsystems, Inc. All rights
//! reserved. Developed at SunPro, a Sun Microsystems, Inc. business. Permission to use, copy,
//! modify, and distribute this software is freely granted, provided that this notice is
//! preserved."

/// π/2 as the double libm uses (the double nearest π/2), as three f32 whose sum is that double
/// exactly (each step takes 24 of its 53 bits; the remainders are exact by Sterbenz's lemma).
const FRAC_PI_2: f64 = core::f64::consts::FRAC_PI_2;
const FRAC_PI_2_HI: f32 = FRAC_PI_2 as f32;
const FRAC_PI_2_MID: f32 = (FRAC_PI_2 - FRAC_PI_2_HI as f64) as f32;
const FRAC_PI_2_LO: f32 = (FRAC_PI_2 - FRAC_PI_2_HI as f64 - FRAC_PI_2_MID as f64) as f32;

/// The coefficients of `r(z) ≈ (asin(√z) − √z)/√z`, a rational function of degree (3, 1).
const P_S0: f32 = 1.666_658_7e-1;
const P_S1: f32 = -4.274_342_2e-2;
const P_S2: f32 = -8.656_363e-3;
const Q_S1: f32 = -7.066_296_3e-1;

fn r(z: f32) -> f32 {
    let p = z * (P_S0 + z * (P_S1 + z * P_S2));
    let q = 1.0 + z * Q_S1;
    p / q
}

/// Arcsine, rad, equal to `libm::asinf(x)` for every `x` (NaN for |x| > 1 and NaN).
pub fn asinf(x: f32) -> f32 {
    let ix = x.to_bits() & 0x7fff_ffff;
    if ix >= 0x3f80_0000 {
        // ±1 gives libm's double π/2 rounded to f32; beyond, no angle.
        return match (ix == 0x3f80_0000, x < 0.0) {
            (true, false) => FRAC_PI_2_HI,
            (true, true) => -FRAC_PI_2_HI,
            (false, _) => f32::NAN,
        };
    }
    if ix < 0x3f00_0000 {
        // |x| < 0.5: f32 in libm too; below 2^−12 (and above the subnormals) x itself.
        if (0x0080_0000..0x3980_0000).contains(&ix) {
            return x;
        }
        return x + x * r(x * x);
    }
    let y = half_to_one(x.abs());
    if x < 0.0 {
        -y
    } else {
        y
    }
}

/// `π/2 − 2·(s + s·r(z))` for 0.5 ≤ a < 1, rounded to f32 as libm's double expression is.
fn half_to_one(a: f32) -> f32 {
    // Exact: 1 − a by Sterbenz's lemma, the halving by a power of two.
    let z = (1.0 - a) * 0.5;
    let rz = r(z);
    // √z as s_hi + s_lo: the f32 root and one Newton correction from its residual z − s_hi²
    // (z − sq is exact by Sterbenz's lemma, sq_err is the product's exact error).
    let s_hi = libm::sqrtf(z);
    let (sq, sq_err) = two_prod(s_hi, s_hi);
    let s_lo = ((z - sq) - sq_err) / (2.0 * s_hi);
    // t = s + s·r.
    let (m_hi, m_err) = two_prod(s_hi, rz);
    let m_lo = m_err + s_lo * rz;
    let (t_hi, t_err) = two_sum(s_hi, m_hi);
    let t_lo = t_err + (s_lo + m_lo);
    // π/2 − 2t as head + residual + tail, the head and residual an exact split of their sum.
    let (a_hi, a_err) = two_sum(FRAC_PI_2_HI, -2.0 * t_hi);
    let (b_hi, b_err) = two_sum(FRAC_PI_2_MID, -2.0 * t_lo);
    let (c_hi, c_err) = two_sum(a_err, b_hi);
    let (head, residual) = two_sum(a_hi, c_hi);
    let tail = (c_err + b_err) + FRAC_PI_2_LO;
    round_sum(head, residual, tail)
}

/// `head + residual + tail` rounded to the nearest f32 (ties to even), for a positive `head`
/// that is `head + residual` rounded (so |residual| is at most half an ulp) and a `tail` far
/// below an ulp: `tail` only decides when `residual` leaves the sum at or next to a midpoint,
/// and the comparison with the midpoint is exact (Sterbenz again).
fn round_sum(head: f32, residual: f32, tail: f32) -> f32 {
    let up = f32::from_bits(head.to_bits() + 1);
    let down = f32::from_bits(head.to_bits() - 1);
    let odd = head.to_bits() & 1 == 1;
    if residual > 0.0 || (residual == 0.0 && tail > 0.0) {
        let gap = (up - head) * 0.5 - residual;
        if tail > gap || (tail == gap && odd) {
            return up;
        }
    } else if residual < 0.0 || (residual == 0.0 && tail < 0.0) {
        let gap = (head - down) * 0.5 + residual;
        if -tail > gap || (-tail == gap && odd) {
            return down;
        }
    }
    head
}

/// `a + b` rounded and its rounding error, exactly (Knuth's two-sum).
fn two_sum(a: f32, b: f32) -> (f32, f32) {
    let s = a + b;
    let b_part = s - a;
    let a_part = s - b_part;
    (s, (a - a_part) + (b - b_part))
}

/// `a · b` rounded and its rounding error, exactly (Dekker's product: no fused multiply-add in
/// `core`, and libm's is in software).
fn two_prod(a: f32, b: f32) -> (f32, f32) {
    let p = a * b;
    let (a_hi, a_lo) = split(a);
    let (b_hi, b_lo) = split(b);
    (p, ((a_hi * b_hi - p) + a_hi * b_lo + a_lo * b_hi) + a_lo * b_lo)
}

/// Veltkamp's split of an f32 into two halves of 12 significant bits, whose products are exact.
fn split(a: f32) -> (f32, f32) {
    let c = 4097.0 * a;
    let hi = c - (c - a);
    (hi, a - hi)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn same(x: f32) -> bool {
        let (ours, libm) = (asinf(x), libm::asinf(x));
        ours.to_bits() == libm.to_bits() || (ours.is_nan() && libm.is_nan())
    }

    #[test]
    fn equals_libm_for_every_f32_from_a_half_to_one() {
        let mut differ = (0usize, None);
        for bits in (0x3f00_0000u32..0x3f80_0000).flat_map(|bits| [bits, bits | 0x8000_0000]) {
            if !same(f32::from_bits(bits)) {
                differ = (differ.0 + 1, differ.1.or(Some(bits)));
            }
        }
        assert_eq!(differ, (0, None), "(how many differ, the first one's bits)");
    }

    #[test]
    fn equals_libm_below_a_half_and_at_the_edges() {
        // Below 0.5 both are the same f32 expressions: every 61st bit pattern, both signs.
        for bits in (0..0x3f00_0000u32).step_by(61).chain([0, 1, 0x007f_ffff, 0x0080_0000, 0x397f_ffff, 0x3980_0000, 0x3eff_ffff]) {
            for x in [f32::from_bits(bits), -f32::from_bits(bits)] {
                assert!(same(x), "{x:e}");
            }
        }
        for x in [1.0, -1.0, 1.000_000_1, -2.0, f32::INFINITY, f32::NEG_INFINITY, f32::NAN] {
            assert!(same(x), "{x:e}");
        }
    }

    #[test]
    fn the_three_parts_of_pi_over_2_sum_to_libms_double() {
        assert_eq!(f64::from(FRAC_PI_2_HI) + f64::from(FRAC_PI_2_MID) + f64::from(FRAC_PI_2_LO), FRAC_PI_2);
        assert_eq!(FRAC_PI_2_HI, core::f32::consts::FRAC_PI_2);
    }
}
