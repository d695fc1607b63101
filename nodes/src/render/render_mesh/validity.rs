//! Where `render.mesh` is outside its domain, read from the scene in front of it (issue 57):
//! relief deep against the mesh's curvature (the MDF assumes a shell flat over a tile), tiles the
//! parameterisation squeezes (the BTF was captured on square texels), and what the camera sees
//! viewed or lit beyond the BTF's most oblique sampled direction (extrapolated from the outer
//! rings there). Each is measured without rendering, from the mesh, the camera and the light, and
//! becomes a warning with its numbers where it passes its threshold.

use crate::support::geometry::{cross, dot, length, normalize as unit, sub, V3};
use crate::support::raytrace::camera::CameraParams;
use crate::support::raytrace::light::LightParams;
use crate::types::Mesh;

/// The shell's depth over the mesh's radius of curvature above which the relief is drawn bent.
pub const SHELL_OVER_RADIUS: f64 = 0.25;
/// Texels stretched beyond this aspect (either way) count as squeezed.
pub const SQUEEZE: f64 = 1.5;
/// The share of the surface (by area) past a limit that is worth a warning.
pub const SHARE: f64 = 0.05;
/// Tolerance on the sampled cone, radians (1°): the outer ring itself is inside.
const CONE_SLACK: f64 = 0.017_453_3;

/// What the BTF samples: its texels [width, height] and its directions (unit, z along the
/// normal).
#[derive(Clone, Copy, Debug)]
pub struct Sampled<'a> {
    pub texels: [usize; 2],
    pub views: &'a [[f64; 3]],
    pub lights: &'a [[f64; 3]],
}

/// What the scene measures against the renderer's domain.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Validity {
    /// The mesh's radius of curvature: one over the 95th percentile of its edges' curvature,
    /// |Δn| / |Δp|; absent on a flat mesh.
    pub radius: Option<f64>,
    /// The share of the mesh's area whose texels are stretched beyond [`SQUEEZE`], and the worst
    /// stretch (≥ 1).
    pub squeezed: (f64, f64),
    /// The share of the camera-facing surface (by projected area) seen beyond the sampled views'
    /// cone, and lit beyond the lights' (of what is both facing and lit); with the cones' θ, degrees.
    pub view_beyond: Option<(f64, f64)>,
    pub light_beyond: Option<(f64, f64)>,
}

/// A position or normal of the mesh in f64.
fn f64s(a: [f32; 3]) -> V3 {
    a.map(f64::from)
}

/// The most oblique θ (radians) of a set of unit directions in the tile's frame (z up).
fn cone(dirs: &[[f64; 3]]) -> Option<f64> {
    dirs.iter()
        .map(|d| d[2].clamp(-1.0, 1.0).acos())
        .fold(None, |m: Option<f64>, t| Some(m.map_or(t, |m| m.max(t))))
}

/// Measures the scene: the mesh at `tiling` seen by `camera` under `light`, against what the BTF
/// samples.
pub fn measure(
    mesh: &Mesh,
    camera: &CameraParams,
    light: &LightParams,
    tiling: [f64; 2],
    btf: Sampled,
) -> Validity {
    let Sampled {
        texels,
        views,
        lights,
    } = btf;
    let mut v = Validity::default();
    // Curvature over the edges whose ends carry normals.
    let mut curvature: Vec<f64> = Vec::new();
    let has_normals = mesh.normals.len() == mesh.positions.len();
    let (view_cone, light_cone) = (cone(views), cone(lights));
    let (mut facing, mut seen_beyond, mut lit, mut lit_beyond) = (0.0, 0.0, 0.0, 0.0);
    let (mut area_sum, mut squeezed_area, mut worst) = (0.0, 0.0, 1.0f64);

    let towards_target = unit(sub(camera.eye, camera.target));
    for t in 0..mesh.triangles() {
        let [a, b, c] = mesh.corners(t);
        let (pa, pb, pc) = (
            f64s(mesh.positions[a]),
            f64s(mesh.positions[b]),
            f64s(mesh.positions[c]),
        );
        let n = cross(sub(pb, pa), sub(pc, pa));
        let area = 0.5 * length(n);
        let Some(face) = unit(n) else { continue };
        if has_normals {
            for (i, j) in [(a, b), (b, c), (c, a)] {
                let dp = length(sub(f64s(mesh.positions[i]), f64s(mesh.positions[j])));
                let dn = length(sub(f64s(mesh.normals[i]), f64s(mesh.normals[j])));
                if dp > 1e-12 {
                    curvature.push(dn / dp);
                }
            }
        }
        // The texels' stretch: world length per texel along u over along v.
        if let Some((du, dv)) = mesh.uv_derivatives(t) {
            let (lu, lv) = (
                length(f64s(du)) / tiling[0] / texels[0] as f64,
                length(f64s(dv)) / tiling[1] / texels[1] as f64,
            );
            if lu > 0.0 && lv > 0.0 && lu.is_finite() && lv.is_finite() && area > 0.0 {
                let s = (lu / lv).max(lv / lu);
                area_sum += area;
                if s > SQUEEZE {
                    squeezed_area += area;
                }
                worst = worst.max(s);
            }
        }
        // What the camera sees of the triangle: its projected area, facing the camera.
        let centre = [
            (pa[0] + pb[0] + pc[0]) / 3.0,
            (pa[1] + pb[1] + pc[1]) / 3.0,
            (pa[2] + pb[2] + pc[2]) / 3.0,
        ];
        let to_eye = if camera.orthographic.is_some() {
            towards_target
        } else {
            unit(sub(camera.eye, centre))
        };
        let Some(to_eye) = to_eye else { continue };
        let cos_v = dot(face, to_eye);
        if cos_v <= 0.0 {
            continue;
        }
        let w = area * cos_v;
        facing += w;
        if view_cone.is_some_and(|c| cos_v.acos() > c + CONE_SLACK) {
            seen_beyond += w;
        }
        let to_light = match light.position {
            _ if light.is_environment() => None,
            Some(p) => unit(sub(p, centre)),
            None => unit(light.direction),
        };
        if let Some(l) = to_light {
            let cos_l = dot(face, l);
            if cos_l > 0.0 {
                lit += w;
                if light_cone.is_some_and(|c| cos_l.acos() > c + CONE_SLACK) {
                    lit_beyond += w;
                }
            }
        }
    }
    if !curvature.is_empty() {
        curvature.sort_by(f64::total_cmp);
        let k = curvature[(curvature.len() - 1) * 95 / 100];
        if k > 1e-9 {
            v.radius = Some(1.0 / k);
        }
    }
    if area_sum > 0.0 {
        v.squeezed = (squeezed_area / area_sum, worst);
    }
    if facing > 0.0 {
        v.view_beyond = view_cone.map(|c| (seen_beyond / facing, c.to_degrees()));
    }
    if lit > 0.0 {
        v.light_beyond = light_cone.map(|c| (lit_beyond / lit, c.to_degrees()));
    }
    v
}

impl Validity {
    /// The warnings, each with its numbers and what it means for the image.
    /// `shell`: the shell's depth where the MDF maps relief onto it (absent without an MDF,
    /// where the shell draws nothing).
    pub fn warnings(&self, shell: Option<f64>) -> Vec<String> {
        let mut w = Vec::new();
        if let (Some(radius), Some(shell)) = (self.radius, shell) {
            let ratio = shell / radius;
            if ratio > SHELL_OVER_RADIUS {
                w.push(format!(
                    "outside the model's domain: the shell ({shell:.4}) is {ratio:.2} of the mesh's radius of curvature ({radius:.4}, the 95th percentile of its edges; above {SHELL_OVER_RADIUS}): the MDF assumes a shell flat over a tile, so relief this deep on this curvature is drawn bent (a thinner `shell`, or the true geometry through render.reference)"
                ));
            }
        }
        let (share, worst) = self.squeezed;
        if share > SHARE {
            w.push(format!(
                "outside the model's domain: {:.0}% of the mesh's area has its texels stretched beyond {SQUEEZE}:1 (worst {worst:.1}:1) by its texture coordinates: the BTF, captured on square texels, is drawn squeezed there",
                share * 100.0
            ));
        }
        if let Some((share, cone)) = self.view_beyond {
            if share > SHARE {
                w.push(format!(
                    "outside the model's domain: {:.0}% of the surface facing the camera is seen more obliquely than the BTF's most oblique view (θ {cone:.1}°): its appearance there is extrapolated from the outer rings",
                    share * 100.0
                ));
            }
        }
        if let Some((share, cone)) = self.light_beyond {
            if share > SHARE {
                w.push(format!(
                    "outside the model's domain: {:.0}% of the lit surface facing the camera is lit more obliquely than the BTF's most oblique light (θ {cone:.1}°): its appearance there is extrapolated from the outer rings",
                    share * 100.0
                ));
            }
        }
        w
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::primitive::{build, Params, Shape};

    fn mesh(shape: Shape, size: f64, minor: f64) -> Mesh {
        build(&Params {
            shape,
            size,
            minor,
            segments: [64, 32],
        })
        .unwrap()
    }

    /// UBO2003's rings go to θ = 75°; a ring at 60° stands for a BTF sampled less far.
    fn ring(theta_deg: f64) -> Vec<[f64; 3]> {
        let t = theta_deg.to_radians();
        (0..8)
            .map(|k| {
                let p = k as f64 * std::f64::consts::FRAC_PI_4;
                [t.sin() * p.cos(), t.sin() * p.sin(), t.cos()]
            })
            .chain([[0.0, 0.0, 1.0]])
            .collect()
    }

    #[test]
    fn each_limit_is_measured_from_the_scene_and_warned_past_its_threshold() {
        let camera = CameraParams::default();
        let light = LightParams::default();
        let dirs = ring(75.0);
        let btf = |views, lights| Sampled {
            texels: [64, 64],
            views,
            lights,
        };
        // A torus whose tube is 0.38, its tightest radius (the ring's is 0.52 at the inside): a
        // shell of 0.2 is 0.53 of it; 0.01 is well inside.
        let torus = mesh(Shape::Torus, 0.9, 0.38);
        let v = measure(&torus, &camera, &light, [12.0, 5.0], btf(&dirs, &dirs));
        let radius = v.radius.unwrap();
        // The tube's radius is the tightest principal radius (0.38) up to the mesh's facets.
        assert!((radius - 0.38).abs() < 0.05, "radius {radius}");
        assert!(0.2 / radius > SHELL_OVER_RADIUS);
        let curved = |w: Vec<String>| w.iter().any(|w| w.contains("radius of curvature"));
        assert!(curved(v.warnings(Some(0.2))));
        // Without an MDF the shell draws nothing: no curvature warning; a thin shell is inside.
        assert!(!curved(v.warnings(None)));
        assert!(!curved(v.warnings(Some(0.01))));

        // A sphere tiled 6 × 3 has square texels at its equator and squeezed ones towards its
        // poles: the area within 41.8° of a pole (sin θ < 2/3) is 1 − cos 41.8° = 25% of it.
        let sphere = mesh(Shape::Sphere, 1.0, 0.0);
        let v = measure(&sphere, &camera, &light, [6.0, 3.0], btf(&dirs, &dirs));
        let (share, worst) = v.squeezed;
        assert!((share - 0.255).abs() < 0.03, "squeezed share {share}");
        assert!(worst > 10.0, "worst {worst}");
        assert!(v
            .warnings(Some(0.01))
            .iter()
            .any(|w| w.contains("stretched")));

        // A plane tiled evenly is neither curved nor squeezed.
        let plane = mesh(Shape::Plane, 2.0, 0.0);
        let grazing = CameraParams {
            eye: [0.0, -3.0, 0.3],
            ..CameraParams::default()
        };
        let v = measure(&plane, &grazing, &light, [4.0, 4.0], btf(&dirs, &dirs));
        assert_eq!(v.radius, None);
        assert!(v.squeezed.0 < 1e-9);
        // Seen at grazing angles (81° to 86° from the normal): beyond a 75° cone; from straight
        // above, inside a 60° one.
        let (share, cone) = v.view_beyond.unwrap();
        assert!((cone - 75.0).abs() < 1e-6);
        assert!(share > 0.99, "share beyond {share}");
        assert!(v
            .warnings(Some(0.01))
            .iter()
            .any(|w| w.contains("seen more obliquely")));
        let above = CameraParams {
            eye: [0.0, 0.0, 4.0],
            ..CameraParams::default()
        };
        let sixty = ring(60.0);
        let v = measure(&plane, &above, &light, [4.0, 4.0], btf(&sixty, &dirs));
        assert!(v.view_beyond.unwrap().0 < 1e-9);
        // A light at 80° from the plane's normal, lights sampled to 60°: all of it beyond.
        let low = LightParams {
            direction: [0.0, 80f64.to_radians().sin(), 80f64.to_radians().cos()],
            ..LightParams::default()
        };
        let v = measure(&plane, &above, &low, [4.0, 4.0], btf(&dirs, &sixty));
        assert!(v.light_beyond.unwrap().0 > 0.99);
        assert!(v
            .warnings(Some(0.01))
            .iter()
            .any(|w| w.contains("lit more obliquely")));
    }
}
