//! Rank-r SVD compression of an MDF table (thesis ch. 4 stores the MDF compressed): the
//! views × texels matrix M is approximated by U_r U_rᵀ M, with U_r the leading eigenvectors of
//! M Mᵀ (views × views, small). Storage is r·(views + texels) floats instead of views·texels.

use faer::linalg::matmul::matmul;
use faer::{Accum, Mat, MatRef, Par, Side};

#[derive(Debug)]
pub struct Compressed {
    pub data: Vec<f32>,
    /// RMSE of the reconstruction over all entries, in texels.
    pub rmse: f64,
    /// Full table size over the factors' size.
    pub ratio: f64,
}

/// `data` is views-major (views × texels), all finite.
pub fn compress(
    data: &[f32],
    views: usize,
    texels: usize,
    rank: usize,
) -> Result<Compressed, String> {
    if data.iter().any(|d| !d.is_finite()) {
        return Err(
            "the table has no-hit (+inf) entries, which a linear basis cannot represent".into(),
        );
    }
    let r = rank.min(views).max(1);
    let m64: Vec<f64> = data.iter().map(|v| *v as f64).collect();
    // Row-major views × texels is column-major texels × views: M = Xᵀ.
    let x = MatRef::from_column_major_slice(&m64, texels, views);
    let mut gram = Mat::<f64>::zeros(views, views);
    // Sequential: the same bits whatever the thread count.
    matmul(
        gram.as_mut(),
        Accum::Replace,
        x.transpose(),
        x,
        1.0,
        Par::Seq,
    );
    let evd = gram
        .self_adjoint_eigen(Side::Lower)
        .map_err(|e| format!("eigendecomposition did not converge: {e:?}"))?;
    let eig: Vec<f64> = (0..views).map(|i| evd.S().column_vector()[i]).collect();
    let mut order: Vec<usize> = (0..views).collect();
    order.sort_by(|&a, &b| eig[b].total_cmp(&eig[a]).then(a.cmp(&b)));
    let u = Mat::<f64>::from_fn(views, r, |i, k| evd.U()[(i, order[k])]);
    // Coefficients C = U_rᵀ M (r × texels), i.e. X U_r (texels × r).
    let mut c = Mat::<f64>::zeros(texels, r);
    matmul(c.as_mut(), Accum::Replace, x, u.as_ref(), 1.0, Par::Seq);
    let mut approx = Mat::<f64>::zeros(texels, views);
    matmul(
        approx.as_mut(),
        Accum::Replace,
        c.as_ref(),
        u.transpose(),
        1.0,
        Par::Seq,
    );
    let mut out = vec![0f32; views * texels];
    let mut sq = 0.0;
    for v in 0..views {
        for t in 0..texels {
            let a = approx[(t, v)];
            let e = a - m64[v * texels + t];
            sq += e * e;
            out[v * texels + t] = a as f32;
        }
    }
    Ok(Compressed {
        data: out,
        rmse: (sq / (views * texels).max(1) as f64).sqrt(),
        ratio: (views * texels) as f64 / (r * (views + texels)) as f64,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_rank_two_table_is_exact_at_rank_two_and_not_at_one() {
        // M = a·bᵀ + c·dᵀ with independent factors: rank 2 exactly (closed form).
        let (views, texels) = (5, 40);
        let data: Vec<f32> = (0..views)
            .flat_map(|v| {
                (0..texels).map(move |t| {
                    (v as f32 + 1.0) * (t as f32 * 0.1).sin()
                        + (v as f32 * v as f32) * (t as f32 * 0.05).cos()
                })
            })
            .collect();
        let two = compress(&data, views, texels, 2).unwrap();
        assert!(two.rmse < 1e-5, "{}", two.rmse);
        let one = compress(&data, views, texels, 1).unwrap();
        assert!(one.rmse > 1e-2);
        assert!((two.ratio - 200.0 / 90.0).abs() < 1e-12);
        let mut bad = data.clone();
        bad[3] = f32::INFINITY;
        assert!(compress(&bad, views, texels, 2)
            .unwrap_err()
            .contains("+inf"));
    }
}
