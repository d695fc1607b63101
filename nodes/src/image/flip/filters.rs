//! FLIP's spatial filters, all separable: the contrast sensitivity functions (sums of Gaussians
//! in visual degrees, one per opponent channel) and the edge and point detectors (first and second
//! derivatives of a Gaussian whose width is that of the human edge detector, 0.082°). Borders are
//! clamped, as in the papers.

use rayon::prelude::*;

/// One channel of an image, row-major.
#[derive(Clone, Debug)]
pub struct Plane {
    pub width: usize,
    pub height: usize,
    pub data: Vec<f32>,
}

/// Convolves with `kx` along rows and `ky` along columns (odd lengths, centred), borders clamped.
/// Each output pixel is summed in a fixed order (tap 0 first, in f64), so the result does not
/// depend on threads. The taps run in the outer loop and the pixels of a row in the inner one, so
/// a row's sums proceed side by side in SIMD lanes, each pixel's in the same order as a loop over
/// its own taps: the same bits.
pub fn separable(p: &Plane, kx: &[f64], ky: &[f64]) -> Plane {
    let (w, h) = (p.width, p.height);
    let rx = kx.len() / 2;
    let ry = (ky.len() / 2) as isize;
    let mut tmp = vec![0f32; w * h];
    tmp.par_chunks_mut(w.max(1))
        .enumerate()
        .for_each(|(y, row)| {
            let src = &p.data[y * w..(y + 1) * w];
            // The row with its borders clamped out to the kernel's reach.
            let pad: Vec<f64> = (0..w + 2 * rx)
                .map(|j| src[(j as isize - rx as isize).clamp(0, w as isize - 1) as usize] as f64)
                .collect();
            let mut acc = vec![0f64; w];
            for (t, k) in kx.iter().enumerate() {
                for (a, v) in acc.iter_mut().zip(&pad[t..t + w]) {
                    *a += k * v;
                }
            }
            for (o, a) in row.iter_mut().zip(&acc) {
                *o = *a as f32;
            }
        });
    let mut data = vec![0f32; w * h];
    data.par_chunks_mut(w.max(1))
        .enumerate()
        .for_each(|(y, row)| {
            let mut acc = vec![0f64; w];
            for (t, k) in ky.iter().enumerate() {
                let sy = (y as isize + t as isize - ry).clamp(0, h as isize - 1) as usize;
                for (a, v) in acc.iter_mut().zip(&tmp[sy * w..(sy + 1) * w]) {
                    *a += k * *v as f64;
                }
            }
            for (o, a) in row.iter_mut().zip(&acc) {
                *o = *a as f32;
            }
        });
    Plane {
        width: w,
        height: h,
        data,
    }
}

/// Opponent channels of YCxCz, each with its contrast sensitivity function.
#[derive(Clone, Copy, Debug)]
pub enum Channel {
    Achromatic,
    RedGreen,
    BlueYellow,
}

impl Channel {
    /// (a1, b1, a2, b2) of S(x) = Σ a·√(π/b)·exp(−π²x²/b), x in degrees (FLIP 2020, Table 1;
    /// fitted to the contrast sensitivity data of Mullen 1985 and Movshon & Kiorpes 1988).
    fn coefficients(self) -> [(f64, f64); 2] {
        match self {
            Channel::Achromatic => [(1.0, 0.0047), (0.0, 1e-5)],
            Channel::RedGreen => [(1.0, 0.0053), (0.0, 1e-5)],
            Channel::BlueYellow => [(34.1, 0.04), (13.5, 0.025)],
        }
    }
}

/// Radius in pixels shared by the three CSF filters: three standard deviations of the widest
/// Gaussian (b = 0.04).
pub fn csf_radius(ppd: f64) -> usize {
    (3.0 * (0.04f64 / (2.0 * std::f64::consts::PI.powi(2))).sqrt() * ppd).ceil() as usize
}

/// Filters one channel with its CSF. The 2-D kernel is a sum of (at most two) separable
/// Gaussians, so it is applied as one separable pass per Gaussian, weighted so that the whole 2-D
/// kernel sums to one.
pub fn csf_filter(p: &Plane, channel: Channel, ppd: f64) -> Plane {
    let r = csf_radius(ppd) as isize;
    let pi2 = std::f64::consts::PI.powi(2);
    let mut terms = Vec::new();
    let mut total = 0f64;
    for (a, b) in channel.coefficients() {
        if a == 0.0 {
            continue;
        }
        let taps: Vec<f64> = (-r..=r)
            .map(|i| {
                let x = i as f64 / ppd;
                (-pi2 * x * x / b).exp()
            })
            .collect();
        let sum: f64 = taps.iter().sum();
        let weight = a * (std::f64::consts::PI / b).sqrt();
        total += weight * sum * sum;
        terms.push((weight, taps));
    }
    let mut out: Option<Plane> = None;
    for (weight, taps) in &terms {
        let scale = weight / total;
        let f = separable(p, taps, taps);
        out = Some(match out {
            None => Plane {
                data: f
                    .data
                    .par_iter()
                    .map(|v| (*v as f64 * scale) as f32)
                    .collect(),
                ..f
            },
            Some(mut acc) => {
                acc.data
                    .par_iter_mut()
                    .zip(&f.data)
                    .for_each(|(o, v)| *o = (*o as f64 + *v as f64 * scale) as f32);
                acc
            }
        });
    }
    out.unwrap_or_else(|| p.clone())
}

/// Which feature a detector responds to.
#[derive(Clone, Copy, Debug)]
pub enum Feature {
    Edge,
    Point,
}

/// The detector's 1-D factors: the derivative along the detection axis (positive weights scaled to
/// sum to 1 and negative ones to −1) and the Gaussian across it (summing to 1). Their outer
/// product is the 2-D detector of the paper with the same normalisation.
pub fn feature_kernels(feature: Feature, ppd: f64) -> (Vec<f64>, Vec<f64>) {
    const EDGE_WIDTH_DEG: f64 = 0.082;
    let sd = 0.5 * EDGE_WIDTH_DEG * ppd;
    let r = (3.0 * sd).ceil() as isize;
    let g: Vec<f64> = (-r..=r)
        .map(|x| (-((x * x) as f64) / (2.0 * sd * sd)).exp())
        .collect();
    let gsum: f64 = g.iter().sum();
    let across: Vec<f64> = g.iter().map(|v| v / gsum).collect();
    let raw: Vec<f64> = (-r..=r)
        .zip(&g)
        .map(|(x, gv)| match feature {
            Feature::Edge => -(x as f64) * gv,
            Feature::Point => ((x * x) as f64 / (sd * sd) - 1.0) * gv,
        })
        .collect();
    let pos: f64 = raw.iter().filter(|v| **v > 0.0).sum();
    let neg: f64 = -raw.iter().filter(|v| **v < 0.0).sum::<f64>();
    let along = raw
        .iter()
        .map(|v| if *v > 0.0 { v / pos } else { v / neg })
        .collect();
    (along, across)
}

/// Magnitude of the feature response (x and y detectors) per pixel.
pub fn feature_magnitude(p: &Plane, feature: Feature, ppd: f64) -> Vec<f32> {
    let (along, across) = feature_kernels(feature, ppd);
    let (fx, fy) = rayon::join(
        || separable(p, &along, &across),
        || separable(p, &across, &along),
    );
    fx.data
        .par_iter()
        .zip(&fy.data)
        .map(|(a, b)| ((*a as f64).powi(2) + (*b as f64).powi(2)).sqrt() as f32)
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn radii_at_the_default_viewing_condition() {
        // At 67.02 ppd the FLIP paper's filters span 3σ: CSF radius ⌈3·√(0.04/2π²)·67.02⌉ = 10,
        // feature radius ⌈3·0.041·67.02⌉ = 9 (worked by hand).
        assert_eq!(csf_radius(67.02), 10);
        assert_eq!(feature_kernels(Feature::Edge, 67.02).0.len(), 19);
    }

    #[test]
    fn filters_keep_a_constant_and_detectors_ignore_it() {
        let p = Plane {
            width: 9,
            height: 7,
            data: vec![0.25; 63],
        };
        for ch in [Channel::Achromatic, Channel::RedGreen, Channel::BlueYellow] {
            let f = csf_filter(&p, ch, 20.0);
            assert!(f.data.iter().all(|v| (v - 0.25).abs() < 1e-6));
        }
        for feat in [Feature::Edge, Feature::Point] {
            assert!(feature_magnitude(&p, feat, 20.0)
                .iter()
                .all(|v| v.abs() < 1e-6));
        }
    }

    #[test]
    fn separable_pass_equals_a_brute_force_2d_convolution() {
        // Independent check: direct 2-D sum with clamped indices.
        let (w, h) = (6usize, 5usize);
        let data: Vec<f32> = (0..w * h).map(|i| ((i * 7919) % 13) as f32).collect();
        let p = Plane {
            width: w,
            height: h,
            data: data.clone(),
        };
        let kx = [0.1, 0.5, 0.4];
        let ky = [0.2, 0.3, 0.1, 0.3, 0.1];
        let f = separable(&p, &kx, &ky);
        for y in 0..h as isize {
            for x in 0..w as isize {
                let mut s = 0f64;
                for (j, b) in ky.iter().enumerate() {
                    for (i, a) in kx.iter().enumerate() {
                        let sx = (x + i as isize - 1).clamp(0, w as isize - 1) as usize;
                        let sy = (y + j as isize - 2).clamp(0, h as isize - 1) as usize;
                        s += a * b * data[sy * w + sx] as f64;
                    }
                }
                assert!((f.data[y as usize * w + x as usize] as f64 - s).abs() < 1e-4);
            }
        }
    }

    #[test]
    fn the_row_at_a_time_pass_is_the_pixel_at_a_time_pass_bit_for_bit() {
        // The loop the filter had before it ran taps outside pixels: the same f64 sums in the
        // same order, so the same bits, borders (a kernel wider than the image) included.
        fn pixel_at_a_time(p: &Plane, kx: &[f64], ky: &[f64]) -> Vec<f32> {
            let (w, h) = (p.width, p.height);
            let (rx, ry) = ((kx.len() / 2) as isize, (ky.len() / 2) as isize);
            let mut tmp = vec![0f32; w * h];
            for y in 0..h {
                for x in 0..w {
                    let mut s = 0f64;
                    for (t, k) in kx.iter().enumerate() {
                        let sx = (x as isize + t as isize - rx).clamp(0, w as isize - 1) as usize;
                        s += k * p.data[y * w + sx] as f64;
                    }
                    tmp[y * w + x] = s as f32;
                }
            }
            let mut out = vec![0f32; w * h];
            for y in 0..h {
                for x in 0..w {
                    let mut s = 0f64;
                    for (t, k) in ky.iter().enumerate() {
                        let sy = (y as isize + t as isize - ry).clamp(0, h as isize - 1) as usize;
                        s += k * tmp[sy * w + x] as f64;
                    }
                    out[y * w + x] = s as f32;
                }
            }
            out
        }
        for (w, h) in [(37usize, 23usize), (5, 3), (1, 1)] {
            let p = Plane {
                width: w,
                height: h,
                data: (0..w * h)
                    .map(|i| ((i * 7919) % 101) as f32 / 37.0)
                    .collect(),
            };
            for feature in [Feature::Edge, Feature::Point] {
                let (along, across) = feature_kernels(feature, 67.0);
                let got = separable(&p, &along, &across).data;
                let want = pixel_at_a_time(&p, &along, &across);
                let same = got
                    .iter()
                    .zip(&want)
                    .all(|(a, b)| a.to_bits() == b.to_bits());
                assert!(same, "{w} × {h} {feature:?}");
            }
        }
    }
}
