//! Seeded, stateless randomness: a value is a pure function of (seed, coordinates), so parallel
//! loops give the same bits whatever the thread count or order.

/// SplitMix64's finaliser (Steele, Lea & Flood 2014): a well-mixed 64-bit hash step.
pub fn mix(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9e37_79b9_7f4a_7c15);
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// Hash of several integers.
pub fn hash(seed: u64, parts: &[u64]) -> u64 {
    parts.iter().fold(mix(seed), |h, &p| mix(h ^ p))
}

/// Uniform in [0, 1) from a hash (53 random bits).
pub fn unit(h: u64) -> f64 {
    (h >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
}

/// SplitMix64 (Steele, Lea & Flood 2014) as a stream.
pub(crate) struct Stream(pub(crate) u64);

impl Stream {
    pub(crate) fn unit(&mut self) -> f64 {
        let v = mix(self.0);
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        unit(v)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn uniform_mean_and_variance() {
        // For U(0,1): mean 1/2, variance 1/12. With n = 100 000 the standard error of the mean is
        // sqrt(1/12/n) ≈ 0.0009, so 0.005 is over 5 standard errors.
        let n = 100_000;
        let xs: Vec<f64> = (0..n).map(|i| unit(hash(7, &[i]))).collect();
        let mean = xs.iter().sum::<f64>() / n as f64;
        let var = xs.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n as f64;
        assert!((mean - 0.5).abs() < 0.005, "{mean}");
        assert!((var - 1.0 / 12.0).abs() < 0.002, "{var}");
        assert_ne!(hash(1, &[2, 3]), hash(1, &[3, 2]));
    }
}
