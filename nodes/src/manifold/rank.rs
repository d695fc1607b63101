//! Spearman's rank correlation, the measure of how well a recovered ordering (a weathering
//! degree, an embedding coordinate) follows the true one. Ties get their average rank and the
//! coefficient is Pearson's on the ranks, so clamped data (many equal values) is handled.

/// Average ranks (0-based) of `v`.
fn ranks(v: &[f64]) -> Vec<f64> {
    let mut idx: Vec<usize> = (0..v.len()).collect();
    idx.sort_by(|&i, &j| v[i].total_cmp(&v[j]).then(i.cmp(&j)));
    let mut r = vec![0.0; v.len()];
    let mut start = 0;
    while start < idx.len() {
        let mut end = start + 1;
        while end < idx.len() && v[idx[end]] == v[idx[start]] {
            end += 1;
        }
        let average = (start + end - 1) as f64 / 2.0;
        for &i in &idx[start..end] {
            r[i] = average;
        }
        start = end;
    }
    r
}

/// Spearman's ρ of two equally long samples; 0 when either is constant.
pub fn spearman(a: &[f64], b: &[f64]) -> f64 {
    let (ra, rb) = (ranks(a), ranks(b));
    let n = a.len() as f64;
    let (ma, mb) = (ra.iter().sum::<f64>() / n, rb.iter().sum::<f64>() / n);
    let (mut sab, mut saa, mut sbb) = (0.0, 0.0, 0.0);
    for (x, y) in ra.iter().zip(&rb) {
        sab += (x - ma) * (y - mb);
        saa += (x - ma) * (x - ma);
        sbb += (y - mb) * (y - mb);
    }
    if saa <= 0.0 || sbb <= 0.0 {
        return 0.0;
    }
    sab / (saa * sbb).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn textbook_values() {
        // Without ties ρ = 1 − 6Σd²/(n(n²−1)): for ranks (1,2,3,4,5) vs (2,1,4,3,5), Σd² = 4,
        // ρ = 1 − 24/120 = 0.8. With ties, scipy.stats.spearmanr([1,2,2,3],[1,2,3,4]) =
        // 0.9486832980505138 (√0.9).
        assert!((spearman(&[1., 2., 3., 4., 5.], &[2., 1., 4., 3., 5.]) - 0.8).abs() < 1e-12);
        assert!((spearman(&[1., 2., 2., 3.], &[1., 2., 3., 4.]) - 0.9_f64.sqrt()).abs() < 1e-12);
        assert!((spearman(&[3., 2., 1.], &[1., 2., 3.]) + 1.0).abs() < 1e-12);
        assert_eq!(spearman(&[1., 1., 1.], &[1., 2., 3.]), 0.0);
    }
}
