//! e^(−x) for the score's sum: exact to about 1e-15 relative, inline and
//! branch-free.

use squall_core::geometry::{Real, round_small};

/// 2^(−j/16) for j = 0..16.
const EXP2_SIXTEENTHS: [Real; 16] = [
    1.0,
    0.957_603_280_698_573_7,
    0.917_004_043_204_671_2,
    0.878_126_080_186_649_7,
    0.840_896_415_253_714_5,
    0.805_245_165_974_627_1,
    0.771_105_412_703_970_4,
    0.738_413_072_969_749_7,
    std::f64::consts::FRAC_1_SQRT_2,
    0.677_127_773_468_446_3,
    0.648_419_777_325_504_8,
    0.620_928_906_036_742,
    0.594_603_557_501_360_5,
    0.569_394_317_378_345_8,
    0.545_253_866_332_628_8,
    0.522_136_891_213_706_9,
];

/// e^(−x) for x ≥ 0 to about 1e-15 relative, 0 from 700 on; inline and
/// branch-free, so that a loop of them runs at the processor's throughput
/// (the score takes one per matched beam, and a libm call there cost a
/// tenth of the run).
#[inline(always)]
pub(super) fn exp_neg(x: Real) -> Real {
    let clamped = x.min(700.0);
    // e^(−x) = 2^(−n/16) · e^(−r), n = round(16 x / ln 2), |r| ≤ ln 2 / 32.
    let (rounded, n) = round_small(clamped * (16.0 * std::f64::consts::LOG2_E));
    let t = rounded * (std::f64::consts::LN_2 / 16.0) - clamped;
    let p = 1.0
        + t * (1.0 + t * (0.5 + t * (1.0 / 6.0 + t * (1.0 / 24.0 + t * (1.0 / 120.0 + t * (1.0 / 720.0))))));
    let v = p * EXP2_SIXTEENTHS[(n & 15) as usize] * Real::from_bits(((1023 - (n >> 4)) as u64) << 52);
    if x < 700.0 { v } else { 0.0 }
}
