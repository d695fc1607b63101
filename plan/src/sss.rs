//! The translucency stage: the BRDF approximation or the gather at some spacing, the octree
//! threshold, and the profile's table.

use crate::*;
use mesoflow_graph::GraphFile;
use serde_json::{json, Value};

pub(crate) fn decide_sss(cx: &Stage, out: &mut GraphFile, share: f64) -> Decision {
    let Stage {
        model,
        file,
        render,
        scene,
        full,
        cheapest,
        why_cheapest,
        ..
    } = *cx;
    // The graph's own spacing, where it sets one: no candidate samples closer.
    let given_spacing = file
        .node(render)
        .and_then(|n| n.params.get("spacing"))
        .and_then(Value::as_f64);
    let set = |out: &mut GraphFile, k: &str, v: Value| {
        if let Some(n) = out.node_mut(render) {
            n.params.insert(k.into(), v);
        }
    };
    let mfp = scene.mfp_pixels;
    let candidate = |o: calibration::SssOption| model.sss.iter().find(|c| c.option == o);
    let brdf_error = mfp
        .and_then(|m| candidate(calibration::SssOption::Brdf).and_then(|c| c.flip.at(m)))
        .map(|p| p.0);
    if full {
        // The full model is the graph as written: a plan only simplifies it.
        return Decision {
            stage: "sss",
            choice: json!({ "model": "as given" }),
            reason: "budget 0: the graph's own translucency, unchanged".into(),
            predicted_error: Some(0.0),
            predicted_cost: None,
        };
    }
    let brdf = |out: &mut GraphFile, reason: String, predicted: Option<f64>| {
        set(out, "mode", json!("brdf"));
        Decision {
            stage: "sss",
            choice: json!({ "mode": "brdf" }),
            reason,
            predicted_error: predicted,
            predicted_cost: Some(json!({ "samples": 0 })),
        }
    };
    if cheapest {
        return brdf(out, why_cheapest.to_string(), brdf_error);
    }
    if let Some(p) = mfp.filter(|p| *p < 0.5) {
        return brdf(
            out,
            format!(
                "the longest effective mean free path ({:.3} mm) is {p:.2} of a pixel footprint: scattering stays inside a pixel",
                scene.mfp_mm.unwrap_or(f64::NAN)
            ),
            brdf_error,
        );
    }
    // The cheapest calibrated candidate (by render time) predicted within the budget, by the
    // worse of the calibration media.
    let best = mfp.and_then(|m| {
        model
            .sss_predictions(m)
            .into_iter()
            .filter(|(o, e, _)| {
                *e <= share
                    && matches!(
                        o,
                        calibration::SssOption::Brdf | calibration::SssOption::Gather { .. }
                    )
            })
            .min_by(|a, b| a.2.total_cmp(&b.2))
    });
    let default_spacing = scene.mfp_min_mm.map(|m| 0.25 * m);
    match (best, default_spacing, scene.pixel_footprint_mm) {
        (Some((calibration::SssOption::Brdf, e, time)), _, _) => {
            let mut d = brdf(
                out,
                format!(
                    "scattering spans {:.2} px; the BRDF approximation is predicted at FLIP {e:.3}, within {share:.3}",
                    mfp.unwrap_or(f64::NAN),
                ),
                Some(e),
            );
            d.predicted_cost = Some(json!({ "samples": 0, "render_time_vs_full": time }));
            d
        }
        (
            Some((calibration::SssOption::Gather { footprints: k }, e, time)),
            Some(default),
            Some(footprint),
        ) => {
            let spacing = (k * footprint)
                .max(default)
                .max(given_spacing.unwrap_or(0.0));
            set(out, "mode", json!("diffusion"));
            set(out, "spacing", json!(spacing));
            // The graph's own octree threshold stays (the calibration's gathers summed every
            // sample, so the prediction leaves out what the octree adds: the probe measures
            // it); brute force would be more model, and on the CPU more time, than the graph.
            Decision {
                stage: "sss",
                choice: json!({ "mode": "diffusion", "spacing_mm": spacing }),
                reason: format!(
                    "scattering spans {:.2} px; samples {k} pixel footprints apart ({spacing:.3} mm, never closer than the default {default:.3} mm) are predicted at FLIP {e:.3} (the worse calibration medium), within {share:.3}",
                    mfp.unwrap_or(f64::NAN),
                ),
                predicted_error: Some(e),
                predicted_cost: Some(json!({ "render_time_vs_full": time })),
            }
        }
        _ => {
            // Nothing cheaper is predicted within the budget: the graph's own gather, as
            // written (a plan never gives more model, nor a costlier gather, than the graph).
            Decision {
                stage: "sss",
                choice: json!({ "model": "as given" }),
                reason: format!(
                    "scattering spans {:.2} px; no cheaper candidate is predicted within {share:.3}: the graph's own gather, unchanged",
                    mfp.unwrap_or(f64::NAN)
                ),
                predicted_error: Some(0.0),
                predicted_cost: None,
            }
        }
    }
}

/// The subsurface options of the invisible tier for a gathered render: each with the worse
/// calibration medium's (FLIP, time) at this view where that FLIP is within a tenth of `share`;
/// none for the full model, a BRDF render or a view the calibration does not cover.
pub(crate) fn invisible_sss(
    cx: &Stage,
    out: &GraphFile,
    share: f64,
) -> Vec<(calibration::SssOption, f64, f64)> {
    let brdf = out
        .node(cx.render)
        .is_some_and(|n| n.params.get("mode") == Some(&json!("brdf")));
    match cx.scene.mfp_pixels {
        Some(mfp) if !cx.full && !brdf => cx
            .model
            .sss_predictions(mfp)
            .into_iter()
            .filter(|(_, e, _)| *e <= 0.1 * share)
            .collect(),
        _ => Vec::new(),
    }
}

/// The CPU path's octree: the gather at the largest calibrated threshold the measured model
/// predicts within a tenth of the translucency's share (meant to be invisible, as shadow maps
/// are), else brute force as `decide_sss` set it. The GPU path sums every sample whatever the
/// threshold, so there the choice changes nothing; on the CPU the octree is what makes the
/// gather fast.
pub(crate) fn decide_threshold(cx: &Stage, out: &mut GraphFile, share: f64) -> Option<Decision> {
    // Never a finer octree than the graph's own (0.05 unless it sets one): a smaller
    // threshold is more model.
    let given = cx
        .file
        .node(cx.render)
        .and_then(|n| n.params.get("threshold"))
        .and_then(Value::as_f64)
        .unwrap_or(mesoflow_nodes::sss::render::Params::default().threshold);
    let (t, e, time) = invisible_sss(cx, out, share)
        .into_iter()
        .filter_map(|(o, e, time)| match o {
            calibration::SssOption::Octree { threshold } => Some((threshold, e, time)),
            _ => None,
        })
        .filter(|(t, ..)| *t > given)
        .max_by(|a, b| a.0.total_cmp(&b.0))?;
    out.node_mut(cx.render)?
        .params
        .insert("threshold".into(), json!(t));
    Some(Decision {
        stage: "octree",
        choice: json!({ "threshold": t }),
        reason: format!(
            "on the CPU path (the GPU sums every sample): an octree at ΔA/d² < {t} is predicted at FLIP {e:.4} (the worse calibration medium), within a tenth of {share:.3}"
        ),
        predicted_error: Some(e),
        predicted_cost: Some(json!({ "cpu_render_time_vs_full": time })),
    })
}

/// The diffusion profile: the classical dipole instead of the graph's PBD where the measured
/// model predicts the change within a tenth of the translucency's share (like a shadow map's,
/// meant to be invisible), for a gathered render (a BRDF uses only the profile's totals, which
/// the dipole gets 1–17% wrong where PBD's are 4–10% high: no calibration says which a view
/// shows). The render itself costs the same; the saving is the profile's computation. The
/// graph's profile node stays as it is (others may read it): the render reads a copy.
pub(crate) fn decide_profile(cx: &Stage, out: &mut GraphFile, share: f64) -> Option<Decision> {
    let Stage {
        model,
        file,
        render,
        scene,
        ..
    } = *cx;
    let (_, e, _) = invisible_sss(cx, out, share)
        .into_iter()
        .find(|(o, ..)| *o == calibration::SssOption::Dipole)?;
    let mfp = scene.mfp_pixels?;
    let from = file.node(render)?.inputs.get("profile")?;
    let (id, port) = from.split_once('.')?;
    let profile = file.node(id).filter(|n| n.kind == "sss.profile")?;
    if profile.params.get("model").and_then(Value::as_str) != Some("pbd") {
        return None;
    }
    let mut params = profile.params.clone();
    params.insert("model".into(), json!("dipole"));
    let copy = format!("{PREFIX}profile");
    upsert(out, &copy, "sss.profile", params, profile.inputs.clone());
    out.node_mut(render)?
        .inputs
        .insert("profile".into(), format!("{copy}.{port}"));
    Some(Decision {
        stage: "profile",
        choice: json!({ "model": "dipole" }),
        reason: format!(
            "scattering spans {mfp:.2} px: the classical dipole's profile instead of PBD's is predicted at FLIP {e:.4} (the worse calibration medium), within a tenth of {share:.3}"
        ),
        predicted_error: Some(e),
        predicted_cost: model
            .dipole_profile_time
            .map(|t| json!({ "profile_time_vs_full": t })),
    })
}
