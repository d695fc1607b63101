//! From gathered sums to pixels: the near disc, the exitance's way out in angle (`emission.rs`), the
//! caller's exiting and local terms, single scattering, and the silhouette's coverage.

use super::emission::Local;
use super::gather::View;
use super::setup::{irradiance, Setup};
use super::single::Traced;
use super::{Params, Weights};
use crate::support::geometry::{dot, sub, V3};
use crate::support::optics::fresnel::transmit_in;
use crate::support::optics::phase::henyey_greenstein;
use crate::support::raytrace::light::Light;
use crate::support::raytrace::shadow::ShadowMap;
use crate::types::{Image, ScatteringMaterial};
use rayon::prelude::*;

/// Radiance and exitance images from the gathered sums.
pub(super) fn finish(
    setup: &Setup,
    view: &View,
    sums: &[[f64; 3]],
    p: &Params,
    (material, light): (&ScatteringMaterial, &Light),
    weights: &dyn Weights,
    traced: Option<&Traced>,
) -> (Image, Image) {
    let eta = setup.eta;
    // Each pixel on its own (in parallel, the same bits at any thread count).
    let pixels: Vec<([f32; 3], [f32; 3])> = view
        .hits
        .par_iter()
        .zip(sums)
        .enumerate()
        .map(|(px, (h, s))| {
            let Some((x, n, d, frag)) = h else {
                return (p.background.map(|v| v as f32), [0.0f32; 3]);
            };
            let e0 = irradiance(light, setup.shadow.as_ref(), *x, *n, eta);
            let to_light = light.at(*x).0;
            // The near disc's light enters through the same entrance function as the samples'.
            let f0 = if e0 > 0.0 {
                let (f, k) = (
                    weights.entrance(frag, to_light),
                    setup.energy_at(dot(*n, to_light)),
                );
                [0, 1, 2].map(|c| f[c] * k[c])
            } else {
                [0.0; 3]
            };
            let bounced = setup.bounced_at(*x);
            let m = [0, 1, 2].map(|c| s[c] + (e0 * f0[c] + bounced[c]) * setup.near_energy[c]);
            let v = d.map(|c| -c);
            let cos_o = dot(*n, v).clamp(0.0, 1.0);
            let single = match (p.single_scattering, traced) {
                (false, _) => [0.0; 3],
                (true, Some(t)) => {
                    let (_, ng) = t.tracer.triangle(frag.tri as usize);
                    t.radiance(material, light, *x, ng, *d, cos_o)
                }
                (true, None) => {
                    single_scattering(material, light, setup.shadow.as_ref(), *x, *n, v)
                }
            };
            let (exit, local) = weights.pixel(px, frag, v);
            // A silhouette pixel shows the object over its covered share, the background
            // elsewhere.
            let cover = view.coverage[px];
            // What the pixel's own irradiance would return from a plane: the light that leaves
            // with the local shape under `emission: half_space`.
            let own = (e0 > 0.0).then(|| Local {
                mu0: dot(*n, to_light).clamp(0.0, 1.0),
                exitance: [0, 1, 2].map(|c| e0 * f0[c] * setup.total[c] * exit[c]),
            });
            let leaving =
                setup
                    .exit
                    .leaving(cos_o, [0, 1, 2].map(|c| m[c] * exit[c]), own.as_ref());
            let radiance = [0, 1, 2].map(|c| {
                let object = leaving[c] + single[c] + local[c];
                (cover * object + (1.0 - cover) * p.background[c]) as f32
            });
            (radiance, m.map(|v| v as f32))
        })
        .collect();
    let radiance: Vec<f32> = pixels.iter().flat_map(|p| p.0).collect();
    let exitance: Vec<f32> = pixels.iter().flat_map(|p| p.1).collect();
    let image = |data| Image {
        width: view.width,
        height: view.height,
        channels: 3,
        data,
    };
    (image(radiance), image(exitance))
}

/// Hanrahan & Krueger's single scattering of a flat semi-infinite medium, per channel.
pub(super) fn single_scattering(
    m: &ScatteringMaterial,
    light: &Light,
    shadow: Option<&ShadowMap>,
    x: V3,
    n: V3,
    v: V3,
) -> [f64; 3] {
    let (l, e) = light.at(x);
    let (cos_i, cos_o) = (dot(n, l), dot(n, v));
    if cos_i <= 0.0 || cos_o <= 0.0 || shadow.is_some_and(|s| !s.lit(x, cos_i)) {
        return [0.0; 3];
    }
    let eta = m.eta;
    let (ti, to) = (transmit_in(cos_i, eta), transmit_in(cos_o, eta));
    if ti <= 0.0 || to <= 0.0 {
        return [0.0; 3];
    }
    let refracted = |c: f64| (1.0 - (1.0 - c * c) / (eta * eta)).max(0.0).sqrt();
    let (mi, mo) = (refracted(cos_i), refracted(cos_o));
    if mi + mo <= 0.0 {
        return [0.0; 3];
    }
    // Tangential parts of l and v, scaled by 1/η inside; propagation down in, up out.
    let lt = sub(l, n.map(|k| k * cos_i));
    let vt = sub(v, n.map(|k| k * cos_o));
    let cos = -dot(lt, vt) / (eta * eta) - mi * mo;
    let phase = henyey_greenstein(cos.clamp(-1.0, 1.0), m.g);
    [0, 1, 2].map(|c| {
        let s = m.sigma_s_prime[c] / (1.0 - m.g);
        let t = s + m.sigma_a[c];
        let albedo = if t > 0.0 { s / t } else { 0.0 };
        albedo * ti * to / (eta * eta) * phase * e * cos_i / (mi + mo)
    })
}
