//! Bilinear, periodic interpolation of per-texel values on a tile: what the synthetic capture
//! and the relief renderer both read between texel centres (grid point (x, y) is texel (x, y)'s
//! centre, x right, y down the image).

/// The values at grid point (x, y) of a `w`×`h` periodic tile, `at(texel index)` giving a
/// texel's K values.
pub fn bilerp<T: Copy + Into<f64>, const K: usize>(
    w: usize,
    h: usize,
    x: f64,
    y: f64,
    at: impl Fn(usize) -> [T; K],
) -> [f64; K] {
    let (w, h) = (w as i64, h as i64);
    let (i, j) = (x.floor() as i64, y.floor() as i64);
    let (fx, fy) = (x - i as f64, y - j as f64);
    let idx = |a: i64, b: i64| (b.rem_euclid(h) * w + a.rem_euclid(w)) as usize;
    let corners = [
        (idx(i, j), (1.0 - fx) * (1.0 - fy)),
        (idx(i + 1, j), fx * (1.0 - fy)),
        (idx(i, j + 1), (1.0 - fx) * fy),
        (idx(i + 1, j + 1), fx * fy),
    ];
    let mut out = [0.0; K];
    for (c, wgt) in corners {
        let v = at(c);
        for k in 0..K {
            let value: f64 = v[k].into();
            out[k] += wgt * value;
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn texel_centres_give_their_values_and_the_tile_wraps() {
        let v = [1.0f32, 2.0, 3.0, 4.0]; // 2×2: row 0 = 1, 2; row 1 = 3, 4
        let at = |i: usize| [v[i]];
        assert_eq!(bilerp(2, 2, 1.0, 0.0, at), [2.0]);
        assert_eq!(bilerp(2, 2, 0.5, 0.5, at), [2.5]);
        // x = 1.5 lies between texel 1 and texel 0 of the next tile.
        assert_eq!(bilerp(2, 2, 1.5, 0.0, at), [1.5]);
        assert_eq!(bilerp(2, 2, -2.0, 3.0, at), [3.0]);
    }
}
