//! K-means (Lloyd's iterations from a k-means++ start) over equally long f32 vectors — the
//! per-pixel intensity vectors whose cluster means give the Ward fit its starting points (seed
//! 003 §3). Seeded; assignments run on rayon and centroid sums in pixel order, so the result
//! does not depend on the thread count.

use crate::support::rng;
use rayon::prelude::*;

pub struct Clusters {
    /// k × dims, row-major.
    pub centroids: Vec<f64>,
    /// Per vector, its cluster.
    pub labels: Vec<usize>,
}

fn dist2(a: &[f32], c: &[f64]) -> f64 {
    a.iter()
        .zip(c)
        .map(|(x, y)| (*x as f64 - y) * (*x as f64 - y))
        .sum()
}

/// `vectors` holds n vectors of `dims` values each. k is capped at n.
pub fn kmeans(vectors: &[f32], dims: usize, k: usize, iterations: usize, seed: u64) -> Clusters {
    let n = vectors.len() / dims;
    let k = k.clamp(1, n.max(1));
    let v = |i: usize| &vectors[i * dims..(i + 1) * dims];
    // k-means++: each next centre drawn with probability ∝ squared distance to the chosen ones.
    let first = (rng::unit(rng::hash(seed, &[0])) * n as f64) as usize % n;
    let mut centroids: Vec<f64> = v(first).iter().map(|x| *x as f64).collect();
    let mut near: Vec<f64> = (0..n)
        .into_par_iter()
        .map(|i| dist2(v(i), &centroids))
        .collect();
    for c in 1..k {
        let total: f64 = near.iter().sum();
        let pick = if total > 0.0 {
            let mut target = rng::unit(rng::hash(seed, &[c as u64])) * total;
            let mut chosen = n - 1;
            for (i, d) in near.iter().enumerate() {
                if target < *d {
                    chosen = i;
                    break;
                }
                target -= d;
            }
            chosen
        } else {
            c % n
        };
        let centre: Vec<f64> = v(pick).iter().map(|x| *x as f64).collect();
        near.par_iter_mut().enumerate().for_each(|(i, d)| {
            *d = d.min(dist2(v(i), &centre));
        });
        centroids.extend(centre);
    }
    let mut labels = vec![0; n];
    for _ in 0..iterations.max(1) {
        let next: Vec<usize> = (0..n)
            .into_par_iter()
            .map(|i| {
                (0..k)
                    .map(|c| (dist2(v(i), &centroids[c * dims..(c + 1) * dims]), c))
                    .min_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)))
                    .map_or(0, |m| m.1)
            })
            .collect();
        let changed = next != labels;
        labels = next;
        let mut sums = vec![0.0; k * dims];
        let mut counts = vec![0usize; k];
        for (i, &c) in labels.iter().enumerate() {
            counts[c] += 1;
            for (s, x) in sums[c * dims..(c + 1) * dims].iter_mut().zip(v(i)) {
                *s += *x as f64;
            }
        }
        for c in 0..k {
            // An emptied cluster keeps its centre.
            if counts[c] > 0 {
                for d in 0..dims {
                    centroids[c * dims + d] = sums[c * dims + d] / counts[c] as f64;
                }
            }
        }
        if !changed {
            break;
        }
    }
    Clusters { centroids, labels }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn separates_well_separated_blobs() {
        // Three tight blobs 10 apart in 2-D: every point must land with its own blob, and each
        // centroid on its blob's mean (exact: the blobs' points are symmetric around it).
        let centres = [[0.0f32, 0.0], [10.0, 0.0], [0.0, 10.0]];
        let offsets = [[0.1f32, 0.0], [-0.1, 0.0], [0.0, 0.1], [0.0, -0.1]];
        let mut v = Vec::new();
        for c in &centres {
            for o in &offsets {
                v.extend([c[0] + o[0], c[1] + o[1]]);
            }
        }
        let r = kmeans(&v, 2, 3, 20, 7);
        for (b, centre) in centres.iter().enumerate() {
            let l = r.labels[b * 4];
            assert!(r.labels[b * 4..b * 4 + 4].iter().all(|x| *x == l));
            assert!((r.centroids[l * 2] - centre[0] as f64).abs() < 1e-6);
            assert!((r.centroids[l * 2 + 1] - centre[1] as f64).abs() < 1e-6);
        }
        let mut distinct = r.labels.clone();
        distinct.sort();
        distinct.dedup();
        assert_eq!(distinct.len(), 3);
    }
}
