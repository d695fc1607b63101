//! MDF of a mesostructure that is not a height field (overhangs, holes, loops): a triangle mesh
//! in the unit tile, x and y in [0, 1] (x right, y up the image: the tangent frame), z up, all in
//! tile units, repeated periodically. A ray enters the reference plane (the top of the shell) at
//! a texel centre and walks the tiles its footprint crosses (2-D DDA over unit cells), testing
//! that tile's copy of every triangle, until it drops below the mesh; rays that meet nothing —
//! through holes — get +∞. CPU path on rayon (f64), GPU path in `mesh_tile.wgsl` (f32); they
//! agree to 1e-3 texel (tested).

use crate::support::raytrace::layers::intersect;
use crate::types::{Direction, Mesh};
use mesoflow_runtime::{Gpu, NodeContext, NodeError};
use rayon::prelude::*;

/// The shader: the shared ray–triangle test, then the tile walk.
pub(crate) const WGSL: &str = concat!(
    include_str!("../support/raytrace/triangle.wgsl"),
    include_str!("mesh_tile.wgsl")
);

pub struct MeshTile {
    /// Triangles (corners in tile units) with their xy bounds, for a cheap rejection.
    tris: Vec<([[f64; 3]; 3], [f64; 4])>,
    pub lo: f64,
    pub hi: f64,
}

impl MeshTile {
    pub fn new(mesh: &Mesh) -> Result<MeshTile, NodeError> {
        mesh.check().map_err(|e| NodeError::input("mesh", e))?;
        let out = mesh.positions.iter().find(|p| {
            !(-1e-6..=1.0 + 1e-6).contains(&p[0]) || !(-1e-6..=1.0 + 1e-6).contains(&p[1])
        });
        if let Some(p) = out {
            return Err(NodeError::input(
                "mesh",
                format!("vertex {p:?} is outside the unit tile (x and y must lie in [0, 1])"),
            ));
        }
        let tris: Vec<_> = (0..mesh.triangles())
            .map(|t| {
                let c = mesh.corners(t).map(|i| mesh.positions[i].map(|v| v as f64));
                let xs = c.map(|p| p[0]);
                let ys = c.map(|p| p[1]);
                let bounds = [
                    xs.iter().copied().fold(f64::INFINITY, f64::min),
                    xs.iter().copied().fold(f64::NEG_INFINITY, f64::max),
                    ys.iter().copied().fold(f64::INFINITY, f64::min),
                    ys.iter().copied().fold(f64::NEG_INFINITY, f64::max),
                ];
                (c, bounds)
            })
            .collect();
        if tris.is_empty() {
            return Err(NodeError::input("mesh", "the mesh has no triangles"));
        }
        let (lo, hi) = mesh
            .positions
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), p| {
                (a.min(p[2] as f64), b.max(p[2] as f64))
            });
        Ok(MeshTile { tris, lo, hi })
    }

    /// Distance (tile units) from `o` along unit `d` (d.z < 0) to the first triangle, walking
    /// the periodic copies; `None` when the ray passes below the mesh without a hit.
    pub fn cast(&self, o: [f64; 3], d: [f64; 3]) -> Option<f64> {
        if d[2] >= 0.0 {
            return None;
        }
        let t_end = (self.lo - o[2]) / d[2] + 1e-9;
        let (mut i, mut j) = (o[0].floor() as i64, o[1].floor() as i64);
        let step = |v: f64| if v > 0.0 { 1i64 } else { -1 };
        let (si, sj) = (step(d[0]), step(d[1]));
        let boundary = |c: i64, s: i64, o: f64, d: f64| {
            if d == 0.0 {
                f64::INFINITY
            } else {
                ((if s > 0 { c + 1 } else { c }) as f64 - o) / d
            }
        };
        let mut t = 0.0;
        while t <= t_end {
            let exit = boundary(i, si, o[0], d[0]).min(boundary(j, sj, o[1], d[1]));
            // The tile's copy of the mesh, in the ray's frame: move the origin instead.
            let local = [o[0] - i as f64, o[1] - j as f64, o[2]];
            let (ta, tb) = (t, exit.min(t_end));
            let (xa, xb) = (local[0] + d[0] * ta, local[0] + d[0] * tb);
            let (ya, yb) = (local[1] + d[1] * ta, local[1] + d[1] * tb);
            let best = self
                .tris
                .iter()
                .filter(|(_, b)| {
                    xa.max(xb) >= b[0] - 1e-9
                        && xa.min(xb) <= b[1] + 1e-9
                        && ya.max(yb) >= b[2] - 1e-9
                        && ya.min(yb) <= b[3] + 1e-9
                })
                .filter_map(|(c, _)| intersect(local, d, c[0], c[1], c[2]).map(|h| h.0))
                .filter(|&s| s >= ta - 1e-9 && s <= tb + 1e-9)
                .fold(f64::INFINITY, f64::min);
            if best.is_finite() {
                return Some(best);
            }
            t = exit;
            if boundary(i, si, o[0], d[0]) < boundary(j, sj, o[1], d[1]) {
                i += si;
            } else {
                j += sj;
            }
        }
        None
    }
}

/// The shell's top (tile units) and depth (tile units) for a requested depth in texels.
fn shell(
    tile: &MeshTile,
    width: usize,
    depth_texels: Option<f64>,
) -> Result<(f64, f64), NodeError> {
    let texel = 1.0 / width as f64;
    let range = tile.hi - tile.lo;
    let depth = depth_texels.map_or(range, |d| d * texel);
    if depth.is_nan() || depth < range - 1e-9 {
        return Err(NodeError::param(
            "depth",
            format!(
                "a shell of {} texels cannot hold a tile {} texels deep",
                depth / texel,
                range / texel
            ),
        ));
    }
    Ok((tile.lo + depth, depth))
}

/// The table (views × H × W, output texels) and the shell depth in texels, on the CPU.
pub fn tabulate(
    ctx: &NodeContext,
    tile: &MeshTile,
    views: &[Direction],
    (width, height): (usize, usize),
    depth_texels: Option<f64>,
) -> Result<(Vec<f32>, f64), NodeError> {
    let texel = 1.0 / width as f64;
    let (top, depth) = shell(tile, width, depth_texels)?;
    // Start a hair above the plane so geometry lying exactly on it is hit at distance 0.
    let lift = 1e-7;
    let plane = width * height;
    let mut data = vec![0f32; plane * views.len()];
    data.par_chunks_mut(plane)
        .zip(views)
        .try_for_each(|(out, view)| {
            ctx.check_cancel()?;
            let w = view.vector();
            let d = [-w[0], -w[1], -w[2]];
            for (k, v) in out.iter_mut().enumerate() {
                let (x, y) = (k % width, k / width);
                let o = [
                    (x as f64 + 0.5) / width as f64,
                    1.0 - (y as f64 + 0.5) / height as f64,
                    top + lift,
                ];
                *v = match tile.cast(o, d) {
                    Some(t) => ((t - lift / w[2]).max(0.0) / texel) as f32,
                    None => f32::INFINITY,
                };
            }
            Ok::<(), NodeError>(())
        })?;
    Ok((data, depth / texel))
}

/// The same table on the GPU (wgpu compute, f32; `mesh_tile.wgsl`).
pub fn tabulate_gpu(
    gpu: &Gpu,
    tile: &MeshTile,
    views: &[Direction],
    (width, height): (usize, usize),
    depth_texels: Option<f64>,
) -> Result<(Vec<f32>, f64), NodeError> {
    let texel = 1.0 / width as f64;
    let (top, depth) = shell(tile, width, depth_texels)?;
    let mut input: Vec<f32> = Vec::with_capacity(tile.tris.len() * 13 + views.len() * 4);
    for (c, b) in &tile.tris {
        input.extend(c.iter().flatten().map(|v| *v as f32));
        input.extend(b.map(|v| v as f32));
    }
    for v in views {
        let w = v.vector();
        input.extend([-w[0], -w[1], -w[2], w[2]].map(|x| x as f32));
    }
    // f32 cannot move a point by 1e-7 of a tile; 1e-5 is representable and still far below a
    // texel.
    let lift = 1e-5 * top.abs().max(1.0);
    let u = |v: usize| (v as u32).to_le_bytes();
    let f = |v: f64| (v as f32).to_le_bytes();
    let params: Vec<u8> = [
        u(tile.tris.len()),
        u(width),
        u(height),
        u(views.len()),
        f(top),
        f(tile.lo),
        f(lift),
        f(texel),
    ]
    .concat();
    let rows = height * views.len();
    let pass = crate::support::gpu::Pass2d {
        label: "mdf.tabulate (mesh tile)",
        shader: WGSL,
        entry: "main",
        params: &params,
        input: &input,
        output_len: width * rows,
        grid: (width as u32, rows as u32),
    };
    Ok((crate::support::gpu::compute_2d(gpu, &pass)?, depth / texel))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn quad(z: f32, lo: f32, hi: f32) -> Mesh {
        Mesh {
            positions: vec![[lo, lo, z], [hi, lo, z], [hi, hi, z], [lo, hi, z]],
            uvs: vec![[0.0, 0.0]; 4],
            normals: vec![[0.0, 0.0, 1.0]; 4],
            tangents: vec![[1.0, 0.0, 0.0, 1.0]; 4],
            indices: vec![0, 1, 2, 0, 2, 3],
        }
    }

    #[test]
    fn a_full_floor_gives_the_plane_distance_like_a_height_field() {
        // A floor covering the tile at z = 0 under a shell of 8 texels: depth / cos θ.
        let tile = MeshTile::new(&quad(0.0, 0.0, 1.0)).unwrap();
        let ctx = NodeContext::detached(None);
        let views: Vec<Direction> = crate::btf::directions::ubo81();
        let (data, depth) = tabulate(&ctx, &tile, &views, (16, 16), Some(8.0)).unwrap();
        assert!((depth - 8.0).abs() < 1e-12);
        for (k, v) in views.iter().enumerate() {
            let want = 8.0 / v.theta.cos();
            for d in &data[k * 256..(k + 1) * 256] {
                assert!((*d as f64 - want).abs() < 1e-4 * want, "{d} vs {want}");
            }
        }
    }

    #[test]
    fn a_floating_plate_is_hit_inside_and_missed_outside() {
        // A plate over the middle half of the tile, nothing under it: vertical rays inside hit
        // it at distance 0 (it is the shell's top), rays outside fall through: +inf. A slanted
        // ray from outside reaches it iff its footprint enters the plate before the ray drops
        // below it — it never does here (the plate is the lowest and highest point): still +inf.
        let tile = MeshTile::new(&quad(0.5, 0.25, 0.75)).unwrap();
        let ctx = NodeContext::detached(None);
        let views = vec![Direction::degrees(0.0, 0.0), Direction::degrees(45.0, 0.0)];
        let (data, _) = tabulate(&ctx, &tile, &views, (8, 8), None).unwrap();
        let at = |k: usize, x: usize, y: usize| data[k * 64 + y * 8 + x];
        assert_eq!(at(0, 4, 4), 0.0);
        assert!(at(0, 0, 0).is_infinite() && at(0, 7, 3).is_infinite());
        assert_eq!(at(1, 3, 3), 0.0);
        assert!(at(1, 0, 0).is_infinite());
    }

    #[test]
    fn a_plate_over_a_floor_shadows_the_floor_along_slanted_rays() {
        // Plate at z = 0.5 over x ∈ [0.25, 0.75] (all y), floor at 0; shell top 0.5. A 45° ray
        // travelling towards −x (view φ = 0) entering at x0 > 0.75 reaches the floor at
        // x0 − 0.5; it meets the plate only if it enters above it (x0 ≤ 0.75). Closed form: for
        // x0 in (0.75, 1): floor at distance 0.5/cos 45° (the plate is at the top, not in the way).
        let mut m = quad(0.0, 0.0, 1.0);
        let plate = quad(0.5, 0.25, 0.75);
        let n = m.positions.len() as u32;
        m.positions.extend(
            plate
                .positions
                .iter()
                .map(|p| [p[0], if p[1] < 0.5 { 0.0 } else { 1.0 }, p[2]]),
        );
        m.uvs.extend(plate.uvs);
        m.normals.extend(plate.normals);
        m.tangents.extend(plate.tangents);
        m.indices.extend(plate.indices.iter().map(|i| i + n));
        let tile = MeshTile::new(&m).unwrap();
        let ctx = NodeContext::detached(None);
        let views = vec![Direction::degrees(45.0, 0.0)];
        let (data, _) = tabulate(&ctx, &tile, &views, (16, 4), None).unwrap();
        let texel = 1.0 / 16.0;
        for x in 13..16 {
            let want = 0.5 / 45f64.to_radians().cos() / texel;
            assert!((data[16 + x] as f64 - want).abs() < 1e-4, "x {x}");
        }
        for x in 4..12 {
            assert_eq!(data[16 + x], 0.0, "x {x}: on the plate");
        }
    }

    #[test]
    fn vertices_outside_the_tile_are_refused() {
        let e = MeshTile::new(&quad(0.0, 0.0, 1.5))
            .err()
            .unwrap()
            .to_string();
        assert!(e.contains("unit tile"), "{e}");
    }

    #[test]
    fn gpu_and_cpu_agree_on_every_backend() {
        // A plate over a floor (an overhang no height field can hold), and the plate alone
        // (holes: +inf entries), all 81 UBO views.
        let mut m = quad(0.0, 0.0, 1.0);
        let plate = quad(0.6, 0.2, 0.7);
        let n = m.positions.len() as u32;
        m.positions.extend(plate.positions.clone());
        m.uvs.extend(plate.uvs.clone());
        m.normals.extend(plate.normals.clone());
        m.tangents.extend(plate.tangents.clone());
        m.indices.extend(plate.indices.iter().map(|i| i + n));
        let views = crate::btf::directions::ubo81();
        let ctx = NodeContext::detached(None);
        let tiles = [MeshTile::new(&m).unwrap(), MeshTile::new(&plate).unwrap()];
        let cpus: Vec<Vec<f32>> = tiles
            .iter()
            .map(|t| tabulate(&ctx, t, &views, (24, 24), Some(20.0)).unwrap().0)
            .collect();
        assert!(cpus[1].iter().any(|d| d.is_infinite()));
        let mut tested = 0;
        for backends in [wgpu::Backends::PRIMARY, wgpu::Backends::GL] {
            let Ok(gpu) = Gpu::with_backends(backends) else {
                continue;
            };
            for (tile, cpu) in tiles.iter().zip(&cpus) {
                let (out, _) = tabulate_gpu(&gpu, tile, &views, (24, 24), Some(20.0)).unwrap();
                let mut off = 0;
                let mut worst = 0f32;
                for (a, b) in cpu.iter().zip(&out) {
                    let diff = if a.is_infinite() || b.is_infinite() {
                        if a == b {
                            0.0
                        } else {
                            f32::INFINITY
                        }
                    } else {
                        (a - b).abs()
                    };
                    if diff > 1e-3 {
                        off += 1;
                    } else {
                        worst = worst.max(diff);
                    }
                }
                eprintln!("GPU ({}) vs CPU mesh-tile MDF: max |diff| {worst:e} texel, {off} of {} entries beyond 1e-3", gpu.describe(), cpu.len());
                // Rays through a triangle's edge or the plate's rim can land on either side in f32;
                // 1 entry in 10³ allows those and fails on any systematic error.
                assert!(
                    (off as f64) < 1e-3 * cpu.len() as f64,
                    "{}: {off} entries differ",
                    gpu.describe()
                );
            }
            tested += 1;
        }
        crate::support::gpu::require_tested(tested);
    }
}
