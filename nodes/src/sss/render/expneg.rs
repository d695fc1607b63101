//! e^x for x ≤ 0, the hot path of the beams' kernels (two per beam point, twelve points, three
//! channels, per term of every gather): glibc's `exp` was a third of a translucent render's time
//! (perf, issue 56). Range reduction x = k·ln 2 + r (|r| ≤ ln 2 / 2, k by the 1.5·2⁵² rounding
//! trick, ln 2 in two parts), e^r by its Taylor polynomial to r¹³ (remainder under 2·10⁻¹⁷ of
//! e^r), 2^k from the exponent bits. Straight-line arithmetic with no call and no branch, so
//! loops over it vectorise. Within 4·10⁻¹⁶ of `f64::exp` relative (two ulps; tested over the range);
//! below −708 (where e^x is under 2⁻¹⁰²² and f64 turns subnormal) it gives e^−708 ≈ 3·10⁻³⁰⁸.

const LOG2E: f64 = std::f64::consts::LOG2_E;
/// ln 2 split so that k·LN2_HI is exact for |k| < 2²⁰.
const LN2_HI: f64 = f64::from_bits(0x3fe6_2e42_fee0_0000);
const LN2_LO: f64 = f64::from_bits(0x3dea_39ef_3579_3c76);
/// 1.5·2⁵²: adding it rounds to an integer held in the low mantissa bits.
const ROUND: f64 = 6_755_399_441_055_744.0;
/// 1/n! for n = 2..=13.
const INV_FACT: [f64; 12] = [
    1.0 / 2.0,
    1.0 / 6.0,
    1.0 / 24.0,
    1.0 / 120.0,
    1.0 / 720.0,
    1.0 / 5_040.0,
    1.0 / 40_320.0,
    1.0 / 362_880.0,
    1.0 / 3_628_800.0,
    1.0 / 39_916_800.0,
    1.0 / 479_001_600.0,
    1.0 / 6_227_020_800.0,
];

/// e^x for x ≤ 0 (a positive x is taken as 0: e⁰ = 1).
#[inline(always)]
pub(super) fn exp_neg(x: f64) -> f64 {
    let x = x.clamp(-708.0, 0.0);
    let t = x * LOG2E + ROUND;
    let k = t - ROUND;
    let r = (x - k * LN2_HI) - k * LN2_LO;
    // Horner from the highest term: 1 + r(1 + r(1/2 + r(1/6 + …))).
    let mut p = INV_FACT[11];
    for &c in INV_FACT[..11].iter().rev() {
        p = p * r + c;
    }
    let p = 1.0 + r * (1.0 + r * p);
    // k ∈ [−1022, 0]: the bits of t hold k + 1.5·2⁵²'s mantissa, whose low 32 bits are k.
    let ki = (t.to_bits() as i64).wrapping_sub(ROUND.to_bits() as i64);
    let scale = f64::from_bits(((ki + 1023) as u64) << 52);
    p * scale
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn within_two_ulps_of_the_library_exp_over_the_range() {
        let mut worst = 0.0f64;
        let mut x = -700.0;
        while x <= 0.0 {
            let (a, b) = (exp_neg(x), x.exp());
            worst = worst.max(((a - b) / b).abs());
            x += 0.000_731;
        }
        for x in [
            0.0,
            -1e-300,
            -1e-12,
            -0.5 * std::f64::consts::LN_2,
            -1.0,
            -745.0,
            -1e9,
        ] {
            let (a, b) = (exp_neg(x), x.exp());
            assert!(a >= 0.0 && a.is_finite(), "{x}: {a}");
            if b > 1e-300 {
                worst = worst.max(((a - b) / b).abs());
            } else {
                assert!(a < 1e-300, "{x}: {a}");
            }
        }
        assert!(worst < 2e-16 * 2.0, "{worst}");
        assert_eq!(exp_neg(3.0), 1.0);
        let floor = (-708f64).exp();
        assert!((exp_neg(f64::NEG_INFINITY) - floor).abs() <= 4e-16 * floor);
    }
}
