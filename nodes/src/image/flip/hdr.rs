//! HDR-FLIP (Andersson et al. 2021): linear renders are exposed over a range of stops, tone mapped
//! (ACES, as in the paper), and compared with LDR-FLIP at every exposure; a pixel's error is its
//! largest over the exposures. The range runs from the exposure that brings the reference's
//! brightest pixel to 0.85 after tone mapping to the one that brings its median luminance there.

use super::color::luminance;
use super::ldr::{flip_map, Rgb};
use rayon::prelude::*;

/// Narkowicz's fit of the ACES filmic curve with FLIP's 0.6 pre-scale:
/// t(x) = (k0·x² + k1·x + k2) / (k3·x² + k4·x + k5).
const ACES: [f64; 6] = [
    0.6 * 0.6 * 2.51,
    0.6 * 0.03,
    0.0,
    0.6 * 0.6 * 2.43,
    0.6 * 0.59,
    0.14,
];

/// Tone-mapped value the exposure range aims for.
const TARGET: f64 = 0.85;

fn tone_map(x: f64) -> f64 {
    let k = ACES;
    ((k[0] * x * x + k[1] * x + k[2]) / (k[3] * x * x + k[4] * x + k[5])).clamp(0.0, 1.0)
}

/// The input that tone-maps to `t`: the positive root of (k0 − t·k3)x² + (k1 − t·k4)x + (k2 − t·k5).
fn tone_map_inverse(t: f64) -> f64 {
    let k = ACES;
    let (a, b, c) = (k[0] - t * k[3], k[1] - t * k[4], k[2] - t * k[5]);
    (-b + (b * b - 4.0 * a * c).sqrt()) / (2.0 * a)
}

/// The exposures (stops) HDR-FLIP evaluates.
#[derive(Clone, Debug, PartialEq)]
pub struct Exposures {
    pub start: f64,
    pub stop: f64,
    pub count: usize,
}

impl Exposures {
    /// From the reference alone. A median luminance of 0 (a render mostly background) is taken
    /// as f32's epsilon, as NVIDIA's implementation does, so the range reaches the darkest lit
    /// pixels. A black reference, which that implementation refuses, gets the single exposure 0.
    ///
    /// With `selected`, only those pixels' luminances set the range: the pixels a mask keeps,
    /// so that a black background does not push the median to 0 and the range to +24 stops,
    /// exposing shadows no viewer of the object would see.
    pub fn from_reference(reference: &Rgb, selected: Option<&[bool]>) -> Exposures {
        let n = reference.width * reference.height;
        let mut lum: Vec<f64> = (0..n)
            .filter(|i| selected.is_none_or(|s| s[*i]))
            .map(|i| luminance([0, 1, 2].map(|c| reference.planes[c][i] as f64)))
            .collect();
        let n = lum.len();
        // The largest and the upper middle by selection: what a sort would put there.
        let hi = lum
            .iter()
            .copied()
            .fold(0.0, |a: f64, b| if b.total_cmp(&a).is_gt() { b } else { a });
        if n == 0 || hi <= 0.0 {
            return Exposures {
                start: 0.0,
                stop: 0.0,
                count: 1,
            };
        }
        // The upper middle element: the median the reference implementation takes.
        let lo = (*lum.select_nth_unstable_by(n / 2, f64::total_cmp).1).max(f32::EPSILON as f64);
        let x = tone_map_inverse(TARGET);
        let start = (x / hi).log2();
        let stop = (x / lo).log2();
        let count = ((stop - start).ceil() as usize).max(2);
        Exposures { start, stop, count }
    }

    pub fn stops(&self) -> Vec<f64> {
        if self.count <= 1 {
            return vec![self.start];
        }
        let step = (self.stop - self.start) / (self.count - 1) as f64;
        (0..self.count)
            .map(|i| self.start + i as f64 * step)
            .collect()
    }
}

fn exposed(img: &Rgb, stops: f64) -> Rgb {
    let gain = stops.exp2();
    Rgb {
        width: img.width,
        height: img.height,
        planes: [0, 1, 2].map(|c| {
            img.planes[c]
                .par_iter()
                .map(|v| tone_map(*v as f64 * gain) as f32)
                .collect()
        }),
    }
}

/// Per-pixel HDR-FLIP error in [0, 1], and the exposures used (from the `selected` pixels of
/// the reference, or all). `progress` is told after each exposure.
pub fn hdr_flip_map(
    reference: &Rgb,
    test: &Rgb,
    ppd: f64,
    selected: Option<&[bool]>,
    mut progress: impl FnMut(usize, usize),
) -> (Vec<f32>, Exposures) {
    let ex = Exposures::from_reference(reference, selected);
    let mut out = vec![0f32; reference.width * reference.height];
    let stops = ex.stops();
    for (k, c) in stops.iter().enumerate() {
        let e = flip_map(&exposed(reference, *c), &exposed(test, *c), ppd);
        for (o, v) in out.iter_mut().zip(e) {
            *o = o.max(v);
        }
        progress(k + 1, stops.len());
    }
    (out, ex)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tone_map_inverse_inverts() {
        let x = tone_map_inverse(TARGET);
        assert!((tone_map(x) - TARGET).abs() < 1e-12);
    }

    #[test]
    fn exposure_range_of_a_two_level_image() {
        // Grey pixels, so luminance = value. Sorted [1, 1, 4, 4]: the upper-middle median (index
        // 2) is 4 like the maximum, so both ends are log2(x/4) and the minimum of two exposures
        // is still taken.
        let img = Rgb {
            width: 4,
            height: 1,
            planes: [0, 1, 2].map(|_| vec![1.0, 4.0, 1.0, 4.0]),
        };
        let ex = Exposures::from_reference(&img, None);
        let x = tone_map_inverse(TARGET);
        assert!((ex.start - (x / 4.0).log2()).abs() < 1e-9);
        assert!((ex.stop - (x / 4.0).log2()).abs() < 1e-9);
        assert_eq!(ex.count, 2);
    }

    #[test]
    fn a_black_reference_gets_one_exposure_and_no_nan() {
        let black = Rgb {
            width: 3,
            height: 3,
            planes: [0, 1, 2].map(|_| vec![0.0; 9]),
        };
        let grey = Rgb {
            width: 3,
            height: 3,
            planes: [0, 1, 2].map(|_| vec![0.5; 9]),
        };
        let (m, ex) = hdr_flip_map(&black, &grey, 67.0, None, |_, _| {});
        assert_eq!(ex.count, 1);
        assert!(m.iter().all(|v| v.is_finite() && *v > 0.0));
    }
}
