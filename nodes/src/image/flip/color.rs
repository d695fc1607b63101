//! Colour spaces FLIP works in: linear sRGB primaries ↔ CIE XYZ (D65), the linear opponent space
//! YCxCz (where the contrast sensitivity filters apply) and CIELAB with the Hunt adjustment (where
//! colour differences are measured). White is linear RGB (1, 1, 1).

/// Linear sRGB → XYZ, rows X, Y, Z. The rational entries are the exact sRGB/D65 matrix the FLIP
/// papers use; their rows sum to the D65 white point.
const RGB_TO_XYZ: [[f64; 3]; 3] = [
    [
        10135552.0 / 24577794.0,
        8788810.0 / 24577794.0,
        4435075.0 / 24577794.0,
    ],
    [
        2613072.0 / 12288897.0,
        8788810.0 / 12288897.0,
        887015.0 / 12288897.0,
    ],
    [
        1425312.0 / 73733382.0,
        8788810.0 / 73733382.0,
        70074185.0 / 73733382.0,
    ],
];

// Written out rather than as `[0, 1, 2].map(…)`: these run several times a pixel, and the
// arithmetic (so every bit) is the same.
#[inline]
fn mul(m: &[[f64; 3]; 3], v: [f64; 3]) -> [f64; 3] {
    let row = |r: &[f64; 3]| r[0] * v[0] + r[1] * v[1] + r[2] * v[2];
    [row(&m[0]), row(&m[1]), row(&m[2])]
}

fn xyz_to_rgb_matrix() -> [[f64; 3]; 3] {
    let m = RGB_TO_XYZ;
    let det = m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
        - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
        + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]);
    let c =
        |r0: usize, c0: usize, r1: usize, c1: usize| m[r0][c0] * m[r1][c1] - m[r0][c1] * m[r1][c0];
    [
        [
            c(1, 1, 2, 2) / det,
            -c(0, 1, 2, 2) / det,
            c(0, 1, 1, 2) / det,
        ],
        [
            -c(1, 0, 2, 2) / det,
            c(0, 0, 2, 2) / det,
            -c(0, 0, 1, 2) / det,
        ],
        [
            c(1, 0, 2, 1) / det,
            -c(0, 0, 2, 1) / det,
            c(0, 0, 1, 1) / det,
        ],
    ]
}

/// The conversions, with the white point and inverse matrix computed once.
pub struct Spaces {
    white: [f64; 3],
    xyz_to_rgb: [[f64; 3]; 3],
}

impl Default for Spaces {
    fn default() -> Self {
        Spaces {
            white: mul(&RGB_TO_XYZ, [1.0; 3]),
            xyz_to_rgb: xyz_to_rgb_matrix(),
        }
    }
}

impl Spaces {
    /// Linear RGB → YCxCz: Y' = 116·Y/Yn − 16, Cx = 500·(X/Xn − Y/Yn), Cz = 200·(Y/Yn − Z/Zn).
    /// Unlike CIELAB there is no cube root, so the space is linear and filtering in it is exact.
    #[inline]
    pub fn rgb_to_ycxcz(&self, rgb: [f64; 3]) -> [f64; 3] {
        let xyz = mul(&RGB_TO_XYZ, rgb);
        let (x, y, z) = (
            xyz[0] / self.white[0],
            xyz[1] / self.white[1],
            xyz[2] / self.white[2],
        );
        [116.0 * y - 16.0, 500.0 * (x - y), 200.0 * (y - z)]
    }

    #[inline]
    pub fn ycxcz_to_rgb(&self, c: [f64; 3]) -> [f64; 3] {
        let y = (c[0] + 16.0) / 116.0;
        let x = y + c[1] / 500.0;
        let z = y - c[2] / 200.0;
        mul(
            &self.xyz_to_rgb,
            [x * self.white[0], y * self.white[1], z * self.white[2]],
        )
    }

    /// Linear RGB → CIELAB (D65), then the Hunt adjustment (a and b scaled by L/100: colour
    /// differences shrink as luminance falls).
    #[inline]
    pub fn rgb_to_hunt_lab(&self, rgb: [f64; 3]) -> [f64; 3] {
        let xyz = mul(&RGB_TO_XYZ, rgb);
        const DELTA: f64 = 6.0 / 29.0;
        let f = |t: f64| {
            if t > DELTA * DELTA * DELTA {
                t.cbrt()
            } else {
                t / (3.0 * DELTA * DELTA) + 4.0 / 29.0
            }
        };
        let (fx, fy, fz) = (
            f(xyz[0] / self.white[0]),
            f(xyz[1] / self.white[1]),
            f(xyz[2] / self.white[2]),
        );
        let l = 116.0 * fy - 16.0;
        let a = 500.0 * (fx - fy);
        let b = 200.0 * (fy - fz);
        [l, 0.01 * l * a, 0.01 * l * b]
    }
}

/// HyAB distance: city-block in lightness, Euclidean in chroma (Abasi et al. 2020), which holds
/// up better than ΔE for large differences.
pub fn hyab(a: [f64; 3], b: [f64; 3]) -> f64 {
    (a[0] - b[0]).abs() + ((a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

/// Luminance weights the HDR exposure range is computed from (ITU-R BT.709).
pub fn luminance(rgb: [f64; 3]) -> f64 {
    0.2126 * rgb[0] + 0.7152 * rgb[1] + 0.0722 * rgb[2]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn white_maps_to_the_top_of_both_lightness_scales() {
        // CIE definitions: the white point has Y' = L* = 100 and no chroma.
        let s = Spaces::default();
        let y = s.rgb_to_ycxcz([1.0; 3]);
        let l = s.rgb_to_hunt_lab([1.0; 3]);
        for v in [y, l] {
            assert!((v[0] - 100.0).abs() < 1e-9 && v[1].abs() < 1e-9 && v[2].abs() < 1e-9);
        }
        // sRGB's Y row is the published 0.2126 / 0.7152 / 0.0722 to four decimals.
        assert!((RGB_TO_XYZ[1][0] - 0.2126).abs() < 1e-4);
        assert!((RGB_TO_XYZ[1][1] - 0.7152).abs() < 1e-4);
    }

    #[test]
    fn ycxcz_round_trips() {
        let s = Spaces::default();
        let rgb = [0.3, 0.7, 0.1];
        let back = s.ycxcz_to_rgb(s.rgb_to_ycxcz(rgb));
        for i in 0..3 {
            assert!((back[i] - rgb[i]).abs() < 1e-12);
        }
    }

    #[test]
    fn lab_of_srgb_red_matches_the_published_value() {
        // CIELAB of sRGB red (1,0,0) under D65: L* 53.24, a* 80.09, b* 67.20 (Lindbloom's tables);
        // after the Hunt adjustment a and b are scaled by 0.5324.
        let v = Spaces::default().rgb_to_hunt_lab([1.0, 0.0, 0.0]);
        assert!((v[0] - 53.24).abs() < 0.01, "{v:?}");
        assert!((v[1] - 0.5324 * 80.09).abs() < 0.05, "{v:?}");
        assert!((v[2] - 0.5324 * 67.20).abs() < 0.05, "{v:?}");
    }
}
