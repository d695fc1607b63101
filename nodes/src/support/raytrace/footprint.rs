//! What one pixel covers on the surface: the scene scale the planner decides from and every
//! renderer reports. From a camera, the mesh, the texture tiling (with the tile's texel count) and
//! the millimetres per world unit: the nearest visible distance, the finest pixel footprint over
//! the visible surface (widened by 1/cos θ where the surface is seen at a grazing angle θ from its
//! normal), the texels one pixel spans there, and the shell's thickness in pixels.
//!
//! The visible surface is sampled by ray casting at most [`SAMPLES_PER_SIDE`] rays along each
//! side of the image (the footprint varies smoothly; the silhouette's exact pixels do not matter),
//! and each sample's footprint is in full-resolution pixels.

use super::camera::Camera;
use super::layers::{self, Frag};
use crate::support::geometry::{bounding_sphere, cross, dot, length, mul, normalize, sub, V3};
use crate::support::progress::Counter;
use crate::types::Mesh;
use mesoflow_runtime::{Outputs, Port, Scalar};

/// Rays along the longer image side, at most.
pub const SAMPLES_PER_SIDE: u32 = 160;

/// Grazing views widen the footprint by 1/cos θ, up to this factor (cos θ ≥ 1/50): past it
/// the surface is edge-on and covers a sliver of pixels either way.
const MAX_WIDENING: f64 = 50.0;

/// The texture on the surface: tiles per unit of texture coordinate and texels per tile.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Texture {
    pub tiling: [f64; 2],
    pub texels: [usize; 2],
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Footprint {
    /// Rays that hit the mesh, of those cast.
    pub visible_samples: usize,
    pub samples: usize,
    /// Distance along the ray to the nearest visible surface, world units.
    pub nearest_distance: f64,
    /// The finest footprint of one pixel on the visible surface, world units.
    pub pixel_world: f64,
    /// The same in millimetres.
    pub pixel_mm: f64,
    /// Texels one pixel spans where the texture is seen finest; `None` without a texture or where
    /// the mesh's texture coordinates are degenerate.
    pub texels_per_pixel: Option<f64>,
    /// The median footprint over the visible samples, world units: what most of the object's
    /// pixels cover.
    pub median_pixel_world: f64,
    /// Fraction of the visible samples that see a triangle from behind (its winding's normal
    /// points away from the viewer): near 1 when the camera is inside a closed mesh.
    pub backfacing_fraction: f64,
    /// Fraction of the visible full-resolution pixels on a silhouette: next to a pixel that
    /// misses the mesh or sees a surface more than 10% farther or nearer (an inner contour). The
    /// MDF changes only these pixels.
    pub silhouette_fraction: f64,
    /// The mesh's bounding sphere's diameter in pixels, at its centre's distance: how many texels
    /// a shadow map of it needs to be no coarser than the screen.
    pub object_pixels: f64,
}

impl Footprint {
    /// Pixels a length (world units) spans at the finest footprint: a shell of thickness s is
    /// s / pixel_world pixels thick on screen where it is seen largest.
    pub fn pixels(&self, world: f64) -> f64 {
        world / self.pixel_world
    }
}

/// Whether `p` lies inside the closed `mesh`: the parity of the crossings of three rays along
/// skewed directions, by majority (a ray grazing an edge can miscount once).
pub fn contains(mesh: &Mesh, p: V3) -> bool {
    let dirs = [
        [1.0, 0.013, 0.027],
        [0.021, 1.0, -0.017],
        [-0.011, 0.019, 1.0],
    ];
    let odd = dirs
        .iter()
        .filter(|d| {
            let crossings = (0..mesh.triangles())
                .filter(|&t| {
                    let [a, b, c] = mesh.corners(t);
                    let q = |i: usize| mesh.positions[i].map(|v| v as f64);
                    layers::intersect(p, **d, q(a), q(b), q(c)).is_some()
                })
                .count();
            crossings % 2 == 1
        })
        .count();
    odd >= 2
}

/// The shadow-map densities the planner chooses among and the calibration measures: texels
/// per pixel the object spans on screen.
pub const SHADOW_TEXELS_PER_PIXEL: [f64; 3] = [1.0, 2.0, 4.0];

/// The shadow map no finer than the screen: `texels_per_pixel` texels per pixel the object
/// spans, a power of two, at least 32 and at most `graph` (the renderer's own). The planner
/// decides with it and the calibration measures it.
pub fn shadow_resolution(object_pixels: f64, texels_per_pixel: f64, graph: u32) -> u32 {
    let want = (texels_per_pixel * object_pixels)
        .max(32.0)
        .min(graph as f64);
    (want as u32).next_power_of_two().min(graph)
}

/// The footprint of `camera`'s pixels on `mesh`; `None` when no ray hits it.
pub fn footprint(
    mesh: &Mesh,
    camera: &Camera,
    texture: Option<Texture>,
    mm_per_unit: f64,
) -> Option<Footprint> {
    let longer = camera.width.max(camera.height);
    let scale = (SAMPLES_PER_SIDE as f64 / longer as f64).min(1.0);
    let mut coarse = camera.clone();
    coarse.width = ((camera.width as f64 * scale).round() as u32).max(1);
    coarse.height = ((camera.height as f64 * scale).round() as u32).max(1);
    let l = layers::trace(mesh, &coarse, 1, &Counter::none());
    // One full-resolution pixel's angular (pinhole) or linear (orthographic) size.
    let pixel = 2.0 * camera.half / camera.height as f64;
    let mut finest = f64::INFINITY;
    let mut nearest = f64::INFINITY;
    let mut finest_texels = f64::INFINITY;
    let mut all = Vec::new();
    let mut backfacing = 0usize;
    let samples = l.width * l.height;
    for y in 0..l.height {
        for x in 0..l.width {
            let Some(f) = l.front[y * l.width + x] else {
                continue;
            };
            let (_, dir) = coarse.ray(x as u32, y as u32);
            let (n, world_per_texel) = surface_scale(mesh, &f, texture);
            backfacing += (dot(n, dir) > 0.0) as usize;
            let cos = dot(n, dir).abs().max(1.0 / MAX_WIDENING);
            let across = if camera.orthographic {
                pixel
            } else {
                f.t * dot(dir, camera.forward) * pixel
            };
            let w = across / cos;
            finest = finest.min(w);
            nearest = nearest.min(f.t);
            all.push(w);
            if let Some(tw) = world_per_texel {
                finest_texels = finest_texels.min(w / tw);
            }
        }
    }
    if all.is_empty() {
        return None;
    }
    all.sort_by(f64::total_cmp);
    let depth = |x: usize, y: usize| l.front[y * l.width + x].map(|f| f.t);
    let mut edge = 0usize;
    for y in 0..l.height {
        for x in 0..l.width {
            let Some(t) = depth(x, y) else { continue };
            let neighbours = [
                (x > 0).then(|| (x - 1, y)),
                (x + 1 < l.width).then(|| (x + 1, y)),
                (y > 0).then(|| (x, y - 1)),
                (y + 1 < l.height).then(|| (x, y + 1)),
            ];
            let contour = neighbours
                .into_iter()
                .flatten()
                .any(|(nx, ny)| depth(nx, ny).is_none_or(|tn| (tn - t).abs() > 0.1 * t));
            edge += contour as usize;
        }
    }
    // Contours are lines: their share of an object's pixels falls as the resolution rises, by
    // the ratio of sample spacing to pixel size.
    let per_sample = coarse.height as f64 / camera.height as f64;
    Some(Footprint {
        visible_samples: all.len(),
        samples,
        nearest_distance: nearest,
        pixel_world: finest,
        pixel_mm: finest * mm_per_unit,
        texels_per_pixel: finest_texels.is_finite().then_some(finest_texels),
        median_pixel_world: all[all.len() / 2],
        backfacing_fraction: backfacing as f64 / all.len() as f64,
        silhouette_fraction: (edge as f64 / all.len() as f64 * per_sample).min(1.0),
        object_pixels: {
            let (centre, radius) = bounding_sphere(mesh);
            let at = if camera.orthographic {
                pixel
            } else {
                dot(sub(centre, camera.eye), camera.forward).max(1e-9) * pixel
            };
            2.0 * radius / at
        },
    })
}

/// The footprint outputs a renderer declares: always the pixel footprint in mm, and with a
/// texture the texels per pixel. Both are absent when no pixel sees the mesh.
pub fn output_ports(texels: bool) -> Vec<Port> {
    let mut v = vec![Port::optional_output(
        "pixel_footprint_mm",
        "Scalar",
        "finest footprint of one pixel on the visible surface, mm (widened at grazing angles); absent when nothing is visible",
    )];
    if texels {
        v.push(Port::optional_output(
            "texels_per_pixel",
            "Scalar",
            "texels one pixel spans where the texture is seen finest; absent when nothing is visible",
        ));
    }
    v
}

/// Adds the footprint outputs that can be computed.
pub fn with_metrics(mut out: Outputs, f: Option<&Footprint>) -> Outputs {
    if let Some(f) = f {
        out = out.with("pixel_footprint_mm", Scalar(f.pixel_mm));
        if let Some(t) = f.texels_per_pixel {
            out = out.with("texels_per_pixel", Scalar(t));
        }
    }
    out
}

/// The geometric normal at a hit and, with a texture, the world length of one texel there (the
/// geometric mean of its u and v sides, from the triangle's texture-coordinate Jacobian).
fn surface_scale(mesh: &Mesh, f: &Frag, texture: Option<Texture>) -> (V3, Option<f64>) {
    let [i0, i1, i2] = mesh.corners(f.tri as usize);
    let p = |i: usize| mesh.positions[i].map(|v| v as f64);
    let (e1, e2) = (sub(p(i1), p(i0)), sub(p(i2), p(i0)));
    let n = normalize(cross(e1, e2)).unwrap_or([0.0, 0.0, 1.0]);
    let Some(tex) = texture else {
        return (n, None);
    };
    let uv = |i: usize| {
        mesh.uvs
            .get(i)
            .map_or([0.0; 2], |t| [t[0] as f64, t[1] as f64])
    };
    let (du1, dv1) = (uv(i1)[0] - uv(i0)[0], uv(i1)[1] - uv(i0)[1]);
    let (du2, dv2) = (uv(i2)[0] - uv(i0)[0], uv(i2)[1] - uv(i0)[1]);
    let det = du1 * dv2 - du2 * dv1;
    if det.abs() < 1e-20 {
        return (n, None);
    }
    let dpdu = mul(sub(mul(e1, dv2), mul(e2, dv1)), 1.0 / det);
    let dpdv = mul(sub(mul(e2, du1), mul(e1, du2)), 1.0 / det);
    let texel_u = length(dpdu) / (tex.tiling[0] * tex.texels[0] as f64);
    let texel_v = length(dpdv) / (tex.tiling[1] * tex.texels[1] as f64);
    let texel = (texel_u * texel_v).sqrt();
    (n, (texel.is_finite() && texel > 0.0).then_some(texel))
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::support::raytrace::camera::CameraParams;

    /// A unit square in z = 0 facing +z, texture coordinates = (x, y) + 0.5.
    pub(crate) fn square() -> Mesh {
        let positions = vec![
            [-0.5, -0.5, 0.0],
            [0.5, -0.5, 0.0],
            [0.5, 0.5, 0.0],
            [-0.5, 0.5, 0.0],
        ];
        let mut m = Mesh {
            positions,
            normals: vec![[0.0, 0.0, 1.0]; 4],
            uvs: vec![[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]],
            tangents: vec![[1.0, 0.0, 0.0, 1.0]; 4],
            indices: vec![0, 1, 2, 0, 2, 3],
        };
        m.compute_normals();
        m
    }

    #[test]
    fn orthographic_footprint_is_the_view_height_over_rows() {
        // Orthographic, half height 1 over 100 rows: a pixel is 0.02 units; the square's texture
        // (4 tiles of 64 texels per unit) has 1/256-unit texels, so 5.12 texels per pixel.
        let cam = Camera::new(&CameraParams {
            eye: [0.0, 0.0, 3.0],
            target: [0.0; 3],
            orthographic: Some(1.0),
            resolution: [100, 100],
            ..Default::default()
        })
        .unwrap();
        let tex = Texture {
            tiling: [4.0, 4.0],
            texels: [64, 64],
        };
        let f = footprint(&square(), &cam, Some(tex), 10.0).unwrap();
        assert!((f.pixel_world - 0.02).abs() < 1e-12, "{f:?}");
        assert!((f.pixel_mm - 0.2).abs() < 1e-10);
        assert!((f.texels_per_pixel.unwrap() - 5.12).abs() < 1e-9);
        assert!((f.nearest_distance - 3.0).abs() < 1e-9);
        // The square spans 50 of the 100 rows and columns: its outline is 4·50 − 4 = 196 of
        // its 2500 pixels (counted by hand).
        assert!(
            (f.silhouette_fraction - 196.0 / 2500.0).abs() < 1e-9,
            "{}",
            f.silhouette_fraction
        );
    }

    #[test]
    fn pinhole_footprint_grows_with_distance() {
        // Pinhole at distance d, vertical fov 40°, 300 rows: on-axis a pixel spans
        // d·2·tan(20°)/300 (closed form).
        let at = |d: f64| {
            let cam = Camera::new(&CameraParams {
                eye: [0.0, 0.0, d],
                target: [0.0; 3],
                fov: 40.0,
                resolution: [400, 300],
                ..Default::default()
            })
            .unwrap();
            footprint(&square(), &cam, None, 1.0).unwrap()
        };
        let d = 4.0;
        let frontal = at(d);
        let expect = d * 2.0 * 20f64.to_radians().tan() / 300.0;
        // The finest sample is the one nearest the axis, a few pixels off it: 1% covers that.
        assert!(
            (frontal.pixel_world - expect).abs() < 0.01 * expect,
            "{} vs {expect}",
            frontal.pixel_world
        );
        assert!((at(2.0 * d).pixel_world / frontal.pixel_world - 2.0).abs() < 0.02);
    }

    #[test]
    fn grazing_views_widen_by_one_over_cosine() {
        // Orthographic, so every sample sees the square at the same angle: at 60° from the
        // normal the footprint is exactly 1/cos 60° = 2 times the frontal one, at 85° 11.47 times.
        let at = |deg: f64| {
            let (s, c) = deg.to_radians().sin_cos();
            let cam = Camera::new(&CameraParams {
                eye: [0.0, 3.0 * s, 3.0 * c],
                target: [0.0; 3],
                orthographic: Some(1.0),
                resolution: [100, 100],
                ..Default::default()
            })
            .unwrap();
            footprint(&square(), &cam, None, 1.0).unwrap().pixel_world
        };
        assert!((at(60.0) / at(0.0) - 2.0).abs() < 1e-9);
        let w85 = 1.0 / 85f64.to_radians().cos();
        assert!((at(85.0) / at(0.0) - w85).abs() < 1e-9 * w85);
    }

    #[test]
    fn points_inside_a_closed_mesh_are_found() {
        let sphere = crate::mesh::primitive::build(&crate::mesh::primitive::Params {
            shape: crate::mesh::primitive::Shape::Sphere,
            size: 1.0,
            segments: [24, 12],
            ..Default::default()
        })
        .unwrap();
        assert!(contains(&sphere, [0.1, 0.2, -0.1]));
        assert!(!contains(&sphere, [0.0, 0.0, 3.0]));
        assert!(
            !contains(&square(), [0.0, 0.0, 0.5]),
            "an open sheet has no inside"
        );
    }

    #[test]
    fn no_hit_gives_none() {
        let cam = Camera::new(&CameraParams {
            eye: [0.0, 0.0, 3.0],
            target: [0.0, 0.0, 6.0],
            resolution: [32, 32],
            ..Default::default()
        })
        .unwrap();
        assert!(footprint(&square(), &cam, None, 1.0).is_none());
    }
}
