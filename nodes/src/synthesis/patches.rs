//! Feature planes, grids of square patches over them, and the nearest-patch search that texture
//! optimisation alternates with its least-squares update: PatchMatch (Barnes et al. 2009) run
//! Jacobi-style, so every query reads the previous round's field and the result does not depend
//! on the thread count, and an exhaustive search to check it against.

use crate::support::rng;
use rayon::prelude::*;

/// Interleaved f32 channels, row 0 at the top.
#[derive(Clone, Debug, PartialEq)]
pub struct Plane {
    pub width: usize,
    pub height: usize,
    pub channels: usize,
    pub data: Vec<f32>,
}

impl Plane {
    pub fn pixel(&self, x: usize, y: usize) -> &[f32] {
        let at = (y * self.width + x) * self.channels;
        &self.data[at..at + self.channels]
    }

    /// Half size (floor, at least 1), each pixel the mean of its 2 × 2 block (clipped at the edge).
    pub fn downsample(&self) -> Plane {
        let (w, h, c) = (half(self.width), half(self.height), self.channels);
        let mut data = vec![0.0f32; w * h * c];
        for y in 0..h {
            for x in 0..w {
                let ys = (2 * y..(2 * y + 2).min(self.height)).collect::<Vec<_>>();
                let xs = (2 * x..(2 * x + 2).min(self.width)).collect::<Vec<_>>();
                let k = (ys.len() * xs.len()) as f32;
                for &sy in &ys {
                    for &sx in &xs {
                        for (o, v) in data[(y * w + x) * c..][..c]
                            .iter_mut()
                            .zip(self.pixel(sx, sy))
                        {
                            *o += v / k;
                        }
                    }
                }
            }
        }
        Plane {
            width: w,
            height: h,
            channels: c,
            data,
        }
    }

    /// Bilinear resampling to `width` × `height` (pixel centres aligned, edges clamped).
    pub fn resize(&self, width: usize, height: usize) -> Plane {
        let c = self.channels;
        let mut data = vec![0.0f32; width * height * c];
        let sx = self.width as f64 / width as f64;
        let sy = self.height as f64 / height as f64;
        for y in 0..height {
            let fy = ((y as f64 + 0.5) * sy - 0.5).clamp(0.0, (self.height - 1) as f64);
            let (y0, ty) = (fy.floor() as usize, (fy - fy.floor()) as f32);
            let y1 = (y0 + 1).min(self.height - 1);
            for x in 0..width {
                let fx = ((x as f64 + 0.5) * sx - 0.5).clamp(0.0, (self.width - 1) as f64);
                let (x0, tx) = (fx.floor() as usize, (fx - fx.floor()) as f32);
                let x1 = (x0 + 1).min(self.width - 1);
                for k in 0..c {
                    let top = self.pixel(x0, y0)[k] * (1.0 - tx) + self.pixel(x1, y0)[k] * tx;
                    let bottom = self.pixel(x0, y1)[k] * (1.0 - tx) + self.pixel(x1, y1)[k] * tx;
                    data[(y * width + x) * c + k] = top * (1.0 - ty) + bottom * ty;
                }
            }
        }
        Plane {
            width,
            height,
            channels: c,
            data,
        }
    }
}

/// One pyramid step down: floor(n / 2), at least 1.
pub fn half(n: usize) -> usize {
    (n / 2).max(1)
}

/// Top-left corners of the output patches: every `spacing` pixels, plus the last position that
/// fits so the far edge is covered; with `periodic`, patches wrap around instead.
#[derive(Clone, Debug)]
pub struct Grid {
    pub size: usize,
    pub width: usize,
    pub height: usize,
    pub periodic: bool,
    pub xs: Vec<usize>,
    pub ys: Vec<usize>,
}

impl Grid {
    /// `size` must not exceed `width` or `height` (the callers check).
    pub fn new(width: usize, height: usize, size: usize, spacing: usize, periodic: bool) -> Grid {
        let axis = |n: usize| -> Vec<usize> {
            if periodic {
                (0..n).step_by(spacing).collect()
            } else {
                let last = n - size;
                let mut v: Vec<usize> = (0..=last).step_by(spacing).collect();
                if v.last() != Some(&last) {
                    v.push(last);
                }
                v
            }
        };
        Grid {
            size,
            width,
            height,
            periodic,
            xs: axis(width),
            ys: axis(height),
        }
    }

    pub fn len(&self) -> usize {
        self.xs.len() * self.ys.len()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    pub fn pos(&self, q: usize) -> (usize, usize) {
        (self.xs[q % self.xs.len()], self.ys[q / self.xs.len()])
    }

    /// For each coordinate along an axis, the grid index whose patch covers it with the nearest
    /// centre.
    fn nearest_cover(positions: &[usize], n: usize, size: usize, periodic: bool) -> Vec<usize> {
        (0..n)
            .map(|x| {
                let mut best = (usize::MAX, 0);
                for (g, &p) in positions.iter().enumerate() {
                    let off = if periodic {
                        (x + n - p) % n
                    } else {
                        x.wrapping_sub(p)
                    };
                    if off < size {
                        let d = (2 * off).abs_diff(size);
                        if d < best.0 {
                            best = (d, g);
                        }
                    }
                }
                best.1
            })
            .collect()
    }
}

/// A nearest-patch candidate: the exemplar patch's top-left corner and the squared distance.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Match {
    pub x: u32,
    pub y: u32,
    pub d2: f32,
}

/// Every grid patch of `img`, each s × s × channels contiguous, row by row.
pub fn gather(img: &Plane, grid: &Grid) -> Vec<f32> {
    let (s, c) = (grid.size, img.channels);
    let mut out = vec![0.0f32; grid.len() * s * s * c];
    out.par_chunks_mut(s * s * c)
        .enumerate()
        .for_each(|(q, patch)| {
            let (px, py) = grid.pos(q);
            for i in 0..s {
                let y = (py + i) % img.height;
                let row = &mut patch[i * s * c..(i + 1) * s * c];
                if px + s <= img.width {
                    let at = (y * img.width + px) * c;
                    row.copy_from_slice(&img.data[at..at + s * c]);
                } else {
                    for j in 0..s {
                        let x = (px + j) % img.width;
                        row[j * c..(j + 1) * c].copy_from_slice(img.pixel(x, y));
                    }
                }
            }
        });
    out
}

/// Squared distance between `patch` and the exemplar patch at (x, y); stops early once it
/// exceeds `bound` (the result is then only known to be larger).
pub fn distance2(ex: &Plane, size: usize, patch: &[f32], x: usize, y: usize, bound: f32) -> f32 {
    let row = size * ex.channels;
    let mut sum = 0.0f32;
    for i in 0..size {
        let at = ((y + i) * ex.width + x) * ex.channels;
        let a = &ex.data[at..at + row];
        let b = &patch[i * row..(i + 1) * row];
        // Eight independent lanes so the compiler can vectorise; the order is fixed.
        let mut acc = [0.0f32; 8];
        let (ca, cb) = (a.chunks_exact(8), b.chunks_exact(8));
        let (ra, rb) = (ca.remainder(), cb.remainder());
        for (u, v) in ca.zip(cb) {
            for k in 0..8 {
                let d = u[k] - v[k];
                acc[k] += d * d;
            }
        }
        let mut tail = 0.0f32;
        for (u, v) in ra.iter().zip(rb) {
            tail += (u - v) * (u - v);
        }
        sum += acc.iter().sum::<f32>() + tail;
        if sum > bound {
            return sum;
        }
    }
    sum
}

/// The exemplar positions a patch of `size` may take: [0, max_x] × [0, max_y].
fn limits(ex: &Plane, size: usize) -> (u32, u32) {
    ((ex.width - size) as u32, (ex.height - size) as u32)
}

/// A field of uniformly random matches (distances not yet computed).
pub fn random_field(ex: &Plane, size: usize, n: usize, seed: u64) -> Vec<Match> {
    let (mx, my) = limits(ex, size);
    (0..n)
        .map(|q| {
            let h = rng::hash(seed, &[q as u64]);
            Match {
                x: (rng::unit(h) * (mx + 1) as f64) as u32,
                y: (rng::unit(rng::mix(h)) * (my + 1) as f64) as u32,
                d2: f32::INFINITY,
            }
        })
        .collect()
}

/// Improves `field` (one match per grid patch) by PatchMatch: first the current matches are
/// re-measured against `patches`, then each round every patch tries its grid neighbours' matches
/// shifted by the offset between them, a random search around its own match at halving radii,
/// and one uniform sample; it keeps the best. A match only ever gets closer.
pub fn refine(
    ex: &Plane,
    grid: &Grid,
    patches: &[f32],
    field: &mut Vec<Match>,
    rounds: usize,
    seed: u64,
) {
    let s = grid.size;
    let dim = s * s * ex.channels;
    let (mx, my) = limits(ex, s);
    field.par_iter_mut().enumerate().for_each(|(q, m)| {
        m.x = m.x.min(mx);
        m.y = m.y.min(my);
        m.d2 = distance2(
            ex,
            s,
            &patches[q * dim..(q + 1) * dim],
            m.x as usize,
            m.y as usize,
            f32::INFINITY,
        );
    });
    let (nx, ny) = (grid.xs.len(), grid.ys.len());
    for round in 0..rounds {
        let prev = &*field;
        let next: Vec<Match> = (0..prev.len())
            .into_par_iter()
            .map(|q| {
                let patch = &patches[q * dim..(q + 1) * dim];
                let mut best = prev[q];
                let try_at = |x: i64, y: i64, best: &mut Match| {
                    let (x, y) = (x.clamp(0, mx as i64) as u32, y.clamp(0, my as i64) as u32);
                    if x == best.x && y == best.y {
                        return;
                    }
                    let d2 = distance2(ex, s, patch, x as usize, y as usize, best.d2);
                    if d2 < best.d2 {
                        *best = Match { x, y, d2 };
                    }
                };
                let (gx, gy) = (q % nx, q / nx);
                let (px, py) = grid.pos(q);
                // Propagation: a neighbour matched at m suggests m shifted by our offset from it.
                for (dx, dy) in [(-1i64, 0i64), (1, 0), (0, -1), (0, 1)] {
                    let Some(nq) = neighbour(gx, gy, dx, dy, nx, ny, grid.periodic) else {
                        continue;
                    };
                    let (qx, qy) = grid.pos(nq);
                    let ox = offset(px, qx, grid.width, grid.periodic);
                    let oy = offset(py, qy, grid.height, grid.periodic);
                    let m = prev[nq];
                    try_at(m.x as i64 + ox, m.y as i64 + oy, &mut best);
                }
                // Random search around the current best, then one uniform sample.
                let h = rng::hash(seed, &[round as u64, q as u64]);
                let mut radius = mx.max(my) as i64;
                let mut k = 0u64;
                while radius >= 1 {
                    let r = rng::hash(h, &[k]);
                    let jx = (rng::unit(r) * (2 * radius + 1) as f64) as i64 - radius;
                    let jy = (rng::unit(rng::mix(r)) * (2 * radius + 1) as f64) as i64 - radius;
                    try_at(best.x as i64 + jx, best.y as i64 + jy, &mut best);
                    radius /= 2;
                    k += 1;
                }
                let r = rng::hash(h, &[u64::MAX]);
                try_at(
                    (rng::unit(r) * (mx + 1) as f64) as i64,
                    (rng::unit(rng::mix(r)) * (my + 1) as f64) as i64,
                    &mut best,
                );
                best
            })
            .collect();
        *field = next;
    }
}

fn neighbour(
    gx: usize,
    gy: usize,
    dx: i64,
    dy: i64,
    nx: usize,
    ny: usize,
    periodic: bool,
) -> Option<usize> {
    let (x, y) = (gx as i64 + dx, gy as i64 + dy);
    let (x, y) = if periodic {
        (x.rem_euclid(nx as i64), y.rem_euclid(ny as i64))
    } else if x < 0 || y < 0 || x >= nx as i64 || y >= ny as i64 {
        return None;
    } else {
        (x, y)
    };
    Some(y as usize * nx + x as usize)
}

/// Signed offset from a neighbour's position `from` to `to` along an axis of length n.
fn offset(to: usize, from: usize, n: usize, periodic: bool) -> i64 {
    let d = to as i64 - from as i64;
    if periodic && d.abs() > n as i64 / 2 {
        d - d.signum() * n as i64
    } else {
        d
    }
}

/// The exact nearest exemplar patch, scanning every position (row-major; the first of equals wins).
pub fn nearest_exact(ex: &Plane, size: usize, patch: &[f32]) -> Match {
    let (mx, my) = limits(ex, size);
    let mut best = Match {
        x: 0,
        y: 0,
        d2: f32::INFINITY,
    };
    for y in 0..=my {
        for x in 0..=mx {
            let d2 = distance2(ex, size, patch, x as usize, y as usize, best.d2);
            if d2 < best.d2 {
                best = Match { x, y, d2 };
            }
        }
    }
    best
}

/// For every output pixel, the exemplar pixel it came from: the match of the covering patch with
/// the nearest centre, plus the pixel's place in that patch.
pub fn source_map(grid: &Grid, field: &[Match]) -> Vec<(u32, u32)> {
    let cx = Grid::nearest_cover(&grid.xs, grid.width, grid.size, grid.periodic);
    let cy = Grid::nearest_cover(&grid.ys, grid.height, grid.size, grid.periodic);
    let nx = grid.xs.len();
    let mut out = Vec::with_capacity(grid.width * grid.height);
    for (y, &gy) in cy.iter().enumerate() {
        for (x, &gx) in cx.iter().enumerate() {
            let m = field[gy * nx + gx];
            let ox = (x + grid.width - grid.xs[gx]) % grid.width;
            let oy = (y + grid.height - grid.ys[gy]) % grid.height;
            out.push((m.x + ox as u32, m.y + oy as u32));
        }
    }
    out
}

/// Starting matches for a new grid from a source map: each patch starts where the exemplar pixel
/// under its centre came from, moved back by half a patch.
pub fn field_from_sources(ex: &Plane, grid: &Grid, sources: &[(u32, u32)]) -> Vec<Match> {
    let (mx, my) = limits(ex, grid.size);
    let half = (grid.size / 2) as i64;
    (0..grid.len())
        .map(|q| {
            let (px, py) = grid.pos(q);
            let cx = (px + grid.size / 2) % grid.width;
            let cy = (py + grid.size / 2) % grid.height;
            let (sx, sy) = sources[cy * grid.width + cx];
            Match {
                x: (sx as i64 - half).clamp(0, mx as i64) as u32,
                y: (sy as i64 - half).clamp(0, my as i64) as u32,
                d2: f32::INFINITY,
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn noise(w: usize, h: usize, c: usize, seed: u64) -> Plane {
        Plane {
            width: w,
            height: h,
            channels: c,
            data: (0..w * h * c)
                .map(|i| rng::unit(rng::hash(seed, &[i as u64])) as f32)
                .collect(),
        }
    }

    #[test]
    fn grid_covers_every_pixel_and_ends_at_the_edge() {
        let g = Grid::new(37, 20, 8, 2, false);
        assert_eq!(*g.xs.last().unwrap(), 29);
        assert_eq!(*g.ys.last().unwrap(), 12);
        let p = Grid::new(36, 20, 8, 4, true);
        assert_eq!(p.xs, vec![0, 4, 8, 12, 16, 20, 24, 28, 32]);
    }

    #[test]
    fn distance_is_the_plain_sum_of_squares() {
        // Brute-force reference: the textbook double loop in f64.
        let ex = noise(13, 11, 3, 1);
        let patch: Vec<f32> = noise(5, 5, 3, 2).data;
        let d = distance2(&ex, 5, &patch, 4, 3, f32::INFINITY) as f64;
        let mut want = 0.0f64;
        for i in 0..5 {
            for j in 0..5 {
                for c in 0..3 {
                    let a = ex.pixel(4 + j, 3 + i)[c] as f64;
                    let b = patch[(i * 5 + j) * 3 + c] as f64;
                    want += (a - b) * (a - b);
                }
            }
        }
        assert!((d - want).abs() < 1e-5 * want, "{d} vs {want}");
    }

    #[test]
    fn patchmatch_finds_patches_cut_from_the_exemplar() {
        // Every output patch is an exact copy of some exemplar patch, so the exhaustive search
        // gives distance 0; PatchMatch must reach it for almost all patches after a few rounds.
        // The exemplar is smooth (a sum of plane waves), as textures are: random search then
        // descends towards the match instead of needing a lucky hit as in white noise.
        let waves: Vec<[f32; 4]> = (0..6u64)
            .map(|k| {
                let h = rng::hash(3, &[k]);
                let u = |i: u64| rng::unit(rng::hash(h, &[i])) as f32;
                [u(0) - 0.5, u(1) - 0.5, u(2) * std::f32::consts::TAU, u(3)]
            })
            .collect();
        let ex = Plane {
            width: 40,
            height: 40,
            channels: 3,
            data: (0..40 * 40 * 3)
                .map(|i| {
                    let (x, y, c) = ((i / 3 % 40) as f32, (i / 120) as f32, (i % 3) as f32);
                    waves
                        .iter()
                        .map(|w| w[3] * (w[0] * x + w[1] * y + w[2] + c).sin())
                        .sum::<f32>()
                })
                .collect(),
        };
        let (w, h) = (32, 32);
        // The output is the exemplar shifted by (5, 7): a coherent field to propagate.
        let mut img = Plane {
            width: w,
            height: h,
            channels: 3,
            data: vec![0.0; w * h * 3],
        };
        for y in 0..h {
            for x in 0..w {
                let v = ex.pixel(x + 5, y + 7).to_vec();
                img.data[(y * w + x) * 3..][..3].copy_from_slice(&v);
            }
        }
        let grid = Grid::new(w, h, 7, 2, false);
        let patches = gather(&img, &grid);
        let mut field = random_field(&ex, 7, grid.len(), 9);
        refine(&ex, &grid, &patches, &mut field, 6, 4);
        let exact = field.iter().filter(|m| m.d2 == 0.0).count();
        assert!(
            exact as f64 >= 0.95 * grid.len() as f64,
            "{exact} of {}",
            grid.len()
        );
        let q = grid.len() / 2;
        let (px, py) = grid.pos(q);
        let m = nearest_exact(&ex, 7, &patches[q * 147..(q + 1) * 147]);
        assert_eq!((m.x as usize, m.y as usize), (px + 5, py + 7));
    }

    #[test]
    fn refinement_is_independent_of_the_thread_count() {
        let ex = noise(30, 30, 1, 5);
        let img = noise(24, 24, 1, 6);
        let grid = Grid::new(24, 24, 6, 2, true);
        let patches = gather(&img, &grid);
        let run = |threads| {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            pool.install(|| {
                let mut f = random_field(&ex, 6, grid.len(), 1);
                refine(&ex, &grid, &patches, &mut f, 3, 2);
                f
            })
        };
        assert_eq!(run(1), run(3));
    }

    #[test]
    fn downsample_and_resize_keep_a_constant() {
        let c = Plane {
            width: 9,
            height: 7,
            channels: 2,
            data: vec![0.25; 9 * 7 * 2],
        };
        assert!(c.downsample().data.iter().all(|v| (v - 0.25).abs() < 1e-7));
        assert!(c.resize(20, 3).data.iter().all(|v| (v - 0.25).abs() < 1e-7));
    }
}
