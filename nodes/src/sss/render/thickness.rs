//! How thick the object is against the material's reduced mean free path 1/σt′. Diffusion
//! assumes light forgets its direction long before it crosses the object. Against the
//! volumetric truth (`graphs/sss_truth.json` with other presets and shapes, docs/guide/translucency.md's
//! translucency section) the torus's error with `geometry: body` stayed under 0.12 where its tube was 7.5 or more
//! reduced mean free paths across. At 3.7 (ketchup) and 2.5 (chicken1) `geometry: body` and
//! `exit_normal` sent far too much light through the tube (0.20–0.39, the dimmer half
//! 63–83% too bright), and 45–51% too much through a chicken1 sphere 4.6 paths across;
//! `planar` left those dimmer halves 10–38% too dark (the half chosen by a second truth of
//! another seed, so that its noise does not choose the pixels). Below [`THIN`] the render
//! warns.

use super::Geometry;
use crate::sss::octree::Source;
use crate::support::geometry::{add, dot, mul, V3};
use crate::support::raytrace::tracer::Tracer;
use crate::types::ScatteringMaterial;

/// Reduced mean free paths across the object under which `sss.render` warns: between the
/// thickest failure measured (4.6, the chicken1 sphere) and the thinnest success (7.5).
pub(super) const THIN: f64 = 6.0;

/// Samples probed: evenly strided over the irradiance samples, enough for a stable median.
const PROBES: usize = 256;

/// The median distance, mm, from a sample into the object along its inward normal to where
/// that ray leaves it; `None` when no probe finds the far side (an open mesh, a single sheet).
/// `sources` are in mm, the tracer in world units of `unit` mm.
pub(super) fn median_mm(tracer: &Tracer, sources: &[Source], unit: f64) -> Option<f64> {
    let stride = sources.len().div_ceil(PROBES).max(1);
    let mut depths: Vec<f64> = sources
        .iter()
        .step_by(stride)
        .filter_map(|s| {
            let inward: V3 = s.n.map(|v| -v);
            let from = add(s.p.map(|v| v / unit), mul(inward, tracer.epsilon));
            let hit = tracer.closest(from, inward)?;
            let (_, ng) = tracer.triangle(hit.tri);
            // Only a surface the ray leaves through is the far side.
            (dot(ng, inward) > 0.0).then_some((hit.t + tracer.epsilon) * unit)
        })
        .collect();
    if depths.is_empty() {
        return None;
    }
    depths.sort_by(f64::total_cmp);
    Some(depths[depths.len() / 2])
}

/// The warning for channels whose reduced extinction puts fewer than [`THIN`] mean free paths
/// across `thickness_mm`, or `None`; what to expect depends on the `geometry`.
pub(super) fn warning(
    thickness_mm: f64,
    material: &ScatteringMaterial,
    geometry: Geometry,
) -> Option<String> {
    let thin: Vec<String> = ["red", "green", "blue"]
        .iter()
        .zip(material.sigma_s_prime.iter().zip(&material.sigma_a))
        .filter_map(|(name, (s, a))| {
            let paths = thickness_mm * (s + a);
            (paths < THIN).then(|| format!("{name} {paths:.1}"))
        })
        .collect();
    let expect = match geometry {
        Geometry::Planar => {
            "expect the dimmer half 10–38% too dark (measured against the volumetric truth)"
        }
        Geometry::ExitNormal => "the light through thin parts comes out far too bright (the dimmer half 45–79% too bright against the volumetric truth; `geometry: planar` left it 10–38% too dark)",
        Geometry::Body | Geometry::Auto => "the light through thin parts comes out far too bright (the dimmer half 51–83% too bright against the volumetric truth; `geometry: planar` left it 10–38% too dark)",
        Geometry::Directional => {
            "expect large errors (not measured against the volumetric truth for `directional`)"
        }
    };
    (!thin.is_empty()).then(|| {
        format!(
            "the object is {thickness_mm:.2} mm thick (median along the inward normal): reduced mean free paths (1/σt′) across it {}, under the {THIN} diffusion needs; {expect}",
            thin.join(", ")
        )
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::primitive::{self, Shape};
    use crate::sss::points;

    fn material(sigma_t: f64) -> ScatteringMaterial {
        ScatteringMaterial {
            sigma_s_prime: [0.9 * sigma_t; 3],
            sigma_a: [0.1 * sigma_t; 3],
            eta: 1.0,
            g: 0.0,
        }
    }

    #[test]
    fn a_sphere_is_its_diameter_thick_and_a_torus_its_tube() {
        let unit = 10.0;
        for (shape, size, minor, expected) in [
            // Along the inward normal a sphere's chord is its diameter, a torus's the tube's.
            (Shape::Sphere, 1.0, 0.0, 20.0),
            (Shape::Torus, 0.9, 0.38, 7.6),
        ] {
            let mesh = primitive::build(&primitive::Params {
                shape,
                size,
                minor,
                segments: [96, 48],
            })
            .unwrap();
            let samples = points::sample(&mesh, 0.05, 1);
            let sources: Vec<Source> = samples
                .points
                .iter()
                .map(|s| Source {
                    p: s.p.map(|v| v * unit),
                    n: s.n,
                    power: [0.0; 3],
                })
                .collect();
            let t = median_mm(&Tracer::new(&mesh), &sources, unit).unwrap();
            // The facets' sagitta at 96 × 48 segments: under 0.3% of the radius each side.
            assert!((t / expected - 1.0).abs() < 0.01, "{shape:?}: {t} mm");
        }
    }

    #[test]
    fn warns_below_six_mean_free_paths_and_names_the_channel() {
        assert!(warning(10.0, &material(1.0), Geometry::ExitNormal).is_none());
        let mut m = material(1.0);
        m.sigma_s_prime[0] = 0.2;
        m.sigma_a[0] = 0.1;
        let w = warning(10.0, &m, Geometry::ExitNormal).unwrap();
        assert!(w.contains("red 3.0") && !w.contains("green"), "{w}");
        assert!(
            w.contains("too bright") && w.contains("`geometry: planar`"),
            "{w}"
        );
        let w = warning(10.0, &m, Geometry::Planar).unwrap();
        assert!(w.contains("too dark") && !w.contains("too bright"), "{w}");
    }
}
