//! A parsed file's factors as a `BtfBasis`, without expanding them, and the values of one
//! texel turned back into linear RGB.

use super::*;
use crate::types::{BasisBlock, Centring, ColorSpace};
use crate::types::{BtfBasis, Direction, DirectionPair};

fn pairs(h: &Header) -> Vec<DirectionPair> {
    let dir = |d: &[f32; 2]| Direction {
        theta: d[0] as f64,
        phi: d[1] as f64,
    };
    h.views
        .iter()
        .flat_map(|v| {
            h.lights.iter().map(move |l| DirectionPair {
                view: dir(v),
                light: dir(l),
            })
        })
        .collect()
}

/// The factors as a `BtfBasis` in the file's own channel space (labelled RGB, or YCbCr for a YUV
/// DFMF, whose U and V are rescaled to Cb and Cr), texels re-ordered row-major. With
/// `with_cosine`, when the file leaves the cosine out each column is multiplied by cos θi
/// (mesoflow's values include it; blocks with a per-texel mean cannot take it, see `nonlinear`).
/// The caller decides whether the space is really RGB (`nonlinear`).
pub fn to_basis(f: &Ubo2014, with_cosine: bool) -> BtfBasis {
    let h = &f.header;
    let (w, ht, nl) = (h.width, h.height, h.lights.len());
    let t = w * ht;
    let pairs = pairs(h);
    let n = pairs.len();
    // Row-major texel i = y·w + x is the file's y + h·x.
    let file_texel = |i: usize| (i / w) + ht * (i % w);
    let cosine: Vec<f32> = pairs
        .iter()
        .map(|p| {
            if h.cosine_in_data || !with_cosine {
                1.0
            } else {
                p.light.theta.cos() as f32
            }
        })
        .collect();
    let mut color = ColorSpace::Rgb;
    let mut blocks = Vec::new();
    // A block over all pairs: maps from a texel-indexed matrix, basis from an angle-indexed one.
    let block = |channel: Option<u8>,
                 texel_of: &dyn Fn(usize, usize) -> f32,
                 angle_of: &dyn Fn(usize, usize) -> f32,
                 s: &[f32],
                 cols: usize,
                 first_pair: usize,
                 pair_count: usize,
                 mean: Vec<f32>,
                 centring: Centring,
                 scale: f32| {
        let k = s.len();
        let maps = (0..k)
            .flat_map(|kk| (0..t).map(move |i| texel_of(file_texel(i), kk)))
            .collect();
        let basis = (0..k)
            .flat_map(|kk| (0..cols).map(move |j| angle_of(j, kk) * scale))
            .collect::<Vec<f32>>();
        BasisBlock {
            first_pair,
            pair_count,
            channel,
            centring,
            mean,
            maps,
            basis,
            singular: s.to_vec(),
        }
    };
    match &f.payload {
        Payload::Fmf { factor: fa, .. } => {
            let k = fa.k();
            if fa.cols == t {
                // U: (c + 3·pair) × k — exactly the block's column order j = 3·pair + c.
                let mut b = block(
                    None,
                    &|x, kk| fa.sxv[x * k + kk],
                    &|j, kk| fa.u[j * k + kk],
                    &fa.s,
                    3 * n,
                    0,
                    n,
                    vec![0.0; 3 * n],
                    Centring::Columns,
                    1.0,
                );
                scale_columns(&mut b, &cosine, 3);
                blocks.push(b);
            } else {
                for ch in 0..3 {
                    let mut b = block(
                        Some(ch as u8),
                        &|x, kk| fa.u[(ch + 3 * x) * k + kk],
                        &|j, kk| fa.sxv[j * k + kk],
                        &fa.s,
                        n,
                        0,
                        n,
                        vec![0.0; n],
                        Centring::Columns,
                        1.0,
                    );
                    scale_columns(&mut b, &cosine, 1);
                    blocks.push(b);
                }
            }
        }
        Payload::Dfmf {
            color_model,
            channels,
            ..
        } => {
            // YUV's U and V are multiples of Cb and Cr: B − Y = 2.03211·U = 1.772·Cb and
            // R − Y = 1.13983·V = 1.402·Cr.
            let yuv = *color_model == 1;
            if yuv {
                color = ColorSpace::YCbCr;
            }
            for (ch, fa) in channels.iter().enumerate() {
                let k = fa.k();
                let scale = match (yuv, ch) {
                    (true, 1) => (2.03211 / 1.772) as f32,
                    (true, 2) => (1.13983 / 1.402) as f32,
                    _ => 1.0,
                };
                let mut b = if fa.cols == t {
                    block(
                        Some(ch as u8),
                        &|x, kk| fa.sxv[x * k + kk],
                        &|j, kk| fa.u[j * k + kk],
                        &fa.s,
                        n,
                        0,
                        n,
                        vec![0.0; n],
                        Centring::Columns,
                        scale,
                    )
                } else {
                    block(
                        Some(ch as u8),
                        &|x, kk| fa.u[x * k + kk],
                        &|j, kk| fa.sxv[j * k + kk],
                        &fa.s,
                        n,
                        0,
                        n,
                        vec![0.0; n],
                        Centring::Columns,
                        scale,
                    )
                };
                scale_columns(&mut b, &cosine, 1);
                blocks.push(b);
            }
        }
        Payload::Pvf { slots } => {
            for (v, s) in slots.iter().enumerate() {
                let k = s.ev.len();
                let first = v * nl;
                if s.weights == t {
                    // Light field: C is (c + 3·l) × k, the block's column order; W is texels × k.
                    let mean = s.mean.clone();
                    let mut b = block(
                        None,
                        &|x, kk| s.w[x * k + kk],
                        &|j, kk| s.c[j * k + kk],
                        &s.ev,
                        3 * nl,
                        first,
                        nl,
                        mean,
                        Centring::Columns,
                        1.0,
                    );
                    scale_columns(&mut b, &cosine[first..first + nl], 3);
                    b.singular = s.ev.clone();
                    blocks.push(b);
                } else {
                    for ch in 0..3 {
                        let mean = (0..t).map(|i| s.mean[ch + 3 * file_texel(i)]).collect();
                        let b = block(
                            Some(ch as u8),
                            &|x, kk| s.c[(ch + 3 * x) * k + kk],
                            &|j, kk| s.w[j * k + kk],
                            &s.ev,
                            nl,
                            first,
                            nl,
                            mean,
                            Centring::Texels,
                            1.0,
                        );
                        blocks.push(b);
                    }
                }
            }
        }
    }
    BtfBasis {
        width: w,
        height: ht,
        pairs,
        color,
        blocks,
    }
}

/// Multiplies a block's columns (and a per-column mean) by the cosine of their pair.
fn scale_columns(b: &mut BasisBlock, cosine: &[f32], channels: usize) {
    if cosine.iter().all(|c| *c == 1.0) {
        return;
    }
    let cols = b.cols();
    for (j, m) in b.mean.iter_mut().enumerate().take(cols) {
        *m *= cosine[j / channels];
    }
    for kk in 0..b.rank() {
        for j in 0..cols {
            b.basis[kk * cols + j] *= cosine[j / channels];
        }
    }
}

/// The non-linear steps after the factors' product, per texel value triple in the file's channel
/// space: dynamic-range restoration and the DFMF colour models btflib defines.
pub fn finish_values(f: &Ubo2014, v: [f64; 3]) -> Result<[f64; 3], String> {
    let yuv = |[y, u, w]: [f64; 3]| {
        [
            y + 1.13983 * w,
            y - 0.39465 * u - 0.5806 * w,
            y + 2.03211 * u,
        ]
    };
    match &f.payload {
        Payload::Fmf { dynamic_range, .. } => Ok(if *dynamic_range != 0 {
            v.map(|x| x.exp() - DRR_EPS)
        } else {
            v
        }),
        Payload::Pvf { .. } => Ok(v),
        Payload::Dfmf {
            color_model,
            color_mean,
            color_matrix: m,
            ..
        } => match color_model {
            0 | 1 => Ok(v),
            3 => {
                let m = m.map(|x| x as f64);
                Ok([0, 1, 2].map(|c| {
                    v[0] * m[c] + v[1] * m[3 + c] + v[2] * m[6 + c] + color_mean[c] as f64
                }))
            }
            4 => Ok([v[0] + v[1] - v[2], v[0] + v[2], v[0] - v[1] - v[2]]),
            9 => Ok(yuv([v[0].exp() - DRR_EPS, v[1], v[2]])),
            10 => {
                let lg = |x: f64| x.signum() * (x.abs() + DRR_EPS.ln()).exp();
                Ok(yuv([v[0].exp() - DRR_EPS, lg(v[1]), lg(v[2])]))
            }
            11 => {
                let y = v[0].exp() - DRR_EPS;
                Ok(yuv([y, v[1] * (y + DRR_EPS), v[2] * (y + DRR_EPS)]))
            }
            12 => Ok(v.map(|x| x.exp() - DRR_EPS)),
            m => Err(format!(
                "colour model {m} ({}) is not supported",
                color_model_name(*m)
            )),
        },
    }
}
