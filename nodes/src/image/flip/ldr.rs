//! LDR-FLIP (Andersson et al. 2020): the per-pixel perceived difference between two display
//! images seen at `ppd` pixels per degree. A colour pipeline (CSF filtering in YCxCz, Hunt-adjusted
//! CIELAB, HyAB distance, compressed to [0, 1]) is raised to a power set by a feature pipeline
//! (edges and points present in one image and not the other).

use super::color::{hyab, Spaces};
use super::filters::{csf_filter, feature_magnitude, Channel, Feature, Plane};
use rayon::prelude::*;

/// Exponents and error redistribution of the paper: qc, qf, pc, pt.
const QC: f64 = 0.7;
const QF: f64 = 0.5;
const _: () = assert!(QF == 0.5, "the feature exponent is taken as a square root");
const PC: f64 = 0.4;
const PT: f64 = 0.95;

/// A linear RGB image as three planes, values already in [0, 1].
pub struct Rgb {
    pub width: usize,
    pub height: usize,
    pub planes: [Vec<f32>; 3],
}

impl Rgb {
    fn pixel(&self, i: usize) -> [f64; 3] {
        let p = &self.planes;
        [p[0][i] as f64, p[1][i] as f64, p[2][i] as f64]
    }
}

/// Per-pixel LDR-FLIP error in [0, 1].
pub fn flip_map(reference: &Rgb, test: &Rgb, ppd: f64) -> Vec<f32> {
    let spaces = Spaces::default();
    let n = reference.width * reference.height;
    let cmax = max_colour_difference(&spaces);

    let prepare = |img: &Rgb| -> ([Plane; 3], Vec<f32>, Vec<f32>) {
        let opponent: Vec<[f64; 3]> = (0..n)
            .into_par_iter()
            .map(|i| spaces.rgb_to_ycxcz(img.pixel(i)))
            .collect();
        let ycc: [Vec<f32>; 3] =
            [0, 1, 2].map(|c| opponent.par_iter().map(|v| v[c] as f32).collect());
        let plane = |data: Vec<f32>| Plane {
            width: img.width,
            height: img.height,
            data,
        };
        // The feature pipeline sees the unfiltered luminance, normalised to [0, 1].
        let lum = plane(ycc[0].par_iter().map(|y| (y + 16.0) / 116.0).collect());
        let [y, cx, cz] = ycc;
        // The three channels' filters and the two detectors side by side: each is a fixed
        // sequence of sums, so running them at once changes no bit.
        let ((a, b), (c, (edges, points))) = rayon::join(
            || {
                rayon::join(
                    || csf_filter(&plane(y), Channel::Achromatic, ppd),
                    || csf_filter(&plane(cx), Channel::RedGreen, ppd),
                )
            },
            || {
                rayon::join(
                    || csf_filter(&plane(cz), Channel::BlueYellow, ppd),
                    || {
                        rayon::join(
                            || feature_magnitude(&lum, Feature::Edge, ppd),
                            || feature_magnitude(&lum, Feature::Point, ppd),
                        )
                    },
                )
            },
        );
        ([a, b, c], edges, points)
    };
    let ((rf, re, rp), (tf, te, tp)) = rayon::join(|| prepare(reference), || prepare(test));
    let edges = (re, te);
    let points = (rp, tp);

    let lab = |f: &[Plane; 3], i: usize| {
        let c = [
            f[0].data[i] as f64,
            f[1].data[i] as f64,
            f[2].data[i] as f64,
        ];
        let [r, g, b] = spaces.ycxcz_to_rgb(c);
        spaces.rgb_to_hunt_lab([r.clamp(0.0, 1.0), g.clamp(0.0, 1.0), b.clamp(0.0, 1.0)])
    };
    (0..n)
        .into_par_iter()
        .map(|i| {
            let colour = redistribute(hyab(lab(&rf, i), lab(&tf, i)).powf(QC), cmax);
            let feature =
                ((edges.0[i] - edges.1[i]).abs()).max((points.0[i] - points.1[i]).abs()) as f64;
            // QF is ½: the square root (correctly rounded, as pow's ½ is to within an ulp).
            let feature = (feature / std::f64::consts::SQRT_2).sqrt();
            colour.powf(1.0 - feature) as f32
        })
        .collect()
}

/// The largest colour difference FLIP expects: pure green against pure blue, Hunt-adjusted.
fn max_colour_difference(s: &Spaces) -> f64 {
    hyab(
        s.rgb_to_hunt_lab([0.0, 1.0, 0.0]),
        s.rgb_to_hunt_lab([0.0, 0.0, 1.0]),
    )
    .powf(QC)
}

/// Maps [0, pc·cmax) onto [0, pt) and the rest onto [pt, 1]: small differences get most of the
/// range, where they are told apart.
fn redistribute(e: f64, cmax: f64) -> f64 {
    let knee = PC * cmax;
    if e < knee {
        PT / knee * e
    } else {
        PT + (e - knee) / (cmax - knee) * (1.0 - PT)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn flat(w: usize, h: usize, rgb: [f32; 3]) -> Rgb {
        Rgb {
            width: w,
            height: h,
            planes: rgb.map(|v| vec![v; w * h]),
        }
    }

    #[test]
    fn identical_images_have_no_error() {
        let a = flat(8, 8, [0.2, 0.5, 0.9]);
        assert!(flip_map(&a, &a, 67.0).iter().all(|v| *v == 0.0));
    }

    #[test]
    fn green_against_blue_is_the_largest_error() {
        // FLIP's scale is defined so that flat green vs flat blue scores exactly 1 (no features).
        let e = flip_map(
            &flat(16, 16, [0.0, 1.0, 0.0]),
            &flat(16, 16, [0.0, 0.0, 1.0]),
            67.0,
        );
        assert!(e.iter().all(|v| (v - 1.0).abs() < 1e-5), "{}", e[0]);
    }
}
